"""
Figures of a run against the plan: the measured end effector vs the planner's setpoints.

The controller's own reference (``ControllerState.position_desired``) is held, blended back
from a hold or carried forward when the loop cannot keep up; the error against it says how
well the law followed that reference, not whether the arm did its task. The figures here
judge the arm against the plan: the end effector measured at each state stamp (the
simulator's or driver's ``ee_position``) against the planner's streamed setpoint
interpolated (linearly, per axis) at that stamp.

:func:`plan_figures` is the one computation the analysis (``make analyze``), the soak, the
graph benchmark, the recorder's end-of-run summary and the controller's ``/diagnostics``
use. :func:`tracking_bound_mm` is the one definition of the per-case bound those runs are
judged by (1.5 x the offline runner's worst max error over seeds 0-9: 1.70 mm horizontal,
5.51 mm vertical on the reference machine), :func:`plan_met` the one verdict.

Plain numpy, no ROS: arrays of stamps [s], positions [m], velocities [m/s].
"""

import math

import numpy as np

from .errors import FreejointValueError, positive

BOUND_FACTOR = 1.5
"""The tracking bound of a real-time run: this x the offline runner's worst max error."""
BOUND_FACTOR_HOGS = 3.0
"""The same beside CPU hogs (``make soak --hogs N``)."""
BOUND_SEEDS = range(10)
"""The offline seeds the bound is taken over."""
SHARE_MET = 0.99
"""A run meets its bound when at least this share of the plan's moving ticks is within it."""
OFFLINE_WORST_MAX_MM = {'horizontal': (5, 1.1336738429506854),
                        'vertical': (6, 3.6728808453953605)}
"""(seed, max error [mm]) of the worst of :data:`BOUND_SEEDS` per case, as ``make offline``
computes it on the reference machine (test_plan_figures recomputes the seed: another CPU
gives other last bits). The tools that do not run the offline seeds take the bound from it."""

_BOUNDS = {}


def tracking_bound_mm(case, hogs=False, recompute=False, offline_max_mm=None):
    """
    Return the tracking bound of ``case`` [mm] and how it is made.

    The bound is :data:`BOUND_FACTOR` (:data:`BOUND_FACTOR_HOGS` with ``hogs``) x the
    offline runner's worst max error over the seeds :data:`BOUND_SEEDS` (the paper's
    circle, robust law, disturbance on: ``freejoint_core.offline.run_case``): with
    ``recompute`` run here, once per process (a few seconds per seed; what the soak
    does), else :data:`OFFLINE_WORST_MAX_MM` (1.70 mm horizontal, 5.51 mm vertical).
    Another arm (a spatial one: its offline twin, the graph's parameter files, circle and
    hold) is judged the same way from its own seeds' max errors, ``offline_max_mm``.

    Parameters
    ----------
    case : str
        'horizontal' or 'vertical' (the paper's arm), or the name of the arm whose
        ``offline_max_mm`` are given.
    hogs : bool
        The run had CPU hogs beside it.
    recompute : bool
        Run the offline seeds on this machine.
    offline_max_mm : sequence of float, optional
        The max errors [mm] of the arm's offline runner over :data:`BOUND_SEEDS`, run by
        the caller (the paper's runner does not run other arms).

    Returns
    -------
    tuple of float
        ``(bound_mm, factor, offline_worst_max_mm)``.

    Raises
    ------
    FreejointValueError
        ``case`` is not one of the paper's cases and no ``offline_max_mm`` are given, or
        these are not one finite number per seed.

    """
    from .offline import run_case
    factor = BOUND_FACTOR_HOGS if hogs else BOUND_FACTOR
    if offline_max_mm is not None:
        values = _array('offline_max_mm', offline_max_mm, (len(BOUND_SEEDS),))
        worst = float(np.max(values))
        return factor * worst, factor, worst
    if case not in ('horizontal', 'vertical'):
        raise FreejointValueError(f"case: expected 'horizontal' or 'vertical', got {case!r}")
    if not recompute:
        worst = OFFLINE_WORST_MAX_MM[case][1]
    else:
        if case not in _BOUNDS:
            _BOUNDS[case] = max(run_case(case, 'robust', seed)[0]['max_mm']
                                for seed in BOUND_SEEDS)
        worst = _BOUNDS[case]
    return factor * worst, factor, worst


def _array(name, value, shape):
    """Return ``value`` as a finite float array of ``shape`` (None: any length), or raise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a numeric array, got {value!r}') from None
    if arr.ndim != len(shape) or any(s is not None and a != s for a, s in zip(arr.shape,
                                                                              shape)):
        want = '(%s)' % ', '.join('n' if s is None else str(s) for s in shape)
        raise FreejointValueError(f'{name}: expected shape {want}, got {arr.shape}')
    if arr.size and not np.all(np.isfinite(arr)):
        row = int(np.nonzero(~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1))[0][0])
        raise FreejointValueError(f'{name}: non-finite value at row {row}')
    return arr


def _increasing(name, t):
    if t.size > 1 and np.any(np.diff(t) <= 0.0):
        k = int(np.nonzero(np.diff(t) <= 0.0)[0][0])
        raise FreejointValueError(f'{name}: stamps must increase, row {k + 1} is not after '
                                  f'row {k}')


def plan_figures(t, p, sp_t, sp_p, sp_v, bound_mm=None, held=None, plan_id=None,
                 plan_time=None, final=None, plan_end=None):
    """
    Return the figures of a run against the plan.

    Parameters
    ----------
    t : array_like, shape (N,)
        State stamps [s], increasing (subtract an origin first for system time: float64
        keeps 0.2 us at 1.8e9 s).
    p : array_like, shape (N, m)
        The end effector measured at those stamps [m] (m = 2 or 3).
    sp_t : array_like, shape (K,)
        The planner's setpoint stamps [s] on the same time base, increasing (one per
        stamp: the last one recorded).
    sp_p, sp_v : array_like, shape (K, m)
        Their positions [m] and velocities [m/s].
    bound_mm : float, optional
        The run's tracking bound [mm] (:func:`tracking_bound_mm`); None: no share.
    held : array_like of bool, shape (N,), optional
        States the controller did not track the plan from: no command answered them (the
        driver braked) or it held (``STATUS_HOLDING``). None: not known.
    plan_id, plan_time, final : array_like, shape (K,), optional
        The setpoints' plan, time within it [s] and end mark (``CartesianSetpoints``):
        per plan its lateness. All three or none.
    plan_end : dict, optional
        Plan id -> the time its outcome was decided [s] (the planner's ``plan_outcome``
        stamp, same time base): a plan aborted (stopped along its path, its setpoint
        standing) ends there, not at the next plan's start.

    Returns
    -------
    dict
        ``ticks`` (states within the setpoints' span, judged), ``rms_mm`` / ``max_mm``
        (error ``|p - p_plan|`` over them [mm]; None without any), ``moving_ticks`` (the
        judged states whose interpolated setpoint speed is non-zero: the plan moves),
        ``moving_max_mm``, ``within`` (moving ticks within ``bound_mm``), ``share``
        (``within / moving_ticks``; None without bound or moving tick), ``bound_mm``,
        ``moving_s`` (time the plan moved while states came: the moving ticks' intervals
        to the next state [s]), ``held_s`` (of it, the time the controller held or the
        driver braked [s]; None without ``held``), ``plans`` (list of dict per plan id >
        0 in the order they start: ``plan_id``, ``start_s`` (stamp of its first setpoint
        at plan time >= 0 [s]), ``end_s`` (stamp of its ``final`` setpoint, None: not
        completed - replaced, or the record ended), ``late_s`` (end minus the nominal end,
        the start plus the plan time at the end [s]: how long the plan's time stood
        still, None if not completed)), ``plans_completed``, ``late_max_s`` (largest
        ``late_s``, None if none completed), ``error_mm`` (N,) (NaN outside the span),
        ``moving`` (N,) bool.

    Raises
    ------
    FreejointValueError
        Naming the first bad argument (shapes, non-finite values, stamps not increasing,
        a negative bound).

    Notes
    -----
    A state stamped outside ``[sp_t[0], sp_t[-1]]`` has no plan and is not judged. A
    planner that pauses its plan's time (a feed hold) streams setpoints at rest meanwhile:
    those ticks do not count as moving, and the pause shows as the plan's lateness.

    """
    t = _array('t', t, (None,))
    n = t.shape[0]
    p = _array('p', p, (n, None))
    m = p.shape[1]
    if m not in (2, 3):
        raise FreejointValueError(f'p: expected 2 or 3 values per row, got {m}')
    _increasing('t', t)
    sp_t = _array('sp_t', sp_t, (None,))
    k = sp_t.shape[0]
    sp_p = _array('sp_p', sp_p, (k, m))
    sp_v = _array('sp_v', sp_v, (k, m))
    _increasing('sp_t', sp_t)
    if bound_mm is not None:
        bound_mm = positive('bound_mm', bound_mm)
    if held is not None:
        held = np.asarray(held)
        if held.shape != (n,):
            raise FreejointValueError(f'held: expected shape ({n},), got {held.shape}')
        held = held.astype(bool)
    extra = (plan_id, plan_time, final)
    if any(v is not None for v in extra) and any(v is None for v in extra):
        raise FreejointValueError('plan_id: plan_id, plan_time and final go together')

    error = np.full(n, np.nan)
    moving = np.zeros(n, dtype=bool)
    judged = np.zeros(n, dtype=bool)
    if k:
        judged = (t >= sp_t[0]) & (t <= sp_t[-1])
        tj = t[judged]
        plan = np.column_stack([np.interp(tj, sp_t, sp_p[:, j]) for j in range(m)])
        error[judged] = 1e3 * np.sqrt(np.sum((p[judged] - plan) ** 2, axis=1))
        speed = np.sqrt(np.sum(sp_v * sp_v, axis=1))
        moving[judged] = np.interp(tj, sp_t, speed) > 0.0
    err = error[judged]
    moving_err = error[moving]
    step = np.append(np.diff(t), 0.0)
    within = int(np.count_nonzero(moving_err <= bound_mm)) if bound_mm is not None else None
    out = {
        'ticks': int(err.size),
        'rms_mm': float(math.sqrt(float(np.mean(err * err)))) if err.size else None,
        'max_mm': float(err.max()) if err.size else None,
        'moving_ticks': int(moving_err.size),
        'moving_max_mm': float(moving_err.max()) if moving_err.size else None,
        'bound_mm': bound_mm,
        'within': within,
        'share': (within / moving_err.size if within is not None and moving_err.size
                  else None),
        'moving_s': float(step[moving].sum()),
        'held_s': None if held is None else float(step[moving & held].sum()),
        'error_mm': error,
        'moving': moving,
    }
    out.update(_plans(sp_t, extra, t, p, sp_p, error, moving, bound_mm, plan_end or {})
               if plan_id is not None else
               {'plans': [], 'plans_completed': 0, 'late_max_s': None})
    return out


PATH_COARSE = 10
"""Every this many of a plan's setpoints are compared first with each state; the nearest
segment is then searched within :data:`PATH_REFINE` setpoints of the nearest of them."""
PATH_REFINE = 2 * PATH_COARSE


def path_distance(p, path):
    """
    Return each point's distance to a polyline (the path, not the time along it).

    Parameters
    ----------
    p : numpy.ndarray, shape (N, m)
        Points [m].
    path : numpy.ndarray, shape (K, m)
        The polyline's vertices in order (K >= 1) [m], e.g. a plan's setpoints.

    Returns
    -------
    numpy.ndarray, shape (N,)
        The distance of each point to the nearest of the segments [m] (K = 1: to the
        vertex). The segment is searched within :data:`PATH_REFINE` vertices of the nearest
        of every :data:`PATH_COARSE`-th vertex: exact when the path's vertices are dense
        against its curvature and the points' distance to it (setpoints at 1 kHz on the
        paper's circle: 0.25 mm apart on a 200 mm radius).

    """
    # a plan that stood (a feed hold) repeats its vertex: one is the same curve
    path = path[np.r_[True, np.any(np.diff(path, axis=0) != 0.0, axis=1)]]
    n = p.shape[0]
    k = path.shape[0]
    out = np.full(n, np.inf)
    if n == 0:
        return out
    coarse = np.arange(0, k, PATH_COARSE)
    for lo in range(0, n, 2048):
        pts = p[lo:lo + 2048]
        d2 = np.sum((pts[:, None, :] - path[coarse][None, :, :]) ** 2, axis=2)
        near = coarse[np.argmin(d2, axis=1)]
        best = np.full(len(pts), np.inf)
        for off in range(-PATH_REFINE, PATH_REFINE + 1):
            a = np.clip(near + off, 0, k - 1)
            b = np.clip(a + 1, 0, k - 1)
            seg = path[b] - path[a]
            len2 = np.sum(seg * seg, axis=1)
            u = np.where(len2 > 0.0, np.sum((pts - path[a]) * seg, axis=1)
                         / np.where(len2 > 0.0, len2, 1.0), 0.0)
            u = np.clip(u, 0.0, 1.0)
            d = np.sqrt(np.sum((pts - path[a] - u[:, None] * seg) ** 2, axis=1))
            best = np.minimum(best, d)
        out[lo:lo + 2048] = best
    return out


def _plans(sp_t, extra, t, p, sp_p, error, moving, bound_mm, plan_end):
    """
    Return the per-plan figures of the setpoints' plan ids, times and end marks.

    Per plan also its states (stamped from its first setpoint at plan time >= 0 to its
    end, else to the next plan's start or the last setpoint, and not after its outcome in
    ``plan_end``): ``moving_ticks``, ``within``
    (None without bound), ``max_mm`` (against the plan at the stamp) and ``path_max_mm``
    (the largest distance to the plan's path, all its setpoints as a polyline: where the
    arm was relative to the path, whenever the plan's time stood or ran).
    """
    k = sp_t.shape[0]
    ids = np.asarray(extra[0])
    if ids.shape != (k,) or (k and (not np.all(np.isfinite(ids.astype(float)))
                                    or np.any(ids < 0))):
        raise FreejointValueError(f'plan_id: expected ({k},) ids >= 0, got {ids!r:.60}')
    ids = ids.astype(np.int64)
    ptime = _array('plan_time', extra[1], (k,))
    final = np.asarray(extra[2])
    if final.shape != (k,):
        raise FreejointValueError(f'final: expected shape ({k},), got {final.shape}')
    final = final.astype(bool)
    plans = []
    started = (ids > 0) & (ptime >= 0.0)
    order = list(dict.fromkeys(ids[started].tolist()))
    for i, pid in enumerate(order):
        rows = np.nonzero((ids == pid) & started)[0]
        first = rows[0]
        ends = rows[final[rows]]
        entry = {'plan_id': pid, 'start_s': float(sp_t[first]), 'end_s': None,
                 'late_s': None}
        if ends.size:
            end = ends[0]
            entry['end_s'] = float(sp_t[end])
            entry['late_s'] = float((sp_t[end] - sp_t[first]) - (ptime[end] - ptime[first]))
            stop = sp_t[end]
        elif i + 1 < len(order):
            stop = sp_t[np.nonzero((ids == order[i + 1]) & started)[0][0]]
        else:
            stop = sp_t[-1]
        if pid in plan_end:
            stop = min(stop, float(plan_end[pid]))
        span = (t >= sp_t[first]) & (t <= stop)
        mov = error[span & moving]
        entry['moving_ticks'] = int(mov.size)
        entry['within'] = (None if bound_mm is None
                           else int(np.count_nonzero(mov <= bound_mm)))
        entry['max_mm'] = float(np.nanmax(error[span])) if span.any() else None
        entry['path_max_mm'] = (1e3 * float(path_distance(p[span], sp_p[ids == pid]).max())
                                if span.any() else None)
        plans.append(entry)
    done = [e['late_s'] for e in plans if e['late_s'] is not None]
    return {'plans': plans, 'plans_completed': len(done),
            'late_max_s': max(done) if done else None}


EXCUSING_OUTCOMES = frozenset({'SUCCEEDED', 'CONTROLLER_NOT_READY', 'PAUSED_TOO_LONG'})
"""Outcomes that say why a plan was not tracked on every moving tick: it paused for a
controller that was not ready and finished late (SUCCEEDED with pauses), or was aborted
for that (the two codes naming it)."""


def outcome_excuses(figures, outcomes):
    """
    Return whether the plans' outcomes excuse a share below :data:`SHARE_MET`, and why.

    Each plan with a moving tick outside the bound must have an outcome saying it paused
    (SUCCEEDED after a pause) or was aborted for a controller that was not ready, and the
    arm must have stayed within the bound of that plan's path throughout (its
    ``path_max_mm``: braked where the guard stopped it, then back on the path): the plan
    stood while the arm did, and the arm never left the path the plan asked for.

    Parameters
    ----------
    figures : dict
        :func:`plan_figures` with a bound and plan ids.
    outcomes : dict
        Plan id -> ``(code_name, pauses)`` of the planner's ``plan_outcome`` (a plan
        without one is not excused: replaced, or the run ended before it did).

    Returns
    -------
    tuple of (bool, str)
        Excused, and the first reason it is not (or the plans it excuses).

    """
    bound = figures.get('bound_mm')
    if bound is None:
        return False, 'no bound'
    excused = []
    for plan in figures.get('plans', []):
        if plan.get('within') is None or plan['within'] == plan['moving_ticks']:
            continue
        pid = plan['plan_id']
        if pid not in outcomes:
            return False, f'plan {pid}: off the bound and no outcome'
        code, pauses = outcomes[pid]
        if code not in EXCUSING_OUTCOMES or (code == 'SUCCEEDED' and not pauses):
            return False, f'plan {pid}: off the bound and {code} with {pauses} pause(s)'
        if plan['path_max_mm'] is None or plan['path_max_mm'] > bound:
            return False, (f'plan {pid}: {code} but the arm left the path by '
                           f"{plan['path_max_mm']:.2f} mm > {bound:.3f} mm")
        excused.append(f'plan {pid} {code}, {pauses} pause(s), path max '
                       f"{plan['path_max_mm']:.2f} mm")
    return bool(excused), '; '.join(excused) or 'no plan off the bound'


def plan_met(figures, diverged=False, outcome_excuses=False):
    """
    Return whether a run met its bound against the plan.

    Parameters
    ----------
    figures : dict
        :func:`plan_figures` with a ``bound_mm``.
    diverged : bool
        The plant diverged (never met).
    outcome_excuses : bool
        The plan's own outcome says it was paused or aborted with a reason and the arm
        stayed within the bound of the path meanwhile (a planner with a goal outcome
        reports it; the caller judges it). Then a share below :data:`SHARE_MET` is met.

    Returns
    -------
    bool
        Not diverged, at least one moving tick judged, and :data:`SHARE_MET` of the moving
        ticks within the bound (or ``outcome_excuses``).

    """
    if diverged or figures.get('share') is None:
        return False
    return bool(figures['share'] >= SHARE_MET or outcome_excuses)


def format_figures(figures):
    """
    Return one line of the figures against the plan (what the tools print).

    Parameters
    ----------
    figures : dict
        :func:`plan_figures`.

    Returns
    -------
    str

    """
    def mm(value):
        return 'n/a' if value is None else '%.4f mm' % value
    parts = ['rms %s, max %s over %d ticks' % (mm(figures['rms_mm']), mm(figures['max_mm']),
                                               figures['ticks'])]
    if figures['share'] is not None:
        parts.append('%.1f %% of the %d moving ticks within %.3f mm' % (
            100.0 * figures['share'], figures['moving_ticks'], figures['bound_mm']))
    else:
        parts.append('%d moving ticks' % figures['moving_ticks'])
    if figures['held_s'] is not None:
        parts.append('held or braked %.3f s of the %.3f s the plan moved'
                     % (figures['held_s'], figures['moving_s']))
    total = len(figures['plans'])
    if total:
        parts.append('%d of %d plans completed%s' % (
            figures['plans_completed'], total, '' if figures['late_max_s'] is None
            else ', late by at most %.3f s' % figures['late_max_s']))
    return '; '.join(parts)
