"""Spatial arms from URDFs: model terms, law, plan-time checks, a short run."""

import re

from freejoint_core.control import Gains, STATUS_TORQUE_LIMITED
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import NullSpace
from freejoint_core.spatial_law import gravity_carrying_free_joint, SpatialGains, SpatialLaw
from freejoint_core.spatial_law import task_conditioning
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_offline import CASES, circle, circle_axes, run_case
import mujoco
import numpy as np
import pinocchio as pin
import pytest

UR5_PLAN = np.array(CASES['ur5_wrist2'][2])
PANDA_PLAN = np.array(CASES['panda_j7'][2])


def _states(n, count, seed):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-2.0, 2.0, n), rng.uniform(-1.0, 1.0, n)) for _ in range(count)]


def test_ur5_mass_matrix_and_bias_equal_mujocos_import_of_the_same_urdf():
    arm = known_arm('ur5', ['wrist_2_joint'])
    text = re.sub(r'<(visual|collision)>.*?</\1>', '', arm.urdf, flags=re.S)
    mjm = mujoco.MjModel.from_xml_string(text)
    mjm.opt.gravity[:] = (0.0, 0.0, -9.81)
    mjd = mujoco.MjData(mjm)
    assert [mjm.joint(i).name for i in range(mjm.njnt)] == list(arm.joint_names)
    for q, qd in _states(arm.n, 5, 1):
        mjd.qpos[:], mjd.qvel[:] = q, qd
        mujoco.mj_forward(mjm, mjd)
        mass = np.zeros((arm.n, arm.n))
        mujoco.mj_fullM(mjm, mjd, mass)
        terms = arm.terms(q, qd)
        np.testing.assert_allclose(terms.M, mass, atol=1e-10)
        np.testing.assert_allclose(terms.h, mjd.qfrc_bias, atol=1e-10)
        np.testing.assert_allclose(terms.Minv @ terms.M, np.eye(arm.n), atol=1e-9)


@pytest.mark.parametrize('name,free', [('ur5', 'wrist_2_joint'), ('panda', 'panda_joint7')])
def test_pose_jacobian_and_jdot_qdot_equal_finite_differences_of_the_placement(name, free):
    arm = known_arm(name, [] if name == 'ur5' else [free], m=6)
    h = 1e-6
    for q, qd in _states(arm.n, 3, 2):
        terms = arm.terms(q, qd)
        p0, r0 = arm.placement(q)
        for j in range(arm.n):
            dq = np.zeros(arm.n)
            dq[j] = h
            pp, rp = arm.placement(q + dq)
            pm, rm = arm.placement(q - dq)
            np.testing.assert_allclose(terms.J[:3, j], (pp - pm) / (2 * h), atol=1e-7)
            omega = (pin.log3(rp @ r0.T) - pin.log3(rm @ r0.T)) / (2 * h)
            np.testing.assert_allclose(terms.J[3:, j], omega, atol=1e-7)
        # Jdot qd: the derivative of J(q) qd along q + t qd
        jp = arm.terms(q + h * qd, qd).J
        jm = arm.terms(q - h * qd, qd).J
        np.testing.assert_allclose(terms.jdqd, (jp - jm) @ qd / (2 * h), atol=1e-6)


@pytest.mark.parametrize('name,free', [('ur5', 'wrist_2_joint'), ('panda', 'panda_joint7')])
def test_decoupling_predicts_the_task_acceleration_of_aba_with_the_free_joint_unforced(
        name, free):
    arm = known_arm(name, [free])
    rng = np.random.default_rng(3)
    for q, qd in _states(arm.n, 3, 4):
        terms = arm.terms(q, qd)
        da, b, maa = arm.decoupling(terms)
        tau_a = rng.uniform(-5.0, 5.0, arm.r)
        tau = np.zeros(arm.n)
        tau[list(arm.active)] = tau_a
        qdd = arm.forward_dynamics(q, qd, tau)
        np.testing.assert_allclose(da @ tau_a + b, terms.J @ qdd + terms.jdqd, atol=1e-8)
        a, p = list(arm.active), list(arm.passive)
        mm = terms.M
        schur = mm[np.ix_(a, a)] - mm[np.ix_(a, p)] @ np.linalg.solve(mm[np.ix_(p, p)],
                                                                      mm[np.ix_(p, a)])
        np.testing.assert_allclose(maa, schur, atol=1e-9)


def test_chain_locks_the_panda_fingers_and_reads_the_urdf_limits():
    arm = known_arm('panda', ['panda_joint7'])
    assert arm.joint_names == tuple(f'panda_joint{i}' for i in range(1, 8))
    assert (arm.n, arm.r, arm.passive) == (7, 6, (6,))
    np.testing.assert_array_equal(arm.effort, [87, 87, 87, 87, 12, 12, 12])
    assert arm.upper[3] == pytest.approx(-0.0698)
    ur5 = known_arm('ur5', ['wrist_2_joint'])
    np.testing.assert_array_equal(ur5.effort, [150, 150, 150, 28, 28, 28])


def test_bad_links_and_joints_are_named_in_the_error():
    with pytest.raises(FreejointValueError, match='tip_link'):
        known_arm('ur5').__class__(known_arm('ur5').urdf, 'base_link', 'no_such_link')
    with pytest.raises(FreejointValueError, match='passive'):
        known_arm('ur5', ['no_joint'])
    with pytest.raises(FreejointValueError, match='m:'):
        known_arm('ur5', m=4)


def test_spatial_gains_are_sized_by_m_and_the_planar_defaults_are_unchanged():
    assert SpatialGains(task_dim=3).K == (100.0,) * 3
    assert SpatialGains(task_dim=6).Lambda == (50.0,) * 6
    assert Gains().K == (100.0, 100.0)
    with pytest.raises(FreejointValueError, match='K'):
        SpatialGains(task_dim=3, K=(1.0, 2.0))


@pytest.mark.parametrize('name,free,m', [('panda', ['panda_joint7'], 3), ('ur5', [], 6)])
def test_conditioning_gives_the_same_verdicts_for_the_arm_ten_times_heavier(name, free, m):
    light = known_arm(name, free, m=m)
    heavy = known_arm(name, free, m=m)
    for j in range(1, heavy.model.njoints):       # every mass and inertia x10, same levers
        body = heavy.model.inertias[j]
        heavy.model.inertias[j] = pin.Inertia(10.0 * body.mass, body.lever, 10.0 * body.inertia)
    assert heavy.terms(PANDA_PLAN[:heavy.n], np.zeros(heavy.n)).M[0, 0] == pytest.approx(
        10.0 * light.terms(PANDA_PLAN[:heavy.n], np.zeros(heavy.n)).M[0, 0])
    kappa_min = SpatialGains(task_dim=m).kappa_min
    rng = np.random.default_rng(5)
    for _ in range(50):
        q = rng.uniform(np.maximum(light.lower, -3.0), np.minimum(light.upper, 3.0))
        da1, _, m1 = light.decoupling(light.terms(q, np.zeros(light.n)))
        da2, _, m2 = heavy.decoupling(heavy.terms(q, np.zeros(light.n)))
        k1 = task_conditioning(da1, m1, 0.9)[0]
        k2 = task_conditioning(da2, m2, 0.9)[0]
        assert k2 == pytest.approx(k1, rel=1e-7, abs=1e-9)
        assert (k1 < kappa_min) == (k2 < kappa_min)
        assert 0.0 <= k1 <= 1.0


def test_conditioning_is_one_for_an_isotropic_task_and_zero_for_a_rank_deficient_one():
    assert task_conditioning(np.eye(3), np.eye(3), 0.5)[0] == pytest.approx(1.0)
    da = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [1.0, 1.0, 0.0, 0.0]])
    assert task_conditioning(da, np.eye(4), 0.5)[0] == pytest.approx(0.0, abs=1e-7)
    # a length unit changes nothing once the reach is given in the same unit
    da6 = np.random.default_rng(0).normal(size=(6, 6))
    scaled = da6.copy()
    scaled[:3] *= 1000.0                      # position rows in mm/s^2
    assert task_conditioning(scaled, np.eye(6), 900.0)[0] == pytest.approx(
        task_conditioning(da6, np.eye(6), 0.9)[0])


@pytest.mark.parametrize('name,plan,free', [('ur5', UR5_PLAN, 'elbow_joint'),
                                            ('panda', PANDA_PLAN, 'panda_joint4')])
def test_a_free_joint_that_must_carry_gravity_is_refused_with_one_line(name, plan, free):
    arm = known_arm(name, [free])
    pose, why = gravity_carrying_free_joint(arm, plan)
    assert pose is None
    assert '\n' not in why and why.startswith(f'free joint {free} must carry gravity')


@pytest.mark.parametrize('name,plan,free', [('ur5', UR5_PLAN, 'wrist_2_joint'),
                                            ('panda', PANDA_PLAN, 'panda_joint7')])
def test_a_wrist_free_joint_gets_a_rest_pose_with_the_tip_in_place(name, plan, free):
    arm = known_arm(name, [free])
    pose, why = gravity_carrying_free_joint(arm, plan)
    assert why is None
    np.testing.assert_allclose(arm.fk(pose), arm.fk(plan), atol=1e-6)
    assert abs(arm.gravity_torque(pose)[arm.passive[0]]) < 1e-6


def test_torques_stay_within_the_urdf_effort_limits_for_a_far_setpoint():
    arm = known_arm('ur5', ['wrist_2_joint'])
    law = SpatialLaw(arm.nominal(0.7))
    out = law.step(UR5_PLAN, np.zeros(6), arm.fk(UR5_PLAN) + 0.3, np.zeros(3), np.zeros(3),
                   5e-4)
    assert out.status & STATUS_TORQUE_LIMITED
    assert np.all(np.abs(out.tau) <= arm.effort[list(arm.active)])


def test_circle_starts_and_ends_at_rest_at_the_start_point_in_a_vertical_plane():
    p0 = np.array([0.6, 0.1, 0.25])
    for t in (0.0, 5.0, 7.0):
        pos, vel, acc = circle(p0, 0.1, t, 5.0)
        np.testing.assert_allclose(pos, p0, atol=1e-12)
        np.testing.assert_allclose(vel, 0.0, atol=1e-12)
    pts = np.array([circle(p0, 0.1, t, 5.0)[0] for t in np.linspace(0, 5, 41)])
    assert np.allclose(np.linalg.norm(pts - (pts.max(0) + pts.min(0)) / 2, axis=1), 0.1)
    across = np.array([-p0[1], p0[0], 0.0])
    np.testing.assert_allclose((pts - p0) @ np.cross(across, [0, 0, 1]), 0.0, atol=1e-12)


def test_ur5_with_wrist_2_free_tracks_within_3_mm_for_the_first_half_second():
    rec = run_case('ur5_wrist2', 0, t_stop=0.5)
    assert not rec['diverged']
    assert rec['max_mm'] < 3.0
    assert rec['tau_ratio'] <= 1.0 and rec['vel_ratio'] < 1.0 and rec['vel_ratio_free'] < 1.0


def test_null_space_terms_leave_the_nominal_task_acceleration_unchanged():
    arm = known_arm('panda', ['panda_joint7'])
    nominal = arm.nominal(0.7)
    q, qd = PANDA_PLAN, np.linspace(-0.3, 0.3, 7)
    p_d = arm.fk(q) + 0.001
    plain = SpatialLaw(nominal).step(q, qd, p_d, np.zeros(3), np.zeros(3), 5e-4)
    damped = SpatialLaw(nominal, nullspace=NullSpace(kd=20.0, inverse='weighted',
                                                     projector='dynamic'),
                        free_damping=10.0).step(q, qd, p_d, np.zeros(3), np.zeros(3), 5e-4)
    assert not (plain.status | damped.status) & STATUS_TORQUE_LIMITED
    assert np.linalg.norm(damped.tau - plain.tau) > 1e-3
    da, _, _ = nominal.decoupling(nominal.terms(q, qd))
    np.testing.assert_allclose(da @ damped.tau, da @ plain.tau, atol=1e-9)


def test_pose_task_error_is_zero_at_the_measured_pose_and_six_rows_long():
    arm = known_arm('panda', [], m=6)
    law = SpatialLaw(arm.nominal(0.7))
    pos, rot = arm.placement(PANDA_PLAN)
    out = law.step(PANDA_PLAN, np.zeros(7), pos, np.zeros(6), np.zeros(6), 5e-4, rot_d=rot)
    assert out.e.shape == (6,)
    np.testing.assert_allclose(out.e, 0.0, atol=1e-12)
    assert np.all(np.isfinite(out.tau)) and out.tau.shape == (7,)
    with pytest.raises(FreejointValueError, match='rot_d'):
        law.step(PANDA_PLAN, np.zeros(7), pos, np.zeros(6), np.zeros(6), 5e-4)


def test_holding_the_panda_hand_orientation_with_joint_7_free_is_singular_everywhere():
    # Nothing but the free joint turns the hand about its own axis (its mass lies on the
    # axis): the orientation row along that axis is out of reach of every active torque.
    arm = known_arm('panda', ['panda_joint7'], m=6)
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = rng.uniform(arm.lower, arm.upper)
        da, _, maa = arm.decoupling(arm.terms(q, np.zeros(7)))
        assert task_conditioning(da, maa, 1.0)[0] < 1e-6 < SpatialGains(task_dim=6).kappa_min
    with pytest.raises(FreejointValueError, match='cannot drive m = 6'):
        known_arm('ur5', ['wrist_2_joint'], m=6)


def test_a_seeded_run_repeats_exactly_and_another_seed_differs():
    def metrics(seed):
        rec = run_case('panda_j7', seed, t_stop=0.05)
        return {k: v for k, v in rec.items() if k != 'tick_us'}
    assert metrics(3) == metrics(3)
    assert metrics(3) != metrics(4)


def test_the_default_planes_own_normal_gives_the_default_circle():
    # p0 = (0.5, 0.2, 0.3): across the base-to-tip line (-0.2, 0.5, 0)/|.|, e1 = -that,
    # e2 = z; the plane's normal e1 x e2 = (-0.5, -0.2, 0)/|.|, towards the base
    # (hand-derived)
    p0 = np.array([0.5, 0.2, 0.3])
    e1, e2 = circle_axes(p0)
    assert e1 == pytest.approx(np.array([0.2, -0.5, 0.0]) / np.hypot(0.2, 0.5), abs=1e-15)
    assert e2.tolist() == [0.0, 0.0, 1.0]
    n = np.array([-0.5, -0.2, 0.0])
    f1, f2 = circle_axes(p0, 3.0 * n)                 # any length
    assert f1 == pytest.approx(e1, abs=1e-15) and f2 == pytest.approx(e2, abs=1e-15)
    for t in (0.0, 1.3, 2.5, 4.9, 6.0):
        for got, want in zip(circle(p0, 0.1, t, 5.0, n), circle(p0, 0.1, t, 5.0)):
            assert got == pytest.approx(want, abs=1e-15)


def test_a_circle_in_a_horizontal_plane_keeps_its_height_and_radius():
    p0 = np.array([0.5, 0.2, 0.3])
    e1, e2 = circle_axes(p0, (0.0, 0.0, 2.0))
    assert e1 == pytest.approx(np.array([0.2, -0.5, 0.0]) / np.hypot(0.2, 0.5), abs=1e-15)
    assert e2 == pytest.approx(np.cross([0.0, 0.0, 1.0], e1), abs=1e-15)
    centre = p0 - 0.1 * e1
    assert circle(p0, 0.1, 0.0, 5.0, (0, 0, 1))[0] == pytest.approx(p0, abs=1e-15)
    for t in np.linspace(0.0, 5.0, 11):
        pos, vel, acc = circle(p0, 0.1, t, 5.0, (0, 0, 1))
        assert pos[2] == pytest.approx(0.3, abs=1e-15) and vel[2] == acc[2] == 0.0
        assert np.linalg.norm(pos - centre) == pytest.approx(0.1, abs=1e-14)
    # a normal along the default e1 (in the default plane's x direction): e1 from z
    f1, f2 = circle_axes(p0, e1)
    assert f1 == pytest.approx([0.0, 0.0, 1.0], abs=1e-15)


@pytest.mark.parametrize('normal', [(0.0, 0.0, 0.0), (1.0, float('nan'), 0.0), (1.0, 0.0)])
def test_a_bad_plane_normal_is_refused_naming_it(normal):
    with pytest.raises(FreejointValueError, match='^normal: expected 3 finite numbers'):
        circle_axes(np.array([0.5, 0.2, 0.3]), normal)
