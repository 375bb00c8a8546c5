"""
The simulator's configuration of a spatial arm (task_dim 3), without ROS.

The UR5 and Panda overlays (config/ur5/sim.yaml, config/panda/sim.yaml on top of
config/sim.yaml) build; their initial posture is the offline runner's start posture, computed
here independently (``gravity_carrying_free_joint`` on ``known_arm``, not the parameters'
arm), to the round-off of that search on this CPU (the file holds the digits one CPU
computed); the plant they build from it is ``SpatialPlant`` stepped by hand from the same
posture, bit for bit; what a spatial arm cannot take is refused with one line naming the
parameter.
"""
import math
import os

from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import divergence_reason
from freejoint_core.spatial_law import gravity_carrying_free_joint
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_offline import CASES
from freejoint_core.spatial_plant import SpatialPlant
from freejoint_sim.engines import make_plant
from freejoint_sim.failure_injection import Injector, parse_fail_joint
from freejoint_sim.params import SCHEMA
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))))
CONFIG = os.path.join(ROOT, 'config')
UR5_JOINTS = ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint',
              'wrist_2_joint', 'wrist_3_joint')
UR5_ACTIVE = UR5_JOINTS[:4] + UR5_JOINTS[5:]
# How far the start posture gravity_carrying_free_joint finds may move with the CPU's
# round-off [rad]. Its Gauss-Newton steps use a central-difference Jacobian (h = 1e-6): a
# residual's round-off (~1e-15 of its O(1) m and N m) becomes ~1e-9 of a Jacobian entry,
# and the last step (2.5e-3 rad on the Panda, condition number ~70) carries that as
# ~2e-10 rad. numpy and OpenBLAS pick other kernels on AVX2 than on AVX-512 and the
# Panda's angles differ by up to 3e-13 rad (docs/developing.md, "Another CPU").
IK_ROUND_OFF_RAD = 1e-9


def _values(arm='ur5', **changes):
    """Return the values of config/sim.yaml with the arm's overlay, then ``changes``."""
    values = SCHEMA.yaml_values(os.path.join(CONFIG, 'sim.yaml'),
                                os.path.join(CONFIG, arm, 'sim.yaml'))
    values.update(changes)
    return values


def _start_posture(case):
    """Return the offline runner's start posture of ``case`` (spatial_offline.run_case)."""
    name, free, q_plan = CASES[case]
    q, why = gravity_carrying_free_joint(known_arm(name, [free]).nominal(0.7),
                                         np.array(q_plan))
    assert q is not None, why
    return tuple(q.tolist())


def test_the_ur5_with_wrist_2_free_builds_with_its_chain_joints_and_five_commanded():
    cfg = SCHEMA.config(_values())
    assert cfg.arm.spatial is not None and cfg.arm.task_dim == 3
    assert cfg.joint_names == UR5_JOINTS
    assert cfg.joints == UR5_ACTIVE             # the command: the five active joints
    assert cfg.cmd_to_active == (0, 1, 2, 3, 4)
    assert (cfg.params.n, cfg.params.r, cfg.params.passive) == (6, 5, (4,))


@pytest.mark.parametrize('arm, case', [('ur5', 'ur5_wrist2'), ('panda', 'panda_j7')])
def test_the_configs_initial_posture_is_the_offline_runners_start_posture_to_round_off(
        arm, case):
    cfg = SCHEMA.config(_values(arm))
    np.testing.assert_allclose(cfg.q0, _start_posture(case), rtol=0, atol=IK_ROUND_OFF_RAD)
    # a rest posture: the free joint carries no gravity torque there (to Gauss-Newton's 1e-6)
    spatial = cfg.arm.spatial
    assert abs(spatial.gravity_torque(cfg.q0)[spatial.passive[0]]) < 1e-6


def test_the_commanded_joints_in_another_order_map_to_the_active_ones():
    joints = list(reversed(UR5_ACTIVE))
    cfg = SCHEMA.config(_values(joints=joints))
    assert cfg.cmd_to_active == (4, 3, 2, 1, 0)


@pytest.mark.parametrize('changes, match', [
    ({'initial_joint_positions': '0 -1.2 1.6 -1.97 -1.5708'},
     r'initial_joint_positions: expected 6 finite joint angles \[rad\] \(one per joint, base '
     r"to tip\), got '0 -1.2 1.6 -1.97 -1.5708'"),
    ({'initial_joint_positions': '0 -1.2 3.5 -1.97 -1.5708 0'},
     r'initial_joint_positions: elbow_joint = 3.5 rad is outside its URDF limits '
     r'\[-3.14159265359, 3.14159265359\] rad'),
    ({'initial_joint_positions': ''},
     r'initial_joint_positions: a spatial arm \(task_dim 3\) starts at its 6 joint angles '
     r"\[rad\] \['shoulder_pan_joint', "),
    ({'initial_position': [0.3, 0.1]},
     r'initial_position: planar arms only \(task_dim 2\), got \[0.3, 0.1\] for a spatial '
     r'arm; it starts at initial_joint_positions'),
    ({'initial_passive_deg': 90.0},
     r'initial_passive_deg: planar arms only \(task_dim 2\), got 90.0'),
    ({'start_pose': 'hanging'}, r"start_pose: planar arms only \(task_dim 2\), got 'hanging'"),
    ({'fail_joint': 'wrist_2_joint@1.0'},
     'fail_joint: wrist_2_joint is passive already'),
    ({'joint_names': ['joint1', 'joint2', 'joint3', 'joint4', 'joint5', 'joint6']},
     r"joints: expected the 5 active joints \['joint1', "),
])
def test_what_a_spatial_arm_cannot_take_is_refused_naming_the_parameter(changes, match):
    with pytest.raises(FreejointValueError, match=match):
        SCHEMA.config(_values(**changes))


def test_the_panda_limits_are_its_own_joint_4_above_its_upper_limit_is_refused():
    # panda_joint4 lies in [-3.0718, -0.0698]: 0 (the UR5's zero posture) is outside
    q0 = ' '.join(repr(v) for v in (0.0, -0.3, 0.0, 0.0, 0.0, 2.0, 0.785))
    with pytest.raises(FreejointValueError, match=r'initial_joint_positions: panda_joint4 = '
                                                  r'0.0 rad is outside its URDF limits '
                                                  r'\[-3.0718, -0.0698\] rad'):
        SCHEMA.config(_values('panda', initial_joint_positions=q0))


def test_the_planar_parameters_at_their_defaults_are_ignored_for_a_spatial_arm():
    defaults = SCHEMA.defaults()
    cfg = SCHEMA.config(_values(**{name: defaults[name] for name in (
        'initial_position', 'initial_passive_deg', 'start_pose', 'engine')}))
    assert cfg.q0 == SCHEMA.config(_values()).q0


def _torques(k, r):
    """Return a deterministic, varied active torque [N m] for step k (r joints)."""
    return [3.0 * math.sin(0.3 * k + i) for i in range(r)]


@pytest.mark.parametrize('arm, case', [('ur5', 'ur5_wrist2'), ('panda', 'panda_j7')])
def test_the_configured_plant_is_spatial_plant_stepped_by_hand_bit_for_bit(arm, case):
    cfg = SCHEMA.config(_values(arm, seed=3))
    plant = make_plant(cfg)
    name, free, _ = CASES[case]
    # the Panda's free flange keeps its drivetrain's damping (config/panda/sim.yaml)
    assert cfg.passive_damping == {'ur5': 0.0, 'panda': 1.0}[arm]
    by_hand = SpatialPlant(known_arm(name, [free]), 0.0005, dist_bound=0.5, seed=3,
                           q0=cfg.q0, passive_damping=cfg.passive_damping)
    assert plant.q.tolist() == by_hand.q.tolist() and plant.qd.tolist() == [0.0] * cfg.params.n
    for k in range(40):
        tau = _torques(k, cfg.params.r)
        plant.step(tau, cfg.dt)
        by_hand.step(tau, 0.001)
        assert plant.last_disturbance == by_hand.last_disturbance
    assert plant.q.tolist() == by_hand.q.tolist()
    assert plant.qd.tolist() == by_hand.qd.tolist()
    assert plant.qd.tolist() != [0.0] * cfg.params.n      # it moved
    # the tip the simulator publishes on ee_position: the plant's model, three coordinates
    assert plant.model.fk(plant.q).tolist() == by_hand.arm.fk(by_hand.q).tolist()
    assert len(plant.model.fk(plant.q)) == 3


@pytest.mark.parametrize('arm, case', [('ur5', 'ur5_wrist2'), ('panda', 'panda_j7')])
def test_engine_mujoco_is_spatial_plant_to_round_off(arm, case):
    # MuJoCo's RK4 on its own import of the URDF (the Panda's fingers fixed) against RK4 on
    # Pinocchio's ABA: the same held torque and disturbance draws, 300 steps (0.3 s) of
    # gravity compensation plus a wave; the arm moves by 0.3-0.6 rad. Two programs' round-off
    # over 600 RK4 steps of 0.5 ms from one posture: 3e-14 rad/s apart (AVX2 as AVX-512);
    # 1e-12 bounds it; a posture 3e-13 rad off (another CPU's IK) already parts them by 8e-12.
    cfg = SCHEMA.config(_values(arm, engine='mujoco'))
    plant = make_plant(cfg)
    assert type(plant).__name__ == 'SpatialMujocoPlant'
    name, free, _ = CASES[case]
    real = known_arm(name, [free])
    by_hand = SpatialPlant(real, 0.0005, dist_bound=0.5, seed=0, q0=cfg.q0,
                           passive_damping=cfg.passive_damping)
    active = list(real.active)
    for k in range(300):
        tau = real.gravity_torque(by_hand.q)[active] + 0.5 * np.sin(0.01 * k + np.arange(
            real.r))
        plant.step(tau, cfg.dt)
        by_hand.step(tau, 0.001)
        assert plant.last_disturbance == by_hand.last_disturbance
    assert np.max(np.abs(by_hand.q - np.array(cfg.q0))) > 0.2
    np.testing.assert_allclose(plant.q, by_hand.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(plant.qd, by_hand.qd, rtol=0, atol=1e-12)
    q = plant.q.tolist()
    plant.stop()                # brakes engaged (real time): every joint at rest, in place
    assert plant.qd.tolist() == [0.0] * real.n and plant.q.tolist() == q


def test_another_seed_draws_another_disturbance():
    one = make_plant(SCHEMA.config(_values(seed=0)))
    two = make_plant(SCHEMA.config(_values(seed=1)))
    one.step([0.0] * 5, 0.001)
    two.step([0.0] * 5, 0.001)
    assert one.last_disturbance != two.last_disturbance
    assert all(abs(d) <= 0.5 for d in one.last_disturbance + two.last_disturbance)


def test_a_failure_by_joint_name_leaves_that_ur5_joint_limp_reading_zero_effort():
    cfg = SCHEMA.config(_values(fail_joint='wrist_1_joint@0.002'))
    assert parse_fail_joint(cfg.fail_joint, cfg.joint_names, cfg.params.active) == [(3, 0.002)]
    plant = make_plant(cfg)
    injector = Injector(plant, cfg.joint_names)
    injector.schedule(3, 0.002, 'parameter fail_joint')
    by_hand = SpatialPlant(known_arm('ur5', ['wrist_2_joint']), 0.0005, dist_bound=0.5,
                           seed=0, q0=cfg.q0)
    by_hand.fail_joint(3, 0.002)
    tau = [1.0, 2.0, 3.0, 4.0, 5.0]
    taken = []
    for k in range(4):
        plant.step(tau, 0.001)
        by_hand.step(tau, 0.001)
        applied = [1.0, 2.0, 3.0, 4.0, 0.0, 5.0]     # the command on the active joints
        injector.effort(applied)
        taken += injector.check()
        assert applied == [1.0, 2.0, 3.0, 4.0 if k < 2 else 0.0, 0.0, 5.0]
    assert taken == [('wrist_1_joint', 0.002, 'parameter fail_joint')]
    assert plant.q.tolist() == by_hand.q.tolist()


def test_the_divergence_check_names_any_of_the_n_joints():
    q = [0.0, -1.2, 1.6, -1.97, -1.5708, 0.0]
    qd = [0.0] * 5 + [1500.0]
    assert divergence_reason(q, qd, 1000.0) == ('joint 5: speed 1500 rad/s beyond '
                                                'divergence_speed 1000 rad/s')
    assert divergence_reason(q, [0.0] * 6, 1000.0) is None
    assert divergence_reason(q[:5] + [math.nan], [0.0] * 6, 1000.0).startswith(
        'joint 5: non-finite state')


def test_a_planar_arm_refuses_passive_damping_naming_it():
    values = SCHEMA.yaml_values(os.path.join(CONFIG, 'sim.yaml'))
    values['passive_damping'] = 1.0
    with pytest.raises(FreejointValueError, match=r'^passive_damping: spatial arms only '
                                                  r'\(task_dim 3\), got 1.0 N m s/rad'):
        SCHEMA.config(values)
    values['passive_damping'] = 0.0
    assert SCHEMA.config(values).passive_damping == 0.0


def test_a_negative_passive_damping_is_refused_by_the_schema():
    assert SCHEMA['passive_damping'].reason(-1.0) == (
        'passive_damping: must be in [0, 100] N m s/rad, got -1.0')
