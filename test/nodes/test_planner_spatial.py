"""
The planner node on a spatial arm in its own process, driven by this test.

Started on config/planner.yaml with the UR5 overlay (config/ur5/planner.yaml: wrist_2 free)
in sim time, fed the joint state of the offline runner's start posture as the lockstep
simulator publishes it (with ``/clock`` = 0, said again until answered), it checks the
circle from that posture and streams ``spatial_offline.circle(p0, 0.1, k dt, 5)`` from the
tip ``p0``, 3 values per vector, tick k at k dt, bit for bit.
"""
import os

from freejoint_core.spatial_law import gravity_carrying_free_joint
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_offline import CASES, circle
from freejoint_tools.harness import load_source
import numpy as np
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
MS = 1_000_000  # ns
DT = 0.001
UR5_JOINTS = ['shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint',
              'wrist_2_joint', 'wrist_3_joint']


def _helpers():
    """Return test_planner_node.py (its ClockDriver and service helpers)."""
    return load_source(os.path.join(os.path.dirname(__file__), 'test_planner_node.py'),
                       'planner_node_test_helpers')


def _driver(ros_node, wait, helpers, **clock_args):
    """Return ``(ClockDriver, joint_states publisher)`` once the planner matches both."""
    from freejoint_common.contract import JOINT_STATES
    clock = helpers.ClockDriver(ros_node, **clock_args)
    pub = ros_node.create_publisher(JOINT_STATES.msg_type, JOINT_STATES.name, JOINT_STATES.qos)
    wait(lambda: clock.matched() and pub.get_subscription_count() >= 1, 30.0,
         'the planner matching /clock, setpoint and joint_states',
         spin=lambda: helpers._spin(ros_node, 0.05))
    return clock, pub


def _step_zero(ros_node, helpers, clock, pub, state):
    """Return the lockstep simulator's step 0 as a spin: the state of tick 0, /clock 0."""
    def publish():
        # said again until answered, as the simulator does until its first command
        pub.publish(state)
        helpers._spin(ros_node, 0.02)
        clock.publish(0)
        helpers._spin(ros_node, 0.05)
    return publish


def test_the_planner_on_the_ur5_config_streams_the_offline_runners_circle_from_the_tip(
        procs, ros_node, wait):
    from freejoint_common.contract import JOINT_STATES, stamp_from_ns
    from freejoint_msgs.srv import PlanCircle
    helpers = _helpers()
    # lookahead 100: /clock jumps of up to 100 ticks below (the clock spacing rule)
    proc = procs.start_node('freejoint_planner', 'planner_node', 'planner', [
        '--ros-args', '--params-file', os.path.join(CONFIG, 'planner.yaml'),
        '--params-file', os.path.join(CONFIG, 'ur5', 'planner.yaml'), '-p', 'lookahead:=100'])
    client = helpers._wait_ready(ros_node, procs, proc, wait)
    log = procs.log(proc)
    assert 'spatial arm (task_dim 3)' in log and 'ur5_robot.urdf (spatial' in log
    assert 'singularity map computed' not in log
    clock, pub = _driver(ros_node, wait, helpers, lookahead=100)

    # The offline runner's start posture (config/ur5/sim.yaml's), computed here.
    name, free, q_plan = CASES['ur5_wrist2']
    arm = known_arm(name, [free])
    q0, why = gravity_carrying_free_joint(arm.nominal(0.7), np.array(q_plan))
    assert q0 is not None, why
    p0 = arm.fk(q0)
    state = JOINT_STATES.msg_type(name=UR5_JOINTS, position=q0.tolist(), velocity=[0.0] * 6,
                                  effort=[0.0] * 6)
    stamp_from_ns(0, state.header.stamp)

    lockstep_start = _step_zero(ros_node, helpers, clock, pub, state)
    wait(lambda: clock.last_stamp() == 100 * MS, 60.0,
         'the setpoints of ticks 0-100 after /clock 0 (log: %s)' % procs.log(proc),
         spin=lockstep_start)
    for now in list(range(MS, 10 * MS, MS)) + list(range(10 * MS, 300 * MS, 10 * MS)):
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    log = procs.log(proc)
    assert 'plan 1 from rest: spatial circle radius 0.1 m duration 5 s from [' in log
    assert 'nominal closed loop: 3001 steps of 2 ms in ' in log

    # ~/plan_circle: radius, duration, execute; the planar centre refused; no new circle
    # while the running one moves (no 3-D transition), nor a change of radius
    answer = helpers._call(ros_node, client, PlanCircle.Request(
        centre=[0.1, 0.0], radius=0.1, duration=5.0, start_angle=0.0, direction=1,
        execute=False), 'plan_circle')
    assert not answer.accepted and answer.reason.startswith(
        'bad request: centre, start_angle, direction: do not apply to a spatial arm'), \
        answer.reason
    moving = ('the running plan 1 moves until t = 5.000 s (ROS time): a spatial plan starts '
              'from rest (no 3-D transition); ask again once it holds its end point')
    # direction left at the request's default (0): the spatial circle's one direction
    request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.05, duration=4.0,
                                 start_angle=0.0, execute=True)
    answer = helpers._call(ros_node, client, request, 'plan_circle', timeout=30.0)
    assert not answer.accepted and answer.plan_id == 0
    assert answer.reason.endswith('refused: ' + moving), answer.reason
    result = helpers._set(helpers._param_client(ros_node), 'radius', 0.08)
    assert not result.successful and result.reason.endswith(moving), result.reason

    # Through the end of the circle, then a new one from where it rests.
    for now in range(300 * MS, 5_300 * MS, 100 * MS):
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    got = clock.got
    assert helpers._stamps(got) == [k * MS for k in range(len(got))]
    assert len(got) == 5_200 + 100 + 1
    for k, msg in enumerate(got):
        pos, vel, acc = circle(p0, 0.1, k * DT, 5.0)
        assert (list(msg.position), list(msg.velocity), list(msg.acceleration)) == (
            pos.tolist(), vel.tolist(), acc.tolist()), 'tick %d' % k
        assert (msg.plan_id, msg.plan_time, msg.final) == (1, (k * MS) * 1e-9, k * DT > 5.0)
    assert {b.header.frame_id for b in clock.batches} == {'base_link'}
    held = circle(p0, 0.1, 5.0, 5.0)[0]
    answer = helpers._call(ros_node, client, request, 'plan_circle', timeout=30.0)
    assert answer.accepted and answer.plan_id == 2, answer.reason
    assert 0.5 < answer.margin < 0.6                      # the reach margin [m]
    k1 = len(got)                                         # its first tick: the next one
    for now in range(5_300 * MS, 5_600 * MS, 100 * MS):
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    for k in range(k1, len(got)):
        pos, vel, acc = circle(held, 0.05, (k - k1) * DT, 4.0)
        msg = got[k]
        assert (list(msg.position), list(msg.velocity), list(msg.acceleration)) == (
            pos.tolist(), vel.tolist(), acc.tolist()), 'tick %d' % k
        assert (msg.plan_id, msg.plan_time) == (2, ((k - k1) * MS) * 1e-9)
    # no step: the new circle starts on the point the first one holds
    assert np.linalg.norm(np.array(got[k1].position) - got[k1 - 1].position) < 1e-15
    assert procs.stop(proc) == 0


def test_a_plan_circle_before_any_joint_state_starts_from_the_tip_of_the_first_one(
        procs, ros_node, wait):
    # As make demo starts a run: autostart false, ~/plan_circle with the planner's own
    # values once the graph is up, possibly before the planner holds a joint state
    from freejoint_common.contract import JOINT_STATES, stamp_from_ns
    from freejoint_msgs.srv import PlanCircle
    helpers = _helpers()
    proc = procs.start_node('freejoint_planner', 'planner_node', 'planner', [
        '--ros-args', '--params-file', os.path.join(CONFIG, 'planner.yaml'),
        '--params-file', os.path.join(CONFIG, 'ur5', 'planner.yaml'),
        '-p', 'autostart:=false'])
    client = helpers._wait_ready(ros_node, procs, proc, wait)
    request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.1, duration=5.0,
                                 start_angle=0.0, direction=1, execute=False)
    answer = helpers._call(ros_node, client, request, 'plan_circle')
    assert not answer.accepted and 'refused: no joint state with the positions and ' \
        'velocities of ' in answer.reason, answer.reason
    request.execute = True
    answer = helpers._call(ros_node, client, request, 'plan_circle')
    assert answer.accepted and answer.plan_id == 1 and answer.reason == ''
    assert "from rest: checked when it starts, from the arm's posture then" in procs.log(proc)

    clock, pub = _driver(ros_node, wait, helpers)
    # /clock without a joint state: the plan waits for the arm's posture, nothing streams

    def said_waiting():
        clock.publish(0)
        helpers._spin(ros_node, 0.05)
        return "plan 1: waiting for the arm's posture: no joint state" in procs.log(proc)

    wait(said_waiting, 30.0, 'the planner waiting for a joint state (log: %s)'
         % procs.log(proc), spin=lambda: helpers._spin(ros_node, 0.05))
    assert clock.got == []
    q0 = np.array([0.0, -1.2, 1.6, -1.97, -1.5708, 0.0])   # config/ur5/sim.yaml
    p0 = known_arm('ur5', ['wrist_2_joint']).fk(q0)
    state = JOINT_STATES.msg_type(name=UR5_JOINTS, position=q0.tolist(), velocity=[0.0] * 6)
    stamp_from_ns(0, state.header.stamp)

    lockstep_start = _step_zero(ros_node, helpers, clock, pub, state)
    wait(lambda: clock.last_stamp() == 20 * MS, 60.0,
         'the setpoints of ticks 0-20 (log: %s)' % procs.log(proc), spin=lockstep_start)
    for now in range(10 * MS, 100 * MS, 10 * MS):
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    got = clock.got
    assert helpers._stamps(got) == [k * MS for k in range(90 + 20 + 1)]
    for k, msg in enumerate(got):
        pos, vel, acc = circle(p0, 0.1, k * DT, 5.0)
        assert (list(msg.position), list(msg.velocity), list(msg.acceleration)) == (
            pos.tolist(), vel.tolist(), acc.tolist()), 'tick %d' % k
        assert msg.plan_id == 1
    assert 'plan 1 from rest: spatial circle radius 0.1 m duration 5 s from [' in \
        procs.log(proc)
    assert procs.stop(proc) == 0


@pytest.mark.parametrize('arm, free, case', [('ur5', 'elbow_joint', 'ur5_wrist2'),
                                             ('panda', 'panda_joint4', 'panda_j7')])
def test_a_free_joint_that_must_carry_gravity_is_refused_at_plan_time_in_one_line(
        procs, ros_node, wait, arm, free, case):
    # The example's configuration with another joint free: the configured plan (from rest)
    # is checked at the first joint state and refused with the reason, nothing streams
    from freejoint_common.contract import JOINT_STATES, stamp_from_ns
    helpers = _helpers()
    proc = procs.start_node('freejoint_planner', 'planner_node', 'planner', [
        '--ros-args', '--params-file', os.path.join(CONFIG, 'planner.yaml'),
        '--params-file', os.path.join(CONFIG, arm, 'planner.yaml'),
        '-p', 'passive_joints:=[%s]' % free])
    helpers._wait_ready(ros_node, procs, proc, wait)
    clock, pub = _driver(ros_node, wait, helpers)
    chain = known_arm(CASES[case][0]).joint_names
    state = JOINT_STATES.msg_type(name=list(chain), position=list(CASES[case][2]),
                                  velocity=[0.0] * len(chain), effort=[0.0] * len(chain))
    stamp_from_ns(0, state.header.stamp)

    lockstep_start = _step_zero(ros_node, helpers, clock, pub, state)
    refusal = f'free joint {free} must carry gravity'
    wait(lambda: refusal in procs.log(proc), 60.0,
         'the refusal (log: %s)' % procs.log(proc), spin=lockstep_start)
    lines = [line for line in procs.log(proc).splitlines() if refusal in line]
    assert len(lines) == 1, lines
    assert f'free joint {free} must carry gravity: no rest posture within the joint limits ' \
           'holds the tip at [' in lines[0]
    assert clock.last_stamp() is None            # no setpoint streamed
