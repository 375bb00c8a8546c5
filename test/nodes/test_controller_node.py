"""
The controller node in its own process, driven by this test as simulator and planner.

Every answer is compared with ``RobustController`` stepped here on the same inputs: the
node must compute exactly the core law, whatever the JointState's joint order, and take
parameter changes on the next tick.
"""
import math
import os
import re

from freejoint_core.arm import table1
from freejoint_core.control import (Gains, RobustController, STATUS_BAD_INPUT,
                                    STATUS_STALE_SETPOINT, STATUS_STALE_STATE)
from freejoint_msgs.msg import ControllerState
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PARAMS = os.path.join(ROOT, 'config', 'controller.yaml')
STATUS_HOLDING = ControllerState.STATUS_HOLDING
STATUS_RATE_LIMITED = ControllerState.STATUS_RATE_LIMITED
STATUS_RESUMING = ControllerState.STATUS_RESUMING
DT = 0.001
DT_NS = 1_000_000
NAMES = ['joint1', 'joint2', 'joint3']
# A configuration near the paper's start (q3 = 120 deg), moving a little.
Q0 = (-1.369438, 1.691679, 2.094395)
QD0 = (0.05, -0.1, 0.3)


def _qos(transient=False):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if transient
                                  else DurabilityPolicy.VOLATILE))


class Driver:
    """This test as the controller's simulator and planner."""

    def __init__(self, node, wait):
        import rclpy
        from freejoint_msgs.msg import CartesianSetpoint, ControllerState
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray
        self.rclpy = rclpy
        self.node = node
        self.wait = wait
        self.states = {}
        self.commands = {}
        self.pub_js = node.create_publisher(JointState, 'joint_states', _qos())
        self.pub_sp = node.create_publisher(CartesianSetpoint, 'setpoint', _qos(True))
        node.create_subscription(ControllerState, 'controller_state', self._on_state, _qos())
        node.create_subscription(Float64MultiArray, 'effort_controller/commands',
                                 self._on_command, _qos())
        self.JointState = JointState
        self.CartesianSetpoint = CartesianSetpoint

    def _on_state(self, msg):
        ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.states.setdefault(ns, []).append(msg)

    def _on_command(self, msg):
        label = msg.layout.dim[0].label if msg.layout.dim else ''
        self.commands.setdefault(label, []).append(list(msg.data))

    def spin(self):
        self.rclpy.spin_once(self.node, timeout_sec=0.05)

    @staticmethod
    def stamp(msg, k):
        msg.header.stamp.sec = (k * DT_NS) // 1_000_000_000
        msg.header.stamp.nanosec = (k * DT_NS) % 1_000_000_000

    def setpoint(self, k, values):
        msg = self.CartesianSetpoint()
        self.stamp(msg, k)
        msg.position = list(values[0:2])
        msg.velocity = list(values[2:4])
        msg.acceleration = list(values[4:6])
        self.pub_sp.publish(msg)

    def joint_state(self, k, q, qd, names=NAMES):
        msg = self.JointState()
        self.stamp(msg, k)
        msg.name = list(names)
        msg.position = [float(v) for v in q]
        msg.velocity = [float(v) for v in qd]
        msg.effort = [0.0] * len(names)
        self.pub_js.publish(msg)

    def answer(self, k, what='the answer', timeout=15.0):
        """Wait for the ControllerState of tick k; return it and the command."""
        ns = k * DT_NS
        self.wait(lambda: ns in self.states and 'stamp_ns=%d' % ns in self.commands,
                  timeout, '%s to tick %d' % (what, k), spin=self.spin)
        return self.states[ns][0], self.commands['stamp_ns=%d' % ns][0]

    def connect(self, proc, procs):
        self.wait(lambda: (self.pub_js.get_subscription_count() > 0
                           and self.pub_sp.get_subscription_count() > 0
                           and len(self.node.get_publishers_info_by_topic(
                               '/controller_state')) > 0),
                  30.0, 'the controller to connect (log: %s)' % procs.log(proc),
                  spin=self.spin)


def _setpoint(k):
    """Return a setpoint near the start point, changing with k."""
    return (0.2 - 1e-4 * k, 1e-4 * k, -0.01, 0.02, 0.5, -0.3)


def _expect(ctl, q, qd, sp):
    out = ctl.step(q, qd, sp[0:2], sp[2:4], sp[4:6], DT)
    return out


def _start(procs, *extra):
    return procs.start_node('freejoint_control', 'controller_node', 'controller',
                            ['--ros-args', '--params-file', PARAMS, *extra])


def _state_q(k):
    return tuple(v + 1e-3 * k for v in Q0), tuple(v * (1 + 0.1 * k) for v in QD0)


def test_params_file_loads_and_each_tick_is_the_core_law(procs, ros_node, wait):
    proc = _start(procs)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    for k in range(4):
        q, qd = _state_q(k)
        drv.setpoint(k, _setpoint(k))
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        out = _expect(ctl, q, qd, _setpoint(k))
        assert cmd == out.tau.tolist()
        assert list(st.effort) == out.tau.tolist()
        assert list(st.theta_hat) == out.theta.tolist()
        assert list(st.position) == out.p.tolist()
        assert list(st.position_desired) == list(_setpoint(k)[0:2])
        assert st.det_dd == out.det and st.status == 0 and st.message == ''
        assert list(st.joint_names) == ['joint1', 'joint2']
    # A repeated state gets the cached answer: no second theta update.
    q, qd = _state_q(3)
    drv.joint_state(3, q, qd)
    wait(lambda: len(drv.states[3 * DT_NS]) >= 2, 15.0, 'the repeated answer', spin=drv.spin)
    assert list(drv.states[3 * DT_NS][1].theta_hat) == ctl.theta.tolist()
    k = 4
    q, qd = _state_q(k)
    drv.setpoint(k, _setpoint(k))
    drv.joint_state(k, q, qd)
    st, cmd = drv.answer(k)
    assert cmd == _expect(ctl, q, qd, _setpoint(k)).tau.tolist()
    assert procs.stop(proc) == 0


def test_joint_state_in_another_order_with_extra_joints_drives_it_the_same(
        procs, ros_node, wait):
    proc = _start(procs)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    names = ['gripper', 'joint3', 'wrist', 'joint1', 'joint2']
    for k in range(3):
        q, qd = _state_q(k)
        out = _expect(ctl, q, qd, _setpoint(k))
        drv.setpoint(k, _setpoint(k))
        if k == 1:
            # As a driver's joint_state_broadcaster may publish: own order, extra joints.
            drv.joint_state(k, (0.7, q[2], -1.0, q[0], q[1]), (0.0, qd[2], 5.0, qd[0], qd[1]),
                            names)
        else:
            drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        assert cmd == out.tau.tolist()
        assert list(st.theta_hat) == out.theta.tolist()
    assert procs.stop(proc) == 0


def test_set_parameters_changes_the_next_tick_and_a_bad_value_is_refused(
        procs, ros_node, wait):
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    import rclpy
    proc = _start(procs)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    client = AsyncParameterClient(ros_node, 'controller_node')
    assert client.wait_for_services(timeout_sec=15.0), 'no parameter services'

    def set_params(*params):
        future = client.set_parameters(list(params))
        rclpy.spin_until_future_complete(ros_node, future, timeout_sec=15.0)
        assert future.done(), 'no answer from set_parameters within 15 s'
        return future.result().results

    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    q, qd = _state_q(0)
    drv.setpoint(0, _setpoint(0))
    drv.joint_state(0, q, qd)
    drv.answer(0)
    _expect(ctl, q, qd, _setpoint(0))

    (res,) = set_params(Parameter('K', value=[40.0, 60.0]))
    assert res.successful, res.reason
    ctl.set_gains(Gains(K=(40.0, 60.0)))
    q, qd = _state_q(1)
    drv.setpoint(1, _setpoint(1))
    drv.joint_state(1, q, qd)
    _, cmd = drv.answer(1)
    assert cmd == _expect(ctl, q, qd, _setpoint(1)).tau.tolist()

    bad = [(Parameter('K', value=[-1.0, 100.0]), r'^K: values must be finite and > 0'),
           (Parameter('Gamma', value=[0.01, 0.01]), r'^Gamma: expected shape \(5,\), got \(2,\)'),
           (Parameter('h_form', value='max'), r"^h_form: expected 'sum' or 'sat'"),
           (Parameter('Lambda', value=[0.0, 1.0]), r'^Lambda: values must be finite and > 0')]
    for param, reason in bad:
        (res,) = set_params(param)
        assert not res.successful
        assert re.match(reason, res.reason), res.reason
    # Out of its descriptor's range: refused by rclpy with the range in the reason.
    (res,) = set_params(Parameter('epsilon', value=-0.5))
    assert not res.successful and 'epsilon' in res.reason

    # Still running, on the last good values (K = 40, 60).
    q, qd = _state_q(2)
    drv.setpoint(2, _setpoint(2))
    drv.joint_state(2, q, qd)
    _, cmd = drv.answer(2)
    assert cmd == _expect(ctl, q, qd, _setpoint(2)).tau.tolist()

    # The robust switch and theta0 (which restarts theta_hat) also act on the next tick.
    (res,) = set_params(Parameter('robust', value=False))
    assert res.successful, res.reason
    ctl.set_gains(Gains(K=(40.0, 60.0), robust=False))
    q, qd = _state_q(3)
    drv.setpoint(3, _setpoint(3))
    drv.joint_state(3, q, qd)
    st, cmd = drv.answer(3)
    assert cmd == _expect(ctl, q, qd, _setpoint(3)).tau.tolist()
    assert list(st.delta_v) == [0.0, 0.0]
    assert procs.stop(proc) == 0


def test_missing_joint_and_non_finite_state_are_refused_with_zero_effort(
        procs, ros_node, wait):
    proc = _start(procs)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    q, qd = _state_q(0)
    drv.setpoint(0, _setpoint(0))
    drv.joint_state(0, q[:2], qd[:2], ['joint1', 'joint2'])
    st, cmd = drv.answer(0, 'the refusal of a state without joint3')
    assert cmd == [0.0, 0.0]
    assert st.status == STATUS_BAD_INPUT
    assert "lacks joint(s) ['joint3']" in st.message
    drv.setpoint(1, _setpoint(1))
    drv.joint_state(1, (q[0], math.nan, q[2]), qd)
    st, cmd = drv.answer(1, 'the refusal of a NaN state')
    assert cmd == [0.0, 0.0]
    assert st.status == STATUS_BAD_INPUT and 'non-finite' in st.message
    wait(lambda: 'non-finite position or velocity' in procs.log(proc), 10.0,
         'the NaN refusal in the log')
    assert "state refused: JointState lacks joint(s) ['joint3']" in procs.log(proc)
    # A good state afterwards is served by the law, ramping up from the zero effort the arm
    # got at effort_rate_limit (20000 N m/s: 20 N m per 1 ms tick).
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    drv.setpoint(2, _setpoint(2))
    drv.joint_state(2, q, qd)
    st, cmd = drv.answer(2)
    tau = _expect(ctl, q, qd, _setpoint(2)).tau.tolist()
    assert cmd == [max(-20.0, min(20.0, x)) for x in tau]
    assert st.status == (STATUS_RATE_LIMITED if cmd != tau else 0)
    assert list(st.theta_hat) == ctl.theta.tolist()
    assert procs.stop(proc) == 0


def test_with_on_stale_zero_stale_setpoint_and_stale_state_command_zero_effort_and_say_so(
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'stale_timeout:=0.3', '-p', 'on_stale_setpoint:=zero')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    q, qd = _state_q(0)
    drv.setpoint(0, _setpoint(0))
    drv.joint_state(0, q, qd)
    st, cmd = drv.answer(0)
    assert st.status == 0 and cmd != [0.0, 0.0]
    # State 1 without its setpoint: held, then answered with zero after stale_timeout.
    drv.joint_state(1, q, qd)
    st, cmd = drv.answer(1, 'the stale-setpoint answer')
    assert cmd == [0.0, 0.0]
    assert st.status == STATUS_STALE_SETPOINT and 'stale setpoint' in st.message
    # No more states: zero effort and STALE_STATE.
    wait(lambda: any(m.status == STATUS_STALE_STATE for m in drv.states[DT_NS]), 15.0,
         'the stale-state message', spin=drv.spin)
    assert drv.commands['stamp_ns=%d' % DT_NS][-1] == [0.0, 0.0]
    assert 'no joint_states for 0.3 s: zero effort' in procs.log(proc)
    assert procs.stop(proc) == 0
