"""Internal-motion stabilisation: null-space term, weighted inverse, equilibrium poses."""

import dataclasses
import math

from freejoint_core.arm import ArmModel, table1
from freejoint_core.control import Gains, RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import (equilibrium_pose, hanging_pose, NullSpace, projector,
                                     pseudo_inverse, weighted_inverse)
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
