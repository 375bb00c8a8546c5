"""
Circle trajectory with a quintic time scaling of the angle (paper, Sec. 4).

The end effector goes once around a circle; the polar angle about the centre
follows the quintic ``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` of the
normalised time ``tau = t / T``, so position, velocity and acceleration are
continuous and the velocity and acceleration are zero at both ends.
"""

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

    def check_reachable(self, params):
        """
        Raise unless the whole circle lies in the arm's reach annulus.

        Parameters
        ----------
        params : ArmParams or sequence of float
            The arm (only its ``lengths`` are used) or the link lengths (m).

        Raises
        ------
        FreejointValueError
            Naming ``radius`` when no centre could fit a circle of this radius
            in the annulus (``2 radius > r_max - r_min``), else ``centre`` when
            this centre puts part of the circle out of reach.

        """
        lengths = getattr(params, 'lengths', params)
        r_min, r_max = workspace_annulus(lengths)
        if 2.0 * self._radius > r_max - r_min:
            raise FreejointValueError(
                f'radius: {self._radius} m does not fit the reach annulus '
                f'[{r_min:.6g}, {r_max:.6g}] m of the arm')
        dist = math.hypot(self._cx, self._cy)
        near = abs(dist - self._radius)   # closest base distance on the circle
        far = dist + self._radius
        if far > r_max or near < r_min:
            raise FreejointValueError(
                f'centre: circle about ({self._cx:.6g}, {self._cy:.6g}) m with radius '
                f'{self._radius} m spans base distances [{near:.6g}, {far:.6g}] m, outside '
                f'the reach annulus [{r_min:.6g}, {r_max:.6g}] m')

    def __repr__(self):
        return (f'CircleQuintic(centre=({self._cx!r}, {self._cy!r}), radius={self._radius!r}, '
                f'duration={self._duration!r}, start_angle={self._start!r}, '
                f'direction={self._dir!r})')
