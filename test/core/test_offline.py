"""Behaviour of the offline closed-loop runner (short runs: 0.1-0.5 s)."""

import json
import math

from freejoint_core import offline
from freejoint_core.arm import ArmModel, table1
from freejoint_core.control import Gains
from freejoint_core.errors import FreejointValueError
from freejoint_core.metrics import KEYS, read_records
from freejoint_core.trajectory import CircleQuintic
import numpy as np
import pytest


def test_initial_state_puts_the_end_effector_on_the_start_at_q3_120():
    q = offline.initial_state(table1('horizontal'))
    assert q[2] == pytest.approx(math.radians(120.0), abs=1e-15)
    assert q[1] > 0.0
    np.testing.assert_allclose(ArmModel(table1('horizontal')).fk(q), [0.2, 0.0], atol=1e-12)
    # Hand check: joints 2-3 form a rigid 0.5 m segment at 60 deg to link 2 (equal links,
    # q3 = 120 deg), so 0.2^2 = 0.5^2 + 0.5^2 + 2 (0.5)(0.5) cos(gamma) and q2 = gamma - 60.
    gamma = math.degrees(math.acos((0.04 - 0.5) / 0.5))
    assert math.degrees(q[1]) == pytest.approx(gamma - 60.0, abs=1e-9)


def test_exact_model_without_disturbance_tracks_to_well_under_a_micrometre():
    rec, trace = offline.run_case('horizontal', 'exact', None, duration=0.5, record_trace=True)
    assert rec['diverged_at_s'] is None
    assert rec['max_mm'] < 1e-3            # < 1 um
    assert rec['rms_mm'] < 1e-3
    assert rec['source'] == 'offline' and rec['variant'] == 'exact'
    # the error of the trace is the one the record summarises
    err = 1000.0 * np.hypot(trace['e'][:, 0], trace['e'][:, 1])
    assert rec['max_mm'] == pytest.approx(err.max(), rel=1e-12)
    assert rec['final_mm'] == pytest.approx(err[-1], rel=1e-12)


def test_ticks_are_k_dt_without_the_final_instant_and_follow_the_circle():
    rec, trace = offline.run_case('vertical', 'robust', 0, duration=0.1, record_trace=True)
    assert trace['t'].shape == (100,)
    np.testing.assert_array_equal(trace['t'], np.arange(100) * 1e-3)
    traj = CircleQuintic()
    for k in (0, 37, 99):
        assert tuple(trace['p_d'][k]) == traj.sample_tuple(k * 1e-3)[:2]
    np.testing.assert_allclose(trace['p'][0], [0.2, 0.0], atol=1e-12)
    assert trace['q'].shape == (100, 3) and trace['theta'].shape == (100, 5)
    assert rec['theta_final'] == trace['theta'][-1].tolist()
    assert rec['q3_range_deg'] == pytest.approx(
        [np.degrees(trace['q'][:, 2]).min(), np.degrees(trace['q'][:, 2]).max()])


def test_same_seed_gives_an_identical_record_and_another_seed_a_different_one():
    a, _ = offline.run_case('horizontal', 'robust', 4, duration=0.2)
    b, _ = offline.run_case('horizontal', 'robust', 4, duration=0.2)
    c, _ = offline.run_case('horizontal', 'robust', 5, duration=0.2)
    assert a == b
    assert c['rms_mm'] != a['rms_mm'] and c['tau_peak_nm'] != a['tau_peak_nm']


def test_robust_off_keeps_theta_at_zero_and_robust_adapts():
    off, _ = offline.run_case('vertical', 'robust_off', 1, duration=0.2)
    on, _ = offline.run_case('vertical', 'robust', 1, duration=0.2)
    assert off['theta_final'] == [0.0] * 5
    assert all(v > 0.0 for v in on['theta_final'])


def test_absurd_gains_diverge_with_a_time_and_no_nan():
    # K dt = 5 >> 2: the sampled loop is unstable within a few ticks.
    rec, trace = offline.run_case('horizontal', 'robust', 0, duration=0.5,
                                  gains=Gains(K=(5e3, 5e3)), record_trace=True)
    assert rec['diverged_at_s'] is not None
    assert 0.0 < rec['diverged_at_s'] < 0.1
    assert trace['t'][-1] == pytest.approx(rec['diverged_at_s'])
    assert rec['max_mm'] > 0.5 * 1000.0 or max(map(abs, trace['qd'][-1])) > 1000.0
    json.dumps(rec, allow_nan=False)       # raises on NaN/inf
    assert set(rec) == set(KEYS)


def test_tiny_nominal_model_in_the_vertical_case_diverges_without_crashing():
    rec, _ = offline.run_case('vertical', 'robust', 0, duration=0.5, nominal_scale=0.05)
    assert rec['diverged_at_s'] is not None and 0.0 < rec['diverged_at_s'] < 0.5
    assert all(math.isfinite(v) for v in (rec['rms_mm'], rec['max_mm'], rec['min_det']))


@pytest.mark.parametrize('kwargs, match', [
    ({'case': 'diagonal'}, '^case:'),
    ({'variant': 'fast'}, '^variant:'),
    ({'duration': 0.0005}, '^duration:'),
    ({'duration': 0.1005}, '^duration:'),
    ({'dt': -1e-3}, '^dt:'),
    ({'nominal_scale': 0.0}, '^nominal_scale:'),
    ({'gains': {'K': 1}}, '^gains:'),
    ({'trajectory': 'circle'}, '^trajectory:'),
    ({'q3_0_deg': 'up'}, '^q3_0_deg:'),
    ({'dt_sub': 3e-4}, '^dt_sub:'),
    ({'dt_sub': 0.0}, '^dt_sub:'),
])
def test_bad_arguments_raise_naming_them(kwargs, match):
    args = {'case': 'horizontal', 'variant': 'robust', 'seed': 0, 'duration': 0.1}
    args.update(kwargs)
    with pytest.raises(FreejointValueError, match=match):
        offline.run_case(**args)


def _rec(**over):
    rec = {'case': 'horizontal', 'variant': 'robust', 'seed': 0, 'rms_mm': 0.3,
           'max_mm': 0.8, 'final_mm': 0.5, 'tau_peak_nm': [10.0, 7.0],
           'theta_final': [0.0] * 5, 'q3_range_deg': [91.0, 145.0], 'min_det': 0.4,
           'diverged_at_s': None, 'source': 'offline'}
    rec.update(over)
    return rec


def test_compare_records_reports_the_largest_change_per_figure():
    a = [_rec(), _rec(seed=1), _rec(variant='robust_off', diverged_at_s=3.0),
         _rec(seed=2)]
    b = [_rec(rms_mm=0.3 + 2e-9), _rec(seed=1, tau_peak_nm=[10.0, 7.5], max_mm=0.7),
         _rec(variant='robust_off', diverged_at_s=3.25), _rec(seed=2, diverged_at_s=1.0)]
    diff = offline.compare_records(a, b)
    assert diff['completed'] == 2 and diff['diverged'] == 1 and diff['mismatch'] == 1
    assert diff['figures']['rms_mm'] == pytest.approx(2e-9, rel=1e-6)
    assert diff['figures']['max_mm'] == pytest.approx(0.1)
    assert diff['figures']['tau_peak_nm'] == pytest.approx(0.5)
    assert diff['figures']['final_mm'] == 0.0
    assert diff['diverged_at_s'] == pytest.approx(0.25)
    with pytest.raises(FreejointValueError, match='^b:'):
        offline.compare_records(a, b[:2])
    with pytest.raises(FreejointValueError, match='^b:'):
        offline.compare_records([_rec()], [_rec(seed=7)])


def test_main_prints_the_table_and_writes_the_records(tmp_path, capsys, monkeypatch):
    calls = []

    def short_run(case, variant, seed, **kw):
        calls.append((case, variant, seed, kw.get('dt_sub')))
        return real_run(case, variant, seed, duration=0.05, **kw)

    real_run = offline.run_case
    monkeypatch.setattr(offline, 'run_case', short_run)
    out = tmp_path / 'o' / 'metrics.json'
    assert offline.main(['--seeds', '2', '--off-seeds', '1', '--cases', 'vertical',
                         '--out', str(out), '--dt-sub', '0.001']) == 0
    assert calls == [('vertical', 'robust', 0, 0.001), ('vertical', 'robust', 1, 0.001),
                     ('vertical', 'robust_off', 0, 0.001), ('vertical', 'exact', 0, 0.001)]
    text = capsys.readouterr().out
    assert 'rms_mm' in text and 'worst_rms_mm' in text
    recs = read_records(out)
    assert [(r['variant'], r['seed']) for r in recs] == [
        ('robust', 0), ('robust', 1), ('robust_off', 0), ('exact', 0)]
