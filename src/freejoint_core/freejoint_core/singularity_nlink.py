"""
Singularity map and semi-singular region of any planar serial arm (paper, Sec. 3.2).

:mod:`freejoint_core.singularity` holds the paper's 3-link arm (one passive joint) on a
(q2, q3) grid with its closed form; this module is the general path for a planar arm of
``n`` revolute joints with any passive subset leaving ``r >= 2`` active joints, and
:func:`arm_region` picks between the two (the 3-link one-passive arm keeps the existing
map exactly).

Which joint coordinates matter (each checked against brute force in
``test/core/test_singularity_nlink.py``).  Joints are 0-based here, ``q_0`` the base
joint; ``phi_a = q_0 + ... + q_a`` the absolute angle of link ``a``.

* Gravity: ``Da = J M^-1 B`` (eq. 4) holds no gravity term (``J`` is kinematic, ``M``
  the inertia), so the map is the same for every gravity vector.
* Base rotation ``q_0``: ``fk(q_0 + a, ...) = Rot(a) fk(q_0, ...)``, so ``J -> Rot(a) J``,
  while ``M`` depends on the differences ``phi_a - phi_b`` only (below), i.e. on
  ``q_1 .. q_{n-1}``.  Hence ``Da -> Rot(a) Da`` and
  ``det(Da Da^T) -> det(Rot(a) Da Da^T Rot(a)^T) = det(Da Da^T)``: the determinant
  condition depends on the relative joint angles ``q_1 .. q_{n-1}`` only, whatever the
  passive set (a passive base joint included).  The map is (n-1)-dimensional and
  evaluated at ``q_0 = 0``.
* Mirror: ``q -> -q`` reflects the arm about the x axis, ``S = diag(1, -1)``:
  ``fk(-q) = S fk(q)``, so ``J(-q) = -S J(q)``, ``M(-q) = M(q)`` (cosines are even),
  ``Da(-q) = -S Da(q)``: every 2 x 2 minor of ``Da`` changes sign and ``det(Da Da^T)``
  does not.  Half of the grid is computed, the other half mirrored.
* The end-effector radius ``|fk(q)|`` depends on ``q_1 .. q_{n-1}`` only, so the
  Cartesian image of a flagged sample is a full circle about the base: the
  semi-singular region is again a union of annuli (:class:`SemiSingularRegion`), and
  :func:`~freejoint_core.singularity.check_path` applies unchanged.

Evaluation in absolute link angles.  With ``phi = S q`` (``S`` lower triangular ones),
``M = S^T M_phi S`` where ``M_phi[a, b] = H_ab cos(phi_a - phi_b)`` (``H_aa = I_a +
m_a c_a^2 + L_a^2 sum_{k>a} m_k``, ``H_ab = L_a (m_b c_b + L_b sum_{k>b} m_k)`` for
``a < b``), and ``J = J_phi S`` with ``J_phi[:, a] = L_a (-sin phi_a, cos phi_a)``.  So
``Da = J_phi M_phi^-1 S^-T B``; with ``W = M_phi^-1 J_phi^T`` (n x 2) the row of
``Da^T = B^T S^-1 W`` for active joint ``k`` is ``W_k - W_{k-1}`` (``W_{-1} = 0``).  ``M_phi`` is
symmetric positive definite: a Cholesky factorisation written over the batch (one numpy
operation per matrix entry, on arrays of sample points) gives ``W``.

Cauchy-Binet: ``det(Da Da^T) = sum_{k<l} D_kl^2`` over the 2 x 2 minors ``D_kl`` of the
2 x r matrix ``Da``, so ``Da`` is singular exactly where every minor vanishes.  For
``r = 2`` there is one minor, ``det(Da)``, and the singular set has codimension 1; for
``r > 2`` it is the common zero set of ``r (r - 1) / 2`` minors (generically codimension
``r - 1``), which a grid rarely hits.  A sample is therefore flagged if
``det(Da Da^T) <= eps_d`` (the paper's criterion) or if it is a corner of a grid cell
in which every minor takes both signs (a common zero may lie in the cell), and the
radius of each flagged sample is widened by a bound on the radius' change over half a
cell, as the 3-link map does.  Conservative as far as each minor's zero surface is flat
on the scale of a cell (a plane through a cell separates its corners), like the 3-link
map's sign-change test; ``test/core/test_singularity_nlink.py`` checks it against a
Newton search of the singular set.  The paper's sampled criterion alone (``cells=False``:
only samples with ``det(Da Da^T) <= eps_d``) misses such curves between samples and is
then no guarantee.

Consequence for redundant arms (``r > 2``): a singular curve in joint space maps to a
whole interval of radii, and for the shipped 4-link example (joint 1 passive) the
curves reach every radius of the arm's reach, so the conservative region is the whole
reach annulus (as for every other choice of one or two passive joints of that arm, 4 deg
map) and no Cartesian path is certified: the paper's region criterion
cannot guarantee a nonsingular path for such an arm, whose configuration at a point is
left to the dynamics (``test/core/test_singularity_nlink.py`` finds a singular
configuration of the nominal 4-link arm at a radius inside its example circle's band).
"""

from dataclasses import dataclass
import math

import numpy as np

from .errors import FreejointValueError
from .singularity import _check_eps, _check_resolution, _region, det_map, EPS_D, semi_singular
from .trajectory import workspace_annulus

MAX_SAMPLES = 1 << 23
"""Default largest number of grid samples of :func:`det_map_nlink` (about 8.4 million:
2 deg for a 4-link arm is 180^3 = 5.8 million)."""

_CHUNK = 1 << 15  # sample points per batch (arrays of this length stay in cache)


def _check_arm(params):
    for name in ('lengths', 'masses', 'inertias', 'com', 'passive'):
        if not hasattr(params, name):
            raise FreejointValueError(
                f'nominal_params: expected ArmParams, got {type(params).__name__}')
    n = len(params.lengths)
    active = [i for i in range(n) if i not in tuple(params.passive)]
    if len(active) < 2:
        raise FreejointValueError(
            f'nominal_params: passive = {tuple(params.passive)} leaves {len(active)} active '
            f'of {n} joints, need at least 2')
    return n, active


def map_joints(nominal_params):
    """
    Return the joints the singularity map runs over: ``(1, ..., n - 1)``.

    ``det(Da Da^T)`` and the end-effector radius do not depend on the base joint
    ``q_0`` (module notes), whatever the passive set.

    Parameters
    ----------
    nominal_params : ArmParams
        The arm (n joints).

    Returns
    -------
    tuple of int
        0-based joint indices.

    """
    n, _ = _check_arm(nominal_params)
    return tuple(range(1, n))


def _inertia_coefficients(params):
    """Return ``H`` (n, n) of ``M_phi[a, b] = H_ab cos(phi_a - phi_b)``."""
    lengths = np.array(params.lengths, dtype=float)
    masses = np.array(params.masses, dtype=float)
    com = np.array(params.com, dtype=float)
    inertias = np.array(params.inertias, dtype=float)
    n = lengths.size
    tail = np.array([masses[a + 1:].sum() for a in range(n)])    # mass beyond link a
    lever = masses * com + lengths * tail
    h = np.diag(inertias + masses * com ** 2 + lengths ** 2 * tail)
    for a in range(n):
        for b in range(a + 1, n):
            h[a, b] = h[b, a] = lengths[a] * lever[b]
    return h


def _minors_chunk(h, lengths, active, q_rel):
    """
    Return the 2 x 2 minors (C, N) of ``Da`` at ``q_0 = 0`` and ``q_1.. = q_rel`` (d, N).

    Batched Cholesky of ``M_phi`` and two triangular solves, one numpy operation per
    matrix entry over the N samples.
    """
    n = lengths.size
    npts = q_rel.shape[1]
    phi = np.zeros((n, npts))
    np.cumsum(q_rel, axis=0, out=phi[1:])
    c, s = np.cos(phi), np.sin(phi)
    chol = [[None] * n for _ in range(n)]
    for j in range(n):
        for i in range(j, n):
            if i == j:
                val = np.full(npts, h[j, j])
            else:
                val = c[i] * c[j]
                val += s[i] * s[j]
                val *= h[i, j]
            for k in range(j):
                val -= chol[i][k] * chol[j][k]
            if i == j:
                chol[j][j] = np.sqrt(val)
            else:
                val /= chol[j][j]
                chol[i][j] = val
    # W = M_phi^-1 J_phi^T, columns x and y: J_phi^T[a] = L_a (-sin phi_a, cos phi_a)
    cols = []
    for rhs in (-lengths[:, None] * s, lengths[:, None] * c):
        z = [None] * n
        for i in range(n):
            val = rhs[i].copy()
            for k in range(i):
                val -= chol[i][k] * z[k]
            z[i] = val / chol[i][i]
        w = [None] * n
        for i in range(n - 1, -1, -1):
            val = z[i]
            for k in range(i + 1, n):
                val = val - chol[k][i] * w[k]
            w[i] = val / chol[i][i]
        cols.append(w)
    wx, wy = cols
    # row k of Da^T = B^T S^-1 W: q_k = phi_k - phi_{k-1}
    dx = [wx[k] - wx[k - 1] if k else wx[0] for k in active]
    dy = [wy[k] - wy[k - 1] if k else wy[0] for k in active]
    r = len(active)
    return np.array([dx[a] * dy[b] - dx[b] * dy[a]
                     for a in range(r) for b in range(a + 1, r)]).reshape(-1, npts)


def decoupling_minors(nominal_params, q_rel):
    """
    2 x 2 minors of the nominal ``Da = J M^-1 B`` at sampled relative joint angles.

    Batched over any set of samples; ``q_0`` is irrelevant (module notes) and taken 0.

    Parameters
    ----------
    nominal_params : ArmParams
        Planar arm, n joints, at least 2 active.
    q_rel : array_like, shape (N, n - 1)
        Joint angles ``q_1 .. q_{n-1}`` (rad) of each sample.

    Returns
    -------
    numpy.ndarray, shape (N, r (r - 1) / 2)
        Minor ``(k, l)`` of the active columns ``k < l`` (in the order
        ``(0, 1), (0, 2), ..., (r - 2, r - 1)``), 1 / (kg^2 m^2); for ``r = 2`` the one
        column is the signed ``det(Da)``. ``det(Da Da^T)`` is the sum of their squares.

    """
    n, active = _check_arm(nominal_params)
    try:
        q = np.asarray(q_rel, dtype=float)
    except (TypeError, ValueError):
        raise FreejointValueError(
            f'q_rel: expected an (N, {n - 1}) array, got {q_rel!r}') from None
    if q.ndim != 2 or q.shape[1] != n - 1:
        raise FreejointValueError(f'q_rel: expected shape (N, {n - 1}), got {q.shape}')
    if not np.all(np.isfinite(q)):
        raise FreejointValueError('q_rel: values must be finite')
    h = _inertia_coefficients(nominal_params)
    lengths = np.array(nominal_params.lengths, dtype=float)
    out = np.empty((q.shape[0], len(active) * (len(active) - 1) // 2))
    for start in range(0, q.shape[0], _CHUNK):
        sl = slice(start, start + _CHUNK)
        out[sl] = _minors_chunk(h, lengths, active, q[sl].T).T
    return out


def decoupling_det(nominal_params, q_rel):
    """
    ``det(Da Da^T)`` of the nominal arm at sampled relative joint angles, batched.

    Parameters
    ----------
    nominal_params : ArmParams
        Planar arm, n joints, at least 2 active.
    q_rel : array_like, shape (N, n - 1)
        Joint angles ``q_1 .. q_{n-1}`` (rad).

    Returns
    -------
    numpy.ndarray, shape (N,)
        ``det(Da Da^T)`` (1 / (kg^4 m^4)), the sum of the squared minors (Cauchy-Binet).

    """
    minors = decoupling_minors(nominal_params, q_rel)
    return np.einsum('ij,ij->i', minors, minors)


def ee_radius_nlink(lengths, q_rel):
    """
    Distance of the end effector from the base (m), batched, independent of ``q_0``.

    Parameters
    ----------
    lengths : sequence of float, shape (n,)
        Link lengths (m).
    q_rel : array_like, shape (N, n - 1)
        Joint angles ``q_1 .. q_{n-1}`` (rad).

    Returns
    -------
    numpy.ndarray, shape (N,)

    """
    lengths = np.asarray(lengths, dtype=float)
    q = np.asarray(q_rel, dtype=float)
    if q.ndim != 2 or q.shape[1] != lengths.size - 1:
        raise FreejointValueError(
            f'q_rel: expected shape (N, {lengths.size - 1}), got {q.shape}')
    phi = np.concatenate((np.zeros((q.shape[0], 1)), np.cumsum(q, axis=1)), axis=1)
    return np.hypot(np.cos(phi) @ lengths, np.sin(phi) @ lengths)


@dataclass(frozen=True)
class NLinkDetMap:
    """
    Grid map of the nominal decoupling determinant over ``q_1 .. q_{n-1}``.

    Attributes
    ----------
    q : numpy.ndarray, shape (k,)
        Grid angles (rad), ``i * resolution`` for ``i = 0 .. k-1`` (``[0, 2 pi)``), on
        every axis.
    det : numpy.ndarray, shape (k,) * (n - 1)
        ``det(Da Da^T)`` at ``(q_1, ..., q_{n-1}) = (q[i_1], ..., q[i_{n-1}])``, any
        ``q_0`` (1 / (kg^4 m^4)).
    minor_negative : numpy.ndarray of bool, shape (r (r - 1) / 2,) + det.shape
        Sign bit of each 2 x 2 minor of ``Da`` (order of :func:`decoupling_minors`).
    resolution_deg, lengths : float, tuple of float
        Grid step (deg) and link lengths (m), as in ``singularity.DetMap``.

    """

    q: np.ndarray
    det: np.ndarray
    minor_negative: np.ndarray
    resolution_deg: float
    lengths: tuple


def det_map_nlink(nominal_params, resolution_deg=2.0, max_samples=MAX_SAMPLES):
    """
    Step 1, any planar arm: sample ``det(Da Da^T)`` over ``q_1 .. q_{n-1}``.

    ``(360 / resolution_deg)^(n-1)`` samples; the half with the first index in
    ``[0, k/2]`` is computed and the rest mirrored (``q -> -q``, module notes).

    Parameters
    ----------
    nominal_params : ArmParams
        Nominal arm, n >= 2 joints, at least 2 active.
    resolution_deg : float
        Grid step (deg), ``360 / resolution_deg`` an even integer.
    max_samples : int
        Refuse a grid of more samples (memory and time: about 0.1-0.5 us a sample).

    Returns
    -------
    NLinkDetMap

    Raises
    ------
    FreejointValueError
        Naming ``nominal_params``, ``resolution_deg`` or ``max_samples``.

    """
    n, active = _check_arm(nominal_params)
    res, k = _check_resolution(resolution_deg)
    dims = n - 1
    try:
        limit = int(max_samples)
    except (TypeError, ValueError):
        raise FreejointValueError(
            f'max_samples: expected an integer, got {max_samples!r}') from None
    if limit < 1:
        raise FreejointValueError(f'max_samples: expected >= 1, got {limit}')
    total = k ** dims
    if total > limit:
        finest = 360.0 / math.floor(limit ** (1.0 / dims))
        raise FreejointValueError(
            f'resolution_deg: {res:g} deg gives {k}^{dims} = {total} samples for the '
            f'{n}-link arm (joints 2..{n}), above {limit}; use a coarser step '
            f'(>= {finest:.3g} deg, 360 / step an even integer)')
    q = np.arange(k) * (2.0 * math.pi / k)
    half = k // 2 + 1
    nminor = len(active) * (len(active) - 1) // 2
    shape = (k,) * dims
    det = np.empty(shape)
    neg = np.empty((nminor,) + shape, dtype=bool)
    top_shape = (half,) + (k,) * (dims - 1)
    top_det = det[:half].reshape(-1)                      # views of the computed half
    top_neg = [neg[m, :half].reshape(-1) for m in range(nminor)]
    h = _inertia_coefficients(nominal_params)
    lengths = np.array(nominal_params.lengths, dtype=float)
    for start in range(0, top_det.size, _CHUNK):
        sl = slice(start, min(start + _CHUNK, top_det.size))
        flat = np.arange(sl.start, sl.stop)
        q_rel = q[np.array(np.unravel_index(flat, top_shape))]          # (dims, N)
        minors = _minors_chunk(h, lengths, active, q_rel)              # (C, N)
        top_det[sl] = np.einsum('ij,ij->j', minors, minors)
        for m in range(nminor):
            np.signbit(minors[m], out=top_neg[m][sl])
    if half < k:
        # row i (i > k/2) is the mirror of row k - i: every other index j -> (k - j) % k
        rows = k - np.arange(half, k)
        mirror = (-np.arange(k)) % k
        src = det[rows]
        sneg = ~neg[:, rows]                      # minors are odd under the mirror
        for axis in range(1, dims):
            src = np.take(src, mirror, axis=axis)
            sneg = np.take(sneg, mirror, axis=axis + 1)
        det[half:] = src
        neg[:, half:] = sneg
    for arr in (q, det, neg):
        arr.flags.writeable = False
    return NLinkDetMap(q=q, det=det, minor_negative=neg, resolution_deg=res,
                       lengths=tuple(float(v) for v in nominal_params.lengths))


def _cell_any(mask, dims):
    """``out[i] = any(mask[i + o])`` over the cell corners ``o`` in {0, 1}^dims (periodic)."""
    out = mask
    for axis in range(dims):
        out = out | np.roll(out, -1, axis=axis)
    return out


def _cell_corners(mask, dims):
    """Flag every corner of the cells flagged in ``mask`` (periodic)."""
    out = mask
    for axis in range(dims):
        out = out | np.roll(out, 1, axis=axis)
    return out


def semi_singular_nlink(det_map, eps_d=EPS_D, cells=True):
    """
    Step 2, any planar arm: the semi-singular region (union of annuli about the base).

    A sample is flagged if ``det(Da Da^T) <= eps_d`` or (``cells``) if it is a corner of
    a grid cell where every 2 x 2 minor of ``Da`` takes both signs (module notes).  The radius
    of each flagged sample is widened by ``dq / 2 * sum_{k>=1} sum_{a>=k} L_a`` (a bound
    on ``sum_k |dr/dq_k|`` times half a step), merged and clipped to the reach annulus.

    Parameters
    ----------
    det_map : NLinkDetMap
        From :func:`det_map_nlink`.
    eps_d : float
        Criterion (> 0) on ``det(Da Da^T)``; the paper uses 1e-7.
    cells : bool
        True (default): also flag the cells where every minor changes sign, a
        conservative region; False: the paper's sampled criterion alone, which misses
        singular sets thinner than the grid (no guarantee, for comparison).

    Returns
    -------
    SemiSingularRegion
        ``singular_mask`` has the map's shape (n - 1 axes).

    """
    if not isinstance(det_map, NLinkDetMap):
        raise FreejointValueError(
            f'det_map: expected NLinkDetMap, got {type(det_map).__name__}')
    eps = _check_eps(eps_d)
    dims = det_map.det.ndim
    mask = det_map.det <= eps
    if cells:
        straddle = np.ones(det_map.det.shape, dtype=bool)
        for neg in det_map.minor_negative:
            straddle &= _cell_any(neg, dims) & _cell_any(~neg, dims)
        mask |= _cell_corners(straddle, dims)
    idx = np.nonzero(mask)
    q_rel = np.stack([det_map.q[i] for i in idx], axis=1)
    radii = ee_radius_nlink(det_map.lengths, q_rel)
    reach = workspace_annulus(det_map.lengths)
    lengths = np.array(det_map.lengths)
    levers = np.cumsum(lengths[::-1])[::-1]          # sum_{a >= k} L_a
    dq = math.radians(det_map.resolution_deg)
    widen = float(levers[1:].sum()) * dq / 2.0
    return _region(radii, widen, float(levers[1]) * dq, reach, eps, det_map.resolution_deg,
                   mask)


def uses_closed_map(nominal_params):
    """Return True if :func:`arm_region` takes the 3-link (q2, q3) map of ``singularity``."""
    _check_arm(nominal_params)
    return len(nominal_params.lengths) == 3 and len(tuple(nominal_params.passive)) == 1


def arm_region(nominal_params, resolution_deg=1.0, eps_d=EPS_D, max_samples=MAX_SAMPLES,
               cells=True):
    """
    Return the semi-singular region of any planar arm's nominal model (steps 1-2).

    A 3-link arm with one passive joint takes
    ``singularity.semi_singular(singularity.det_map(nominal_params, resolution_deg),
    eps_d)`` (the closed form for the paper's arm, byte for byte the same region);
    any other arm the general batched map :func:`det_map_nlink` /
    :func:`semi_singular_nlink` over ``q_1 .. q_{n-1}``.  Either result goes to
    ``singularity.check_path``.

    Parameters
    ----------
    nominal_params : ArmParams
        Nominal arm (``ArmParams``, e.g. ``UrdfArm.nominal(0.7)``).
    resolution_deg : float
        Grid step (deg), ``360 / resolution_deg`` an even integer.
    eps_d : float
        Criterion on ``det(Da Da^T)`` (paper: 1e-7).
    max_samples : int
        Largest general grid (see :func:`det_map_nlink`), unused on the 3-link map.
    cells : bool
        The general path's cell test (see :func:`semi_singular_nlink`), unused on the
        3-link map.

    Returns
    -------
    SemiSingularRegion

    """
    if uses_closed_map(nominal_params):
        return semi_singular(det_map(nominal_params, resolution_deg), eps_d)
    return semi_singular_nlink(det_map_nlink(nominal_params, resolution_deg, max_samples),
                               eps_d, cells)
