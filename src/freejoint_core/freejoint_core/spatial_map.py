"""
Sampled singularity map of a spatial arm's workspace.

A grid over the joints is out of reach for 6-7 joints (the Panda at 2 deg: about 4e12
postures), so the map samples: ``samples`` postures drawn uniformly within the URDF
position limits of every chain joint, and per posture the tip position and the scale-free
conditioning ``kappa`` of :func:`freejoint_core.spatial_law.task_conditioning` on the
nominal model (``scale``, 0.7 as the controller's; ``m = 3`` unless asked 6).  It sums up

* the share of samples with ``kappa < kappa_min`` (the law's threshold, 1e-3: there the
  tick damps its inverse and reports ``STATUS_NEAR_SINGULAR``);
* the quantiles of ``kappa``, from a histogram of ``log10 kappa`` (200 bins a decade,
  ``1e-16 .. 1``): a quantile to within one bin, 1.2 %;
* a voxel map of the tip positions (cubes of side ``voxel`` [m], voxel ``i`` covering
  ``[i voxel, (i + 1) voxel)`` on each axis, root frame): per voxel the samples, those
  below ``kappa_min``, the smallest ``kappa`` and the sample that has it: where in the
  workspace the arm can be near-singular, and in which posture (:func:`posture`).

Chunks.  Sample ``j`` of chunk ``c`` is row ``j`` of
``default_rng([seed, c]).uniform(lower, upper, (size_c, n))``, the global sample index
``c chunk + j``: a chunk is a function of the arm, the seed, its index and the chunk
size, so chunks run anywhere (worker processes, Ray: ``freejoint_tools.spatial_map``)
in any order.  Maps merge exactly (:func:`merge`): counts add, the smallest ``kappa``
per voxel is kept with the smallest sample index among equal values, the histogram adds;
no floating-point sum, so the map does not depend on how the chunks were spread over
workers nor on the order they came back in.  Memory is one chunk's arrays (1-2 KB a
sample: 10-20 MB for the default 10^4) plus the voxels (about 30 000 of 5 cm for the UR5
or the Panda).

Per sample: Pinocchio's ``computeMinverse`` and ``computeFrameJacobian`` (the tip
placement comes with it), then over the whole chunk at once ``Da = (J M^-1)[:, a]`` and
``(M^-1)[a, a] = C C^T`` (Cholesky); ``Da M~aa Da^T = Y^T Y`` with ``Y = C^-1 Da^T``, so
``kappa`` is the ratio of the smallest to the largest singular value of
``Y diag(ds)`` (``ds`` the position rows over the reach ``L``, as ``task_conditioning``).
The same quantity as the law's (eigenvalues of ``A``), from its square root: round-off
about ``eps / kappa`` relative instead of ``eps / kappa^2`` (tested against the law's
``terms`` + ``decoupling`` + ``task_conditioning`` to 1e-9 where ``kappa >= 1e-3``).
Cost per sample, against the law's per-tick path: docs/performance.md, "Spatial arms:
singularity map".
"""

from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
import functools
import hashlib
import itertools
import json
import math
import multiprocessing
import os

from freejoint_core.arm import NOMINAL_SCALE
from freejoint_core.errors import FreejointValueError
from freejoint_core.spatial_law import arm_reach, SpatialGains
from freejoint_core.spatial_model import KNOWN_ARMS, robot_data_dir, SpatialArm
import numpy as np
import pinocchio as pin

KAPPA_MIN = SpatialGains().kappa_min
"""Default threshold: the law's ``kappa_min`` (1e-3)."""
DEFAULT_CHUNK = 10000
"""Samples per chunk (the unit of a worker's task; 10-20 MB of arrays)."""
MAX_CHUNK = 1000000
DEFAULT_VOXEL = 0.05
"""Voxel side [m]."""
MAX_SAMPLES = 10 ** 12
BINS_PER_DECADE = 200
DECADES = 16
"""The histogram of ``log10 kappa`` covers ``1e-16 .. 1`` (smaller values in the first bin)."""
NBINS = BINS_PER_DECADE * DECADES
_OFFSET = 1 << 20          # voxel index range: |i| < 2^20 on each axis (keys of 63 bits)
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def _integer(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise FreejointValueError(f'{name}: expected an integer, got {value!r}')
    value = int(value)
    if not lo <= value <= hi:
        raise FreejointValueError(f'{name}: expected {lo} .. {hi}, got {value}')
    return value


def _positive(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a number, got {value!r}') from None
    if isinstance(value, bool) or not (math.isfinite(v) and v > 0.0):
        raise FreejointValueError(f'{name}: must be finite and > 0, got {value!r}')
    return v


@functools.lru_cache(maxsize=8)
def _arm(urdf, base_link, tip_link, passive, m, scale):
    """Return (nominal SpatialArm, reach L [m], bound on |tip| [m]) of one arm (cached)."""
    arm = SpatialArm(urdf, base_link, tip_link, passive, m, scale)
    reach = arm_reach(arm)
    pin.framesForwardKinematics(arm.model, arm.data, np.zeros(arm.n))
    origin = float(np.linalg.norm(arm.data.oMi[1].translation))
    return arm, reach, origin + reach


@dataclass(frozen=True)
class MapSpec:
    """
    What a map samples: the arm, the sampling and the summary's parameters.

    Every field is checked when the spec is made (the arm is built from the URDF then).

    Attributes
    ----------
    urdf : str
        URDF text (carried to the workers; not in ``repr``).
    base_link, tip_link : str
        Links bounding the chain.
    passive : tuple of str
        Free joints.
    samples : int
        Postures sampled, 1 .. 1e12.
    seed : int
        Seed of the sampling, >= 0.
    chunk : int
        Samples per chunk, 1 .. 1e6 (part of the sampling: another chunk size draws
        other postures).
    voxel : float
        Voxel side [m], > 0 (at least 1e-6 of the arm's reach).
    m : {3, 6}
        Task rows of ``kappa``: tip position, or position and orientation.
    scale : float
        Nominal model factor on masses, inertias and COM levers, > 0 (the controller's
        0.7 by default).
    kappa_min : float
        Threshold of the near-singular share, in (0, 1).
    name : str
        Label of the arm (``'ur5'``, ``'panda'``, or the URDF's file name).

    """

    urdf: str = field(repr=False)
    base_link: str
    tip_link: str
    passive: tuple
    samples: int
    seed: int = 0
    chunk: int = DEFAULT_CHUNK
    voxel: float = DEFAULT_VOXEL
    m: int = 3
    scale: float = NOMINAL_SCALE
    kappa_min: float = KAPPA_MIN
    name: str = ''

    def __post_init__(self):
        """Check every field; build the arm once (cached per process)."""
        if isinstance(self.passive, str):
            raise FreejointValueError(
                f'passive: expected a list of joint names, got {self.passive!r}')
        object.__setattr__(self, 'passive', tuple(self.passive))
        object.__setattr__(self, 'samples', _integer('samples', self.samples, 1, MAX_SAMPLES))
        object.__setattr__(self, 'seed', _integer('seed', self.seed, 0, 2 ** 63 - 1))
        object.__setattr__(self, 'chunk', _integer('chunk', self.chunk, 1, MAX_CHUNK))
        object.__setattr__(self, 'voxel', _positive('voxel', self.voxel))
        object.__setattr__(self, 'scale', _positive('scale', self.scale))
        kmin = _positive('kappa_min', self.kappa_min)
        if kmin >= 1.0:
            raise FreejointValueError(f'kappa_min: must be < 1, got {self.kappa_min!r}')
        object.__setattr__(self, 'kappa_min', kmin)
        if self.m not in (3, 6) or isinstance(self.m, bool):
            raise FreejointValueError(f'm: expected 3 or 6, got {self.m!r}')
        arm, _, bound = self._model()
        for name, lo, hi in zip(arm.joint_names, arm.lower, arm.upper):
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise FreejointValueError(f'urdf: joint {name!r} has no position range to '
                                          f'sample within (lower {lo:g}, upper {hi:g})')
        if bound / self.voxel >= _OFFSET - 2:
            raise FreejointValueError(
                f'voxel: {self.voxel!r} m is too small for an arm reaching {bound:.3g} m '
                f'(at least {bound / (_OFFSET - 2):.3g} m)')

    def _model(self):
        return _arm(self.urdf, self.base_link, self.tip_link, self.passive, self.m,
                    self.scale)

    @property
    def arm(self):
        """Return the nominal :class:`SpatialArm` the map evaluates (cached)."""
        return self._model()[0]

    @property
    def reach(self):
        """Return the length scale ``L`` of ``kappa`` [m] (``arm_reach``)."""
        return self._model()[1]

    @property
    def chunks(self):
        """Return the number of chunks."""
        return -(-self.samples // self.chunk)

    def chunk_size(self, index):
        """Return the samples of chunk ``index`` (the last one may be short)."""
        index = _integer('index', index, 0, self.chunks - 1)
        return min(self.chunk, self.samples - index * self.chunk)

    def meta(self):
        """Return the spec as a JSON-able dict (the URDF's text included)."""
        return {'name': self.name, 'urdf': self.urdf, 'base_link': self.base_link,
                'tip_link': self.tip_link, 'passive': list(self.passive),
                'samples': self.samples, 'seed': self.seed, 'chunk': self.chunk,
                'voxel': self.voxel, 'm': self.m, 'scale': self.scale,
                'kappa_min': self.kappa_min}

    def key(self):
        """Return what two maps must share to merge: everything but ``samples``."""
        meta = self.meta()
        meta['urdf'] = hashlib.sha256(self.urdf.encode()).hexdigest()
        del meta['samples']
        return json.dumps(meta, sort_keys=True)


def known_spec(name, passive=(), samples=100000, **kwargs):
    """
    Return the :class:`MapSpec` of one of the arms of example-robot-data.

    Parameters
    ----------
    name : {'ur5', 'panda'}
        The arm (``spatial_model.KNOWN_ARMS``: URDF, base and tip link).
    passive : sequence of str
        Free joints.
    samples : int
        Postures sampled.
    **kwargs
        Other fields of :class:`MapSpec` (seed, chunk, voxel, m, scale, kappa_min).

    Returns
    -------
    MapSpec

    """
    if name not in KNOWN_ARMS:
        raise FreejointValueError(f'name: expected one of {sorted(KNOWN_ARMS)}, got {name!r}')
    if isinstance(passive, str):
        raise FreejointValueError(f'passive: expected a list of joint names, got {passive!r}')
    path, base, tip = KNOWN_ARMS[name]
    with open(os.path.join(robot_data_dir(), path), encoding='utf-8') as fh:
        text = fh.read()
    return MapSpec(text, base, tip, tuple(passive), samples, name=name, **kwargs)


def postures(spec, index):
    """
    Return the joint angles of the samples of chunk ``index`` (module notes).

    Parameters
    ----------
    spec : MapSpec
        The map.
    index : int
        Chunk, ``0 .. spec.chunks - 1``.

    Returns
    -------
    numpy.ndarray, (spec.chunk_size(index), n)
        [rad], uniform within each chain joint's URDF position limits.

    """
    size = spec.chunk_size(index)
    arm = spec.arm
    rng = np.random.default_rng([spec.seed, int(index)])
    return rng.uniform(arm.lower, arm.upper, (size, arm.n))


def posture(spec, sample):
    """
    Return the joint angles of one sample of the map (e.g. a voxel's ``worst``), (n,) [rad].

    Parameters
    ----------
    spec : MapSpec
        The map.
    sample : int
        Global sample index, ``0 .. spec.samples - 1``.

    """
    sample = _integer('sample', sample, 0, spec.samples - 1)
    index, row = divmod(sample, spec.chunk)
    arm = spec.arm
    rng = np.random.default_rng([spec.seed, index])
    return rng.uniform(arm.lower, arm.upper, (row + 1, arm.n))[row]


def evaluate(spec, q):
    """
    Return the tip positions and ``kappa`` of postures (module notes).

    Parameters
    ----------
    spec : MapSpec
        Arm, task rows and nominal model.
    q : array_like, (k, n)
        Joint angles [rad], finite.

    Returns
    -------
    p : numpy.ndarray, (k, 3)
        Tip positions [m] (root frame).
    kappa : numpy.ndarray, (k,)
        In [0, 1].

    Raises
    ------
    FreejointValueError
        ``q`` of the wrong shape or not finite.

    """
    arm, reach, _ = spec._model()
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != arm.n or not np.all(np.isfinite(q)):
        raise FreejointValueError(
            f'q: expected (k, {arm.n}) finite joint angles, got shape {q.shape}')
    k, n, m = len(q), arm.n, arm.m
    minv = np.empty((k, n, n))
    jac = np.empty((k, m, n))
    p = np.empty((k, 3))
    model, data, frame = arm.model, arm.data, arm.frame
    for i in range(k):
        minv[i] = pin.computeMinverse(model, data, q[i])
        jac[i] = pin.computeFrameJacobian(model, data, q[i], frame, _LWA)[:m]
        p[i] = data.oMf[frame].translation
    ia = np.array(arm.active)
    da_t = np.swapaxes((jac @ minv)[:, :, ia], 1, 2)           # (k, r, m)
    ds = np.full(m, 1.0 / reach)
    ds[3:] = 1.0
    try:
        chol = np.linalg.cholesky(minv[:, ia][:, :, ia])      # (M^-1)[a, a] = C C^T
    except np.linalg.LinAlgError:
        raise FreejointValueError('urdf: the inertia matrix of the chain is not positive '
                                  'definite at some posture') from None
    y = np.linalg.solve(chol, da_t * ds)                       # C^-1 Da^T Ds, (k, r, m)
    sv = np.linalg.svd(y, compute_uv=False)                    # descending, (k, m)
    top = sv[:, 0]
    kappa = np.divide(sv[:, -1], top, out=np.zeros(k), where=top > 0.0)
    return p, kappa


@dataclass(frozen=True)
class SingularityMap:
    """
    A sampled singularity map, or the part of one that some chunks make (module notes).

    Attributes
    ----------
    spec : MapSpec
        What was sampled (``samples``: the whole map's).
    samples : int
        Samples in this map.
    near : int
        Samples with ``kappa < spec.kappa_min``.
    hist : numpy.ndarray of int64, (NBINS,)
        Samples per bin of ``log10 kappa`` (bin ``b``: ``[-16 + b / 200, -16 + (b + 1) / 200)``;
        smaller values in bin 0).
    kappa_max : float
        Largest ``kappa`` (-inf if empty).
    voxels : numpy.ndarray of int64, (V, 3)
        Voxel indices ``floor(p / voxel)``, sorted (x, then y, then z).
    count, near_count : numpy.ndarray of int64, (V,)
        Samples per voxel, and those below ``kappa_min``.
    kappa_low : numpy.ndarray, (V,)
        Smallest ``kappa`` per voxel.
    worst : numpy.ndarray of int64, (V,)
        Global index of the sample that has it (the smallest of equal ones; its posture:
        :func:`posture`).

    """

    spec: MapSpec
    samples: int
    near: int
    hist: np.ndarray
    kappa_max: float
    voxels: np.ndarray
    count: np.ndarray
    near_count: np.ndarray
    kappa_low: np.ndarray
    worst: np.ndarray

    @property
    def share_near(self):
        """Return the share of samples with ``kappa < kappa_min``, in [0, 1]."""
        return self.near / self.samples if self.samples else 0.0

    def minimum(self):
        """Return ``(kappa, sample index)`` of the smallest ``kappa`` of the map."""
        if not len(self.kappa_low):
            raise FreejointValueError('map: empty')
        order = np.lexsort((self.worst, self.kappa_low))
        return float(self.kappa_low[order[0]]), int(self.worst[order[0]])

    def quantiles(self, qs):
        """
        Return the quantiles of ``kappa`` from the histogram (to within one bin, 1.2 %).

        The quantile ``q`` lies in the bin of the ``ceil(q N)``-th smallest ``kappa`` of
        the ``N`` samples; within it, it is interpolated geometrically.

        Parameters
        ----------
        qs : array_like, (k,)
            Probabilities in [0, 1].

        Returns
        -------
        numpy.ndarray, (k,)
            Geometric interpolation within the bin the quantile falls in, clipped to the
            map's smallest and largest ``kappa``.

        """
        qs = np.atleast_1d(np.asarray(qs, dtype=float))
        if not np.all((qs >= 0.0) & (qs <= 1.0)):
            raise FreejointValueError(f'qs: expected probabilities in [0, 1], got {qs!r}')
        if not self.samples:
            raise FreejointValueError('map: empty')
        cum = np.cumsum(self.hist)
        target = qs * self.samples
        b = np.minimum(np.searchsorted(cum, target), NBINS - 1)
        below = np.where(b > 0, cum[b - 1], 0)
        frac = np.clip((target - below) / np.maximum(self.hist[b], 1), 0.0, 1.0)
        value = 10.0 ** (-DECADES + (b + frac) / BINS_PER_DECADE)
        return np.clip(value, self.minimum()[0], self.kappa_max)

    def voxel_of(self, p):
        """Return the voxel index ``floor(p / voxel)`` (3,) of a point ``p`` (3,) [m]."""
        p = np.asarray(p, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise FreejointValueError(f'p: expected 3 finite numbers, got {p!r}')
        return np.floor(p / self.spec.voxel).astype(np.int64)

    def at(self, p):
        """
        Return the map's entry of the voxel that holds a point.

        Parameters
        ----------
        p : array_like, (3,)
            Point [m], root frame.

        Returns
        -------
        dict or None
            ``voxel`` (3,), ``centre`` (3,) [m], ``count``, ``near_count``, ``kappa_low``,
            ``worst``; None if no sample fell in that voxel.

        """
        idx = self.voxel_of(p)
        hit = np.flatnonzero(np.all(self.voxels == idx, axis=1))
        if not len(hit):
            return None
        i = hit[0]
        return {'voxel': idx, 'centre': (idx + 0.5) * self.spec.voxel,
                'count': int(self.count[i]), 'near_count': int(self.near_count[i]),
                'kappa_low': float(self.kappa_low[i]), 'worst': int(self.worst[i])}

    def summary(self, top=5):
        """Return the map's summary: lines of text (module notes)."""
        s = self.spec
        free = ', '.join(s.passive) or 'none'
        lines = [f'singularity map {s.name or "arm"} (free: {free}), m = {s.m}, nominal '
                 f'{s.scale:g}, {self.samples} samples (seed {s.seed}, chunks of {s.chunk})']
        if not self.samples:
            return lines
        nv = int(np.count_nonzero(self.near_count))
        lines.append(f'kappa < {s.kappa_min:g}: {self.share_near:.3%} of the samples '
                     f'({self.near}), in {nv} of {len(self.count)} voxels of {s.voxel:g} m')
        probs = (0.001, 0.01, 0.05, 0.5, 0.95)
        vals = self.quantiles(probs)
        lines.append('kappa quantiles (to 1.2 %): ' + ', '.join(
            f'{100 * p:g} % {v:.3g}' for p, v in zip(probs, vals)))
        kmin, worst = self.minimum()
        q = posture(s, worst)
        p = evaluate(s, q[None])[0][0]
        lines.append(f'smallest kappa {kmin:.3g} (sample {worst}): tip '
                     f'{np.array2string(p, precision=3)} m, q '
                     f'{np.array2string(q, precision=3)} rad')
        if top and nv:
            share = self.near_count / self.count
            order = np.lexsort((self.worst, self.kappa_low, -share))[:top]
            lines.append(f'voxels with the largest near-singular share (centre [m]: '
                         f'near / samples, smallest kappa), top {min(top, nv)}:')
            for i in order[:nv]:
                c = (self.voxels[i] + 0.5) * s.voxel
                lines.append(f'  {np.array2string(c, precision=3)}: {self.near_count[i]} / '
                             f'{self.count[i]}, {self.kappa_low[i]:.3g}')
        return lines

    def save(self, path):
        """Write the map to ``path`` (numpy ``.npz``; the spec as JSON, no pickle)."""
        meta = self.spec.meta()
        meta.update(map_samples=self.samples, near=self.near, kappa_max=self.kappa_max)
        np.savez_compressed(path, meta=np.array(json.dumps(meta)), hist=self.hist,
                            voxels=self.voxels, count=self.count, near_count=self.near_count,
                            kappa_low=self.kappa_low, worst=self.worst)


def load(path):
    """
    Return the map read from a file written by :meth:`SingularityMap.save`.

    Parameters
    ----------
    path : str
        ``.npz`` file.

    Returns
    -------
    SingularityMap

    """
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z['meta']))
            arrays = {k: z[k] for k in ('hist', 'voxels', 'count', 'near_count', 'kappa_low',
                                        'worst')}
    except (OSError, KeyError, ValueError) as exc:
        raise FreejointValueError(f'path: {path!r} is not a singularity map ({exc})') from None
    spec = MapSpec(**{k: meta[k] for k in (
        'urdf', 'base_link', 'tip_link', 'passive', 'samples', 'seed', 'chunk', 'voxel', 'm',
        'scale', 'kappa_min', 'name')})
    return SingularityMap(spec, meta['map_samples'], meta['near'], kappa_max=meta['kappa_max'],
                          **arrays)


def _voxel_reduce(keys, kappa, index):
    """
    Group entries by voxel key: the smallest ``kappa`` per key, ties to the smallest index.

    Returns the keys, their smallest ``kappa`` and its index, the start of each group in
    the sorted order, and that order (to add counts with ``np.add.reduceat``).
    """
    order = np.lexsort((index, kappa, keys))
    keys, kappa, index = keys[order], kappa[order], index[order]
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]]) if len(keys) else \
        np.zeros(0, dtype=np.int64)
    return keys[starts], kappa[starts], index[starts], starts, order


def _keys(voxels):
    v = voxels + _OFFSET
    return (v[:, 0] << 42) | (v[:, 1] << 21) | v[:, 2]


def _unkeys(keys):
    mask = (1 << 21) - 1
    return np.stack([(keys >> 42) & mask, (keys >> 21) & mask, keys & mask], axis=1) - _OFFSET


def empty(spec):
    """Return the map of no sample (the start of a merge)."""
    z = np.zeros(0, dtype=np.int64)
    return SingularityMap(spec, 0, 0, np.zeros(NBINS, dtype=np.int64), -math.inf,
                          np.zeros((0, 3), dtype=np.int64), z, z, np.zeros(0), z)


def map_of(spec, q, first=0):
    """
    Return the map of given postures (a chunk's, or any: e.g. the postures of a plan).

    Parameters
    ----------
    spec : MapSpec
        The map they belong to.
    q : array_like, (k, n)
        Joint angles [rad].
    first : int
        Sample index of the first posture (the others follow), >= 0.

    Returns
    -------
    SingularityMap
        Of ``k`` samples.

    """
    first = _integer('first', first, 0, 2 ** 62)
    p, kappa = evaluate(spec, q)
    if not np.all(np.isfinite(kappa)):
        raise FreejointValueError('q: kappa is not finite at some posture')
    k = len(kappa)
    vox = np.floor(p / spec.voxel).astype(np.int64)
    index = np.arange(first, first + k, dtype=np.int64)
    near = kappa < spec.kappa_min
    keys, low, worst, starts, order = _voxel_reduce(_keys(vox), kappa, index)
    count = np.diff(np.r_[starts, k]).astype(np.int64)
    near_count = np.add.reduceat(near[order].astype(np.int64), starts) if k else \
        np.zeros(0, dtype=np.int64)
    with np.errstate(divide='ignore'):
        b = np.floor((np.log10(kappa) + DECADES) * BINS_PER_DECADE)
    b = np.clip(np.nan_to_num(b, neginf=0.0), 0, NBINS - 1).astype(np.int64)
    hist = np.bincount(b, minlength=NBINS).astype(np.int64)
    return SingularityMap(spec, k, int(near.sum()), hist,
                          float(kappa.max()) if k else -math.inf, _unkeys(keys), count,
                          near_count, low, worst)


def map_chunk(spec, index):
    """Return the map of chunk ``index`` of ``spec`` (:func:`postures`, :func:`map_of`)."""
    return map_of(spec, postures(spec, index), int(index) * spec.chunk)


def merge(maps):
    """
    Merge maps of the same spec exactly (module notes); the order does not matter.

    Parameters
    ----------
    maps : sequence of SingularityMap
        Maps of disjoint samples (chunks run once each).

    Returns
    -------
    SingularityMap

    Raises
    ------
    FreejointValueError
        ``maps: ...`` if empty or of different specs.

    """
    maps = list(maps)
    if not maps:
        raise FreejointValueError('maps: nothing to merge')
    spec = maps[0].spec
    key = spec.key()
    for mp in maps[1:]:
        if mp.spec.key() != key:
            raise FreejointValueError('maps: of different arms or sampling (spec), cannot '
                                      'merge')
    keys = np.concatenate([_keys(mp.voxels) for mp in maps])
    low = np.concatenate([mp.kappa_low for mp in maps])
    worst = np.concatenate([mp.worst for mp in maps])
    count = np.concatenate([mp.count for mp in maps])
    ncount = np.concatenate([mp.near_count for mp in maps])
    ukeys, ulow, uworst, starts, order = _voxel_reduce(keys, low, worst)
    if len(keys):
        count = np.add.reduceat(count[order], starts)
        ncount = np.add.reduceat(ncount[order], starts)
    return SingularityMap(spec, sum(mp.samples for mp in maps), sum(mp.near for mp in maps),
                          np.sum([mp.hist for mp in maps], axis=0).astype(np.int64),
                          max(mp.kappa_max for mp in maps), _unkeys(ukeys),
                          count.astype(np.int64), ncount.astype(np.int64), ulow, uworst)


def compute_map(spec, workers=1, progress=None):
    """
    Compute the whole map in this process, or in worker processes.

    Parameters
    ----------
    spec : MapSpec
        The map.
    workers : int
        1: the chunks one after the other here; more: that many worker processes (spawned)
        taking one chunk at a time.  The map is the same (module notes).
    progress : callable, optional
        Called with the samples done so far after each chunk.

    Returns
    -------
    SingularityMap

    """
    workers = _integer('workers', workers, 1, 1024)
    total = empty(spec)
    done = 0
    if workers == 1:
        for index in range(spec.chunks):
            total = merge([total, map_chunk(spec, index)])
            done += spec.chunk_size(index)
            if progress:
                progress(done)
        return total
    ctx = multiprocessing.get_context('spawn')
    todo = iter(range(spec.chunks))
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        # at most two chunks a worker in flight: memory stays that of a few chunks
        pending = {pool.submit(map_chunk, spec, i) for i in itertools.islice(todo, 2 * workers)}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                part = fut.result()
                total = merge([total, part])
                done += part.samples
                if progress:
                    progress(done)
                pending |= {pool.submit(map_chunk, spec, i) for i in itertools.islice(todo, 1)}
    return total
