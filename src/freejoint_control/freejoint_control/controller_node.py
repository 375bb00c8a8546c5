"""
Controller node: the robust Cartesian controller of freejoint_core as a ROS 2 node.

Subscribes ``joint_states`` (sensor_msgs/JointState, joints matched by name, any order,
extra joints ignored) and ``setpoint`` (freejoint_msgs/CartesianSetpoint); per state it
publishes the active joint efforts on ``effort_controller/commands``
(std_msgs/Float64MultiArray in the order of parameter ``joints``, the topic of
ros2_control's JointGroupEffortController) and a ``controller_state``
(freejoint_msgs/ControllerState).  The law itself is ``RobustController.step``, the
hold / resume reference and the guards are ``freejoint_core.reference``; this node only
converts messages, pairs states with setpoints, guards its inputs and outputs and offers
``~/reset`` (std_srvs/Trigger: theta_hat back to theta0, hold / blend state forgotten)
(docs/GRAPH.md: lockstep protocol, staleness, hold, limits, parameters).  Its status goes
to ``/diagnostics`` once a second (answer rate, latency, holds, refusals, law faults; per
tick only counters), and the QoS of its topics can be overridden at start-up with ros2's
``qos_overrides.<topic>.<publisher|subscription>.<history|depth|reliability>`` parameters.
With ``standby: true`` (real time) it is a hot spare (``controller_supervisor``): built and
discovered, setpoints taken, not subscribed to joint_states, nothing published
(``/diagnostics`` says STANDBY) until SIGUSR1; it tells the supervisor it is ready once its
commands and setpoints are matched as the graph lists them and the setpoint stream has
caught up (then it idles at SCHED_FIFO 1, before at the default scheduler); the signal
subscribes it and the first state activates it, its reference starting from the arm's
measured motion (``ReferenceShaper.start_from``), the torque ramped from zero.

"""

import math
import signal
import time

from freejoint_common.contract import COMMANDS, CONTROLLER_STATE, JOINT_STATES
from freejoint_common.contract import REALTIME_STATE_QOS, RESET, SETPOINT, stamp_from_ns
from freejoint_common.contract import stamp_label, STANDBY_SETPOINT_QOS, to_ns
from freejoint_common.diagnostics import Diagnostics, LatencyWindow, level_and_message, OK
from freejoint_common.node_tools import NodeParameters, overridable, plain, QOS_OVERRIDES
from freejoint_common.node_tools import Throttle
from freejoint_common.runner import Lifecycle, run
from freejoint_common.scheduling import process_scheduling
from freejoint_control.params import SCHEMA
from freejoint_control.supervisor import notify_ready
from freejoint_core.control import (ControlOutput, STATUS_BAD_INPUT,
                                    STATUS_NEAR_SINGULAR,
                                    STATUS_STALE_SETPOINT, STATUS_STALE_STATE,
                                    STATUS_TORQUE_LIMITED)
from freejoint_core.delay import extrapolate_setpoint, StatePredictor
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import clamp_dt, limit_effort, setpoint_refusal, state_refusal
from freejoint_core.laws import make_law
from freejoint_core.reference import extrapolate, MODE_HOLD, MODE_NONE, ReferenceShaper
from freejoint_msgs.msg import ControllerState
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import MultiArrayDimension

STATUS_HOLDING = ControllerState.STATUS_HOLDING
STATUS_RATE_LIMITED = ControllerState.STATUS_RATE_LIMITED
STATUS_LAW_FAULT = ControllerState.STATUS_LAW_FAULT
STATUS_RESUMING = ControllerState.STATUS_RESUMING
STATUS_DT_CLAMPED = ControllerState.STATUS_DT_CLAMPED
STATUS_SETPOINT_LATE = ControllerState.STATUS_SETPOINT_LATE

_isfinite = math.isfinite
_monotonic = time.monotonic
_NAME_MAP_CACHE = 16
STANDBY_SETTLE = 0.5
"""[s] A spare is ready once nothing was lacking for this long (its discovery of the graph,
which can list the simulator before the planner, settled)."""
STANDBY_IDLE_STREAM = 0.25
"""[s] A matched setpoint publisher silent this long is not streaming: a spare does not
wait for it to catch up before it tells the supervisor it is ready."""


class ControllerNode(Node, Lifecycle):
    """The robust controller between JointState/CartesianSetpoint and effort commands."""

    def __init__(self, **kwargs):
        super().__init__('controller_node', **kwargs)
        self._params = NodeParameters(self, SCHEMA)   # raises: bad start-up parameters
        self.config = self._params.config
        cfg = self.config
        self._ctl = make_law(cfg.law, cfg.nominal, cfg.gains, model=cfg.nominal_model)
        self._shaper = ReferenceShaper(cfg.resume_time, blend_on_start=not cfg.lockstep)
        self._predictor = None
        self._install(cfg)
        self._params.listen(self._apply)

        self._cmd = COMMANDS.msg_type()
        self._cmd.layout.dim = [MultiArrayDimension(label=stamp_label(0), size=len(cfg.joints),
                                                    stride=len(cfg.joints))]
        self._dim = self._cmd.layout.dim[0]
        self._state = ControllerState()
        self._state.joint_names = list(cfg.joints)
        self._zero = [0.0] * len(cfg.joints)

        self._last_ns = -1            # stamp of the last answered state
        self._pending = None          # lockstep: (ns, stamp, q, qd, since) waiting for a setpoint
        self._setpoints = {}          # lockstep: stamp_ns -> (px, py, vx, vy, ax, ay)
        self._recent = []             # real time: [(stamp_ns, values)], in arrival order
        self._setpoint_seen = False     # a setpoint was received (lockstep: stale timeout on)
        self._setpoint_used = False     # a setpoint was tracked (else: 'no setpoint yet')
        self._late = False              # real time: the last setpoint used was late
        self._last_sp = (0.0, 0.0)
        self._last_state_wall = None
        self._stale_reported = False
        self._last_q = None
        self._last_det = 0.0
        self._name_maps = {}
        self._map_names = None
        self._map = None
        self._ticks = 0
        self._zero_answers = 0
        self._holds = 0
        self._faults = 0
        self._refused_setpoints = 0
        self._refused_states = 0
        self._old_states = 0
        self._stale_periods = 0         # onsets of a stale (or late) setpoint stream
        self._stale_now = False
        self._period_bits = 0           # status bits of the answers of the status period
        self._latency = LatencyWindow()
        self._diag_window = None
        self._quiet_sent = False
        self._last_sp_refusal = ''
        self._good_theta = self._ctl.theta
        # Last command sent, in command order (None: none yet in lockstep, whose start is
        # the paper's; real time starts from the zero effort the arm had).
        self._prev_cmd = None if cfg.lockstep else list(self._zero)
        self._rate_armed = not cfg.lockstep
        # Clock of the state ages: system time (what real-time stamps are on), read without
        # rclpy's Clock.now() (tens of microseconds per call); the ROS clock under sim time.
        if self.get_parameter('use_sim_time').value:
            clock = self.get_clock()
            self._now_ns = lambda: clock.now().nanoseconds
        else:
            self._now_ns = time.time_ns
        self._throttle = Throttle(1.0)
        # Hot spare: idle until SIGUSR1, not subscribed to joint_states (a 1-kHz stream
        # it would only drop). The signal's handler only sets a flag (the EventsExecutor
        # has no guard conditions); the next setpoint or watchdog callback subscribes
        # (the runner's between-callbacks rule) and the first state activates.
        self._standby = cfg.standby
        self._activation_requested = False
        self._start_from_motion = False
        self._activated_wall = None
        self._states_sub = None
        if cfg.standby:
            signal.signal(signal.SIGUSR1, self._on_activate_signal)
            # At the default scheduler until ready (_check_standby_ready): its discovery
            # and the setpoint history it is sent then would spend the kernel's real-time
            # budget of the CPU, which stalls every SCHED_FIFO thread of the graph to the
            # end of the second (measured: 43-49-ms gaps of the simulator as a spare got
            # ready at SCHED_FIFO 1). thread_priority applies from the activation on.
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
        self._sp_sub = self.create_subscription(
            SETPOINT.msg_type, SETPOINT.name, self._on_setpoint,
            overridable(STANDBY_SETPOINT_QOS if cfg.standby else SETPOINT.qos),
            qos_overriding_options=QOS_OVERRIDES)
        # After the setpoints (a spare subscribes later too): the single-threaded executor
        # takes what one wait found ready in the order the subscriptions were made, so a
        # setpoint that came in before a state is applied before the state is answered.
        # Real time: only the newest state matters (a queue of old ones would be answered
        # late, a delay the loop cannot take); lockstep: every state, the sim waits.
        if not cfg.standby:
            self._subscribe_states()
        self._sp_wall = None            # standby: monotonic time of the newest setpoint
        self._sp_matched_wall = None    # standby: when a setpoint publisher was first matched
        self._waiting_for = 'start-up'  # standby: what it waits for before it is ready
        self._settled_since = None      # standby: since when nothing was lacking
        self.create_service(RESET.srv_type, RESET.name, self._on_reset)
        self._diagnostics = Diagnostics(self, 'controller', 'freejoint_control',
                                        self._on_diagnostics_timer)
        self._diag_window = self._window(_monotonic())
        period = min(0.05, cfg.stale_timeout / 4.0)
        self.create_timer(period, self._watchdog, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            'controller ready: %s, nominal scale %g, %s, joints %s, dt %g s, robust %s' % (
                cfg.case, cfg.nominal_scale,
                'lockstep' if cfg.lockstep else 'real time', list(cfg.joints), cfg.dt,
                cfg.gains.robust) + (
                ' (standby: idle until SIGUSR1)' if cfg.standby
                else ''))
        if not cfg.standby:
            notify_ready()
        # A spare tells the supervisor it is ready once it could take over at once: see
        # _check_standby_ready (its watchdog).

    # -- standby ---------------------------------------------------------------
    def _subscribe_states(self):
        """Subscribe ``joint_states`` (real time: the newest state; lockstep: every one)."""
        self._states_sub = self.create_subscription(
            JOINT_STATES.msg_type, JOINT_STATES.name, self._on_joint_state,
            overridable(JOINT_STATES.qos if self.config.lockstep else REALTIME_STATE_QOS),
            qos_overriding_options=QOS_OVERRIDES)

    def _standby_waits_for(self):
        """
        Return what a spare still lacks to take over at once ('' : nothing).

        Its commands matched by every subscriber the graph lists (at least one: the
        simulator or driver); every setpoint publisher the graph lists matched and, with
        one, the stream caught up: the newest setpoint received within the carry-forward
        time of now, or none for STANDBY_IDLE_STREAM s (a planner not streaming). A spare
        activated before (measured: its newest setpoint 0.2 s old) holds until the stream
        catches up.
        """
        # Matched: what this node's endpoints matched; listed: what the graph lists (its
        # discovery can be ahead of the matching).
        matched = self._pub_cmd.get_subscription_count()
        listed = self.count_subscribers(COMMANDS.name)
        if matched == 0 or matched < listed:
            return '%s matched by %d of its %d subscribers' % (
                self.resolve_topic_name(COMMANDS.name), matched, listed)
        matched = self._sp_sub.get_publisher_count()
        listed = self.count_publishers(SETPOINT.name)
        if matched < listed:
            return '%s: %d of its %d publishers matched' % (
                self.resolve_topic_name(SETPOINT.name), matched, listed)
        if matched == 0:
            return ''
        now = _monotonic()
        if self._sp_matched_wall is None:
            self._sp_matched_wall = now
        last = self._sp_wall if self._sp_wall is not None else self._sp_matched_wall
        if now - last > STANDBY_IDLE_STREAM:
            return ''
        if not self._recent:
            return 'the setpoint stream matched, no setpoint received yet'
        behind = (self._now_ns() - self._recent[-1][0]) * 1e-9
        if behind * 1e9 > self._carry_ns:
            return 'the setpoint stream catching up (newest %.3f s old)' % behind
        return ''

    def _check_standby_ready(self):
        """Standby: once nothing was lacking for STANDBY_SETTLE s, tell the supervisor."""
        waits_for = self._standby_waits_for()
        now = _monotonic()
        if waits_for:
            self._waiting_for = waits_for
            self._settled_since = None
            return
        if self._settled_since is None:
            self._settled_since = now
        if now - self._settled_since < STANDBY_SETTLE:
            self._waiting_for = 'the graph settling'
            return
        self._waiting_for = ''
        # Idle at SCHED_FIFO 1 (with a thread_priority above 1): below every real-time
        # thread of the graph (idle, it takes only the setpoints), above best-effort load,
        # which must not starve it: its activation must not wait for a CPU.
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

    def _activate(self):
        """Leave standby: this state and the next are answered; start from the motion."""
        self._standby = False
        self._start_from_motion = True
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

    def _start_from(self, q, qd):
        """Start the reference from the measured end-effector motion (fk, J qd)."""
        model = self._ctl.model
        try:
            p = model.fk(q)
            v = model.jacobian(q) @ np.asarray(qd, dtype=float)
            self._shaper.start_from(p.tolist(), v.tolist())
        except (FreejointValueError, ArithmeticError) as exc:
            self._shaper.reset()
            self.get_logger().error('cannot start from the measured motion (%s): blending '
                                    'from the position at rest' % exc)

    # -- parameters ------------------------------------------------------------
    def _install(self, cfg):
        """Cache what the tick needs from a validated configuration."""
        self.config = cfg
        self._dt = cfg.dt
        self._half_ns = cfg.dt_ns // 2
        self._late_ns = cfg.late_periods * cfg.dt_ns
        self._carry_ns = round(cfg.carry_forward_time * 1e9)
        self._max_age_ns = 0 if cfg.lockstep else round(cfg.max_state_age * 1e9)
        self._stale = cfg.stale_timeout
        self._lockstep = cfg.lockstep
        self._identity = cfg.cmd_index == tuple(range(len(cfg.cmd_index)))
        self._limits = cfg.effort_limits
        self._rate = cfg.effort_rate_limit
        self._hold_on_stale = cfg.on_stale_setpoint == 'hold'
        self._shaper.set_resume_time(cfg.resume_time)
        self._hold_stiffness = cfg.hold_stiffness
        self._shaper.set_bounds(cfg.resume_max_velocity, cfg.resume_max_acceleration)
        self._sp_bounds = (cfg.reach, cfg.setpoint_max_velocity, cfg.setpoint_max_acceleration)
        self._state_bounds = (cfg.position_lower, cfg.position_upper, cfg.velocity_limit)
        if cfg.delay_compensation == 'predict':
            if self._predictor is None or self._predictor.params != cfg.nominal:
                self._predictor = StatePredictor(cfg.nominal, cfg.dt)
        else:
            self._predictor = None
        self._active_of_cmd = cfg.cmd_index

    def _apply(self, old, cfg, params):
        """Take a validated parameter change (the set-parameters callback's last step)."""
        if cfg.nominal != old.nominal:
            self._ctl.set_nominal(cfg.nominal, cfg.nominal_model)
        if cfg.gains != old.gains:
            self._ctl.set_gains(cfg.gains)
            if cfg.gains.theta0 != old.gains.theta0:
                self._ctl.reset()
            self._good_theta = self._ctl.theta
        self._install(cfg)
        changed = ', '.join('%s=%s' % (p.name, plain(p.value)) for p in params)
        self.get_logger().info('parameters set (effective next tick): ' + changed)

    # -- inputs ----------------------------------------------------------------
    def _joint_map(self, names):
        """Map a JointState name list to the model joints' indices (cached per list)."""
        key = tuple(names)
        found = self._name_maps.get(key)
        if found is None:
            want = self.config.joint_names
            missing = [n for n in want if n not in key]
            if missing:
                found = (None, 'JointState lacks joint(s) %s (has %s)' % (missing, list(key)),
                         'missing')
            else:
                found = (tuple(key.index(n) for n in want), '', '')
            if len(self._name_maps) >= _NAME_MAP_CACHE:
                self._name_maps.clear()
            self._name_maps[key] = found
        self._map_names = names
        self._map = found
        return found

    def _on_joint_state(self, msg):
        if self._standby:
            self._activate()    # the first state after SIGUSR1 (subscribed at the signal)
        stamp = msg.header.stamp
        ns = to_ns(stamp)
        self._last_state_wall = _monotonic()
        self._stale_reported = False
        if self._max_age_ns:
            age_ns = self._now_ns() - ns
            if age_ns > self._max_age_ns:
                self._old_states += 1
                self._throttle(self.get_logger().warn, 'old_state',
                               'state stamped %d ns is %.3f s old (> max_state_age %g s): '
                               'skipped, no command from it' % (
                                   ns, age_ns * 1e-9, self.config.max_state_age))
                return
        if ns == self._last_ns:
            # A repeated state (the sim's start-up republication): same answer, no new update.
            self._pub_cmd.publish(self._cmd)
            self._pub_state.publish(self._state)
            return
        if ns < self._last_ns:
            self.get_logger().warn(
                'state time went back from %d to %d ns (simulator restarted?): theta_hat '
                'reset to theta0' % (self._last_ns, ns))
            self._restart_state()
            self._setpoints.clear()
            self._recent.clear()
        names = msg.name
        found = self._map if names == self._map_names else self._joint_map(names)
        idx, reason, kind = found
        if idx is not None:
            pos = msg.position
            vel = msg.velocity
            try:
                if len(idx) == 3:
                    i0, i1, i2 = idx
                    q = (pos[i0], pos[i1], pos[i2])
                    qd = (vel[i0], vel[i1], vel[i2])
                else:   # an arm of another number of joints (robot_description)
                    q = tuple([pos[i] for i in idx])
                    qd = tuple([vel[i] for i in idx])
            except (IndexError, ValueError):
                q = None
                kind = 'short'
                reason = 'JointState has %d names but %d positions and %d velocities' % (
                    len(names), len(pos), len(vel))
            if q is not None and not all(map(_isfinite, q + qd)):
                kind = 'nonfinite'
                reason = 'JointState has a non-finite position or velocity: q=%s qd=%s' % (
                    list(q), list(qd))
                q = None
            if q is not None:
                lower, upper, vlim = self._state_bounds
                implausible = state_refusal(q, qd, lower, upper, vlim)
                if implausible is not None:
                    kind = 'implausible'
                    reason = 'implausible state: ' + implausible
                    q = None
        else:
            q = None
        if q is None:
            self._refused_states += 1
            self._throttle(self.get_logger().error, kind,
                           'state refused: %s; zero effort, theta_hat kept' % reason)
            self._answer_zero(ns, stamp, STATUS_BAD_INPUT, 'bad input: ' + reason)
            return
        self._last_q = q
        if self._start_from_motion:
            self._start_from_motion = False
            self._start_from(q, qd)
        if self._lockstep:
            sp = self._setpoints.pop(ns, None)
            if sp is None:
                if self._shaper.mode == MODE_HOLD and self._setpoint_seen:
                    # Already holding on a stale stream: answer at once, not a timeout per tick.
                    self._pending = None
                    self._no_setpoint(ns, stamp, q, qd)
                    return
                self._pending = (ns, stamp, q, qd, _monotonic())
                return
            self._pending = None
            self._tick(ns, stamp, q, qd, ns, sp)
        else:
            found = self._realtime_setpoint(ns)
            if found is None:
                self._no_setpoint(ns, stamp, q, qd)
                return
            if ns - found[0] > self._carry_ns and self._hold_on_stale:
                self._no_setpoint(ns, stamp, q, qd, (ns - found[0]) * 1e-9)
                return
            self._tick(ns, stamp, q, qd, found[0], found[1])

    def _no_setpoint(self, ns, stamp, q, qd, late=None):
        """Answer a state without a fresh (or timely) setpoint: hold or zero effort."""
        if late is not None:
            why = ('setpoint stream late: the newest is %.3g s old, carried forward %g s at '
                   'most' % (late, self.config.carry_forward_time))
        elif self._setpoint_used:
            why = ('stale setpoint: none stamped within %g s before the state%s'
                   % (self._stale, self._sp_refusal_note()))
        else:
            why = 'no setpoint yet' + self._sp_refusal_note()
        if not self._stale_now and (late is not None or self._setpoint_used):
            self._stale_now = True
            self._stale_periods += 1
        if not self._hold_on_stale:
            self._throttle(self.get_logger().warn, 'stale_setpoint', why + ': zero effort')
            self._answer_zero(ns, stamp, STATUS_STALE_SETPOINT, why + ': zero effort')
            return
        if self._shaper.mode != MODE_HOLD:
            self._holds += 1
            self._throttle(self.get_logger().warn, 'hold', why + ': holding position')
        self._tick(ns, stamp, q, qd, None, None, why, late is not None)

    def _sp_refusal_note(self):
        text = self._last_sp_refusal
        return ' (last setpoint refused: %s)' % text if text else ''

    def _realtime_setpoint(self, ns):
        """
        Return (stamp_ns, values) of the newest fresh setpoint for ns, or None.

        Fresh: stamped <= ns + dt/2 and not older than stale_timeout.
        """
        recent = self._recent
        limit = ns + self._half_ns
        while len(recent) > 1 and recent[1][0] <= limit:
            del recent[0]
        if not recent or recent[0][0] > limit:
            return None
        found = recent[0]
        if (ns - found[0]) * 1e-9 > self._stale:
            return None
        return found

    def _on_setpoint(self, msg):
        if self._activation_requested and self._standby:
            self._on_activation_requested()
        stamp = msg.header.stamp
        ns = to_ns(stamp)
        p = msg.position
        v = msg.velocity
        a = msg.acceleration
        values = (p[0], p[1], v[0], v[1], a[0], a[1])
        reach, vmax, amax = self._sp_bounds
        reason = setpoint_refusal(values, reach, vmax, amax)
        if reason is not None:
            self._refused_setpoints += 1
            self._last_sp_refusal = reason
            self._throttle(self.get_logger().error, 'setpoint',
                           'setpoint stamped %d ns refused: %s; dropped' % (ns, reason))
            return
        self._last_sp_refusal = ''
        self._setpoint_seen = True
        if self._standby:
            self._sp_wall = _monotonic()    # only a spare's readiness reads it
        if not self._lockstep:
            recent = self._recent
            recent.append((ns, values))
            if len(recent) > 1000:
                del recent[:500]
            return
        pending = self._pending
        if pending is not None and pending[0] == ns:
            self._pending = None
            self._tick(ns, pending[1], pending[2], pending[3], ns, values)
        elif ns > self._last_ns:
            setpoints = self._setpoints
            setpoints[ns] = values
            if len(setpoints) > 10000:
                for key in sorted(setpoints)[:5000]:
                    del setpoints[key]

    # -- outputs ---------------------------------------------------------------
    def _tick(self, ns, stamp, q, qd, sp_ns, sp, hold_reason='', late=False):
        """Compute and publish the command for the state stamped ns (sp None: hold)."""
        status = 0
        shaper = self._shaper
        if self._lockstep or self._last_ns < 0:
            dt = self._dt
        else:
            dt, clamped = clamp_dt((ns - self._last_ns) * 1e-9, self._dt)
            if clamped:
                status |= STATUS_DT_CLAMPED
                self._throttle(self.get_logger().warn, 'dt',
                               'state stamps %g s apart, outside [0.25, 4] x control_period: '
                               'the law uses dt = %g s' % ((ns - self._last_ns) * 1e-9, dt))
        if sp is None:
            self._late = False
            if shaper.mode != MODE_HOLD:
                ref = shaper.hold(self._ctl.model.fk(q).tolist())
                self._rate_armed = self._prev_cmd is not None
            else:
                ref = shaper.hold(None)
            status |= STATUS_HOLDING
            if late:
                status |= STATUS_SETPOINT_LATE
            elif self._setpoint_used:
                status |= STATUS_STALE_SETPOINT
        else:
            if not self._lockstep:
                age_ns = ns - sp_ns
                if age_ns > 0:
                    sp = extrapolate(sp, age_ns * 1e-9)
                late = age_ns > self._late_ns
                if late:
                    status |= STATUS_SETPOINT_LATE
                elif self._late:
                    shaper.restart_blend()       # the stream is back: no step to it
                self._late = late
            p_now = self._ctl.model.fk(q).tolist() if shaper.mode == MODE_NONE else None
            ref, blending = shaper.track(ns * 1e-9, sp, p_now)
            self._setpoint_used = True
            self._stale_now = False
            if blending:
                status |= STATUS_RESUMING
        stiffness = shaper.stiffness(self._hold_stiffness)
        if stiffness != self._ctl.stiffness:
            self._ctl.set_stiffness(stiffness)
        px, py, vx, vy, ax, ay = ref
        pred = self._predictor
        limits = self._limits
        fault = None
        try:
            if pred is None:
                out = self._ctl.step(q, qd, (px, py), (vx, vy), (ax, ay), dt)
            else:
                out = self._predicted_step(pred, ns, q, qd, ref, dt)
        except (FreejointValueError, ArithmeticError) as exc:
            out = None
            fault = 'result (%s: %s)' % (type(exc).__name__, exc)
        if out is not None:
            tau = out.tau.tolist()
            theta = out.theta.tolist()
            effort = tau if self._identity else [tau[i] for i in self.config.cmd_index]
            for i, x in enumerate(effort):
                if not -limits[i] <= x <= limits[i]:
                    fault = 'torque %r' % (effort,)
            tmax = self.config.gains.theta_max
            for i, x in enumerate(theta):
                if not 0.0 <= x <= tmax[i]:
                    fault = 'theta_hat %r' % (theta,)
        if fault is not None:
            self._faults += 1
            self._ctl.set_theta(self._good_theta)
            theta = self._good_theta.tolist()
            effort = list(self._prev_cmd) if self._prev_cmd is not None else list(self._zero)
            status |= STATUS_LAW_FAULT
            self._throttle(self.get_logger().error, 'fault',
                           'the law gave a non-finite or out-of-range %s: not published, '
                           'theta_hat restored, previous command repeated' % fault)
            out = self._fault_output(q, theta)
        else:
            self._good_theta = out.theta
        status |= out.status
        if self._rate_armed:
            effort, clipped, rated = limit_effort(effort, limits, self._prev_cmd,
                                                  self._rate * dt)
            if rated:
                status |= STATUS_RATE_LIMITED
            else:
                self._rate_armed = False
        self._prev_cmd = effort
        if pred is not None:
            self._push(effort)
        cmd = self._cmd
        cmd.data = effort
        self._dim.label = stamp_label(ns)
        self._pub_cmd.publish(cmd)
        st = self._state
        st.header.stamp = stamp
        st.error = out.e
        st.error_rate = out.edot
        st.sliding = out.s
        st.theta_hat = theta
        st.rho_hat = out.rho
        st.delta_v = out.dv
        st.effort = effort
        st.det_dd = out.det
        st.position = out.p if pred is None else self._ctl.model.fk(q)
        st.position_desired = (px, py)
        st.status = status
        st.message = _status_message(status, out.det, self.config, hold_reason,
                                     shaper) if status else ''
        if sp_ns is None:
            st.setpoint_stamp.sec = 0
            st.setpoint_stamp.nanosec = 0
            st.setpoint_age = 0.0
        else:
            stamp_from_ns(sp_ns, st.setpoint_stamp)
            st.setpoint_age = (ns - sp_ns) * 1e-9
        st.dt = dt
        if self._lockstep:
            # Sim time stands still until the command; the status gives the wall time
            # from the state's receipt to its command.
            st.state_age = 0.0
            self._latency.note(int((_monotonic() - self._last_state_wall) * 1e9))
        else:
            age_ns = self._now_ns() - ns
            st.state_age = age_ns * 1e-9
            self._latency.note(age_ns)
        self._pub_state.publish(st)
        self._period_bits |= status
        self._last_ns = ns
        self._last_sp = (px, py)
        self._last_det = out.det
        self._ticks += 1

    def _fault_output(self, q, theta):
        """Return the published terms of a tick whose law result was refused."""
        zero2 = np.zeros(2)
        return ControlOutput(np.zeros(len(self._zero)), zero2, zero2, zero2,
                             np.array(theta), 0.0, zero2, self._last_det,
                             self._ctl.model.fk(q), 0)

    def _predicted_step(self, pred, ns, q, qd, ref, dt):
        """Run the law on the state predicted to when the command takes effect."""
        age = (self._now_ns() - ns) * 1e-9
        ticks = min(pred.max_ticks, max(1, math.ceil(age / self._dt - 1e-9)))
        try:
            q_pred, qd_pred = pred.predict(q, qd, ticks)
            h = ticks * self._dt
            p, v, a = extrapolate_setpoint(ref[0:2], ref[2:4], ref[4:6], h)
        except FreejointValueError as exc:
            self._throttle(self.get_logger().error, 'predict',
                           'state prediction failed (%s): the law uses the measured state'
                           % exc)
            return self._ctl.step(q, qd, ref[0:2], ref[2:4], ref[4:6], dt)
        return self._ctl.step(q_pred, qd_pred, p, v, a, dt)

    def _push(self, effort):
        """Record the command sent (command order) in the predictor (model order)."""
        tau = [0.0] * len(effort)
        for j, i in enumerate(self._active_of_cmd):
            tau[i] = effort[j]
        self._predictor.push(tau)

    def _answer_zero(self, ns, stamp, status, message):
        """Command zero effort for the state stamped ns; say why in the state message."""
        cmd = self._cmd
        cmd.data = self._zero
        self._dim.label = stamp_label(ns)
        self._pub_cmd.publish(cmd)
        st = self._state
        st.header.stamp = stamp
        zero2 = (0.0, 0.0)
        st.error = zero2
        st.error_rate = zero2
        st.sliding = zero2
        st.theta_hat = self._ctl.theta
        st.rho_hat = 0.0
        st.delta_v = zero2
        st.effort = self._zero
        st.det_dd = self._last_det
        q = self._last_q
        st.position = self._ctl.model.fk(q) if q is not None else self._last_sp
        st.position_desired = self._last_sp
        st.status = status
        st.message = message
        st.setpoint_stamp.sec = 0
        st.setpoint_stamp.nanosec = 0
        st.setpoint_age = 0.0
        st.dt = 0.0
        st.state_age = 0.0 if self._lockstep or ns < 0 else (
            self._now_ns() - ns) * 1e-9
        self._pub_state.publish(st)
        self._period_bits |= status
        if ns >= 0:
            self._last_ns = ns
        self._zero_answers += 1
        # The arm got zero: the next computed command ramps up from it.
        self._prev_cmd = list(self._zero)
        self._rate_armed = True
        if self._predictor is not None:
            self._push(self._zero)

    def _restart_state(self):
        """theta_hat back to theta0, hold / blend forgotten, the rate limit armed."""
        self._ctl.reset()
        self._good_theta = self._ctl.theta
        self._shaper.reset()
        self._rate_armed = self._prev_cmd is not None
        if self._predictor is not None:
            self._predictor.reset()

    def _on_reset(self, request, response):
        """~/reset: restart theta_hat and the hold / blend state (std_srvs/Trigger)."""
        self._restart_state()
        self.get_logger().warn('reset: theta_hat = theta0 %s, hold / blend state cleared'
                               % list(self.config.gains.theta0))
        response.success = True
        response.message = 'theta_hat reset to theta0 %s; hold / blend state cleared' % (
            list(self.config.gains.theta0),)
        return response

    def _watchdog(self):
        """Wall-clock staleness: a held lockstep state without setpoint, or no state."""
        if self._standby:
            if self._activation_requested:
                self._on_activation_requested()     # no setpoint stream: at the latest here
            elif self._waiting_for:
                self._check_standby_ready()
        now = _monotonic()
        pending = self._pending
        if pending is not None:
            if self._setpoint_seen and now - pending[4] > self._stale:
                self._pending = None
                self._no_setpoint(pending[0], pending[1], pending[2], pending[3])
            return
        last = self._last_state_wall
        if last is not None and not self._stale_reported and now - last > self._stale:
            self._stale_reported = True
            self.get_logger().warn('no joint_states for %g s: zero effort' % self._stale)
            stamp = self._state.header.stamp
            self._answer_zero(self._last_ns, stamp, STATUS_STALE_STATE,
                              'stale state: no joint_states within %g s' % self._stale)
            if not self._lockstep:
                # The arm moved under zero effort: the next state starts a hold / blend.
                self._shaper.reset()

    # -- status ----------------------------------------------------------------
    def _window(self, now):
        """Return what a status period starts from: its time and the counters."""
        return (now, self._ticks + self._zero_answers, self._faults, self._refused_states,
                self._refused_setpoints, self._old_states)

    def _on_diagnostics_timer(self):
        """Every second: the status on /diagnostics (lockstep: once while no state comes)."""
        if self._standby:
            self._diag_window = self._window(_monotonic())
            self._diagnostics.publish(
                OK, 'STANDBY: hot spare, not subscribed to joint_states until SIGUSR1' + (
                    '; not ready: %s' % self._waiting_for if self._waiting_for else ''),
                (('mode', 'standby'), ('ready', 'no' if self._waiting_for else 'yes')))
            return
        last = self._last_state_wall
        silent = last is None or last < self._diag_window[0]
        if self._lockstep and silent:
            # Sim time stands still (the simulator waits, holds at max_steps or is gone):
            # one status says so, then nothing until states come (a recorder drains).
            if self._quiet_sent:
                self._diag_window = self._window(_monotonic())
                return
            self._quiet_sent = True
        else:
            self._quiet_sent = False
        self._publish_diagnostics(silent)

    def _publish_diagnostics(self, silent):
        """Build and publish the status of the period now ending (once a second)."""
        now = _monotonic()
        since, answers0, faults0, refused_states0, refused_sp0, old0 = self._diag_window
        self._diag_window = self._window(now)
        elapsed = now - since
        answers = self._ticks + self._zero_answers - answers0
        faults = self._faults - faults0
        refused_states = self._refused_states - refused_states0
        refused_sp = self._refused_setpoints - refused_sp0
        old = self._old_states - old0
        bits = self._period_bits
        self._period_bits = 0
        latency = self._latency.take()
        st = self._state
        current = st.status
        period = 'in the last %.1f s' % elapsed
        errors = []
        warnings = []
        no_state = None
        if self._last_state_wall is None:
            no_state = 'no joint_states yet on %s' % self.resolve_topic_name('joint_states')
        elif self._stale_reported:
            no_state = 'no joint_states for %g s: zero effort commanded' % self._stale
        elif silent:
            no_state = 'no joint_states %s' % period
        if no_state is not None:
            if self._lockstep:
                warnings.append(no_state + ' (lockstep: simulation time stands still)')
            else:
                errors.append(no_state)
        if faults:
            errors.append('%d law faults %s: the previous command repeated, theta_hat '
                          'restored' % (faults, period))
        if current & STATUS_HOLDING or (current & STATUS_STALE_SETPOINT
                                        and not self._hold_on_stale):
            warnings.append(st.message)
        elif bits & STATUS_HOLDING:
            warnings.append('held %s' % period)
        for bit, text in ((STATUS_RATE_LIMITED, 'torque change rate limited'),
                          (STATUS_TORQUE_LIMITED, 'torque limited'),
                          (STATUS_SETPOINT_LATE, 'setpoint stream late (carried forward)'),
                          (STATUS_DT_CLAMPED, 'state stamps irregular: dt clamped')):
            if bits & bit:
                warnings.append('%s %s' % (text, period))
        for count, what in ((refused_states, 'states refused'),
                            (refused_sp, 'setpoints refused'),
                            (old, 'states skipped as too old')):
            if count:
                warnings.append('%d %s %s' % (count, what, period))
        if self._pending is not None:
            ok = ('waiting for the setpoint of the state stamped %d ns (lockstep)'
                  % self._pending[0])
        else:
            ok = st.message or 'tracking'
        level, message = level_and_message(errors, warnings, ok)
        self._diagnostics.publish(level, message, (
            ('mode', 'lockstep' if self._lockstep else 'realtime'),
            ('activated from standby', 'no' if self._activated_wall is None
             else 'at %.3f (system time)' % self._activated_wall),
            ('answer rate [Hz]', '%.1f' % (answers / elapsed if elapsed > 0.0 else 0.0)),
            ('latency mean [ms]', latency[0]),
            ('latency max [ms]', latency[1]),
            ('status', current),
            ('status message', st.message),
            ('ticks', self._ticks),
            ('zero-effort answers', self._zero_answers),
            ('holds', self._holds),
            ('stale setpoint periods', self._stale_periods),
            ('refused states', self._refused_states),
            ('refused setpoints', self._refused_setpoints),
            ('law faults', self._faults),
            ('old states skipped', self._old_states)))

    def report(self):
        """One line for the end of the run: ticks, zero-effort answers, holds, refusals."""
        return ('controller stopped: %d ticks computed, %d zero-effort answers (stale or bad '
                'input), %d holds, %d states and %d setpoints refused, %d law faults, %d '
                'states skipped as too old'
                % (self._ticks, self._zero_answers, self._holds, self._refused_states,
                   self._refused_setpoints, self._faults, self._old_states))

    @property
    def executor_kind(self):
        """Return the parameter ``executor`` (the runner spins the node with it)."""
        return self.config.executor


def _status_message(status, det, cfg, hold_reason, shaper):
    parts = []
    if status & STATUS_HOLDING:
        hold = shaper.hold_position
        parts.append('holding at (%.4f, %.4f) m: %s' % (hold[0], hold[1], hold_reason))
    if status & STATUS_RESUMING:
        parts.append('resuming: blending from the hold to the setpoint over %.3g s'
                     % shaper.blend_duration)
    if status & STATUS_NEAR_SINGULAR:
        parts.append('near singular: |det(Da Da^T)| = %.3g < %.3g, damped pseudo-inverse'
                     % (det, cfg.gains.det_threshold))
    if status & STATUS_TORQUE_LIMITED:
        parts.append('torque limited to %s N m' % list(cfg.effort_limits))
    if status & STATUS_RATE_LIMITED:
        parts.append('torque change limited to %g N m/s' % cfg.effort_rate_limit)
    if status & STATUS_LAW_FAULT:
        parts.append('law fault: non-finite or out-of-range output, previous command repeated')
    if status & STATUS_SETPOINT_LATE and not status & STATUS_HOLDING:
        parts.append('setpoint late: the newest is older than %d control periods, carried '
                     'forward along its velocity and acceleration' % cfg.late_periods)
    if status & STATUS_DT_CLAMPED:
        parts.append('state stamps outside [0.25, 4] x control_period: dt clamped')
    return '; '.join(parts)


def main(args=None):
    """Run the node until SIGINT/SIGTERM; exit 2 on a bad start-up parameter."""
    return run(ControllerNode, 'controller_node', args)


if __name__ == '__main__':
    main()
