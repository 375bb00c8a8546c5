"""
A plan as a goal with an outcome: feed hold on a not-ready controller, tolerances, codes.

Plain Python, no ROS: the node feeds :class:`PlanMonitor` the controller's readiness, the
setpoints it published and the end effector it measured, once per trigger of its stream;
the monitor starts the feed's ramps (``freejoint_core.feed_hold``) on the stream's first
unpublished tick and decides the outcome (docs/feed_hold.md):

* **pause** (feed hold) as soon as the controller is not ready: the plan's time ramps to
  a stop along the path and waits; **resume** (the ramp back to full feed) when it is
  ready again. A plan the controller was never ready for (a configured plan started
  before the controller) waits at its start without limit.
* **PAUSED_TOO_LONG** once a pause lasts longer than ``max_pause``: the plan stays stopped
  where its feed stopped (a new plan joins from there).
* **PATH_TOLERANCE_VIOLATED** when the end effector is farther than ``path_tolerance``
  from the setpoint the plan streamed for the state's stamp, on ticks at full feed and at
  least ``settle`` after a resume ramp ended (the controller's blend from the arm to the
  held setpoint runs meanwhile): the plan stops along the path. While a plan that moved is
  paused, when the end effector is farther than ``path_tolerance`` from the plan's path
  behind where it stands (:data:`REWIND_WINDOW` of plan time: the arm a stopped or held
  controller left there, or one that fell): the plan stays stopped.
* **SUCCEEDED** at the plan's end (its setpoint at the current time at the plan's
  duration: the end point), or, with
  a ``goal_tolerance``, once the end effector is within it of the end point;
  **GOAL_TOLERANCE_VIOLATED** if not within ``goal_time_tolerance`` after the end.
* **CANCELLED** once a cancelled plan's feed stood still; **PREEMPTED** when a newer plan
  replaces it.

The codes are freejoint_msgs/PlanOutcome's (as control_msgs/FollowJointTrajectory's
``error_code``: 0 success, negative failures).
"""

from collections import deque
from dataclasses import dataclass
import math
from typing import NamedTuple, Optional

from freejoint_common.outcome import outcome_line
from freejoint_core.feed_hold import PEAK_RATE, ramp_time

SUCCEEDED = 0
INVALID_GOAL = -1
CONTROLLER_NOT_READY = -2
PAUSED_TOO_LONG = -3
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5
CANCELLED = -6
PREEMPTED = -7
CODE_NAMES = {SUCCEEDED: 'SUCCEEDED', INVALID_GOAL: 'INVALID_GOAL',
              CONTROLLER_NOT_READY: 'CONTROLLER_NOT_READY', PAUSED_TOO_LONG: 'PAUSED_TOO_LONG',
              PATH_TOLERANCE_VIOLATED: 'PATH_TOLERANCE_VIOLATED',
              GOAL_TOLERANCE_VIOLATED: 'GOAL_TOLERANCE_VIOLATED', CANCELLED: 'CANCELLED',
              PREEMPTED: 'PREEMPTED'}
"""Code -> name (freejoint_msgs/PlanOutcome's constants)."""


def circle_peak_speed(radius, duration):
    """
    Return the peak speed [m/s] of one quintic-timed revolution: ``2 pi r 1.875 / T``.

    The angle runs along ``s(t / T)``, ``s`` the quintic smoothstep, whose slope peaks at
    1.875 (``freejoint_core.feed_hold.PEAK_RATE``); planar and spatial circles alike.
    """
    return 2.0 * math.pi * float(radius) * PEAK_RATE / float(duration)


REWIND_WINDOW = 1.0
"""[s] Plan time searched back from where a paused plan stands for the point of its path
nearest the arm (its stop ramp travels half ``feed_hold_time``, the guard's trip comes
within a readiness window of the stop)."""

PATH_STEP = 0.005
"""[s] Plan time between the points of a paused plan's path the arm is measured against (a
point between two is taken as within half their distance of one: the path's curvature over
5 ms neglected, e.g. 6e-6 of the chord on the paper's circle)."""


def ticks_back_to(trajectory, tau, position, dt):
    """
    Return how many ticks back from plan time ``tau`` the path comes nearest ``position``.

    Parameters
    ----------
    trajectory : object with ``sample_tuple(t)``
        The plan (position first in each sample).
    tau : float
        Plan time [s] where the search starts, > 0.
    position : sequence of float, (m,)
        The end effector [m].
    dt : float
        The tick [s].

    Returns
    -------
    int
        Ticks back (0: where it stands), over :data:`REWIND_WINDOW` s of plan time, not
        before 0; the first of equally near points.

    """
    m = len(position)
    best, back = math.inf, 0
    for i in range(int(min(tau, REWIND_WINDOW) / dt) + 1):
        d = math.dist(position, trajectory.sample_tuple(tau - i * dt)[:m])
        if d < best:
            best, back = d, i
    return back


HISTORY_BATCHES = 400
"""Published batches kept to find the setpoint of a measured state's stamp (at 10 ticks a
batch, 4 s of ticks: a joint state taken late is still matched)."""


class Limits(NamedTuple):
    """
    A plan's tolerances (FollowJointTrajectory's, for the end effector) and its pause.

    Attributes
    ----------
    path : float or None
        Largest |end effector - setpoint| [m] at full feed (None: not checked).
    goal : float or None
        Largest |end effector - end point| [m] for success (None: success at the end).
    goal_time : float
        Time after the end to come within ``goal`` [s], >= 0.
    max_pause : float
        Longest pause [s] before PAUSED_TOO_LONG, > 0.

    """

    path: Optional[float]
    goal: Optional[float]
    goal_time: float
    max_pause: float


@dataclass
class Outcome:
    """How a plan ended (freejoint_msgs/PlanOutcome's fields; times in s, ns for stamps)."""

    plan_id: int
    code: int
    message: str
    stamp_ns: int = 0
    planned_duration: float = math.nan
    elapsed: float = math.nan
    lateness: float = math.nan
    time_paused: float = 0.0
    pauses: int = 0
    max_path_error: float = math.nan

    @property
    def code_name(self):
        """Return the code's name (``SUCCEEDED``, ``PAUSED_TOO_LONG``, ...)."""
        return CODE_NAMES.get(self.code, str(self.code))

    def line(self):
        """Return the outcome as one line of text (the log, ``fj``, the analysis)."""
        return outcome_line(self)


def refused(code, message, stamp_ns=0):
    """Return the :class:`Outcome` of a request refused before any plan started."""
    return Outcome(0, code, message, stamp_ns)


def position_of(setpoint):
    """Return a setpoint's position (tuple of m floats): planar or spatial records."""
    position = getattr(setpoint, 'position', None)
    return tuple(position) if position is not None else (setpoint.px, setpoint.py)


class PlanMonitor:
    """
    Watch one running plan of a ``SetpointStream``: feed hold, tolerances, outcome.

    Parameters
    ----------
    stream : SetpointStream
        The planner's stream; its running plan is the one watched.
    limits : Limits
        Tolerances and the longest pause.
    stop_time, start_time : float
        Full-ramp durations [s] of a stop and a resume (the planner's ``feed_hold_time``
        and ``feed_resume_time``), each lengthened to keep the ramp's tangential
        acceleration at the plan's peak speed within ``max_acceleration``
        (``feed_hold.ramp_time``).
    peak_speed, max_acceleration : float
        The plan's peak speed [m/s] and the bound [m/s^2].

    Attributes
    ----------
    outcome : Outcome or None
        Set once decided.
    paused : bool
        The feed holds (stopping or stopped) for a not-ready controller.

    """

    def __init__(self, stream, limits, stop_time, start_time, peak_speed, max_acceleration):
        self.stream = stream
        self.plan = stream.plan
        self.limits = limits
        self.stop_time = ramp_time(stop_time, peak_speed, max_acceleration)
        self.start_time = ramp_time(start_time, peak_speed, max_acceleration)
        self.outcome = None
        self.paused = False
        self.why = ''               # the pause's reason (the controller's)
        self.moved = False          # the controller was ready once since the plan started
        self.pause_since = None     # ns
        self.time_paused = 0.0
        self.pauses = 0
        self.check_from = None      # first tick the path tolerance applies (None: not now)
        self.stopping = None        # (code, message) once stopping (cancel)
        self.ended_ns = None        # ROS time the plan's end was first seen
        self.max_error = math.nan
        self.error = math.nan       # newest measured |ee - setpoint| [m]
        self.error_at = -1          # its state's stamp [ns]
        self.position = None        # newest measured end effector (m values)
        self.position_at = -1       # its state's stamp [ns]
        self.rewound = None         # (plan time [s], distance [m]) moved back this pause
        self.resume_note = ''       # what the last resume started from (the log)
        self._history = deque(maxlen=HISTORY_BATCHES)

    # -- inputs ---------------------------------------------------------------------------
    def published(self, batch):
        """Keep what the stream published: one batch of setpoints (stamps increasing)."""
        if batch:
            self._history.append(batch)

    def setpoint_at(self, stamp_ns):
        """Return the published setpoint of this plan for ``stamp_ns`` (the newest <= it)."""
        half = self.stream.dt_ns // 2
        for batch in reversed(self._history):
            if batch[0].stamp_ns <= stamp_ns + half:
                for sp in reversed(batch):
                    if sp.stamp_ns <= stamp_ns + half:
                        return sp if sp.plan_id == self.plan.plan_id else None
        return None

    def measure(self, stamp_ns, position):
        """
        Take a measured end effector ``position`` (m values) at ``stamp_ns``.

        Returns
        -------
        float
            ``|position - setpoint at stamp_ns|`` [m] (NaN: no setpoint of this plan then).

        """
        if stamp_ns > self.position_at:
            self.position, self.position_at = tuple(position), stamp_ns
        sp = self.setpoint_at(stamp_ns)
        if sp is None:
            return math.nan
        error = math.dist(position, position_of(sp))
        self.error = error
        self.error_at = stamp_ns
        k = stamp_ns // self.stream.dt_ns
        if self.check_from is not None and k >= self.check_from and not self.paused \
                and self.stopping is None and self.outcome is None and not sp.final:
            if not error <= self.max_error:     # NaN at first
                self.max_error = error
            path = self.limits.path
            if path is not None and error > path:
                self._stop(PATH_TOLERANCE_VIOLATED,
                           f"the end effector was {error * 1e3:.2f} mm from the plan's "
                           f'setpoint at t = {stamp_ns * 1e-9:.3f} s (path_tolerance '
                           f'{path * 1e3:.2f} mm): stopped along the path', stamp_ns)
        elif (self.paused and self.moved and self.stopping is None and self.outcome is None
                and self.limits.path is not None):
            off = self._off_path(position, self.limits.path)
            if off is not None:
                if not off <= self.max_error:
                    self.max_error = off
                self._stop(PATH_TOLERANCE_VIOLATED,
                           f'paused ({self.why}), the end effector was {off * 1e3:.2f} mm '
                           f"from the plan's path (path_tolerance "
                           f'{self.limits.path * 1e3:.2f} mm) at t = {stamp_ns * 1e-9:.3f} s: '
                           'it stays stopped', stamp_ns)
        return error

    def cancel(self, now_ns):
        """Stop the plan along its path (feed hold); CANCELLED once its feed stood still."""
        if self.outcome is None and self.stopping is None:
            self.stopping = (CANCELLED, 'cancelled by its client: stopped along the path')
            self._ramp(0.0, self.stop_time)

    def preempt(self, now_ns, by):
        """Return the outcome PREEMPTED: the plan ``by`` replaced this one."""
        return self.finish(PREEMPTED, f'replaced by plan {by}', now_ns)

    def finish(self, code, message, now_ns):
        """Decide the outcome now (if not decided yet); return it."""
        if self.outcome is None:
            self._finish(code, message, now_ns)
        return self.outcome

    def fresh(self):
        """Return a new monitor of the stream's plan with these limits (a new time base)."""
        monitor = PlanMonitor(self.stream, self.limits, self.stop_time, self.start_time, 0.0,
                              1.0)
        return monitor

    # -- per trigger ----------------------------------------------------------------------
    def update(self, now_ns, ready, reason=''):
        """
        Take the controller's readiness at ROS time ``now_ns``; return the outcome if decided.

        Call before the stream's ``advance`` of this trigger: a ramp starts on its first
        unpublished tick; a plan not started yet starts with its feed standing if the
        controller is not ready (``Plan.start_held``).
        """
        if self.outcome is not None:
            return self.outcome
        plan = self.plan
        if self.stream.plan is not plan:
            return None
        if plan.start_tick is None:
            plan.start_held = not ready
            return None
        if self.check_from is None and not self.paused and not self.moved:
            self.check_from = self._first_tick()
        if self.stopping is not None:
            if self._stood_still(now_ns):
                self._finish(*self.stopping, now_ns)
            return self.outcome
        if not ready:
            if not self.paused:
                self.paused = True
                self.pause_since = now_ns
                self.pauses += 1 if self.moved else 0
                self.check_from = None
                self._ramp(0.0, self.stop_time)
            self.why = reason or 'the controller is not ready'
            if self.moved and self.rewound is None and self._stood_still(now_ns):
                self._rewind_to_arm()
            if self.moved and now_ns - self.pause_since > self.limits.max_pause * 1e9:
                self.time_paused += (now_ns - self.pause_since) * 1e-9
                self.pause_since = None
                self._finish(PAUSED_TOO_LONG,
                             f'paused {self.limits.max_pause:g} s (max_pause) for a controller '
                             f'not ready: {self.why}; stopped along the path', now_ns)
            return self.outcome
        if self.paused:
            self.paused = False
            self.resume_note = '' if not self.rewound else (
                ' from the point of its path nearest the arm (%.1f mm, %.3f s of the plan '
                'back)' % (1e3 * self.rewound[1], self.rewound[0]))
            self.rewound = None
            if self.moved:
                self.time_paused += (now_ns - self.pause_since) * 1e-9
            self.pause_since = None
            self.why = ''
            self._ramp(1.0, self.start_time)
            end = self.plan.feed.ramp_end()
            self.check_from = end + int(math.ceil(self.start_time / self.stream.dt))
        self.moved = True
        return self._check_end(now_ns)

    # -- feedback ------------------------------------------------------------------------
    def status(self, now_ns):
        """
        Return the feedback at ``now_ns``: a dict of FollowCircle's feedback fields.

        ``state`` is the pause's reason while paused, else what the plan does.
        """
        sp = self.setpoint_at(now_ns)
        plan = self.plan
        duration = plan.trajectory.duration
        plan_time = sp.plan_time if sp is not None else math.nan
        elapsed = (now_ns - self._first_tick() * self.stream.dt_ns) * 1e-9 \
            if plan.start_tick is not None else 0.0
        feed = plan.feed
        k = now_ns // self.stream.dt_ns
        rate = 1.0 if feed is None or feed.steady else feed.at(max(k, feed.start))[1]
        if self.outcome is not None:
            state = 'ended: ' + self.outcome.code_name
        elif self.stopping is not None:
            state = 'stopping: ' + self.stopping[1]
        elif self.paused:
            state = ('waiting for the controller: ' if not self.moved else 'paused: ') + self.why
        elif plan.start_tick is None:
            state = 'starting'
        elif feed.target == 1.0 and not feed.steady and self.check_from is not None \
                and now_ns // self.stream.dt_ns < self.check_from:
            state = 'resuming'
        elif plan_time < 0.0:
            state = 'transition' if plan.transition is not None else 'start delay'
        else:
            state = 'moving'
        return {'plan_id': plan.plan_id,
                'progress': min(max(plan_time / duration, 0.0), 1.0)
                if math.isfinite(plan_time) else 0.0,
                'plan_time': plan_time, 'elapsed': elapsed,
                'lateness': self.lateness(now_ns), 'feed_rate': rate,
                'paused': self.paused, 'state': state, 'path_error': self.error}

    def lateness(self, now_ns):
        """Return how far the plan's time lags ROS time at ``now_ns`` [s] (feed hold)."""
        sp = self.setpoint_at(now_ns)
        plan = self.plan
        if sp is None or plan.start_tick is None:
            return 0.0
        return (sp.stamp_ns - plan.start_tick * self.stream.dt_ns) * 1e-9 - sp.plan_time

    # -- internals -----------------------------------------------------------------------
    def _first_tick(self):
        plan = self.plan
        if plan.transition is not None and plan.transition_tick is not None:
            return min(plan.transition_tick, plan.start_tick)
        return plan.start_tick

    def _ramp(self, target, full_time):
        # from the first unpublished tick: what went out stays as it was
        self.plan.feed.ramp(self.stream.next_tick, target, full_time)

    def _rewind_to_arm(self):
        """
        Move a plan that stands back along its path to the point nearest the arm.

        The arm stops at once when the controller stops (the driver brakes it, or holds
        it), or along the path on a ramp no longer than the plan's and started earlier
        (the controller's hold after a timing trip: ``readiness_stop_acceleration``), while
        the plan's feed decelerates along the path for half ``feed_hold_time``: it stands
        ahead of the arm, or level with it. Once the feed stands and a state measured since says
        where the arm is, the plan's time goes back (``FeedRate.rewind``, from the first
        unpublished tick) to the point of its path nearest it (:func:`ticks_back_to`, over
        :data:`REWIND_WINDOW` s of plan time, not before the plan's start): it resumes
        from where the arm stopped, the arm not catching up. Once per pause.
        """
        stream, plan = self.stream, self.plan
        k = stream.next_tick
        end = plan.feed.ramp_end()
        if (self.position is None or k is None or end is None or k < end
                or self.position_at < end * stream.dt_ns):
            return
        tau = stream.plan_time_at(k)
        if not tau > 0.0:
            return
        traj = plan.trajectory
        m = len(self.position)
        back = ticks_back_to(traj, tau, self.position, stream.dt)
        moved = math.dist(traj.sample_tuple(tau)[:m], traj.sample_tuple(tau - back
                                                                        * stream.dt)[:m])
        if back:
            plan.feed.rewind(k, back)
        self.rewound = (back * stream.dt, moved)

    def _off_path(self, position, tolerance):
        """
        Return how far ``position`` is from a paused plan's path, if beyond ``tolerance``.

        The path: from where the plan stands back :data:`REWIND_WINDOW` s of plan time (not
        before its start), every :data:`PATH_STEP`; None within ``tolerance`` (or a plan
        that stands in its transition or before its start). Only when the point where it
        stands is farther than ``tolerance`` are the others measured.
        """
        stream, plan = self.stream, self.plan
        k = stream.next_tick
        if k is None:
            return None
        tau = stream.plan_time_at(k)
        if not tau > 0.0:
            return None
        sample = plan.trajectory.sample_tuple
        m = len(position)
        here = sample(tau)[:m]
        best = math.dist(position, here)
        if best <= tolerance:
            return None
        slack = 0.0
        lo = max(0.0, tau - REWIND_WINDOW)
        for i in range(1, int((tau - lo) / PATH_STEP) + 2):
            point = sample(max(lo, tau - i * PATH_STEP))[:m]
            slack = max(slack, 0.5 * math.dist(point, here))
            best = min(best, math.dist(position, point))
            here = point
            if best - slack <= tolerance:
                return None
        return best

    def _stood_still(self, now_ns):
        end = self.plan.feed.ramp_end()
        return end is not None and now_ns // self.stream.dt_ns >= end

    def _stop(self, code, message, now_ns):
        """Stop the plan along the path and decide the outcome now."""
        self._ramp(0.0, self.stop_time)
        self._finish(code, message, now_ns)

    def _check_end(self, now_ns):
        sp = self.setpoint_at(now_ns)
        if sp is None or sp.plan_time < self.plan.trajectory.duration:
            return None
        if self.ended_ns is None:
            self.ended_ns = now_ns
        goal = self.limits.goal
        if goal is None:
            self._finish(SUCCEEDED, '', now_ns)
            return self.outcome
        if self.error_at >= self.ended_ns and self.error <= goal:   # a state since the end
            self._finish(SUCCEEDED, '', now_ns)
        elif now_ns - self.ended_ns > self.limits.goal_time * 1e9:
            self._stop(GOAL_TOLERANCE_VIOLATED,
                       f'the end effector was {self.error * 1e3:.2f} mm from the end point '
                       f"{self.limits.goal_time:g} s after the plan's end (goal_tolerance "
                       f'{goal * 1e3:.2f} mm)', now_ns)
        return self.outcome

    def _finish(self, code, message, now_ns):
        plan = self.plan
        # a plan replaced before its (delayed) first tick never started: elapsed 0
        started = (plan.start_tick is not None
                   and self._first_tick() * self.stream.dt_ns <= now_ns)
        if self.pause_since is not None and self.moved:
            self.time_paused += (now_ns - self.pause_since) * 1e-9
            self.pause_since = None
        self.outcome = Outcome(
            plan.plan_id, code, message, now_ns, float(plan.trajectory.duration),
            (now_ns - self._first_tick() * self.stream.dt_ns) * 1e-9 if started else 0.0,
            self.lateness(now_ns), self.time_paused, self.pauses, self.max_error)
