"""Internal-motion stabilisation: null-space term, weighted inverse, equilibrium poses."""

import dataclasses
import math

from freejoint_core.arm import ArmModel, table1
from freejoint_core.control import Gains, RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import (equilibrium_pose, free_link_swing, FreeLinkModulation,
                                     hanging_pose, NullSpace, projector, pseudo_inverse,
                                     weighted_inverse)
from freejoint_core.offline import initial_state
from freejoint_core.plant import Plant
from freejoint_core.trajectory import CircleQuintic
import numpy as np
import pytest


def _all_active(case):
    return dataclasses.replace(table1(case), passive=())


# -- projectors (hand-checkable) ----------------------------------------------

def test_pseudo_inverse_projector_of_a_selection_is_the_unselected_axis():
    da = np.array([[2.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    pinv = pseudo_inverse(da)
    assert np.array_equal(pinv, [[0.5, 0.0], [0.0, 1.0 / 3.0], [0.0, 0.0]])
    assert np.array_equal(projector(da, pinv), np.diag([0.0, 0.0, 1.0]))


def test_weighted_inverse_by_hand_and_its_projector_annihilated_by_da():
    # Da = [1 1 0; 0 1 1], W = diag(1, 2, 4): Da W Da^T = [3 2; 2 6], inverse [6 -2; -2 3]/14;
    # W Da^T = [1 0; 2 2; 0 4]  ->  X = W Da^T (Da W Da^T)^-1 = [6 -2; 8 2; -8 12] / 14.
    da = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]])
    x = weighted_inverse(da, np.diag([1.0, 2.0, 4.0]))
    assert np.allclose(x, np.array([[6.0, -2.0], [8.0, 2.0], [-8.0, 12.0]]) / 14.0,
                       rtol=0, atol=1e-15)
    assert np.allclose(da @ x, np.eye(2), rtol=0, atol=1e-15)
    assert np.allclose(da @ projector(da, x), 0.0, rtol=0, atol=1e-15)


def test_weighted_inverse_is_the_least_weighted_norm_solution():
    rng = np.random.default_rng(3)
    da = rng.normal(size=(2, 3))
    a = rng.normal(size=(3, 3))
    weight = a @ a.T + 0.5 * np.eye(3)
    w = rng.normal(size=2)
    tau = weighted_inverse(da, weight) @ w
    null = np.linalg.svd(da)[2][2]        # the direction with Da null = 0
    cost = [(tau + s * null) @ np.linalg.solve(weight, tau + s * null)
            for s in (-1e-3, 0.0, 1e-3)]
    assert cost[1] < cost[0] and cost[1] < cost[2]


@pytest.mark.parametrize('kind', [{}, {'inverse': 'weighted', 'projector': 'dynamic'},
                                  {'inverse': 'weighted'}, {'projector': 'dynamic'}])
def test_null_space_term_leaves_the_nominal_task_acceleration_untouched(kind):
    nominal = _all_active('vertical').scaled(0.7)
    q = np.array([-1.2, 1.5, 2.0])
    qd = np.array([0.7, -1.1, 2.5])
    args = (q, qd, (0.21, 0.01), (0.05, -0.02), (0.3, 0.1), 1e-3)
    ns = NullSpace(kd=4.0, kp=2.0, posture=(0.0, 1.0, 1.0), **kind)
    with_ns = RobustController(nominal, Gains(), nullspace=ns).step(*args)
    model = ArmModel(nominal)
    da, b = model.decoupling(q, qd)
    # same task acceleration Da tau + b as the paper's law: v + dv (the robust term)
    plain = RobustController(nominal, Gains()).step(*args)
    assert np.allclose(da @ with_ns.tau, da @ plain.tau, rtol=0, atol=1e-10)
    # and the null-space term did something (r = 3 > m = 2)
    assert np.linalg.norm(with_ns.tau - plain.tau) > 1e-3


def test_null_space_option_is_inert_for_r_equal_m_with_the_pseudo_inverse():
    nominal = table1('vertical').scaled(0.7)
    q = initial_state(table1('vertical'))
    ctrl = RobustController(nominal, Gains(), nullspace=NullSpace(kd=5.0))
    ref = RobustController(nominal, Gains(), use_fast=False)
    assert not ctrl.uses_fast_path
    out = ctrl.step(q, [0.1, 0.2, 0.3], (0.2, 0.0), (0.0, 0.0), (0.0, 0.0), 1e-3)
    exp = ref.step(q, [0.1, 0.2, 0.3], (0.2, 0.0), (0.0, 0.0), (0.0, 0.0), 1e-3)
    assert np.allclose(out.tau, exp.tau, rtol=1e-12, atol=0)


def test_without_the_option_the_paper_arm_keeps_the_fast_path_and_its_torques_bitwise():
    nominal = table1('vertical').scaled(0.7)
    real = table1('vertical')
    a = RobustController(nominal, Gains())
    b = RobustController(nominal, Gains(), nullspace=None)
    assert a.uses_fast_path and b.uses_fast_path
    plant = Plant(real, seed=1, q0=initial_state(real))
    traj = CircleQuintic()
    for k in range(200):
        pdx, pdy, vx, vy, ax, ay = traj.sample_tuple(k * 1e-3)
        ta = a.step(plant.q, plant.qd, (pdx, pdy), (vx, vy), (ax, ay), 1e-3).tau
        tb = b.step(plant.q, plant.qd, (pdx, pdy), (vx, vy), (ax, ay), 1e-3).tau
        assert ta.tobytes() == tb.tobytes()
        plant.step(ta, 1e-3)


def test_null_space_options_are_validated_with_the_field_named():
    with pytest.raises(FreejointValueError, match='^kd:'):
        NullSpace(kd=-1.0)
    with pytest.raises(FreejointValueError, match='^inverse:'):
        NullSpace(inverse='left')
    with pytest.raises(FreejointValueError, match='^projector:'):
        NullSpace(projector='oblique')
    with pytest.raises(FreejointValueError, match='^posture:'):
        NullSpace(kp=1.0)
    with pytest.raises(FreejointValueError, match='^kd:'):
        RobustController(_all_active('vertical'), nullspace=NullSpace(kd=(1.0, 2.0)))
    with pytest.raises(FreejointValueError, match='^nullspace:'):
        RobustController(_all_active('vertical'), nullspace={'kd': 1.0})


# -- the fully actuated paper arm ---------------------------------------------

def test_paper_arm_with_every_joint_driven_is_a_valid_arm():
    arm = _all_active('vertical')
    assert arm.passive == () and arm.r == 3 and arm.active == (0, 1, 2)
    jac, maa = ArmModel(arm).effective([0.1, 0.2, 0.3])
    assert jac.shape == (2, 3) and maa.shape == (3, 3)


def test_fully_actuated_vertical_arm_tracks_with_null_space_damping():
    # 1.5 s of the circle from the paper's start: the damped arm stays within 2 mm and
    # its internal motion is slow; the measured figures over seeds 0-9 are in
    # docs/internal-motion.md.
    from freejoint_core.offline import run_case
    rec, _ = run_case('vertical', 'robust', 0, actuated='all', nullspace=NullSpace(kd=3.0),
                      duration=1.5)
    assert rec['diverged_at_s'] is None
    assert rec['max_mm'] < 2.0
    assert rec['variant'] == 'robust all+ns'


# -- equilibrium poses ----------------------------------------------------------

@pytest.mark.parametrize('branch', [1, -1])
def test_hanging_pose_puts_the_end_effector_on_the_point_with_zero_free_joint_torque(branch):
    params = table1('vertical')
    model = ArmModel(params)
    q = hanging_pose(params, (0.2, 0.0), branch)
    assert np.allclose(model.fk(q), [0.2, 0.0], rtol=0, atol=1e-12)
    assert abs(model.gravity_torque(q)[2]) < 1e-12
    assert math.isclose(math.remainder(float(np.sum(q)), 2 * math.pi), -math.pi / 2,
                        abs_tol=1e-12)
    # joint 3 straight above the end effector, one link length up
    assert np.allclose(ArmModel(params).fk([q[0], q[1], 0.0]) - [0.5 * math.cos(q[0] + q[1]),
                       0.5 * math.sin(q[0] + q[1])], [0.2, 0.5], rtol=0, atol=1e-12)


def test_general_equilibrium_solver_agrees_with_the_closed_form_and_zeroes_passive_gravity():
    params = table1('vertical')
    model = ArmModel(params)
    exact = hanging_pose(params, (0.2, 0.0))
    q = equilibrium_pose(model, (0.2, 0.0), exact + 0.2)
    assert np.allclose(q, exact, rtol=0, atol=1e-9)
    from freejoint_core.urdf import four_link_arm, FOUR_LINK_Q0
    four = ArmModel(four_link_arm('vertical').params)
    q4 = equilibrium_pose(four, (0.35, 0.25), FOUR_LINK_Q0)
    assert np.allclose(four.fk(q4), [0.35, 0.25], rtol=0, atol=1e-10)
    assert abs(four.gravity_torque(q4)[0]) < 1e-10


def test_equilibrium_pose_errors_name_the_argument():
    with pytest.raises(FreejointValueError, match='^model:'):
        equilibrium_pose(ArmModel(table1('horizontal')), (0.2, 0.0), [0.0, 0.0, 0.0])
    with pytest.raises(FreejointValueError, match='^p:'):
        hanging_pose(table1('vertical'), (3.0, 0.0))
    with pytest.raises(FreejointValueError, match='^params:'):
        hanging_pose(_all_active('vertical'), (0.2, 0.0))


# -- the free link's zero dynamics (r = m) -------------------------------------

def test_modulation_leaves_the_setpoint_alone_with_the_link_hanging_still():
    params = table1('vertical').scaled(0.7)
    mod = FreeLinkModulation(params)
    q = hanging_pose(table1('vertical'), (0.2, 0.0))
    for _ in range(3):
        p, v, a = mod.step(q, [0.0, 0.0, 0.0], (0.2, 0.0), (0.0, 0.0), (0.0, 0.0), 1e-3)
        assert np.array_equal(p, [0.2, 0.0]) and not np.any(v) and not np.any(a)


def test_modulation_pushes_the_end_effector_along_u3perp_against_the_link_rate():
    # theta3 = -90 deg (hanging), rate 2 rad/s: u3perp = (-sin, cos)(-pi/2) = (1, 0);
    # drive = k2 * 2 * (1, 0) = (0.4, 0) m/s^2 at k2 = 0.2, delta still 0.
    params = table1('vertical').scaled(0.7)
    mod = FreeLinkModulation(params, gains=(0.0, 0.2, 9.0, 6.0))
    q = hanging_pose(table1('vertical'), (0.2, 0.0))
    _, _, a = mod.step(q, [0.0, 0.0, 2.0], (0.2, 0.0), (0.0, 0.0), (0.0, 0.0), 1e-3)
    assert np.allclose(a, [0.4, 0.0], rtol=0, atol=1e-12)
    # the link equation J thdd = -m3 c3 u3perp . pdd: that acceleration slows it down
    assert -params.masses[2] * params.com[2] * a[0] < 0.0


def test_the_rest_gain_applies_only_once_the_setpoint_has_rested_rest_after():
    # Hanging, link rate 2 rad/s, delta 0 on every call (fresh state each tick, the rest
    # count carried): drive = k2 * 2 along (1, 0), k2 = 0.2 for the first 3 resting ticks
    # (3 ms < rest_after), then k2_rest = 1.0 -> 2.0 m/s^2; a moving tick restarts the count.
    params = table1('vertical').scaled(0.7)
    mod = FreeLinkModulation(params, k2_rest=1.0, rest_after=0.003)
    q = hanging_pose(table1('vertical'), (0.2, 0.0))

    def drive(moving=False):
        saved = mod.snapshot()
        mod.restore(((0.0, 0.0), (0.0, 0.0), None) + saved[3:])
        v = (1e-9, 0.0) if moving else (0.0, 0.0)
        return mod.step(q, [0.0, 0.0, 2.0], (0.2, 0.0), v, (0.0, 0.0), 1e-3)[2][0]

    assert [drive() for _ in range(5)] == pytest.approx([0.4, 0.4, 0.4, 2.0, 2.0], abs=1e-12)
    drive(moving=True)
    assert [drive() for _ in range(4)] == pytest.approx([0.4, 0.4, 0.4, 2.0], abs=1e-12)
    with pytest.raises(FreejointValueError, match='^rest_after:'):
        FreeLinkModulation(params, rest_after=-1.0)


def test_modulation_offset_stays_within_its_bound_for_any_link_motion():
    params = table1('vertical').scaled(0.7)
    mod = FreeLinkModulation(params, delta_max=0.002)
    assert mod.a_max == 4.0 and mod.delta_max == 0.002
    q = hanging_pose(table1('vertical'), (0.2, 0.0))
    worst = 0.0
    for k in range(6000):
        # a saturating drive, held 2 s (delta creeps up to its bound), then switching
        sign = 1.0 if k < 2000 else math.copysign(1.0, math.sin(k / 100.0))
        mod.step(q, [0.0, 0.0, 50.0 * sign], (0.2, 0.0), (0.0, 0.0), (0.0, 0.0), 1e-3)
        worst = max(worst, float(np.linalg.norm(mod.delta)))
    assert 0.95 * 0.002 < worst <= 0.002


def test_settle_mode_drives_only_in_the_first_window_of_a_rest_within_its_bound():
    # Horizontal: no quasi-static angle at rest, drive = k2 * rate along u3perp, saturated
    # at k3 * delta_max = 9 * 0.03 = 0.27 m/s^2; hanging pose, u3perp = (1, 0).
    params = table1('horizontal').scaled(0.7)
    mod = FreeLinkModulation(params, mode='settle', delta_max=0.03, settle_window=0.005)
    assert mod.a_max == pytest.approx(0.27) and mod.delta_max == pytest.approx(0.03)
    q = hanging_pose(table1('vertical'), (0.2, 0.0))
    moving = ((0.2, 0.0), (20.0, 0.0), (0.0, 0.0))      # one tick: 2 cm, a task (> 1 cm)
    resting = ((0.2, 0.0), (0.0, 0.0), (0.0, 0.0))
    # tracking: no drive (and delta 0 stays 0)
    _, _, a = mod.step(q, [0.0, 0.0, 1.0], *moving, 1e-3)
    assert np.array_equal(a, [0.0, 0.0])
    # resting: 1 rad/s -> 0.2 m/s^2 (below the saturation); 3 rad/s -> 0.27 (saturated)
    _, _, a = mod.step(q, [0.0, 0.0, 1.0], *resting, 1e-3)
    assert a[0] == pytest.approx(0.2, abs=1e-12) and a[1] == pytest.approx(0.0, abs=1e-12)
    accel, expected = [], []
    for k in range(6):
        x, u = mod.delta[0], mod.delta_dot[0]
        accel.append(mod.step(q, [0.0, 0.0, 3.0], *resting, 1e-3)[2][0])
        # 4 more resting ticks in the 5-ms window: saturated drive, filter (9, 6); then
        # the window is over: no drive, the return gains (400, 40) pull back
        expected.append(0.27 - 9.0 * x - 6.0 * u if k < 4 else -400.0 * x - 40.0 * u)
    assert accel == pytest.approx(expected, rel=1e-12)
    assert accel[3] > 0.2 and accel[4] < 0.0
    x, u = mod.delta[0], mod.delta_dot[0]
    _, _, a = mod.step(q, [0.0, 0.0, 3.0], *resting, 1e-3)
    assert a[0] == pytest.approx(-400.0 * x - 40.0 * u, rel=1e-12)


def test_settle_mode_shift_stays_within_its_bound_without_clipping_and_returns():
    # A link turning 3 rad/s forever: 0.6 s of drive leaves |delta| <= 3 cm by the filter
    # alone (critically damped: no overshoot of its DC gain), 0.4 s later under 0.1 mm.
    params = table1('horizontal').scaled(0.7)
    mod = FreeLinkModulation(params, mode='settle', delta_max=0.03)
    q = [0.3, 1.5, 2.0]
    rest = ((0.2, 0.0), (0.0, 0.0), (0.0, 0.0))
    mod.step(q, [0.0, 0.0, 3.0], (0.2, 0.0), (20.0, 0.0), (0.0, 0.0), 1e-3)  # a task: 2 cm
    worst = 0.0
    for k in range(1000):
        th = 3.0 * k * 1e-3           # the link's angle turning: u3perp turns with it
        mod.step([q[0], q[1], q[2] + th], [0.0, 0.0, 3.0], *rest, 1e-3)
        worst = max(worst, float(np.linalg.norm(mod.delta)))
        if k == 599:
            at_end = float(np.linalg.norm(mod.delta))
    assert 1e-3 < at_end and worst <= 0.03
    assert float(np.linalg.norm(mod.delta)) < 1e-4
    with pytest.raises(FreejointValueError, match='^settle_window:'):
        FreeLinkModulation(params, mode='settle', settle_window=0.0)


def test_settle_mode_leaves_a_rest_before_any_task_alone_then_settles_the_rest_after_one():
    # A held start point (the planner's, before the first plan) with the rotor turning:
    # nothing to settle - driven, the shift would start the first task off its path.
    params = table1('horizontal').scaled(0.7)
    mod = FreeLinkModulation(params, mode='settle', delta_max=0.03)
    q = [0.3, 1.5, 2.0]
    rest = ((0.2, 0.0), (0.0, 0.0), (0.0, 0.0))
    for _ in range(300):
        p, v, a = mod.step(q, [0.0, 0.0, 3.0], *rest, 1e-3)
        assert (tuple(p), tuple(v), tuple(a)) == ((0.2, 0.0), (0.0, 0.0), (0.0, 0.0))
    # A resume blend's sub-millimetre motion (0.1 mm) is not a task: still nothing.
    for _ in range(10):
        mod.step(q, [0.0, 0.0, 3.0], (0.2, 0.0), (0.01, 0.0), (0.0, 0.0), 1e-3)
    for _ in range(5):
        assert np.array_equal(mod.step(q, [0.0, 0.0, 3.0], *rest, 1e-3)[2], [0.0, 0.0])
    mod.step(q, [0.0, 0.0, 3.0], (0.2, 0.0), (10.0, 0.0), (0.0, 0.0), 1e-3)   # a task: 1 cm
    mod.step(q, [0.0, 0.0, 3.0], *rest, 1e-3)
    assert np.linalg.norm(mod.delta_dot) > 0.0                  # its rest is settled
    saved = mod.snapshot()
    mod.reset()                                                 # e.g. after a brake
    mod.step(q, [0.0, 0.0, 3.0], *rest, 1e-3)
    assert np.array_equal(mod.delta, [0.0, 0.0])
    mod.restore(saved)
    mod.step(q, [0.0, 0.0, 3.0], *rest, 1e-3)
    assert np.linalg.norm(mod.delta) > 0.0


def test_the_horizontal_stabilised_options_settle_the_free_rotor_in_the_rests():
    from freejoint_core.circles import HORIZONTAL_SETTLE, run_circles, stabilised_options
    assert stabilised_options('horizontal') == {'stabilise': HORIZONTAL_SETTLE}
    records, _ = run_circles('horizontal', 'robust', 0, circles=2, rest=1.0,
                             **stabilised_options('horizontal'))
    paper, _ = run_circles('horizontal', 'robust', 0, circles=2, rest=1.0)
    # circle 1 is the paper's (no rest before it); the rest after it slows the link
    assert records[0]['max_mm'] == paper[0]['max_mm']
    assert abs(records[1]['free_rate_dps']) != abs(paper[1]['free_rate_dps'])
    assert all(r['max_mm'] <= 1.7 for r in records)


def test_modulation_rejects_bad_options_naming_them():
    params = table1('vertical')
    with pytest.raises(FreejointValueError, match='^gains:'):
        FreeLinkModulation(params, gains=(0.0, 0.2, 9.0, 1.0))     # k4^2 < 4 k3
    with pytest.raises(FreejointValueError, match='^delta_max:'):
        FreeLinkModulation(params, delta_max=0.0)
    with pytest.raises(FreejointValueError, match='^mode:'):
        FreeLinkModulation(params, mode='sometimes')
    with pytest.raises(FreejointValueError, match='^params:'):
        FreeLinkModulation(_all_active('vertical'))


def _link_spin(q, rate):
    """Joint rates turning the last link at ``rate`` about the still end effector."""
    null = np.linalg.svd(ArmModel(table1('vertical')).jacobian(q))[2][2]
    return rate * null / null.sum()


def _hold_swing(modulation, seconds=2.5):
    """Hold the end effector at (0.2, 0), the hanging link given 3 rad/s; final swing."""
    real = table1('vertical')
    q0 = hanging_pose(real, (0.2, 0.0))
    plant = Plant(real, seed=0, q0=q0, qd0=_link_spin(q0, 3.0))
    ctrl = RobustController(real.scaled(0.7), Gains())
    for _ in range(int(round(seconds / 1e-3))):
        sp = ((0.2, 0.0), (0.0, 0.0), (0.0, 0.0))
        if modulation is not None:
            sp = modulation.step(plant.q, plant.qd, *sp, 1e-3)
        plant.step(ctrl.step(plant.q, plant.qd, *sp, 1e-3).tau, 1e-3)
    return math.degrees(free_link_swing(real, plant.q, plant.qd))


def test_swinging_free_link_keeps_swinging_under_the_paper_law_and_settles_when_damped():
    q0 = hanging_pose(table1('vertical'), (0.2, 0.0))
    start = math.degrees(free_link_swing(table1('vertical'), q0, _link_spin(q0, 3.0)))
    assert 20.0 < start < 25.0     # acos(1 - J_eff 9 / (2 m3 c3 g)) = 21.5 deg
    undamped = _hold_swing(None)
    damped = _hold_swing(FreeLinkModulation(table1('vertical').scaled(0.7), delta_max=0.01))
    assert undamped > 20.0          # (the 70 % model even pumps it up slowly)
    assert damped < 12.0            # measured 9.6 deg: the 10-mm bound limits the rate


def test_swing_of_a_hanging_link_at_rest_is_zero_and_revolving_is_pi():
    real = table1('vertical')
    q = hanging_pose(real, (0.2, 0.0))
    assert free_link_swing(real, q, [0.0, 0.0, 0.0]) == pytest.approx(0.0, abs=1e-6)
    assert free_link_swing(real, q, [0.0, 0.0, 50.0]) == math.pi


# -- the r > m arm that diverges without the option -----------------------------

def _four_link_hold_circle(nullspace, ticks):
    """Run the 4-link vertical example from a static equilibrium folded the other way."""
    from freejoint_core.mujoco_plant import MujocoPlant
    from freejoint_core.pin_model import PinArmModel
    from freejoint_core.urdf import four_link_arm, FOUR_LINK_CIRCLE
    arm = four_link_arm('vertical')
    traj = CircleQuintic(centre=FOUR_LINK_CIRCLE['centre'], radius=FOUR_LINK_CIRCLE['radius'])
    q0 = equilibrium_pose(ArmModel(arm.params), traj.sample(0.0)[0],
                          np.radians([-120.0, 150.0, 55.0, -55.0]))
    plant = MujocoPlant(arm, dist_bound=0.5, seed=0, q0=q0)
    model = PinArmModel(arm, 0.7)
    ctrl = RobustController(model.params, Gains(), model=model, nullspace=nullspace)
    worst = 0.0
    for k in range(ticks):
        pdx, pdy, vx, vy, ax, ay = traj.sample_tuple(k * 1e-3)
        out = ctrl.step(plant.q, plant.qd, (pdx, pdy), (vx, vy), (ax, ay), 1e-3)
        worst = max(worst, math.hypot(out.p[0] - pdx, out.p[1] - pdy))
        if worst > 0.05 or not np.all(np.isfinite(out.tau)):
            return k, worst, plant.qd
        plant.step(out.tau, 1e-3)
    return ticks, worst, plant.qd


def test_four_link_vertical_diverges_without_null_space_damping_and_holds_with_it():
    lost_at, _, _ = _four_link_hold_circle(None, 1000)
    assert lost_at < 500            # measured: lost 0.2 s into the circle
    ticks, worst, qd = _four_link_hold_circle(NullSpace(kd=5.0), 1500)
    assert ticks == 1500 and worst < 5e-3
    assert np.all(np.abs(qd) < 20.0)


# -- the circles runner ----------------------------------------------------------

def test_circles_runner_writes_one_record_per_circle_with_its_rest():
    from freejoint_core.circles import run_circles
    recs, _ = run_circles('horizontal', 'exact', 0, circles=2, rest=0.5, hold=0.2)
    assert [r['circle'] for r in recs] == [1, 2]
    assert [r['rest_s'] for r in recs] == [0.5, 0.2]
    for r in recs:
        assert {'case', 'variant', 'seed', 'circle', 'rms_mm', 'max_mm', 'effort_peak',
                'swing_deg', 'diverged_at_s'} <= set(r)
        assert len(r['effort_peak']) == 2 and r['diverged_at_s'] is None
        assert r['swing_deg'] is None          # no gravity: no hanging angle to swing about
        assert r['max_mm'] < 1.0


def test_offline_cli_takes_circles_rests_and_the_stabilisation_flag(tmp_path, capsys):
    from freejoint_core import offline
    args = offline._parse(['--circles', '3', '--rest', '1.0', '--stabilise', '--actuated',
                           'all', '--nullspace-kd', '5'])
    assert (args.circles, args.rest, args.stabilise) == (3, 1.0, True)
    assert offline._internal_options(args)['nullspace'] == NullSpace(kd=5.0)
    out = tmp_path / 'circles.json'
    assert offline.main(['--circles', '1', '--seeds', '1', '--cases', 'horizontal',
                         '--out', str(out)]) == 0
    import json
    recs = json.loads(out.read_text())
    assert len(recs) == 1 and recs[0]['circle'] == 1 and recs[0]['case'] == 'horizontal'
    assert 'rms mean / worst' in capsys.readouterr().out
