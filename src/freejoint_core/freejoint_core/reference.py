"""
The controller's reference between the streamed setpoints and the law: hold and resume.

A real arm must not go limp when its setpoints stop, nor jump when they come back.
:class:`ReferenceShaper` gives, per tick, the reference ``(p, v, a)`` the law tracks:

- **hold**: before the first setpoint (real time) and whenever the setpoints go stale,
  the reference is the end-effector position measured at the onset of the hold, frozen,
  with zero velocity and acceleration (as ros2_controllers' joint_trajectory_controller
  holds the current position on activation and on cancel);
- **resume**: when setpoints come (back), the reference is the streamed setpoint plus an
  offset that starts at (last reference - setpoint) in position, velocity and
  acceleration and decays to zero over ``resume_time`` along a quintic (C2): the
  reference's position, velocity and acceleration stay continuous (:func:`quintic_offset`);
- **stream**: the setpoint itself;
- **return to a hold** (:meth:`ReferenceShaper.return_to`): a hold interrupted by a stop
  of the loop (the arm braked where it had drifted) blends back to its own position;
- **start from the measured motion** (:meth:`ReferenceShaper.start_from`): a controller
  taking over a moving arm blends from the end effector's measured position and velocity;
- **stop along the path** (:meth:`ReferenceShaper.stop`): a hold that starts while the
  reference moves, reached by the plan's own stop (the feed hold's ramp,
  ``freejoint_core.feed_hold``) along the last reference's osculating arc (:class:`ArcStop`):
  no step in the reference, and on the path of a circle.

Besides, :func:`extrapolate` carries a late setpoint forward to the state's time (the
controller's guards are ``freejoint_core.guards``).
Plain floats and tuples, no ROS types.  A reference (and a setpoint) is one flat tuple of
``3 m`` values, position, velocity, acceleration (m the task dimension; the planar arms'
``(px, py, vx, vy, ax, ay)``, which has its own unrolled path).

"""

import math

from freejoint_core.errors import FreejointValueError
from freejoint_core.feed_hold import (PEAK_RATE, scale_sample, smoothstep, smoothstep_integral,
                                      smoothstep_rate)

_isfinite = math.isfinite

MODE_NONE = 'none'
MODE_HOLD = 'hold'
MODE_BLEND = 'blend'
MODE_STREAM = 'stream'

STOP_MIN_SPEED = 1e-6
"""[m/s] A reference slower than this is held where it is (:meth:`ReferenceShaper.stop`)."""


def quintic_offset(d0, v0, a0, duration, t):
    """
    Quintic from ``(d0, v0, a0)`` at ``t = 0`` to ``(0, 0, 0)`` at ``t = duration``.

    The minimum-jerk polynomial with these six boundary conditions; held at zero for
    ``t >= duration``.

    Parameters
    ----------
    d0, v0, a0 : float
        Initial value [m], rate [m/s] and second derivative [m/s^2] of the offset.
    duration : float
        Blend time [s], > 0.
    t : float
        Time since the blend started [s], >= 0.

    Returns
    -------
    tuple of float
        ``(d, v, a)`` at ``t`` [m, m/s, m/s^2].

    """
    if t >= duration:
        return 0.0, 0.0, 0.0
    if t <= 0.0:
        return d0, v0, a0
    T = duration
    c3 = -(20.0 * d0 + 12.0 * v0 * T + 3.0 * a0 * T * T) / (2.0 * T ** 3)
    c4 = (30.0 * d0 + 16.0 * v0 * T + 3.0 * a0 * T * T) / (2.0 * T ** 4)
    c5 = -(12.0 * d0 + 6.0 * v0 * T + a0 * T * T) / (2.0 * T ** 5)
    c2 = 0.5 * a0
    d = d0 + t * (v0 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
    v = v0 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)))
    a = 2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5))
    return d, v, a


class ArcStop:
    """
    A stop along the osculating arc of a moving reference, on the feed hold's ramp.

    The reference ``(p0, v0, a0)`` at ``t0`` moves at the speed ``s0 = |v0|`` along the
    tangent ``v0 / s0``; the normal part of ``a0``, ``a_n = a0 - (a0 . t) t``, gives the
    curvature ``k = |a_n| / s0^2`` and the normal of its arc (k below 1e-9 1/m: a straight
    line). The stop runs that arc at full speed as a plan and scales its time with the
    feed rate ``r = 1 - S(u)``, ``u = (t - t0) / T`` (``freejoint_core.feed_hold``): the
    reference's position, velocity and acceleration stay continuous (but for ``a0``'s own
    tangential part, which the stop replaces), it stands after ``T`` at ``s0 T / 2`` along
    the arc, and its extra tangential deceleration peaks at ``1.875 s0 / T``. On a circle
    (the paper's plan) the arc is the path itself.

    Parameters
    ----------
    ref : sequence of float, (3 m,)
        The reference the stop starts from: position [m], velocity [m/s] (speed
        > 0), acceleration [m/s^2].
    t0 : float
        Its time [s].
    duration : float
        ``T`` [s], > 0.

    Attributes
    ----------
    t0, duration : float
    end : tuple of float, (m,)
        Where it stands [m].

    """

    def __init__(self, ref, t0, duration):
        m = len(ref) // 3
        vals = [float(x) for x in ref]
        if m < 1 or len(vals) != 3 * m or not all(map(_isfinite, vals)):
            raise FreejointValueError(f'ref: expected 3 m finite values, got {list(ref)!r}')
        if not (duration > 0.0 and _isfinite(duration)):
            raise FreejointValueError(f'duration: expected a finite value > 0, got {duration!r}')
        p0, v0, a0 = vals[0:m], vals[m:2 * m], vals[2 * m:3 * m]
        s0 = math.sqrt(sum(x * x for x in v0))
        if not s0 > 0.0:
            raise FreejointValueError(f'ref: the velocity {v0!r} has no direction to stop along')
        tangent = [x / s0 for x in v0]
        along = sum(a0[i] * tangent[i] for i in range(m))
        normal = [a0[i] - along * tangent[i] for i in range(m)]
        a_n = math.sqrt(sum(x * x for x in normal))
        k = a_n / (s0 * s0)
        if k > 1e-9:
            normal = [x / a_n for x in normal]
        else:
            k, normal = 0.0, [0.0] * m
        self.m, self.t0, self.duration = m, float(t0), float(duration)
        self._p0, self._t, self._n, self._k, self._s0 = p0, tangent, normal, k, s0
        self.end = self.sample(self.t0 + self.duration)[0:m]

    def _arc(self, s):
        """Return the arc's point [m], tangent and normal at the length ``s`` [m] along it."""
        p0, t, n, k, m = self._p0, self._t, self._n, self._k, self.m
        if k == 0.0:
            return [p0[i] + s * t[i] for i in range(m)], t, n
        c, sn = math.cos(k * s), math.sin(k * s)
        return ([p0[i] + (sn * t[i] + (1.0 - c) * n[i]) / k for i in range(m)],
                [c * t[i] + sn * n[i] for i in range(m)],
                [c * n[i] - sn * t[i] for i in range(m)])

    def sample(self, t):
        """
        Return the reference ``(p, v, a)`` [m, m/s, m/s^2] at ``t`` [s] (3 m values).

        Before ``t0`` the start, after ``t0 + duration`` the end at rest.
        """
        T, s0 = self.duration, self._s0
        u = min(max((t - self.t0) / T, 0.0), 1.0)
        p, tangent, normal = self._arc(s0 * T * (u - smoothstep_integral(u)))
        k = self._k
        plan = (p + [s0 * x for x in tangent] + [s0 * s0 * k * x for x in normal])
        return scale_sample(plan, 1.0 - smoothstep(u), -smoothstep_rate(u) / T)


class ReferenceShaper:
    """
    Hold / resume logic of the controller's reference (see the module notes).

    Parameters
    ----------
    resume_time : float
        Blend time [s] from the hold (or the last reference) to the streamed setpoint,
        >= 0 (0: switch at once).
    blend_on_start : bool
        True (real time): the first setpoint is blended in from the end-effector position
        measured then (a controller (re)started against an arm that is not at the stream's
        position).  False (lockstep): the first setpoint is tracked as it is.
    max_velocity, max_acceleration : float, optional
        Bounds [m/s, m/s^2] on the blend's own peak speed and acceleration for its
        position offset ``d``: the blend lasts ``max(resume_time, 1.875 d / max_velocity,
        sqrt(5.7735 d / max_acceleration))`` (the peaks of a rest-to-rest quintic), so an
        arm found far from the stream is brought back gently.  None: no bound.
    m : int, optional
        Task dimension (default 2): references are ``3 m`` values.

    Attributes
    ----------
    mode : str
        ``'none'`` (nothing yet), ``'hold'``, ``'blend'`` or ``'stream'``.
    blend_duration : float
        Duration [s] of the current (or last) blend.

    """

    def __init__(self, resume_time, blend_on_start=True, max_velocity=None,
                 max_acceleration=None, m=2):
        if not isinstance(m, int) or isinstance(m, bool) or m < 1:
            raise FreejointValueError(f'm: expected an int >= 1, got {m!r}')
        self.m = m
        self._zero3 = (0.0,) * (2 * m)
        self.set_resume_time(resume_time)
        self.set_bounds(max_velocity, max_acceleration)
        self.blend_on_start = bool(blend_on_start)
        self.blend_duration = self.resume_time
        self.reset()

    def set_bounds(self, max_velocity, max_acceleration):
        """
        Set the bounds of the blend's peak speed and acceleration (next blend).

        Parameters
        ----------
        max_velocity, max_acceleration : float or None
            [m/s, m/s^2], > 0; None: no bound.

        """
        for name, value in (('max_velocity', max_velocity),
                            ('max_acceleration', max_acceleration)):
            if value is not None and not (_isfinite(value) and value > 0.0):
                raise FreejointValueError(f'{name}: must be finite and > 0, got {value!r}')
        self.max_velocity = max_velocity
        self.max_acceleration = max_acceleration

    def set_resume_time(self, resume_time):
        """
        Set the blend time [s], >= 0 (effective at the next blend).

        Parameters
        ----------
        resume_time : float
            Blend time [s].

        """
        value = float(resume_time)
        if not (_isfinite(value) and value >= 0.0):
            raise FreejointValueError(f'resume_time: must be finite and >= 0, got {resume_time!r}')
        self.resume_time = value

    def reset(self):
        """Forget the hold and any blend: the next tick starts as at construction."""
        self.mode = MODE_NONE
        self.progress = 1.0
        self._hold = None
        self._last = None        # (p, v, a) of the last reference, (3 m,)
        self._t0 = 0.0
        self._off0 = None
        self._start = None       # (p, v, 0) given by start_from
        self._target = None      # (m,) the next hold's position, given by return_to
        self._hold_blend = None  # (t0, offset (3 m,), duration) of a hold returning to it
        self._stop = None        # the ArcStop a hold starts with

    def start_from(self, p, v):
        """
        Start (again) from the arm's measured motion: the next ``track`` blends from it.

        A controller that takes over an arm in motion (a standby activated after the
        active controller died) starts its reference where the end effector is and as it
        moves, ``(p, v, 0)``, instead of a hold at zero velocity: the first ``track``
        starts a blend whose offset is ``(p - sp, v - v_sp, -a_sp)`` (position and velocity
        of the reference continuous with the measured motion; the blend's duration by the
        usual rules of its position offset). Forgets any hold or blend; a ``hold`` before
        the next ``track`` holds (zero velocity) and forgets this start.

        Parameters
        ----------
        p : sequence of float, (m,)
            Measured end-effector position ``fk(q)`` [m].
        v : sequence of float, (m,)
            Measured end-effector velocity ``J(q) qd`` [m/s].

        """
        m = self.m
        vals = [float(x) for x in p] + [float(x) for x in v]
        if len(p) != m or len(vals) != 2 * m or not all(map(_isfinite, vals)):
            raise FreejointValueError(
                f'p, v: expected {m} finite values each, got {list(p)!r}, {list(v)!r}')
        self.reset()
        self._start = tuple(vals) + (0.0,) * m

    def return_to(self, target):
        """
        Forget the hold and any blend as :meth:`reset` does, but hold ``target`` next.

        A hold interrupted (the arm braked where it drifted to) resumes at its own position
        rather than where the arm now is: the next :meth:`hold` blends from the measured
        position to ``target`` (rest to rest, the blend's usual duration for that offset)
        and then holds it, so stops do not add up. A :meth:`track` first forgets it.

        Parameters
        ----------
        target : sequence of float, (m,)
            The hold position [m].

        """
        vals = [float(x) for x in target]
        if len(vals) != self.m or not all(map(_isfinite, vals)):
            raise FreejointValueError(f'target: expected {self.m} finite values, got '
                                      f'{list(target)!r}')
        self.reset()
        self._target = tuple(vals)

    def _duration(self, d):
        """Return a blend's duration [s] for a position offset of norm ``d`` [m]."""
        duration = self.resume_time
        if self.max_velocity is not None:
            duration = max(duration, 1.875 * d / self.max_velocity)
        if self.max_acceleration is not None:
            duration = max(duration, math.sqrt(5.7735 * d / self.max_acceleration))
        return duration

    @property
    def hold_position(self):
        """Return the frozen hold position (m,) [m], or None when not holding."""
        return self._hold if self.mode == MODE_HOLD else None

    def restart_blend(self):
        """Blend again from the last reference at the next ``track`` (the stream jumped)."""
        if self._last is not None and self.mode in (MODE_STREAM, MODE_BLEND):
            self.mode = MODE_HOLD

    def stiffness(self, scale):
        """
        Return the gain factor for the current mode (``RobustController.set_stiffness``).

        ``scale`` while holding, 1 on the stream (and before anything), and in a blend a
        smooth (C2, quintic smoothstep) return from ``scale`` to 1 over the blend, so the
        stiffer hold hands over to the law's own gains without a step.

        Parameters
        ----------
        scale : float
            The hold's factor (>= 1).

        Returns
        -------
        float

        """
        mode = self.mode
        if mode == MODE_HOLD:
            return scale
        if mode != MODE_BLEND or scale == 1.0:
            return 1.0
        p = self.progress
        return 1.0 + (scale - 1.0) * (1.0 - p * p * p * (10.0 - 15.0 * p + 6.0 * p * p))

    @property
    def stopping(self):
        """Return True while a hold started by :meth:`stop` still moves along its arc."""
        return self._stop is not None and self.mode == MODE_HOLD

    def stop(self, t0, t, max_acceleration):
        """
        Start a hold at the end of a stop along the path; return its reference at ``t``.

        While the reference moves (streaming or blending; its last value ``(p, v, a)``
        given at ``t0``) the hold is reached by stopping along that reference's
        osculating arc (:class:`ArcStop`) over ``T = 1.875 |v| / max_acceleration``
        (the feed hold's ramp, its extra tangential deceleration within
        ``max_acceleration``), as a plan's feed hold stops along its path, instead of a
        step to zero velocity where the arm is; :meth:`hold` then gives the stop and,
        after it, the hold at its end. Returns None (nothing started) when the reference
        does not move (no reference, a hold, slower than :data:`STOP_MIN_SPEED`): hold
        where the arm is.

        Parameters
        ----------
        t0 : float
            Time [s] of the last reference.
        t : float
            Time [s] of this tick, >= ``t0``.
        max_acceleration : float
            Bound [m/s^2] on the stop's extra tangential deceleration, > 0.

        Returns
        -------
        tuple of float, (3 m,) or None

        """
        if not (max_acceleration > 0.0 and _isfinite(max_acceleration)):
            raise FreejointValueError(f'max_acceleration: expected a finite value > 0, got '
                                      f'{max_acceleration!r}')
        last = self._last
        if last is None or self.mode not in (MODE_STREAM, MODE_BLEND):
            return None
        m = self.m
        speed = math.sqrt(sum(x * x for x in last[m:2 * m]))
        if not speed >= STOP_MIN_SPEED:
            return None
        stop = ArcStop(last, t0, PEAK_RATE * speed / max_acceleration)
        self.reset()
        self._stop = stop
        self._hold = tuple(stop.end)
        self.mode = MODE_HOLD
        return self.hold(None, t)

    def hold(self, p_now, t=None):
        """
        Return the hold reference; the hold starts (frozen at ``p_now``) if not holding.

        After :meth:`return_to` the hold is at its target instead, reached by a blend from
        ``p_now`` that starts at ``t``; after :meth:`stop`, at the stop's end, reached along
        its arc (``t`` needed: without it the stop is over).

        Parameters
        ----------
        p_now : tuple of float, (m,)
            Measured end-effector position [m] (used only at the onset of the hold).
        t : float, optional
            Time of the tick [s] (only differences are used); needed after
            :meth:`return_to` (without it the hold starts at ``p_now``).

        Returns
        -------
        tuple of float, (3 m,)
            ``(p, 0, 0)``: position [m], velocity [m/s], acceleration [m/s^2]; while
            returning to a target, its blend; while stopping, the stop.

        """
        m = self.m
        stop = self._stop
        if stop is not None and self.mode == MODE_HOLD:
            if t is not None and t - stop.t0 < stop.duration:
                ref = stop.sample(t)
                self._last = ref
                return ref
            self._stop = None
        if self.mode != MODE_HOLD:
            self.mode = MODE_HOLD
            self._start = None
            target, self._target = self._target, None
            here = tuple([float(x) for x in p_now[0:m]])
            if target is None or t is None:
                self._hold = here
            else:
                self._hold = target
                off = tuple([here[i] - target[i] for i in range(m)])
                self._hold_blend = (t, off + self._zero3, self._duration(math.hypot(*off)))
        blend = self._hold_blend
        if blend is not None:
            t0, off, duration = blend
            tau = t - t0 if t is not None else duration
            if tau < duration:
                ref = _offset_reference(self._hold + self._zero3, off, duration, tau)
                self._last = ref
                return ref
            self._hold_blend = None
        ref = self._hold + self._zero3
        self._last = ref
        return ref

    def track(self, t, sp, p_now):
        """
        Return the reference for the setpoint ``sp`` at time ``t`` and whether it blends.

        Parameters
        ----------
        t : float
            Time of the tick [s] (the state's stamp; only differences are used).
        sp : tuple of float, (3 m,)
            Setpoint: position, velocity, acceleration [m, m/s, m/s^2].
        p_now : tuple of float, (m,)
            Measured end-effector position [m]: the start of the blend when the
            controller starts (``blend_on_start``) with no reference yet (unused after
            :meth:`start_from`).

        Returns
        -------
        ref : tuple of float, (3 m,)
            The reference (position, velocity, acceleration).
        blending : bool
            True while the offset is still decaying.

        """
        mode = self.mode
        if mode == MODE_STREAM:
            self._last = sp
            return sp, False
        self._target = self._hold_blend = self._stop = None
        if mode == MODE_NONE:
            start, self._start = self._start, None
            if start is not None:
                self._last = start
            elif not self.blend_on_start:
                self.mode = MODE_STREAM
                self._last = sp
                return sp, False
            else:
                self._last = tuple([float(x) for x in p_now[0:self.m]]) + self._zero3
            mode = MODE_HOLD
        if mode == MODE_HOLD:
            if self.resume_time <= 0.0:
                self.mode = MODE_STREAM
                self._last = sp
                return sp, False
            last = self._last
            self._off0 = tuple(last[i] - sp[i] for i in range(3 * self.m))
            self._t0 = t
            self.mode = MODE_BLEND
            self.blend_duration = self._duration(math.hypot(*self._off0[0:self.m]))
        tau = t - self._t0
        duration = self.blend_duration
        if tau >= duration:
            self.mode = MODE_STREAM
            self._last = sp
            return sp, False
        self.progress = tau / duration
        o = self._off0
        m = self.m
        if m == 2:
            dx, vx, ax = quintic_offset(o[0], o[2], o[4], duration, tau)
            dy, vy, ay = quintic_offset(o[1], o[3], o[5], duration, tau)
            ref = (sp[0] + dx, sp[1] + dy, sp[2] + vx, sp[3] + vy, sp[4] + ax, sp[5] + ay)
        else:
            ref = _offset_reference(sp, o, duration, tau)
        self._last = ref
        return ref, True


def _offset_reference(base, off0, duration, t):
    """
    Return ``base`` plus the quintic offset (:func:`quintic_offset`) per task axis at ``t``.

    Parameters
    ----------
    base : tuple of float, (3 m,)
        Reference the offset decays to: position, velocity, acceleration.
    off0 : tuple of float, (3 m,)
        The offset's start, laid out as ``base``.
    duration, t : float
        The blend's duration and the time into it [s].

    Returns
    -------
    tuple of float, (3 m,)

    """
    m = len(base) // 3
    pos, vel, acc = [], [], []
    for i in range(m):
        d, v, a = quintic_offset(off0[i], off0[m + i], off0[2 * m + i], duration, t)
        pos.append(base[i] + d)
        vel.append(base[m + i] + v)
        acc.append(base[2 * m + i] + a)
    return tuple(pos + vel + acc)


def extrapolate(sp, h):
    """
    Shift a setpoint by ``h`` along its Taylor polynomial (acceleration held).

    Parameters
    ----------
    sp : tuple of float, (3 m,)
        Position, velocity, acceleration [m, m/s, m/s^2] at ``t`` (planar:
        ``(px, py, vx, vy, ax, ay)``).
    h : float
        Shift [s].

    Returns
    -------
    tuple of float, (3 m,)
        The setpoint at ``t + h``.

    """
    hh = 0.5 * h * h
    if len(sp) == 6:
        px, py, vx, vy, ax, ay = sp
        return (px + h * vx + hh * ax, py + h * vy + hh * ay, vx + h * ax, vy + h * ay,
                ax, ay)
    m = len(sp) // 3
    p, v, a = sp[0:m], sp[m:2 * m], sp[2 * m:3 * m]
    return (tuple([p[i] + h * v[i] + hh * a[i] for i in range(m)])
            + tuple([v[i] + h * a[i] for i in range(m)]) + tuple(a))
