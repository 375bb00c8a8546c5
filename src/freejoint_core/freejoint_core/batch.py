"""
Batched closed-loop simulator: many runs of the paper's 3-link arm advanced together.

Every run is the offline runner's loop (``freejoint_core.offline``, module notes:
tick ``k``, controller on the state of ``t_k``, RK4 plant over ``[t_k, t_{k+1}]``,
the same divergence rule) with a few uncertainty axes a robustness campaign
varies per run, compiled with numba (``batch_kernel``); the arm
is Table I's (three links, joint 3 passive) or, with ``arms``, another 3-link arm whose
joint 3 alone is passive (a URDF arm's ``ArmParams``), the law the paper's fast path
(``control.RobustController._step_fast``) or the sliding-mode or time-delay law
(``law_vsc``, ``law_tdc``: ``task_law.TaskLaw.step``), the plant ``plant.Plant``
(fast3 RK4).

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

from .arm import ArmParams, DEFAULT_DT, table1
from .control import decay_coefficients, Gains
from .errors import FreejointValueError
from .law_base import RunValues
from .laws import make_law
from .offline import _BLOWUP, initial_state
from .plant import DEFAULT_DT_SUB, Plant
from .trajectory import CircleQuintic

RUN_FIELDS = ('vertical', 'scale_mass', 'scale_inertia', 'scale_lc', 'dist_bound',
              'dist_type', 'noise_q', 'noise_qd', 'noise_tau', 'delay', 'lag', 'q3_0_deg',
              'seed')
"""Per-run inputs of :func:`simulate` (see the module notes)."""
DIST_TYPES = ('uniform', 'constant')
ENGINES = ('numba',)
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


def simulate(runs, gains=None, *, dt=DEFAULT_DT, dt_sub=DEFAULT_DT_SUB, duration=5.0,
             trajectory=None, diverge_m=0.5, diverge_qd=1000.0, record_trace=False,
             engine='numba', threads=None, arms=None, law='robust', law_params=None):
    """
    Run every run of ``runs`` with a law's batched kernel; return their metrics.

    The kernel registered for the laws ``robust`` (the paper's), ``vsc`` and ``tdc``
    (:data:`KERNELS`): ``batch_kernel``, compiled with numba, threads over runs;
    :func:`run_scalar` with the same law is the reference it equals run by run.

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
    engine : {'numba'}
        The compiled kernel (``batch_kernel``).
    threads : int, optional
        Threads of the numba engine (default: every core).
    arms : mapping of bool to ArmParams, optional
        The real arm per value of ``vertical`` (:func:`real_arms`; Table I's by default).
    law : {'robust', 'vsc', 'tdc'}
        The law the kernel runs (:data:`KERNEL_LAWS`).
    law_params : mapping of str to float, optional
        The law's own gains by namespaced name (``vsc.phi``, ...; its defaults otherwise).

    Returns
    -------
    dict of str to numpy.ndarray, each (n,)
        Keys :data:`METRICS`; with ``record_trace`` also ``p`` (n, N, 2) [m], NaN
        after a run's last recorded tick.

    """
    if law not in KERNEL_LAWS:
        raise FreejointValueError(f'law: the batched kernel runs {KERNEL_LAWS}, got {law!r}')
    if engine not in ENGINES:
        raise FreejointValueError(f'engine: expected one of {ENGINES}, got {engine!r}')
    runs = check_runs(runs)
    gains = Gains() if gains is None else gains
    if not isinstance(gains, Gains):
        raise FreejointValueError(f'gains: expected Gains, got {type(gains).__name__}')
    trajectory = CircleQuintic() if trajectory is None else trajectory
    n_ticks, n_sub = check_grid(dt, dt_sub, duration)
    reals = real_arms(arms)
    lp = _law_vector(law, gains, law_params, dt)
    return _simulate_numba(runs, gains, dt, dt_sub, n_ticks, n_sub, trajectory, diverge_m,
                           diverge_qd, record_trace, threads, reals, law, lp)


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
    """Return the gains in the ``gp`` layout of ``batch_kernel`` (those of ``_step_fast``)."""
    inf = math.inf
    tmax = gains.theta_max if gains.theta_max is not None else (inf,) * 5
    lim = gains.tau_limit
    limit = (inf, inf) if lim is None else ((lim, lim) if isinstance(lim, float) else lim)
    coef = decay_coefficients(gains.Gamma, gains.sigma, dt)
    return np.array(list(gains.Lambda) + [k + lm for k, lm in zip(gains.K, gains.Lambda)]
                    + [k * lm for k, lm in zip(gains.K, gains.Lambda)] + list(gains.R)
                    + [gains.epsilon, float(gains.h_form == 'sum'), float(gains.robust),
                       gains.det_threshold]
                    + [a for a, _ in coef] + [c for _, c in coef]
                    + list(gains.theta0) + list(tmax) + list(limit))


def _law_vector(law, gains, law_params, dt):
    """
    Return the task law's values in the ``lp`` layout of ``batch_kernel`` (empty: robust).

    ``K`` (2) then the law's own gains by name in the order the kernel reads them; for
    ``tdc`` the filter's time constant as the low-pass coefficient ``1 - exp(-dt / tc)``
    (1: none), computed here as the scalar step computes it.
    """
    if law == 'robust':
        return np.zeros(0)
    from .laws import LAWS
    from .law_base import law_params as own
    g = own(law, LAWS[law].gain_schema, law_params)
    if law == 'vsc':
        values = [g[name] for name in ('vsc.phi', 'vsc.eta', 'vsc.delta', 'vsc.beta0',
                                       'vsc.beta1')]
    else:
        tc = g['tdc.filter']
        values = [g['tdc.mbar'], 1.0 - math.exp(-dt / tc) if tc > 0.0 else 1.0]
    return np.array(list(gains.K) + values, dtype=float)


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
                    diverge_qd, record_trace, threads, reals, law, lp):
    from . import batch_kernel
    cr, cn, ln, q_init, des = _prepare(runs, trajectory, dt, n_ticks, reals)
    dist, nq, nqd, ntau, flags = draws(runs, n_ticks)
    lag = runs['lag']
    alpha = np.where(lag > 0.0, 1.0 - np.exp(-dt / np.where(lag > 0.0, lag, 1.0)), 1.0)
    n = cr.shape[0]
    out = np.empty((n, batch_kernel.N_OUT))
    out_p = np.full((n, n_ticks, 2) if record_trace else (1, 1, 2), np.nan)
    args = (cr, cn, ln, q_init, des, _gain_vector(gains, dt), KERNEL_LAWS.index(law), lp,
            dist, nq, nqd, ntau, flags,
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


KERNEL_LAWS = ('robust', 'vsc', 'tdc')
"""The laws ``batch_kernel`` runs, in the order of its ``law`` codes."""


def _kernel_of(law):
    """Return :func:`simulate` for ``law`` (a kernel as :data:`KERNELS` holds them)."""
    def kernel(runs, gains=None, **options):
        return simulate(runs, gains, law=law, **options)
    kernel.__name__ = f'simulate_{law}'
    return kernel


KERNELS = {law: _kernel_of(law) for law in KERNEL_LAWS}
"""Batched kernels registered per law name: ``kernel(runs, gains, law_params=None,
**options)`` computing what :func:`run_scalar` computes with that law, run by run (tests
check they agree)."""


def register_kernel(law, kernel):
    """Register the batched campaign kernel of the law registered as ``law``."""
    if not callable(kernel):
        raise FreejointValueError(f'kernel: expected a callable, got {kernel!r}')
    KERNELS[law] = kernel


def simulate_law(runs, gains=None, *, law='robust', law_params=None, processes=None,
                 **options):
    """
    Run every run of ``runs`` with the registered law ``law``; return their metrics.

    The law's batched kernel (:data:`KERNELS`, given the law's own gains) when it has
    one, else its scalar step run by run (:func:`run_scalar`, ``processes`` worker
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
    if law in KERNELS:
        return KERNELS[law](runs, gains, **({'law_params': own} if own else {}), **options)
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
    reported = RunValues(ctrl)
    theta = np.zeros(reported.theta_size)
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
        det = reported.conditioning(out)
        if not all(map(math.isfinite, (err2, t0, t1, det))):
            diverged = t
            break
        p_rec.append((px, py))
        err_mm.append(1000.0 * math.hypot(ex, ey))
        taus.append((abs(t0), abs(t1)))
        q3s.append(q[2])
        dets.append(det)
        theta = reported.theta(out)
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
