"""A spatial arm from its URDF alone: continuous joints, the gain rule, refusals, init -> twin."""

import math
import os

from freejoint_control.params import SCHEMA as CONTROLLER
from freejoint_core.arm_gains import BETA, CHECK_DT, drivetrain_damping, joint_inertia
from freejoint_core.arm_gains import KD_REF, kernel_basis, SPEED_SHARE, Z
from freejoint_core.arm_gains import mode_steps, nullspace_gains, nullspace_inertia
from freejoint_core.arm_gains import POSTURE_TIME, rule
from freejoint_core.errors import FreejointValueError
from freejoint_core.spatial_model import robot_data_dir, SpatialArm
from freejoint_planner.spatial_planning import check_spatial_plan, too_stiff
from freejoint_tools.arm_init import arm_files, ArmInitError, free_damping, tip_leaf
from freejoint_tools.harness import load_source
import numpy as np
import pinocchio as pin
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
JACO = ('kinova_description/robots/kinova.urdf', 'j2s6s200_link_base',
        'j2s6s200_end_effector')
UR10 = 'ur_description/urdf/ur10_robot.urdf'
# the UR10's start posture of fj arm init (wrist_2 free; its tip 0.876 m ahead, 0.39 m up)
UR10_Q0 = (3.22795902246596, -2.248345377316516, -1.5092603933208404, -6.075275075068047,
           3.430093270749557, 5.150823090436277)


def _jaco(passive=('j2s6s200_joint_6',)):
    path, base, tip = JACO
    return SpatialArm(os.path.join(robot_data_dir(), path), base, tip, passive)


def test_the_rule_by_hand_a_joints_inertia_per_2_ms_capped_at_20():
    # kd_i = min(20, 1 x I_i / 0.002)
    assert (BETA, CHECK_DT, KD_REF, POSTURE_TIME) == (1.0, 2e-3, 20.0, 2.0)
    assert rule([0.0005, 0.02, 0.518, 4.0]) == pytest.approx([0.25, 10.0, 20.0, 20.0],
                                                             rel=1e-12)


def test_one_damping_for_all_decays_each_mode_at_kd_over_its_inertia():
    arm = _jaco().nominal(0.7)
    q = np.array([0.3, 2.9, 1.3, -4.1, 1.4, 0.2])
    steps, joints = mode_steps(arm, q, 4.0)
    assert steps == pytest.approx(np.sort(0.002 * 4.0 / nullspace_inertia(arm, q))[::-1],
                                  rel=1e-9)
    assert all(name in arm.joint_names for name in joints)


def test_the_rules_gains_keep_every_mode_from_reversing_in_one_check_step():
    arm = _jaco().nominal(0.7)
    q = np.array([0.3, 2.9, 1.3, -4.1, 1.4, 0.2])
    kd, kp, inertia = nullspace_gains(arm, q)
    assert kp == 10.0 and inertia == pytest.approx(joint_inertia(arm, q))
    assert mode_steps(arm, q, kd)[0][0] <= 1.0 + 1e-9
    raw = rule(inertia)
    scale = max(1.0, mode_steps(arm, q, raw)[0][0])
    assert kd == pytest.approx(raw / scale, rel=1e-12)


def test_kernel_basis_of_a_hand_matrix_is_orthonormal_and_annihilated():
    da = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
    z = kernel_basis(da)
    assert z.shape == (3, 1)
    assert np.allclose(np.abs(z[:, 0]), [0.0, math.sqrt(0.5), math.sqrt(0.5)])
    assert np.allclose(da @ z, 0.0)


def test_null_space_inertia_is_that_of_the_motions_that_leave_the_tip_still():
    arm = _jaco().nominal(0.7)
    q = np.array([0.3, 2.9, 1.3, -4.1, 1.4, 0.2])
    vals = nullspace_inertia(arm, q)
    assert vals.shape == (arm.r - 3,) == (2,)
    # independent: the least kinetic energy of unit active rates that move the tip by 0
    terms = arm.terms(q, np.zeros(arm.n))
    da, _, maa = arm.decoupling(terms)
    z = kernel_basis(da @ maa)
    rng = np.random.default_rng(0)
    ratios = []
    for _ in range(2000):
        v = z @ rng.normal(size=z.shape[1])
        v /= np.linalg.norm(v)
        assert np.linalg.norm(da @ maa @ v) < 1e-9
        ratios.append(v @ maa @ v)
    assert min(ratios) >= vals[0] * (1 - 1e-9) and min(ratios) < vals[0] * 1.01


def test_continuous_joints_are_angles_without_position_limits_and_the_urdf_limits():
    arm = _jaco()
    assert arm.continuous == ('j2s6s200_joint_1', 'j2s6s200_joint_4', 'j2s6s200_joint_6')
    assert arm.n == 6 and arm.model.nq == 6
    assert np.all(np.isinf(arm.lower[[0, 3, 5]])) and np.all(np.isinf(arm.upper[[0, 3, 5]]))
    # the URDF's numbers (kinova.urdf): joint_2 0.820304748437..5.46288055874, 80 N m
    assert arm.lower[1] == 0.820304748437 and arm.upper[1] == 5.46288055874
    assert arm.effort.tolist() == [40.0, 80.0, 40.0, 20.0, 20.0, 20.0]
    assert arm.velocity[0] == 0.628318530718 and arm.velocity[5] == 0.837758040957


def test_continuous_joints_as_angles_equal_pinocchios_cos_sin_model():
    arm = _jaco(())
    full = pin.buildModelFromUrdf(os.path.join(robot_data_dir(), JACO[0]))
    data = full.createData()
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-3.0, 3.0, 6)
        q[[1, 2, 4]] = rng.uniform(1.0, 5.0, 3)
        x = []
        for j in range(1, full.njoints):
            x += [math.cos(q[j - 1]), math.sin(q[j - 1])] if full.joints[j].nq == 2 \
                else [q[j - 1]]
        x = np.array(x)
        pin.framesForwardKinematics(full, data, x)
        tip = data.oMf[full.getFrameId(JACO[2])].translation
        assert np.allclose(arm.fk(q), tip, atol=1e-12)
        assert np.allclose(arm.terms(q, np.zeros(6)).M, pin.crba(full, data, x), atol=1e-12)


def test_the_tip_is_the_deepest_link_of_moving_joints():
    with open(os.path.join(robot_data_dir(), UR10)) as fh:
        assert tip_leaf(fh.read(), 'world') in ('tool0', 'ee_link')


def test_a_too_stiff_damping_is_refused_naming_the_joint_and_the_numbers():
    arm = SpatialArm(os.path.join(robot_data_dir(), UR10), 'world', 'tool0',
                     ['wrist_2_joint']).nominal(0.7)
    q = np.array(UR10_Q0)
    why = too_stiff(arm, q, 20.0)
    assert why.startswith('null-space damping too stiff for joint wrist_3_joint: '
                          'nullspace_kd 20 N m s/rad on its effective inertia ')
    inertia = joint_inertia(arm, q)[-1]
    steps = mode_steps(arm, q, 20.0)[0]
    assert f'{inertia:.3g} kg m^2' in why and f'removes {steps[0]:.3g} x' in why
    assert f'gives it {inertia / 0.002:.3g}' in why
    assert too_stiff(arm, q, nullspace_gains(arm, q)[0]) == ''
    verdict = check_spatial_plan(arm, np.array(UR10_Q0), np.zeros(6), 0.1, 5.0, 1.0, 5.0,
                                 kd=20.0, kp=10.0)
    assert 'too stiff for joint wrist_3_joint' in verdict.reason


def test_arm_init_refuses_a_free_joint_off_the_chain_and_a_missing_file(tmp_path):
    with pytest.raises(FreejointValueError, match="passive: 'nope' is not a joint"):
        arm_files(os.path.join(robot_data_dir(), JACO[0]), ['nope'], JACO[2], JACO[1])
    with pytest.raises(ArmInitError, match='urdf: cannot read'):
        arm_files(str(tmp_path / 'none.urdf'), ['j'])


def test_init_then_the_twin_runs_the_jaco_within_its_bound_for_half_a_second(tmp_path):
    from freejoint_tools.arm_init import init_arm
    out = tmp_path / 'jaco'
    init_arm(os.path.join(robot_data_dir(), JACO[0]), ['j2s6s200_joint_6'], str(out),
             JACO[2], JACO[1])
    assert sorted(os.listdir(out)) == ['arm.yaml', 'controller.yaml', 'planner.yaml',
                                       'sim.yaml']
    # the limits are not written: the controller takes the URDF's (kinova.urdf's numbers)
    cfg = CONTROLLER.from_yaml(os.path.join(ROOT, 'config', 'controller.yaml'),
                               str(out / 'controller.yaml'))
    assert cfg.effort_limits == (40.0, 80.0, 40.0, 20.0, 20.0)
    assert cfg.position_lower[:3] == (-1000.0, 0.820304748437, 0.331612557879)  # 1: continuous
    assert cfg.position_upper[5] == 1000.0 and cfg.velocity_limit[5] == 1000.0  # 6: free
    assert cfg.velocity_limit[:5] == (0.628318530718,) * 3 + (0.837758040957,) * 2
    demo = load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'freejoint_demo')
    record, trace = demo.spatial_offline(str(out), 0, 500)
    assert len(trace['p']) == 500 and record['diverged_at_s'] is None
    assert record['max_mm'] < 3.0
    assert record['active_outside_limits'] == [] and record['free_outside_limits'] == []
    assert record['case'] == 'kinova_j2s6s200_joint_6'


def _ur10():
    return SpatialArm(os.path.join(robot_data_dir(), UR10), 'world', 'tool0',
                      ['wrist_2_joint'])


def _xarm7():
    return SpatialArm(os.path.join(robot_data_dir(), 'xarm_description/urdf/xarm7.urdf'),
                      'link_base', 'link_eef', ['joint7'])


def test_the_drivetrain_floor_by_hand_the_speed_a_disturbance_sustains_against_it():
    arm = _ur10()
    q = np.array(UR10_Q0)
    got = drivetrain_damping(arm, q, 0.5, 1e-3, 5e-4, 15.0)
    # 0.5 N m / (0.8 x 3.2 rad/s): wrist_2's rated speed sets it, not its +-2 pi range
    assert (SPEED_SHARE, Z) == (0.8, 4.0)
    assert got.floor == pytest.approx(0.5 / (0.8 * 3.2), rel=1e-12)
    assert (got.joint, got.cause, got.reason) == ('wrist_2_joint', 'speed', '')
    # the cap: the free joint's inertia with the active joints following, over dt_sub;
    # independent: the Schur complement M_pp - M_pa M_aa^-1 M_ap of Pinocchio's crba
    m = arm.terms(q, np.zeros(6)).M
    a, p = list(arm.active), 4
    inertia = m[p, p] - m[p, a] @ np.linalg.solve(m[np.ix_(a, a)], m[a, p])
    assert got.cap == pytest.approx(inertia / 5e-4, rel=1e-9)


def test_over_a_long_run_the_free_joints_walk_to_its_limit_sets_the_floor():
    arm = _ur10()
    q = np.array(UR10_Q0)
    got = drivetrain_damping(arm, q, 0.5, 1e-3, 5e-4, 1000.0)
    gap = min(q[4] + 2 * math.pi, 2 * math.pi - q[4])
    # 4 sigma of sum d_k dt / b over 10^6 periods: 4 x 0.5 / sqrt(3) x sqrt(1000 x 1e-3)
    assert got.floor == pytest.approx(4 * 0.5 / math.sqrt(3) * 1.0 / gap, rel=1e-9)
    assert got.cause == 'position' and got.reason == ''


def test_a_free_joint_the_simulator_cannot_hold_is_refused_with_its_limit_and_numbers():
    arm = _xarm7()
    q = np.zeros(arm.n)
    got = drivetrain_damping(arm, q, 0.5, 1e-3, 5e-4, 3600.0)
    assert got.floor > got.cap
    assert got.reason.startswith('free joint joint7 cannot be kept within its limits under '
                                 'the +-0.5 N m disturbance: its position limits ')
    assert f'need b >= 4 sigma sqrt(T dt) / gap = {got.floor:.4g} N m s/rad' in got.reason
    assert f'above the {got.cap:.4g} N m s/rad' in got.reason and 'dt_sub 0.0005 s' in got.reason
    with pytest.raises(ArmInitError, match='free joint joint7 cannot be kept'):
        free_damping(arm, q, 0.0, run_s=3600.0)
    # a lab's identified value is taken (capped), not refused
    assert free_damping(arm, q, 0.0, given=0.1, run_s=3600.0) == 0.1
    # the URDF's damping where larger than the floor, within the cap
    assert free_damping(arm, q, 0.25) == pytest.approx(min(0.25, got.cap))


def test_init_refuses_a_circle_too_fast_or_out_of_reach_before_any_search():
    path = os.path.join(robot_data_dir(), 'so_arm_description/urdf/so100.urdf')
    with pytest.raises(ArmInitError, match=r'^duration: 5 s for radius 2 m peaks at 4.71239 '
                       r'm/s, above max_speed 1 m/s \(duration >= 23.5619 s\)$'):
        arm_files(path, ['wrist_roll'], radius=2.0)
    with pytest.raises(ArmInitError) as err:
        arm_files(path, ['wrist_roll'], radius=0.4)
    assert str(err.value).startswith('no start posture found: radius: the circle leaves the '
                                     'reach of the arm: its point ')
    assert 'beyond the reach 0.4497 m' in str(err.value)
    with pytest.raises(ArmInitError, match=r'^hold: expected a finite number of seconds > 0, '
                       r'got -1.0$'):
        arm_files(path, ['wrist_roll'], hold_s=-1.0)
