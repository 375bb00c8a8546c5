"""
Planner node: singularity-checked circle plans streamed on the control grid.

At start (and whenever a map parameter changes: ``case``, ``nominal_scale``,
``resolution_deg``, ``eps_d``) it computes the singularity map of the nominal arm and the
semi-singular region (``freejoint_core.singularity``; about 0.1 s at 0.25 deg, during
which the node does nothing else), publishes it as ``semi_singular_map``
(nav_msgs/OccupancyGrid, transient local; 100 semi-singular, 0 nonsingular, -1 out of
reach) and checks circles against it. A circle that enters the semi-singular region or
leaves the reach is refused with the reason (``~/plan_circle`` answers it; a parameter
change gets it back from ``ros2 param set``) and never streams: the running plan goes on.

An accepted plan streams ``setpoints`` (freejoint_msgs/CartesianSetpoints: the ticks of a
firing in one message) on the control grid of the ROS clock as ``docs/GRAPH.md`` lays down:
triggered by every ``/clock`` message in sim time (by a wall timer reading the system clock
otherwise, every ``max(1, lookahead // 2)`` control periods: each firing publishes about
half the lookahead at once, a tenth of the wake-ups of a 1/control_period timer at the
default 20), each tick ``t_k = k dt`` with ``t_k <= now + lookahead dt`` published once, in
order, carrying ``CircleQuintic.sample_tuple(k_plan dt)``. The planned path goes out as a
LINE_STRIP on ``planned_path`` (visualization_msgs/Marker, transient local).

Sim time (``use_sim_time``, the switch every ROS node has): ROS time advances only with
``/clock``, which the lockstep simulator may publish every ``N``-th step only (its
``clock_rate``). The ticks between two ``/clock`` messages must already be out when the first
of them arrives, so ``lookahead >= N - 1`` is required and ``lookahead >= 2 N - 1`` rides
out one lost ``/clock`` (``stream.py``). The node learns ``N`` from the ``/clock`` it sees,
logs it with the verdict, and warns, naming the rule, when ticks went out after ROS time
had passed them. It takes ``/clock`` once: its own subscription triggers the stream and
sets the node's ROS clock (``ROSClock.set_ros_time_override``), in place of rclpy's
``TimeSource``, which would subscribe ``/clock`` a second time (a delivery and a Python
callback per message); ``freejoint_common.clock.own_clock`` removes the TimeSource's
subscription (the TimeSource still switches the ROS clock on ``use_sim_time``).

With ``autostart`` the configured circle (parameters ``centre``, ``radius``, ``duration``,
``start_angle``, ``direction``, ``start_delay``) starts at activation and again, anew,
after every accepted change of those parameters.

No step in the reference (``docs/GRAPH.md``, Plan changes): a plan accepted once the stream
has published a tick starts from the stream's state at its first unpublished tick, by a
quintic transition into the circle's start (``planning.prepare_transition``,
``freejoint_core.trajectory.plan_transition``), refused with the reason when none fits the
bounds or its path enters the region, and while another transition runs. A plan from rest
(nothing streamed yet on the time base: the first plan, or the running one after ROS time
went back) starts where the arm is: the end effector of the newest ``joint_states`` (the
nominal model's kinematics) by a transition from rest into the circle's start, held to the
circle's own peaks and largest step per tick (``planning.transition_from_rest``), or is
refused with the reason. The joint states are taken only when needed (a subscription of
depth 1 on a hidden helper node no executor spins: no callback per tick); with a
``joint_states`` publisher but no state yet the plan waits for one (the stream only follows
the clock); with none at all (in real time: none within ``ARM_DISCOVERY_S`` of the
planner's start) it starts at the circle's start as before (logged).
A joint reported failed on ``joint_failures`` (std_msgs/String, its name: a driver's or
operator's notice, or the controller's detection) joins the passive set of the
arm the planner plans for (``planning.after_failure``): the map is recomputed for that arm
and checks the plans from then on, or, if the arm cannot track (fewer active joints than
the task has, or an internal motion that runs away), every plan is refused saying why; the
running plan goes on (the controller decides what the arm does). That assessment and the
new map (0.05-0.25 s of CPU) are made at the next plan request, not at the failure, when
the graph needs the CPU (measured in real time: on the executor they stalled the stream,
in a process beside it they starved the middleware).
Its state goes on ``/diagnostics`` once a second (``planning.planner_status``): ready
(OK), settling (WARN: the settle gate's free link still swinging) or cannot
plan (ERROR: a joint failure left an arm that cannot track), with the running plan's id
and the passive joints of its arm.
Refusals name the usable region (``SingularityModel.usable``). Every circle is
held to the arm's reach and to ``max_speed`` / ``max_acceleration``. ``lookahead`` is checked
against the clock spacing rule at run time.

A spatial arm (``task_dim`` 3, ``NodeArm.spatial``) takes another branch, the
planar one untouched: its plan is the offline runner's circle
(``spatial_planning.SpatialCircle``: ``freejoint_core.spatial_offline.circle(p0, radius, t,
duration, normal)``) from the tip ``p0`` of the arm's joint state, in the vertical plane
facing the robot or the plane of ``plane_normal``, streamed with 3 values per vector (in
lockstep the configured plan starts at tick 0, so tick k carries ``circle(p0, radius, k dt,
duration, normal)``). ``radius``, ``duration``, ``plane_normal`` and ``start_delay``
apply; ``centre``, ``start_angle``, ``direction``, ``circles`` and ``rest`` do not (refused
away from their defaults, ``params.PLANAR_ONLY``). A plan from rest (the
configured one, or any after ROS time went back) is checked when it starts, from the
newest joint state (it waits for one): speed and acceleration bounds, reach, a free joint
that must carry gravity, and the nominal closed loop (``spatial_planning.nominal_loop``:
kappa, the active joints' URDF limits, tracking; 0.6-1.1 s of CPU for the example arms,
during which the node does nothing else), refused with one line in the log (nothing
streams). A plan asked for by ``~/plan_circle`` (``radius``, ``duration``, ``execute``;
``centre``, ``start_angle`` and ``direction`` must be ``[0, 0]``, 0, 0 or 1 (0: the
request's default, the one direction a spatial circle has); ``margin`` is the
reach margin [m]; with no joint state yet, an executed one is checked when it starts), or
by a change of ``radius`` / ``duration`` once the stream has published, is checked at once
from the newest joint state and starts where the running plan rests, at its start or its
end point: there is no 3-D transition, so one asked for while the running circle moves is
refused, saying until when. The singularity map
(``semi_singular_map``), the settle gate and the assessment of a reported joint failure
are planar: none is used (a failure refuses every later plan).
"""

from dataclasses import replace
import math
import time

from freejoint_common.arm_description import resolve_arm
from freejoint_common.clock import own_clock, set_ros_time
from freejoint_common.contract import CLOCK, CLOCK_SUBSCRIPTION_QOS, CONTROLLER_READINESS
from freejoint_common.contract import FOLLOW_CIRCLE, JOINT_FAILURES, JOINT_STATES, PLAN_CIRCLE
from freejoint_common.contract import PLAN_OUTCOME, PLANNED_PATH, profile, SEMI_SINGULAR_MAP
from freejoint_common.contract import SETPOINTS, to_ns
from freejoint_common.diagnostics import Diagnostics, ERROR, OK, WARN
from freejoint_common.node_tools import NodeParameters, overridable, QOS_OVERRIDES
from freejoint_common.runner import Lifecycle, run
from freejoint_common.schema import nullspace_kd
from freejoint_core.arm import table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.singularity import check_path
from freejoint_core.trajectory import CircleQuintic, RepeatedCircle
import numpy as np
from rclpy.action import ActionServer, CancelResponse
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future

from .conversions import occupancy_grid, outcome_msg, path_marker, setpoints_msg
from .params import CIRCLE_KEYS, LOOKAHEAD_MAX, MAP_KEYS, SCHEMA, validate
from .plan_goal import CANCELLED, circle_peak_speed, CONTROLLER_NOT_READY, INVALID_GOAL
from .plan_goal import Limits, PlanMonitor, refused, SUCCEEDED
from .planning import assess_failure, circle_bounds, compute_model, describe_join
from .planning import end_effector, grid_bound, grid_extent, join_from_arm, joint_state
from .planning import JOIN_REFUSED, JOIN_WAIT, make_circle, planner_status, READY, SETTLING
from .planning import prepare_transition, settle_gate_refusal, swing_deg
from .stream import Plan, SetpointStream

NODE_NAME = 'freejoint_planner'
ARM_DISCOVERY_S = 2.0
"""[s] Real time: how long after its start the planner waits for a joint_states publisher
before a plan from rest starts without the arm's position (discovery of a node started
together can take that long; in sim time the simulator's /clock and joint_states come
together, and a planner alone is driven by its /clock)."""

MARKER_POINTS = 361
FEEDBACK_PERIOD = 0.1
"""[s] Wall time between two follow_circle feedback messages."""


class PlannerNode(Node, Lifecycle):
    """Thin ROS wrapper around freejoint_core's singularity analysis and CircleQuintic."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        # Every parameter of params.SCHEMA, validated (a bad one raises: exit 2); with
        # thread_priority / cpu_affinity (ros2_control's names), as the sim and controller:
        # in real time the stream must not be starved by SCHED_FIFO neighbours.
        self._params = NodeParameters(self, SCHEMA)
        self._cfg = self._params.config
        self._pending = None
        # The arm (robot_description / description_file, passive_joints, gravity): its
        # nominal model is the map's; read-only but gravity, which the map does not hold.
        arm = resolve_arm(self._cfg)
        self._node_arm = arm
        self._spatial = arm.spatial     # a spatial arm (task_dim 3), None: planar
        self._arm = None if arm.urdf_arm is None else arm.params
        self._passive = None            # the passive set after reported failures (None: none)
        self._failure_refusal = ''      # why no plan is accepted since a failure ('' : none)
        self._failures_pending = []     # joints reported failed, not assessed yet
        self._joint_names = arm.joint_names
        self._offsets = arm.joint_offsets     # measured angles + these = the model's
        self._arm_source = arm.source
        # Where the arm is, for a plan from rest: joint_states taken only when needed (a
        # depth-1 subscription on a hidden node no executor spins: no callback per state).
        self._js_node = Node('_%s_arm' % self.get_name(), namespace=self.get_namespace(),
                             context=self.context, use_global_arguments=False,
                             enable_rosout=False, start_parameter_services=False)
        self._js_sub = self._js_node.create_subscription(
            JOINT_STATES.msg_type, self.resolve_topic_name(JOINT_STATES.name),
            lambda _msg: None, profile(1, reliable=False))
        self._arm_xy = None         # the end effector of the newest joint state taken
        self._arm_state = None      # the newest joint state taken (JointState)
        self._arm_note = ''         # why the newest joint state gave no position
        self._waits_logged = None   # plan id whose wait for the arm was logged
        self._born = time.monotonic()
        self._sim = self.get_parameter('use_sim_time').value
        own_clock(self)     # one /clock delivery: _on_clock sets the ROS clock
        if self._spatial is not None:
            self._model = None
            self._init_spatial()
        else:
            self._model = compute_model(*(self._cfg[k] for k in MAP_KEYS),
                                        arm=self._map_arm(self._cfg))
            reason = (grid_bound(self._model.region.reach, self._cfg['grid_resolution'])
                      or circle_bounds(make_circle(self._cfg), self._model,
                                       self._cfg['max_speed'], self._cfg['max_acceleration']))
            if not reason and self._cfg['settle_swing_deg'] > 0.0:
                reason = settle_gate_refusal(self._model.nominal)
            if reason:
                raise FreejointValueError(reason)
            self.get_logger().info(
                f'singularity map computed in {self._model.seconds * 1e3:.0f} ms: '
                f'{self._model.describe()}; {self._model.usable()}; arm: {self._arm_source}')
        # QoS overridable (qos_overrides./setpoints.publisher.<history|depth|reliability>).
        self._setpoint_pub = self.create_publisher(SETPOINTS.msg_type, SETPOINTS.name,
                                                   overridable(SETPOINTS.qos),
                                                   qos_overriding_options=QOS_OVERRIDES)
        self._map_pub = self.create_publisher(SEMI_SINGULAR_MAP.msg_type, SEMI_SINGULAR_MAP.name,
                                              SEMI_SINGULAR_MAP.qos)
        self._marker_pub = self.create_publisher(PLANNED_PATH.msg_type, PLANNED_PATH.name,
                                                 PLANNED_PATH.qos)
        self._stream = SetpointStream(self._cfg['control_period'], self._cfg['lookahead'],
                                      skip_late=not self._sim)
        self._last_plan_id = 0
        self._restarts_logged = 0
        self._spacing_logged = 0
        self._late_logged = 0
        # The plan as a goal (plan_goal): the controller's readiness pauses it (feed hold)
        # and refuses new ones; each outcome goes out latched on plan_outcome.
        self._readiness = None          # (ready, reason) last heard, None: nothing yet
        self._readiness_sub = self.create_subscription(
            CONTROLLER_READINESS.msg_type, CONTROLLER_READINESS.name, self._on_readiness,
            CONTROLLER_READINESS.qos)
        self._outcome_pub = self.create_publisher(PLAN_OUTCOME.msg_type, PLAN_OUTCOME.name,
                                                  PLAN_OUTCOME.qos)
        self._monitor = None            # PlanMonitor of the running plan
        self._goal = None               # (goal handle, Future of its Outcome, plan id)
        self._feedback_at = 0.0         # monotonic time of the last feedback
        self._publish_map()
        if self._cfg['autostart'] and self._spatial is not None:
            # from rest: the circle starts at the tip of the first joint state (_join)
            self._execute_spatial(self._cfg['radius'], self._cfg['duration'],
                                  self._cfg['start_delay'], 'configured')
        elif self._cfg['autostart']:
            circle = make_circle(self._cfg)
            reason, margin, choice, tick = self._admit(circle, self._model, self._cfg)
            if not reason:
                self._execute(circle, self._cfg['start_delay'], margin, 'configured', choice,
                              tick)
            else:
                self.get_logger().error(
                    f'configured circle refused, nothing streams: {self._describe(circle)}: '
                    f'{reason}')
        self.create_subscription(CLOCK.msg_type, CLOCK.name, self._on_clock,
                                 CLOCK_SUBSCRIPTION_QOS)
        self._timer = self._make_timer()
        # A joint reported failed (by a driver, an operator or the controller's detection):
        # plans from then on are for the arm with it free.
        self.create_subscription(JOINT_FAILURES.msg_type, JOINT_FAILURES.name,
                                 self._on_joint_failure, JOINT_FAILURES.qos)
        # Its state on /diagnostics once a second: ready, settling (the settle gate) or
        # cannot plan (a joint failure), with the running plan (planning.planner_status).
        self._diag_seen = None
        self._diagnostics = Diagnostics(self, 'planner', 'freejoint_planner',
                                        self._on_diagnostics_timer)
        self._params.listen(self._apply, self._check, watch=('use_sim_time',))
        self.create_service(PLAN_CIRCLE.srv_type, PLAN_CIRCLE.name, self._on_plan_circle)
        self._action = ActionServer(self, FOLLOW_CIRCLE.action_type, FOLLOW_CIRCLE.name,
                                    self._on_follow_circle,
                                    cancel_callback=self._on_cancel_goal)
        self.get_logger().info(
            f"ready: {'sim time (/clock)' if self._sim else 'system time'}, "
            f"dt {self._cfg['control_period']:g} s, lookahead {self._cfg['lookahead']} ticks")

    # ---- parameters -------------------------------------------------------------------
    def _check(self, params, new, _config):
        """Check a valid parameter change against the stream, the map and the plans."""
        sim = self._sim
        for p in params:
            if p.name == 'use_sim_time':
                sim = bool(p.value)
        n = self._stream.spacing
        if (sim and n > 1 and new['lookahead'] != self._cfg['lookahead']
                and int(new['lookahead']) < n - 1):
            return (f"lookahead: {new['lookahead']} ticks is below N - 1 = {n - 1} for /clock "
                    f'every N = {n} ticks (the clock spacing rule: the ticks between two '
                    f'/clock must be out when the first arrives); >= {2 * n - 1} rides out a '
                    'lost /clock')
        changed = {k for k in new if new[k] != self._cfg[k]}
        if self._spatial is not None:
            return self._check_change_spatial(sim, changed, new)
        model = self._model
        if changed & set(MAP_KEYS):
            model = compute_model(*(new[k] for k in MAP_KEYS), arm=self._map_arm(new))
            self.get_logger().info(f'singularity map recomputed in {model.seconds * 1e3:.0f} '
                                   f'ms: {model.describe()}')
            plan = self._stream.plan
            if plan is not None:
                check = model.check(plan.trajectory)
                if check.ok and plan.transition is not None:
                    check = check_path(model.region, plan.transition.sample_ticks(
                        self._stream.dt, plan.transition_ticks + 1)[:, :2])
                if not check.ok:
                    return (f'the running plan {plan.plan_id} would enter the '
                            f'semi-singular region of the new map: {check.reason}')
        reason = grid_bound(model.region.reach, new['grid_resolution'])
        if not reason and new['settle_swing_deg'] > 0.0:
            reason = settle_gate_refusal(model.nominal)
        if reason:
            return reason
        if changed and not changed & set(CIRCLE_KEYS):
            # the bounds or the map changed: the configured circle must still be valid (a
            # restart with these values would end at start-up otherwise)
            reason = circle_bounds(make_circle(new), model, new['max_speed'],
                                   new['max_acceleration'])
            if reason:
                return (f"{', '.join(sorted(changed))}: the configured circle would exceed "
                        f'the bounds: {reason}')
        circle = admitted = None
        if changed & set(CIRCLE_KEYS):
            circle = make_circle(new)
            reason, *admitted = self._admit(circle, model, new, transition=new['autostart'])
            if reason:
                return (f'circle refused, the running plan goes on: '
                        f'{self._describe(circle)}: {reason}')
        self._pending = (sim, changed, model, circle, admitted)
        return None

    def _apply(self, _old, new, _params):
        """Take an accepted parameter change: stream, timer, map, configured circle."""
        sim, changed, model, circle, admitted = self._pending
        self._pending = None
        self._cfg = new
        self._stream.lookahead = int(new['lookahead'])
        if 'lookahead' in changed:
            self.destroy_timer(self._timer)
            self._timer = self._make_timer()
        if self._spatial is not None:
            self._apply_spatial(changed, admitted)
        else:
            self._apply_planar(changed, new, model, circle, admitted)
        if sim != self._sim:
            self._switch_time_source(sim)

    def _apply_planar(self, changed, new, model, circle, admitted):
        """Take an accepted change of a planar arm's parameters: map, configured circle."""
        if model is not self._model or changed & {'grid_resolution', 'frame_id'}:
            self._model = model
            self._publish_map()
        if circle is not None and new['autostart']:
            margin, choice, tick = admitted
            self._execute(circle, new['start_delay'], margin, 'configured', choice, tick)
        elif 'frame_id' in changed and self._stream.plan is not None:
            self._publish_marker(self._stream.plan)

    def _map_arm(self, cfg):
        """Return the real arm of the map: the configured one, failed joints free."""
        if self._passive is None:
            return self._arm
        return replace(self._arm or table1(cfg['case']), passive=self._passive)

    def _on_joint_failure(self, msg):
        """
        joint_failures: plan for the arm with that joint free (``planning.after_failure``).

        Only noted here: the assessment and the new map take 0.05-0.25 s of CPU, which
        at the failure would stall the setpoint stream (the controller then holds) or, in
        a process or thread beside it, take the CPU and the GIL the graph needs just then
        (both measured in real time); they are done at the next plan request
        (:meth:`_take_failures`), as a map parameter change's.
        """
        self._failures_pending.append(msg.data)
        self.get_logger().warning(f'{msg.data} reported failed (joint_failures): the arm '
                                  'without it is assessed at the next plan request')

    def _take_failures(self):
        """Assess the failures reported since the last plan (executor): set, refusal, map."""
        if self._spatial is not None:
            self._take_failures_spatial()
            return
        cfg = self._cfg
        self._take_arm_state()
        got = self._arm_state
        state = None if got is None else joint_state(self._joint_names, got.name,
                                                     got.position, got.velocity,
                                                     self._offsets)
        pending, self._failures_pending = self._failures_pending, []
        for name in pending:
            out, model = assess_failure(self._map_arm(cfg) or table1(cfg['case']),
                                        self._joint_names, name, state, make_circle(cfg),
                                        cfg['nominal_scale'],
                                        tuple(cfg[k] for k in MAP_KEYS))
            self._failure_refusal = self._failure_refusal or out.refusal
            if out.arm is not None:
                self._passive = out.arm.passive
            if model is not None:
                self._model = model
                self._publish_map()
            self.get_logger().warning(out.note + (
                '; no plan is accepted from now on, the running one goes on'
                if out.refusal else ''))

    def _on_diagnostics_timer(self):
        """
        Every second: the planner's state (``planning.planner_status``) and its plan.

        In sim time, while ``/clock`` stands still (a lockstep simulator waiting, holding
        at ``max_steps`` or gone), a status goes out only when it differs from the last
        one: a recorder's received count then stays steady (drained), as with the
        controller's and the simulator's status, and a change is still reported.
        """
        settling = (self._settling() if self._cfg['settle_swing_deg'] > 0.0
                    and self._spatial is None else None)
        state, message = planner_status(self._failure_refusal, self._failures_pending,
                                        settling)
        plan = self._stream.plan
        monitor = self._monitor
        level = {READY: OK, SETTLING: WARN}.get(state, ERROR)
        if monitor is not None and monitor.outcome is None and monitor.paused:
            level = max(level, WARN)
            message += f'; plan {monitor.plan.plan_id} paused: {monitor.why}'
        values = (('state', state), ('plan', plan.plan_id if plan is not None else 'none'),
                  ('plan state', 'none' if monitor is None else
                   monitor.status(self._now_ns())['state']),
                  ('passive joints', [self._joint_names[i] for i in (
                      self._model.nominal.passive if self._spatial is None
                      else self._spatial.passive)]))
        if self._sim:
            seen = (self._now_ns(), level, message, repr(values))
            if seen == self._diag_seen:
                return
            self._diag_seen = seen
        self._diagnostics.publish(level, message, values)

    def _make_timer(self):
        """
        Return the real-time trigger: a wall timer every max(1, lookahead // 2) periods.

        Each firing publishes every tick up to now + lookahead, so at least half the
        lookahead stays published ahead; cancelled in sim time (/clock triggers instead).
        """
        period = self._cfg['control_period'] * max(1, int(self._cfg['lookahead']) // 2)
        timer = self.create_timer(period, self._on_timer,
                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        if self._sim:
            timer.cancel()
        return timer

    def _switch_time_source(self, sim):
        """Trigger on /clock (sim time) or the wall timer; restart on the new time base."""
        self._sim = sim
        self._stream.skip_late = not sim
        self._stream.reset_time_base()
        if sim:
            self._timer.cancel()
        else:
            self._timer.reset()
        self.get_logger().warning(
            f"use_sim_time {sim}: streaming on {'/clock' if sim else 'system time'}; the "
            'running plan starts again on the new time base')

    # ---- plans ------------------------------------------------------------------------
    @staticmethod
    def _series(series):
        if not isinstance(series, RepeatedCircle):
            return ''
        return f', {series.count} revolutions, {series.rest:g} s rest after each but the last'

    @staticmethod
    def _describe(circle):
        c = circle.centre
        return (f'circle centre ({c[0]:.6g}, {c[1]:.6g}) m radius {circle.radius:.6g} m '
                f'duration {circle.duration:.6g} s')

    def _admit(self, circle, model, cfg, transition=True):
        """
        Check a circle and how it would join the stream (no ROS in the checks).

        Returns ``(reason, margin, choice, tick)``: ``reason`` '' if accepted; the circle's
        margin (m); the ``TransitionChoice`` (None: starts directly) and its first tick.
        ``transition`` false: the circle alone (it is not to be started).
        """
        if self._failures_pending:
            before = self._model
            self._take_failures()
            if model is before:         # the map the caller had: the failed arm's now
                model = self._model
        if self._failure_refusal:
            return self._failure_refusal, math.nan, None, None
        reason = circle_bounds(circle, model, cfg['max_speed'], cfg['max_acceleration'])
        if reason:
            return f'{reason} ({model.usable()})', math.nan, None, None
        check = model.check(circle)
        if not check.ok:
            return f'{check.reason} ({model.usable()})', check.margin, None, None
        if not transition:
            return '', check.margin, None, None
        reason, choice, tick = prepare_transition(
            self._stream, circle, model, cfg['transition_max_duration'],
            bounds=(cfg['max_speed'], cfg['max_acceleration']),
            arm=self._arm_position() if self._stream.fresh() else None)
        return reason, check.margin, choice, tick

    def _execute(self, circle, start_delay, margin, source, choice=None, tick=None):
        """Replace the running plan by ``circle``; it starts at the next trigger."""
        self._last_plan_id += 1
        segment = None if choice is None else choice.segment
        from_rest = self._stream.fresh()
        cfg = self._cfg
        series = circle if cfg['circles'] == 1 and cfg['rest'] == 0.0 else RepeatedCircle(
            circle, cfg['circles'], cfg['rest'], cfg['control_period'])
        plan = Plan(self._last_plan_id, series, round(float(start_delay) * 1e9),
                    transition=segment, ticks=0 if segment is None else choice.ticks,
                    transition_tick=tick, joined=not (from_rest and choice is None))
        self._stream.start(plan)
        self._watch(plan, circle.radius, circle.duration)
        self._publish_marker(plan)
        if not plan.joined:
            how = 'from rest: where the arm is is decided when it starts'
        elif from_rest:
            how = 'from rest: ' + describe_join(self._arm_xy, choice)
        elif segment is None:
            how = 'starts at its start point'
        else:
            how = (f'transition of {choice.ticks} ticks from tick {tick} (peaks '
                   f'{choice.peak_speed:.4g} m/s, {choice.peak_acceleration:.4g} m/s^2, '
                   f'{choice.max_step * 1e3:.4g} mm per tick; path margin '
                   f'{choice.margin:.4f} m) into its start')
        self.get_logger().info(
            f'plan {plan.plan_id} ({source}) accepted with margin {margin:.4f} m: '
            f'{self._describe(circle)}{self._series(series)}, start delay '
            f'{float(start_delay):g} s, {how}')
        return plan.plan_id

    def _on_plan_circle(self, request, response):
        """
        Check a requested circle; if accepted and ``execute``, start it now.

        A request to execute one while the controller is not ready is refused with the
        reason; a refused request to execute goes out on plan_outcome (plan_id 0).
        """
        ready, why = self._ready()
        if request.execute and not ready:
            _refuse(response, f'controller not ready: {why}')
            self.get_logger().warning(f'plan_circle: refused: {response.reason}',
                                      throttle_duration_sec=1.0)
        elif self._spatial is not None:
            self._plan_circle_spatial(request, response)
        else:
            self._plan_circle_planar(request, response)
        if request.execute and not response.accepted:
            self._publish_outcome(refused(INVALID_GOAL if ready else CONTROLLER_NOT_READY,
                                          response.reason, self._now_ns()))
        return response

    def _plan_circle_planar(self, request, response):
        """``~/plan_circle`` of a planar arm (the controller ready, or a check only)."""
        try:
            problem = validate({'centre': list(request.centre), 'radius': request.radius,
                                'duration': request.duration,
                                'start_angle': request.start_angle,
                                'direction': int(request.direction)})
            if problem:
                raise FreejointValueError(problem)
            circle = CircleQuintic(centre=tuple(float(v) for v in request.centre),
                                   radius=request.radius, duration=request.duration,
                                   start_angle=request.start_angle,
                                   direction=int(request.direction))
        except FreejointValueError as exc:
            _refuse(response, f'bad request: {exc}')
            self.get_logger().error(f'plan_circle: {response.reason}',
                                    throttle_duration_sec=1.0)
            return response
        reason, margin, choice, tick = self._admit(circle, self._model, self._cfg,
                                                   transition=request.execute)
        if not reason and request.execute and self._cfg['settle_swing_deg'] > 0.0:
            reason = self._settling()
        response.accepted = not reason
        response.margin = float(margin)
        response.plan_id = 0
        if reason:
            response.reason = f'{self._describe(circle)} refused: {reason}'
            self.get_logger().warning(f'plan_circle: {response.reason}',
                                      throttle_duration_sec=1.0)
        elif request.execute:
            response.plan_id = self._execute(circle, 0.0, margin, 'plan_circle', choice, tick)
        else:
            self.get_logger().info(f'plan_circle: {self._describe(circle)} accepted with '
                                   f'margin {margin:.4f} m (not executed)')
        return response

    # ---- spatial arms ---------------------------------------------------------------
    # .spatial_planning is imported in these methods only: it imports Pinocchio, about a
    # tenth of a second of the start of a planar arm's planner, which never uses it.
    def _init_spatial(self):
        """Check a spatial arm's configured circle and say what does not apply to it."""
        from .spatial_planning import describe as describe_spatial, plane_normal
        from .spatial_planning import spatial_bounds
        cfg = self._cfg
        reason = spatial_bounds(cfg['radius'], cfg['duration'], cfg['max_speed'],
                                cfg['max_acceleration'])
        if reason:
            raise FreejointValueError(reason)
        self.get_logger().info(
            f'spatial arm (task_dim 3): {self._arm_source}; plans: '
            f"{describe_spatial(cfg['radius'], cfg['duration'])} in "
            + ('the vertical plane facing the robot' if plane_normal(cfg['plane_normal']) is None
               else 'the plane normal to %s' % list(cfg['plane_normal']))
            + ' (freejoint_core.spatial_offline.circle), checked along the nominal '
            'closed loop (kappa, reach, URDF limits) and for free joints that must carry '
            'gravity; the planar singularity map (semi_singular_map, resolution_deg, eps_d, '
            'singular_cells, grid_resolution) and the settle gate do not apply')
        if cfg['settle_swing_deg'] > 0.0:
            self.get_logger().warning(
                f"settle_swing_deg {cfg['settle_swing_deg']:g} ignored: the settle gate is "
                "for a planar arm's free last link")

    def _check_change_spatial(self, sim, changed, new):
        """Check a valid parameter change of a spatial arm's planner (``_check``)."""
        from .spatial_planning import describe as describe_spatial, spatial_bounds
        reason = spatial_bounds(new['radius'], new['duration'], new['max_speed'],
                                new['max_acceleration'])
        what = describe_spatial(new['radius'], new['duration'])
        if reason and changed & set(CIRCLE_KEYS):
            return f'circle refused, the running plan goes on: {what}: {reason}'
        if reason:
            return (f"{', '.join(sorted(changed))}: the configured circle would exceed the "
                    f'bounds: {reason}')
        admitted = None
        if changed & set(CIRCLE_KEYS) and new['autostart']:
            reason, verdict = self._admit_spatial(new['radius'], new['duration'], new)
            if reason:
                return f'circle refused, the running plan goes on: {what}: {reason}'
            admitted = (verdict,)
        self._pending = (sim, changed, None, None, admitted)
        return None

    def _apply_spatial(self, changed, admitted):
        """Take an accepted change of a spatial arm's parameters: the configured circle."""
        cfg = self._cfg
        if admitted is not None:
            self._execute_spatial(cfg['radius'], cfg['duration'], cfg['start_delay'],
                                  'configured', admitted[0])
        elif 'frame_id' in changed and self._stream.plan is not None:
            self._publish_marker(self._stream.plan)

    def _take_failures_spatial(self):
        """Take reported failures of a spatial arm: plans refused from then on (no assessment)."""
        pending, self._failures_pending = self._failures_pending, []
        names = list(self._joint_names)
        for name in pending:
            if name not in names:
                note = f'joint failure notice for {name!r} ignored: not a joint of {names}'
            elif names.index(name) in self._spatial.passive:
                note = f'{name} failed: it is free in the planned arm already'
            else:
                note = (f'{name} failed: a changed passive set of a spatial arm is not '
                        'assessed (planar arms only): no plan can be checked')
                self._failure_refusal = self._failure_refusal or note
                note += '; no plan is accepted from now on, the running one goes on'
            self.get_logger().warning(note)

    def _spatial_state(self):
        """Return the arm's ``(q, qd)`` (model order) from the newest joint state, or None."""
        self._take_arm_state()
        got = self._arm_state
        if got is None:
            return None
        return joint_state(self._joint_names, got.name, got.position, got.velocity)

    def _admit_spatial(self, radius, duration, cfg, now=False, later=True):
        """
        Check a spatial plan (``spatial_planning``); ``(reason, verdict)``.

        ``verdict`` None with no reason: a plan from rest, checked when it starts
        (:meth:`_join_spatial`, from the arm's posture then); ``now``: check it from the
        newest joint state at once even so (``~/plan_circle``), or, with no joint state yet,
        leave it to its start (``later``) or refuse it (a check without execution).
        """
        from .spatial_planning import spatial_bounds, start_point
        if self._failures_pending:
            self._take_failures()
        if self._failure_refusal:
            return self._failure_refusal, None
        reason = spatial_bounds(radius, duration, cfg['max_speed'], cfg['max_acceleration'])
        if reason:
            return reason, None
        p0, reason = start_point(self._stream)
        if reason:
            return reason, None
        if p0 is None and not now:
            return '', None
        state = self._spatial_state()
        if state is None and p0 is None and later:
            return '', None
        if state is None:
            return (f'no joint state with the positions and velocities of '
                    f"{list(self._joint_names)} yet: a spatial plan is checked from the arm's "
                    'posture'), None
        verdict = self._check_spatial_plan(radius, duration, cfg, state, p0)
        return verdict.reason, verdict

    def _check_spatial_plan(self, radius, duration, cfg, state, p0=None):
        """Return ``check_spatial_plan`` from ``state``; ``p0`` None: the tip of the real arm."""
        from .spatial_planning import check_spatial_plan
        q, qd = state
        if p0 is None:          # the tip as the offline runner takes it (the real arm's fk)
            p0 = self._spatial.fk(np.asarray(q, dtype=float))
        return check_spatial_plan(self._node_arm.nominal(cfg['nominal_scale']), q, qd, radius,
                                  duration, cfg['max_speed'], cfg['max_acceleration'], p0=p0,
                                  normal=cfg['plane_normal'], kd=nullspace_kd(cfg),
                                  kp=cfg['nullspace_kp'])

    def _execute_spatial(self, radius, duration, start_delay, source, verdict=None):
        """Replace the running plan by a spatial circle (``verdict`` None: from the tip)."""
        from .spatial_planning import describe as describe_spatial, SpatialRequest
        self._last_plan_id += 1
        traj = SpatialRequest(radius, duration, self._cfg['plane_normal']) if verdict is None \
            else verdict.circle
        plan = Plan(self._last_plan_id, traj, round(float(start_delay) * 1e9),
                    joined=verdict is not None)
        self._stream.start(plan)
        self._watch(plan, radius, duration)
        self._publish_marker(plan)
        if verdict is None:
            what = describe_spatial(radius, duration)
            how = "from rest: checked when it starts, from the arm's posture then"
        else:
            what = describe_spatial(radius, duration, verdict.circle.p0)
            how = verdict.describe()
        self.get_logger().info(f'plan {plan.plan_id} ({source}) accepted: {what}, start '
                               f'delay {float(start_delay):g} s; {how}')
        return plan.plan_id

    def _join_spatial(self, plan):
        """Check a spatial plan from rest from the arm's posture and start it; True: hold."""
        from .spatial_planning import describe as describe_spatial
        state = self._spatial_state()
        if state is None:
            if self._waits_logged != plan.plan_id:
                self._waits_logged = plan.plan_id
                self.get_logger().info(
                    f"plan {plan.plan_id}: waiting for the arm's posture: no joint state with "
                    f'the positions and velocities of {list(self._joint_names)} yet (the '
                    'circle starts at the tip)')
            return True
        traj = plan.trajectory
        verdict = self._check_spatial_plan(traj.radius, traj.duration, self._cfg, state)
        p0 = None if verdict.circle is None else verdict.circle.p0
        if verdict.reason:
            self._stream.plan = None
            self.get_logger().error(
                f'plan {plan.plan_id} refused at its start, nothing streams: '
                f'{describe_spatial(traj.radius, traj.duration, p0)}: {verdict.reason}')
            return True
        plan.trajectory = verdict.circle
        plan.joined = True
        self._publish_marker(plan)
        self.get_logger().info(
            f'plan {plan.plan_id} from rest: {describe_spatial(traj.radius, traj.duration, p0)} '
            f'(the tip of the newest joint state); {verdict.describe()}')
        return False

    def _plan_circle_spatial(self, request, response):
        """``~/plan_circle`` of a spatial arm: radius, duration, execute (module notes)."""
        from .spatial_planning import describe as describe_spatial
        centre = [float(v) for v in request.centre]
        problem = validate({'radius': request.radius, 'duration': request.duration})
        if not problem and (centre != [0.0, 0.0] or request.start_angle != 0.0
                            or int(request.direction) not in (0, 1)):
            problem = ('centre, start_angle, direction: do not apply to a spatial arm (its '
                       'circle starts at the tip, in the plane of plane_normal): '
                       f'send [0, 0], 0, 0 or 1; got {centre}, {request.start_angle:g}, '
                       f'{int(request.direction)}')
        what = describe_spatial(request.radius, request.duration)
        response.plan_id = 0
        if problem:
            _refuse(response, f'bad request: {problem}')
            self.get_logger().error(f'plan_circle: {response.reason}',
                                    throttle_duration_sec=1.0)
            return response
        reason, verdict = self._admit_spatial(request.radius, request.duration, self._cfg,
                                              now=True, later=request.execute)
        response.accepted = not reason
        response.margin = float(verdict.margin) if verdict is not None else math.nan
        if verdict is not None and verdict.circle is not None:
            what = describe_spatial(request.radius, request.duration, verdict.circle.p0)
        if reason:
            response.reason = f'{what} refused: {reason}'
            self.get_logger().warning(f'plan_circle: {response.reason}',
                                      throttle_duration_sec=1.0)
        elif request.execute:       # verdict None: from rest, no joint state yet
            response.plan_id = self._execute_spatial(request.radius, request.duration, 0.0,
                                                     'plan_circle', verdict)
        else:
            self.get_logger().info(f'plan_circle: {what} accepted (not executed): '
                                   f'{verdict.describe()}')
        return response

    # ---- the plan as a goal: readiness, feed hold, outcome (plan_goal) ----------------
    def _on_readiness(self, msg):
        """controller_readiness: the controller's judgement of its loop (latched)."""
        before = self._readiness
        self._readiness = (bool(msg.ready), str(msg.reason))
        if before != self._readiness:
            self.get_logger().info(
                'controller ready' if msg.ready else f'controller not ready: {msg.reason}')

    def _ready(self):
        """
        Return ``(ready, reason)``: may a plan move (``readiness`` parameter, module notes).

        Not ready: the controller said so, or (real time, or ``required``) it is not
        heard: no controller_readiness publisher, or none heard from yet.
        """
        mode = self._cfg['readiness']
        if mode == 'ignore':
            return True, ''
        trust_silence = self._sim and mode == 'auto'
        if self._readiness_sub.get_publisher_count() == 0:
            if trust_silence:
                return True, ''
            return False, ('no controller_readiness publisher (no controller running, or '
                           "one that does not say; readiness: 'ignore' for such a one)")
        if self._readiness is None:
            return (True, '') if trust_silence else (
                False, 'no controller_readiness heard yet')
        ready, why = self._readiness
        return ready, why or ('' if ready else 'the controller says not ready')

    def _limits(self, goal=None):
        """Return the plan's Limits: the parameters, or a follow_circle goal's own."""
        cfg = self._cfg

        def pick(value, default):
            # goal: 0 = the parameter, < 0 = not checked; parameter 0 = not checked
            value = default if goal is None or value == 0.0 else value
            return None if not value > 0.0 else float(value)
        g = goal
        return Limits(path=pick(g and g.path_tolerance, cfg['path_tolerance']),
                      goal=pick(g and g.goal_tolerance, cfg['goal_tolerance']),
                      goal_time=float(g.goal_time_tolerance if g is not None
                                      and g.goal_time_tolerance > 0.0
                                      else cfg['goal_time_tolerance']),
                      max_pause=float(g.max_pause if g is not None and g.max_pause > 0.0
                                      else cfg['max_pause']))

    def _watch(self, plan, radius, duration):
        """Watch a plan just started (PlanMonitor); the one it replaced is PREEMPTED."""
        old = self._monitor
        if old is not None and old.outcome is None:
            self._end(old.preempt(self._now_ns(), plan.plan_id))
        cfg = self._cfg
        self._monitor = PlanMonitor(self._stream, self._limits(), cfg['feed_hold_time'],
                                    cfg['feed_resume_time'],
                                    circle_peak_speed(radius, duration),
                                    cfg['max_acceleration'])

    def _supervise(self, now_ns):
        """Before the stream's advance: readiness -> feed hold; the outcome if decided."""
        monitor = self._monitor
        if monitor is None or monitor.outcome is not None:
            return
        if monitor.plan is not self._stream.plan:       # refused at its start (_join)
            self._end(monitor.finish(INVALID_GOAL, 'refused at its start (see the log)',
                                     now_ns))
            return
        ready, why = self._ready()
        paused = monitor.paused
        outcome = monitor.update(now_ns, ready, why)
        if monitor.paused != paused and outcome is None:
            if monitor.paused:
                self.get_logger().warning(
                    f'plan {monitor.plan.plan_id} paused (feed hold: it stops along its path '
                    f'within {monitor.stop_time:.3f} s and waits): controller not ready: {why}')
            else:
                self.get_logger().info(
                    f'plan {monitor.plan.plan_id} resumes (feed back to full within '
                    f'{monitor.start_time:.3f} s){monitor.resume_note}: controller ready')
        if outcome is not None:
            self._end(outcome)

    def _measure(self, due):
        """After the stream's advance: keep what went out, measure the arm against it."""
        monitor = self._monitor
        if monitor is None:
            return
        monitor.published(due)
        if monitor.outcome is not None:
            return
        got = self._take_arm_state()
        if got is not None:
            position = self._end_effector(got)
            if position is not None:
                monitor.measure(to_ns(got.header.stamp), position)
            if monitor.outcome is not None:
                self._end(monitor.outcome)
        if self._goal is not None and time.monotonic() - self._feedback_at >= FEEDBACK_PERIOD:
            self._feedback_at = time.monotonic()
            self._goal[0].publish_feedback(
                FOLLOW_CIRCLE.action_type.Feedback(**monitor.status(self._now_ns())))

    def _end_effector(self, state):
        """Return the end effector (m values) of a joint state, None if it has no arm."""
        if self._spatial is None:
            return end_effector(self._model, self._joint_names, state.name, state.position,
                                self._offsets)
        q = joint_state(self._joint_names, state.name, state.position,
                        [0.0] * len(state.position))
        return None if q is None else tuple(self._spatial.fk(np.asarray(q[0])))

    def _end(self, outcome):
        """Publish a plan's outcome, log it and end its goal (if it has one)."""
        self._publish_outcome(outcome)
        goal = self._goal
        if goal is not None and goal[2] == outcome.plan_id:
            self._goal = None
            monitor = self._monitor
            if monitor is not None and monitor.plan.plan_id == outcome.plan_id:
                # the last feedback says where the plan ended, whatever the feedback period
                goal[0].publish_feedback(
                    FOLLOW_CIRCLE.action_type.Feedback(**monitor.status(self._now_ns())))
            goal[1].set_result(outcome)

    def _publish_outcome(self, outcome):
        """Send an Outcome on plan_outcome (latched) and log it."""
        msg = outcome_msg(outcome)
        self._outcome_pub.publish(msg)
        if outcome.code == SUCCEEDED:       # one severity per call site (rclpy's logger)
            self.get_logger().info(f'outcome: {outcome.line()}')
        else:
            self.get_logger().warning(f'outcome: {outcome.line()}')
        return msg

    async def _on_follow_circle(self, goal_handle):
        """
        follow_circle: the circle as a goal (plan_circle's checks), ended by its outcome.

        Refused requests (not ready, a bad or refused circle) are accepted goals aborted at
        once with the code and the reason: an action's rejection carries no reason.
        """
        goal = goal_handle.request
        request = PLAN_CIRCLE.srv_type.Request(
            centre=list(goal.centre), radius=goal.radius, duration=goal.duration,
            start_angle=goal.start_angle, direction=goal.direction, execute=True)
        reason = ''
        for name in ('path_tolerance', 'goal_tolerance', 'goal_time_tolerance', 'max_pause'):
            if not math.isfinite(getattr(goal, name)):
                reason = f'bad request: {name}: expected a finite number, got ' \
                    f'{getattr(goal, name)!r}'
        answer = PLAN_CIRCLE.srv_type.Response()
        if reason:
            answer.reason = reason
            self._publish_outcome(refused(INVALID_GOAL, reason, self._now_ns()))
        else:
            self._on_plan_circle(request, answer)
        if not answer.accepted:
            goal_handle.abort()
            code = CONTROLLER_NOT_READY if answer.reason.startswith('controller not ready') \
                else INVALID_GOAL
            return self._result(refused(code, answer.reason, self._now_ns()))
        self._monitor.limits = self._limits(goal)
        future = Future()       # a goal running before was preempted (_watch): ended
        self._goal = (goal_handle, future, answer.plan_id)
        outcome = await future
        if outcome.code == SUCCEEDED:
            goal_handle.succeed()
        elif outcome.code == CANCELLED:
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return self._result(outcome)

    def _result(self, outcome):
        """Return the FollowCircle result of an Outcome."""
        return FOLLOW_CIRCLE.action_type.Result(outcome=outcome_msg(outcome))

    def _on_cancel_goal(self, goal_handle):
        """Cancel the running goal: its plan stops along the path, then ends CANCELLED."""
        goal = self._goal
        if goal is None or goal[0] is not goal_handle or self._monitor is None:
            return CancelResponse.REJECT
        self._monitor.cancel(self._now_ns())
        self.get_logger().info(f'plan {goal[2]}: cancel requested: stopping along the path')
        return CancelResponse.ACCEPT

    # ---- publishing -------------------------------------------------------------------
    def _now_ns(self):
        return self.get_clock().now().nanoseconds

    def _publish_map(self):
        if self._spatial is not None:
            return          # planar only (the map is over the plane of the joint axes)
        cell = float(self._cfg['grid_resolution'])
        extent = grid_extent(self._model.region.reach, cell)
        grid = self._model.region.to_grid(extent, cell)
        self._map_pub.publish(occupancy_grid(grid, extent, cell, self._cfg['frame_id'],
                                             self._now_ns()))

    def _publish_marker(self, plan):
        if self._spatial is not None:
            from .spatial_planning import SpatialRequest
            if isinstance(plan.trajectory, SpatialRequest):
                return      # its start point (the tip) is not known yet
        self._marker_pub.publish(path_marker(plan.trajectory.points(MARKER_POINTS),
                                             self._cfg['frame_id'], self._now_ns(),
                                             plan.plan_id))

    def _take_arm_state(self):
        """Take the newest joint state the depth-1 subscription holds (None: nothing new)."""
        got = None
        try:
            handle = self._js_sub.handle
            with handle:
                while True:
                    taken = handle.take_message(self._js_sub.msg_type, False)
                    if taken is None:
                        break
                    got = taken[0]
        except InvalidHandle:          # destroyed at shutdown
            return None
        if got is not None:
            self._arm_state = got
        return got

    def _arm_position(self):
        """
        Return the arm's end effector (x, y) from the newest joint state, None if unknown.

        Takes what the depth-1 subscription holds (the newest state; nothing new: the one
        taken before); a state without the arm's joints gives None and says why
        (``_arm_note``).
        """
        self._take_arm_state()
        got = self._arm_state       # the newest taken, here or by the settle gate
        if got is not None:
            self._arm_xy = end_effector(self._model, self._joint_names, got.name, got.position,
                                        self._offsets)
            self._arm_note = '' if self._arm_xy is not None else (
                f'joint_states has no finite positions of the joints {list(self._joint_names)} '
                f'(it names {list(got.name)})')
        return self._arm_xy

    def _settling(self):
        """Return why a plan must wait for the free link to settle ('' : it is settled)."""
        limit = self._cfg['settle_swing_deg']
        self._take_arm_state()
        got = self._arm_state
        swing = None if got is None else swing_deg(self._model, self._joint_names, got.name,
                                                   got.position, got.velocity, self._offsets)
        if swing is None:
            return ('settling: no joint state with the positions and velocities of '
                    f"{list(self._joint_names)} to judge the free link's swing by "
                    f'(settle_swing_deg {limit:g})')
        if swing > limit:
            return (f'settling: the free link swings {swing:.2f} deg (> settle_swing_deg '
                    f'{limit:g}); ask again once it has settled')
        return ''

    def _join(self, plan):
        """Decide how a plan from rest starts (``planning.join_from_arm``); True: hold."""
        if self._spatial is not None:
            return self._join_spatial(plan)
        position = self._arm_position()
        wait = None
        if position is None and not self._arm_note:
            count = self._js_sub.get_publisher_count()
            if count:
                wait = (f"waiting for the arm's position: joint_states has {count} "
                        f'publisher(s), no state with the joints {list(self._joint_names)} '
                        'yet')
            elif not self._sim and time.monotonic() - self._born < ARM_DISCOVERY_S:
                wait = (f"waiting up to {ARM_DISCOVERY_S:g} s from the planner's start for a "
                        "joint_states publisher (the arm's position)")
        action, text = join_from_arm(
            plan, self._stream, self._model, position, wait,
            self._cfg['transition_max_duration'],
            (self._cfg['max_speed'], self._cfg['max_acceleration']))
        if action == JOIN_WAIT:
            if self._waits_logged != plan.plan_id:
                self._waits_logged = plan.plan_id
                self.get_logger().info(f'plan {plan.plan_id}: {text}')
            return True
        if action == JOIN_REFUSED:
            self._stream.plan = None
            self.get_logger().error(f'plan {plan.plan_id} refused at its start, nothing '
                                    f'streams: {text}')
            return True
        if position is None:
            text += f': {self._arm_note}' if self._arm_note else ''
            self.get_logger().warning(f'plan {plan.plan_id} {text}')
        else:
            self.get_logger().info(f'plan {plan.plan_id} from rest: {text}')
        return False

    def _advance(self, now_ns):
        frame_id = self._cfg['frame_id']
        publish = self._setpoint_pub.publish
        stream = self._stream
        if stream.last_now_ns is not None and now_ns < stream.last_now_ns:
            # ROS time went back (a reset simulator): the arm's position taken before is
            # stale, and the running plan joins from rest again
            self._arm_xy = None
            self._arm_note = ''
            if self._spatial is not None:
                self._arm_state = None      # a spatial plan starts at the tip of a new state
            stream.advance(now_ns, hold=True)
        plan = stream.plan
        hold = (plan is not None and plan.start_tick is None and not plan.joined
                and self._join(plan))
        self._supervise(now_ns)
        due = stream.advance(now_ns, hold=hold)
        if due:
            publish(setpoints_msg(due, frame_id))
        self._measure(due)
        if stream.restarts != self._restarts_logged:
            if self._monitor is not None and self._monitor.outcome is None:
                self._monitor = self._monitor.fresh()   # the plan starts again
            self._restarts_logged = stream.restarts
            self._spacing_logged = 0
            self.get_logger().warning(
                f'ROS time went back to {now_ns * 1e-9:.6f} s: the stream starts over and the '
                'running plan starts again')

    def _check_spacing(self, now_ns):
        """Log the /clock spacing learnt (when it grows) and warn about late ticks."""
        stream = self._stream
        n = stream.spacing
        lookahead = stream.lookahead
        rule = (f'lookahead must be >= N - 1 = {n - 1} ticks for /clock every N = {n} '
                f'ticks, >= 2 N - 1 = {2 * n - 1} to ride out a lost /clock')
        if stream.late != self._late_logged:
            late = stream.late - self._late_logged
            self._late_logged = stream.late
            self.get_logger().warning(
                f'{late} setpoint(s) went out only at /clock {now_ns * 1e-9:.6f} s, after ROS '
                f'time had passed them (lockstep: the controller waited for them): {rule}; '
                f'lookahead is {lookahead}', throttle_duration_sec=1.0)
        if n > self._spacing_logged:
            self._spacing_logged = n
            if lookahead >= 2 * n - 1:
                self.get_logger().info(f'/clock every {n} ticks (or more): lookahead '
                                       f'{lookahead} covers it and one lost /clock')
            else:
                self.get_logger().warning(
                    f'/clock every {n} ticks (or more): {rule}; lookahead is {lookahead}'
                    + ('' if lookahead >= n - 1 else ': ticks will go out late'))

    def _on_clock(self, msg):
        if self._sim:
            now_ns = to_ns(msg.clock)
            set_ros_time(self, now_ns)
            self._advance(now_ns)
            stream = self._stream
            if stream.spacing > self._spacing_logged or stream.late != self._late_logged:
                self._check_spacing(now_ns)
                if stream.lookahead < stream.spacing - 1:
                    self._raise_lookahead(now_ns)

    def _raise_lookahead(self, now_ns):
        """
        Raise lookahead to 2 N - 1: the /clock spacing N learnt exceeds lookahead + 1.

        The safe choice (loud): the ticks the controller waits for go out now, and one
        lost /clock is ridden out; capped at the parameter's upper bound (the keep-last
        depth). The parameter is set, so ``ros2 param get`` tells the truth.
        """
        n = self._stream.spacing
        old = self._stream.lookahead
        value = min(2 * n - 1, LOOKAHEAD_MAX)
        self.get_logger().error(
            f'/clock every N = {n} ticks but lookahead is {old} < N - 1 = {n - 1} (clock '
            f'spacing rule: in lockstep the controller waits for ticks only the next /clock '
            f'would release): lookahead raised to {value}'
            + ('' if value >= n - 1 else f', the most allowed: still below {n - 1}'))
        result = self.set_parameters([Parameter('lookahead', value=value)])[0]
        if not result.successful:
            self.get_logger().error(f'lookahead could not be raised: {result.reason}')
            return
        self._advance(now_ns)

    def _on_timer(self):
        if not self._sim:
            self._advance(self._now_ns())

    def destroy_node(self):
        """Destroy the node and its hidden joint-state helper."""
        self._js_node.destroy_node()
        super().destroy_node()


def _refuse(response, reason):
    """Fill a PlanCircle response refusing the request for ``reason``; return it."""
    response.accepted = False
    response.reason = reason
    response.margin = math.nan
    response.plan_id = 0
    return response


def main(args=None):
    """Run the node until SIGINT/SIGTERM; exit 2 on a bad start-up parameter."""
    return run(PlannerNode, 'freejoint_planner', args)


if __name__ == '__main__':
    main()
