"""Joint failures: plant injection, momentum residual, detectors, verdicts."""

import dataclasses
import math

from freejoint_core.arm import ArmModel, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.failure import (assess_passive_set, CANNOT_TRACK, DEFAULT_LEVELS,
                                    default_levels, EffortDetector,
                                    least_harm_torque, MomentumObserver, Reconfigurer,
                                    ResidualDetector, TRACKING)
from freejoint_core.failure_offline import parse_fail, run_failure_case
from freejoint_core.mujoco_plant import MujocoPlant
from freejoint_core.offline import initial_state
from freejoint_core.plant import Plant
from freejoint_core.trajectory import CircleQuintic
from freejoint_core.urdf import paper_arm
import numpy as np
import pytest

DT = 1e-3


def _full_arm(case):
    return dataclasses.replace(table1(case), passive=())


def _torques(k):
    return [2.0 * math.sin(3e-3 * k), 1.0, -0.5 * math.cos(1e-3 * k)]


def test_failed_joint_moves_as_the_plant_with_its_torque_zeroed():
    arm = _full_arm('vertical')
    q0 = initial_state(table1('vertical'))
    failing = Plant(arm, seed=3, q0=q0)
    failing.fail_joint(1, 0.05)
    zeroed = Plant(arm, seed=3, q0=q0)
    for k in range(120):
        tau = _torques(k)
        failing.step(tau, DT)
        zeroed.step([tau[0], 0.0 if k >= 50 else tau[1], tau[2]], DT)
        assert failing.q.tolist() == zeroed.q.tolist()
        assert failing.qd.tolist() == zeroed.qd.tolist()
    assert failing.failed == (1,)
    assert failing.last_effort == (tau[0], 0.0, tau[2])
    assert zeroed.last_effort == (tau[0], 0.0, tau[2])


def test_a_failure_scheduled_later_changes_nothing_before_it_and_reset_clears_it():
    arm = _full_arm('horizontal')
    a, b = Plant(arm, seed=1), Plant(arm, seed=1)
    b.fail_joint(2, 1.0)
    for k in range(30):
        a.step(_torques(k), DT)
        b.step(_torques(k), DT)
    assert a.q.tolist() == b.q.tolist() and b.failed == ()
    assert b.failures == {2: 1.0}
    b.reset()
    assert b.failures == {} and b.last_effort == (0.0, 0.0, 0.0)


@pytest.mark.parametrize('joint, at', [(3, 0.0), (-1, 0.0), (True, 0.0), (0, -1.0),
                                       (0, math.nan), (0, 'soon')])
def test_fail_joint_rejects_bad_arguments_by_name(joint, at):
    plant = Plant(_full_arm('horizontal'))
    with pytest.raises(FreejointValueError, match='^(joint|at_s):'):
        plant.fail_joint(joint, at)


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_residual_is_zero_with_the_exact_model_and_no_failure(case):
    arm = _full_arm(case)
    plant = Plant(arm, dist_bound=0.0, q0=initial_state(table1(case)))
    obs = MomentumObserver(arm)
    last = [0.0, 0.0, 0.0]
    worst = 0.0
    for k in range(400):
        worst = max(worst, float(np.max(np.abs(obs.step(plant.q, plant.qd, last, DT)))))
        last = _torques(k)
        plant.step(last, DT)
    # against torques of 0.5-2 N m: only the trapezoid's O(dt^2) error is left
    assert worst < 1e-3


def test_residual_of_a_torque_that_did_not_act_is_the_first_order_filter_of_minus_it():
    # At rest without gravity nothing moves: p = 0, beta = 0, so a commanded torque c
    # that never acted is an unexplained -c and r_k = -c (1 - (1 - K_O dt)^k) exactly.
    arm = _full_arm('horizontal')
    obs = MomentumObserver(arm, k_o=100.0)
    q = [0.3, -0.2, 1.0]
    c = [0.0, 0.0, 2.0]
    obs.step(q, [0.0] * 3, c, DT)
    for k in range(1, 60):
        r = obs.step(q, [0.0] * 3, c, DT)
        assert r[2] == pytest.approx(-2.0 * (1.0 - 0.9 ** k), rel=1e-12, abs=1e-15)
        assert r[0] == 0.0 and r[1] == 0.0


def test_a_failed_joints_residual_converges_to_minus_its_lost_torque_and_only_its_own():
    arm = _full_arm('vertical')
    plant = Plant(arm, dist_bound=0.0, q0=initial_state(table1('vertical')))
    plant.fail_joint(2, 0.0)
    obs = MomentumObserver(arm, k_o=100.0)
    tau = [5.0, 3.0, 1.5]
    obs.step(plant.q, plant.qd, tau, DT)
    for k in range(1, 101):
        plant.step(tau, DT)
        r = obs.step(plant.q, plant.qd, tau, DT)
        if k in (10, 30, 100):
            assert r[2] == pytest.approx(-1.5 * (1.0 - 0.9 ** k), abs=2e-3)
            assert abs(r[0]) < 2e-3 and abs(r[1]) < 2e-3


def test_momentum_terms_of_the_closed_form_equal_the_general_models():
    arm = _full_arm('vertical')
    obs = MomentumObserver(arm)
    model = ArmModel(arm)
    q, qd = np.array([0.4, -1.1, 2.0]), np.array([1.5, -0.7, 3.0])
    mom, beta = obs.momentum_terms(q, qd)
    np.testing.assert_allclose(mom, model.mass_matrix(q) @ qd, rtol=1e-12)
    expect = model.coriolis_matrix(q, qd).T @ qd - model.gravity_torque(q)
    np.testing.assert_allclose(beta, expect, rtol=1e-12, atol=1e-12)


def test_residual_detector_flags_after_the_consecutive_ticks_and_isolates_the_largest():
    det = ResidualDetector([1.0, 2.0, 1.0], margin=1.5, ticks=3)
    assert det.thresholds == [1.5, 3.0, 1.5]
    assert det.update([1.6, 0.0, 0.0]) is None
    assert det.update([1.6, 0.0, 0.0]) is None
    assert det.update([0.0, 0.0, 0.0]) is None   # the run of ticks is broken
    for _ in range(2):
        assert det.update([-1.6, 3.1, 2.0]) is None
    assert det.update([-1.6, 3.1, 2.0]) == 2     # 2.0/1.5 beats 1.6/1.5 and 3.1/3.0


def test_residual_detector_ignores_joints_it_does_not_watch():
    det = ResidualDetector([1.0, 1.0, 1.0], margin=1.0, ticks=1, watch=[0, 1])
    assert det.update([0.0, 0.0, 50.0]) is None
    assert det.update([0.0, -1.01, 50.0]) == 1


def test_effort_detector_flags_a_joint_that_reads_zero_against_its_command():
    det = EffortDetector(3, tol=0.05, rel=0.1, ticks=2)
    assert det.update([1.0, 2.0, 0.01], [1.0, 2.0, 0.0]) is None   # within tolerance
    assert det.update([1.0, 2.0, 0.5], [1.0, 2.0, 0.0]) is None
    assert det.update([1.0, 2.0, 0.5], [1.0, 2.0, 0.0]) == 2


def test_fewer_active_joints_than_task_coordinates_cannot_track():
    arm = _full_arm('vertical').scaled(0.7)
    a = assess_passive_set(arm, (1, 2), [0.1, 0.2, 0.3], [0.0] * 3)
    assert a.verdict == CANNOT_TRACK and a.reason.startswith('r = 1')


def test_joint_two_free_in_the_vertical_plane_cannot_track_though_its_det_passes():
    arm = _full_arm('vertical').scaled(0.7)
    q0 = initial_state(table1('vertical'))
    a = assess_passive_set(arm, (1,), q0, [0.0] * 3, CircleQuintic(), 0.0, horizon=1.5)
    assert a.det > 1.0
    assert a.verdict == CANNOT_TRACK and 'internal motion' in a.reason


def test_joint_three_free_in_the_vertical_plane_can_be_held():
    arm = _full_arm('vertical').scaled(0.7)
    q0 = initial_state(table1('vertical'))
    a = assess_passive_set(arm, (2,), q0, [0.0] * 3, CircleQuintic(), 0.0, horizon=1.5)
    assert a.verdict == TRACKING and a.max_qd < 100.0


def test_least_harm_is_a_damper_without_gravity_and_a_soft_gravity_hold_with_it():
    h = _full_arm('horizontal')
    tau = least_harm_torque(h, [0], [0.1, 0.2, 0.3], [2.0, 1.0, 1.0], [0.0] * 3)
    assert tau.tolist() == [-0.6]
    v = _full_arm('vertical')
    q = [0.0, 0.0, 0.0]   # arm stretched along +x: G_1 = g (m1 c1 + m2 (L1 + c2) + ...)
    tau = least_harm_torque(v, [0], q, [1.0, 0.0, 0.0], [0.1, 0.0, 0.0])
    g1 = 9.81 * (0.25 + 0.75 + 1.25)
    assert tau[0] == pytest.approx(g1 + 10.0 * 0.1 - 5.0 * 1.0)
    assert least_harm_torque(v, [0], q, [0.0] * 3, q, limit=[3.0]).tolist() == [3.0]


def test_a_notice_switches_to_the_paper_law_at_once_and_rebases_the_observer():
    nominal = _full_arm('horizontal').scaled(0.7)
    rec = Reconfigurer(nominal, DT)
    sw = rec.switch(2, 1.0, 'notice', initial_state(table1('horizontal')), [0.0] * 3)
    assert sw.verdict == TRACKING and sw.nominal.passive == (2,)
    assert rec.active == (0, 1) and rec.detector.watch == (0, 1)
    assert rec.observer.residual.tolist() == [0.0, 0.0, 0.0]


def test_notice_path_switches_at_the_first_tick_of_the_failure():
    rec, _ = run_failure_case('horizontal', 0, [(2, 0.02)], notice=True, detect=False,
                              duration=0.03, assess={'horizon': 0.3})
    assert rec['detected_at_s'] == [0.02] and rec['detected_by'] == 'notice'
    assert rec['verdict'] == TRACKING and rec['switches'][0]['passive'] == [3]


def test_the_residual_isolates_a_failed_joint_within_the_vertical_budget():
    rec, _ = run_failure_case('vertical', 4, [(2, 0.3)], duration=0.33,
                              assess={'horizon': 0.5})
    assert rec['detected_by'] == 'residual' and rec['switches'][0]['joint'] == 3
    assert 0.3 < rec['detected_at_s'][0] <= 0.32
    assert rec['verdict'] == TRACKING and not rec['false_alarm']


def test_joints_two_and_three_failing_give_cannot_track_and_a_bounded_least_harm_torque():
    rec, _ = run_failure_case('vertical', 0, [(1, 0.2), (2, 0.2)], duration=0.5)
    assert rec['verdict'] == CANNOT_TRACK and rec['verdict_at_s'] <= 0.25
    assert rec['effort_ok'] and rec['diverged_at_s'] is None


def test_no_false_alarm_on_a_short_fault_free_run():
    rec, _ = run_failure_case('horizontal', 0, (), duration=0.8)
    assert rec['switches'] == [] and not rec['false_alarm']
    assert rec['diverged_at_s'] is None


def test_parse_fail_reads_one_based_joints_and_times():
    assert parse_fail('joint3@2.5') == [(2, 2.5)]
    assert parse_fail('joint2@2.5,joint3@2.5') == [(1, 2.5), (2, 2.5)]
    with pytest.raises(FreejointValueError, match='^fail:'):
        parse_fail('joint4@1')


def test_levels_of_an_unmeasured_passive_set_are_the_largest_measured_of_its_case():
    arm = _full_arm('horizontal')
    assert default_levels(arm) == DEFAULT_LEVELS[(False, ())]
    joint2_free = dataclasses.replace(arm, passive=(1,))
    rows = [DEFAULT_LEVELS[(False, ())], DEFAULT_LEVELS[(False, (2,))]]
    assert default_levels(joint2_free) == tuple(max(c) for c in zip(*rows))


def test_after_cannot_track_a_further_failure_leaves_the_least_harm_set():
    nominal = table1('vertical').scaled(0.7)   # the paper's arm: joint 3 free
    rec = Reconfigurer(nominal, DT, effort=True)
    q = initial_state(table1('vertical'))
    first = rec.switch(1, 1.0, 'residual', q, [0.0] * 3)
    assert first.verdict == CANNOT_TRACK and first.nominal is None and rec.active == (0,)
    assert rec.observe(q, [0.0] * 3, [5.0, 0.0, 0.0], [5.0, 0.0, 0.0]) is None
    assert rec.observe(q, [0.0] * 3, [5.0, 0.0, 0.0], [0.0, 0.0, 0.0]) is None
    assert rec.observe(q, [0.0] * 3, [5.0, 0.0, 0.0], [0.0, 0.0, 0.0]) == (0, 'effort')
    second = rec.switch(0, 1.002, 'effort', q, [0.0] * 3)
    assert second.verdict == CANNOT_TRACK and rec.active == ()


def test_a_failed_joint_on_the_mujoco_plant_moves_as_its_torque_zeroed():
    arm = paper_arm('vertical')   # joint 3 free: the active joints are 1 and 2
    q0 = initial_state(table1('vertical'))
    failing = MujocoPlant(arm, seed=2, q0=q0)
    failing.fail_joint(1, 0.02)
    zeroed = MujocoPlant(arm, seed=2, q0=q0)
    for k in range(40):
        tau = _torques(k)[:2]
        failing.step(tau, DT)
        zeroed.step([tau[0], 0.0 if k >= 20 else tau[1]], DT)
    assert failing.q.tolist() == zeroed.q.tolist()
    assert failing.last_effort == (tau[0], 0.0, 0.0)


def test_damping_the_freed_link_in_the_rests_slows_its_revolutions_and_leaves_the_circle():
    # Vertical, joint 3 fails at 2.5 s: after the circle (5 s) the paper's law holds the end
    # effector while the freed link revolves about it (its angle q1 + q2 + q3 sweeps
    # 285 deg in the 12th second). The damping in the rests (a shift of the setpoint of at
    # most 3 cm, bounded by its filter alone) slows it; the circle is the law's alone.
    runs = {}
    for name, opts in (('law', None), ('damped', {'mode': 'rest', 'delta_max': 0.03,
                                                  'sat': 0.27})):
        rec, tr = run_failure_case('vertical', 0, [(2, 2.5)], duration=12.0,
                                   record_trace=True, free_link_damping=opts)
        t = tr['t']
        sweep = np.ptp(np.degrees(tr['q'][t >= 11.0].sum(axis=1)))
        rest_mm = 1e3 * np.linalg.norm(tr['e'][t >= 5.0], axis=1).max()
        runs[name] = (rec['max_mm'], sweep, rest_mm, rec['diverged_at_s'])
    assert runs['law'][1] > 250.0 and runs['damped'][1] < 0.7 * runs['law'][1], runs
    assert runs['damped'][0] == runs['law'][0] < 5.5, runs        # the circle: unchanged
    assert runs['damped'][2] < 5.5 and runs['damped'][3] is None, runs
    with pytest.raises(FreejointValueError, match=r'^free_link_damping: .*unexpected keyword'):
        run_failure_case('vertical', 0, [(2, 2.5)], duration=0.01,
                         free_link_damping={'delta': 0.03})
