"""
The controller node in its own process, driven by this test as simulator and planner.

Every answer is compared with ``RobustController`` stepped here on the same inputs: the
node must compute exactly the core law, whatever the JointState's joint order, and take
parameter changes on the next tick.
"""
import math
import os
import re

from freejoint_common.contract import COMMANDS, CONTROLLER_STATE, DIAGNOSTICS, JOINT_STATES
from freejoint_common.contract import profile, SETPOINT, stamp_from_ns, stamp_label, to_ns
from freejoint_control.params import SCHEMA
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
        self.pub_sp = node.create_publisher(SETPOINT.msg_type, SETPOINT.name, _qos(True))
        self.subs = (
            node.create_subscription(CONTROLLER_STATE.msg_type, CONTROLLER_STATE.name,
                                     self._on_state, _qos()),
            node.create_subscription(COMMANDS.msg_type, COMMANDS.name, self._on_command,
                                     _qos()))
        self.JointState = JOINT_STATES.msg_type
        self.CartesianSetpoint = SETPOINT.msg_type

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
        msg = self.CartesianSetpoint()
        self.stamp(msg, k)
        msg.position = list(values[0:2])
        msg.velocity = list(values[2:4])
        msg.acceleration = list(values[4:6])
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
           (Parameter('Lambda', value=[0.0, 1.0]), r'^Lambda: values must be finite and > 0')]
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
    assert drv.commands[stamp_label(DT_NS)][-1] == [0.0, 0.0]
    assert 'no joint_states for 0.3 s: zero effort' in procs.log(proc)
    assert procs.stop(proc) == 0


# -- hold, resume, limits, dt from stamps, reset, faults (issues 10 and 11) ------------------
FILE = SCHEMA.yaml_values(PARAMS)  # what the node takes from config/controller.yaml
LIMITS = tuple(FILE['effort_limits'])
STALE_JUMP_NS = 2_100_000_000   # a jump of the stamps beyond the tests' stale_timeout 2 s
OLD_STAMPS = ('-p', 'max_state_age:=0.0')
"""Real time with the tests' stamps (from 0, i.e. 1970): no state is skipped as too old."""
RATE = FILE['effort_rate_limit']        # [N m/s]
STIFFNESS = FILE['hold_stiffness']


class Replica:
    """What the node must answer, from the core: law, hold / blend reference, limits."""

    def __init__(self, case, lockstep, resume=0.5, limits=LIMITS, rate=RATE, dt=DT,
                 resume_bounds=(1.0, 5.0), stiffness=STIFFNESS):
        from freejoint_core.reference import ReferenceShaper
        self.ctl = RobustController(table1(case).scaled(0.7),
                                    Gains(tau_limit=limits, theta_max=(100.0,) * 5))
        self.shaper = ReferenceShaper(resume, not lockstep, *resume_bounds)
        self.lockstep = lockstep
        self.stiffness = stiffness
        self.limits = limits
        self.rate = rate
        self.dt = dt
        self.prev = None if lockstep else [0.0, 0.0]
        self.armed = not lockstep
        self.last_ns = -1
        self.late = False

    def fk(self, q):
        return self.ctl.model.fk(q).tolist()

    def tick(self, ns, q, qd, sp, sp_ns=None):
        """
        Return (effort, reference, dt, ControlOutput) for the state stamped ns.

        ``sp_ns``: the stamp of ``sp`` when older than the state (real time: carried
        forward to the state's time, late beyond 10 periods).
        """
        from freejoint_core.reference import (clamp_dt, extrapolate, limit_effort,
                                              MODE_HOLD, MODE_NONE)
        if self.lockstep or self.last_ns < 0:
            dt = self.dt
        else:
            dt = clamp_dt((ns - self.last_ns) * 1e-9, self.dt)[0]
        if sp is not None and not self.lockstep:
            age = ns - (ns if sp_ns is None else sp_ns)
            if age > 0:
                sp = extrapolate(sp, age * 1e-9)
            late = age > 10 * DT_NS
            if not late and self.late:
                self.shaper.restart_blend()
            self.late = late
        if sp is None:
            self.late = False
            if self.shaper.mode != MODE_HOLD:
                ref = self.shaper.hold(self.fk(q))
                self.armed = self.prev is not None
            else:
                ref = self.shaper.hold(None)
        else:
            p_now = self.fk(q) if self.shaper.mode == MODE_NONE else None
            ref, _ = self.shaper.track(ns * 1e-9, sp, p_now)
        scale = self.shaper.stiffness(self.stiffness)
        if scale != self.ctl.stiffness:
            self.ctl.set_stiffness(scale)
        out = self.ctl.step(q, qd, ref[0:2], ref[2:4], ref[4:6], dt)
        effort = out.tau.tolist()
        if self.armed:
            effort, _, rated = limit_effort(effort, self.limits, self.prev, self.rate * dt)
            self.armed = rated
        self.prev = effort
        self.last_ns = ns
        return effort, ref, dt, out

    def zero(self, ns):
        """Note that the node answered ns with zero effort."""
        self.prev = [0.0, 0.0]
        self.armed = True
        self.last_ns = ns

    def reset(self):
        self.ctl.reset()
        self.shaper.reset()
        self.armed = self.prev is not None


def _finite_within(cmd, limits=LIMITS):
    return all(math.isfinite(x) and abs(x) <= lim for x, lim in zip(cmd, limits))


def _moving_setpoint(k, base):
    """Return a setpoint moving at 0.1 m/s along x from `base` (3 cm away at k = 0)."""
    return (base[0] + 0.03 + 1e-4 * k, base[1] - 0.02, 0.1, 0.0, 0.0, 0.0)


def test_real_time_controller_holds_against_gravity_before_the_first_setpoint_and_resumes_without_a_step(  # noqa: E501
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'case:=vertical', '-p', 'lockstep:=false', *OLD_STAMPS,
                  '-p', 'resume_time:=0.05', '-p', 'stale_timeout:=2.0',
                  '-p', 'resume_max_velocity:=100.0', '-p', 'resume_max_acceleration:=1e4')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('vertical', lockstep=False, resume=0.05, resume_bounds=(100.0, 1e4))
    q, qd = Q0, (0.0, 0.0, 0.0)
    hold = rep.fk(q)
    base = hold
    prev_cmd = [0.0, 0.0]
    refs = []
    for k in range(160):
        def values_of(j):
            return _moving_setpoint(j, base) if 10 <= j < 80 or j >= 120 else None
        sp = values_of(k)
        drv.setpoints_ahead(k, values_of)
        if k == 100:
            q = (Q0[0] + 0.01, Q0[1], Q0[2])       # the arm moved: a new hold starts here
            drv.offset_ns = STALE_JUMP_NS          # and 2.1 s of stamps passed meanwhile
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        # Between 80 and 100 the setpoint of tick 79 is still fresh (< stale_timeout).
        used = _moving_setpoint(min(k, 79), base) if 80 <= k < 100 else sp
        effort, ref, dt, out = rep.tick(drv.ns(k), q, qd, used,
                                        drv.ns(79) if 80 <= k < 100 else None)
        assert cmd == effort, k
        assert list(st.position_desired) == list(ref[0:2]), k
        assert list(st.theta_hat) == out.theta.tolist(), k
        assert st.dt == dt
        assert _finite_within(cmd)
        if k in (0, 100):
            # No torque jump at the start (from zero) nor at the onset of a hold.
            assert max(abs(a - b) for a, b in zip(cmd, prev_cmd)) <= RATE * dt + 1e-9, k
        prev_cmd = cmd
        refs.append(list(ref[0:2]))
        holding = bool(st.status & STATUS_HOLDING)
        if k < 10:
            # Before the first setpoint: hold where the arm is, against gravity (not zero).
            assert holding and not st.status & STATUS_STALE_SETPOINT, st.message
            assert list(st.position_desired) == hold
            assert 'holding at' in st.message and 'no setpoint yet' in st.message
            assert st.setpoint_stamp.sec == 0 and st.setpoint_stamp.nanosec == 0
        elif k < 60 or 120 <= k < 170:
            assert st.status & STATUS_RESUMING and not holding, (k, st.message)
            assert to_ns(st.setpoint_stamp) == drv.ns(k)
        elif 100 <= k < 120:
            # Stale: held at fk(q) of the first stale tick, not zero effort.
            assert holding and st.status & STATUS_STALE_SETPOINT, (k, st.message)
            assert list(st.position_desired) == rep.fk(q)
            assert 'stale setpoint' in st.message
        else:
            assert not holding and not st.status & STATUS_RESUMING, (k, st.message)
        if 80 <= k < 100:
            assert st.setpoint_age == pytest.approx((k - 79) * DT, abs=1e-12)
        assert st.state_age > 0.0
    # Gravity is held: the hold efforts are the vertical arm's, far from zero.
    assert max(abs(x) for x in drv.commands[stamp_label(9 * DT_NS)][0]) > 5.0
    # The reference has no step: per 1 ms tick at most what the 50 ms quintic blend of the
    # 3.6 cm offset and the 0.1 m/s stream give ((1.875 x 0.036 / 0.05 + 0.1) m/s x 1 ms =
    # 1.45 mm, a little more with the velocity offset); a step would be the 36 mm offset.
    steps = [math.dist(a, b) for a, b in zip(refs, refs[1:])]
    assert max(steps[:99]) < 2e-3 and max(steps[101:]) < 2e-3
    assert procs.stop(proc) == 0


def test_lockstep_holds_when_setpoints_go_stale_and_answers_at_once_while_holding(
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'case:=vertical', '-p', 'stale_timeout:=1.0')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('vertical', lockstep=True)
    q, qd = Q0, QD0
    drv.setpoint(0, _setpoint(0))
    drv.joint_state(0, q, qd)
    st, cmd = drv.answer(0)
    effort, _, _, _ = rep.tick(0, q, qd, _setpoint(0))
    assert cmd == effort and st.status == 0
    # State 1 without its setpoint: after stale_timeout, the hold (the law, not zero).
    q1 = (Q0[0] + 0.002, Q0[1], Q0[2])
    drv.joint_state(1, q1, qd)
    st, cmd = drv.answer(1, 'the hold answer')
    effort, ref, _, out = rep.tick(DT_NS, q1, qd, None)
    assert cmd == effort and cmd != [0.0, 0.0]
    assert st.status & STATUS_HOLDING and st.status & STATUS_STALE_SETPOINT, st.message
    assert list(st.position_desired) == rep.fk(q1)
    assert list(st.theta_hat) == out.theta.tolist()
    wait(lambda: 'holding position' in procs.log(proc), 10.0, 'the hold in the log')
    # While holding, a state without setpoint is answered (no stale_timeout per tick), with
    # the same frozen reference.
    drv.joint_state(2, q, qd)
    st, cmd = drv.answer(2)
    effort, _, _, _ = rep.tick(2 * DT_NS, q, qd, None)
    assert cmd == effort and list(st.position_desired) == rep.fk(q1)
    # The setpoints return: the reference blends from the hold.
    for k in (3, 4):
        drv.setpoint(k, _setpoint(k))
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        effort, ref, _, _ = rep.tick(k * DT_NS, q, qd, _setpoint(k))
        assert cmd == effort and st.status & STATUS_RESUMING
        assert list(st.position_desired) == list(ref[0:2])
    assert list(drv.states[3 * DT_NS][0].position_desired) == pytest.approx(
        rep.fk(q1), abs=1e-15)
    assert procs.stop(proc) == 0


def test_real_time_dt_comes_from_the_state_stamps_bounded_to_four_periods(
        procs, ros_node, wait):
    from freejoint_msgs.msg import ControllerState as CS
    proc = _start(procs, '-p', 'lockstep:=false', *OLD_STAMPS, '-p', 'resume_time:=0.0',
                  '-p', 'stale_timeout:=2.0')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('horizontal', lockstep=False, resume=0.0)
    # A driver at 500 Hz (2 ms), then a 30 ms gap (clamped to 4 ms).
    ticks = ((0, DT), (2, 0.002), (4, 0.002), (6, 0.002), (36, 0.004), (38, 0.002))
    stamps = [k for k, _ in ticks]
    for k, want in ticks:
        q, qd = _state_q(k)
        drv.setpoints_ahead(k, lambda j: _setpoint(j) if j in stamps else None, ahead=32)
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        effort, _, dt, out = rep.tick(k * DT_NS, q, qd, _setpoint(k))
        assert dt == want and st.dt == want
        assert cmd == effort and list(st.theta_hat) == out.theta.tolist()
        assert bool(st.status & CS.STATUS_DT_CLAMPED) == (k == 36), st.message
    wait(lambda: 'outside [0.25, 4] x control_period' in procs.log(proc), 10.0,
         'the clamp warning')
    assert procs.stop(proc) == 0


def test_per_joint_effort_limits_clip_each_joint_and_bad_limits_or_gains_are_refused(
        procs, ros_node, wait):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    proc = _start(procs, '-p', 'effort_limits:=[5.0, 3.0]')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    for k in range(3):
        q, qd = _state_q(k)
        drv.setpoint(k, _setpoint(k))
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        tau = _expect(ctl, q, qd, _setpoint(k)).tau.tolist()
        assert cmd == [max(-5.0, min(5.0, tau[0])), max(-3.0, min(3.0, tau[1]))]
        assert abs(tau[0]) > 5.0 and st.status & ControllerState.STATUS_TORQUE_LIMITED
        assert 'torque limited to [5.0, 3.0] N m' in st.message
    params = ParameterCalls(ros_node, 'controller_node')
    bad = [(Parameter('effort_limits', value=[1.0]), r'^effort_limits: expected 2 values'),
           (Parameter('effort_limits', value=[-1.0, 2.0]), r'^effort_limits: expected 2'),
           (Parameter('K', value=[1e300, 100.0]), r'^K: values must be <= 10000'),
           (Parameter('K', value=[990.0, 100.0]), r'^K: K\[0\] \+ Lambda\[0\] = 1040'),
           (Parameter('Lambda', value=[1e5, 50.0]), r'^Lambda: values must be <= 10000'),
           (Parameter('R', value=[1e4, 2.0]), r'^R: values must be <= 1000'),
           (Parameter('Gamma', value=[1e9] * 5), r'^Gamma: values must be <= 1000'),
           (Parameter('sigma', value=[1e9] * 5), r'^sigma: values must be <= 1000'),
           (Parameter('theta0', value=[1e3] * 5), r'^theta0: values must be <= theta_max'),
           (Parameter('theta_max', value=[1e300] * 5), r'^theta_max: expected 5 values'),
           (Parameter('joint_velocity_limit', value=[1.0]), r'^joint_velocity_limit: exp'),
           (Parameter('on_stale_setpoint', value='drop'), r'^on_stale_setpoint: expected')]
    for param, reason in bad:
        (res,) = params.set_parameters([param])
        assert not res.successful and re.match(reason, res.reason), (param.name, res.reason)
    (res,) = params.set_parameters([Parameter('effort_limits', value=[2.0, 300.0])])
    assert res.successful, res.reason
    q, qd = _state_q(3)
    drv.setpoint(3, _setpoint(3))
    drv.joint_state(3, q, qd)
    _, cmd = drv.answer(3)
    tau = _expect(ctl, q, qd, _setpoint(3)).tau.tolist()
    assert cmd == [max(-2.0, min(2.0, tau[0])), tau[1]]
    assert procs.stop(proc) == 0


def test_restarted_real_time_controller_ramps_its_torque_from_zero_without_a_spike(
        procs, ros_node, wait):
    # As after kill -9 mid-circle: the arm moves, 3.6 cm off the stream, vertical.
    proc = _start(procs, '-p', 'case:=vertical', '-p', 'lockstep:=false', *OLD_STAMPS,
                  '-p', 'stale_timeout:=2.0')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('vertical', lockstep=False)
    base = rep.fk(Q0)
    prev = [0.0, 0.0]
    limited = []
    for k in range(30):
        q = tuple(v + 1e-4 * k for v in Q0)
        qd = (0.1, -0.1, 0.5)
        drv.setpoints_ahead(k, lambda j: _moving_setpoint(j, base))
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        effort, _, _, _ = rep.tick(k * DT_NS, q, qd, _moving_setpoint(k, base))
        assert cmd == effort, (k, st.status, st.dt, st.setpoint_stamp.nanosec, st.message)
        assert max(abs(a - b) for a, b in zip(cmd, prev)) <= RATE * DT + 1e-9
        limited.append(bool(st.status & STATUS_RATE_LIMITED))
        prev = cmd
    assert limited[0], 'the first command after the start was not rate limited'
    assert not limited[-1], 'the command never caught up with the law'
    assert procs.stop(proc) == 0


def test_reset_service_restarts_theta_hat_and_the_hold(procs, ros_node, wait):
    from freejoint_common.contract import RESET
    from freejoint_tools.harness import ServiceCalls
    proc = _start(procs, '-p', 'lockstep:=false', *OLD_STAMPS, '-p', 'resume_time:=0.01',
                  '-p', 'stale_timeout:=2.0')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('horizontal', lockstep=False, resume=0.01)
    q, qd = Q0, (1.0, -2.0, 3.0)          # fast: theta_hat grows
    for k in range(25):
        drv.setpoints_ahead(k, _setpoint)
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        effort, _, _, out = rep.tick(k * DT_NS, q, qd, _setpoint(k))
        assert cmd == effort, (k, st.status, st.dt, st.setpoint_stamp.nanosec, st.message)
    assert max(st.theta_hat) > 0.0 and not st.status & STATUS_RESUMING
    # Sent again after 3 s unanswered (rmw_fastrtps#390: a response sent before the server
    # matched the client's response reader is dropped); a second reset with no state in
    # between leaves the controller as one does.
    answer = ServiceCalls(ros_node).call(RESET.srv_type, RESET.of('controller_node'),
                                         RESET.srv_type.Request(), 15.0, resend=3.0)
    assert answer is not None and answer.success, 'no answer from ~/reset'
    assert 'theta_hat reset to theta0' in answer.message
    rep.reset()
    k = 25
    drv.setpoints_ahead(k, _setpoint)
    drv.joint_state(k, q, qd)
    st, cmd = drv.answer(k)
    effort, ref, _, out = rep.tick(k * DT_NS, q, qd, _setpoint(k))
    assert cmd == effort and list(st.theta_hat) == out.theta.tolist()
    # Blends in again from the arm's position, like a start.
    assert st.status & STATUS_RESUMING and list(st.position_desired) == rep.fk(q)
    assert procs.stop(proc) == 0


FAULTS = {
    'qd_1e10': ('state', lambda q, qd: (q, (qd[0], 1e10, qd[2])),
                'joint 1 velocity 10000000000.0'),
    'qd_1e160': ('state', lambda q, qd: (q, (1e160, qd[1], qd[2])),
                 'joint 0 velocity 1e+160'),
    'q_1e6': ('state', lambda q, qd: ((q[0], q[1], 1e6), qd), 'joint 2 position 1000000.0'),
    'setpoint_1e300': ('setpoint', None, 'beyond the reach'),
    'K_1e300': ('param', None, 'K: values must be <= 10000'),
}


@pytest.mark.parametrize('fault', sorted(FAULTS))
def test_absurd_input_is_refused_with_a_reason_and_tracking_resumes_within_half_a_second(
        procs, ros_node, wait, fault):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    kind, corrupt, reason = FAULTS[fault]
    proc = _start(procs, '-p', 'case:=vertical', '-p', 'lockstep:=false', *OLD_STAMPS,
                  '-p', 'resume_time:=0.01', '-p', 'stale_timeout:=2.0')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('vertical', lockstep=False, resume=0.01)
    q, qd = Q0, QD0
    clean = {0, ControllerState.STATUS_NEAR_SINGULAR}
    k_fault = 20

    def values_of(j):
        if kind == 'setpoint' and j == k_fault:
            return (1e300, 0.0, 0.0, 0.0, 0.0, 0.0)
        return _setpoint(j)
    for k in range(k_fault):
        drv.setpoints_ahead(k, values_of)
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        assert cmd == rep.tick(k * DT_NS, q, qd, _setpoint(k))[0]
    assert st.status in clean, st.message
    theta_before = list(st.theta_hat)
    k = k_fault
    drv.setpoints_ahead(k, values_of)
    if kind == 'state':
        bad_q, bad_qd = corrupt(q, qd)
        drv.joint_state(k, bad_q, bad_qd)
        st, cmd = drv.answer(k, 'the refusal')
        assert cmd == [0.0, 0.0] and st.status == STATUS_BAD_INPUT, st.message
        assert reason in st.message and list(st.theta_hat) == theta_before
        rep.zero(k * DT_NS)
        wait(lambda: 'implausible state' in procs.log(proc), 10.0, 'the refusal in the log')
    elif kind == 'setpoint':
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        # Dropped: the previous setpoint (1 ms old, still fresh) is tracked, carried
        # forward by its age.
        effort, ref, _, _ = rep.tick(k * DT_NS, q, qd, _setpoint(k - 1), (k - 1) * DT_NS)
        assert cmd == effort and list(st.position_desired) == list(ref[0:2])
        wait(lambda: reason in procs.log(proc), 10.0, 'the setpoint refusal in the log')
        assert 'setpoint stamped %d ns refused' % (k * DT_NS) in procs.log(proc)
    else:
        (res,) = ParameterCalls(ros_node, 'controller_node').set_parameters(
            [Parameter('K', value=[1e300, 1e300])])
        assert not res.successful and res.reason.startswith(reason), res.reason
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        assert cmd == rep.tick(k * DT_NS, q, qd, _setpoint(k))[0]
    assert _finite_within(cmd) and all(math.isfinite(x) for x in st.theta_hat)
    # Good input again: the law's own command (no hold, no ramp, no fault) within 0.5 s of
    # stamps, every effort finite and within the limits, theta_hat finite.
    resumed = None
    for k in range(k_fault + 1, k_fault + 1 + 500):
        drv.setpoints_ahead(k, values_of)
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        assert cmd == rep.tick(k * DT_NS, q, qd, _setpoint(k))[0]
        assert _finite_within(cmd) and all(math.isfinite(x) for x in st.theta_hat)
        if st.status in clean:
            resumed = k
            break
    assert resumed is not None, 'tracking did not resume within 0.5 s: %s' % st.message
    assert (resumed - k_fault) * DT <= 0.5
    assert procs.stop(proc) == 0


def test_delay_compensation_predict_runs_the_law_on_the_predicted_state_in_real_time(
        procs, ros_node, wait):
    from freejoint_core.delay import extrapolate_setpoint, StatePredictor
    from freejoint_core.reference import limit_effort
    # The test's stamps start at 0 (1970): the state age is huge, so the horizon is the
    # predictor's longest, max_ticks periods: deterministic.
    proc = _start(procs, '-p', 'case:=vertical', '-p', 'lockstep:=false', *OLD_STAMPS,
                  '-p', 'stale_timeout:=2.0', '-p', 'delay_compensation:=predict')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    ctl = RobustController(table1('vertical').scaled(0.7),
                           Gains(tau_limit=LIMITS, theta_max=(100.0,) * 5))
    ctl.set_stiffness(STIFFNESS)       # holding throughout: the stiffer hold
    pred = StatePredictor(table1('vertical').scaled(0.7), DT)
    m = pred.max_ticks
    # The arm at rest where the hold starts: the hold reference has no velocity, so the
    # reference shifted by the horizon is the hold itself.
    q, qd = Q0, (0.0, 0.0, 0.0)
    hold = ctl.model.fk(q).tolist()
    prev = [0.0, 0.0]
    armed = True
    for k in range(5):
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        assert st.status & STATUS_HOLDING, st.message
        q_pred, qd_pred = pred.predict(q, qd, m)
        p, v, a = extrapolate_setpoint(hold, (0.0, 0.0), (0.0, 0.0), m * DT)
        out = ctl.step(q_pred, qd_pred, p, v, a, DT)
        effort = out.tau.tolist()
        if armed:
            effort, _, armed = limit_effort(effort, LIMITS, prev, RATE * DT)
        pred.push(effort)
        prev = effort
        assert cmd == effort, k
        # Published: the measured position, the reference at the state's time.
        assert list(st.position) == hold and list(st.position_desired) == hold
    assert procs.stop(proc) == 0
    # Lockstep has no delay to compensate: refused at start-up with the reason.
    proc = _start(procs, '-p', 'delay_compensation:=predict')
    assert proc.wait(30.0) == 2
    assert "delay_compensation: 'predict' is for real time" in procs.log(proc)


def test_a_non_finite_law_result_is_never_published_and_theta_hat_is_restored(
        ros_node, monkeypatch):
    """In-process: the law fed, past the guards, the q-dot of 1e160 that issue 11 found."""
    from freejoint_control.controller_node import ControllerNode
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from freejoint_msgs.msg import CartesianSetpoint
    node = ControllerNode(parameter_overrides=[
        Parameter('case', value='vertical'), Parameter('lockstep', value=False),
        Parameter('stale_timeout', value=2.0), Parameter('resume_time', value=0.0),
        Parameter('max_state_age', value=0.0)])
    try:
        published = []
        monkeypatch.setattr(node._pub_cmd, 'publish',
                            lambda msg: published.append(list(msg.data)))
        states = []
        monkeypatch.setattr(node._pub_state, 'publish', lambda msg: states.append(
            (msg.status, msg.message, list(msg.theta_hat), list(msg.effort))))
        ctl = node._ctl
        real_step = ctl.step
        k_bad = 5

        def step(q, qd, p_d, pd_d, pdd_d, dt):
            if tick['k'] == k_bad:
                qd = (1e160, qd[1], qd[2])
            return real_step(q, qd, p_d, pd_d, pdd_d, dt)
        monkeypatch.setattr(ctl, 'step', step)
        tick = {'k': 0}
        rep = Replica('vertical', lockstep=False, resume=0.0)
        q, qd = Q0, QD0
        for k in range(8):
            tick['k'] = k
            sp = CartesianSetpoint()
            sp.header.stamp.nanosec = k * DT_NS
            values = _setpoint(k)
            sp.position, sp.velocity, sp.acceleration = values[0:2], values[2:4], values[4:6]
            node._on_setpoint(sp)
            js = JointState()
            js.header.stamp.nanosec = k * DT_NS
            js.name = NAMES
            js.position, js.velocity = list(q), list(qd)
            node._on_joint_state(js)
            status, message, theta, effort = states[-1]
            assert published[-1] == effort and _finite_within(effort)
            assert all(math.isfinite(x) for x in theta)
            if k == k_bad:
                assert status & ControllerState.STATUS_LAW_FAULT, message
                assert 'law fault' in message
                assert effort == published[-2]            # the previous command again
                assert theta == states[-2][2] == ctl.theta.tolist()   # restored
                rep.shaper.track(k * DT_NS * 1e-9, values, None)
                rep.last_ns = k * DT_NS
                rep.armed = False
            else:
                expected, _, _, out = rep.tick(k * DT_NS, q, qd, values)
                assert effort == expected and theta == out.theta.tolist(), k
                assert not status & ControllerState.STATUS_LAW_FAULT, message
        assert 'law fault' not in states[-1][1]
        assert '1 law faults' in node.report()
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
        Parameter('stale_timeout', value=2.0), Parameter('max_state_age', value=0.0)])
    executor = make_executor(kind)
    executor.add_node(node)
    if kind == 'events':
        executor.spin_once(timeout_sec=0.05)    # its first event: registering the entities
    try:
        states = []
        monkeypatch.setattr(node._pub_cmd, 'publish', lambda msg: None)
        monkeypatch.setattr(node._pub_state, 'publish', lambda msg: states.append(
            (msg.status, msg.message, list(msg.effort), to_ns(msg.setpoint_stamp))))
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
        rep = Replica('vertical', lockstep=False)
        assert effort == rep.tick(0, q, qd, _setpoint(0))[0]
    finally:
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_node()


def test_a_late_setpoint_stream_is_carried_forward_then_held_and_rejoined_without_a_step(
        procs, ros_node, wait):
    """A starved planner (gaps of 0.3 s seen): no frozen reference, no step when it returns."""
    proc = _start(procs, '-p', 'lockstep:=false', *OLD_STAMPS, '-p', 'stale_timeout:=2.0',
                  '-p', 'resume_time:=0.02', '-p', 'carry_forward_time:=0.05')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    rep = Replica('horizontal', lockstep=False, resume=0.02)
    q, qd = Q0, (0.0, 0.0, 0.0)
    base = rep.fk(q)

    def stream(j):
        # Moving, accelerating and with jerk (30 m/s^3), so that carrying forward shows.
        t = j * DT
        return (base[0] + 0.1 * t + 0.5 * t * t + 5.0 * t ** 3, base[1],
                0.1 + t + 15.0 * t * t, 0.0, 1.0 + 30.0 * t, 0.0)

    def values_of(j):
        return None if 30 <= j < 90 else stream(j)
    refs = []
    blend_end = None
    for k in range(330):
        drv.setpoints_ahead(k, values_of)
        drv.joint_state(k, q, qd)
        st, cmd = drv.answer(k)
        # Ticks 30..79: the setpoint of tick 29 carried forward (<= carry_forward_time
        # 0.05 s); 80..89: older, so the hold; from 90 the stream again, blended in.
        if 80 <= k < 90:
            effort, ref, _, _ = rep.tick(k * DT_NS, q, qd, None)
        else:
            sp_k = min(k, 29) if 30 <= k < 90 else k
            effort, ref, _, _ = rep.tick(k * DT_NS, q, qd, stream(sp_k), sp_k * DT_NS)
        assert cmd == effort, k
        assert list(st.position_desired) == list(ref[0:2]), k
        assert bool(st.status & ControllerState.STATUS_SETPOINT_LATE) == (40 <= k < 90), (
            k, st.message)
        assert bool(st.status & STATUS_HOLDING) == (80 <= k < 90), (k, st.message)
        if 40 <= k < 80:
            assert 'setpoint late' in st.message, (k, st.message)
        if 80 <= k < 90:
            assert 'setpoint stream late' in st.message, (k, st.message)
        if k == 90:
            blend_end = 90 + math.ceil(rep.shaper.blend_duration / DT - 1e-9)
        if k >= 90:
            assert bool(st.status & STATUS_RESUMING) == (k < blend_end), (k, st.message)
        refs.append(ref)
    assert blend_end < 330
    # Carried forward, not frozen at tick 29 ...
    assert refs[79][0] - refs[29][0] > 0.005
    # ... and no step but the hold's onset (which holds the arm where it is): the position
    # moves as the reference's own velocity says, tick to tick.
    for k in range(1, 330):
        if k != 80:
            moved = refs[k][0] - refs[k - 1][0]
            assert abs(moved - refs[k - 1][2] * DT) < 2e-5, (k, moved, refs[k - 1][2] * DT)
    assert procs.stop(proc) == 0


def test_real_time_skips_a_state_older_than_max_state_age_without_a_command(
        procs, ros_node, wait):
    """A backlog of old states (start-up, a stall) must not be answered late."""
    import time
    # 2 s: generous for this loaded test machine's own delays (the default is 0.1 s).
    proc = _start(procs, '-p', 'lockstep:=false', '-p', 'max_state_age:=2.0')
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    k_old = time.time_ns() // DT_NS - 10_000        # stamps on the system clock: 10 s old
    drv.joint_state(k_old, Q0, QD0)
    wait(lambda: 'skipped, no command from it' in procs.log(proc), 15.0, 'the skip logged',
         spin=drv.spin)
    k_now = time.time_ns() // DT_NS
    drv.joint_state(k_now, Q0, QD0)                 # fresh: answered (a hold: no setpoint)
    st, cmd = drv.answer(k_now)
    assert st.status & STATUS_HOLDING and _finite_within(cmd)
    assert 0.0 <= st.state_age < 2.0
    assert stamp_label(drv.ns(k_old)) not in drv.commands
    assert procs.stop(proc) == 0
    assert '1 states skipped as too old' in procs.log(proc)


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
        'qos_overrides./setpoint.subscription.reliability',
        'qos_overrides./effort_controller/commands.publisher.reliability',
        'qos_overrides./controller_state.publisher.depth'])
    assert params == {
        JS_RELIABILITY: 'best_effort' if override else 'reliable',
        'qos_overrides./joint_states.subscription.depth': 1,     # real time: newest only
        'qos_overrides./joint_states.subscription.history': 'keep_last',
        'qos_overrides./setpoint.subscription.reliability': 'reliable',
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


def test_diagnostics_say_holding_with_warn_without_setpoints_and_ok_while_tracking(
        procs, ros_node, wait):
    import time
    ok, warn, error = 0, 1, 2
    proc = _start(procs, '-p', 'lockstep:=false', *OLD_STAMPS, '-p', 'resume_time:=0.05')
    diag = Diagnostics(ros_node)
    drv = Driver(ros_node, wait)
    drv.connect(proc, procs)
    # No state yet: the arm is not controlled.
    wait(lambda: diag.find(error, 'no joint_states yet on /joint_states'), 10.0,
         'ERROR: no joint_states yet', spin=drv.spin)
    drv.offset_ns = time.time_ns()
    q, qd = Q0, (0.0, 0.0, 0.0)
    base = Replica('horizontal', lockstep=False).fk(q)
    rest = (base[0], base[1], 0.0, 0.0, 0.0, 0.0)     # a setpoint where the arm is, at rest
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
    assert values['holds'] == '1' and values['stale setpoint periods'] == '0', values
    assert float(values['answer rate [Hz]']) > 0.0 and values['latency max [ms]'] != '-'
    assert int(values['status']) & STATUS_HOLDING
    # Setpoints where the arm is: tracking, OK (after the blend and the first period).
    level, message, values = run_until(
        lambda: diag.find(ok, 'tracking'), 'OK: tracking', lambda j: rest)
    assert values['status'] == '0' and values['law faults'] == '0', values
    assert values['mode'] == 'realtime' and float(values['answer rate [Hz]']) > 0.0
    # The stream stops: held again, a stale setpoint period.
    level, message, values = run_until(
        lambda: diag.find(warn, 'stale setpoint'), 'WARN: stale setpoint',
        lambda j: None)
    # (A stall of this test beyond stale_timeout between states would add a hold.)
    assert values['stale setpoint periods'] == '1' and int(values['holds']) >= 2, values
    # No more states: ERROR, zero effort.
    wait(lambda: diag.find(error, 'no joint_states for'), 10.0, 'ERROR: no joint_states',
         spin=drv.spin)
    assert procs.stop(proc) == 0
