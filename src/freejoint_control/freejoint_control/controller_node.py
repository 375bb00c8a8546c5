"""
Controller node: the controller loop of ``freejoint_control.loop`` as a ROS 2 node.

Subscribes ``joint_states`` (joints matched by name) and ``setpoints``; per state it
publishes the active joint efforts on ``effort_controller/commands`` (the order of
parameter ``joints``: ros2_control's JointGroupEffortController) and a ``controller_state``
(thinned by ``state_publish_rate``, and whenever the status changes). What to answer -
pairing, hold / resume, guards, the law (``law``), limits, faults - is
:class:`ControlLoop`'s; this node converts messages, reads the clocks, publishes, offers
``~/reset`` and the loop's status on ``/diagnostics`` (docs/GRAPH.md). QoS overridable
with ros2's ``qos_overrides.<topic>.<publisher|subscription>.<policy>`` parameters.
``standby: true`` (real time): a hot spare of ``controller_supervisor``, idle and not
subscribed to joint_states until SIGUSR1, then active from the arm's measured motion.
``joint_failures`` not ``off``: notices on ``joint_failures`` in, the failure monitor's
detections out there (docs/failures.md). Whenever it stops in real time (a readiness
trip, no joint_states) it sends the stop command (the gravity hold of the active joints)
and asks the driver to brake on ``brake_request`` (std_msgs/String: why); a resting
setpoint, for a shorter drive watchdog on ``brake_timeout_request``. Its judgement of its
loop goes out on ``controller_readiness`` (latched) at start-up (a spare: at its
activation) and at each change.

"""

import signal
import time

from freejoint_common.arm_description import resolve_arm
from freejoint_common.contract import BRAKE_REQUEST, BRAKE_TIMEOUT_REQUEST, COMMANDS
from freejoint_common.contract import CONTROLLER_READINESS, CONTROLLER_STATE, JOINT_FAILURES
from freejoint_common.contract import JOINT_STATES, stamp_from_ns
from freejoint_common.contract import REALTIME_STATE_QOS, RESET, SETPOINTS
from freejoint_common.contract import setpoint_samples, STANDBY_SETPOINT_QOS
from freejoint_common.diagnostics import Diagnostics, LatencyWindow, level_and_message, OK
from freejoint_common.node_tools import NodeParameters, overridable, plain, QOS_OVERRIDES
from freejoint_common.node_tools import Throttle
from freejoint_common.runner import Lifecycle, run
from freejoint_common.scheduling import process_scheduling
from freejoint_control.conversions import Messages, StateThinning
from freejoint_control.loop import ControlLoop, ERROR, RECEIPT, WARN
from freejoint_control.params import SCHEMA
from freejoint_control.readiness import realtime_epsilon
from freejoint_control.supervisor import notify_ready
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

_monotonic = time.monotonic


class ControllerNode(Node, Lifecycle):
    """The controller loop between JointState/CartesianSetpoints and effort commands."""

    def __init__(self, **kwargs):
        super().__init__('controller_node', **kwargs)
        self._params = NodeParameters(self, SCHEMA)   # raises: bad start-up parameters
        cfg = self.config = self._params.config
        self._throttle = Throttle(1.0)
        self._loop = ControlLoop(cfg, self._log)
        self._params.listen(self._apply)
        self._lockstep = cfg.lockstep
        self._thinning = StateThinning(cfg.state_publish_rate)

        # Serialized in and out (conversions.Messages): no message object per tick.
        self._messages = Messages(cfg.joints, self._loop.result.law_state_names)
        self._latency = LatencyWindow()
        self._quiet_sent = False
        # Clock of the state ages: system time (what real-time stamps are on), read without
        # rclpy's Clock.now() (tens of microseconds per call); the ROS clock under sim time.
        if self.get_parameter('use_sim_time').value:
            clock = self.get_clock()
            self._now_ns = lambda: clock.now().nanoseconds
        else:
            self._now_ns = time.time_ns
        # Hot spare: idle until SIGUSR1, not subscribed to joint_states (a 1-kHz stream
        # it would only drop). The signal's handler only sets a flag (the EventsExecutor
        # has no guard conditions); the next setpoint or watchdog callback subscribes
        # (the runner's between-callbacks rule) and the first state activates.
        self._activation_requested = False
        self._activated_wall = None
        self._states_sub = None
        if cfg.standby:
            signal.signal(signal.SIGUSR1, self._on_activate_signal)
            # At the default scheduler until ready: its discovery and the setpoint history
            # it is sent then would spend the kernel's real-time budget of the CPU, which
            # stalls every SCHED_FIFO thread of the graph (measured: 43-49-ms gaps of the
            # simulator as a spare got ready at SCHED_FIFO 1). thread_priority applies
            # from the activation on.
            process_scheduling().request(self.get_fully_qualified_name(), 0,
                                         cfg.cpu_affinity)

        # Each QoS overridable (qos_overrides.<topic>.<publisher|subscription>.<policy>,
        # e.g. a best-effort joint_states of a real driver), defaults as in GRAPH.md.
        self._pub_cmd = self.create_publisher(
            COMMANDS.msg_type, COMMANDS.name, overridable(COMMANDS.qos),
            qos_overriding_options=QOS_OVERRIDES)
        self._pub_state = self.create_publisher(CONTROLLER_STATE.msg_type, CONTROLLER_STATE.name,
                                                overridable(CONTROLLER_STATE.qos),
                                                qos_overriding_options=QOS_OVERRIDES)
        self._pub_brake = self.create_publisher(BRAKE_REQUEST.msg_type, BRAKE_REQUEST.name,
                                                BRAKE_REQUEST.qos)
        self._pub_wait = None if cfg.lockstep else self.create_publisher(
            BRAKE_TIMEOUT_REQUEST.msg_type, BRAKE_TIMEOUT_REQUEST.name, BRAKE_TIMEOUT_REQUEST.qos)
        # The loop's readiness (latched): a spare publishes from its activation on, not to
        # override the active controller's judgement.
        self._pub_ready = None
        if not cfg.standby:
            self._start_readiness()
        self._sp_sub = self.create_subscription(
            SETPOINTS.msg_type, SETPOINTS.name, self._on_setpoints,
            overridable(STANDBY_SETPOINT_QOS if cfg.standby else SETPOINTS.qos),
            qos_overriding_options=QOS_OVERRIDES)
        # After the setpoints (a spare subscribes later too): the single-threaded executor
        # takes what one wait found ready in the order the subscriptions were made, so a
        # setpoint that came in before a state is applied before the state is answered.
        if not cfg.standby:
            self._subscribe_states()
        self.create_service(RESET.srv_type, RESET.name, self._on_reset)
        # Joint failures: a driver's or operator's notice (joint_failures on).
        # Its detections go out there too (the planner, a spare and the bag learn of them).
        self._pub_failure = None
        if cfg.joint_failures != 'off':
            self.create_subscription(JOINT_FAILURES.msg_type, JOINT_FAILURES.name,
                                     self._on_failure_notice, JOINT_FAILURES.qos)
            self._pub_failure = self.create_publisher(JOINT_FAILURES.msg_type,
                                                      JOINT_FAILURES.name, JOINT_FAILURES.qos)
        self._diagnostics = Diagnostics(self, 'controller', 'freejoint_control',
                                        self._on_diagnostics_timer)
        self._diag_window = (_monotonic(), self._loop.counters())
        period = min(0.05, cfg.stale_timeout / 4.0)
        self.create_timer(period, self._watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        arm = resolve_arm(cfg.values)   # its gravity vector, not a case name, when given
        epsilon = '' if cfg.lockstep else ', epsilon %g (realtime_epsilon: %s)' % (
            realtime_epsilon(arm.params, cfg.delay_compensation, cfg.realtime_epsilon,
                             cfg.epsilon))
        self.get_logger().info(
            'controller ready: %s, nominal scale %g, %s, joints %s, dt %g s, law %s, robust %s'
            % (arm.source if arm.described else cfg.case, cfg.nominal_scale,
               'lockstep' if cfg.lockstep else 'real time', list(cfg.joints), cfg.dt, cfg.law,
               cfg.gains.robust) + epsilon
            + (' (standby: idle until SIGUSR1)' if cfg.standby else ''))
        if not cfg.standby:
            notify_ready()
        # A spare tells the supervisor it is ready once it could take over at once (its
        # watchdog: _check_standby_ready).

    def _log(self, level, kind, text):
        """Log a line of the loop (``kind``: throttled per kind; None: always)."""
        logger = self.get_logger()
        # rclpy ties one severity to each logging call site: a call line per severity.
        if kind is not None:
            self._throttle(logger.error if level == ERROR else logger.warn, kind, text)
        elif level == ERROR:
            logger.error(text)
        elif level == WARN:
            logger.warn(text)
        else:
            logger.info(text)

    # -- standby ---------------------------------------------------------------
    def _subscribe_states(self):
        """Subscribe ``joint_states`` (real time: the newest state; lockstep: every one)."""
        self._states_sub = self.create_subscription(
            JOINT_STATES.msg_type, JOINT_STATES.name, self._on_joint_state,
            overridable(JOINT_STATES.qos if self.config.lockstep else REALTIME_STATE_QOS),
            qos_overriding_options=QOS_OVERRIDES, raw=True)

    def _check_standby_ready(self):
        """Standby: once nothing was lacking for STANDBY_SETTLE s, tell the supervisor."""
        loop = self._loop
        mono = _monotonic()
        waits_for = loop.standby_waits_for(
            self._pub_cmd.get_subscription_count(), self.count_subscribers(COMMANDS.name),
            self._sp_sub.get_publisher_count(), self.count_publishers(SETPOINTS.name),
            mono, self._now_ns(), (self.resolve_topic_name(COMMANDS.name),
                                   self.resolve_topic_name(SETPOINTS.name)))
        if not loop.standby_settled(waits_for, mono):
            return
        # Idle at SCHED_FIFO 1 (with a thread_priority above 1): below every real-time
        # thread of the graph, above best-effort load, which must not starve its activation.
        cfg = self.config
        process_scheduling().request(self.get_fully_qualified_name(),
                                     1 if cfg.thread_priority > 1 else 0, cfg.cpu_affinity)
        # Logged before the supervisor hears of it: its 'standby ready' line comes after.
        self.get_logger().info('standby ready: commands matched, setpoint stream %s' % (
            'caught up' if self._sp_sub.get_publisher_count() else 'not matched (no planner)'))
        notify_ready()

    def _on_activate_signal(self, signum, frame):
        """SIGUSR1: activation requested (only a flag here)."""
        self._activation_requested = True

    def _on_activation_requested(self):
        """Subscribe joint_states (once); the first state activates (:meth:`_activate`)."""
        if self._states_sub is None:
            self._subscribe_states()
            self.get_logger().info('activation requested (SIGUSR1): joint_states subscribed, '
                                   'active from the first state')

    def _start_readiness(self):
        """Create the readiness publisher; publish the judgement now (start-up)."""
        self._pub_ready = self.create_publisher(
            CONTROLLER_READINESS.msg_type, CONTROLLER_READINESS.name, CONTROLLER_READINESS.qos)
        ready, reason = self._loop.readiness()
        self._publish_readiness(self._now_ns(), ready, reason)

    def _publish_readiness(self, ns, ready, reason):
        """Publish a ControllerReadiness (stamp [ns]: the state's, or now)."""
        msg = CONTROLLER_READINESS.msg_type(ready=bool(ready), reason=reason)
        stamp_from_ns(max(0, ns), msg.stamp)
        self._pub_ready.publish(msg)

    def _send_stop_notes(self):
        """Publish what the loop noted: a readiness change, a brake request (after the command)."""
        loop = self._loop
        note = loop.take_readiness()
        if note is not None and self._pub_ready is not None:
            self._publish_readiness(*note)
        if loop.brake_request is not None:
            self._pub_brake.publish(BRAKE_REQUEST.msg_type(data=loop.take_brake_request()))

    def _activate(self):
        """Leave standby: this state and the next are answered; start from the motion."""
        self._loop.activate()
        if self._pub_ready is None:
            self._start_readiness()
        self._activated_wall = time.time()
        cfg = self.config
        refused = process_scheduling().request(self.get_fully_qualified_name(),
                                               cfg.thread_priority, cfg.cpu_affinity)
        if refused is not None:
            self.get_logger().error('thread_priority %d not applied at the activation: %s'
                                    % (cfg.thread_priority, refused))
        self.get_logger().warn("activated (standby): the reference starts from the arm's "
                               'measured motion, theta_hat from theta0, torque ramped from '
                               'zero')

    # -- parameters ------------------------------------------------------------
    def _apply(self, old, cfg, params):
        """Take a validated parameter change (the set-parameters callback's last step)."""
        self._loop.apply(old, cfg)
        self.config = cfg
        self._thinning.set_rate(cfg.state_publish_rate)
        changed = ', '.join('%s=%s' % (p.name, plain(p.value)) for p in params)
        self.get_logger().info('parameters set (effective next tick): ' + changed)

    # -- messages --------------------------------------------------------------
    def _on_joint_state(self, data):
        """Answer a serialized JointState (the loop) and publish what the loop says."""
        loop = self._loop
        try:
            ns, names, position, velocity, effort = self._messages.read_state(data)
        except ValueError as exc:
            loop.refuse_state_message(str(exc))
            return
        if loop.standby:
            self._activate()    # the first state after SIGUSR1 (subscribed at the signal)
        res = loop.on_state(ns, names, position, velocity,
                            0 if self._lockstep else self._now_ns(), _monotonic(), effort)
        if loop.drive_wait_request is not None and self._pub_wait is not None:
            self._pub_wait.publish(BRAKE_TIMEOUT_REQUEST.msg_type(data=loop.take_drive_wait()))
        if res is not None:
            self._publish(res)
        if loop.readiness_note is not None or loop.brake_request is not None:
            self._send_stop_notes()
        if self._pub_failure is not None:
            for name in loop.failures.announcements():
                self._pub_failure.publish(JOINT_FAILURES.msg_type(data=name))

    def _on_failure_notice(self, msg):
        """joint_failures: the joint named by ``data`` failed (the law switches next tick)."""
        why = self._loop.on_failure_notice(msg.data)
        if not why:
            self.get_logger().warn('joint failure notice: %s (taken at the next tick)'
                                   % msg.data)

    def _on_setpoints(self, msg):
        """Take a batch's setpoints in order (lockstep: a waiting state is answered at its own)."""
        if self._activation_requested and self._loop.standby:
            self._on_activation_requested()
        loop = self._loop
        try:
            samples = setpoint_samples(msg)
        except ValueError as exc:
            if len(msg.stamps):
                loop.refuse_setpoint(int(msg.stamps[0]), str(exc), len(msg.stamps))
            return
        loop.on_setpoints(samples, _monotonic(), self._publish)

    def _publish(self, res):
        """Publish the command and (rate allowing) the ControllerState of a Result."""
        messages = self._messages
        if res.repeated:
            # A repeated state (the sim's start-up republication): the same answer again.
            self._pub_cmd.publish(messages.command)
            if messages.controller_state is not None:
                self._pub_state.publish(messages.controller_state)
            return
        ns = res.stamp_ns
        self._pub_cmd.publish(messages.write_command(ns, res.effort))
        latency = res.latency_ns
        if latency is RECEIPT:
            # Lockstep: the wall time from the state's receipt to its command.
            self._latency.note(int((_monotonic() - self._loop.last_state_wall) * 1e9))
        elif latency is not None:
            self._latency.note(latency)
        if self._thinning.due(ns, res.status):     # state_publish_rate
            self._pub_state.publish(messages.write_controller_state(res))

    def _on_reset(self, request, response):
        """~/reset: restart theta_hat and the hold / blend state (std_srvs/Trigger)."""
        self._loop.reset()
        response.message = 'theta_hat reset to theta0 %s; hold / blend state cleared' % (
            list(self.config.gains.theta0),)
        self.get_logger().warn('reset: ' + response.message)
        response.success = True
        return response

    def _watchdog(self):
        """Wall-clock staleness (the loop's watchdog); a spare's activation and readiness."""
        loop = self._loop
        if loop.standby:
            if self._activation_requested:
                self._on_activation_requested()     # no setpoint stream: at the latest here
            elif loop.waiting_for:
                self._check_standby_ready()
        res = loop.watchdog(self._now_ns(), _monotonic())
        if res is not None:
            self._publish(res)
            self._send_stop_notes()

    # -- status ----------------------------------------------------------------
    def _on_diagnostics_timer(self):
        """Every second: the status on /diagnostics (lockstep: once while no state comes)."""
        loop = self._loop
        now = _monotonic()
        since, start = self._diag_window
        self._diag_window = (now, loop.counters())
        if loop.standby:
            self._diagnostics.publish(
                OK, 'STANDBY: hot spare, not subscribed to joint_states until SIGUSR1' + (
                    '; not ready: %s' % loop.waiting_for if loop.waiting_for else ''),
                (('mode', 'standby'), ('ready', 'no' if loop.waiting_for else 'yes')))
            return
        last = loop.last_state_wall
        silent = last is None or last < since
        if self._lockstep and silent:
            # Sim time stands still (the simulator waits, holds at max_steps or is gone):
            # one status says so, then nothing until states come (a recorder drains).
            if self._quiet_sent:
                return
            self._quiet_sent = True
        else:
            self._quiet_sent = False
        errors, warnings, ok, values = loop.diagnostics(
            now - since, start, silent, self._latency.take(),
            self.resolve_topic_name('joint_states'), self._activated_wall)
        level, message = level_and_message(errors, warnings, ok)
        self._diagnostics.publish(level, message, values)

    def report(self):
        """One line for the end of the run: ticks, zero-effort answers, holds, refusals."""
        return self._loop.report()

    @property
    def executor_kind(self):
        """Return the parameter ``executor`` (the runner spins the node with it)."""
        return self.config.executor


def main(args=None):
    """Run the node until SIGINT/SIGTERM; exit 2 on a bad start-up parameter."""
    return run(ControllerNode, 'controller_node', args)


if __name__ == '__main__':
    main()
