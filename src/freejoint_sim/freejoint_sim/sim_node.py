"""
Simulator node: an arm with a free joint (freejoint_core.plant.Plant) in ROS 2.

Publishes ``joint_states`` (sensor_msgs/JointState: every joint, the passive one included;
position, velocity and the actuator effort applied over the last step) and ``ee_position``
(geometry_msgs/PointStamped, from the core model's forward kinematics: x, y of a planar
arm, z 0; x, y, z of a spatial arm's tip in its base frame); takes the active
joint efforts on ``effort_controller/commands`` (std_msgs/Float64MultiArray in the order of
parameter ``joints``, what ros2_control's JointGroupEffortController takes; remap it to
``/<controller>/commands``).  ``~/reset`` (std_srvs/Trigger) puts the arm back at its
initial configuration, at rest, with a freshly seeded disturbance, at the next step (time
keeps running), and clears a divergence.  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray,
one status named ``<node>: simulator``) at 1 Hz: OK / WARN with steps, step rate, command
latency (state to command), command timeouts, refused commands, dropped steps, brakes;
ERROR with the reason at once when the plant diverges.  Joint failures
(``freejoint_sim.failure_injection``): parameter ``fail_joint`` (``joint3@2.5``) and
``~/fail_joint`` (freejoint_msgs/FailJoint) make a joint's actuator and brake fail; its
effort then reads 0, the log and ``/diagnostics`` say when, and with ``report_failures``
a notice goes out on ``joint_failures``.  A spatial arm (``task_dim`` 3: a serial URDF
chain on Pinocchio, ``freejoint_core.spatial_plant.SpatialPlant``) is the same node with its
n chain joints in ``joint_states``, its r active joints' efforts in the command and its
URDF text on ``robot_description``.

Modes (docs/GRAPH.md):

* ``lockstep``: the node owns ``/clock``; at step k it publishes ``/clock = t_k`` and the
  state stamped t_k, waits for the command answering t_k, integrates one control period
  with it and the disturbance draw of step k, and goes on.  Deterministic for a seed, as
  fast as the graph answers.  With ``clock_rate`` (Hz, 0 = every step) ``/clock`` goes out
  only on the steps that are multiples of ``1 / (clock_rate * control_period)`` (and at
  step 0, its republications, and ``max_steps``), the state still every step: fewer
  ``/clock`` publications and deliveries per tick (gazebo_ros's ``publish_rate``).  A
  node that streams ahead of ``/clock`` every N steps needs a lookahead of at least N - 1
  steps (the planner: ``docs/GRAPH.md``, lockstep item 5).
* ``realtime``: steps on the wall clock at ``1 / control_period`` and applies the latest
  command, which the stepping thread takes itself at each step as a driver reads its
  command at its update (no executor callback per command).  Each state is stamped with
  its step's time on the stepping grid (the monotonic grid mapped to system time once at
  start), so a late publication shows as age, not as a wrong time.  With ``start_braked``
  (default) the arm is held at q(0) at rest until the first accepted command (brakes
  engaged; states still published), and
  again after ``~/reset``; once running, no command for ``brake_timeout`` engages the
  brakes where the arm is (a drive watchdog) until the next accepted command;
  ``brake_timeout_at_rest`` after a command that found the arm at rest, or the
  controller's ``brake_timeout_request`` when shorter (``freejoint_sim.watchdog``).
  Brakes engaged after the start are released by a command answering a state published
  after they engaged (a command computed before, e.g. a controller's stop command or a
  stalled one catching up, leaves them on). With ``command_watchdog: false`` it is a
  driver that holds the last command (ros2_control's forward_command_controller): no
  watchdog, no command timeout, the brake topics ignored; only the start-up brakes.

A diverged plant (non-finite, or a joint faster than ``divergence_speed``, or an angle
beyond ``freejoint_core.guards.MAX_ANGLE``) is not integrated further: the simulator
publishes its last sane state, reports ERROR on ``/diagnostics`` and counts the divergence
in its end-of-run line until ``~/reset``.

A command of the wrong length or with a non-finite value is refused (throttled error
naming the problem) and zero effort is applied; no command for ``command_timeout`` wall
seconds means zero effort and a warning (ros2_control would hold the last command
forever; this node does not).

"""

import math
import threading
import time

from builtin_interfaces.msg import Time
from freejoint_common.cdr import CommandReader, JointStateWriter, PointStampedWriter
from freejoint_common.contract import BRAKE_REQUEST, BRAKE_TIMEOUT_REQUEST, CLOCK, COMMANDS
from freejoint_common.contract import EE_POSITION
from freejoint_common.contract import FAIL_JOINT, JOINT_FAILURES, JOINT_STATES
from freejoint_common.contract import label_to_stamp, read_serialized, RESET, ROBOT_DESCRIPTION
from freejoint_common.contract import stamp_from_ns
from freejoint_common.diagnostics import Diagnostics, LatencyWindow, level_and_message
from freejoint_common.node_tools import NodeParameters, overridable, plain, QOS_OVERRIDES
from freejoint_common.node_tools import Throttle
from freejoint_common.runner import Lifecycle, run
from freejoint_core.errors import FreejointValueError, PlantDivergedError
from freejoint_core.guards import divergence_reason
from freejoint_sim.engines import make_plant
from freejoint_sim.failure_injection import Injector, parse_fail_joint
from freejoint_sim.limits import LimitWatch
from freejoint_sim.params import SCHEMA
from freejoint_sim.timing import StepTiming
from freejoint_sim.watchdog import DriveWatchdog
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node

REPUBLISH_PERIOD = 0.2
"""Lockstep: wall period [s] of republishing step 0 until the first command arrives."""
MAX_CATCH_UP = 20
"""Real time: steps integrated at most at one wake-up before dropping behind."""
_UNLABELLED = 1 << 62
"""The stamp of a command without a label: it answers the newest state (releases brakes)."""

_isfinite = math.isfinite
_monotonic = time.monotonic
_time_ns = time.time_ns


def _never_called(_msg):
    """Stand for the callback of the real-time command subscription (no executor spins it)."""


def _command_fields(msg):
    dims = msg.layout.dim
    return (dims[0].label if dims else None), msg.data


class SimNode(Node, Lifecycle):
    """The simulated arm behind JointState / effort command topics."""

    def __init__(self, **kwargs):
        super().__init__('sim_node', **kwargs)
        self._params = NodeParameters(self, SCHEMA)   # raises: bad start-up parameters
        cfg = self.config = self._params.config
        self._plant = make_plant(cfg)
        self._fk = self._plant.model.fk
        self._spatial = cfg.arm.spatial is not None   # ee_position x, y, z (else x, y)
        self._limits = self._make_limits(cfg)
        self._injector = self._make_injector(cfg)
        self._fail_requests = []
        self._install(cfg)
        self._params.listen(self._apply)

        n = cfg.params.n
        r = cfg.params.r
        self._r = r
        self._zero = [0.0] * r
        self._applied = [0.0] * n      # actuator effort of the last step, all joints
        self._active = cfg.params.active
        self._k = 0
        self._t_ns = 0
        self._timeouts = 0
        self._refused = 0
        self._got_first = False
        self._waiting_since = _monotonic()
        self._last_publish = 0.0
        self._reset_pending = False
        self._latest = None            # real time: (tau, receipt, step answered, accepted,
        #                                             the watchdog's wait after it, and why)
        self._requested_wait = 0.0     # real time: the controller's brake_timeout_request
        self._cmd_timed_out = False
        self._throttle = Throttle(1.0)
        self._dropped = 0
        self._divergences = 0
        self._diverged = None          # reason while the plant is diverged, else None
        self._braked = not cfg.lockstep and cfg.start_braked
        self._braked_since = _monotonic()
        self._brake_reason = ''
        self._brake_engagements = 0
        self._brake_asked = None       # real time: why the controller asked to brake now
        self._brakes_asked = 0
        self._braked_ns = -1           # real time: stamp of the last state before the brakes
        self._rt_origin_ns = 0         # real time: system time [ns] of step 0 on the grid
        self._take_state()
        self._diag_window = (_monotonic(), 0, 0, 0, 0)
        self._final_status_sent = False
        self._latency = LatencyWindow()   # state-to-command latencies of the status window
        self._note_latency = self._latency.note
        # measurement: an optional observer of the step events (timing_file), None if off
        self._observer = (StepTiming(cfg.timing_file, cfg.timing_steps,
                                     'lockstep' if self._lockstep else 'realtime', self._dt,
                                     self.get_logger().info) if cfg.timing_file else None)

        # joint_states and ee_position written serialized, commands read serialized
        # (freejoint_common.cdr): no message object per step.
        self._write_js = JointStateWriter(cfg.joint_names)
        self._write_ee = PointStampedWriter(cfg.frame_id)
        self._read_command = CommandReader()
        self._clock_msg = CLOCK.msg_type()
        self._stamp = Time()

        # QoS overridable (qos_overrides.<topic>.<publisher|subscription>.<policy>).
        self._pub_js = self.create_publisher(JOINT_STATES.msg_type, JOINT_STATES.name,
                                             overridable(JOINT_STATES.qos),
                                             qos_overriding_options=QOS_OVERRIDES)
        self._pub_ee = self.create_publisher(EE_POSITION.msg_type, EE_POSITION.name,
                                             overridable(EE_POSITION.qos),
                                             qos_overriding_options=QOS_OVERRIDES)
        self._pub_clock = (self.create_publisher(CLOCK.msg_type, CLOCK.name, CLOCK.qos)
                           if cfg.lockstep else None)
        self._cmd_node = None
        self._cmd_sub = self.create_subscription(COMMANDS.msg_type, COMMANDS.name,
                                                 self._on_command, overridable(COMMANDS.qos),
                                                 qos_overriding_options=QOS_OVERRIDES, raw=True)
        if not cfg.lockstep:
            self._take_commands_yourself()
        self.create_service(RESET.srv_type, RESET.name, self._on_reset)
        if not cfg.lockstep:    # a drive that brakes when told (the watchdog stays)
            self.create_subscription(BRAKE_REQUEST.msg_type, BRAKE_REQUEST.name,
                                     self._on_brake_request, BRAKE_REQUEST.qos)
            self.create_subscription(BRAKE_TIMEOUT_REQUEST.msg_type, BRAKE_TIMEOUT_REQUEST.name,
                                     self._on_brake_timeout_request, BRAKE_TIMEOUT_REQUEST.qos)
        # Joint failures: ~/fail_joint, the notices a driver would publish.
        self.create_service(FAIL_JOINT.srv_type, FAIL_JOINT.name, self._on_fail_joint)
        self._pub_failures = (self.create_publisher(JOINT_FAILURES.msg_type,
                                                    JOINT_FAILURES.name, JOINT_FAILURES.qos)
                              if cfg.report_failures else None)
        self._publish_description(cfg.arm)
        self._diagnostics = Diagnostics(self, 'simulator', 'freejoint_sim',
                                        self._on_diagnostics_timer)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        if cfg.lockstep:
            period = max(0.001, min(0.05, cfg.command_timeout / 4.0))
            self.create_timer(period, self._lockstep_watchdog, clock=steady)
        else:
            self._rt_start = None
            self._rt_stop = threading.Event()
            self._rt_thread = threading.Thread(target=self._realtime_loop, name='sim_step',
                                               daemon=True)
        self.get_logger().info(
            'simulator ready: %s arm, %s, dt %g s (%s %g s), disturbance %g N m seed %d, '
            '%sq0 = [%s] rad, command timeout %g s' % (
                cfg.arm.source if cfg.arm.urdf_arm or cfg.arm.spatial is not None
                else cfg.case,
                'lockstep' if cfg.lockstep else 'real time', cfg.dt,
                'MuJoCo RK4' if cfg.engine == 'mujoco' else 'RK4', cfg.dt_sub, cfg.dist_bound,
                cfg.seed, 'free-joint damping %g N m s/rad, ' % cfg.passive_damping
                if cfg.passive_damping else '',
                ', '.join('%.6f' % v for v in cfg.arm.to_joints(cfg.q0)),
                cfg.command_timeout))
        if cfg.lockstep:
            self._publish_state()
            self.get_logger().info('lockstep: waiting for the first command (step 0 is '
                                   'republished every %g s)' % REPUBLISH_PERIOD)
        else:
            if self._braked:
                self.get_logger().info('brakes engaged: the arm is held at q0 until the '
                                       'first command')
            if self._holds_last:
                self.get_logger().warn('command_watchdog: false: every command is applied '
                                       'until the next one, with no watchdog, no command '
                                       'timeout and no brakes on request (a driver that '
                                       'holds the last command)')
            self._rt_thread.start()

    def _take_commands_yourself(self):
        """
        Real time: move the command subscription to a hidden node the stepping thread takes.

        A driver reads the newest command at its update, not when the command arrives: the
        stepping thread takes what arrived at each step (``_take_commands``), so no executor
        wakes up per command (one wake-up and a hand-over of the GIL per period fewer; the
        executor still runs services, the brake topics and the diagnostics timer). The
        subscription made on this node declared the QoS overrides' parameters and resolved
        the topic (remapped) and the QoS (overridden); the hidden node's, with both, replaces
        it.
        """
        made = self._cmd_sub
        topic, qos = made.topic_name, made.qos_profile
        self.destroy_subscription(made)
        self._cmd_node = Node('_%s_commands' % self.get_name(), namespace=self.get_namespace(),
                              context=self.context, use_global_arguments=False,
                              enable_rosout=False, start_parameter_services=False)
        self._cmd_sub = self._cmd_node.create_subscription(
            COMMANDS.msg_type, topic, _never_called, qos, raw=True)

    def _publish_description(self, arm):
        """Publish the arm's URDF on /robot_description (latched, as robot_state_publisher)."""
        try:
            text = arm.spatial.urdf if arm.spatial is not None else arm.description().urdf
        except FreejointValueError as exc:
            self.get_logger().warn('no %s: %s' % (ROBOT_DESCRIPTION.name, exc))
            return
        self._pub_description = self.create_publisher(
            ROBOT_DESCRIPTION.msg_type, ROBOT_DESCRIPTION.name, ROBOT_DESCRIPTION.qos)
        self._pub_description.publish(ROBOT_DESCRIPTION.msg_type(data=text))

    # -- parameters ------------------------------------------------------------
    def _install(self, cfg):
        self.config = cfg
        self._dt = cfg.dt
        self._dt_ns = cfg.dt_ns
        self._timeout = cfg.command_timeout
        self._holds_last = not cfg.lockstep and not cfg.command_watchdog
        self._watchdog = DriveWatchdog(
            0.0 if cfg.lockstep or self._holds_last else cfg.brake_timeout,
            cfg.brake_timeout_at_rest, cfg.rest_speed)
        self._every = cfg.publish_every
        self._clock_every = cfg.clock_every
        self._lockstep = cfg.lockstep
        self._cmd_map = cfg.cmd_to_active
        self._identity = cfg.cmd_to_active == tuple(range(len(cfg.cmd_to_active)))
        self._max_steps = cfg.max_steps
        self._max_speed = cfg.divergence_speed

    def _apply(self, old, cfg, params):
        """Take a validated parameter change (the set-parameters callback's last step)."""
        self._install(cfg)
        self._write_ee = PointStampedWriter(cfg.frame_id)
        self.get_logger().info('parameters set: %s (arm, disturbance, dt_sub and initial '
                               'state take effect on ~/reset)'
                               % ', '.join('%s=%s' % (p.name, plain(p.value)) for p in params))

    def _on_reset(self, request, response):
        self._reset_pending = True
        cfg = self.config
        response.success = True
        response.message = ('arm back at q0 = [%s] rad at rest, %s case, seed %d, from step '
                            '%d on%s' % (', '.join('%.6f' % v for v in cfg.arm.to_joints(cfg.q0)),
                                         cfg.case, cfg.seed, self._k + 1,
                                         '; divergence cleared' if self._diverged else ''))
        self.get_logger().info('reset requested: ' + response.message)
        return response

    def _do_reset(self):
        cfg = self.config
        self._reset_pending = False
        self._plant = make_plant(cfg)
        self._fk = self._plant.model.fk
        self._injector = self._make_injector(cfg)
        self._limits = self._make_limits(cfg)
        self._applied = [0.0] * cfg.params.n
        self._diverged = None
        self._take_state()
        if not cfg.lockstep and cfg.start_braked:
            self._braked = True
            self._braked_since = _monotonic()
            self._braked_ns = -1
            self._brake_reason = ''
            self.get_logger().info('reset: brakes engaged until the next command')

    # -- joint failures ----------------------------------------------------------
    def _make_injector(self, cfg):
        """Return the failure schedule of a new plant (parameter ``fail_joint``)."""
        injector = Injector(self._plant, cfg.joint_names)
        for j, at in parse_fail_joint(cfg.fail_joint, cfg.joint_names, cfg.params.active):
            injector.schedule(j, at, 'parameter fail_joint')
        return injector

    def _on_fail_joint(self, request, response):
        """~/fail_joint: the joint's actuator and brake fail from the next step."""
        cfg = self.config
        try:
            ((j, _),) = parse_fail_joint('%s@0' % request.joint, cfg.joint_names,
                                         cfg.params.active)
        except (FreejointValueError, ValueError) as exc:
            response.success = False
            response.message = str(exc).replace('fail_joint: ', 'joint: ', 1)
            return response
        # Taken by the stepping thread before its next step (real time: no change of the
        # plant's schedule while it steps).
        self._fail_requests.append(j)
        at = self._plant.t
        response.success = True
        response.at = at
        response.message = '%s fails from the next step (t = %.3f s, step %d)' % (
            request.joint, at, self._k)
        self.get_logger().warn('fail_joint: ' + response.message)
        return response

    def _failures_after_step(self, applied):
        """Failed joints read 0 effort; log, report and publish a failure taking effect."""
        injector = self._injector
        injector.effort(applied)
        for name, at, how in injector.check():
            self.get_logger().warn('joint failure injected: %s failed at t = %.3f s (%s): '
                                   'no torque from then on, effort 0 in joint_states'
                                   % (name, at, how))
            if self._pub_failures is not None:
                self._pub_failures.publish(JOINT_FAILURES.msg_type(data=name))
            self._publish_diagnostics(update=False)

    # -- commands --------------------------------------------------------------
    def _command_effort(self, data):
        """Active efforts in model order from a command's data, or None (refused, logged)."""
        if len(data) != self._r:
            kind = 'length'
            problem = 'expected %d efforts for %s, got %d' % (
                self._r, list(self.config.joints), len(data))
        else:
            for v in data:
                if not _isfinite(v):
                    kind = 'nonfinite'
                    problem = 'non-finite effort in %s' % list(data)
                    break
            else:
                if self._identity:
                    return list(data)
                tau = [0.0] * self._r
                for j, i in enumerate(self._cmd_map):
                    tau[i] = data[j]
                return tau
        self._refused += 1
        self._throttle(self.get_logger().error, kind,
                       'command refused: %s; zero effort applied' % problem)
        return None

    def _read(self, raw):
        """Return a serialized command's (label, data); None if unreadable (counted, logged)."""
        try:
            return read_serialized(raw, self._read_command, COMMANDS.msg_type,
                                   _command_fields)
        except ValueError as exc:
            self._refused += 1
            self._throttle(self.get_logger().error, 'unreadable',
                           'command refused: %s; not applied' % exc)
            return None

    def _take_commands(self):
        """
        Real time: take every command that arrived since the last step, the newest last.

        Each is judged at its receipt: the middleware's reception time (system clock),
        mapped to the monotonic clock by the two clocks read now.
        """
        sub = self._cmd_sub
        handle = sub.handle
        take = handle.take_message
        msg_type = sub.msg_type
        mono = sys_ns = None
        try:
            with handle:
                while True:
                    got = take(msg_type, True)
                    if got is None:
                        return
                    if mono is None:
                        mono, sys_ns = _monotonic(), _time_ns()
                    received = got[1]['received_timestamp'] or sys_ns
                    self._command_arrived(got[0], mono - max(0, sys_ns - received) * 1e-9,
                                          received)
        except InvalidHandle:          # destroyed at shutdown
            return

    def _command_arrived(self, raw, now, received_ns):
        """Real time: a command received at ``now`` (monotonic s), ``received_ns`` (system)."""
        read = self._read(raw)
        if read is None:
            return
        label, data = read
        ns = label_to_stamp(label)     # None: no label, the current step's answer
        tau = self._command_effort(data)
        if ns is not None:   # the age of the state it answers (its grid time) at receipt
            self._note_latency(received_ns - ns)
        answered = -1
        if self._observer is not None:
            answered = self._observer.command_received(ns, self._k, now)
        self._latest = (self._zero if tau is None else tau, now, answered, tau is not None,
                        *self._watchdog.judge(self._qd_list, self._requested_wait),
                        _UNLABELLED if ns is None else ns)
        if self._cmd_timed_out:
            self._cmd_timed_out = False
            self.get_logger().info('commands are back')

    def _on_command(self, raw):
        """Lockstep: a command answering the current step advances it."""
        now = _monotonic()
        read = self._read(raw)
        if read is None:
            return
        label, data = read
        ns = label_to_stamp(label)     # None: no label, the current step's answer
        if self._holding():
            return
        if ns is not None and ns != self._t_ns:
            self.get_logger().debug('dropped a command for stamp %d ns at step %d '
                                    '(t = %d ns)' % (ns, self._k, self._t_ns))
            return
        tau = self._command_effort(data)
        self._note_latency(int((now - self._last_publish) * 1e9))
        if self._observer is not None:
            self._observer.command_answered(self._k, now)
        if not self._got_first:
            self._got_first = True
            self.get_logger().info('first command: running')
        self._advance(self._zero if tau is None else tau)

    # -- stepping --------------------------------------------------------------
    def _holding(self):
        """Return True once a lockstep run has reached ``max_steps`` (it then holds)."""
        return 0 < self._max_steps <= self._k

    def _advance(self, tau):
        """
        Integrate one control period with ``tau`` (active, model order); publish.

        Braked or diverged, the step passes without integration (zero effort applied).
        """
        if self._reset_pending:
            self._do_reset()
        else:
            while self._fail_requests:
                self._injector.schedule(self._fail_requests.pop(0), self._plant.t,
                                        'service ~/fail_joint')
            if self._braked or self._diverged is not None:
                tau = self._zero
            else:
                try:
                    self._plant.step(tau, self._dt)
                except PlantDivergedError as exc:
                    self._diverge(str(exc))
                    tau = self._zero
                else:
                    if not self._take_state():
                        tau = self._zero
            applied = self._applied
            for i, v in zip(self._active, tau):
                applied[i] = v
            if self._injector.scheduled:
                self._failures_after_step(applied)
        self._k += 1
        self._t_ns = self._k * self._dt_ns
        if self._lockstep or self._k % self._every == 0:
            self._publish_state()
        observer = self._observer
        if observer is not None:
            observer.step_done(self._k)
        if self._lockstep and self._k == self._max_steps:
            self.get_logger().info('reached max_steps = %d (t = %.3f s): holding'
                                   % (self._k, self._t_ns * 1e-9))
            if observer is not None:
                observer.run_over()   # no later command can be received

    def _take_state(self):
        """Take the plant's state for publication if sane; else diverge, return False."""
        plant = self._plant
        q = plant.q
        q_list = q.tolist()
        qd_list = plant.qd.tolist()
        reason = divergence_reason(q_list, qd_list, self._max_speed)
        if reason is not None:
            self._diverge('the integration over step %d gave an absurd state: %s'
                          % (self._k, reason))
            return False
        self._q = q
        if self._limits is not None:
            for line in self._limits.observe(plant.t, q_list, qd_list):
                self.get_logger().warning(line + ' (the plant has no end stops: a real arm '
                                          'would be stopped)')
        # published as the joints measure them (the URDF's angles: the arm's offsets off)
        self._q_list = q_list if not self.config.arm.joint_offsets else list(
            self.config.arm.to_joints(q_list))
        self._qd_list = qd_list
        return True

    def _diverge(self, reason):
        """Stop integrating: note, log and report (ERROR on /diagnostics) a divergence."""
        self._diverged = 'step %d: %s' % (self._k, reason)
        self._divergences += 1
        self.get_logger().error('plant diverged at %s; publishing the last sane state, no '
                                'further integration (call ~/reset)' % self._diverged)
        self._publish_diagnostics(update=False)

    def _publish_state(self):
        t_ns = self._t_ns
        if not self._lockstep:
            t_ns += self._rt_origin_ns   # the step's time on the grid, not the wall clock
        stamp = stamp_from_ns(t_ns, self._stamp)
        if self._lockstep:
            k = self._k
            if k % self._clock_every == 0 or k == self._max_steps:
                self._clock_msg.clock = stamp
                self._pub_clock.publish(self._clock_msg)
        sec, nanosec = stamp.sec, stamp.nanosec
        js = self._write_js(sec, nanosec, self._q_list, self._qd_list, self._applied)
        if self._observer is not None:
            self._observer.state_published(self._k, t_ns)
        self._pub_js.publish(js)
        if self._spatial:
            x, y, z = self._fk(self._q).tolist()
        else:
            (x, y), z = self._fk(self._q).tolist(), 0.0
        self._pub_ee.publish(self._write_ee(sec, nanosec, x, y, z))
        now = _monotonic()
        self._waiting_since = now
        self._last_publish = now

    def _lockstep_watchdog(self):
        now = _monotonic()
        if not self._got_first:
            if now - self._last_publish >= REPUBLISH_PERIOD:
                self._publish_state()
                self.get_logger().info('waiting for the first command on %s' %
                                       self._cmd_topic(), throttle_duration_sec=5.0)
            return
        if self._holding():
            return
        if now - self._waiting_since > self._timeout:
            self._timeouts += 1
            self.get_logger().warn(
                'no command for step %d (t = %.3f s) within %g s: zero effort (%d timeouts '
                'so far)' % (self._k, self._t_ns * 1e-9, self._timeout, self._timeouts))
            self._advance(self._zero)

    def _realtime_loop(self):
        """
        Real time: step on the wall clock in a thread of its own.

        Sleeps to the next period boundary ``t0 + (k + 1) dt`` of the monotonic clock (an
        absolute grid: no drift), then takes the commands that arrived, integrates what is due
        and publishes. A thread instead of an executor timer: the state goes out on time even
        while the executor thread runs parameters or a service call, and each period costs
        one wake-up (a timer costs two and fires late under load: docs/performance.md). The
        thread inherits the process's ``thread_priority``; an unexpected error is logged
        (throttled) and stepping goes on.
        """
        stop = self._rt_stop
        sleep = time.sleep
        while not stop.is_set():
            try:
                self._realtime_step()
            except Exception as exc:   # noqa: B902 - a bug must not stop the arm silently
                self._throttle(self.get_logger().error, 'step_error',
                               'real-time step %d failed: %r' % (self._k, exc))
            delay = self._rt_start + (self._k + 1) * self._dt - _monotonic()
            if delay > 0.0:
                sleep(delay)

    def stop_stepping(self):
        """Stop the real-time stepping thread (before the node is destroyed)."""
        if not self._lockstep and self._rt_thread.is_alive():
            self._rt_stop.set()
            self._rt_thread.join(1.0)

    def _realtime_step(self):
        if self._rt_start is None:
            # The grid: step k at rt_start + k dt on the monotonic clock, at
            # rt_origin_ns + k dt_ns in system time (mapped once, here).
            system_ns = self.get_clock().now().nanoseconds
            now = _monotonic()
            self._rt_start = now - self._dt
            self._rt_origin_ns = system_ns - self._dt_ns
        self._take_commands()
        now = _monotonic()
        due = int((now - self._rt_start) / self._dt) - self._k
        if due > MAX_CATCH_UP:
            self._throttle(self.get_logger().warn, 'behind',
                           'real time: %d steps behind the wall clock, dropping %d'
                           % (due, due - 1))
            self._rt_start += (due - 1) * self._dt
            self._rt_origin_ns += (due - 1) * self._dt_ns
            self._dropped += due - 1
            if self._observer is not None:
                self._observer.steps_dropped(due - 1)
            due = 1
        latest = self._latest
        asked = self._brake_asked
        if asked is not None:
            self._brake_asked = None
            if not self._braked and self._diverged is None:
                self._engage_brakes(now, asked)
        if self._braked:
            if (latest is not None and latest[3] and latest[1] >= self._braked_since
                    and latest[6] >= self._braked_ns):
                self._braked = False
                self._brake_reason = ''
                self.get_logger().info('brakes released at step %d (t = %.3f s): first '
                                       'command' % (self._k, self._t_ns * 1e-9))
        elif (latest is not None and self._watchdog.expired(now, latest[1], latest[4])
              and self._diverged is None):
            self._engage_brakes(now, waited=latest[4], wait_kind=latest[5])
        for i in range(due):
            if i:
                self._take_commands()   # catching up: a command answering a state just out
            latest = self._latest
            if latest is None:
                tau = self._zero
            elif now - latest[1] > self._timeout and not self._holds_last:
                tau = self._zero
                if not self._cmd_timed_out:
                    self._cmd_timed_out = True
                    self._timeouts += 1
                    self.get_logger().warn(
                        'no command on %s for %g s: zero effort (not holding the last one)'
                        % (self._cmd_topic(), self._timeout))
            else:
                tau = latest[0]
                if self._observer is not None:
                    self._observer.command_applied(self._k, latest[2])
            self._advance(tau)

    def _engage_brakes(self, now, asked=None, waited=0.0, wait_kind='moving'):
        """
        Stop the arm where it is and hold it until the next accepted command.

        ``asked``: the controller's reason on brake_request; None: the drive watchdog (no
        command for ``waited`` s: brake_timeout, brake_timeout_at_rest after a command
        that found the arm at rest, or the controller's brake_timeout_request: ``wait_kind``,
        the reason of ``DriveWatchdog.judge``).
        """
        self._plant.stop()
        self._take_state()
        self._braked = True
        self._braked_since = now
        # Released by a command answering a state after this one (not one computed before).
        self._braked_ns = self._t_ns + self._rt_origin_ns + 1
        if asked is None:
            self._brake_engagements += 1
            rest = {'at rest': ', the arm at rest',
                    'asked': ', as the controller asked while its setpoint rests (%s)'
                    % BRAKE_TIMEOUT_REQUEST.name}.get(wait_kind, '')
            self._brake_reason = 'no command for %g s%s' % (waited, rest)
            why = 'no command on %s for %g s%s' % (self._cmd_topic(), waited, rest)
        else:
            self._brakes_asked += 1
            self._brake_reason = 'asked on %s' % BRAKE_REQUEST.name
            why = 'the controller asked (%s): %s' % (BRAKE_REQUEST.name, asked)
        self.get_logger().warn(
            '%s: brakes engaged at step %d (t = %.3f s), the arm is held where it is until '
            'the next command' % (why, self._k, self._t_ns * 1e-9))
        self._publish_diagnostics(update=False)

    def _on_brake_timeout_request(self, msg):
        """brake_timeout_request: the wait the commands taken from now on may shorten to."""
        try:
            wait = DriveWatchdog.check_request(msg.data)
        except FreejointValueError as exc:
            self._throttle(self.get_logger().error, 'brake_timeout_request',
                           '%s: ignored, the last good request (%g s) kept' % (
                               exc, self._requested_wait))
            return
        if wait != self._requested_wait:
            self._requested_wait = wait
            self.get_logger().info(
                'the controller asks for the brakes after %g s without a command while its '
                'setpoint rests (%s); the drive waits the shorter of it and its own' % (
                    wait, BRAKE_TIMEOUT_REQUEST.name) if wait > 0.0 else
                "the controller asks for no shorter wait (%s): the drive's own watchdog"
                % BRAKE_TIMEOUT_REQUEST.name)

    def _on_brake_request(self, msg):
        """brake_request: engage the brakes at the next step (the stepping thread does)."""
        if self._holds_last:
            self._throttle(self.get_logger().warn, 'brake_request',
                           'brake_request ignored (%s): this driver holds the last command '
                           '(command_watchdog: false)' % (msg.data or 'no reason given'))
            return
        self._brake_asked = msg.data or 'no reason given'

    def _cmd_topic(self):
        return self.resolve_topic_name('effort_controller/commands')

    # -- status ----------------------------------------------------------------
    def _on_diagnostics_timer(self):
        if self._holding():
            # A lockstep run over at max_steps sends nothing more (a recorder's count then
            # stays steady: drained), after one last status saying so.
            if self._final_status_sent:
                return
            self._final_status_sent = True
        self._publish_diagnostics(update=True)

    def _publish_diagnostics(self, update):
        """Publish the status on /diagnostics; ``update`` starts a new rate window."""
        now = _monotonic()
        k = self._k
        since, k0, refused0, timeouts0, dropped0 = self._diag_window
        elapsed = now - since
        rate = (k - k0) / elapsed if elapsed > 0.0 else 0.0
        refused = self._refused - refused0
        timeouts = self._timeouts - timeouts0
        dropped = self._dropped - dropped0
        latency = self._latency.take(restart=update)
        if update:
            self._diag_window = (now, k, self._refused, self._timeouts, self._dropped)
        warnings = []
        if self._cmd_timed_out:
            warnings.append('no command for %g s: zero effort' % self._timeout)
        elif timeouts:
            warnings.append('%d command timeouts in the last %.1f s: zero effort' % (
                timeouts, elapsed))
        if self._braked and self._brake_reason:
            warnings.append('brakes engaged (%s): the arm is held until the next command'
                            % self._brake_reason)
        if refused:
            warnings.append('%d commands refused in the last %.1f s' % (refused, elapsed))
        if dropped:
            warnings.append('behind the wall clock: %d steps dropped in the last %.1f s' % (
                dropped, elapsed))
        if self._braked:
            ok = 'brakes engaged: holding q0 until the first command'
        elif not self._lockstep and self._latest is None:
            ok = 'no command yet: zero effort'
        elif self._lockstep and not self._got_first:
            ok = 'waiting for the first command'
        elif self._holding():
            ok = 'holding at max_steps'
        else:
            ok = 'running'
        if self._limits is not None and self._limits.passed:
            warnings.append('joints past their URDF limits: ' + self._limits.summary())
        if self._injector.taken:
            warnings.append('joint failure injected: ' + ', '.join(
                '%s at t = %.3f s (%s)' % taken for taken in self._injector.taken))
        errors = [] if self._diverged is None else [
            'plant diverged at %s; publishing the last sane state (call ~/reset)'
            % self._diverged]
        level, message = level_and_message(errors, warnings, ok)
        self._diagnostics.publish(level, message, (
            ('mode', 'lockstep' if self._lockstep else 'realtime'),
            ('step', k),
            ('sim time [s]', '%.3f' % (self._t_ns * 1e-9)),
            ('step rate [Hz]', '%.1f' % rate),
            ('publish rate [Hz]', '%g' % (1.0 / (self._dt * self._every))),
            ('command latency mean [ms]', latency[0]),
            ('command latency max [ms]', latency[1]),
            ('command timeouts', self._timeouts),
            ('refused commands', self._refused),
            ('dropped steps', self._dropped),
            ('brakes', 'engaged' if self._braked else 'released'),
            ('brake engagements (no command)', self._brake_engagements),
            ('brake engagements (asked)', self._brakes_asked),
            ('brake wait asked [s]', '%g' % self._requested_wait if self._requested_wait
             else 'none'),
            ('divergences', self._divergences),
            ('diverged', 'true' if self._diverged is not None else 'false'),
            ('failed joints', ', '.join('%s at %.3f s' % taken[:2]
                                        for taken in self._injector.taken) or 'none')))

    def report(self):
        """One line for the end of the run: steps, timeouts, refusals, brakes, divergences."""
        past = self._limits.summary() if self._limits is not None else ''
        return 'simulator stopped at step %d (t = %.3f s): %d command timeouts, %d refused ' \
            'commands, %d divergences, %d brake engagements (%d asked)%s' % (
                self._k, self._t_ns * 1e-9, self._timeouts, self._refused,
                self._divergences, self._brake_engagements + self._brakes_asked,
                self._brakes_asked,
                '; past their URDF limits: ' + past if past else '')

    @staticmethod
    def _make_limits(cfg):
        """Return the URDF limits' watch of a spatial arm (None: a planar arm)."""
        arm = cfg.arm.spatial
        if arm is None:
            return None
        return LimitWatch(arm.joint_names, arm.lower, arm.upper, arm.velocity)

    @property
    def executor_kind(self):
        """Return the parameter ``executor`` (the runner spins the node with it)."""
        return self.config.executor

    def on_shutdown(self):
        """Stop the real-time stepping thread; tell the step observer the run is over."""
        self.stop_stepping()
        if self._observer is not None:
            self._observer.run_over()

    def destroy_node(self):
        """Stop stepping; destroy the node and (real time) its hidden command node."""
        self.stop_stepping()
        if self._cmd_node is not None:
            self._cmd_node.destroy_node()
        super().destroy_node()


def main(args=None):
    """Run the node until SIGINT/SIGTERM; exit 2 on a bad start-up parameter."""
    return run(SimNode, 'sim_node', args)


if __name__ == '__main__':
    main()
