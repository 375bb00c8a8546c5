"""The analysis computes the graph's records from bags and draws the paper's figures."""
import json
import math
import os

import pytest


def _live_record(written, case, variant, seed, max_ticks=None):
    """Record from the messages themselves, as the demo computes it from live messages."""
    from freejoint_common.records import arrays_from_messages
    from freejoint_core.metrics import compute_record
    arrays = arrays_from_messages(written['/controller_state'], written['/joint_states'],
                                  'joint3', max_ticks=max_ticks)
    return compute_record(case, variant, seed, source='graph', **arrays)


def test_bag_records_equal_the_records_of_the_messages_recorded(tmp_path, make_bag,
                                                                analyze, same_record):
    path = str(tmp_path / 'horizontal')
    written = make_bag(path, 400, custom_data={'case': 'horizontal', 'variant': 'robust',
                                               'seed': '7', 'max_ticks': '300'})
    done = analyze(path, '--no-plots')
    assert done.returncode == 0, done.stderr
    with open(os.path.join(path, 'metrics.json')) as fh:
        records = json.load(fh)
    assert len(records) == 1
    same_record(records[0], _live_record(written, 'horizontal', 'robust', 7, 300))
    table = done.stdout.splitlines()
    assert table[0].split()[:3] == ['case', 'variant', 'seed']
    assert table[2].split()[:3] == ['horizontal', 'robust', '7']
    assert table[2].split()[-1] == 'bag'


def test_two_bags_give_figures_3_4_2_and_a_comparison(tmp_path, make_bag, analyze):
    bags = []
    for case in ('horizontal', 'vertical'):
        bags.append(str(tmp_path / 'demo' / case))
        make_bag(bags[-1], 200, custom_data={'case': case, 'variant': 'robust', 'seed': '0'})
    figures = str(tmp_path / 'figures')
    done = analyze(*bags, '--figures-dir', figures)
    assert done.returncode == 0, done.stderr
    names = sorted(os.listdir(figures))
    assert names == ['compare.png', 'fig2_singularity.png', 'fig3_horizontal.png',
                     'fig4_vertical.png']
    for name in names:
        with open(os.path.join(figures, name), 'rb') as fh:
            assert fh.read(8) == b'\x89PNG\r\n\x1a\n', name
    rows = [line.split()[0] for line in done.stdout.splitlines()[2:4]]
    assert rows == ['horizontal', 'vertical']
    assert all(os.path.isfile(os.path.join(b, 'metrics.json')) for b in bags)


def test_figures_default_to_the_bag_and_its_parent(tmp_path, make_bag, analyze):
    path = str(tmp_path / 'runs' / 'vertical')
    make_bag(path, 50, custom_data={'case': 'vertical', 'variant': 'robust_off'})
    done = analyze(path)
    assert done.returncode == 0, done.stderr
    assert os.path.isfile(os.path.join(path, 'fig4_vertical.png'))
    assert os.path.isfile(str(tmp_path / 'runs' / 'fig2_singularity.png'))


def test_killed_recording_is_analysed_up_to_its_last_chunk_with_a_warning(
        tmp_path, make_bag, analyze, same_record):
    path = str(tmp_path / 'killed')
    written = make_bag(path, 250, custom_data={'case': 'vertical', 'variant': 'robust',
                                               'seed': '1', 'max_ticks': '250'},
                       finalise=False, chunk_size=1 << 30, flush_every=100)
    done = analyze(path, '--no-plots')
    assert done.returncode == 0, done.stderr
    assert 'not finalised' in done.stderr and 'Traceback' not in done.stderr
    assert 'holds 200 ticks, fewer than max_ticks = 250' in done.stderr
    with open(os.path.join(path, 'metrics.json')) as fh:
        record = json.load(fh)[0]
    same_record(record, _live_record(written, 'vertical', 'robust', 1, 200))


def test_case_is_taken_from_the_bag_name_when_the_bag_has_no_run_information(
        tmp_path, make_bag, analyze):
    path = str(tmp_path / 'vertical')
    make_bag(path, 20)
    done = analyze(path, '--no-plots')
    assert done.returncode == 0, done.stderr
    assert "case 'vertical' taken from its name" in done.stderr
    row = done.stdout.splitlines()[2].split()
    assert row[:3] == ['vertical', 'unknown', '-']


@pytest.mark.parametrize('damage', ['missing', 'truncated', 'foreign', 'no_states'])
def test_bad_input_gives_one_line_naming_the_file_and_a_non_zero_exit(
        tmp_path, make_bag, analyze, damage):
    path = str(tmp_path / 'run')
    if damage in ('truncated', 'no_states'):
        make_bag(path, 30)
    if damage == 'truncated':
        mcap = os.path.join(path, 'run_0.mcap')
        os.truncate(mcap, os.path.getsize(mcap) - 100)
        expected = mcap + ': truncated at byte'
    elif damage == 'foreign':
        os.makedirs(os.path.join(path, 'src'))
        with open(os.path.join(path, 'README'), 'w') as fh:
            fh.write('not a bag\n')
        expected = path + ': not a rosbag2 bag'
    elif damage == 'no_states':
        done = analyze(path, '--no-plots', '--state-topic', '/nothing')
        expected = path + ': no topic /nothing in the bag'
    else:
        expected = path + ': no such bag'
    if damage != 'no_states':
        done = analyze(path, '--no-plots')
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith('analyze: error: ' + expected), lines[0]
    assert done.stdout == ''


def test_a_real_time_bag_is_analysed_in_seconds_from_its_first_tick(tmp_path, make_bag):
    from freejoint_tools.analyze import analyse_bag
    path = str(tmp_path / 'horizontal')
    t0_ns = 1_795_695_095_917_000_000             # a real-time run's, Unix time
    make_bag(path, 300, custom_data={'case': 'horizontal', 'variant': 'robust'}, t0_ns=t0_ns)
    _, trace, _ = analyse_bag(path)
    assert trace['t0'] == pytest.approx(t0_ns * 1e-9, abs=1e-6)
    assert trace['t'][0] == 0.0
    # tick k is k ms after the first (within the float rounding of 1.8e9 s: 0.24 us)
    assert trace['t'][-1] == pytest.approx(0.299, abs=1e-6)
    assert len(trace['joints']['joint3']) == 300        # the joint states still paired


def test_a_lockstep_bag_keeps_its_sim_time(tmp_path, make_bag):
    from freejoint_tools.analyze import analyse_bag
    path = str(tmp_path / 'horizontal')
    make_bag(path, 50, custom_data={'case': 'horizontal', 'variant': 'robust'})
    _, trace, _ = analyse_bag(path)
    assert trace['t0'] == 0.0
    assert trace['t'][0] == 0.0 and trace['t'][-1] == pytest.approx(0.049, abs=1e-12)


# ---- the analysis of any arm: the arm, its passive joint and Fig. 2 from the bag ---------

FOUR = (('joint1', 'joint2', 'joint3', 'joint4'), ('joint2', 'joint3', 'joint4'))


def _description(name):
    from std_msgs.msg import String

    from freejoint_core.urdf import shipped_urdf_path
    with open(shipped_urdf_path(name), encoding='utf-8') as fh:
        return ('/robot_description', 'std_msgs/msg/String', True, String(data=fh.read()))


def test_the_passive_joint_is_the_one_the_controller_does_not_command(tmp_path, make_bag):
    from freejoint_tools.analyze import analyse_bag
    path = str(tmp_path / 'by_hand')                  # a hand-run recorder: no run info
    make_bag(path, 100, joints=FOUR, extra=[_description('four_link_arm')])
    record, trace, warnings = analyse_bag(path)
    assert trace['info']['passive_joint'] == 'joint1'
    arm = trace['arm']
    assert arm['passive'] == ['joint1'] and arm['joints'] == list(FOUR[0])
    assert arm['source'] == 'the recorded /robot_description' and arm['params'].n == 4
    assert arm['params'].passive == (0,)
    # joint1 of the bag maker's joint states: 0.1 sin(k / 100), k = 0 .. 99
    assert record['q3_range_deg'][1] == pytest.approx(
        max(math.degrees(0.1 * math.sin(k / 100.0)) for k in range(100)), abs=1e-12)


def test_without_a_description_the_paper_arm_and_its_joint3_are_taken(tmp_path, make_bag):
    from freejoint_tools.analyze import analyse_bag
    path = str(tmp_path / 'horizontal')
    make_bag(path, 20, custom_data={'case': 'horizontal', 'variant': 'robust'})
    _, trace, _ = analyse_bag(path)
    assert trace['info']['passive_joint'] == 'joint3'
    assert trace['arm']['name'] == 'Table I' and trace['arm']['params'].passive == (2,)


def test_the_run_information_still_names_the_passive_joint_first(tmp_path, make_bag):
    from freejoint_tools.analyze import analyse_bag
    path = str(tmp_path / 'run')
    make_bag(path, 20, custom_data={'case': 'horizontal', 'passive_joint': 'joint2'})
    _, trace, _ = analyse_bag(path)
    assert trace['info']['passive_joint'] == 'joint2'


def test_run_titles_name_the_case_once():
    from freejoint_tools.plots import run_title
    trace = {'name': 'horizontal', 'finalised': True, 'arm': None,
             'info': {'case': 'horizontal', 'variant': 'robust', 'seed': 0}}
    assert run_title(trace) == 'Case 1 (horizontal motion): robust, seed 0, from the bag'
    trace['name'] = 'mine'
    trace['arm'] = {'name': 'four_link_arm', 'passive': ['joint1']}
    assert run_title(trace) == ('Case 1 (horizontal motion): robust, seed 0, bag mine, '
                                'four_link_arm arm, passive joint1, from the bag')


def test_fig2_is_computed_for_the_arm_on_the_finest_grid_its_map_allows():
    from freejoint_core.arm import table1
    from freejoint_core.singularity import det_map, EPS_D, semi_singular
    from freejoint_core.urdf import four_link_arm
    from freejoint_tools.plots import fig2_region
    region, step, _ = fig2_region(table1('horizontal'), 0.7)
    assert step == 0.25
    paper = semi_singular(det_map(table1('horizontal').scaled(0.7), 0.25), EPS_D)
    assert (region.intervals == paper.intervals).all() and region.reach == paper.reach
    # 4 links: a (q2, q3, q4) map; 0.25 .. 1 deg exceed the core's sample limit
    region, step, nominal = fig2_region(four_link_arm().params, 0.7)
    assert step == 2.0 and nominal.n == 4 and region.singular_mask.ndim == 3


def test_a_four_link_bag_gives_its_figures_without_options(tmp_path, make_bag, analyze):
    path = str(tmp_path / 'four')
    make_bag(path, 60, joints=FOUR, extra=[_description('four_link_arm')],
             custom_data={'case': 'horizontal', 'variant': 'robust', 'seed': '0'})
    done = analyze(path, '--figures-dir', str(tmp_path / 'figs'))
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(tmp_path / 'figs')) == ['fig2_singularity.png', 'fig3_four.png']


def test_a_fine_joint_space_map_is_drawn_in_blocks_that_keep_every_flagged_sample():
    from types import SimpleNamespace

    import numpy as np

    from freejoint_tools.plots import _joint_space_mask
    mask = np.zeros((1440, 1440), dtype=bool)
    mask[721, :] = True                                   # one row: q2 = 180.25 deg
    shown, block = _joint_space_mask(SimpleNamespace(singular_mask=mask))
    assert block == 8 and shown.shape == (180, 180)
    assert shown[90].all() and shown.sum() == 180         # 721 // 8 = 90


def test_joint_failures_are_read_from_the_simulators_diagnostics_and_the_controllers_message():
    from types import SimpleNamespace as Ns
    from freejoint_tools.analyze import failure_lines, failures_of
    import numpy as np

    def state(text):
        return Ns(message=text)

    def diag(value, key='failed joints'):
        return Ns(status=[Ns(values=[Ns(key='level', value='WARN'), Ns(key=key, value=value)])])
    switched = ('joint3 failed at t = 2.507 s (detected by effort): law switched to passive '
                "['joint3']")
    states = [state(''), state('no setpoint yet'), state(switched), state(switched),
              state('joint2 failed at t = 3.010 s (detected by residual): cannot_track (r = 1 '
                    'active joints < m = 2): least-harm command on [0]'),
              state('joint3 failed at t = 9.000 s (detected by notice): ...')]
    diagnostics = [diag('none', key='steps'), diag('joint3 at 2.500 s'),
                   diag('joint3 at 2.500 s, joint2 at 3.000 s'),
                   diag('joint1 at 4.250 s')]
    got = failures_of(states, diagnostics)
    assert got == [
        {'joint': 'joint3', 'failed_s': 2.5, 'detected_s': 2.507, 'by': 'effort'},
        {'joint': 'joint2', 'failed_s': 3.0, 'detected_s': 3.01, 'by': 'residual'},
        {'joint': 'joint1', 'failed_s': 4.25, 'detected_s': None, 'by': None}]
    # A notice with no injection recorded (a real driver's bag): detected, time unknown.
    assert failures_of([states[-1]]) == [
        {'joint': 'joint3', 'failed_s': None, 'detected_s': 9.0, 'by': 'notice'}]
    assert failures_of(states[:2], diagnostics[:1]) == []
    # The lines: delay, and the largest error from the failure on (ticks of 1 ms).
    t = np.arange(5000) * 1e-3
    error = np.where(t < 2.5, 1e-3, 2e-3)
    error[3100] = 7e-3
    lines = failure_lines('vertical', got, t, error)
    assert lines == [
        'vertical: joint3 failed at 2.500 s, detected at 2.507 s by effort (delay 7 ms); max '
        'tracking error after it 7.0000 mm',
        'vertical: joint2 failed at 3.000 s, detected at 3.010 s by residual (delay 10 ms); '
        'max tracking error after it 7.0000 mm',
        'vertical: joint1 failed at 4.250 s, not detected; max tracking error after it 2.0000 mm']
    assert failure_lines('x', [{'joint': 'joint3', 'failed_s': None, 'detected_s': 9.0,
                                'by': 'notice'}], t, error) == [
        'x: joint3 failed at (not recorded), detected at 9.000 s by notice']


def test_a_spatial_path_is_drawn_in_the_plane_of_its_circle():
    import numpy as np

    from freejoint_tools.plots import _drawn, path_plane
    # a 0.1-m circle in the plane x = 0.5 (y, z), centre (0.5, 0.1, 0.4)
    a = np.linspace(0.0, 2.0 * np.pi, 73)[:-1]
    p_d = np.column_stack((np.full(72, 0.5), 0.1 + 0.1 * np.cos(a), 0.4 + 0.1 * np.sin(a)))
    origin, u, v, labels = path_plane(p_d)
    assert origin == pytest.approx([0.5, 0.1, 0.4], abs=1e-12)
    assert abs(u[0]) < 1e-12 and abs(v[0]) < 1e-12 and abs(u @ v) < 1e-12
    drawn = _drawn(p_d, (origin, u, v, labels))
    assert np.hypot(*drawn.T) == pytest.approx(np.full(72, 0.1), abs=1e-12)   # the radius
    assert labels[0].startswith('u [m]')
    # a planar path keeps its own x, y
    origin, u, v, labels = path_plane(p_d[:, :2])
    assert (u.tolist(), v.tolist(), labels) == ([1.0, 0.0], [0.0, 1.0], ('x [m]', 'y [m]'))
