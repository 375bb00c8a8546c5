"""
Batched closed-loop simulator: many runs of the paper's 3-link arm advanced together.

Every run is the offline runner's loop (``freejoint_core.offline``, module notes:
tick ``k``, controller on the state of ``t_k``, RK4 plant over ``[t_k, t_{k+1}]``,
the same divergence rule) with a few uncertainty axes a robustness campaign
varies per run (issue 24).  Everything is a numpy array over the runs; the arm
is Table I's (three links, joint 3 passive) or, with ``arms``, another 3-link arm whose
joint 3 alone is passive (a URDF arm's ``ArmParams``), the law the paper's fast path
(``control.RobustController._step_fast``), the plant ``plant.Plant`` (fast3 RK4).

Per-run inputs (:data:`RUN_FIELDS`), each a 1-D array over the runs:

* ``vertical`` (bool): Case 2 (gravity 9.81 m/s^2) instead of Case 1 (with ``arms``:
  the arm ``arms[True]`` instead of ``arms[False]``);
* ``scale_mass``, ``scale_inertia``, ``scale_lc``: the nominal model's masses,
  inertias and COM distances are the real ones times these (lengths exact);
* ``dist_bound`` [N m] and ``dist_type``: 0 ``uniform`` (the plant's: each
  period ``numpy.random.default_rng(seed).uniform(-b, b, 3)``, the same stream
  as ``plant.Plant``), 1 ``constant`` (one such draw at the start, held);
* ``noise_q`` [rad], ``noise_qd`` [rad/s]: standard deviation of Gaussian
  measurement noise added to the state the controller sees (every joint, every
  tick; the error is still the true ``p(t_k) - p_d(t_k)``); generators
  ``default_rng([24, 1, seed])`` and ``default_rng([24, 2, seed])``, three
  ``standard_normal`` draws per tick;
* ``noise_tau`` [N m]: Gaussian noise on the applied active torques
  (``default_rng([24, 3, seed])``, two draws per tick; the recorded torque is the
  commanded one);
* ``delay`` (int, ticks): the command of tick ``k`` acts over
  ``[t_{k+m}, t_{k+m+1}]``, the command of tick 0 before (as ``run_case``'s
  ``delay_ticks`` without predictor);
* ``lag`` [s]: first-order actuator, ``u_k = u_{k-1} + a (c_k - u_{k-1})``,
  ``a = 1 - exp(-dt / lag)``, ``u_{-1} = c_0`` (no start transient), ``c_k`` the
  (delayed) command; 0 disables it;
* ``q3_0_deg``: initial passive angle (deg), ``q1, q2`` by ``offline.initial_state``;
* ``seed`` (int >= 0).

Applied torque at tick ``k``: ``u_k + torque noise``, with the disturbance, held
over the period.  With every axis off (``noise_* = 0``, ``delay = 0``,
``lag = 0``, ``dist_type`` uniform) a run is ``offline.run_case(case, 'robust',
seed, nominal_scale=s, dist_bound=b, q3_0_deg=...)`` (equal scales ``s``);
:func:`run_scalar` is the per-run reference built from the same components
(``Plant``, the registered law) and :func:`simulate` equals it to round-off
(tests: ``test/core/test_batch.py``).
"""

from concurrent.futures import ThreadPoolExecutor
import math
import os

import numpy as np

from .arm import ArmParams, table1
from .control import Gains
from .errors import FreejointValueError
from .laws import make_law
from .offline import _BLOWUP, DEFAULT_DT, initial_state
from .plant import DEFAULT_DT_SUB, Plant
from .trajectory import CircleQuintic

RUN_FIELDS = ('vertical', 'scale_mass', 'scale_inertia', 'scale_lc', 'dist_bound',
              'dist_type', 'noise_q', 'noise_qd', 'noise_tau', 'delay', 'lag', 'q3_0_deg',
              'seed')
"""Per-run inputs of :func:`simulate` (see the module notes)."""
DIST_TYPES = ('uniform', 'constant')
ENGINES = ('numba', 'numpy')
METRICS = ('rms_mm', 'max_mm', 'final_mm', 'tau_peak_1_nm', 'tau_peak_2_nm', 'q3_min_deg',
           'q3_max_deg', 'min_det', 'theta_final_norm', 'diverged_at_s', 'ticks')
"""Per-run outputs of :func:`simulate` (``diverged_at_s`` NaN when the run completed)."""
_NOISE_TAG = 24


def run_defaults(n):
    """
    Per-run inputs of the paper's point (70 %, 0.5 N m uniform, no noise), n runs.

    Parameters
    ----------
    n : int
        Number of runs.

    Returns
    -------
    dict of str to numpy.ndarray, each (n,)
        Keys :data:`RUN_FIELDS`; ``seed`` 0 .. n-1, ``vertical`` False.

    """
    z = np.zeros(n)
    return {'vertical': np.zeros(n, bool), 'scale_mass': z + 0.7, 'scale_inertia': z + 0.7,
            'scale_lc': z + 0.7, 'dist_bound': z + 0.5, 'dist_type': np.zeros(n, np.int64),
            'noise_q': z.copy(), 'noise_qd': z.copy(), 'noise_tau': z.copy(),
            'delay': np.zeros(n, np.int64), 'lag': z.copy(), 'q3_0_deg': z + 120.0,
            'seed': np.arange(n, dtype=np.int64)}


def check_runs(runs):
    """
    Validate per-run inputs; return them as arrays of one length.

    Parameters
    ----------
    runs : dict
        Keys :data:`RUN_FIELDS`, each array_like (n,).

    Returns
    -------
    dict of str to numpy.ndarray

    Raises
    ------
    FreejointValueError
        Naming the field: missing, unknown, wrong length, out of range.

    """
    if not isinstance(runs, dict):
        raise FreejointValueError(f'runs: expected a dict, got {type(runs).__name__}')
    unknown = sorted(set(runs) - set(RUN_FIELDS))
    if unknown:
        raise FreejointValueError(f'runs: unknown field {unknown[0]!r}')
    out = {}
    n = None
    for name in RUN_FIELDS:
        if name not in runs:
            raise FreejointValueError(f'runs: missing field {name!r}')
        arr = np.asarray(runs[name])
        if arr.ndim != 1 or (n is not None and arr.shape[0] != n):
            raise FreejointValueError(f'{name}: expected shape ({n or "n"},), got {arr.shape}')
        n = arr.shape[0]
        if name == 'vertical':
            arr = arr.astype(bool)
        elif name in ('dist_type', 'delay', 'seed'):
            if not np.issubdtype(arr.dtype, np.integer) and not np.all(arr == np.round(arr)):
                raise FreejointValueError(f'{name}: expected integers')
            arr = arr.astype(np.int64)
            if np.any(arr < 0):
                raise FreejointValueError(f'{name}: values must be >= 0')
            if name == 'dist_type' and np.any(arr >= len(DIST_TYPES)):
                raise FreejointValueError(f'dist_type: values must be < {len(DIST_TYPES)}')
        else:
            arr = arr.astype(float)
            if not np.all(np.isfinite(arr)):
                raise FreejointValueError(f'{name}: values must be finite')
            low_strict = name.startswith('scale_')
            if np.any(arr <= 0.0) if low_strict else (name != 'q3_0_deg' and np.any(arr < 0)):
                raise FreejointValueError(
                    f'{name}: values must be {">" if low_strict else ">="} 0')
        out[name] = arr
    if n == 0:
        raise FreejointValueError('runs: need at least one run')
    return out


def nominal_params(real, scale_mass, scale_inertia, scale_lc):
    """Return ``real`` with masses, inertias, COM distances scaled per group."""
    return ArmParams(lengths=real.lengths, masses=tuple(scale_mass * v for v in real.masses),
                     inertias=tuple(scale_inertia * v for v in real.inertias),
                     com=tuple(scale_lc * v for v in real.com), passive=real.passive,
                     gravity=real.gravity)


def _consts(params_list):
    """Per-run arrays of the fast3 constants (d, h, g h) of a list of 3-link ArmParams."""
    cols = {k: [] for k in ('d1', 'd2', 'd3', 'h12', 'h13', 'h23', 'gh1', 'gh2', 'gh3')}
    for p in params_list:
        (l1, l2, _), (m1, m2, m3) = p.lengths, p.masses
        (i1, i2, i3), (c1, c2, c3) = p.inertias, p.com
        h1 = m1 * c1 + l1 * (m2 + m3)
        h2 = m2 * c2 + l2 * m3
        h3 = m3 * c3
        cols['d1'].append(m1 * c1 * c1 + l1 * l1 * (m2 + m3) + i1)
        cols['d2'].append(m2 * c2 * c2 + l2 * l2 * m3 + i2)
        cols['d3'].append(m3 * c3 * c3 + i3)
        cols['h12'].append(l1 * h2)
        cols['h13'].append(l1 * h3)
        cols['h23'].append(l2 * h3)
        g = p.gravity
        cols['gh1'].append(g * h1)
        cols['gh2'].append(g * h2)
        cols['gh3'].append(g * h3)
    return {k: np.array(v) for k, v in cols.items()}


def real_arms(arms=None):
    """
    Return the real arm of each value of ``vertical``: ``{False: ArmParams, True: ArmParams}``.

    Parameters
    ----------
    arms : mapping of bool to ArmParams, optional
        The real arm of the runs with ``vertical`` False and True; default Table I's
        horizontal and vertical arms. Each has three links, joint 3 alone passive, and
        both the same lengths (the kernel's geometry).

    Raises
    ------
    FreejointValueError
        Naming ``arms`` and what the batch kernel cannot run.

    """
    if arms is None:
        return {v: table1('vertical' if v else 'horizontal') for v in (False, True)}
    try:
        out = {False: arms[False], True: arms[True]}
    except (KeyError, TypeError):
        raise FreejointValueError(f'arms: expected a mapping of False and True to ArmParams, '
                                  f'got {arms!r}') from None
    for v, arm in out.items():
        if not isinstance(arm, ArmParams):
            raise FreejointValueError(f'arms[{v}]: expected ArmParams, got {type(arm).__name__}')
        if arm.n != 3 or arm.passive != (2,):
            raise FreejointValueError(
                f'arms[{v}]: the batch kernel runs 3-link arms whose joint 3 alone is passive, '
                f'got {arm.n} joints, passive {list(arm.passive)}')
    if out[False].lengths != out[True].lengths:
        raise FreejointValueError(f'arms: both arms need the same lengths, got '
                                  f'{out[False].lengths} and {out[True].lengths}')
    return out


def _terms(c, q0, q1, q2, w0, w1, w2):
    """Vector form of ``fast3.Arm3Model._terms`` (same operations, same order)."""
    f2 = q0 + q1
    f3 = f2 + q2
    c1 = np.cos(q0)
    s1 = np.sin(q0)
    c2 = np.cos(f2)
    s2 = np.sin(f2)
    c3 = np.cos(f3)
    s3 = np.sin(f3)
    o2 = w0 + w1
    o3 = o2 + w2
    k1 = w0 * w0
    k2 = o2 * o2
    k3 = o3 * o3
    h12 = c['h12']
    h13 = c['h13']
    h23 = c['h23']
    x = h12 * (c1 * c2 + s1 * s2)
    y = h13 * (c1 * c3 + s1 * s3)
    z = h23 * (c2 * c3 + s2 * s3)
    a12 = h12 * (s1 * c2 - c1 * s2)
    a13 = h13 * (s1 * c3 - c1 * s3)
    a23 = h23 * (s2 * c3 - c2 * s3)
    d1 = c['d1']
    d2 = c['d2']
    d3 = c['d3']
    a11 = d2 * d3 - z * z
    b12 = y * z - x * d3
    b13 = x * z - d2 * y
    a22 = d1 * d3 - y * y
    b23 = x * y - d1 * z
    a33 = d1 * d2 - x * x
    inv = 1.0 / (d1 * a11 + x * b12 + y * b13)
    return (c1, s1, c2, s2, c3, s3, o2, o3, k1, k2, k3, a12, a13, a23,
            a11, b12, b13, a22, b23, a33, inv)


def _qdd(c, q0, q1, q2, w0, w1, w2, t0, t1, t2):
    """Vector form of ``fast3.Arm3Model.qdd``."""
    (c1, _, c2, _, c3, _, _, _, k1, k2, k3, a12, a13, a23,
     a11, b12, b13, a22, b23, a33, inv) = _terms(c, q0, q1, q2, w0, w1, w2)
    r1 = t0 - t1 - (a12 * k2 + a13 * k3) - c['gh1'] * c1
    r2 = t1 - t2 - (a23 * k3 - a12 * k1) - c['gh2'] * c2
    r3 = t2 + (a13 * k1 + a23 * k2) - c['gh3'] * c3
    p1 = (a11 * r1 + b12 * r2 + b13 * r3) * inv
    p2 = (b12 * r1 + a22 * r2 + b23 * r3) * inv
    p3 = (b13 * r1 + b23 * r2 + a33 * r3) * inv
    return p1, p2 - p1, p3 - p2


def _task(c, lengths, q0, q1, q2, w0, w1, w2):
    """Vector form of ``fast3.Arm3Model.task`` for passive joint 3 (active 1, 2)."""
    (c1, s1, c2, s2, c3, s3, o2, o3, k1, k2, k3, a12, a13, a23,
     a11, b12, b13, a22, b23, a33, inv) = _terms(c, q0, q1, q2, w0, w1, w2)
    f1v = a12 * k2 + a13 * k3 + c['gh1'] * c1
    f2v = a23 * k3 - a12 * k1 + c['gh2'] * c2
    f3v = -(a13 * k1 + a23 * k2) + c['gh3'] * c3
    l1, l2, l3 = lengths
    lc1 = l1 * c1
    lc2 = l2 * c2
    lc3 = l3 * c3
    ls1 = l1 * s1
    ls2 = l2 * s2
    ls3 = l3 * s3
    px = lc1 + lc2 + lc3
    py = ls1 + ls2 + ls3
    vx = -(ls1 * w0 + ls2 * o2 + ls3 * o3)
    vy = lc1 * w0 + lc2 * o2 + lc3 * o3
    jdx = -(lc1 * k1 + lc2 * k2 + lc3 * k3)
    jdy = -(ls1 * k1 + ls2 * k2 + ls3 * k3)
    vx1 = -(a11 * ls1 + b12 * ls2 + b13 * ls3) * inv
    vx2 = -(b12 * ls1 + a22 * ls2 + b23 * ls3) * inv
    vx3 = -(b13 * ls1 + b23 * ls2 + a33 * ls3) * inv
    vy1 = (a11 * lc1 + b12 * lc2 + b13 * lc3) * inv
    vy2 = (b12 * lc1 + a22 * lc2 + b23 * lc3) * inv
    vy3 = (b13 * lc1 + b23 * lc2 + a33 * lc3) * inv
    bx = jdx - (vx1 * f1v + vx2 * f2v + vx3 * f3v)
    by = jdy - (vy1 * f1v + vy2 * f2v + vy3 * f3v)
    return px, py, vx, vy, vx1, vx2 - vx1, vy1, vy2 - vy1, bx, by


def _fk(lengths, q0, q1, q2):
    l1, l2, l3 = lengths
    f2 = q0 + q1
    f3 = f2 + q2
    return (l1 * np.cos(q0) + l2 * np.cos(f2) + l3 * np.cos(f3),
            l1 * np.sin(q0) + l2 * np.sin(f2) + l3 * np.sin(f3))


class _Law:
    """The paper's law (``_step_fast``) over arrays; the gains are common to all runs."""

    def __init__(self, gains, dt):
        self.lam = gains.Lambda
        self.kpl = tuple(k + lm for k, lm in zip(gains.K, gains.Lambda))
        self.ktl = tuple(k * lm for k, lm in zip(gains.K, gains.Lambda))
        self.rr = gains.R
        self.eps = gains.epsilon
        self.sum = gains.h_form == 'sum'
        self.robust = gains.robust
        self.thr = gains.det_threshold
        coef = []
        for g, sg in zip(gains.Gamma, gains.sigma):
            if sg > 0.0:
                a = math.exp(-g * sg * dt)
                coef.append((a, (1.0 - a) / sg))
            else:
                coef.append((1.0, g * dt))
        self.coef = coef
        self.tmax = gains.theta_max
        lim = gains.tau_limit
        self.limit = None if lim is None else ((lim, lim) if isinstance(lim, float) else lim)

    def step(self, c, lengths, q, qd, des, theta):
        """Return ``tau0, tau1, px, py, det`` and update ``theta`` (list of 5 arrays)."""
        q0, q1, q2 = q
        w0, w1, w2 = qd
        pdx, pdy, vdx, vdy, adx, ady = des
        px, py, vx, vy, d00, d01, d10, d11, bx, by = _task(c, lengths, q0, q1, q2, w0, w1, w2)
        ex = px - pdx
        ey = py - pdy
        edx = vx - vdx
        edy = vy - vdy
        lx, ly = self.lam
        sx = edx + lx * ex
        sy = edy + ly * ey
        gdx, gdy = self.kpl
        gpx, gpy = self.ktl
        vvx = adx - gdx * edx - gpx * ex
        vvy = ady - gdy * edy - gpy * ey
        if self.robust:
            rx, ry = self.rr
            alx = rx * sx
            aly = ry * sy
            na2 = alx * alx + aly * aly
            na = np.sqrt(na2)
            eps = self.eps
            h = na + eps if self.sum else np.where(na > eps, na, eps)
            psi = (1.0, w0 * w0 + w1 * w1 + w2 * w2, math.sqrt(adx * adx + ady * ady),
                   np.sqrt(edx * edx + edy * edy), np.sqrt(ex * ex + ey * ey))
            th = theta
            rho = th[0] + th[1] * psi[1] + th[2] * psi[2] + th[3] * psi[3] + th[4] * psi[4]
            f = rho / h
            dvx = -f * alx
            dvy = -f * aly
            u = na2 / h
            new = [a * t + cc * (u * ps) for (a, cc), t, ps in zip(self.coef, th, psi)]
            if self.tmax is not None:
                new = [np.where(t > tm, tm, t) for t, tm in zip(new, self.tmax)]
            theta[:] = new
            wx = vvx + dvx - bx
            wy = vvy + dvy - by
        else:
            wx = vvx + 0.0 - bx
            wy = vvy + 0.0 - by
        a00 = d00 * d00 + d01 * d01
        a01 = d00 * d10 + d01 * d11
        a11 = d10 * d10 + d11 * d11
        det = a00 * a11 - a01 * a01
        near = np.abs(det) < self.thr
        if np.any(near):
            gap = self.thr - det
            tr = a00 + a11
            lam2 = np.where(near, 2.0 * gap / (tr + np.sqrt(np.abs(tr * tr + 4.0 * gap))), 0.0)
            a00 = np.where(near, a00 + lam2, a00)
            a11 = np.where(near, a11 + lam2, a11)
            det_use = np.where(near, a00 * a11 - a01 * a01, det)
        else:
            det_use = det
        y0 = (a11 * wx - a01 * wy) / det_use
        y1 = (a00 * wy - a01 * wx) / det_use
        t0 = d00 * y0 + d10 * y1
        t1 = d01 * y0 + d11 * y1
        if self.limit is not None:
            l0, l1 = self.limit
            t0 = np.clip(t0, -l0, l0)
            t1 = np.clip(t1, -l1, l1)
        return t0, t1, px, py, np.abs(det)


def _rk4(c, q, w, tau, h, n_sub):
    """``n_sub`` RK4 steps of size ``h`` (vector form of ``Plant._rk4_fast3``)."""
    t0, t1, t2 = tau
    q0, q1, q2 = q
    w0, w1, w2 = w
    h2 = 0.5 * h
    h6 = h / 6.0
    for _ in range(n_sub):
        a0, a1, a2 = _qdd(c, q0, q1, q2, w0, w1, w2, t0, t1, t2)
        u0 = w0 + h2 * a0
        u1 = w1 + h2 * a1
        u2 = w2 + h2 * a2
        b0, b1, b2 = _qdd(c, q0 + h2 * w0, q1 + h2 * w1, q2 + h2 * w2, u0, u1, u2, t0, t1, t2)
        v0 = w0 + h2 * b0
        v1 = w1 + h2 * b1
        v2 = w2 + h2 * b2
        c0, c1, c2 = _qdd(c, q0 + h2 * u0, q1 + h2 * u1, q2 + h2 * u2, v0, v1, v2, t0, t1, t2)
        x0 = w0 + h * c0
        x1 = w1 + h * c1
        x2 = w2 + h * c2
        d0, d1, d2 = _qdd(c, q0 + h * v0, q1 + h * v1, q2 + h * v2, x0, x1, x2, t0, t1, t2)
        q0 = q0 + h6 * (w0 + 2.0 * (u0 + v0) + x0)
        q1 = q1 + h6 * (w1 + 2.0 * (u1 + v1) + x1)
        q2 = q2 + h6 * (w2 + 2.0 * (u2 + v2) + x2)
        w0 = w0 + h6 * (a0 + 2.0 * (b0 + c0) + d0)
        w1 = w1 + h6 * (a1 + 2.0 * (b1 + c1) + d1)
        w2 = w2 + h6 * (a2 + 2.0 * (b2 + c2) + d2)
    return [q0, q1, q2], [w0, w1, w2]


def check_grid(dt, dt_sub, duration):
    """
    Return ``(ticks, sub-steps)`` of a run, or raise naming ``duration`` or ``dt_sub``.

    Parameters
    ----------
    dt, dt_sub, duration : float
        Control period, RK4 step and run length (s).

    Returns
    -------
    tuple of int
        ``duration / dt`` and ``dt / dt_sub`` (both integers, checked).

    """
    n_ticks = int(round(duration / dt))
    if n_ticks < 1 or abs(n_ticks * dt - duration) > 1e-9 * duration:
        raise FreejointValueError(
            f'duration: {duration} s is not a positive integer multiple of dt = {dt} s')
    n_sub = round(dt / dt_sub)
    if n_sub < 1 or abs(n_sub * dt_sub - dt) > 1e-9 * dt:
        raise FreejointValueError(
            f'dt_sub: dt = {dt} s is not an integer multiple of dt_sub = {dt_sub} s')
    return n_ticks, n_sub


class _Streams:
    """Per-run random streams drawn in blocks of ticks (the scalar reference draws per tick)."""

    def __init__(self, seed, bound, dtype, sigma, width, tag):
        self.n = len(seed)
        self.on = np.nonzero((bound if tag is None else sigma) > 0.0)[0]
        self.gens = {int(i): np.random.default_rng(
            int(seed[i]) if tag is None else [_NOISE_TAG, tag, int(seed[i])]) for i in self.on}
        self.width = width
        self.tag = tag
        self.scale = bound if tag is None else sigma
        self.block = None
        self.start = 0

    def fill(self, k0, nb):
        """Draw ticks ``k0 .. k0 + nb - 1``: array (nb, width, n) (zeros where off)."""
        out = np.zeros((nb, self.width, self.n))
        for i, g in self.gens.items():
            if self.tag is None:
                out[:, :, i] = g.random((nb, self.width))
            else:
                out[:, :, i] = g.standard_normal((nb, self.width))
        if self.tag is None:
            b = self.scale
            out = -b + (b + b) * out
            out[:, :, np.setdiff1d(np.arange(self.n), self.on)] = 0.0
        else:
            out = self.scale * out
        return out


def simulate(runs, gains=None, *, dt=DEFAULT_DT, dt_sub=DEFAULT_DT_SUB, duration=5.0,
             trajectory=None, diverge_m=0.5, diverge_qd=1000.0, record_trace=False,
             block=250, engine='numba', threads=None, arms=None):
    """
    Run every run of ``runs`` together and return their metrics.

    Parameters
    ----------
    runs : dict of str to array_like, each (n,)
        Per-run inputs, keys :data:`RUN_FIELDS` (see the module notes).
    gains : Gains, optional
        Controller gains of every run (paper's by default).
    dt, dt_sub, duration : float
        Control period, RK4 step and run length (s), as ``offline.run_case``.
    trajectory : CircleQuintic, optional
        Desired path (the paper's circle by default).
    diverge_m, diverge_qd : float
        Divergence thresholds (m, rad/s), as ``offline.run_case``.
    record_trace : bool
        Also return the end-effector position per run and tick.
    block : int
        Ticks of random numbers drawn at once per run (numpy engine).
    engine : {'numba', 'numpy'}
        ``numba``: the compiled kernel (``batch_kernel``, threads over runs);
        ``numpy``: every operation an array over the runs (slower; same numbers).
    threads : int, optional
        Threads of the numba engine (default: every core).
    arms : mapping of bool to ArmParams, optional
        The real arm per value of ``vertical`` (:func:`real_arms`; Table I's by default).

    Returns
    -------
    dict of str to numpy.ndarray, each (n,)
        Keys :data:`METRICS`; with ``record_trace`` also ``p`` (n, N, 2) [m], NaN
        after a run's last recorded tick.

    """
    if engine not in ENGINES:
        raise FreejointValueError(f'engine: expected one of {ENGINES}, got {engine!r}')
    runs = check_runs(runs)
    gains = Gains() if gains is None else gains
    if not isinstance(gains, Gains):
        raise FreejointValueError(f'gains: expected Gains, got {type(gains).__name__}')
    trajectory = CircleQuintic() if trajectory is None else trajectory
    n_ticks, n_sub = check_grid(dt, dt_sub, duration)
    reals = real_arms(arms)
    if engine == 'numba':
        return _simulate_numba(runs, gains, dt, dt_sub, n_ticks, n_sub, trajectory,
                               diverge_m, diverge_qd, record_trace, threads, reals)
    n = runs['seed'].shape[0]
    real_list = [reals[bool(v)] for v in runs['vertical']]
    lengths = reals[False].lengths
    cr_all = _consts(real_list)
    cn_all = _consts([nominal_params(r, a, b, c) for r, a, b, c in zip(
        real_list, runs['scale_mass'], runs['scale_inertia'], runs['scale_lc'])])
    px0, py0 = trajectory.sample(0.0)[0]
    q0_cache = {}
    q_init = np.empty((3, n))
    for i in range(n):
        key = (bool(runs['vertical'][i]), float(runs['q3_0_deg'][i]))
        if key not in q0_cache:
            q0_cache[key] = initial_state(real_list[i], key[1], (px0, py0))
        q_init[:, i] = q0_cache[key]
    des = [trajectory.sample_tuple(k * dt) for k in range(n_ticks)]
    law = _Law(gains, dt)
    seed = runs['seed']
    dist = _Streams(seed, runs['dist_bound'], None, None, 3, None)
    nq = _Streams(seed, None, None, runs['noise_q'], 3, 1)
    nqd = _Streams(seed, None, None, runs['noise_qd'], 3, 2)
    ntau = _Streams(seed, None, None, runs['noise_tau'], 2, 3)
    const_d = runs['dist_type'] == 1
    d_const = None
    if np.any(const_d):
        d_const = np.zeros((3, n))
        for i in np.nonzero(const_d & (runs['dist_bound'] > 0.0))[0]:
            b = runs['dist_bound'][i]
            d_const[:, i] = np.random.default_rng(int(seed[i])).uniform(-b, b, 3)
        dist.on = np.setdiff1d(dist.on, np.nonzero(const_d)[0])
        dist.gens = {i: g for i, g in dist.gens.items() if not const_d[i]}
    delay = runs['delay']
    max_delay = int(delay.max())
    hist_len = max_delay + 1
    lag = runs['lag']
    alpha = np.where(lag > 0.0, 1.0 - np.exp(-dt / np.where(lag > 0.0, lag, 1.0)), 1.0)
    use_lag = bool(np.any(lag > 0.0))
    any_noise = bool(len(nq.on) or len(nqd.on))

    # Results.
    err_sum = np.zeros(n)
    err_max = np.zeros(n)
    err_last = np.zeros(n)
    tau_pk = np.zeros((2, n))
    q3_min = np.full(n, np.inf)
    q3_max = np.full(n, -np.inf)
    det_min = np.full(n, np.inf)
    diverged = np.full(n, np.nan)
    n_rec = np.zeros(n, np.int64)
    theta_fin = np.zeros((5, n))
    trace = np.full((n, n_ticks, 2), np.nan) if record_trace else None

    # Live state (columns of the runs still going; ``idx`` maps them back).
    idx = np.arange(n)
    q = [q_init[j].copy() for j in range(3)]
    w = [np.zeros(n) for _ in range(3)]
    theta = [np.full(n, t) for t in gains.theta0]
    hist = np.zeros((hist_len, 2, n))
    u_prev = None
    cr, cn = cr_all, cn_all
    blocks = {}
    limit2 = diverge_m * diverge_m
    h = dt_sub

    def take(name, k):
        s, b0 = blocks[name]
        return b0[k - s][..., idx]

    with np.errstate(all='ignore'):
        for k in range(n_ticks):
            if not idx.size:
                break
            if k % block == 0:
                nb = min(block, n_ticks - k)
                for name, st in (('d', dist), ('q', nq), ('qd', nqd), ('tau', ntau)):
                    if len(st.on):
                        blocks[name] = (k, st.fill(k, nb))
            t = k * dt
            d_k = des[k]
            if any_noise:
                qm = [q[j] + take('q', k)[j] if 'q' in blocks else q[j] for j in range(3)]
                wm = [w[j] + take('qd', k)[j] if 'qd' in blocks else w[j] for j in range(3)]
            else:
                qm, wm = q, w
            th_before = [x.copy() for x in theta]
            t0, t1, px, py, det = law.step(cn, lengths, qm, wm, d_k, theta)
            if any_noise:
                px, py = _fk(lengths, *q)
            ex = px - d_k[0]
            ey = py - d_k[1]
            err2 = ex * ex + ey * ey
            bad = ~(np.isfinite(err2) & np.isfinite(t0) & np.isfinite(t1) & np.isfinite(det))
            ok = ~bad
            # Record the good ones.
            err_mm = 1000.0 * np.hypot(ex, ey)
            gi = idx[ok]
            err_sum[gi] += (err_mm * err_mm)[ok]
            err_max[gi] = np.maximum(err_max[gi], err_mm[ok])
            err_last[gi] = err_mm[ok]
            tau_pk[0, gi] = np.maximum(tau_pk[0, gi], np.abs(t0[ok]))
            tau_pk[1, gi] = np.maximum(tau_pk[1, gi], np.abs(t1[ok]))
            q3 = q[2][ok]
            q3_min[gi] = np.minimum(q3_min[gi], q3)
            q3_max[gi] = np.maximum(q3_max[gi], q3)
            det_min[gi] = np.minimum(det_min[gi], det[ok])
            n_rec[gi] = k + 1
            for j in range(5):
                theta_fin[j, gi] = theta[j][ok]
            if record_trace:
                trace[gi, k, 0] = px[ok]
                trace[gi, k, 1] = py[ok]
            # theta of a bad tick is not the record's: keep the one before.
            if np.any(bad):
                bi = idx[bad]
                for j in range(5):
                    theta_fin[j, bi] = th_before[j][bad]
            wmax = np.maximum(np.maximum(np.abs(w[0]), np.abs(w[1])), np.abs(w[2]))
            stop = bad | (ok & ((err2 > limit2) | (wmax > diverge_qd)))
            # Commands: delay line, lag, torque noise, disturbance.
            cmd0 = np.where(ok, t0, 0.0)
            cmd1 = np.where(ok, t1, 0.0)
            hist[k % hist_len, 0] = cmd0
            hist[k % hist_len, 1] = cmd1
            if k == 0:
                first = np.stack([cmd0, cmd1])
                hist0 = first.copy()
            if max_delay:
                src = k - delay[idx]
                slot = np.where(src >= 0, src, 0) % hist_len
                cols = np.arange(idx.size)
                a0 = np.where(src >= 0, hist[slot, 0, cols], hist0[0])
                a1 = np.where(src >= 0, hist[slot, 1, cols], hist0[1])
            else:
                a0, a1 = cmd0, cmd1
            if use_lag:
                if u_prev is None:
                    u_prev = first.copy()
                al = alpha[idx]
                a0 = u_prev[0] + al * (a0 - u_prev[0])
                a1 = u_prev[1] + al * (a1 - u_prev[1])
                u_prev = np.stack([a0, a1])
            if 'tau' in blocks:
                nt = take('tau', k)
                a0 = a0 + nt[0]
                a1 = a1 + nt[1]
            if 'd' in blocks or d_const is not None:
                dk = take('d', k) if 'd' in blocks else np.zeros((3, idx.size))
                if d_const is not None:
                    dk = np.where(const_d[idx], d_const[:, idx], dk)
                f0, f1, f2 = dk[0] + a0, dk[1] + a1, dk[2]
            else:
                f0, f1, f2 = 0.0 + a0, 0.0 + a1, np.zeros(idx.size)
            qn, wn = _rk4(cr, q, w, (f0, f1, f2), h, n_sub)
            fin = np.isfinite(qn[0])
            for arr in qn + wn:
                fin &= np.isfinite(arr)
            plant_bad = ~stop & ~fin
            diverged[idx[bad]] = t
            diverged[idx[stop & ~bad]] = t
            diverged[idx[plant_bad]] = (k + 1) * dt
            q, w = qn, wn
            alive = ~(stop | plant_bad)
            if not np.all(alive):
                idx = idx[alive]
                q = [x[alive] for x in q]
                w = [x[alive] for x in w]
                theta = [x[alive] for x in theta]
                hist = hist[:, :, alive]
                hist0 = hist0[:, alive]
                first = first[:, alive]
                if u_prev is not None:
                    u_prev = u_prev[:, alive]
                cr = {key: v[idx] for key, v in cr_all.items()}
                cn = {key: v[idx] for key, v in cn_all.items()}
    if np.any(n_rec == 0):
        raise FreejointValueError('gains: the first tick already fails for some run')
    out = {
        'rms_mm': np.sqrt(err_sum / n_rec), 'max_mm': err_max, 'final_mm': err_last,
        'tau_peak_1_nm': tau_pk[0], 'tau_peak_2_nm': tau_pk[1],
        'q3_min_deg': np.degrees(q3_min), 'q3_max_deg': np.degrees(q3_max),
        'min_det': det_min, 'theta_final_norm': np.sqrt((theta_fin ** 2).sum(axis=0)),
        'diverged_at_s': diverged, 'ticks': n_rec}
    if record_trace:
        out['p'] = trace
    return out


def _prepare(runs, trajectory, dt, n_ticks, reals):
    """Real / nominal constants (n, 9), initial states (n, 3) and setpoints (N, 6)."""
    n = runs['seed'].shape[0]
    real_list = [reals[bool(v)] for v in runs['vertical']]
    keys = ('d1', 'd2', 'd3', 'h12', 'h13', 'h23', 'gh1', 'gh2', 'gh3')
    cr = _consts(real_list)
    cn = _consts([nominal_params(r, a, b, c) for r, a, b, c in zip(
        real_list, runs['scale_mass'], runs['scale_inertia'], runs['scale_lc'])])
    px0, py0 = trajectory.sample(0.0)[0]
    cache = {}
    q_init = np.empty((n, 3))
    for i in range(n):
        key = (bool(runs['vertical'][i]), float(runs['q3_0_deg'][i]))
        if key not in cache:
            cache[key] = initial_state(real_list[i], key[1], (px0, py0))
        q_init[i] = cache[key]
    des = np.array([trajectory.sample_tuple(k * dt) for k in range(n_ticks)])
    return (np.stack([cr[k] for k in keys], axis=1), np.stack([cn[k] for k in keys], axis=1),
            np.array(reals[False].lengths), q_init, des)


def _gain_vector(gains, dt):
    """Return the gains in the ``gp`` layout of ``batch_kernel``."""
    law = _Law(gains, dt)
    inf = math.inf
    tmax = law.tmax if law.tmax is not None else (inf,) * 5
    limit = law.limit if law.limit is not None else (inf, inf)
    return np.array(list(law.lam) + list(law.kpl) + list(law.ktl) + list(law.rr)
                    + [law.eps, float(law.sum), float(law.robust), law.thr]
                    + [a for a, _ in law.coef] + [c for _, c in law.coef]
                    + list(gains.theta0) + list(tmax) + list(limit))


def draws(runs, n_ticks):
    """
    Return the random numbers of every run, from the generators of the scalar reference.

    Parameters
    ----------
    runs : dict
        Checked per-run inputs (:func:`check_runs`).
    n_ticks : int
        Ticks per run.

    Returns
    -------
    dist : numpy.ndarray, (n, N, 3)
        Disturbance [N m] per tick.
    nq, nqd, ntau : numpy.ndarray, (n, N, 3), (n, N, 3), (n, N, 2)
        Scaled noise; (1, 1, k) zeros when no run has it.
    flags : numpy.ndarray of bool, (n, 3)
        Which runs have q, qd, torque noise.

    """
    n = runs['seed'].shape[0]
    dist = np.zeros((n, n_ticks, 3))
    flags = np.stack([runs['noise_q'] > 0, runs['noise_qd'] > 0, runs['noise_tau'] > 0],
                     axis=1)
    noise = [np.zeros((n, n_ticks, w)) if flags[:, j].any() else np.zeros((1, 1, w))
             for j, w in enumerate((3, 3, 2))]
    for i in range(n):
        seed = int(runs['seed'][i])
        b = float(runs['dist_bound'][i])
        if b > 0.0:
            g = np.random.default_rng(seed)
            if runs['dist_type'][i] == 1:
                dist[i] = g.uniform(-b, b, 3)
            else:
                dist[i] = -b + (b + b) * g.random((n_ticks, 3))
        for j, name in enumerate(('noise_q', 'noise_qd', 'noise_tau')):
            if flags[i, j]:
                g = np.random.default_rng([_NOISE_TAG, j + 1, seed])
                noise[j][i] = runs[name][i] * g.standard_normal((n_ticks, noise[j].shape[2]))
    return dist, noise[0], noise[1], noise[2], flags


def _simulate_numba(runs, gains, dt, dt_sub, n_ticks, n_sub, trajectory, diverge_m,
                    diverge_qd, record_trace, threads, reals):
    from . import batch_kernel
    cr, cn, ln, q_init, des = _prepare(runs, trajectory, dt, n_ticks, reals)
    dist, nq, nqd, ntau, flags = draws(runs, n_ticks)
    lag = runs['lag']
    alpha = np.where(lag > 0.0, 1.0 - np.exp(-dt / np.where(lag > 0.0, lag, 1.0)), 1.0)
    n = cr.shape[0]
    out = np.empty((n, batch_kernel.N_OUT))
    out_p = np.full((n, n_ticks, 2) if record_trace else (1, 1, 2), np.nan)
    args = (cr, cn, ln, q_init, des, _gain_vector(gains, dt), dist, nq, nqd, ntau, flags,
            runs['delay'], alpha, float(dt), float(dt_sub), int(n_sub),
            float(diverge_m * diverge_m), float(diverge_qd), bool(record_trace), out, out_p)
    threads = max(1, min(threads or os.cpu_count() or 1, n))
    if threads == 1:
        batch_kernel.run_range(0, n, 1, *args)
    else:   # interleaved: neighbouring runs (alike, similar cost) go to different threads
        with ThreadPoolExecutor(threads) as pool:
            for f in [pool.submit(batch_kernel.run_range, j, n, threads, *args)
                      for j in range(threads)]:
                f.result()
    if np.any(out[:, 10] == 0):
        raise FreejointValueError('gains: the first tick already fails for some run')
    res = {name: out[:, j] for j, name in enumerate(METRICS)}
    res['ticks'] = out[:, 10].astype(np.int64)
    if record_trace:
        res['p'] = out_p
    return res


KERNELS = {'robust': simulate}
"""Batched kernels registered per law name: ``kernel(runs, gains, **options)`` computing
what :func:`run_scalar` computes with that law, run by run (tests check they agree)."""


def register_kernel(law, kernel):
    """Register the batched campaign kernel of the law registered as ``law``."""
    if not callable(kernel):
        raise FreejointValueError(f'kernel: expected a callable, got {kernel!r}')
    KERNELS[law] = kernel


def simulate_law(runs, gains=None, *, law='robust', law_params=None, processes=None,
                 **options):
    """
    Run every run of ``runs`` with the registered law ``law``; return their metrics.

    The law's batched kernel (:data:`KERNELS`) when it has one and no own gains are
    given, else its scalar step run by run (:func:`run_scalar`, ``processes`` worker
    processes, default every core): the same metrics, slower.

    Parameters
    ----------
    runs, gains
        As :func:`simulate`.
    law : str
        A law of ``freejoint_core.laws.LAWS``.
    law_params : mapping of str to float, optional
        The laws' own gains by namespaced name.
    processes : int, optional
        Worker processes of the scalar path (1: in this process).
    **options
        ``dt``, ``dt_sub``, ``duration``, ``trajectory``, ``diverge_m``, ``diverge_qd``,
        ``arms`` (and for a kernel its own options).

    Returns
    -------
    dict of str to numpy.ndarray, each (n,)
        Keys :data:`METRICS`.

    """
    from .laws import LAWS
    if law not in LAWS:
        raise FreejointValueError(f'law: expected one of {tuple(LAWS)}, got {law!r}')
    own = {k: v for k, v in (law_params or {}).items() if k.startswith(law + '.')}
    if law in KERNELS and not own:
        return KERNELS[law](runs, gains, **options)
    runs = check_runs(runs)
    n = runs['seed'].shape[0]
    one = [{k: v[i] for k, v in runs.items()} for i in range(n)]
    job = _ScalarJob(gains, law, own or None, options)
    workers = max(1, min(processes or os.cpu_count() or 1, n))
    if workers == 1:
        results = [job(r) for r in one]
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context(
                'forkserver')) as pool:
            results = list(pool.map(job, one, chunksize=max(1, n // (4 * workers))))
    out = {name: np.array([r[name] for r in results], dtype=float) for name in METRICS}
    out['ticks'] = out['ticks'].astype(np.int64)
    return out


class _ScalarJob:
    """
    One run of :func:`run_scalar` with fixed law and options (picklable).

    A worker process imports the module that registered the law first (a law registered
    by a module the worker has not imported yet, e.g. a lab's own).
    """

    def __init__(self, gains, law, law_params, options):
        from .laws import LAWS
        self.module = getattr(LAWS[law], '__module__', None)
        self.args = (gains, law, law_params, options)

    def __call__(self, run):
        from .laws import LAWS
        gains, law, law_params, options = self.args
        if law not in LAWS and self.module:
            import importlib
            importlib.import_module(self.module)
        return run_scalar(run, gains, law=law, law_params=law_params, **options)[0]


def run_scalar(run, gains=None, *, dt=DEFAULT_DT, dt_sub=DEFAULT_DT_SUB, duration=5.0,
               trajectory=None, diverge_m=0.5, diverge_qd=1000.0, arms=None, law='robust',
               law_params=None):
    """
    One run of :func:`simulate`, tick by tick with ``Plant`` and the law's scalar step.

    The reference :func:`simulate` is tested against: ``offline.run_case``'s loop with
    the campaign axes added in the order of the module notes; the law built by
    ``laws.make_law`` (a law without a batched kernel runs in campaigns through this).

    Parameters
    ----------
    run : dict
        One value per :data:`RUN_FIELDS` key.
    gains, dt, dt_sub, duration, trajectory, diverge_m, diverge_qd, arms
        As :func:`simulate`.
    law, law_params
        The registered control law and the laws' own gains (``offline.run_case``).

    Returns
    -------
    metrics : dict
        :data:`METRICS` keys, floats.
    p : numpy.ndarray, (ticks, 2)
        End-effector position of the recorded ticks [m].

    """
    r = {k: v[0] for k, v in check_runs({k: [v] for k, v in run.items()}).items()}
    gains = Gains() if gains is None else gains
    trajectory = CircleQuintic() if trajectory is None else trajectory
    n_ticks, n_sub = check_grid(dt, dt_sub, duration)
    real = real_arms(arms)[bool(r['vertical'])]
    nominal = nominal_params(real, r['scale_mass'], r['scale_inertia'], r['scale_lc'])
    seed = int(r['seed'])
    px0, py0 = trajectory.sample(0.0)[0]
    plant = Plant(real, dt_sub, dist_bound=0.0, seed=seed,
                  q0=initial_state(real, r['q3_0_deg'], (px0, py0)))
    ctrl = make_law(law, nominal, gains, params=law_params)
    fk = plant.model.fk
    b = float(r['dist_bound'])
    rng_d = np.random.default_rng(seed)
    d_const = rng_d.uniform(-b, b, 3).tolist() if b > 0 and r['dist_type'] == 1 else None
    gens = {name: np.random.default_rng([_NOISE_TAG, tag, seed])
            for name, tag in (('noise_q', 1), ('noise_qd', 2), ('noise_tau', 3))}
    m = int(r['delay'])
    lag = float(r['lag'])
    alpha = 1.0 - math.exp(-dt / lag) if lag > 0.0 else None
    cmds = []
    u = None
    p_rec, err_mm, taus, q3s, dets = [], [], [], [], []
    theta = ctrl.theta
    diverged = math.nan
    for k in range(n_ticks):
        t = k * dt
        pdx, pdy, vdx, vdy, adx, ady = trajectory.sample_tuple(t)
        q = plant.q
        qd = plant.qd
        qm = q + r['noise_q'] * gens['noise_q'].standard_normal(3) if r['noise_q'] > 0 else q
        wm = qd + r['noise_qd'] * gens['noise_qd'].standard_normal(3) \
            if r['noise_qd'] > 0 else qd
        try:
            out = ctrl.step(qm, wm, (pdx, pdy), (vdx, vdy), (adx, ady), dt)
        except _BLOWUP:
            diverged = t
            break
        px, py = (fk(q) if qm is not q or wm is not qd else out.p).tolist()
        t0, t1 = out.tau.tolist()
        ex = px - pdx
        ey = py - pdy
        err2 = ex * ex + ey * ey
        if not all(map(math.isfinite, (err2, t0, t1, out.det))):
            diverged = t
            break
        p_rec.append((px, py))
        err_mm.append(1000.0 * math.hypot(ex, ey))
        taus.append((abs(t0), abs(t1)))
        q3s.append(q[2])
        dets.append(out.det)
        theta = out.theta
        if err2 > diverge_m * diverge_m or max(abs(v) for v in qd.tolist()) > diverge_qd:
            diverged = t
            break
        cmds.append((t0, t1))
        c0, c1 = cmds[max(0, k - m)]
        if alpha is not None:
            if u is None:
                u = cmds[0]
            u = (u[0] + alpha * (c0 - u[0]), u[1] + alpha * (c1 - u[1]))
            c0, c1 = u
        if r['noise_tau'] > 0:
            n0, n1 = (r['noise_tau'] * gens['noise_tau'].standard_normal(2)).tolist()
            c0, c1 = c0 + n0, c1 + n1
        if d_const is not None:
            full = list(d_const)
        elif b > 0:
            full = rng_d.uniform(-b, b, 3).tolist()
        else:
            full = [0.0, 0.0, 0.0]
        full[0] += float(c0)
        full[1] += float(c1)
        if plant._advance(n_sub, full) is not None:
            diverged = (k + 1) * dt
            break
    e = np.array(err_mm)
    tau = np.array(taus)
    metrics = {
        'rms_mm': math.sqrt(float(np.mean(e * e))), 'max_mm': float(e.max()),
        'final_mm': float(e[-1]), 'tau_peak_1_nm': float(tau[:, 0].max()),
        'tau_peak_2_nm': float(tau[:, 1].max()),
        'q3_min_deg': math.degrees(min(q3s)), 'q3_max_deg': math.degrees(max(q3s)),
        'min_det': float(min(dets)), 'theta_final_norm': float(np.sqrt(np.sum(theta ** 2))),
        'diverged_at_s': diverged, 'ticks': len(e)}
    return metrics, np.array(p_rec)
