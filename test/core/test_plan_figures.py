"""Behaviour of the figures against the plan (freejoint_core.plan_figures), hand-derived."""

import math

from freejoint_core import plan_figures as pf
from freejoint_core.errors import FreejointValueError
import numpy as np
import pytest

DT = 1e-3


def _line_plan(seconds=1.0, speed=0.1, rest=0.0):
    """Setpoints on a 1-ms grid: x = speed * t along +x for ``seconds``, ``rest`` s at rest."""
    n_move = int(round(seconds / DT))
    n_rest = int(round(rest / DT))
    t = np.arange(n_move + n_rest) * DT
    x = np.where(t < seconds, speed * t, speed * seconds)
    v = np.where(np.arange(len(t)) < n_move, speed, 0.0)
    return t, np.column_stack([x, np.zeros_like(x)]), np.column_stack([v, np.zeros_like(v)])


def test_an_arm_on_the_plan_has_zero_error_and_every_moving_tick_within():
    t, p, v = _line_plan(rest=0.5)
    fig = pf.plan_figures(t, p, t, p, v, bound_mm=1.7)
    assert fig['ticks'] == 1500 and fig['moving_ticks'] == 1000
    assert fig['rms_mm'] == 0.0 and fig['max_mm'] == 0.0
    assert fig['within'] == 1000 and fig['share'] == 1.0
    assert pf.plan_met(fig)


def test_a_plan_that_moves_while_the_arm_stands_still_has_no_tick_within():
    # The arm stands 10 mm behind the plan's start: the error grows from 10 mm to 110 mm.
    t, sp, v = _line_plan()
    arm = np.tile([-0.01, 0.0], (len(t), 1))
    fig = pf.plan_figures(t, arm, t, sp, v, bound_mm=5.5, held=np.ones(len(t), bool))
    assert fig['share'] == 0.0 and fig['within'] == 0
    assert fig['max_mm'] == pytest.approx(10.0 + 0.1 * 999, abs=1e-9)   # 10 + 100 t mm
    # held the whole time the plan moved: 999 intervals of 1 ms (the last state has none)
    assert fig['held_s'] == pytest.approx(0.999, abs=1e-12)
    assert fig['moving_s'] == pytest.approx(0.999, abs=1e-12)
    assert not pf.plan_met(fig)


def test_a_constant_offset_of_3_4_mm_is_5_mm_and_the_bound_decides_the_share():
    t, sp, v = _line_plan()
    arm = sp + [0.003, 0.004]
    fig = pf.plan_figures(t, arm, t, sp, v, bound_mm=5.5)
    assert fig['rms_mm'] == pytest.approx(5.0, abs=1e-9)
    assert fig['max_mm'] == pytest.approx(5.0, abs=1e-9)
    assert fig['share'] == 1.0
    assert pf.plan_figures(t, arm, t, sp, v, bound_mm=4.9)['share'] == 0.0
    assert pf.plan_figures(t, arm, t, sp, v)['share'] is None      # no bound, no share


def test_the_setpoint_is_interpolated_at_states_between_its_stamps():
    # States half a period after the setpoints: on a straight line at constant speed the
    # linear interpolation is exact, so an arm on the line has no error.
    t, sp, v = _line_plan()
    ts = t[:-1] + 0.5 * DT
    arm = np.column_stack([0.1 * ts, np.zeros_like(ts)])
    fig = pf.plan_figures(ts, arm, t, sp, v, bound_mm=1.0)
    assert fig['max_mm'] == pytest.approx(0.0, abs=1e-12)
    assert fig['moving_ticks'] == len(ts)


def test_states_outside_the_plans_span_are_not_judged():
    t, sp, v = _line_plan(seconds=0.1)
    ts = np.arange(-50, 150) * DT             # 50 states before, 50 after the plan's stamps
    arm = np.zeros((len(ts), 2))
    fig = pf.plan_figures(ts, arm, t, sp, v, bound_mm=1.0)
    assert fig['ticks'] == 100
    assert np.isnan(fig['error_mm'][:50]).all() and np.isnan(fig['error_mm'][150:]).all()
    assert not fig['moving'][:50].any()


def test_only_the_plans_moving_ticks_count_in_the_share():
    # 1 s moving (arm on the plan), then 1 s at rest with the arm 10 mm off: the rest's
    # error shows in max but not in the share.
    t, sp, v = _line_plan(rest=1.0)
    arm = sp.copy()
    arm[1000:, 1] += 0.01
    fig = pf.plan_figures(t, arm, t, sp, v, bound_mm=1.7)
    assert fig['max_mm'] == pytest.approx(10.0, abs=1e-9)
    assert fig['moving_ticks'] == 1000 and fig['share'] == 1.0
    assert fig['moving_max_mm'] == 0.0


def test_held_time_counts_only_while_the_plan_moves():
    t, sp, v = _line_plan(rest=0.5)
    held = np.zeros(len(t), bool)
    held[200:450] = True                     # 0.25 s during the motion
    held[1200:1300] = True                   # 0.1 s at rest: not counted
    fig = pf.plan_figures(t, sp, t, sp, v, bound_mm=1.7, held=held)
    assert fig['held_s'] == pytest.approx(0.25, abs=1e-12)


def test_a_plan_whose_time_stood_still_is_late_by_that_long():
    # Plan 1: 0.5 s of plan time; its time stands still 0.25 s from 0.2 s on (a feed hold),
    # so its final setpoint comes 0.25 s after its nominal end. Plan 2 starts and is cut off.
    stamps, ids, ptime, final = [], [], [], []
    k = 0

    def add(plan, t, end=False):
        stamps.append(len(stamps) * DT)
        ids.append(plan)
        ptime.append(t)
        final.append(end)
    for i in range(-20, 0):                  # transition ticks before the start: not counted
        add(1, i * DT)
        k += 1
    plan_t = 0.0
    while True:
        done = plan_t > 0.5
        add(1, plan_t, done)
        k += 1
        if done:
            break
        paused = 0.2 <= plan_t and k * DT < 0.2 + 0.25 + 20 * DT
        plan_t = plan_t if paused else round(plan_t + DT, 9)
    for i in range(100):
        add(2, i * DT)
        k += 1
    n = len(stamps)
    sp = np.zeros((n, 2))
    v = np.zeros((n, 2))
    fig = pf.plan_figures(stamps, sp, stamps, sp, v, plan_id=ids, plan_time=ptime,
                          final=final)
    first, second = fig['plans']
    assert first['plan_id'] == 1 and second['plan_id'] == 2
    assert first['start_s'] == pytest.approx(20 * DT)
    assert first['late_s'] == pytest.approx(0.25, abs=1.5 * DT)
    assert second['end_s'] is None and second['late_s'] is None
    assert fig['plans_completed'] == 1
    assert fig['late_max_s'] == first['late_s']


def test_a_plan_on_time_is_not_late():
    stamps = np.arange(600) * DT
    ptime = stamps.copy()
    final = ptime > 0.5
    fig = pf.plan_figures(stamps, np.zeros((600, 2)), stamps, np.zeros((600, 2)),
                          np.zeros((600, 2)), plan_id=np.ones(600, int), plan_time=ptime,
                          final=final)
    assert fig['plans'][0]['late_s'] == pytest.approx(0.0, abs=1e-12)


def test_a_run_held_while_the_plan_moved_is_not_met_whatever_the_reference_error():
    # The arm holds its start point (the controller's reference: zero error against it)
    # while the plan goes round a 0.1-m circle: far off the plan, not met.
    t = np.arange(2000) * DT
    w = 2.0 * math.pi / 2.0
    sp = 0.1 * np.column_stack([np.cos(w * t), np.sin(w * t)])
    v = 0.1 * w * np.column_stack([-np.sin(w * t), np.cos(w * t)])
    arm = np.tile(sp[0], (len(t), 1))
    fig = pf.plan_figures(t, arm, t, sp, v, bound_mm=1.7, held=np.ones(len(t), bool))
    assert fig['share'] < 0.05
    assert not pf.plan_met(fig)
    assert pf.plan_met(fig, outcome_excuses=True)        # the hook for a plan's outcome
    assert not pf.plan_met(fig, diverged=True, outcome_excuses=True)


def test_plan_met_needs_99_percent_of_the_moving_ticks():
    assert pf.plan_met({'share': 0.99})
    assert not pf.plan_met({'share': 0.989})
    assert not pf.plan_met({'share': None})


@pytest.mark.parametrize('change, name', [
    ({'t': [0.0, 0.002, 0.001]}, 't'),
    ({'p': np.zeros((3, 4))}, 'p'),
    ({'p': [[0.0, 0.0], [math.nan, 0.0], [0.0, 0.0]]}, 'p'),
    ({'sp_t': [0.0, 0.0, 0.001]}, 'sp_t'),
    ({'sp_p': np.zeros((2, 2))}, 'sp_p'),
    ({'sp_v': np.zeros((3, 3))}, 'sp_v'),
    ({'bound_mm': -1.0}, 'bound_mm'),
    ({'held': [True]}, 'held'),
    ({'plan_id': [1, 1, 1]}, 'plan_id'),
    ({'plan_id': [1, 1], 'plan_time': [0.0, 0.1, 0.2], 'final': [0, 0, 1]}, 'plan_id'),
])
def test_bad_input_is_named(change, name):
    args = {'t': [0.0, 0.001, 0.002], 'p': np.zeros((3, 2)), 'sp_t': [0.0, 0.001, 0.002],
            'sp_p': np.zeros((3, 2)), 'sp_v': np.zeros((3, 2))}
    args.update(change)
    with pytest.raises(FreejointValueError, match='^' + name):
        pf.plan_figures(**args)


def test_the_bound_is_one_and_a_half_times_the_offline_worst(monkeypatch):
    monkeypatch.setitem(pf._BOUNDS, 'vertical', 3.0)
    assert pf.tracking_bound_mm('vertical', recompute=True) == (4.5, 1.5, 3.0)
    assert pf.tracking_bound_mm('vertical', hogs=True, recompute=True) == (9.0, 3.0, 3.0)
    stored = pf.OFFLINE_WORST_MAX_MM['vertical'][1]
    assert pf.tracking_bound_mm('vertical') == (1.5 * stored, 1.5, stored)
    with pytest.raises(FreejointValueError, match='^case'):
        pf.tracking_bound_mm('ur5')


def test_another_arms_bound_is_made_the_same_way_of_its_own_seeds():
    worst = [1.2, 1.39, 1.3, 1.0, 1.1, 1.25, 1.38, 1.2, 1.21, 1.22]
    assert pf.tracking_bound_mm('ur5', offline_max_mm=worst) == (1.5 * 1.39, 1.5, 1.39)
    assert pf.tracking_bound_mm('ur5', True, offline_max_mm=worst) == (3.0 * 1.39, 3.0, 1.39)
    with pytest.raises(FreejointValueError, match=r'^offline_max_mm: expected shape \(10\)'):
        pf.tracking_bound_mm('ur5', offline_max_mm=worst[:9])
    with pytest.raises(FreejointValueError, match='^offline_max_mm: non-finite'):
        pf.tracking_bound_mm('ur5', offline_max_mm=worst[:9] + [math.nan])


def test_the_line_says_share_held_time_and_plans():
    t, sp, v = _line_plan()
    fig = pf.plan_figures(t, sp, t, sp, v, bound_mm=1.7, held=np.zeros(len(t), bool),
                          plan_id=np.ones(len(t), int), plan_time=t, final=t > 0.998)
    line = pf.format_figures(fig)
    assert '100.0 % of the 1000 moving ticks within 1.700 mm' in line
    assert 'held or braked 0.000 s' in line and '1 of 1 plans completed' in line


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_the_stored_offline_worst_is_what_the_offline_runner_computes(case):
    # The worst seed's max error as make offline computes it; another CPU (AVX2 without
    # AVX-512) computes other last bits of a chaotic 10-s run: 1e-6 relative.
    from freejoint_core.offline import run_case
    seed, worst = pf.OFFLINE_WORST_MAX_MM[case]
    assert run_case(case, 'robust', seed)[0]['max_mm'] == pytest.approx(worst, rel=1e-6)


def test_the_distance_to_the_path_is_to_its_segments_not_to_the_setpoint_of_the_time():
    # A square's corner path (0,0)-(1,0)-(1,1) sampled every 1 mm: by hand, (0.5, 0.2)
    # is 0.2 from the first side, (1.3, 0.5) 0.3 from the second, (1.3, -0.4) 0.5 from
    # the corner (1, 0), (0.9995, 0.5) 0.5 mm inside the second side.
    side = np.linspace(0.0, 1.0, 1001)
    path = np.vstack([np.column_stack([side, np.zeros(1001)]),
                      np.column_stack([np.ones(1000), side[1:]])])
    pts = np.array([[0.5, 0.2], [1.3, 0.5], [1.3, -0.4], [0.9995, 0.5]])
    got = pf.path_distance(pts, path)
    np.testing.assert_allclose(got, [0.2, 0.3, 0.5, 0.0005], rtol=0, atol=1e-12)
    assert pf.path_distance(np.array([[3.0, 4.0]]), np.zeros((1, 2)))[0] == 5.0


def _paused_plan(arm_off_path):
    # A 0.1-m circle of 2 s whose time stands 0.5 s (feed hold) from t = 0.5 s, the arm
    # braked 0.1 s before the plan stood (it stops at once, the plan 20 mm further on):
    # the moving ticks of that 0.1 s are off the 1.7-mm bound; the arm stays on the
    # circle (or ``arm_off_path`` m outside it).
    t = np.arange(3000) * DT
    ptime = np.clip(t, None, 0.5) + np.clip(t - 1.0, 0.0, None)
    w = 2.0 * math.pi / 2.0
    sp = 0.1 * np.column_stack([np.cos(w * ptime), np.sin(w * ptime)])
    moving = (t < 0.5) | (t >= 1.0)
    v = 0.1 * w * np.column_stack([-np.sin(w * ptime), np.cos(w * ptime)]) * moving[:, None]
    arm_time = np.where((t >= 0.4) & (t < 1.0), 0.4, ptime)
    arm_time = np.where((t >= 1.0) & (t < 1.1), 0.4 + (t - 1.0) * 2.0, arm_time)
    arm = (0.1 + arm_off_path) * np.column_stack([np.cos(w * arm_time),
                                                  np.sin(w * arm_time)])
    return pf.plan_figures(t, arm, t, sp, v, bound_mm=1.7, plan_id=np.ones(3000, int),
                           plan_time=ptime, final=ptime >= ptime[-1])


def test_a_plan_paused_and_finished_late_excuses_its_run_when_the_arm_stayed_on_the_path():
    fig = _paused_plan(0.0)
    plan = fig['plans'][0]
    assert plan['within'] < plan['moving_ticks'] and fig['share'] < pf.SHARE_MET
    assert plan['path_max_mm'] < 1e-3                    # on the circle all along
    excused, why = pf.outcome_excuses(fig, {1: ('SUCCEEDED', 1)})
    assert excused and 'plan 1 SUCCEEDED, 1 pause(s)' in why
    assert pf.plan_met(fig, outcome_excuses=excused)


@pytest.mark.parametrize('outcomes, off, reason', [
    ({}, 0.0, 'plan 1: off the bound and no outcome'),
    ({1: ('SUCCEEDED', 0)}, 0.0, 'plan 1: off the bound and SUCCEEDED with 0 pause(s)'),
    ({1: ('PREEMPTED', 1)}, 0.0, 'plan 1: off the bound and PREEMPTED'),
    ({1: ('SUCCEEDED', 1)}, 0.002,
     'plan 1: SUCCEEDED but the arm left the path by 2.00 mm > 1.700 mm'),
])
def test_no_excuse_without_a_pause_or_abort_named_or_with_the_arm_off_the_path(
        outcomes, off, reason):
    fig = _paused_plan(off)
    excused, why = pf.outcome_excuses(fig, outcomes)
    assert not excused and why.startswith(reason)


def test_a_plan_tracked_on_every_moving_tick_needs_no_excuse():
    t, sp, v = _line_plan()
    fig = pf.plan_figures(t, sp, t, sp, v, bound_mm=1.7, plan_id=np.ones(len(t), int),
                          plan_time=t, final=t >= t[-1])
    assert fig['plans'][0]['within'] == fig['plans'][0]['moving_ticks']
    assert pf.outcome_excuses(fig, {}) == (False, 'no plan off the bound')


def test_an_aborted_plan_ends_at_its_outcome_not_at_what_the_arm_did_after():
    # The plan aborted at 1.2 s (stood from 0.6 s); at 2.0 s the arm is put back 50 mm
    # off its path: that belongs to no plan once the outcome's time closes its span.
    t = np.arange(3000) * DT
    ptime = np.clip(t, None, 0.5)
    w = 2.0 * math.pi / 2.0
    sp = 0.1 * np.column_stack([np.cos(w * ptime), np.sin(w * ptime)])
    v = 0.1 * w * np.column_stack([-np.sin(w * ptime), np.cos(w * ptime)]) * (
        t < 0.5)[:, None]
    arm = sp.copy()
    arm[2000:] += [0.0, 0.05]
    args = (t, arm, t, sp, v)
    kw = {'bound_mm': 1.7, 'plan_id': np.ones(3000, int), 'plan_time': ptime,
          'final': np.zeros(3000, bool)}
    assert pf.plan_figures(*args, **kw)['plans'][0]['path_max_mm'] > 49.0
    ended = pf.plan_figures(*args, plan_end={1: 1.2}, **kw)['plans'][0]
    assert ended['path_max_mm'] < 1e-9 and ended['moving_ticks'] == 500
