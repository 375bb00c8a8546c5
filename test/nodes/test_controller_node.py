"""
The controller node in its own process, driven by this test as simulator and planner.

Only what needs a process: start-up from the params file and each lockstep tick the core
law end to end, parameters over DDS (set, refused), a bad start-up parameter, ~/reset,
controller_state thinning, the executor's subscription order, QoS overrides and
/diagnostics. The controller's decisions themselves (hold, stale, resume, guards, faults,
limits, standby) are tested in one process against ``freejoint_control.loop``
(test/control/test_loop.py).
"""
import math
import os
import re

from freejoint_common.contract import COMMANDS, CONTROLLER_STATE, DIAGNOSTICS, JOINT_STATES
from freejoint_common.contract import profile, SETPOINTS, stamp_from_ns, stamp_label, to_ns
from freejoint_control.params import SCHEMA
from freejoint_core.arm import table1
from freejoint_core.control import Gains, RobustController
from freejoint_msgs.msg import ControllerState
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PARAMS = os.path.join(ROOT, 'config', 'controller.yaml')
STATUS_HOLDING = ControllerState.STATUS_HOLDING
STATUS_RATE_LIMITED = ControllerState.STATUS_RATE_LIMITED
DT = 0.001
DT_NS = 1_000_000
NAMES = ['joint1', 'joint2', 'joint3']
# A configuration near the paper's start (q3 = 120 deg), moving a little.
Q0 = (-1.369438, 1.691679, 2.094395)
QD0 = (0.05, -0.1, 0.3)


def _qos(transient=False):
    return profile(100, latched=transient)


class Driver:
    """This test as the controller's simulator and planner."""

    def __init__(self, node, wait):
        import rclpy
        self.rclpy = rclpy
        self.node = node
        self.wait = wait
        self.states = {}
        self.commands = {}
        self.pub_js = node.create_publisher(JOINT_STATES.msg_type, JOINT_STATES.name, _qos())
        self.pub_sp = node.create_publisher(SETPOINTS.msg_type, SETPOINTS.name, _qos(True))
        self.subs = (
            node.create_subscription(CONTROLLER_STATE.msg_type, CONTROLLER_STATE.name,
                                     self._on_state, _qos()),
            node.create_subscription(COMMANDS.msg_type, COMMANDS.name, self._on_command,
                                     _qos()))
        self.JointState = JOINT_STATES.msg_type
        self.CartesianSetpoints = SETPOINTS.msg_type

    def _on_state(self, msg):
        ns = to_ns(msg.header.stamp)
        self.states.setdefault(ns, []).append(msg)

    def _on_command(self, msg):
        label = msg.layout.dim[0].label if msg.layout.dim else ''
        self.commands.setdefault(label, []).append(list(msg.data))

    def spin(self):
        self.rclpy.spin_once(self.node, timeout_sec=0.05)

    offset_ns = 0
    """Added to every stamp (a jump of the stamps, as after a stall of the driver)."""

    def ns(self, k):
        return k * DT_NS + self.offset_ns

    def stamp(self, msg, k):
        stamp_from_ns(self.ns(k), msg.header.stamp)

    def setpoint(self, k, values):
        msg = self.CartesianSetpoints(stamps=[self.ns(k)], position=list(values[0:2]),
                                      velocity=list(values[2:4]),
                                      acceleration=list(values[4:6]))
        self.stamp(msg, k)
        self.pub_sp.publish(msg)

    def setpoints_ahead(self, k, values_of, ahead=5):
        """
        Publish the setpoints of ticks k..k+ahead not yet out (values_of(j) None: none).

        Real time pairs a state with the newest setpoint already received: sending them
        ahead, as the planner does (and waiting for the first ones to be acknowledged),
        keeps the pairing free of the race between topics.
        """
        from rclpy.duration import Duration
        sent = self.__dict__.setdefault('_sent', set())
        published = False
        for j in range(k, k + ahead + 1):
            if j not in sent:
                sent.add(j)
                values = values_of(j)
                if values is not None:
                    self.setpoint(j, values)
                    published = True
        if published and not self.__dict__.get('_acked'):
            # The first ones: delivered before the first state goes out.
            self._acked = True
            assert self.pub_sp.wait_for_all_acked(Duration(seconds=15.0)), \
                'setpoints not acknowledged within 15 s'

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
        ns = self.ns(k)
        self.wait(lambda: ns in self.states and stamp_label(ns) in self.commands,
                  timeout, '%s to tick %d' % (what, k), spin=self.spin)
        return self.states[ns][0], self.commands[stamp_label(ns)][0]

    def matched(self):
        """Return whether this test's endpoints and the controller's match both ways."""
        return (self.pub_js.get_subscription_count() > 0
                and self.pub_sp.get_subscription_count() > 0
                and all(sub.get_publisher_count() > 0 for sub in self.subs))

    def connect(self, proc, procs):
        # Matched both ways, not only seen in the graph: the graph (ros_discovery_info) can
        # list the controller's publishers before this test's readers have matched them, and
        # an answer published then is lost (the watchdog's stale answer 2 s later was the one
        # received).
        self.wait(self.matched, 30.0, 'the controller to connect (log: %s)' % procs.log(proc),
                  spin=self.spin)
        # Spinning, not only matched: the node's executor (rclpy's EventsExecutor, the
        # config's) registers its subscriptions from an unordered set when it first spins,
        # so a setpoint and a state that reached the node before then can be answered state
        # first - a one-tick hold, "no setpoint yet" (the in-process
        # test_a_setpoint_delivered_before_a_state_...). A parameter call answered means the
        # executor has registered every subscription: from then on messages are taken in the
        # order they arrive.
        from freejoint_tools.harness import ParameterCalls
        ParameterCalls(self.node, 'controller_node').get_parameters(['case'])


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
        assert list(st.law_state[:5]) == out.internal['theta_hat'].tolist()
        assert list(st.position) == out.p.tolist()
        assert list(st.position_desired) == list(_setpoint(k)[0:2])
        assert st.det_dd == out.internal['det'] and st.status == 0 and st.message == ''
        assert list(st.joint_names) == ['joint1', 'joint2']
    # A repeated state gets the cached answer: no second theta update.
    q, qd = _state_q(3)
    drv.joint_state(3, q, qd)
    wait(lambda: len(drv.states[3 * DT_NS]) >= 2, 15.0, 'the repeated answer', spin=drv.spin)
    assert list(drv.states[3 * DT_NS][1].law_state[:5]) == ctl.theta.tolist()
    k = 4
    q, qd = _state_q(k)
    drv.setpoint(k, _setpoint(k))
    drv.joint_state(k, q, qd)
    st, cmd = drv.answer(k)
    assert cmd == _expect(ctl, q, qd, _setpoint(k)).tau.tolist()
    assert procs.stop(proc) == 0


def test_set_parameters_changes_the_next_tick_and_a_bad_value_is_refused(
        procs, ros_node, wait):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    proc = _start(procs)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    params = ParameterCalls(ros_node, 'controller_node')
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    q, qd = _state_q(0)
    drv.setpoint(0, _setpoint(0))
    drv.joint_state(0, q, qd)
    drv.answer(0)
    _expect(ctl, q, qd, _setpoint(0))

    (res,) = params.set_parameters([Parameter('K', value=[40.0, 60.0])])
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
           (Parameter('Lambda', value=[0.0, 1.0]), r'^Lambda: values must be finite and > 0'),
           (Parameter('K', value=[1e300, 1e300]), r'^K: values must be <= 10000'),
           (Parameter('effort_limits', value=[1.0]), r'^effort_limits: expected 2 values'),
           (Parameter('on_stale_setpoint', value='drop'), r'^on_stale_setpoint: expected'),
           (Parameter('state_publish_rate', value=-1.0),
            r'^Parameter state_publish_rate out of range')]
    for param, reason in bad:
        (res,) = params.set_parameters([param])
        assert not res.successful
        assert re.match(reason, res.reason), res.reason
    # Out of its descriptor's range: refused by rclpy with the range in the reason.
    (res,) = params.set_parameters([Parameter('epsilon', value=-0.5)])
    assert not res.successful and 'epsilon' in res.reason

    # Still running, on the last good values (K = 40, 60).
    q, qd = _state_q(2)
    drv.setpoint(2, _setpoint(2))
    drv.joint_state(2, q, qd)
    _, cmd = drv.answer(2)
    assert cmd == _expect(ctl, q, qd, _setpoint(2)).tau.tolist()

    # The robust switch and theta0 (which restarts theta_hat) also act on the next tick.
    (res,) = params.set_parameters([Parameter('robust', value=False)])
    assert res.successful, res.reason
    ctl.set_gains(Gains(K=(40.0, 60.0), robust=False))
    q, qd = _state_q(3)
    drv.setpoint(3, _setpoint(3))
    drv.joint_state(3, q, qd)
    st, cmd = drv.answer(3)
    assert cmd == _expect(ctl, q, qd, _setpoint(3)).tau.tolist()
    assert list(st.law_state[6:8]) == [0.0, 0.0]
    assert procs.stop(proc) == 0


FILE = SCHEMA.yaml_values(PARAMS)  # what the node takes from config/controller.yaml
LIMITS = tuple(FILE['effort_limits'])
# The test's states are stamped by the test (old, a few): not a real-time loop to judge.
OLD_STAMPS = ('-p', 'max_state_age:=0.0', '-p', 'readiness_guard:=false')
"""Real time with the tests' stamps (from 0, i.e. 1970): no state is skipped as too old."""


def _finite_within(cmd, limits=LIMITS):
    return all(math.isfinite(x) and abs(x) <= lim for x, lim in zip(cmd, limits))


def _loop(**given):
    """Return the ROS-free loop of the node's configuration (config/controller.yaml + given)."""
    from freejoint_control.loop import ControlLoop
    return ControlLoop(SCHEMA.config(dict(FILE, **given)))


def test_a_bad_start_up_parameter_exits_2_with_the_reason(procs):
    # Lockstep has no delay to compensate: refused at start-up with the reason.
    proc = _start(procs, '-p', 'delay_compensation:=predict')
    assert proc.wait(30.0) == 2
    assert "delay_compensation: 'predict' is for real time" in procs.log(proc)


def test_reset_service_restarts_theta_hat(procs, ros_node, wait):
    from freejoint_common.contract import RESET
    from freejoint_tools.harness import ServiceCalls
    proc = _start(procs)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    ctl = RobustController(table1('horizontal').scaled(0.7),
                           Gains(tau_limit=LIMITS, theta_max=(100.0,) * 5))
    qd = (1.0, -2.0, 3.0)          # fast: theta_hat grows
    for k in range(5):
        drv.setpoint(k, _setpoint(k))
        drv.joint_state(k, Q0, qd)
        st, cmd = drv.answer(k)
        assert cmd == _expect(ctl, Q0, qd, _setpoint(k)).tau.tolist()
    assert max(st.law_state[:5]) > 0.0
    # Sent again after 3 s unanswered (rmw_fastrtps#390: a response sent before the server
    # matched the client's response reader is dropped); a second reset with no state in
    # between leaves the controller as one does.
    answer = ServiceCalls(ros_node).call(RESET.srv_type, RESET.of('controller_node'),
                                         RESET.srv_type.Request(), 15.0, resend=3.0)
    assert answer is not None and answer.success, 'no answer from ~/reset'
    assert 'theta_hat reset to theta0' in answer.message
    ctl.reset()
    drv.setpoint(5, _setpoint(5))
    drv.joint_state(5, Q0, qd)
    st, cmd = drv.answer(5)
    out = _expect(ctl, Q0, qd, _setpoint(5))
    assert list(st.law_state[:5]) == out.internal['theta_hat'].tolist()
    # The rate limit armed by the reset: ramped from the previous command.
    assert st.status & STATUS_RATE_LIMITED or cmd == out.tau.tolist()
    assert procs.stop(proc) == 0


def test_state_publish_rate_thins_controller_state_but_not_the_commands(ros_node, monkeypatch):
    """
    In-process, lockstep: 12 ticks 1 ms apart at ``state_publish_rate`` 200 Hz.

    Every state gets its command; ControllerStates at 0, 5 and 10 ms of stamps. Set to 0
    while running: every answer from the next on gets one.
    """
    from rclpy.parameter import Parameter
    from freejoint_control.controller_node import ControllerNode
    node = ControllerNode(parameter_overrides=[Parameter('case', value='vertical'),
                                               Parameter('state_publish_rate', value=200.0)])
    try:
        commands, states = [], []
        monkeypatch.setattr(node._pub_cmd, 'publish', commands.append)
        monkeypatch.setattr(node._pub_state, 'publish', lambda data: states.append(
            to_ns(_controller_state(data).header.stamp)))
        node._on_setpoints(_batch(range(16)))
        for k in range(12):
            _serialized_state(node, k)
        assert len(commands) == 12
        assert states == [0, 5 * DT_NS, 10 * DT_NS]
        assert node.set_parameters([Parameter('state_publish_rate', value=0.0)])[0].successful
        for k in range(12, 16):
            _serialized_state(node, k)
        assert len(commands) == 16
        assert states[3:] == [k * DT_NS for k in range(12, 16)]
    finally:
        node.destroy_node()


def test_the_node_publishes_its_readiness_at_start_up_and_at_each_change(ros_node, monkeypatch):
    """
    In-process: lockstep ready from the start, real time not until its good windows.

    Then each change: a stall of the states makes it not ready, the stop command sent first.
    """
    from rclpy.parameter import Parameter
    from freejoint_control.controller_node import ControllerNode
    from freejoint_control.loop import STATUS_STOPPED
    sent = []
    monkeypatch.setattr(ControllerNode, '_publish_readiness',
                        lambda self, ns, ready, reason: sent.append((ns, ready, reason)))
    node = ControllerNode(parameter_overrides=[Parameter('case', value='vertical')])
    node.destroy_node()
    assert [s[1:] for s in sent] == [(True, '')]
    del sent[:]
    node = ControllerNode(parameter_overrides=[Parameter('case', value='vertical'),
                                               Parameter('lockstep', value=False),
                                               Parameter('max_state_age', value=0.0)])
    try:
        assert [s[1:] for s in sent] == [(False, 'real-time loop not judged yet: waiting for 5 '
                                          'good windows of 0.2 s')]
        commands = []
        monkeypatch.setattr(node._pub_cmd, 'publish', commands.append)
        now = [0]
        monkeypatch.setattr(node, '_now_ns', lambda: now[0])
        for k in range(1100):              # on time: ready at the fifth window (1 s)
            now[0] = k * DT_NS
            _serialized_state(node, k)
        assert sent[1] == (1000 * DT_NS, True, '') and len(sent) == 2
        n = len(commands)
        now[0] = 1115 * DT_NS              # 15 states missed (> 10, the vertical arm's gap)
        _serialized_state(node, 1115)
        assert sent[2] == (1115 * DT_NS, False, 'real-time loop not ready: 15 consecutive '
                           'states not answered, more than the 10 the law rides through')
        assert len(commands) == n + 1      # the stop command, then nothing
        assert node._loop.result.status == STATUS_STOPPED
        now[0] = 1116 * DT_NS
        _serialized_state(node, 1116)
        assert len(commands) == n + 1 and len(sent) == 3
    finally:
        node.destroy_node()


@pytest.mark.parametrize('kind', ['single_threaded', 'events'])
def test_a_setpoint_delivered_before_a_state_is_applied_before_the_state_is_answered(
        ros_node, wait, monkeypatch, kind):
    """
    In-process: setpoint 0 then state 0, both in the node's readers before it answers.

    Single-threaded executor: both acknowledged by the node's readers before its executor
    runs at all, so one wait finds both ready; the state must be answered with setpoint 0,
    not held as "no setpoint yet" (the executor takes them in the order the subscriptions
    were made). Events executor (the config's): with the node spinning first - before, it
    registers the subscriptions from an unordered set, and a state and a setpoint both
    waiting then may be answered state first (a one-tick hold at start-up) - the messages
    are taken in the order they arrived.
    """
    from rclpy.duration import Duration
    from rclpy.parameter import Parameter
    from freejoint_common.runner import make_executor
    from freejoint_control.controller_node import ControllerNode
    node = ControllerNode(parameter_overrides=[
        Parameter('case', value='vertical'), Parameter('lockstep', value=False),
        Parameter('stale_timeout', value=2.0), Parameter('max_state_age', value=0.0),
        Parameter('readiness_guard', value=False)])
    executor = make_executor(kind)
    executor.add_node(node)
    if kind == 'events':
        executor.spin_once(timeout_sec=0.05)    # its first event: registering the entities
    try:
        states = []
        monkeypatch.setattr(node._pub_cmd, 'publish', lambda msg: None)
        monkeypatch.setattr(node._pub_state, 'publish', lambda data: states.append(
            (lambda msg: (msg.status, msg.message, list(msg.effort),
                          to_ns(msg.setpoint_stamp)))(_controller_state(data))))
        drv = Driver(ros_node, wait)
        wait(drv.matched, 30.0, 'the in-process controller to match', spin=drv.spin)
        q, qd = Q0, QD0
        drv.setpoint(0, _setpoint(0))
        assert drv.pub_sp.wait_for_all_acked(Duration(seconds=15.0)), 'setpoint not acked'
        drv.joint_state(0, q, qd)
        assert drv.pub_js.wait_for_all_acked(Duration(seconds=15.0)), 'state not acked'
        wait(lambda: states, 15.0, 'the answer to state 0',
             spin=lambda: executor.spin_once(timeout_sec=0.05))
        status, message, effort, sp_ns = states[0]
        assert not status & STATUS_HOLDING and 'no setpoint yet' not in message, message
        assert sp_ns == 0
        loop = _loop(case='vertical', lockstep=False, stale_timeout=2.0, max_state_age=0.0,
                     readiness_guard=False)
        loop.on_setpoint(0, _setpoint(0), 0, 0.0)
        assert effort == loop.on_state(0, NAMES, q, qd, 0, 0.0).effort
    finally:
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_node()


def test_a_batch_of_setpoints_is_applied_one_by_one_and_a_refused_one_alone_is_dropped(
        ros_node, monkeypatch):
    """
    In-process, lockstep, no DDS delivery: the node's ``setpoints`` callback called directly.

    A batch of ticks 0..3 whose tick-2 position is not finite: ticks 0, 1 and 3 are taken,
    tick 2 is refused and counted; state 2 then waits for its setpoint, and a batch carrying
    it answers the waiting state at once, with the command a separate loop gives for the
    same inputs. A batch whose arrays do not fit its stamps, or whose vectors are not the
    task's 2 values, is refused (every stamp counted) and answers nothing.
    """
    from rclpy.parameter import Parameter
    from freejoint_control.controller_node import ControllerNode
    node = ControllerNode(parameter_overrides=[Parameter('case', value='vertical')])
    try:
        answers = []
        monkeypatch.setattr(node._pub_cmd, 'publish', lambda msg: None)
        monkeypatch.setattr(node._pub_state, 'publish', lambda data: answers.append(
            (lambda msg: (to_ns(msg.header.stamp), to_ns(msg.setpoint_stamp),
                          list(msg.effort)))(_controller_state(data))))
        node._on_setpoints(_batch([0, 1, 2, 3], bad=(2,)))
        assert node._loop.refused_setpoints == 1
        for k in (0, 1):
            _serialized_state(node, k)
        assert [a[:2] for a in answers] == [(0, 0), (DT_NS, DT_NS)]
        _serialized_state(node, 2)
        assert len(answers) == 2, 'state 2 answered without its setpoint'
        short = _batch([2, 5])
        short.velocity = [0.0]
        node._on_setpoints(short)           # both its setpoints counted
        node._on_setpoints(_batch([2], m=3))
        assert node._loop.refused_setpoints == 4 and len(answers) == 2
        node._on_setpoints(_batch([2]))
        assert [a[:2] for a in answers[2:]] == [(2 * DT_NS, 2 * DT_NS)]
        _serialized_state(node, 3)
        assert [a[:2] for a in answers[3:]] == [(3 * DT_NS, 3 * DT_NS)]
        loop = _loop(case='vertical')
        for k in range(4):
            loop.on_setpoint(k * DT_NS, _setpoint(k), 0, 0.0)
            assert answers[k][2] == loop.on_state(k * DT_NS, NAMES, Q0, QD0, 0, 0.0).effort
        # A joint_states message that cannot be read: refused, counted, nothing answered.
        node._on_joint_state(b'\x00\x01\x00\x00\x01\x02')
        assert node._loop.refused_states == 1 and len(answers) == 4
    finally:
        node.destroy_node()


def _batch(ks, bad=(), m=2):
    """Return the CartesianSetpoints of ticks ``ks`` (``bad``: a NaN position; m values)."""
    from freejoint_msgs.msg import CartesianSetpoints
    values = [_setpoint(k) for k in ks]
    pos = [v for k, s in zip(ks, values) for v in (
        (math.nan, 0.0) if k in bad else s[0:2]) + (0.0,) * (m - 2)]
    return CartesianSetpoints(
        stamps=[k * DT_NS for k in ks], position=pos,
        velocity=[v for s in values for v in s[2:4] + (0.0,) * (m - 2)],
        acceleration=[v for s in values for v in s[4:6] + (0.0,) * (m - 2)])


def _serialized_state(node, k):
    """Give the node in this process the state of tick k, serialized as it takes it (raw)."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    msg = JointState(name=NAMES, position=list(Q0), velocity=list(QD0))
    stamp_from_ns(k * DT_NS, msg.header.stamp)
    node._on_joint_state(serialize_message(msg))


def _controller_state(data):
    """Return the ControllerState the node published serialized, deserialized by rclpy."""
    from freejoint_msgs.msg import ControllerState
    from rclpy.serialization import deserialize_message
    return deserialize_message(data, ControllerState)


JS_RELIABILITY = 'qos_overrides./joint_states.subscription.reliability'


@pytest.mark.parametrize('override', [True, False], ids=['override', 'no_override'])
def test_a_best_effort_joint_states_driver_drives_the_controller_only_with_the_qos_override(
        override, procs, ros_node, wait):
    """A sensor-data (best-effort) joint_states, as many real drivers publish it."""
    from freejoint_tools.harness import ParameterCalls
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    extra = ('-p', JS_RELIABILITY + ':=best_effort') if override else ()
    proc = _start(procs, '-p', 'lockstep:=false', *OLD_STAMPS, *extra)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)      # the controller is up: its reliable joint_states matched
    params = ParameterCalls(ros_node, 'controller_node', timeout=30.0).get_values([
        JS_RELIABILITY, 'qos_overrides./joint_states.subscription.depth',
        'qos_overrides./joint_states.subscription.history',
        'qos_overrides./setpoints.subscription.reliability',
        'qos_overrides./effort_controller/commands.publisher.reliability',
        'qos_overrides./controller_state.publisher.depth'])
    assert params == {
        JS_RELIABILITY: 'best_effort' if override else 'reliable',
        'qos_overrides./joint_states.subscription.depth': 1,     # real time: newest only
        'qos_overrides./joint_states.subscription.history': 'keep_last',
        'qos_overrides./setpoints.subscription.reliability': 'reliable',
        'qos_overrides./effort_controller/commands.publisher.reliability': 'reliable',
        'qos_overrides./controller_state.publisher.depth': 1000}
    sensor = ros_node.create_publisher(JointState, 'joint_states', qos_profile_sensor_data)
    drv.pub_js = sensor           # the driver's states now go out best effort only
    if override:
        wait(lambda: sensor.get_subscription_count() > 0, 30.0,
             'the best-effort publisher to match the controller', spin=drv.spin)
        for k in range(3):
            # Best effort: a state sent before the controller matched this publisher is
            # lost, not queued, so it is sent again until answered.
            ns = drv.ns(k)
            wait(lambda: drv.joint_state(k, Q0, (0.0, 0.0, 0.0)) or (
                drv.spin() or ns in drv.states), 15.0,
                 'the answer to best-effort state %d' % k)
            st, cmd = drv.answer(k, 'the answer to a best-effort state')
            assert st.status & STATUS_HOLDING and _finite_within(cmd), st.message
    else:
        # Reliable subscription, best-effort publisher: incompatible QoS, no match, so the
        # states never reach the controller (documented; the override is the remedy).
        for _ in range(40):
            drv.spin()
        assert sensor.get_subscription_count() == 0, 'matched without the override'
        for k in range(3):
            drv.joint_state(k, Q0, (0.0, 0.0, 0.0))
        for _ in range(20):
            drv.spin()
        assert not drv.states and not drv.commands
    assert procs.stop(proc) == 0


class Diagnostics:
    """The controller's statuses on /diagnostics: (level, message, {key: value})."""

    NAME = 'controller_node: controller'

    def __init__(self, node):
        self.statuses = []
        node.create_subscription(DIAGNOSTICS.msg_type, DIAGNOSTICS.name, self._on_array,
                                 DIAGNOSTICS.qos)

    def _on_array(self, msg):
        for status in msg.status:
            if status.name == self.NAME:
                self.statuses.append((ord(status.level), status.message,
                                      {v.key: v.value for v in status.values}))

    def find(self, level, text):
        """Return the last status of ``level`` whose message has ``text``, or None."""
        found = [s for s in self.statuses if s[0] == level and text in s[1]]
        return found[-1] if found else None


def test_a_loop_not_ready_at_rest_asks_the_driver_to_brake_once_on_brake_request(
        procs, ros_node, wait):
    from freejoint_common.contract import BRAKE_REQUEST
    # Real time with the guard on (it starts not judged: no command) and no plan.
    proc = _start(procs, '-p', 'lockstep:=false', '-p', 'max_state_age:=0.0')
    diag = Diagnostics(ros_node)
    drv = Driver(ros_node, wait)
    asked = []
    ros_node.create_subscription(BRAKE_REQUEST.msg_type, BRAKE_REQUEST.name,
                                 lambda msg: asked.append(msg.data), BRAKE_REQUEST.qos)
    drv.connect(proc, procs)
    wait(lambda: ros_node.count_publishers(BRAKE_REQUEST.name) >= 1, 15.0,
         'the brake_request publisher', spin=drv.spin)
    k = 0

    def stepping():
        nonlocal k
        drv.joint_state(k, Q0, (0.0, 0.0, 0.0))
        k += 1
        drv.spin()

    wait(lambda: asked, 15.0, 'a brake request', spin=stepping)
    assert asked[0] == ('real-time loop not judged yet: waiting for 5 good windows of 0.2 s: '
                        'brake now')
    # Once per stop, however many states it leaves unanswered; never a command (nothing
    # computed was sent: the start-up brakes stay on).
    target = k + 20
    wait(lambda: diag.statuses and int(diag.statuses[-1][2].get(
        'states not answered (stopped)', 0)) >= target, 15.0, '20 more states withheld',
        spin=stepping)
    assert len(asked) == 1 and not drv.commands
    assert diag.statuses[-1][2]['brake requests'] == '1'
    assert diag.statuses[-1][2]['stop commands'] == '0'
    assert procs.stop(proc) == 0


def test_the_node_publishes_its_loops_diagnostics_no_state_then_holding_then_silent(
        procs, ros_node, wait):
    import time
    from freejoint_common.contract import BRAKE_TIMEOUT_REQUEST
    warn, error = 1, 2
    proc = _start(procs, '-p', 'lockstep:=false', *OLD_STAMPS)
    diag = Diagnostics(ros_node)
    asked = []     # holding (no setpoint): the driver asked for the short watchdog, once
    ros_node.create_subscription(BRAKE_TIMEOUT_REQUEST.msg_type, BRAKE_TIMEOUT_REQUEST.name,
                                 lambda msg: asked.append(msg.data), BRAKE_TIMEOUT_REQUEST.qos)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    # No state yet: the arm is not controlled.
    wait(lambda: diag.find(error, 'no joint_states yet on /joint_states'), 10.0,
         'ERROR: no joint_states yet', spin=drv.spin)
    drv.offset_ns = time.time_ns()
    q, qd = Q0, (0.0, 0.0, 0.0)
    k = 0

    def run_until(found, what, values_of, timeout=30.0):
        nonlocal k
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            drv.setpoints_ahead(k, values_of)
            drv.joint_state(k, q, qd)
            k += 1
            for _ in range(3):       # the state, the command, now and then a status
                drv.rclpy.spin_once(drv.node, timeout_sec=0.001)
            status = found()
            if status is not None:
                return status
        raise AssertionError('timed out after %g s waiting for %s (statuses: %s)'
                             % (timeout, what, diag.statuses[-3:]))

    level, message, values = run_until(
        lambda: diag.find(warn, 'holding at'), 'WARN: holding', lambda j: None)
    assert 'no setpoint yet' in message, message
    # (>= 1: a stall of this test beyond stale_timeout between states - the watchdog's zero
    # effort - makes the next state a new hold; no setpoint yet: never a stale period.)
    assert int(values['holds']) >= 1 and values['stale setpoint periods'] == '0', values
    assert float(values['answer rate [Hz]']) > 0.0 and values['latency max [ms]'] != '-'
    assert int(values['status']) & STATUS_HOLDING
    wait(lambda: asked, 5.0, 'the brake_timeout_request', spin=drv.spin)
    assert asked == [0.01]
    # Tracking, a stale stream and their counts: the loop's diagnostics in one process
    # (test/control/test_loop.py::test_diagnostics_say_holding_then_tracking_then_stale_then_
    # no_state); here, that the node publishes them and its own silence check.
    # No more states: ERROR, zero effort.
    wait(lambda: diag.find(error, 'no joint_states for'), 10.0, 'ERROR: no joint_states',
         spin=drv.spin)
    assert procs.stop(proc) == 0
