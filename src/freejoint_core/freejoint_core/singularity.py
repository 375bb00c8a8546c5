"""
Dynamic singularities of the nominal decoupling matrix (paper, Sec. 3.2).

The paper's three steps for a singularity-free Cartesian path:

1. :func:`det_map` - sample ``|det(Da Da^T)|`` of the *nominal* decoupling
   matrix ``Da = J M^-1 B`` (eq. 4) over joint space;
2. :func:`semi_singular` - map the samples below ``eps_d`` to Cartesian space
   by the forward kinematics: the *semi-singular* region (its complement in
   reach is guaranteed nonsingular);
3. :func:`check_path` - accept a desired path only if it stays in the
   nonsingular region, and report by how much.

Reductions used (each one proven by a test in ``test/core/test_singularity.py``):

* ``Da`` depends on ``q`` only: ``J`` is kinematic and ``M`` holds no gravity,
  which enters the dynamics only through ``G(q)`` and thus only the drift
  ``b`` of eq. (5). The map is the same for the horizontal and vertical cases.
* Base rotation: ``fk(q1 + a, ...) = Rot(a) fk(q1, ...)`` so ``J -> Rot(a) J``
  while ``M`` does not depend on ``q1``; hence ``Da -> Rot(a) Da`` and
  ``det(Da Da^T)`` is invariant to ``q1``. The map is over ``(q2, q3)``.
* Mirror: ``(q2, q3) -> (-q2, -q3)`` reflects the arm about its first link,
  ``det(Da)`` changes sign and ``det(Da Da^T) = det(Da)^2`` is unchanged.
* The end-effector radius ``|fk(q)|`` depends on ``(q2, q3)`` only, so the
  Cartesian image of a singular ``(q2, q3)`` is the full circle of that
  radius: the semi-singular region is a union of annuli about the base and
  is stored as radial intervals.

Closed form for the 3-link arm with joint 3 passive (the paper's arm).  In
absolute link angles the inertia matrix has constant diagonal ``A_i`` and
off-diagonal ``h_ij cos(phi_i - phi_j)``; the change to relative angles has
unit determinant, so::

    det M = A1 A2 A3 + 2 h12 h13 h23 c2 c3 c23
            - A3 h12^2 c2^2 - A1 h23^2 c3^2 - A2 h13^2 c23^2
    A1 = I1 + m1 lc1^2 + (m2 + m3) L1^2,  A2 = I2 + m2 lc2^2 + m3 L2^2,
    A3 = I3 + m3 lc3^2,  h12 = (m2 lc2 + m3 L2) L1,  h13 = m3 lc3 L1,
    h23 = m3 lc3 L2,  c2 = cos q2, c3 = cos q3, c23 = cos(q2 + q3).

With ``Da = Ja_eff Maa_eff^-1`` (eq. 4), ``det Maa_eff = det M / M33`` and the
columns ``J_i = perp(p - o_i)`` of the planar Jacobian, the Schur expansion
``det(Da) det(M) = M33 [J1 J2] - M32 [J1 J3] + M31 [J2 J3]`` (``[a b]`` the 2-D
cross product) collapses to::

    det Da = L1 L2 sin(q2) (I3 + m3 lc3 (lc3 - L3)) / det M

so ``Da`` is singular exactly at ``q2 = 0, pi`` (stretched or folded elbow)
unless the end effector sits at the centre of percussion of link 3
(``I3 = m3 lc3 (L3 - lc3)``), where it is singular everywhere.
"""

from dataclasses import dataclass
import math

import numpy as np

from .errors import FreejointValueError, positive
from .trajectory import workspace_annulus

# Paper's criterion eps_d for |det(Da Da^T)| (Sec. 4).
EPS_D = 1e-7

# Occupancy values of to_grid: a cell wholly in the nonsingular region within reach,
# a cell touching the semi-singular region, a cell touching points out of reach ('unknown').
GRID_FREE = 0
GRID_SEMI_SINGULAR = 100
GRID_UNREACHABLE = -1

_CHUNK = 1 << 16  # grid points per batch on the general (batched linear algebra) path


def _check_params(params):
    for name in ('lengths', 'masses', 'inertias', 'com', 'passive'):
        if not hasattr(params, name):
            raise FreejointValueError(
                f'nominal_params: expected ArmParams, got {type(params).__name__}')
    if len(params.lengths) != 3:
        raise FreejointValueError(
            f'nominal_params: the (q2, q3) map needs a 3-link arm, got n = '
            f'{len(params.lengths)}')
    if len(params.passive) != 1:
        raise FreejointValueError(
            f'nominal_params: need exactly one passive joint (r = m = 2), got '
            f'passive = {tuple(params.passive)}')


def _check_resolution(resolution_deg):
    try:
        res = float(resolution_deg)
    except (TypeError, ValueError):
        raise FreejointValueError(
            f'resolution_deg: expected a number, got {resolution_deg!r}') from None
    if not math.isfinite(res) or res <= 0.0 or res > 90.0:
        raise FreejointValueError(f'resolution_deg: expected 0 < value <= 90, got {res}')
    steps = 360.0 / res
    n = int(round(steps))
    if abs(steps - n) > 1e-9 * steps or n % 2:
        raise FreejointValueError(
            f'resolution_deg: 360 / {res} must be an even integer (so that 0 and 180 deg '
            f'are samples)')
    return res, n


def _coefficients(params):
    """Return the constants ``A1, A2, A3, h12, h13, h23, k`` of the closed form."""
    (l1, l2, l3), (m1, m2, m3) = params.lengths, params.masses
    (i1, i2, i3), (c1, c2, c3) = params.inertias, params.com
    a1 = i1 + m1 * c1 * c1 + (m2 + m3) * l1 * l1
    a2 = i2 + m2 * c2 * c2 + m3 * l2 * l2
    a3 = i3 + m3 * c3 * c3
    h12 = (m2 * c2 + m3 * l2) * l1
    h13 = m3 * c3 * l1
    h23 = m3 * c3 * l2
    k = l1 * l2 * (i3 + m3 * c3 * (c3 - l3))
    return a1, a2, a3, h12, h13, h23, k


def det_da_closed_form(nominal_params, q2, q3):
    """
    Signed ``det(Da)`` of the 3-link arm with joint 3 passive, vectorised.

    ``det(Da Da^T) = det(Da)^2`` since ``Da`` is square (r = m = 2).

    Parameters
    ----------
    nominal_params : ArmParams
        3-link arm, ``passive == (2,)``.
    q2, q3 : array_like
        Joint angles (rad), broadcast against each other. ``q1`` is irrelevant.

    Returns
    -------
    numpy.ndarray
        ``det(Da)`` (m^2 / (kg^2 m^4) = 1 / (kg^2 m^2)), broadcast shape.

    """
    _check_params(nominal_params)
    if tuple(nominal_params.passive) != (2,):
        raise FreejointValueError(
            f'nominal_params: closed form needs passive == (2,), got '
            f'{tuple(nominal_params.passive)}')
    q2 = np.asarray(q2, dtype=float)
    q3 = np.asarray(q3, dtype=float)
    a1, a2, a3, h12, h13, h23, k = _coefficients(nominal_params)
    c2, c3, c23 = np.cos(q2), np.cos(q3), np.cos(q2 + q3)
    det_m = (a1 * a2 * a3 + 2.0 * h12 * h13 * h23 * c2 * c3 * c23
             - a3 * h12 ** 2 * c2 * c2 - a1 * h23 ** 2 * c3 * c3 - a2 * h13 ** 2 * c23 * c23)
    return k * np.sin(q2) / det_m


def _batched_da(params, q2, q3):
    """``Da`` (N, 2, 2) of a 3-link arm, any single passive joint, q1 = 0."""
    (l1, l2, l3) = params.lengths
    a1, a2, a3, h12, h13, h23, _ = _coefficients(params)
    c2, c3, c23 = np.cos(q2), np.cos(q3), np.cos(q2 + q3)
    n = q2.size
    m_abs = np.empty((n, 3, 3))
    m_abs[:, 0, 0], m_abs[:, 1, 1], m_abs[:, 2, 2] = a1, a2, a3
    m_abs[:, 0, 1] = m_abs[:, 1, 0] = h12 * c2
    m_abs[:, 0, 2] = m_abs[:, 2, 0] = h13 * c23
    m_abs[:, 1, 2] = m_abs[:, 2, 1] = h23 * c3
    tmat = np.tril(np.ones((3, 3)))        # phi_dot = T q_dot
    mass = tmat.T @ m_abs @ tmat           # relative-angle inertia matrix
    # J columns: perp(p - o_i), q1 = 0.
    r3 = np.stack((l3 * c23, l3 * np.sin(q2 + q3)), axis=-1)
    r2 = r3 + np.stack((l2 * c2, l2 * np.sin(q2)), axis=-1)
    r1 = r2 + np.array([l1, 0.0])
    jac = np.empty((n, 2, 3))
    for col, rvec in enumerate((r1, r2, r3)):
        jac[:, 0, col] = -rvec[:, 1]
        jac[:, 1, col] = rvec[:, 0]
    active = [i for i in range(3) if i not in tuple(params.passive)]
    bmat = np.broadcast_to(np.eye(3)[:, active], (n, 3, 2))
    return jac @ np.linalg.solve(mass, bmat)


def det_da_general(nominal_params, q2, q3):
    """
    Signed ``det(Da)`` of a 3-link arm with any one passive joint, vectorised.

    Batched linear algebra (``numpy.linalg.solve`` on (N, 3, 3)); slower than
    :func:`det_da_closed_form` but not tied to ``passive == (2,)``.

    Parameters
    ----------
    nominal_params : ArmParams
        3-link arm with one passive joint.
    q2, q3 : array_like
        Joint angles (rad), broadcast against each other.

    Returns
    -------
    numpy.ndarray
        ``det(Da)`` (1 / (kg^2 m^2)), broadcast shape.

    """
    _check_params(nominal_params)
    q2, q3 = np.broadcast_arrays(np.asarray(q2, dtype=float), np.asarray(q3, dtype=float))
    shape = q2.shape
    q2, q3 = q2.ravel(), q3.ravel()
    out = np.empty(q2.size)
    for start in range(0, q2.size, _CHUNK):
        sl = slice(start, start + _CHUNK)
        da = _batched_da(nominal_params, q2[sl], q3[sl])
        out[sl] = da[:, 0, 0] * da[:, 1, 1] - da[:, 0, 1] * da[:, 1, 0]
    return out.reshape(shape)


def ee_radius(lengths, q2, q3):
    """
    Distance of the end effector from the base (m), 3-link arm, vectorised.

    ``|p|^2 = L1^2 + L2^2 + L3^2 + 2 L1 L2 c2 + 2 L2 L3 c3 + 2 L1 L3 c23``:
    independent of ``q1``.

    Parameters
    ----------
    lengths : sequence of float, shape (3,)
        Link lengths (m).
    q2, q3 : array_like
        Joint angles (rad), broadcast against each other.

    Returns
    -------
    numpy.ndarray
        Radius (m), broadcast shape.

    """
    l1, l2, l3 = (float(v) for v in lengths)
    q2 = np.asarray(q2, dtype=float)
    q3 = np.asarray(q3, dtype=float)
    r2 = (l1 * l1 + l2 * l2 + l3 * l3 + 2.0 * l1 * l2 * np.cos(q2)
          + 2.0 * l2 * l3 * np.cos(q3) + 2.0 * l1 * l3 * np.cos(q2 + q3))
    return np.sqrt(np.maximum(r2, 0.0))


@dataclass(frozen=True)
class DetMap:
    """
    Joint-space map of the nominal decoupling determinant.

    Attributes
    ----------
    q : numpy.ndarray, shape (n,)
        Grid angles (rad), ``k * resolution`` for ``k = 0 .. n-1`` (``[0, 2 pi)``),
        used for both ``q2`` (rows) and ``q3`` (columns).
    det : numpy.ndarray, shape (n, n)
        ``|det(Da Da^T)|`` at ``(q2 = q[i], q3 = q[j])``, any ``q1``
        (1 / (kg^4 m^4)).
    det_da : numpy.ndarray, shape (n, n)
        Signed ``det(Da)``; a sign change between neighbours brackets a zero.
    resolution_deg : float
        Grid step (deg).
    lengths : tuple of float
        Link lengths (m), for the Cartesian image.

    """

    q: np.ndarray
    det: np.ndarray
    det_da: np.ndarray
    resolution_deg: float
    lengths: tuple

    @property
    def radius(self):
        """Return the distance of the end effector from the base on the grid (m), (n, n)."""
        return ee_radius(self.lengths, self.q[:, None], self.q[None, :])


def _closed_form_grid(params, n):
    """
    ``det(Da)`` on the full (q2, q3) grid, closed form, about 11 array passes.

    ``cos(q2 + q3)`` on a uniform periodic grid is ``C[(i + j) mod n]``: a
    sliding-window view of ``[C, C]`` (no computation). The mirror symmetry
    ``det_da(-q2, -q3) = -det_da(q2, q3)`` gives rows ``n/2+1 .. n-1`` from
    rows ``1 .. n/2-1``.
    """
    a1, a2, a3, h12, h13, h23, k = _coefficients(params)
    q = np.arange(n) * (2.0 * math.pi / n)
    c = np.cos(q)
    s = np.sin(q)
    # exact zeros / signs at 0, 90, 180, 270 deg keep the grid symmetric
    c[np.abs(c) < 1e-15] = 0.0
    s[np.abs(s) < 1e-15] = 0.0
    half = n // 2 + 1                                     # rows 0 .. n/2
    cc = np.concatenate((c, c))
    win = np.lib.stride_tricks.sliding_window_view(cc, n)[:half]      # c23, view
    win2 = np.lib.stride_tricks.sliding_window_view(
        cc * cc * (a2 * h13 ** 2), n)[:half]                          # A2 h13^2 c23^2
    ch = c[:half]
    out = np.empty((n, n))
    top = out[:half]
    np.multiply.outer(ch * (2.0 * h12 * h13 * h23), c, out=top)
    top *= win
    top -= win2
    top += (a1 * a2 * a3 - a3 * h12 ** 2 * ch * ch)[:, None]
    top -= (a1 * h23 ** 2) * c * c
    np.divide((k * s[:half])[:, None], top, out=top)
    # mirror: row n-i, column (n-j) mod n  <-  -row i, column j
    lower = out[half:]                                    # rows n/2+1 .. n-1
    src = top[n // 2 - 1:0:-1]                            # rows n/2-1 .. 1
    lower[:, 0] = -src[:, 0]
    lower[:, 1:] = -src[:, :0:-1]
    return q, out


def det_map(nominal_params, resolution_deg=1.0, method='auto'):
    """
    Step 1: sample ``|det(Da Da^T)|`` of the nominal model over joint space.

    Uses the nominal parameters only; gravity plays no part (``Da = J M^-1 B``
    holds no gravity term, see the module notes) and ``q1`` drops out by the
    base-rotation invariance, so the map is over ``(q2, q3)`` in ``[0, 2 pi)``.

    Parameters
    ----------
    nominal_params : ArmParams
        Nominal 3-link arm with one passive joint (Table I nominal:
        ``table1(case).scaled(0.7)``).
    resolution_deg : float
        Grid step (deg), ``360 / resolution_deg`` an even integer. At 0.25 deg
        the map has 1440 x 1440 samples.
    method : {'auto', 'closed_form', 'general'}
        'closed_form' (needs ``passive == (2,)``; array passes only),
        'general' (batched 3 x 3 solves, any passive joint, slower),
        'auto' picks the closed form when it applies.

    Returns
    -------
    DetMap

    Raises
    ------
    FreejointValueError
        Naming ``nominal_params``, ``resolution_deg`` or ``method``.

    """
    _check_params(nominal_params)
    _, n = _check_resolution(resolution_deg)
    if method not in ('auto', 'closed_form', 'general'):
        raise FreejointValueError(
            f"method: expected 'auto', 'closed_form' or 'general', got {method!r}")
    closed_ok = tuple(nominal_params.passive) == (2,)
    if method == 'closed_form' and not closed_ok:
        raise FreejointValueError(
            f'method: closed_form needs passive == (2,), got {tuple(nominal_params.passive)}')
    if method == 'general' or not closed_ok:
        q = np.arange(n) * (2.0 * math.pi / n)
        det_da = det_da_general(nominal_params, q[:, None], q[None, :])
    else:
        q, det_da = _closed_form_grid(nominal_params, n)
    det = np.square(det_da)
    for arr in (q, det, det_da):
        arr.flags.writeable = False
    return DetMap(q=q, det=det, det_da=det_da, resolution_deg=float(resolution_deg),
                  lengths=tuple(float(v) for v in nominal_params.lengths))


@dataclass(frozen=True)
class SemiSingularRegion:
    """
    Step 2: the Cartesian semi-singular region, a union of annuli.

    Attributes
    ----------
    intervals : numpy.ndarray, shape (k, 2)
        Sorted, disjoint radial intervals ``[r_lo, r_hi]`` (m) about the base,
        conservative (see :func:`semi_singular`).
    sample_intervals : numpy.ndarray, shape (k', 2)
        The same from the flagged samples' radii alone, without the cell
        widening (the paper's plain sampling), for reporting.
    reach : tuple of float
        ``(r_min, r_max)`` (m) of the arm's reach annulus.
    eps_d : float
        Criterion used on ``|det(Da Da^T)|``.
    resolution_deg : float
        Grid step (deg) of the underlying map.
    singular_mask : numpy.ndarray of bool, shape (n, n)
        Flagged joint-space samples (rows q2, columns q3).

    """

    intervals: np.ndarray
    sample_intervals: np.ndarray
    reach: tuple
    eps_d: float
    resolution_deg: float
    singular_mask: np.ndarray

    @property
    def nonsingular_intervals(self):
        """Return the complement of ``intervals`` within reach, shape (k'', 2), m."""
        lo, hi = self.reach
        out = []
        cur = lo
        for a, b in self.intervals:
            if a > cur:
                out.append((cur, a))
            cur = max(cur, b)
        if cur < hi:
            out.append((cur, hi))
        return np.array(out, dtype=float).reshape(-1, 2)

    def radial_distance(self, r):
        """
        Signed distance (m) of base distances ``r`` to the forbidden set.

        Positive in the nonsingular region within reach (distance to the
        nearest semi-singular interval or reach boundary, an ``r_min = 0``
        inner boundary excluded since the base itself is reachable), negative
        inside a semi-singular interval or out of reach (depth), vectorised.
        """
        r = np.asarray(r, dtype=float)
        lo, hi = self.reach
        dist = hi - r                                  # < 0 beyond reach
        if lo > 0.0:
            dist = np.minimum(dist, r - lo)
        for a, b in self.intervals:
            # outside [a, b]: distance to it; inside: minus the depth
            d = np.maximum(a - r, r - b)
            dist = np.minimum(dist, d)
        return dist

    def to_grid(self, extent, cell):
        """
        Rasterise to an occupancy grid (for ``nav_msgs/OccupancyGrid``).

        Parameters
        ----------
        extent : sequence of float, shape (4,)
            ``(x_min, x_max, y_min, y_max)`` (m) of the grid, base frame.
        cell : float
            Cell size (m), > 0. ``nx = ceil((x_max - x_min) / cell)``, same in y.

        Returns
        -------
        numpy.ndarray of int8, shape (ny, nx)
            Row-major, row ``i`` is ``y = y_min + (i + 1/2) cell`` (row 0 at
            the bottom), column ``j`` is ``x = x_min + (j + 1/2) cell``; the
            origin (lower-left corner of cell (0, 0)) is ``(x_min, y_min)``.
            ``ravel()`` gives OccupancyGrid ``data``. Values:
            :data:`GRID_SEMI_SINGULAR` (100) if any point of the cell is
            semi-singular, else :data:`GRID_UNREACHABLE` (-1) if any point is
            out of reach, else :data:`GRID_FREE` (0).

        """
        try:
            ext = np.asarray(extent, dtype=float)
        except (TypeError, ValueError):
            raise FreejointValueError(f'extent: expected 4 numbers, got {extent!r}') from None
        if ext.shape != (4,) or not np.all(np.isfinite(ext)):
            raise FreejointValueError(
                f'extent: expected finite (x_min, x_max, y_min, y_max), got {extent!r}')
        x0, x1, y0, y1 = (float(v) for v in ext)
        if x1 <= x0 or y1 <= y0:
            raise FreejointValueError(
                f'extent: need x_min < x_max and y_min < y_max, got {ext.tolist()}')
        cell = positive('cell', cell)
        nx = int(math.ceil((x1 - x0) / cell - 1e-9))
        ny = int(math.ceil((y1 - y0) / cell - 1e-9))
        xl = x0 + np.arange(nx) * cell
        yl = y0 + np.arange(ny) * cell
        xh, yh = xl + cell, yl + cell
        # nearest / farthest |coordinate| over each cell's span
        xn = np.where((xl <= 0.0) & (xh >= 0.0), 0.0, np.minimum(np.abs(xl), np.abs(xh)))
        yn = np.where((yl <= 0.0) & (yh >= 0.0), 0.0, np.minimum(np.abs(yl), np.abs(yh)))
        xf = np.maximum(np.abs(xl), np.abs(xh))
        yf = np.maximum(np.abs(yl), np.abs(yh))
        rn = np.hypot(yn[:, None], xn[None, :])
        rf = np.hypot(yf[:, None], xf[None, :])
        grid = np.full((ny, nx), GRID_FREE, dtype=np.int8)
        lo, hi = self.reach
        grid[(rf > hi) | (rn < lo)] = GRID_UNREACHABLE
        for a, b in self.intervals:
            grid[(rn <= b) & (rf >= a)] = GRID_SEMI_SINGULAR
        return grid


def _merge(lo, hi):
    """Merge intervals given by sorted ``lo`` and matching ``hi`` arrays."""
    if lo.size == 0:
        return np.zeros((0, 2))
    order = np.argsort(lo, kind='stable')
    lo, hi = lo[order], np.maximum.accumulate(hi[order])
    breaks = np.nonzero(lo[1:] > hi[:-1])[0]
    starts = np.concatenate(([0], breaks + 1))
    ends = np.concatenate((breaks, [lo.size - 1]))
    return np.column_stack((lo[starts], hi[ends]))


def semi_singular(det_map, eps_d=EPS_D):
    """
    Step 2: the semi-singular region in Cartesian space (union of annuli).

    A joint-space sample ``(q2, q3)`` is flagged singular if
    ``|det(Da Da^T)| <= eps_d`` there, or if ``det(Da)`` changes sign to a
    grid neighbour (a zero lies in between; catches bands thinner than the
    grid). Its Cartesian image is the circle of radius ``|fk|`` about the
    base. To cover the whole grid cell around each flagged sample, each radius
    is widened by ``(L2 + 2 L3) * dq / 2`` (a bound on ``|dr/dq2| + |dr/dq3|``
    times half a step), and overlapping intervals are merged and clipped to
    the reach annulus: a conservative region.

    Parameters
    ----------
    det_map : DetMap
        From :func:`det_map`.
    eps_d : float
        Criterion (> 0) on ``|det(Da Da^T)|``; the paper uses 1e-7.

    Returns
    -------
    SemiSingularRegion

    """
    if not isinstance(det_map, DetMap):
        raise FreejointValueError(f'det_map: expected DetMap, got {type(det_map).__name__}')
    eps = _check_eps(eps_d)
    sgn = np.signbit(det_map.det_da)
    mask = det_map.det <= eps
    for axis in (0, 1):
        flip = sgn != np.roll(sgn, -1, axis=axis)      # change between k and k+1
        mask |= flip | np.roll(flip, 1, axis=axis)
    i, j = np.nonzero(mask)
    radii = ee_radius(det_map.lengths, det_map.q[i], det_map.q[j])
    reach = workspace_annulus(det_map.lengths)
    _, l2, l3 = det_map.lengths
    dq = math.radians(det_map.resolution_deg)
    widen = (l2 + 2.0 * l3) * dq / 2.0
    return _region(radii, widen, (l2 + l3) * dq, reach, eps, det_map.resolution_deg, mask)


def _check_eps(eps_d):
    """Return ``eps_d`` as a float, or raise naming it (finite, > 0)."""
    return positive('eps_d', eps_d)


def _region(radii, widen, gap_step, reach, eps, resolution_deg, mask):
    """
    Return the ``SemiSingularRegion`` of the flagged samples' end-effector radii (m).

    Each radius widened by ``widen`` (m) either way, merged and clipped to ``reach``;
    the raw radii merged where consecutive ones are closer than ``gap_step`` (m).
    """
    intervals = _merge(np.clip(radii - widen, *reach), np.clip(radii + widen, *reach))
    # the raw sample radii, merged where consecutive radii are closer than a step
    srt = np.sort(radii)
    if srt.size:
        gap = np.nonzero(np.diff(srt) > gap_step)[0]
        starts = np.concatenate(([0], gap + 1))
        ends = np.concatenate((gap, [srt.size - 1]))
        sample_intervals = np.column_stack((srt[starts], srt[ends]))
    else:
        sample_intervals = np.zeros((0, 2))
    mask.flags.writeable = False
    return SemiSingularRegion(intervals=intervals, sample_intervals=sample_intervals,
                              reach=reach, eps_d=eps, resolution_deg=resolution_deg,
                              singular_mask=mask)


@dataclass(frozen=True)
class PathCheck:
    """
    Result of :func:`check_path`.

    Attributes
    ----------
    ok : bool
        True if every point lies in the nonsingular region within reach.
    margin : float
        Minimum over the points of the signed radial distance (m) to the
        semi-singular set and the reach boundary; negative when refused.
    reason : str
        Empty when ok, else names the first offending point (and time).

    """

    ok: bool
    margin: float
    reason: str


def check_path(region, points, times=None):
    """
    Step 3: accept a Cartesian path only if it avoids the semi-singular set.

    Parameters
    ----------
    region : SemiSingularRegion
        From :func:`semi_singular`.
    points : array_like, shape (N, 2)
        Path points (m), base frame, N >= 1.
    times : array_like, shape (N,), optional
        Time of each point (s), only used to name the first offender.

    Returns
    -------
    PathCheck

    """
    if not isinstance(region, SemiSingularRegion):
        raise FreejointValueError(
            f'region: expected SemiSingularRegion, got {type(region).__name__}')
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise FreejointValueError(f'points: expected an (N, 2) array, got {points!r}') from None
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 1:
        raise FreejointValueError(f'points: expected shape (N, 2) with N >= 1, got {pts.shape}')
    if not np.all(np.isfinite(pts)):
        raise FreejointValueError('points: values must be finite')
    if times is not None:
        try:
            tt = np.asarray(times, dtype=float)
        except (TypeError, ValueError):
            raise FreejointValueError(f'times: expected an (N,) array, got {times!r}') from None
        if tt.shape != (pts.shape[0],):
            raise FreejointValueError(
                f'times: expected shape ({pts.shape[0]},), got {tt.shape}')
    r = np.hypot(pts[:, 0], pts[:, 1])
    dist = region.radial_distance(r)
    margin = float(dist.min())
    bad = np.nonzero(dist <= 0.0)[0]
    if bad.size == 0:
        return PathCheck(True, margin, '')
    k = int(bad[0])
    rk = float(r[k])
    when = f' (t = {float(tt[k]):.6g} s)' if times is not None else ''
    lo, hi = region.reach
    where = f'outside the reach annulus [{lo:.6g}, {hi:.6g}] m'
    for a, b in region.intervals:
        if a <= rk <= b:
            where = f'inside the semi-singular annulus [{a:.6g}, {b:.6g}] m'
            break
    else:
        if lo <= rk <= hi:
            where = f'on the boundary of the nonsingular region (margin {float(dist[k]):.3g} m)'
    reason = (f'point {k}{when} at ({pts[k, 0]:.6g}, {pts[k, 1]:.6g}) m, r = {rk:.6g} m, is '
              f'{where}')
    return PathCheck(False, margin, reason)
