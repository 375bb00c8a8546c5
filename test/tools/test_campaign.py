"""Campaign files are checked before any run; designs expand as written; runs resume."""
import os

from freejoint_tools import campaign
import numpy as np
import pyarrow.parquet as pq
import pytest

GOOD = """
name: tiny
case: vertical
duration: 0.2
task: {centre: [0.0, 0.0], radius: 0.2, duration: 5.0}
design: {kind: grid}
seeds: 2
chunk: 5
axes:
  scale: {values: [0.5, 0.7, 1.5]}
  delay: {values: [0, 3]}
"""


def _file(tmp_path, text, name='c.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize('replace,named', [
    (('  delay: {values: [0, 3]}', '  wind: {values: [0, 3]}'), 'axes.wind: unknown axis'),
    (('{values: [0.5, 0.7, 1.5]}', '{range: [1.5, 0.5], steps: 3}'),
     'axes.scale.range: low must be < high'),
    (('{values: [0.5, 0.7, 1.5]}', '{values: [0.5, -0.7]}'),
     'axes.scale.values[1]: -0.7 is out of range'),
    (('{values: [0, 3]}', '{range: [0, 3]}'), 'axes.delay.steps: a grid range needs steps'),
    (('{values: [0.5, 0.7, 1.5]}', '{values: [2.1]}'), 'axes.scale.values[0]: 2.1 is out of'),
    (('seeds: 2', 'seeds: 2\ncontroller: {Kp: [1, 2]}'),
     'controller.Kp: not a parameter of the controller node'),
    (('seeds: 2', 'seeds: 2\ncontroller: {K: [1, 2, 3]}'), 'controller.K: expected shape (2,)'),
    (('seeds: 2', 'seeds: 2\ncontroller: {stale_timeout: 0.5}'),
     'controller.stale_timeout: a node parameter the offline loop does not model'),
    (('case: vertical', 'case: sideways'), 'case: expected one of'),
    (('case: vertical', 'case: vertical\narm: {urdf: /nonexistent.urdf}'), 'arm.urdf:'),
    (('design: {kind: grid}', 'design: {kind: sobol}'), 'design.kind: expected one of'),
    (('seeds: 2', 'seeds: 2\nfixed: {noise_q: -1.0}'), 'fixed.noise_q: -1.0 is out of range'),
    (('duration: 0.2', 'duration: 0.2\nspeed: 3'), 'speed: unknown key'),
])
def test_a_bad_campaign_file_ends_with_one_line_naming_the_field_exit_2_before_any_run(
        tmp_path, capsys, replace, named):
    path = _file(tmp_path, GOOD.replace(*replace))
    out_dir = str(tmp_path / 'out')
    assert campaign.main(['run', path, '--out', out_dir]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('campaign: ') and named in err, err
    assert not os.path.exists(out_dir)


def _urdf_campaign(tmp_path, urdf_text, arm_extra='', name='u.yaml'):
    urdf = tmp_path / 'arm.urdf'
    urdf.write_text(urdf_text)
    text = GOOD.replace('case: vertical',
                        f'case: vertical\narm: {{urdf: {urdf}{arm_extra}}}')
    return _file(tmp_path, text, name)


def _paper_urdf_text():
    from freejoint_core.urdf import shipped_urdf_path
    with open(shipped_urdf_path('paper_arm'), encoding='utf-8') as f:
        return f.read()


def test_the_paper_arms_urdf_as_a_campaign_arm_gives_the_table_i_campaigns_results(tmp_path):
    # paper_arm.urdf is Table I: the same runs, every input and metric equal
    paper = campaign.run(campaign.load(_file(tmp_path, GOOD)), str(tmp_path / 'paper'),
                         progress=False)
    camp = campaign.load(_urdf_campaign(tmp_path, _paper_urdf_text()))
    assert camp['arm']['passive_joints'] == ['joint3']
    assert camp['arm']['gravity'] == [0.0, -9.81, 0.0]      # the case's, not given
    urdf = campaign.run(camp, str(tmp_path / 'urdf'), progress=False)
    with open(paper, 'rb') as fa, open(urdf, 'rb') as fb:
        assert fa.read() == fb.read()


def test_a_urdf_arm_runs_its_own_dynamics(tmp_path):
    # heavier free link (mass 1 -> 3): another arm, other results
    text = _paper_urdf_text()
    third = text.rindex('<mass value="1.0"/>')
    heavier = text[:third] + '<mass value="3.0"/>' + text[third + len('<mass value="1.0"/>'):]
    paper = pq.read_table(campaign.run(campaign.load(_file(tmp_path, GOOD)),
                                       str(tmp_path / 'paper'), progress=False))
    other = pq.read_table(campaign.run(campaign.load(_urdf_campaign(tmp_path, heavier)),
                                       str(tmp_path / 'other'), progress=False))
    assert other.column('run_index').to_pylist() == list(range(12))
    assert other.column('rms_mm').to_pylist() != paper.column('rms_mm').to_pylist()


@pytest.mark.parametrize('arm_extra,edit,named', [
    ('', lambda t: t.replace('<origin xyz="0.25 0 0" rpy="0 0 0"/>\n      <mass',
                             '<origin xyz="0.4 0 0" rpy="0 0 0"/>\n      <mass', 1),
     "axes.scale: 1.5 puts a nominal centre of mass beyond its link's end (this arm: at "
     'most 1.25)'),
    (', passive_joints: [joint2]', lambda t: t,
     'arm.passive_joints: campaigns run 3-link arms whose last joint alone is passive'),
    (', gravity: [0, 0]', lambda t: t, 'gravity: expected 3'),
    (', wheels: 4', lambda t: t, 'arm.wheels: unknown key'),
    ('', lambda t: t.replace('<robot', '<rob', 1), 'arm: '),
])
def test_a_urdf_arm_the_batch_kernel_cannot_run_ends_with_one_line_naming_it(
        tmp_path, capsys, arm_extra, edit, named):
    path = _urdf_campaign(tmp_path, edit(_paper_urdf_text()), arm_extra)
    assert campaign.main(['run', path, '--out', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and named in err, err
    assert not os.path.exists(str(tmp_path / 'o'))


def test_the_four_link_urdf_is_refused_naming_its_joints(tmp_path, capsys):
    from freejoint_core.urdf import shipped_urdf_path
    text = GOOD.replace('case: vertical', 'case: vertical\narm: {urdf: %s, passive_joints: '
                        '[joint1]}' % shipped_urdf_path('four_link_arm'))
    assert campaign.main(['run', _file(tmp_path, text), '--out', str(tmp_path / 'o')]) == 2
    err = capsys.readouterr().err
    assert 'has 4 joints' in err and "passive ['joint1']" in err, err


def test_a_grid_design_is_the_product_of_the_axes_times_the_seeds(tmp_path):
    rows = campaign.design(campaign.load(_file(tmp_path, GOOD)))
    assert rows['run_index'].tolist() == list(range(12))
    assert rows['scale_mass'].tolist() == [0.5] * 4 + [0.7] * 4 + [1.5] * 4
    assert rows['scale_lc'].tolist() == rows['scale_inertia'].tolist() == \
        rows['scale_mass'].tolist()
    assert rows['delay'].tolist() == [0, 0, 3, 3] * 3
    assert rows['seed'].tolist() == [0, 1] * 6
    assert set(rows['dist_bound']) == {0.5} and set(rows['q3_0_deg']) == {120.0}


def test_a_latin_hypercube_puts_one_run_in_each_stratum_of_each_axis(tmp_path):
    text = GOOD.replace('design: {kind: grid}', 'design: {kind: lhs, samples: 40, seed: 3}')
    text = text.replace('seeds: 2', 'seeds: 1').replace('{values: [0, 3]}', '{range: [0, 39]}')
    text = text.replace('{values: [0.5, 0.7, 1.5]}', '{range: [0.5, 1.5]}')
    camp = campaign.load(_file(tmp_path, text))
    rows = campaign.design(camp)
    strata = np.floor((rows['scale_mass'] - 0.5) / 1.0 * 40).astype(int)
    assert sorted(strata.tolist()) == list(range(40))
    assert sorted(rows['delay'].tolist()) == list(range(40))
    assert rows['seed'].tolist() == list(range(40))
    again = campaign.design(campaign.load(_file(tmp_path, text, 'd.yaml')))
    assert np.array_equal(again['scale_mass'], rows['scale_mass'])


def test_a_stopped_campaign_resumes_to_the_table_of_one_uninterrupted_run(tmp_path):
    camp = campaign.load(_file(tmp_path, GOOD))
    whole = campaign.run(camp, str(tmp_path / 'whole'), progress=False)
    part = str(tmp_path / 'part')
    assert campaign.run(camp, part, progress=False, max_chunks=1) is None
    assert len(os.listdir(os.path.join(part, 'chunks'))) == 1
    resumed = campaign.run(camp, part, progress=False)
    with open(whole, 'rb') as fa, open(resumed, 'rb') as fb:
        assert fa.read() == fb.read()
    a = pq.read_table(whole)
    assert a.column('run_index').to_pylist() == list(range(12))
    holds = a.column('holds').to_pylist()
    paper = [i for i in range(12) if a.column('scale_mass')[i].as_py() == 0.7
             and a.column('delay')[i].as_py() == 0]
    assert all(holds[i] for i in paper)


def test_a_results_folder_of_another_campaign_is_refused(tmp_path, capsys):
    out_dir = str(tmp_path / 'out')
    campaign.run(campaign.load(_file(tmp_path, GOOD)), out_dir, progress=False, max_chunks=1)
    other = _file(tmp_path, GOOD.replace('seeds: 2', 'seeds: 3'), 'other.yaml')
    assert campaign.main(['run', other, '--out', out_dir, '--no-progress']) == 2
    assert 'another campaign' in capsys.readouterr().err


def test_the_report_prints_the_summary_and_draws_a_heatmap_per_pair_of_axes(tmp_path, capsys):
    out_dir = str(tmp_path / 'out')
    campaign.run(campaign.load(_file(tmp_path, GOOD)), out_dir, progress=False)
    assert campaign.main(['report', out_dir]) == 0
    text = capsys.readouterr().out
    assert text.startswith('runs: 12, law holds in ')
    assert '| scale | 0.7 | 4 |' in text and '| delay | 3 | 6 |' in text
    assert os.path.exists(os.path.join(out_dir, 'heatmap_scale__delay.png'))


def test_ctrl_c_keeps_the_finished_chunks_and_the_same_command_resumes(tmp_path, capsys,
                                                                       monkeypatch):
    path = _file(tmp_path, GOOD)
    out_dir = str(tmp_path / 'out')
    real = campaign.run_chunk
    calls = []

    def interrupted(camp, rows):
        calls.append(len(rows['run_index']))
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(camp, rows)

    monkeypatch.setattr(campaign, 'run_chunk', interrupted)
    assert campaign.main(['run', path, '--out', out_dir, '--no-progress']) == 130
    assert 'stopped; 1 of 3 chunks kept' in capsys.readouterr().err
    monkeypatch.setattr(campaign, 'run_chunk', real)
    assert campaign.main(['run', path, '--out', out_dir, '--no-progress']) == 0
    assert pq.read_table(os.path.join(out_dir, 'results.parquet')).num_rows == 12


def test_fj_campaign_delegates_to_the_campaign_command(tmp_path, capsys):
    from freejoint_tools import cli
    path = _file(tmp_path, GOOD.replace('seeds: 2', 'seeds: 0'))
    assert cli.main(['campaign', 'run', path, '--out', str(tmp_path / 'o')]) == 2
    assert capsys.readouterr().err == 'campaign: seeds: expected 1 .. 1e6, got 0\n'
    assert cli.main(['campaign', 'run', _file(tmp_path, GOOD, 'g.yaml'), '--check']) == 0
    assert capsys.readouterr().out == 'campaign tiny: 12 runs, axes scale, delay\n'


ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SPATIAL = """
name: ur5_tiny
arm: {arm}
duration: 0.3
success: {{max_mm: 3.0}}
axes:
  dist_bound: {{values: [0.5, 2.0]}}
"""


def test_a_spatial_arms_campaign_runs_the_same_twin_as_make_offline(tmp_path):
    from freejoint_tools.arm_twin import twin
    from freejoint_tools.harness import load_source
    # config/ur5 relative to the campaign file, as a lab's fj arm init directory would be
    path = _file(tmp_path, SPATIAL.format(arm=os.path.relpath(
        os.path.join(ROOT, 'config', 'ur5'), str(tmp_path))))
    camp = campaign.load(path)
    assert camp['case'] == 'spatial'
    assert camp['arm']['dir'] == os.path.join(ROOT, 'config', 'ur5')
    table = pq.read_table(campaign.run(camp, str(tmp_path / 'out'), progress=False))
    assert table.column('dist_bound').to_pylist() == [0.5, 2.0]
    assert table.column('ticks').to_pylist() == [300, 300]
    # the paper's point (70 % nominal, 0.5 N m, seed 0) is make offline ARM=ur5's run
    demo = load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'freejoint_demo')
    record, trace = demo.spatial_offline('ur5', 0, 300)
    assert table.column('max_mm').to_pylist()[0] == record['max_mm']
    assert table.column('min_det').to_pylist()[0] == float(np.min(trace['kappa']))
    free = np.degrees(trace['q'][:, 4])       # wrist_2, the free joint
    assert table.column('q3_max_deg').to_pylist()[0] == free.max()
    # another disturbance bound: another run, the same as the twin given that bound
    other, _ = twin(os.path.join(ROOT, 'config', 'ur5'), 0, 300, sim={'dist_bound': 2.0})
    assert table.column('max_mm').to_pylist()[1] == other['max_mm'] != record['max_mm']
    assert table.column('holds').to_pylist() == [True, True]
    assert np.isnan(table.column('tau_peak_1_nm').to_pylist()).all()


@pytest.mark.parametrize('extra,named', [
    ('task: {radius: 0.1}', 'task: a spatial arm takes it from its parameter files'),
    ('controller: {K: [1, 2, 3]}', 'controller: a spatial arm takes it from its'),
    ('fixed: {delay: 2}', 'fixed.delay: not an axis of a spatial arm (its axes: scale, '
     'dist_bound, seed)'),
])
def test_a_spatial_arms_campaign_refuses_what_its_files_say_naming_the_key(
        tmp_path, capsys, extra, named):
    text = SPATIAL.format(arm=os.path.join(ROOT, 'config', 'ur5')) + extra + '\n'
    assert campaign.main(['run', _file(tmp_path, text), '--check']) == 2
    assert capsys.readouterr().err.startswith('campaign: ' + named)
    missing = SPATIAL.format(arm=str(tmp_path / 'none'))
    assert campaign.main(['run', _file(tmp_path, missing, 'm.yaml'), '--check']) == 2
    assert 'arm: ' in capsys.readouterr().err
