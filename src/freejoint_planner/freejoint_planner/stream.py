"""
Control-grid arithmetic and the setpoint stream of a plan (plain Python, no ROS).

The rules are those of ``docs/GRAPH.md`` (lockstep protocol, item 5):

* tick ``k`` has the stamp ``t_k = k * dt_ns`` integer nanoseconds of ROS time,
  ``dt_ns = round(dt * 1e9)``;
* whenever ROS time advances to ``now`` every not yet published tick with
  ``t_k <= now + lookahead * dt_ns`` is published, in order, each exactly once;
* tick ``k`` of a plan that starts at tick ``k0`` carries
  ``CircleQuintic.sample_tuple((k - k0) * dt)`` (the offline runner's ``t_k = k dt``),
  ``plan_time = (t_k - t_k0) * 1e-9`` and ``final = (k - k0) * dt > duration``; before the
  start the start point is held (``plan_time < 0``), after the duration the end point.

A plan starts at the first trigger after it was accepted, on the first tick at or after
``now + start_delay`` that has not been published yet (ticks already published belong to
the previous plan). With no plan at all nothing is published and the stream only follows
the clock. If ROS time goes backwards (a simulator reset, a looped bag) the stream starts
over on the new time base and the running plan starts again (without its transition).
A spatial plan (a trajectory with ``task_dim`` 3: ``spatial_planning.SpatialCircle``)
streams :class:`SpatialSetpoint` (3 values per vector) by the same rules, without
transitions.

Transitions (no step in the reference). A plan accepted once the stream has published a
tick on its time base may carry a transition (``freejoint_core.trajectory.
QuinticTransition``) anchored at the first unpublished tick ``kt`` (``next_tick`` when it
was accepted, ``state_at(kt)`` its start state): tick ``kt + j`` carries the transition at
``j dt`` until its ``n`` ticks are out, the circle then starts on tick ``k0 = max(kt + n,
ceil((now + start_delay) / dt))`` (its start point held in between). Transition ticks carry
the new plan's id, ``plan_time = (k - k0) dt < 0`` and ``final = False``.

A plan from rest (nothing streamed yet on its time base: the first plan, or the running one
after ROS time went back) has no stream state to start from: the node starts it where the
arm is (``planning.join_from_arm``), by a transition anchored at the plan's own first tick
(``transition_tick`` None until ``advance`` starts the plan); until that is decided
(``Plan.joined`` false) ``advance(now, hold=True)`` only follows the clock.

Clock spacing rule (sim time). ROS time only advances with ``/clock``, and the lockstep
simulator may publish it every ``N``-th step only (its ``clock_rate``). The ticks strictly
between two ``/clock`` messages, ``k + 1 .. k + N - 1``, must all be out when ``/clock =
t_k`` triggers the stream, or the controller waits for them (the next ``/clock`` never comes:
the simulator is waiting for their commands). So **lookahead >= N - 1** is required, and
**lookahead >= 2 N - 1** rides out one lost ``/clock`` message (the subscription is best
effort). The stream cannot know ``N`` in advance: it learns it (``spacing``, the largest
advance in ticks from one trigger to the next) and counts the ticks it published only after
ROS time had passed them (``late``), so the node can warn and name the rule.
"""

from typing import NamedTuple

from freejoint_common.setpoint import SetpointSample
from freejoint_core.feed_hold import FeedRate, scale_sample


def period_ns(dt):
    """
    Return the control period in integer nanoseconds, ``round(dt * 1e9)``.

    Parameters
    ----------
    dt : float
        Control period (s), > 0 and a whole number of nanoseconds.

    Returns
    -------
    int

    Raises
    ------
    ValueError
        If ``dt`` is not positive or not a whole number of nanoseconds (to 1e-3 ns).

    """
    dt = float(dt)
    if not dt > 0.0:
        raise ValueError(f'control_period: expected > 0 s, got {dt}')
    dt_ns = round(dt * 1e9)
    if dt_ns < 1 or abs(dt * 1e9 - dt_ns) > 1e-3:
        raise ValueError(f'control_period: {dt} s is not a whole number of nanoseconds')
    return dt_ns


def ceil_div(a, b):
    """Return ``ceil(a / b)`` for integers (``b > 0``), exact for any size."""
    return -((-a) // b)


def first_tick_at_or_after(t_ns, dt_ns):
    """Return the smallest tick ``k`` with ``k * dt_ns >= t_ns``."""
    return ceil_div(t_ns, dt_ns)


def last_tick_due(now_ns, dt_ns, lookahead):
    """Return the largest tick ``k`` with ``k * dt_ns <= now_ns + lookahead * dt_ns``."""
    return (now_ns + lookahead * dt_ns) // dt_ns


class Setpoint(NamedTuple):
    """One setpoint of the stream (planar, m = 2): what a ``CartesianSetpoints`` holds per tick."""

    stamp_ns: int
    px: float
    py: float
    vx: float
    vy: float
    ax: float
    ay: float
    plan_id: int
    plan_time: float
    final: bool


SpatialSetpoint = SetpointSample
"""One setpoint of a spatial plan (task_dim 3): 3 values per vector (the record a
``setpoints`` batch is read into, ``freejoint_common.setpoint``)."""


class Plan:
    """
    A trajectory with an id and a start delay; its start tick is fixed when it starts.

    Parameters
    ----------
    plan_id : int
        Id carried by its setpoints (> 0).
    trajectory : object
        Has ``sample_tuple(t)`` and ``duration`` (``freejoint_core.trajectory.CircleQuintic``).
    start_delay_ns : int
        Delay (ns, >= 0) from the trigger at which the plan starts to its first tick.

    transition : object, optional
        Has ``sample_tuple(t)``: the segment into the trajectory's start, ``ticks`` long,
        from tick ``transition_tick`` on.
    ticks : int
        Length of the transition in ticks (> 0 with a transition).
    transition_tick : int, optional
        Its first tick: the stream's first unpublished tick when the plan was accepted;
        None: the plan's own first tick (a plan from rest, anchored when it starts).
    joined : bool
        How the plan joins the stream is decided (a transition or none); false: the node
        decides it from the arm's position before the plan starts (a plan from rest).

    """

    def __init__(self, plan_id, trajectory, start_delay_ns=0, transition=None, ticks=0,
                 transition_tick=None, joined=True):
        self.plan_id = int(plan_id)
        self.trajectory = trajectory
        self.start_delay_ns = int(start_delay_ns)
        self.start_tick = None          # fixed by SetpointStream.advance
        self.joined = bool(joined)
        self.feed = None                # its FeedRate (feed hold), given by the stream
        self.start_held = False         # start with the feed standing (feed hold)
        self.transition = None
        self.transition_ticks = 0
        self.transition_tick = None
        if transition is not None:
            self.set_transition(transition, ticks, transition_tick)

    def set_transition(self, transition, ticks, transition_tick=None):
        """
        Give the plan its transition (None: none), ``ticks`` long, from ``transition_tick``.

        ``transition_tick`` None anchors it at the plan's first tick (when it starts).
        """
        if transition is not None and int(ticks) <= 0:
            raise ValueError(f'ticks: expected > 0 with a transition, got {ticks}')
        self.transition = transition
        self.transition_ticks = 0 if transition is None else int(ticks)
        self.transition_tick = None if transition_tick is None else int(transition_tick)

    def transition_end(self):
        """Return the first tick after the transition (None without one, or not anchored)."""
        if self.transition is None or self.transition_tick is None:
            return None
        return self.transition_tick + self.transition_ticks

    def __repr__(self):
        return (f'Plan(plan_id={self.plan_id}, trajectory={self.trajectory!r}, '
                f'start_delay_ns={self.start_delay_ns}, start_tick={self.start_tick}, '
                f'transition={self.transition!r}, transition_tick={self.transition_tick}, '
                f'ticks={self.transition_ticks}, joined={self.joined})')


class SetpointStream:
    """
    Which setpoints are due when ROS time advances, each tick exactly once, in order.

    Parameters
    ----------
    dt : float
        Control period (s), a whole number of nanoseconds.
    lookahead : int
        Ticks published ahead of ROS time (>= 0).
    skip_late : bool
        If true (real time on the wall clock) ticks already in the past when they fall
        due are skipped (counted in ``skipped``); if false (sim time) none is ever skipped.

    Attributes
    ----------
    spacing : int
        Largest advance of ROS time, in ticks, from one ``advance`` to the next since the
        time base started (sim time: the ``/clock`` spacing ``N`` of the module's rule).
    late : int
        Ticks published only after ROS time had passed them (sim time: ``lookahead`` was
        below ``N - 1``, or ``/clock`` messages were lost); never in real time (skipped).
    restarts, skipped : int
        Times ROS time went backwards; late ticks skipped (``skip_late`` only).

    """

    def __init__(self, dt, lookahead=20, skip_late=False):
        self.dt = float(dt)
        self.dt_ns = period_ns(dt)
        self.lookahead = int(lookahead)
        if self.lookahead < 0:
            raise ValueError(f'lookahead: expected >= 0 ticks, got {lookahead}')
        self.skip_late = bool(skip_late)
        self.plan = None
        self.next_tick = None           # first tick not yet published (None: not started)
        self.last_now_ns = None
        self.restarts = 0               # times ROS time went backwards
        self.skipped = 0                # late ticks skipped (skip_late only)
        self.late = 0                   # ticks published after ROS time passed them
        self.spacing = 0                # largest advance (ticks) between two triggers
        self.streamed = False           # a tick was published on this time base

    def start(self, plan):
        """Replace the running plan by ``plan``; it starts at the next ``advance``."""
        plan.start_tick = None
        plan.feed = FeedRate(self.dt)
        self.plan = plan

    def reset_time_base(self):
        """
        Forget the clock (a new time base): restart the stream and the running plan.

        The plan's transition is dropped and it is a plan from rest again (``joined``
        false: the node decides anew from where the arm is, e.g. a reset simulator's start).
        """
        self.next_tick = None
        self.last_now_ns = None
        self.spacing = 0
        self.streamed = False
        if self.plan is not None:
            self.plan.start_tick = None
            self.plan.feed = FeedRate(self.dt)
            self.plan.set_transition(None, 0)
            self.plan.joined = False

    def fresh(self):
        """Return True if nothing was published on this time base (a plan starts from rest)."""
        return not self.streamed

    def pending(self):
        """
        Return ``(k, state)`` of the first unpublished tick, or None if nothing streamed.

        ``state`` is ``(px, py, vx, vy, ax, ay)``: what the running plan publishes at tick
        ``k`` (a plan accepted but not started yet: as if it started at ``k``). None
        before the first tick on this time base was published (the first plan then
        starts as it always did, without a transition).
        """
        if not self.streamed or self.plan is None or self.next_tick is None:
            return None
        k = self.next_tick
        return k, self.state_at(k)

    def in_transition(self, k):
        """Return the running plan if tick ``k`` is one of its transition ticks, else None."""
        plan = self.plan
        if plan is None or plan.transition_end() is None:
            return None
        return plan if plan.transition_tick <= k < plan.transition_end() else None

    def state_at(self, k):
        """Return ``(px, py, vx, vy, ax, ay)`` of the running plan at tick ``k``."""
        plan = self.plan
        if plan.transition is not None and plan.transition_tick is None:
            return plan.transition.sample_tuple(0.0)        # anchored at its first tick
        if plan.start_tick is not None and not plan.feed.steady:
            return self._held(k)[1:7]
        if plan.transition is not None and k < plan.transition_end():
            return plan.transition.sample_tuple((k - plan.transition_tick) * self.dt)
        if plan.start_tick is None:
            return plan.trajectory.sample_tuple(0.0)
        return plan.trajectory.sample_tuple((k - plan.start_tick) * self.dt)

    def advance(self, now_ns, hold=False):
        """
        Return the setpoints due at ROS time ``now_ns`` (int ns), marking them published.

        Parameters
        ----------
        now_ns : int
            Current ROS time (ns).
        hold : bool
            Do not start a plan that has not started yet (it waits for its join from
            rest): the stream only follows the clock, as without a plan.

        Returns
        -------
        list of Setpoint
            In stamp order; empty when nothing is due or there is no plan.

        """
        now_ns = int(now_ns)
        dt_ns = self.dt_ns
        first = first_tick_at_or_after(now_ns, dt_ns)
        prev = self.last_now_ns
        if prev is not None and now_ns < prev:
            self.restarts += 1
            self.reset_time_base()
        elif prev is not None:
            gap = first - first_tick_at_or_after(prev, dt_ns)
            if gap > self.spacing:
                self.spacing = gap
        self.last_now_ns = now_ns
        plan = self.plan
        waiting = plan is None or (hold and plan.start_tick is None)
        if self.next_tick is None:
            self.next_tick = first
        elif self.next_tick < first and (self.skip_late or waiting):
            if not waiting:
                self.skipped += first - self.next_tick
            self.next_tick = first
        if waiting:
            return []
        if plan.start_tick is None:
            if plan.transition is not None and plan.transition_tick is None:
                plan.transition_tick = self.next_tick       # a plan from rest: from here
            plan.start_tick = max(self.next_tick if plan.transition is None
                                  else plan.transition_end(),
                                  first_tick_at_or_after(now_ns + plan.start_delay_ns, dt_ns))
            if plan.start_held:         # the controller not ready: the feed stands
                plan.feed.stand(self.next_tick)
        last = last_tick_due(now_ns, dt_ns, self.lookahead)
        start = self.next_tick
        out = [self.setpoint(k) for k in range(start, last + 1)]
        if last >= start:
            self.next_tick = last + 1
            self.streamed = True
            if start < first:           # sim time: ticks ROS time had already passed
                self.late += min(last + 1, first) - start
        return out

    def setpoint(self, k):
        """Return the setpoint of tick ``k`` of the running plan (which must have started)."""
        plan = self.plan
        if not plan.feed.steady:
            return self._held(k)
        traj = plan.trajectory
        k_plan = k - plan.start_tick
        if plan.transition is not None and k < plan.transition_end():
            px, py, vx, vy, ax, ay = plan.transition.sample_tuple(
                (k - plan.transition_tick) * self.dt)
            return Setpoint(k * self.dt_ns, px, py, vx, vy, ax, ay, plan.plan_id,
                            (k_plan * self.dt_ns) * 1e-9, False)
        t = k_plan * self.dt
        if getattr(traj, 'task_dim', 2) == 3:       # a spatial plan: 3 values per vector
            v = traj.sample_tuple(t)
            return SpatialSetpoint(k * self.dt_ns, v[:3], v[3:6], v[6:], plan.plan_id,
                                   (k_plan * self.dt_ns) * 1e-9, t > traj.duration)
        px, py, vx, vy, ax, ay = traj.sample_tuple(t)
        return Setpoint(k * self.dt_ns, px, py, vx, vy, ax, ay, plan.plan_id,
                        (k_plan * self.dt_ns) * 1e-9, t > traj.duration)

    def plan_time_at(self, k):
        """Return the running plan's time [s] at tick ``k`` (after its start; feed hold in)."""
        plan = self.plan
        lag = plan.feed.at(k)[0]
        return ((k - plan.start_tick) - lag) * self.dt

    def _held(self, k):
        """
        Return the setpoint of tick ``k`` of a plan whose feed ramped (feed hold).

        The plan is evaluated at the fractional tick ``k - lag`` (its transition, the held
        start, the trajectory, as :meth:`setpoint` at whole ticks), its velocity and
        acceleration scaled by the feed (``freejoint_core.feed_hold.scale_sample``).
        """
        plan = self.plan
        traj = plan.trajectory
        lag, rate, rate_dot = plan.feed.at(k)
        plan_time = ((k - plan.start_tick) - lag) * self.dt
        final = False
        if plan.transition is not None and (k - plan.transition_end()) - lag < 0:
            sample = plan.transition.sample_tuple(((k - plan.transition_tick) - lag)
                                                  * self.dt)
        else:
            sample = traj.sample_tuple(plan_time)
            final = plan_time > traj.duration
        v = scale_sample(sample, rate, rate_dot)
        m = len(v) // 3
        if m == 3:
            return SpatialSetpoint(k * self.dt_ns, v[:3], v[3:6], v[6:], plan.plan_id,
                                   plan_time, final)
        return Setpoint(k * self.dt_ns, *v, plan.plan_id, plan_time, final)
