"""
Feed hold: the time scaling that stops a plan along its path and resumes it.

A plan ``x(tau)`` (position, velocity, acceleration of the end effector at plan time
``tau``) is streamed on the control grid. With a feed rate ``r(t)`` in [0, 1] the plan's
time runs as ``d tau / dt = r``: at ``r = 1`` the plan as planned, at ``r = 0`` it stands
(as a CNC's feed hold). The streamed setpoint is the chain rule of ``x(tau(t))``::

    p = p(tau),   v = r v(tau),   a = r**2 a(tau) + r' v(tau)

so a change of ``r`` moves the setpoint only along the path: no step in position, and
with ``r`` C1 (the ramps below) none in velocity or acceleration either.

A ramp takes ``r`` from ``r0`` to ``r1`` over ``T`` seconds along the quintic smoothstep
``S(u) = 10 u^3 - 15 u^4 + 6 u^5`` (``S'`` and ``S''`` vanish at both ends)::

    r(t) = r0 + (r1 - r0) S(u),   u = (t - t0) / T
    r'   = (r1 - r0) S'(u) / T,   |r'| <= 1.875 |r1 - r0| / T

and the plan time gained over it is ``T (r0 + (r1 - r0) / 2)`` (``int_0^1 S = 1/2``).
A ramp from the current rate to the target lasts ``T_full |r1 - r0|``, so ``|r'|`` never
exceeds ``1.875 / T_full``: the extra tangential deceleration of a stop is at most
``1.875 |v| / T_stop``.

Lateness. The plan falls behind the clock by ``int (1 - r) dt``: a full stop from
``r = 1`` costs ``T_stop / 2``, the time at ``r = 0`` counts whole, a full resume costs
``T_start / 2``; a plan paused once for ``P`` seconds at rest ends ``T_stop / 2 + P +
T_start / 2`` late (:func:`lateness`).

Ticks. :class:`FeedRate` gives, per control tick ``k`` (time ``k dt``), the rate, its
derivative and the lag ``lambda_k`` [ticks]: the plan is evaluated at the fractional tick
``k - lambda_k``. A ramp starts on a tick (the stream's first unpublished one: ticks
already published are never changed). Until the first ramp the rate is 1 and the lag the
integer 0, so a plan never held gives exactly the setpoints of the plan itself.

Plain floats, no ROS.
"""

import math

from freejoint_core.errors import FreejointValueError

PEAK_RATE = 1.875
"""Peak of ``S'(u)`` (at ``u = 1/2``): ``|r'| <= PEAK_RATE |r1 - r0| / T``."""


def smoothstep(u):
    """Return ``S(u) = 10 u^3 - 15 u^4 + 6 u^5`` for ``u`` in [0, 1] (clipped outside)."""
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


def smoothstep_rate(u):
    """Return ``S'(u) = 30 u^2 (1 - u)^2`` (0 outside [0, 1])."""
    if u <= 0.0 or u >= 1.0:
        return 0.0
    w = u * (1.0 - u)
    return 30.0 * w * w


def smoothstep_integral(u):
    """Return ``int_0^u S = u^4 (2.5 - 3 u + u^2)`` for ``u`` in [0, 1] (1/2 at 1)."""
    u = min(max(u, 0.0), 1.0)
    return u ** 4 * (2.5 + u * (-3.0 + u))


def lateness(stop_time, paused, start_time):
    """
    Return how late [s] one full stop, a pause at rest and a full resume leave a plan.

    Parameters
    ----------
    stop_time, start_time : float
        Durations [s] of the ramps from rate 1 to 0 and back (each ``T_full``).
    paused : float
        Time at rate 0 between them [s].

    Returns
    -------
    float
        ``stop_time / 2 + paused + start_time / 2``.

    """
    return 0.5 * stop_time + paused + 0.5 * start_time


def ramp_time(full_time, speed, max_acceleration):
    """
    Return the duration [s] of a full ramp (rate 0 <-> 1) at a path speed ``speed``.

    The longer of ``full_time`` and the time that keeps the ramp's extra tangential
    acceleration ``speed |r'|`` within ``max_acceleration``: ``1.875 speed / a_max``.

    Parameters
    ----------
    full_time : float
        The configured ramp [s], > 0.
    speed : float
        The plan's speed at full feed where the ramp starts [m/s], >= 0.
    max_acceleration : float
        Bound on the ramp's tangential acceleration [m/s^2], > 0.

    Returns
    -------
    float

    """
    return max(float(full_time), PEAK_RATE * float(speed) / float(max_acceleration))


def scale_sample(sample, rate, rate_dot):
    """
    Return a plan's sample time-scaled by the feed: ``(p, r v, r^2 a + r' v)``.

    Parameters
    ----------
    sample : tuple of float, (3 m,)
        Position, velocity, acceleration of the plan at its time ``tau`` [m, m/s, m/s^2].
    rate : float
        Feed rate ``r`` (0 .. 1).
    rate_dot : float
        ``dr/dt`` [1/s].

    Returns
    -------
    tuple of float, (3 m,)

    """
    m = len(sample) // 3
    p = sample[0:m]
    v = sample[m:2 * m]
    a = sample[2 * m:3 * m]
    r2 = rate * rate
    return (tuple(p) + tuple([rate * x for x in v])
            + tuple([r2 * a[i] + rate_dot * v[i] for i in range(m)]))


class FeedRate:
    """
    The feed rate of one plan per control tick, and how far its time lags behind.

    Parameters
    ----------
    dt : float
        Control period [s], > 0.

    Attributes
    ----------
    steady : bool
        No ramp ever started: rate 1, lag 0 (the plan as planned, bit for bit).

    """

    def __init__(self, dt):
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise FreejointValueError(f'dt: expected a finite period > 0 s, got {dt!r}')
        self.dt = dt
        self._k0 = None         # first tick of the current ramp (None: steady)
        self._lag0 = 0.0        # lag at _k0 [ticks]
        self._r0 = 1.0
        self._r1 = 1.0
        self._T = 0.0           # ramp duration [s]

    @property
    def steady(self):
        """Return True while no ramp was ever started (rate 1, lag 0)."""
        return self._k0 is None

    @property
    def target(self):
        """Return the rate the current (or last) ramp goes to (1 when steady)."""
        return self._r1

    @property
    def start(self):
        """Return the first tick of the current (or last) ramp (None: steady)."""
        return self._k0

    def ramp_end(self):
        """Return the first tick at or after the end of the current ramp (None: steady)."""
        if self._k0 is None:
            return None
        return self._k0 + int(math.ceil(self._T / self.dt - 1e-9))

    def at(self, k):
        """
        Return ``(lag, rate, rate_dot)`` at tick ``k``.

        Parameters
        ----------
        k : int
            Control tick (at or after the current ramp's first tick).

        Returns
        -------
        tuple
            ``lag`` [ticks] (the int 0 while steady), ``rate``, ``rate_dot`` [1/s].

        """
        if self._k0 is None:
            return 0, 1.0, 0.0
        r0, r1, T, dt = self._r0, self._r1, self._T, self.dt
        n = k - self._k0
        h = n * dt
        if h >= T:
            gained = T * (r0 + 0.5 * (r1 - r0)) + r1 * (h - T)
            return self._lag0 + n - gained / dt, r1, 0.0
        u = h / T
        gained = T * (r0 * u + (r1 - r0) * smoothstep_integral(u))
        return (self._lag0 + n - gained / dt, r0 + (r1 - r0) * smoothstep(u),
                (r1 - r0) * smoothstep_rate(u) / T)

    def stand(self, k):
        """Stand still from tick ``k`` on (rate 0; a plan held at its start, at rest)."""
        self._lag0 = 0.0
        self._k0 = int(k)
        self._r0 = self._r1 = 0.0
        self._T = self.dt

    def rewind(self, k, ticks):
        """
        While the plan stands, move its time back by ``ticks`` from tick ``k`` on.

        A plan paused for an arm that stopped at once (braked) stands further along its
        path than the arm, by what its stop ramp travelled; moved back to where the arm
        stopped, it resumes from there instead of the arm catching up. The position steps
        back along the path while the rate is 0 (nothing tracks it then); the rate and its
        derivative stay 0.

        Parameters
        ----------
        k : int
            First tick of the new time (not earlier than the current ramp's first tick).
        ticks : float
            Plan ticks to go back, >= 0.

        Raises
        ------
        FreejointValueError
            ``ticks`` negative or not finite, ``k`` before the running ramp, or the plan
            not standing at ``k`` (a ramp running or a rate above 0).

        """
        ticks = float(ticks)
        if not (math.isfinite(ticks) and ticks >= 0.0):
            raise FreejointValueError(f'ticks: expected a finite count >= 0, got {ticks!r}')
        if self._k0 is not None and k < self._k0:
            raise FreejointValueError(f'k: tick {k} is before the running ramp (tick '
                                      f'{self._k0})')
        lag, rate, _rate_dot = self.at(k)
        if rate != 0.0 or self._k0 is None or k < self.ramp_end():
            raise FreejointValueError(f'k: the plan does not stand at tick {k} (rate '
                                      f'{rate:g})')
        self._lag0 = float(lag) + ticks
        self._k0 = int(k)
        self._r0 = self._r1 = 0.0
        self._T = self.dt

    def ramp(self, k, target, full_time):
        """
        From tick ``k`` on, take the rate from its value at ``k`` to ``target``.

        The ramp lasts ``full_time |target - r(k)|`` (see the module notes); a rate
        already at ``target`` with no ramp running is left alone.

        Parameters
        ----------
        k : int
            First tick of the ramp (not earlier than the current ramp's first tick).
        target : float
            0 (stop) or 1 (full feed), or any rate in between.
        full_time : float
            Duration [s] of a full ramp (0 <-> 1), > 0.

        Returns
        -------
        bool
            True if a ramp was started.

        """
        target = float(target)
        full_time = float(full_time)
        if not 0.0 <= target <= 1.0:
            raise FreejointValueError(f'target: expected a rate in [0, 1], got {target!r}')
        if not (math.isfinite(full_time) and full_time > 0.0):
            raise FreejointValueError(f'full_time: expected a finite time > 0 s, got '
                                      f'{full_time!r}')
        if self._k0 is not None and k < self._k0:
            raise FreejointValueError(f'k: tick {k} is before the running ramp (tick '
                                      f'{self._k0})')
        lag, rate, _rate_dot = self.at(k)
        if rate == target and (self._k0 is None or k >= self.ramp_end()):
            return False
        self._lag0 = float(lag)
        self._k0 = int(k)
        self._r0 = rate
        self._r1 = target
        self._T = full_time * abs(target - rate)
        if self._T <= 0.0:          # the rate is there, a ramp was still running: end it
            self._T = self.dt
        return True
