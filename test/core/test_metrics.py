"""Behaviour of the run metrics (record format shared by offline, graph and bags)."""

import json
import math

from freejoint_core import metrics
from freejoint_core.errors import FreejointValueError
import numpy as np
import pytest


def _arrays():
    # Errors (m) of 3, 4 and 0 mm along different axes: |e| = 3, 4, 0 mm.
    t = np.array([0.0, 0.001, 0.002])
    p_d = np.array([[0.2, 0.0], [0.2, 0.01], [0.19, 0.02]])
    p = p_d + np.array([[0.003, 0.0], [0.0, -0.004], [0.0, 0.0]])
    tau = np.array([[1.0, -2.0], [-3.5, 0.5], [2.0, 1.0]])
    theta = np.array([[0.0] * 5, [1e-6] * 5, [1e-5, 2e-5, 3e-5, 4e-5, 5e-5]])
    q3 = np.radians([120.0, 90.0, 135.0])
    det = np.array([0.5, -0.25, 0.3])
    return t, p, p_d, tau, theta, q3, det


def test_record_values_are_hand_computed():
    t, p, p_d, tau, theta, q3, det = _arrays()
    rec = metrics.compute_record('horizontal', 'robust', 3, t, p, p_d, tau, theta, q3, det,
                                 None, 'offline')
    assert tuple(rec) == metrics.KEYS
    # rms = sqrt((9 + 16 + 0) / 3) mm
    assert rec['rms_mm'] == pytest.approx(math.sqrt(25.0 / 3.0), rel=1e-12)
    assert rec['max_mm'] == pytest.approx(4.0, rel=1e-12)
    assert rec['final_mm'] == 0.0
    assert rec['tau_peak_nm'] == [3.5, 2.0]
    assert rec['theta_final'] == [1e-5, 2e-5, 3e-5, 4e-5, 5e-5]
    assert rec['q3_range_deg'] == pytest.approx([90.0, 135.0], abs=1e-12)
    assert rec['min_det'] == 0.25
    assert rec['seed'] == 3 and rec['diverged_at_s'] is None
    assert (rec['case'], rec['variant'], rec['source']) == ('horizontal', 'robust', 'offline')


def test_record_is_plain_json():
    t, p, p_d, tau, theta, q3, det = _arrays()
    rec = metrics.compute_record('vertical', 'exact', np.int64(0), t, p, p_d, tau, theta[-1],
                                 q3[:, None], det, np.float64(0.002), 'bag')
    assert json.loads(json.dumps(rec, allow_nan=False)) == rec
    assert type(rec['seed']) is int and type(rec['rms_mm']) is float
    assert type(rec['diverged_at_s']) is float and rec['diverged_at_s'] == 0.002


def test_single_tick_record():
    rec = metrics.compute_record('horizontal', 'robust', None, [0.0], [[0.0, 0.001]],
                                 [[0.0, 0.0]], [[0.1, 0.2]], [0.0] * 5, [0.5], [1.0])
    assert rec['rms_mm'] == pytest.approx(1.0) and rec['final_mm'] == pytest.approx(1.0)
    assert rec['seed'] is None and rec['source'] == 'offline'


@pytest.mark.parametrize('field, value, match', [
    ('t', [], '^t:'),
    ('t', [0.0, 0.002, 0.001], '^t: .*non-decreasing'),
    ('p', np.zeros((2, 2)), r'^p: expected shape \(3, 2\)'),
    ('p_d', [[0.0, 0.0], [0.0, float('nan')], [0.0, 0.0]], '^p_d: non-finite value at row 1'),
    ('tau', np.zeros((3,)), '^tau:'),
    ('theta', np.zeros((2, 5)), r'^theta: expected shape \(k,\) or \(3, k\)'),
    ('q_passive', np.zeros((3, 2)), '^q_passive:'),
    ('det', np.zeros(2), '^det:'),
    ('diverged_at_s', float('inf'), '^diverged_at_s:'),
    ('seed', 1.5, '^seed:'),
    ('case', '', '^case:'),
    ('source', None, '^source:'),
])
def test_bad_inputs_name_the_argument(field, value, match):
    t, p, p_d, tau, theta, q3, det = _arrays()
    args = {'case': 'horizontal', 'variant': 'robust', 'seed': 0, 't': t, 'p': p, 'p_d': p_d,
            'tau': tau, 'theta': theta, 'q_passive': q3, 'det': det, 'diverged_at_s': None,
            'source': 'offline'}
    args[field] = value
    with pytest.raises(FreejointValueError, match=match):
        metrics.compute_record(**args)


def _record(**over):
    t, p, p_d, tau, theta, q3, det = _arrays()
    rec = metrics.compute_record('horizontal', 'robust', 0, t, p, p_d, tau, theta, q3, det)
    rec.update(over)
    return rec


def test_table_has_one_fixed_width_row_per_record():
    recs = [_record(), _record(seed=1, rms_mm=0.123456, diverged_at_s=1.25),
            _record(case='vertical', variant='robust_off', seed=None)]
    table = metrics.format_table(recs)
    lines = table.split('\n')
    assert len(lines) == 2 + 3
    assert lines[0].split()[:4] == ['case', 'variant', 'seed', 'rms_mm']
    assert set(lines[1]) == {'-'}
    assert lines[3].split()[:4] == ['horizontal', 'robust', '1', '0.1235']
    assert lines[3].split()[-2:] == ['1.250', 'offline']
    assert lines[4].split()[:3] == ['vertical', 'robust_off', '-']
    assert '90..135' in lines[2]
    # fixed width: the rms column ends at the same offset on every row
    end = lines[0].index('rms_mm') + len('rms_mm')
    assert lines[2][:end].endswith('2.887') and lines[3][:end].endswith('0.1235')
    assert 'theta_final' in metrics.format_table(recs, theta=True)


def test_a_spatial_arms_table_names_its_free_joint_and_kappa_not_q3_and_det():
    recs = [_record(case='ur5_wrist2', variant='spatial')]
    head = metrics.format_table(recs).split('\n')[0].split()
    assert 'free_deg' in head and 'min_kappa' in head
    assert 'q3_deg' not in head and 'min_det' not in head
    named = metrics.format_table(recs, titles={'q3_deg': 'wrist_2_deg',
                                               'min_det': 'min_kappa'})
    lines = named.split('\n')
    assert lines[0].split()[7:9] == ['wrist_2_deg', 'min_kappa']
    # the column widened to its title: the values end where the titles end
    end = lines[0].index('wrist_2_deg') + len('wrist_2_deg')
    assert lines[2][:end].endswith('90..135')
    mixed = metrics.format_table(recs + [_record()]).split('\n')[0].split()
    assert 'q3_deg' in mixed                    # planar rows keep the planar titles


def test_summary_reports_worst_case_over_seeds():
    recs = [_record(seed=0, rms_mm=0.5, max_mm=1.0), _record(seed=1, rms_mm=0.7, max_mm=0.9),
            _record(variant='exact', rms_mm=1e-4, max_mm=2e-4, diverged_at_s=2.0)]
    rows = metrics.summarize(recs)
    assert rows[0] == {'case': 'horizontal', 'variant': 'robust', 'source': 'offline',
                       'runs': 2, 'worst_rms_mm': 0.7, 'worst_max_mm': 1.0,
                       'mean_rms_mm': pytest.approx(0.6), 'diverged': 0}
    assert rows[1]['runs'] == 1 and rows[1]['diverged'] == 1
    text = metrics.format_summary(recs)
    assert len(text.split('\n')) == 4


def test_write_then_read_round_trips(tmp_path):
    recs = [_record(), _record(seed=None, diverged_at_s=0.5)]
    path = tmp_path / 'sub' / 'metrics.json'
    metrics.write_records(path, recs)
    assert metrics.read_records(path) == recs
    assert json.loads(path.read_text()) == recs


def test_reading_a_foreign_file_names_path(tmp_path):
    path = tmp_path / 'x.json'
    path.write_text('[1, 2]')
    with pytest.raises(FreejointValueError, match='^path:'):
        metrics.read_records(path)
    with pytest.raises(FreejointValueError, match='^path:'):
        metrics.read_records(tmp_path / 'missing.json')
    path.write_text(json.dumps({'records': []}))
    with pytest.raises(FreejointValueError, match='^path:.*JSON list'):
        metrics.read_records(path)
    path.write_text(json.dumps([{'case': 'x'}]))
    with pytest.raises(FreejointValueError, match='^path:.*lacks keys'):
        metrics.read_records(path)


def test_table_and_writer_reject_malformed_records(tmp_path):
    with pytest.raises(FreejointValueError, match='^records:'):
        metrics.format_table([{'case': 'horizontal'}])
    with pytest.raises(FreejointValueError, match='^records:'):
        metrics.write_records(tmp_path / 'm.json', _record())
    with pytest.raises(FreejointValueError, match='^records:'):
        metrics.write_records(tmp_path / 'm.json', [_record(rms_mm=float('nan'))])


def test_a_spatial_tip_gives_the_error_norm_over_its_three_coordinates():
    # errors (3, 4, 12) mm and (0, 0, 0): norms 13 mm and 0 (hand-derived)
    p = [[0.003, 0.004, 0.012], [0.1, 0.2, 0.3]]
    p_d = [[0.0, 0.0, 0.0], [0.1, 0.2, 0.3]]
    rec = metrics.compute_record('ur5_wrist2', 'spatial', 0, [0.0, 0.001], p, p_d,
                                 np.ones((2, 5)), np.zeros(5), [0.0, 0.1], [0.5, 0.6])
    assert rec['max_mm'] == pytest.approx(13.0, abs=1e-12)
    assert rec['final_mm'] == 0.0
    assert rec['rms_mm'] == pytest.approx(13.0 / np.sqrt(2.0), abs=1e-12)
    with pytest.raises(FreejointValueError, match=r'^p_d: expected shape \(2, 2\) or \(2, 3\)'):
        metrics.compute_record('ur5_wrist2', 'spatial', 0, [0.0, 0.001], p, np.zeros((2, 2)),
                               np.ones((2, 5)), np.zeros(5), [0.0, 0.1], [0.5, 0.6])
