"""
The simulator node on a spatial arm in its own process, driven by this test.

Started on config/sim.yaml with the UR5 overlay (config/ur5/sim.yaml: wrist_2 free) in
lockstep, it publishes the six chain joints at the offline runner's start posture, at rest,
the URDF it simulates on /robot_description and the tip in 3-D on ee_position; each state
after a command is ``SpatialPlant`` stepped here with the same efforts, bit for bit (engine
``mujoco``: to round-off, 1e-12).
"""
import math
import os

from freejoint_core.spatial_law import gravity_carrying_free_joint
from freejoint_core.spatial_model import known_arm, robot_data_dir
from freejoint_core.spatial_offline import CASES
from freejoint_core.spatial_plant import SpatialPlant
from freejoint_tools.harness import load_source
import numpy as np
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
DT = 0.001
UR5_JOINTS = ['shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint',
              'wrist_2_joint', 'wrist_3_joint']


def _controller(ros_node, wait):
    """Return test_sim_node.py's ``Controller`` (this test as the simulator's controller)."""
    helpers = load_source(os.path.join(os.path.dirname(__file__), 'test_sim_node.py'),
                          'sim_node_test_helpers')
    return helpers.Controller(ros_node, wait)


def _same(got, want, engine):
    """Assert a published list equals the plant's: exactly (rk4), to 1e-12 (mujoco)."""
    if engine == 'rk4':
        assert list(got) == want.tolist()
    else:
        np.testing.assert_allclose(list(got), want, rtol=0, atol=1e-12)


@pytest.mark.parametrize('engine', ['rk4', 'mujoco'])
def test_sim_on_the_ur5_config_starts_at_the_runners_posture_and_steps_spatial_plant(
        engine, procs, ros_node, wait):
    import rclpy
    from freejoint_common.contract import ROBOT_DESCRIPTION
    sim = procs.start_node('freejoint_sim', 'sim_node', 'sim', [
        '--ros-args', '--params-file', os.path.join(CONFIG, 'sim.yaml'),
        '--params-file', os.path.join(CONFIG, 'ur5', 'sim.yaml'), '-p', 'engine:=' + engine])
    texts = []
    ros_node.create_subscription(ROBOT_DESCRIPTION.msg_type, ROBOT_DESCRIPTION.name,
                                 lambda m: texts.append(m.data), ROBOT_DESCRIPTION.qos)
    ctl = _controller(ros_node, wait)
    ctl.connect(sim, procs)
    assert 'ur5_robot.urdf (spatial, base_link -> tool0)' in procs.log(sim)
    assert ('(MuJoCo RK4 ' if engine == 'mujoco' else '(RK4 ') in procs.log(sim)

    # The offline runner's start posture, computed here (not read from the config).
    name, free, q_plan = CASES['ur5_wrist2']
    arm = known_arm(name, [free])
    q0, why = gravity_carrying_free_joint(arm.nominal(0.7), np.array(q_plan))
    assert q0 is not None, why
    first = ctl.state(0)
    assert list(first.name) == UR5_JOINTS
    assert list(first.position) == q0.tolist()
    assert list(first.velocity) == [0.0] * 6
    assert list(first.effort) == [0.0] * 6
    ee = ctl.ee[0]
    assert [ee.point.x, ee.point.y, ee.point.z] == arm.fk(q0).tolist()
    assert ee.header.frame_id == 'base_link'
    wait(lambda: texts, 30.0, '/robot_description',
         spin=lambda: rclpy.spin_once(ros_node, timeout_sec=0.05))
    with open(os.path.join(robot_data_dir(), 'ur_description', 'urdf', 'ur5_robot.urdf'),
              encoding='utf-8') as fh:
        assert texts[0] == fh.read()

    # Five efforts (the active joints, wrist_2 left out) per step: the plant stepped here.
    plant = SpatialPlant(arm, 0.0005, dist_bound=0.5, seed=0, q0=q0)
    for k in range(10):
        tau = [3.0 * math.sin(0.3 * k + i) for i in range(5)]
        msg = ctl.step(tau, k)              # resent until answered (test_sim_node)
        plant.step(tau, DT)
        _same(msg.position, plant.q, engine)
        _same(msg.velocity, plant.qd, engine)
        assert list(msg.effort) == tau[:4] + [0.0] + tau[4:]
        ee = ctl.ee[(k + 1) * 1_000_000]
        _same([ee.point.x, ee.point.y, ee.point.z], arm.fk(plant.q), engine)
    assert procs.stop(sim) == 0
