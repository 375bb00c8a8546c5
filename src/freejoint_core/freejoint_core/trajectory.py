"""
Circle trajectory with a quintic time scaling of the angle (paper, Sec. 4).

The end effector goes once around a circle; the polar angle about the centre
follows the quintic ``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` of the
normalised time ``tau = t / T``, so position, velocity and acceleration are
continuous and the velocity and acceleration are zero at both ends.
"""

from dataclasses import dataclass
import functools
import math

import numpy as np

from .errors import FreejointValueError

TWO_PI = 2.0 * math.pi


def _finite_float(name, value):
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a real number, got {value!r}') from None
    if not math.isfinite(out):
        raise FreejointValueError(f'{name}: expected a finite number, got {out}')
    return out


def workspace_annulus(lengths):
    """
    Return the reach annulus ``(r_min, r_max)`` (m) of a planar serial arm.

    With every joint free to turn a full revolution (paper, Sec. 4: no joint
    limits) the end effector reaches exactly the points whose distance from
    the base lies in ``[max(0, 2 max(L) - sum(L)), sum(L)]``.

    Parameters
    ----------
    lengths : sequence of float, shape (n,)
        Link lengths (m), each > 0.

    Returns
    -------
    tuple of float
        ``(r_min, r_max)`` in m.

    """
    try:
        arr = np.asarray(lengths, dtype=float)
    except (TypeError, ValueError):
        raise FreejointValueError(f'lengths: expected numbers, got {lengths!r}') from None
    if arr.ndim != 1 or arr.size == 0:
        raise FreejointValueError(f'lengths: expected shape (n,), got {arr.shape}')
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise FreejointValueError(f'lengths: expected finite values > 0, got {arr.tolist()}')
    total = float(arr.sum())
    return max(0.0, 2.0 * float(arr.max()) - total), total


class CircleQuintic:
    """
    One revolution around a circle, quintic in time, held at the ends.

    ``phi(t) = start_angle + direction * 2 pi * s(tau)``, ``tau = t / T``
    clipped to ``[0, 1]``, ``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` and
    ``p(t) = centre + radius (cos phi, sin phi)``. Before ``t = 0`` and after
    ``t = T`` the point is held (zero velocity and acceleration).

    Parameters
    ----------
    centre : sequence of float, shape (2,)
        Circle centre (m), default the base ``(0, 0)``.
    radius : float
        Circle radius (m), > 0. Paper: 0.2.
    duration : float
        Time ``T`` for the revolution (s), > 0. Paper: 5.0.
    start_angle : float
        Polar angle of the start (and end) point about the centre (rad).
        0 starts at ``centre + (radius, 0)``, the paper's ``(0.2, 0)``.
    direction : int
        +1 counter-clockwise, -1 clockwise.

    Raises
    ------
    FreejointValueError
        If an argument is malformed; the message names it.

    """

    def __init__(self, centre=(0.0, 0.0), radius=0.2, duration=5.0, start_angle=0.0,
                 direction=+1):
        try:
            c = np.asarray(centre, dtype=float)
        except (TypeError, ValueError):
            raise FreejointValueError(f'centre: expected 2 numbers, got {centre!r}') from None
        if c.shape != (2,):
            raise FreejointValueError(f'centre: expected shape (2,), got {c.shape}')
        if not np.all(np.isfinite(c)):
            raise FreejointValueError(f'centre: expected finite values, got {c.tolist()}')
        self._cx = float(c[0])
        self._cy = float(c[1])
        self._radius = _finite_float('radius', radius)
        if self._radius <= 0.0:
            raise FreejointValueError(f'radius: expected > 0 m, got {self._radius}')
        self._duration = _finite_float('duration', duration)
        if self._duration <= 0.0:
            raise FreejointValueError(f'duration: expected > 0 s, got {self._duration}')
        self._start = _finite_float('start_angle', start_angle)
        if isinstance(direction, bool) or direction not in (1, -1):
            raise FreejointValueError(f'direction: expected +1 or -1, got {direction!r}')
        self._dir = int(direction)
        # Pre-computed factors of the hot path.
        self._k0 = self._dir * TWO_PI
        self._k1 = self._k0 / self._duration
        self._k2 = self._k1 / self._duration

    @property
    def centre(self):
        """Return the centre of the circle in m, numpy shape (2,)."""
        return np.array([self._cx, self._cy])

    @property
    def radius(self):
        """Return the radius of the circle in m."""
        return self._radius

    @property
    def duration(self):
        """Return the duration of the revolution (s)."""
        return self._duration

    @property
    def start_angle(self):
        """Return the polar angle of the start point about the centre (rad)."""
        return self._start

    @property
    def direction(self):
        """Return +1 (counter-clockwise) or -1 (clockwise)."""
        return self._dir

    def sample_tuple(self, t):
        """
        Sample at time ``t`` as plain floats, for hot loops.

        Parameters
        ----------
        t : float
            Time (s). Not validated (hot path); use :meth:`sample` at the edges.

        Returns
        -------
        tuple of float
            ``(px, py, vx, vy, ax, ay)`` in m, m/s, m/s^2.

        """
        tau = t / self._duration
        if tau <= 0.0:
            tau = 0.0
        elif tau >= 1.0:
            tau = 1.0
        tau2 = tau * tau
        # s, s' and s'' of the quintic in Horner form.
        s = tau2 * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
        ds = tau2 * (30.0 + tau * (-60.0 + 30.0 * tau))
        dds = tau * (60.0 + tau * (-180.0 + 120.0 * tau))
        phi = self._start + self._k0 * s
        w = self._k1 * ds          # angular velocity (rad/s)
        wd = self._k2 * dds        # angular acceleration (rad/s^2)
        r = self._radius
        rc = r * math.cos(phi)
        rs = r * math.sin(phi)
        w2 = w * w
        return (self._cx + rc, self._cy + rs,
                -rs * w, rc * w,
                -rs * wd - rc * w2, rc * wd - rs * w2)

    def sample(self, t):
        """
        Sample position, velocity and acceleration at time ``t``.

        Parameters
        ----------
        t : float
            Time (s), finite. Outside ``[0, duration]`` the end point is held.

        Returns
        -------
        p, pd, pdd : numpy.ndarray, each shape (2,)
            Position (m), velocity (m/s) and acceleration (m/s^2).

        Raises
        ------
        FreejointValueError
            If ``t`` is not a finite number.

        """
        px, py, vx, vy, ax, ay = self.sample_tuple(_finite_float('t', t))
        return np.array([px, py]), np.array([vx, vy]), np.array([ax, ay])

    def points(self, num=721):
        """
        Return ``num`` points evenly spaced in angle along the path, shape (num, 2), m.

        Both ends are included (the first and last point coincide).
        """
        if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 2:
            raise FreejointValueError(f'num: expected an integer >= 2, got {num!r}')
        phi = self._start + self._dir * np.linspace(0.0, TWO_PI, int(num))
        return np.column_stack((self._cx + self._radius * np.cos(phi),
                                self._cy + self._radius * np.sin(phi)))

    def __repr__(self):
        return (f'CircleQuintic(centre=({self._cx!r}, {self._cy!r}), radius={self._radius!r}, '
                f'duration={self._duration!r}, start_angle={self._start!r}, '
                f'direction={self._dir!r})')


class RepeatedCircle:
    """
    ``count`` revolutions of a circle back to back, each but the last followed by a rest.

    Tick ``j`` (time ``j dt``) of the series falls in revolution ``c = j // (n + m)``
    (``n = duration / dt`` ticks of the circle, ``m = rest / dt`` of rest) at its tick
    ``i = j - c (n + m)``: the circle's ``sample_tuple(i dt)`` while ``i < n``, then its
    start point at rest (zero velocity and acceleration); after the last revolution the
    start point is held. Exactly the setpoints of the offline circles runner
    (``freejoint_core.circles.run_circles``, ``circles = count``, ``rest``), tick by tick.

    Parameters
    ----------
    circle : CircleQuintic
        One revolution.
    count : int
        Revolutions, >= 1.
    rest : float
        Rest after each revolution but the last (s), >= 0, a whole number of ``dt``.
    dt : float
        Control period (s), > 0; ``circle.duration`` a whole number of it.

    Raises
    ------
    FreejointValueError
        Naming the argument.

    """

    def __init__(self, circle, count, rest, dt):
        if not isinstance(circle, CircleQuintic):
            raise FreejointValueError(f'circle: expected CircleQuintic, got '
                                      f'{type(circle).__name__}')
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise FreejointValueError(f'count: expected an int >= 1, got {count!r}')
        dt = _finite_float('dt', dt)
        if dt <= 0.0:
            raise FreejointValueError(f'dt: expected > 0 s, got {dt}')
        rest = _finite_float('rest', rest)
        if rest < 0.0:
            raise FreejointValueError(f'rest: expected >= 0 s, got {rest}')
        n = int(round(circle.duration / dt))
        m = int(round(rest / dt))
        if abs(n * dt - circle.duration) > 1e-9 or abs(m * dt - rest) > 1e-9:
            raise FreejointValueError(
                f"rest: {rest} s and the circle's {circle.duration} s must be whole numbers "
                f'of dt = {dt} s')
        self.circle = circle
        self.count = count
        self.rest = rest
        self.dt = dt
        self._n = n
        self._period = n + m
        px, py = circle.sample(0.0)[0].tolist()
        self._rest = (px, py, 0.0, 0.0, 0.0, 0.0)
        self._duration = count * circle.duration + (count - 1) * rest

    @property
    def duration(self):
        """Time (s) from the first revolution's start to the last one's end."""
        return self._duration

    def sample_tuple(self, t):
        """
        Sample at time ``t`` (s) as plain floats: ``(px, py, vx, vy, ax, ay)``.

        ``t`` on the grid (within 1e-6 of a tick) is taken as the tick ``round(t / dt)``
        (before 0: the circle's start held); between ticks (a plan slowed by a feed hold,
        ``freejoint_core.feed_hold``) the series is sampled at ``t`` itself.
        """
        x = t / self.dt
        j = round(x)
        if j < 0:
            return self.circle.sample_tuple(t)
        if abs(x - j) > 1e-6:
            c = int(x // self._period)
            u = t - c * self._period * self.dt
            if c >= self.count or u >= self.circle.duration:
                return self._rest
            return self.circle.sample_tuple(u)
        c, i = divmod(j, self._period)
        if c >= self.count or i >= self._n:
            return self._rest
        return self.circle.sample_tuple(i * self.dt)

    def sample(self, t):
        """Sample position, velocity and acceleration at ``t``: three arrays of shape (2,)."""
        px, py, vx, vy, ax, ay = self.sample_tuple(_finite_float('t', t))
        return np.array([px, py]), np.array([vx, vy]), np.array([ax, ay])

    def points(self, num):
        """Return ``num`` points of the path (the circle's), shape (num, 2)."""
        return self.circle.points(num)


def circle_peaks(circle, num=20001):
    """
    Return the peak speed (m/s) and acceleration (m/s^2) of a ``CircleQuintic``.

    The speed ``r |phi'|`` peaks at mid-revolution, ``1.875 * 2 pi r / T``; the
    acceleration magnitude ``r sqrt(phi''^2 + phi'^4)`` is maximised over ``num``
    evenly spaced normalised times (relative error below 1e-8 at the default).

    Parameters
    ----------
    circle : CircleQuintic
        The circle.
    num : int
        Samples of the normalised time for the acceleration, >= 3.

    Returns
    -------
    tuple of float
        ``(peak_speed, peak_acceleration)``.

    """
    if not isinstance(circle, CircleQuintic):
        raise FreejointValueError(f'circle: expected CircleQuintic, got {type(circle).__name__}')
    tau = np.linspace(0.0, 1.0, max(3, int(num)))
    w = (TWO_PI / circle.duration) * tau * tau * (30.0 + tau * (-60.0 + 30.0 * tau))
    wd = (TWO_PI / circle.duration ** 2) * tau * (60.0 + tau * (-180.0 + 120.0 * tau))
    acc = circle.radius * np.sqrt(wd * wd + w ** 4)
    return 1.875 * TWO_PI * circle.radius / circle.duration, float(acc.max())


def circle_max_tick_step(circle, dt):
    """
    Return the largest distance (m) between the circle's setpoints one tick apart.

    The setpoints are ``sample_tuple(j dt)``, ``j = 0, 1, ...`` (the stream's ticks
    from the circle's start). The chord of tick ``j`` is ``2 r sin(|dphi_j| / 2)``
    with ``dphi_j = 2 pi (s(tau_{j+1}) - s(tau_j))``; ``s'`` is unimodal about
    ``tau = 1/2``, so the widest step is one of the few ticks around mid-revolution
    (ticks near the middle and, for short circles, all of them, are evaluated with
    ``sample_tuple`` exactly as streamed).

    Parameters
    ----------
    circle : CircleQuintic
        The circle.
    dt : float
        Control period (s), > 0.

    Returns
    -------
    float

    """
    dt = _finite_float('dt', dt)
    if dt <= 0.0:
        raise FreejointValueError(f'dt: expected > 0 s, got {dt}')
    last = int(math.ceil(circle.duration / dt)) + 1
    mid = int(circle.duration / (2.0 * dt))
    if last <= 4096:
        ticks = range(0, last + 1)
    else:
        ticks = range(max(0, mid - 3), min(last, mid + 4) + 1)
    pts = np.array([circle.sample_tuple(j * dt)[:2] for j in ticks])
    return float(np.hypot(np.diff(pts[:, 0]), np.diff(pts[:, 1])).max())


class QuinticTransition:
    """
    Quintic in task space from a moving state to a point at rest.

    Each coordinate is the quintic polynomial ``p(t) = sum_i c_i t^i`` with
    ``p(0) = p0``, ``p'(0) = v0``, ``p''(0) = a0`` and ``p(T) = p1``,
    ``p'(T) = p''(T) = 0``: position, velocity and acceleration are continuous
    at both joints when the segment starts from the state of the stream before
    it and ends at the start of a ``CircleQuintic`` (at rest). Time is clipped
    to ``[0, T]``: after ``T`` the end point is held.

    Parameters
    ----------
    p0, v0, a0 : sequence of float, shape (2,)
        Start position (m), velocity (m/s), acceleration (m/s^2).
    p1 : sequence of float, shape (2,)
        End position (m), reached at rest.
    duration : float
        ``T`` (s), > 0.

    Raises
    ------
    FreejointValueError
        If an argument is malformed; the message names it.

    """

    def __init__(self, p0, v0, a0, p1, duration):
        vecs = []
        for name, value in (('p0', p0), ('v0', v0), ('a0', a0), ('p1', p1)):
            try:
                arr = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise FreejointValueError(f'{name}: expected 2 numbers, got {value!r}') from None
            if arr.shape != (2,) or not np.all(np.isfinite(arr)):
                raise FreejointValueError(f'{name}: expected 2 finite numbers, got {value!r}')
            vecs.append(arr)
        p0, v0, a0, p1 = vecs
        T = _finite_float('duration', duration)
        if T <= 0.0:
            raise FreejointValueError(f'duration: expected > 0 s, got {T}')
        self._duration = T
        self._p0, self._v0, self._a0, self._p1 = p0, v0, a0, p1
        # end conditions of the part left after the Taylor terms p0 + v0 t + a0 t^2 / 2
        d = p1 - p0 - v0 * T - 0.5 * a0 * T * T
        e = -v0 - a0 * T
        f = -a0
        c3 = (10.0 * d - 4.0 * e * T + 0.5 * f * T * T) / T ** 3
        c4 = (-15.0 * d + 7.0 * e * T - f * T * T) / T ** 4
        c5 = (6.0 * d - 3.0 * e * T + 0.5 * f * T * T) / T ** 5
        self._cx = tuple(float(v) for v in (p0[0], v0[0], 0.5 * a0[0], c3[0], c4[0], c5[0]))
        self._cy = tuple(float(v) for v in (p0[1], v0[1], 0.5 * a0[1], c3[1], c4[1], c5[1]))

    @property
    def duration(self):
        """Return ``T`` (s)."""
        return self._duration

    @property
    def start(self):
        """Return ``(p0, v0, a0)``, each numpy shape (2,)."""
        return self._p0.copy(), self._v0.copy(), self._a0.copy()

    @property
    def end(self):
        """Return the end point ``p1`` (m), numpy shape (2,)."""
        return self._p1.copy()

    @staticmethod
    def _eval(c, t):
        c0, c1, c2, c3, c4, c5 = c
        p = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
        v = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * (5.0 * c5))))
        a = 2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * (20.0 * c5)))
        return p, v, a

    def sample_tuple(self, t):
        """
        Sample at time ``t`` (s) as plain floats, for hot loops (not validated).

        Returns
        -------
        tuple of float
            ``(px, py, vx, vy, ax, ay)`` in m, m/s, m/s^2.

        """
        if t <= 0.0:
            t = 0.0
        elif t >= self._duration:
            return (float(self._p1[0]), float(self._p1[1]), 0.0, 0.0, 0.0, 0.0)
        px, vx, ax = self._eval(self._cx, t)
        py, vy, ay = self._eval(self._cy, t)
        return (px, py, vx, vy, ax, ay)

    def sample_ticks(self, dt, num):
        """
        Sample at ``t_j = j dt``, ``j = 0 .. num - 1``, as ``sample_tuple`` gives them.

        Returns
        -------
        numpy.ndarray, shape (num, 6)
            Columns ``px, py, vx, vy, ax, ay``; ticks at or past ``T`` hold ``p1``.

        """
        t = np.arange(int(num)) * float(dt)
        px, vx, ax = self._eval(self._cx, t)
        py, vy, ay = self._eval(self._cy, t)
        out = np.column_stack((px, py, vx, vy, ax, ay))
        out[t >= self._duration] = (self._p1[0], self._p1[1], 0.0, 0.0, 0.0, 0.0)
        return out

    def __repr__(self):
        return (f'QuinticTransition(p0={self._p0.tolist()}, v0={self._v0.tolist()}, '
                f'a0={self._a0.tolist()}, p1={self._p1.tolist()}, '
                f'duration={self._duration!r})')


# Hermite bases of a quintic on tau in [0, 1] that ends at rest: h0 takes 0 -> 1, h1 has
# h1'(0) = 1, h2 has h2''(0) = 1, every other boundary value zero. First and second
# derivatives, as polynomial coefficients in tau (lowest first).
_H0 = (np.array([0.0, 0.0, 30.0, -60.0, 30.0]), np.array([0.0, 60.0, -180.0, 120.0]))
_H1 = (np.array([1.0, 0.0, -18.0, 32.0, -15.0]), np.array([0.0, -36.0, 96.0, -60.0]))
_H2 = (np.array([0.0, 1.0, -4.5, 6.0, -2.5]), np.array([1.0, -9.0, 18.0, -10.0]))


@dataclass(frozen=True)
class TransitionChoice:
    """
    Result of :func:`plan_transition`.

    Attributes
    ----------
    ok : bool
        True if a transition within the limits (and clear of ``path_check``) exists.
    reason : str
        Empty when ok, else why there is none.
    segment : QuinticTransition or None
        The transition (None when refused, or when none is needed).
    ticks : int
        ``T / dt``: the circle's start is tick ``ticks`` of the transition (0: none).
    peak_speed, peak_acceleration, max_step : float
        Largest speed (m/s), acceleration (m/s^2) and distance between consecutive
        setpoints (m, the last one to the end point) over its ticks.
    limits : tuple of float
        ``(speed, acceleration, step)`` it was held to.
    margin : float
        ``path_check``'s margin (m) of its tick points (inf without ``path_check``).

    """

    ok: bool
    reason: str
    segment: object
    ticks: int
    peak_speed: float
    peak_acceleration: float
    max_step: float
    limits: tuple
    margin: float


def transition_limits(circle, dt, v0, a0):
    """
    Return the ``(speed, acceleration, step)`` limits of a transition into ``circle``.

    The circle's own peak speed ``V`` and acceleration ``A`` (:func:`circle_peaks`)
    and its largest per-tick step ``S`` (:func:`circle_max_tick_step`), raised to the
    start state's own ``|v0|``, ``|a0|`` (and ``S |v0| / V``) when that is faster:
    a transition cannot start below the state it starts from.
    """
    speed, acc = circle_peaks(circle)
    step = circle_max_tick_step(circle, dt)
    v = float(np.hypot(*np.asarray(v0, dtype=float)))
    a = float(np.hypot(*np.asarray(a0, dtype=float)))
    return max(speed, v), max(acc, a), step * max(1.0, v / speed)


# Candidates coarse-tested at once (the search stops at the first chunk that has one).
CHUNK = 64


@functools.lru_cache(maxsize=8)
def _candidates(max_ticks):
    return np.array(transition_candidates(max_ticks), dtype=np.int64)


def transition_candidates(max_ticks, growth=1.01, dense=32):
    """Return the candidate durations in ticks: 1 .. dense, then growing by ``growth``."""
    out = list(range(1, min(dense, max_ticks) + 1))
    n = dense
    while n < max_ticks:
        n = min(max_ticks, max(n + 1, int(math.ceil(n * growth))))
        out.append(n)
    return out


# A state at rest this close to a circle's start needs no transition (m): rounding, as
# between the paper circle's end (0.2, -4.9e-17) and its start (0.2, 0).
AT_START = 1e-9


def plan_transition(p0, v0, a0, circle, dt, max_duration=60.0, path_check=None,
                    limits=None, coarse=65, max_exact=400):
    """
    Choose the shortest quintic transition from a stream state into ``circle``'s start.

    The candidate durations are whole numbers of ticks (the circle then starts on a
    tick), in increasing order (:func:`transition_candidates`). A candidate is kept if,
    over its ticks ``t_j = j dt`` (as streamed, ``QuinticTransition.sample_ticks``,
    the last one the circle's start), its speed and acceleration stay within the
    limits and no two consecutive setpoints are farther apart than the step limit,
    and ``path_check`` accepts its tick points. A coarse test on ``coarse`` normalised
    times (1 % slack), ``CHUNK`` candidates at a time, skips the hopeless ones first.

    Parameters
    ----------
    p0, v0, a0 : sequence of float, shape (2,)
        The stream's state at the transition's first tick (m, m/s, m/s^2).
    circle : CircleQuintic
        The circle to start; the transition ends at ``circle.sample_tuple(0)`` at rest.
    dt : float
        Control period (s), > 0.
    max_duration : float
        Longest transition considered (s), > 0.
    path_check : callable, optional
        ``path_check(points) -> (ok, margin, reason)`` for points of shape (N, 2) (m).
    limits : tuple of float, optional
        ``(speed, acceleration, step)``; default :func:`transition_limits`.
    coarse : int
        Normalised samples of the coarse test, >= 3.
    max_exact : int
        At most this many candidates are checked tick by tick.

    Returns
    -------
    TransitionChoice
        ``ok`` with ``ticks == 0`` and no segment if the state is at rest (zero velocity
        and acceleration) within ``AT_START`` of the circle's start.

    """
    dt = _finite_float('dt', dt)
    if dt <= 0.0:
        raise FreejointValueError(f'dt: expected > 0 s, got {dt}')
    max_duration = _finite_float('max_duration', max_duration)
    if max_duration <= 0.0:
        raise FreejointValueError(f'max_duration: expected > 0 s, got {max_duration}')
    start = QuinticTransition(p0, v0, a0, p0, 1.0)     # validates the state
    p0, v0, a0 = start.start
    px, py = circle.sample_tuple(0.0)[:2]
    p1 = np.array([px, py])
    if limits is None:
        limits = transition_limits(circle, dt, v0, a0)
    v_lim, a_lim, s_lim = (float(x) for x in limits)
    if float(np.hypot(*(p1 - p0))) <= AT_START and not v0.any() and not a0.any():
        return TransitionChoice(True, '', None, 0, 0.0, 0.0, 0.0, (v_lim, a_lim, s_lim),
                                math.inf)
    speed0, acc0 = float(np.hypot(*v0)), float(np.hypot(*a0))
    if speed0 > v_lim or acc0 > a_lim:
        return TransitionChoice(
            False, f'the current state ({speed0:.6g} m/s, {acc0:.6g} m/s^2) is already above '
            f'the limits (speed {v_lim:.6g} m/s, acceleration {a_lim:.6g} m/s^2)', None, 0,
            math.nan, math.nan, math.nan, (v_lim, a_lim, s_lim), math.nan)
    max_ticks = max(1, int(math.floor(max_duration / dt + 1e-9)))
    cand = _candidates(max_ticks)
    tau = np.linspace(0.0, 1.0, max(3, int(coarse)))
    h = [(np.polyval(d1[::-1], tau)[None, :], np.polyval(d2[::-1], tau)[None, :])
         for d1, d2 in (_H0, _H1, _H2)]
    dp = p1 - p0
    best = (math.inf, None)                           # the closest miss, for the reason
    path_reason = ''
    exact = 0
    for lo in range(0, len(cand), CHUNK):
        # coarse test of a chunk of candidates at once: shape (chunk, coarse) per axis
        n_chunk = cand[lo:lo + CHUNK]
        T = (n_chunk * dt)[:, None]
        v2 = np.zeros((len(n_chunk), tau.size))
        a2 = np.zeros_like(v2)
        for ax in (0, 1):
            v = (dp[ax] * h[0][0] + v0[ax] * T * h[1][0] + a0[ax] * T * T * h[2][0]) / T
            a = (dp[ax] * h[0][1] + v0[ax] * T * h[1][1] + a0[ax] * T * T * h[2][1]) / (T * T)
            v2 += v * v
            a2 += a * a
        hopeful = np.nonzero((v2.max(axis=1) <= (1.01 * v_lim) ** 2)
                             & (a2.max(axis=1) <= (1.01 * a_lim) ** 2))[0]
        for i in hopeful:
            if exact >= max_exact:
                break
            exact += 1
            n = int(n_chunk[i])
            seg = QuinticTransition(p0, v0, a0, p1, n * dt)
            s = seg.sample_ticks(dt, n + 1)
            s[n] = (p1[0], p1[1], 0.0, 0.0, 0.0, 0.0)
            speed = float(np.hypot(s[:, 2], s[:, 3]).max())
            acc_n = float(np.hypot(s[:, 4], s[:, 5]).max())
            step = float(np.hypot(np.diff(s[:, 0]), np.diff(s[:, 1])).max())
            excess = max(speed / v_lim, acc_n / a_lim, step / s_lim)
            if excess > 1.0:
                if excess < best[0]:
                    best = (excess, (n, speed, acc_n, step))
                continue
            margin = math.inf
            if path_check is not None:
                ok, margin, reason = path_check(s[:, :2])
                if not ok:
                    path_reason = path_reason or (
                        f'the shortest transition within the limits ({n * dt:.6g} s) would '
                        f'pass a point {reason}')
                    continue
            return TransitionChoice(True, '', seg, n, speed, acc_n, step,
                                    (v_lim, a_lim, s_lim), float(margin))
    lim = (f'speed {v_lim:.6g} m/s, acceleration {a_lim:.6g} m/s^2, step {s_lim:.6g} m '
           f'per tick')
    if path_reason:
        reason = path_reason + ' (and every longer one up to ' \
            f'{max_duration:g} s within {lim} too)'
    elif best[1] is not None:
        n, speed, acc_n, step = best[1]
        reason = (f'no transition of at most {max_duration:g} s from the current state '
                  f'stays within {lim}: the closest ({n * dt:.6g} s) reaches {speed:.6g} '
                  f'm/s, {acc_n:.6g} m/s^2, {step:.6g} m')
    else:
        reason = f'no transition of at most {max_duration:g} s stays within {lim}'
    return TransitionChoice(False, reason, None, 0, math.nan, math.nan, math.nan,
                            (v_lim, a_lim, s_lim), math.nan)
