"""
Offline failure scenarios: a joint fails mid-task, is detected, the law switches.

``python -m freejoint_core.failure_offline --actuated all --fail joint3@2.5 --seeds 0-9``
runs, per case and seed, the closed loop of ``freejoint_core.offline`` (70 % nominal,
|d| <= 0.5 N m, RK4 plant, 1 ms) on the circle and a hold after it, with the plant's
joint(s) failing at the given times (``Plant.fail_joint``) and a
``failure.Reconfigurer`` in the loop.  Per tick ``k``::

    (q, qd) = plant state at t_k
    reconfigurer.observe(q, qd, tau_{k-1} (all joints), effort_{k-1})  -> joint or None
    (a notice: the failed joint is reported at the first tick at or after its failure)
    on a detection / notice: reconfigurer.switch(...)
        tracking     -> controller.set_nominal(nominal with the new passive set), theta kept
        cannot_track -> least-harm torque (failure.least_harm_torque) from then on
    tau_k = controller.step(...) or the least-harm torque; plant.step(tau_k)

One record per run (``bags/offline/failures.json``): ``case``, ``seed``, ``actuated``,
``failed_joint`` (1-based list), ``failed_at_s``, ``detected_at_s`` (per failed joint, null if
never), ``detected_by``, ``max_mm`` (whole circle), ``max_mm_after_failure`` (circle
ticks from the first failure), ``hold_max_mm`` (the hold), ``effort_peak`` (per joint
[N m]), ``effort_ok`` (within ``EFFORT_LIMITS``), ``diverged_at_s``, ``verdict``,
``verdict_at_s``, ``false_alarm`` (a detection before any failure, or of a healthy joint),
``residual_peak`` (largest ``|r_i|`` before the first failure [N m]) and
``residual_peak_after_switch`` (after the last switch, while tracking), ``switches``.

``--suite`` runs every scenario of docs/failures.md and prints its tables.

Divergence: a non-finite state or torque, a joint faster than 1000 rad/s, or (while the
verdict is ``tracking``) a tracking error above 0.5 m.  Without ``--fail`` the runs measure
false alarms and the fault-free residual levels (``--levels``).
"""

import argparse
import dataclasses
import json
import math
import os
import sys
import time

import numpy as np

from .arm import CASES, DEFAULT_DT, NOMINAL_SCALE, table1
from .control import Gains
from .errors import FreejointValueError
from .failure import (DEFAULT_K_O, DEFAULT_MARGIN, DEFAULT_TICKS, least_harm_torque,
                      Reconfigurer, TRACKING)
from .internal import FreeLinkModulation
from .laws import make_law
from .offline import initial_state
from .plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant
from .trajectory import CircleQuintic

DEFAULT_OUT = 'bags/offline/failures.json'
EFFORT_LIMITS = (300.0, 200.0, 200.0)
"""Per-joint effort limits [N m] (config effort_limits 300/200; joint 3 taken as 200)."""
DEFAULT_NULLSPACE_KD = 3.0
"""Null-space damping [N m s/rad] of the fully actuated arm (``internal.NullSpace``)."""
HOLD_S = 5.0
"""Hold after the circle [s]."""
FAILURE_FREE_LINK_DAMPING = {'mode': 'rest', 'delta_max': 0.03, 'sat': 0.27}
"""``free_link_damping`` of :func:`run_failure_case` measured for the paper's arm with
joint 3 failing (docs/failures.md): ``FreeLinkModulation`` in the rests only, its shift
bounded by the filter (``sat`` = k3 ``delta_max``), never clipped. Vertical: the freed
link stops revolving; horizontal it does not (a free rotor) and only the rest's error
grows. The controller's config/fully_actuated/free_link_damping.yaml gives the same
numbers."""


def parse_fail(spec):
    """
    Parse ``joint3@2.5`` (1-based joint, time in s); several joined by ``,``.

    Returns
    -------
    list of (int, float)
        0-based joint index and time [s].

    """
    out = []
    for item in str(spec).split(','):
        name, sep, at = item.strip().partition('@')
        if not sep or not name.startswith('joint'):
            raise FreejointValueError(f'fail: expected jointN@T[,jointM@T2], got {spec!r}')
        try:
            j = int(name[5:]) - 1
            t = float(at)
        except ValueError:
            raise FreejointValueError(f'fail: expected jointN@T, got {item!r}') from None
        if j < 0 or j > 2 or not math.isfinite(t) or t < 0.0:
            raise FreejointValueError(f'fail: joint must be 1..3 and time >= 0, got {item!r}')
        out.append((j, t))
    return out


def run_failure_case(case, seed, fail=(), *, actuated='all', notice=False, effort=False,
                     duration=None, dt=DEFAULT_DT, dt_sub=DEFAULT_DT_SUB,
                     nominal_scale=NOMINAL_SCALE, dist_bound=DEFAULT_DIST_BOUND,
                     nullspace_kd=DEFAULT_NULLSPACE_KD, k_o=DEFAULT_K_O,
                     margin=DEFAULT_MARGIN, ticks=DEFAULT_TICKS, detect=True, assess=None,
                     diverge_m=0.5, diverge_qd=1000.0, record_trace=False,
                     internal_check=True, free_link_damping=None, law='robust',
                     law_params=None):
    """
    Run one failure scenario and return its record (and trace).

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        Table I case.
    seed : int
        Disturbance seed.
    fail : sequence of (int, float)
        Failing joints (0-based) and times [s] (``parse_fail``).
    actuated : {'all', 'paper'}
        Every joint driven at start (null-space damping ``nullspace_kd``), or joint 3 free.
    notice : bool
        The failure is reported (a driver's notice) at the first tick at or after it.
    effort : bool
        The effort detector compares the command with the plant's ``last_effort``.
    duration : float, optional
        Run length [s]; default the circle plus ``HOLD_S``.
    dt, dt_sub, nominal_scale, dist_bound : float
        As ``offline.run_case``.
    nullspace_kd : float
        Null-space damping of the fully actuated law [N m s/rad].
    k_o, margin, ticks : float, float, int
        Observer gain and residual detector settings.
    detect : bool
        False: no residual / effort detection (notices only, if any).
    assess : dict, optional
        Keyword arguments of ``failure.assess_passive_set``.
    diverge_m, diverge_qd : float
        Divergence limits (module notes).
    record_trace : bool
        Also return ``t``, ``q``, ``qd``, ``e``, ``tau`` (all joints), ``residual``.
    internal_check : bool
        False: the verdict checks only r and ``det`` at the pose, not the internal motion
        (to see what the law does with a passive set the check would refuse).
    free_link_damping : dict, optional
        ``freejoint_core.internal.FreeLinkModulation`` options: once a failure leaves the
        last joint alone free (r = m), the setpoint passes through that link's damping
        (from the switch on, its shift from 0). None (default): the paper's law alone.
        :data:`FAILURE_FREE_LINK_DAMPING` is the option measured (the controller's
        config/fully_actuated/free_link_damping.yaml; docs/failures.md).
    law, law_params
        The registered control law and the laws' own gains (``offline.run_case``).

    Returns
    -------
    record : dict
    trace : dict or None

    """
    if case not in CASES:
        raise FreejointValueError(f'case: expected one of {CASES}, got {case!r}')
    if actuated not in ('all', 'paper'):
        raise FreejointValueError(f"actuated: expected 'all' or 'paper', got {actuated!r}")
    traj = CircleQuintic()
    if duration is None:
        duration = traj.duration + HOLD_S
    n_ticks = int(round(duration / dt))
    real = table1(case)
    q0 = initial_state(real, 120.0, traj.sample(0.0)[0])
    if actuated == 'all':
        real = dataclasses.replace(real, passive=())
    nominal = real.scaled(nominal_scale)
    if free_link_damping is not None:
        try:        # checked now, on the arm with its last joint free, not at the failure
            FreeLinkModulation(dataclasses.replace(nominal, passive=(nominal.n - 1,)),
                               **dict(free_link_damping))
        except (TypeError, ValueError) as exc:
            raise FreejointValueError(f'free_link_damping: {exc}') from None
    ctrl = make_law(law, nominal, Gains(), params=law_params,
                    **({'nullspace_kd': nullspace_kd} if actuated == 'all' else {}))
    plant = Plant(real, dt_sub, dist_bound=dist_bound, seed=seed, q0=q0)
    fail = sorted(fail, key=lambda f: f[1])
    for j, at in fail:
        plant.fail_joint(j, at)
    rec = Reconfigurer(nominal, dt, k_o=k_o, margin=margin, ticks=ticks, effort=effort,
                       assess=assess, trajectory=traj if internal_check else None)
    n = real.n
    plant_active = real.active
    fail_at = dict(fail)
    detected = {}
    detected_by = None
    false_alarm = False
    verdict_at = None
    hold_q = None
    diverged = None
    tau_last = [0.0] * n
    modulation = None
    t_first = fail[0][1] if fail else math.inf
    err = np.full(n_ticks, np.nan)
    peak = [0.0] * n
    res_before = [0.0] * n
    res_after = [0.0] * n
    trace = {'t': [], 'q': [], 'qd': [], 'e': [], 'tau': [], 'residual': []} \
        if record_trace else None
    for k in range(n_ticks):
        t = k * dt
        q, qd = plant.q, plant.qd
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))) \
                or np.max(np.abs(qd)) > diverge_qd:
            diverged = t
            break
        px, py, vx, vy, ax, ay = traj.sample_tuple(t)
        found = []
        if detect:
            hit = rec.observe(q, qd, tau_last, plant.last_effort if effort else None)
            if hit is not None:
                found.append(hit)
        else:
            rec.observer.step(q, qd, tau_last, dt)
        if notice:
            for j, at in fail:
                if t >= at - 1e-9 and j not in detected and all(h[0] != j for h in found):
                    found.append((j, 'notice'))
        for j, how in found:
            if j not in fail_at or t < fail_at[j] - 1e-9:
                false_alarm = True
            detected[j] = round(t, 9)
            detected_by = detected_by or how
            sw = rec.switch(j, t, how, q, qd)
            if sw.verdict == TRACKING:
                ctrl.set_nominal(sw.nominal)    # (its null space dropped when r = 2)
                last_free = sw.nominal.passive == (sw.nominal.n - 1,)
                modulation = FreeLinkModulation(sw.nominal, **free_link_damping) \
                    if free_link_damping is not None and last_free else None
            elif verdict_at is None:
                verdict_at = round(t, 9)
                hold_q = q.copy()
        full = [0.0] * n
        if rec.verdict == TRACKING:
            try:
                if modulation is None:
                    out = ctrl.step(q, qd, (px, py), (vx, vy), (ax, ay), dt)
                else:
                    out = ctrl.step(q, qd, *modulation.step(q, qd, (px, py), (vx, vy),
                                                            (ax, ay), dt), dt)
            except (ArithmeticError, ValueError, np.linalg.LinAlgError):
                diverged = t
                break
            for j, v in zip(rec.nominal.active, out.tau.tolist()):
                full[j] = v
            e = out.p - (px, py)
        else:
            act = rec.active
            lim = [EFFORT_LIMITS[j] for j in act]
            tau = least_harm_torque(rec.nominal, act, q, qd, hold_q, limit=lim)
            for j, v in zip(act, tau.tolist()):
                full[j] = v
            e = ctrl.model.fk(q) - (px, py)
        if not all(map(math.isfinite, full)):
            diverged = t
            break
        err[k] = math.hypot(*e)
        peak = [max(a, abs(b)) for a, b in zip(peak, full)]
        if record_trace:
            trace['t'].append(t)
            trace['q'].append(q)
            trace['qd'].append(qd)
            trace['e'].append(e)
            trace['tau'].append(full)
            trace['residual'].append(rec.observer.residual.copy())
        res = rec.observer.residual.tolist()
        if t < t_first - 1e-9:
            res_before = [max(a, abs(b)) for a, b in zip(res_before, res)]
        elif rec.switches and rec.verdict == TRACKING:
            res_after = [max(a, abs(b)) for a, b in zip(res_after, res)]
        if rec.verdict == TRACKING and err[k] > diverge_m:
            diverged = t
            break
        try:
            plant.step([full[j] for j in plant_active], dt)
        except (ArithmeticError, ValueError):
            diverged = (k + 1) * dt
            break
        tau_last = full
    circle = int(round(traj.duration / dt))
    ok = np.isfinite(err)

    def _max(lo, hi):
        seg = err[lo:hi][ok[lo:hi]]
        return round(float(seg.max()) * 1e3, 6) if seg.size else None

    i_fail = int(math.ceil(t_first / dt - 1e-9)) if fail else None
    record = {
        'case': case, 'seed': seed, 'actuated': actuated,
        'failed_joint': [j + 1 for j, _ in fail] or None,
        'failed_at_s': [at for _, at in fail] or None,
        'detected_at_s': [detected.get(j) for j, _ in fail] or None,
        'detected_by': detected_by,
        'max_mm': _max(0, circle + 1),
        'max_mm_after_failure': _max(i_fail, circle + 1) if fail and i_fail <= circle
        else None,
        'hold_max_mm': _max(circle + 1, n_ticks),
        'effort_peak': [round(v, 6) for v in peak],
        'effort_ok': all(v <= lim for v, lim in zip(peak, EFFORT_LIMITS)),
        'diverged_at_s': diverged,
        'verdict': rec.verdict,
        'verdict_at_s': verdict_at,
        'false_alarm': false_alarm,
        'residual_peak': [round(v, 4) for v in res_before],
        'residual_peak_after_switch': [round(v, 4) for v in res_after] if rec.switches
        else None,
        'switches': [{'joint': s.joint + 1, 't': s.t, 'by': s.detected_by,
                      'passive': [p + 1 for p in s.passive], 'verdict': s.verdict,
                      'reason': s.assessment.reason} for s in rec.switches],
    }
    if record_trace:
        trace = {key: np.array(v) for key, v in trace.items()}
    return record, trace


def measure_levels(case, seeds, actuated, k_o=DEFAULT_K_O, duration=None):
    """
    Largest fault-free ``|r_i|`` per joint over the seeds (no detection in the loop).

    Returns
    -------
    numpy.ndarray, (n,)
        [N m].

    """
    worst = None
    for seed in seeds:
        _, tr = run_failure_case(case, seed, (), actuated=actuated, detect=False,
                                 record_trace=True, duration=duration)
        lv = np.max(np.abs(tr['residual']), axis=0)
        worst = lv if worst is None else np.maximum(worst, lv)
    return worst


SUITE = (
    # name, actuated, fail, notice, effort, duration (None: circle + hold), seeds (None: all)
    ('joint3@2.5 residual', 'all', 'joint3@2.5', False, False, 5.0, None),
    ('fault-free, all', 'all', '', False, False, None, None),
    ('joint2@2.5 residual', 'all', 'joint2@2.5', False, False, None, None),
    ('joint2+3@2.5 residual', 'all', 'joint2@2.5,joint3@2.5', False, False, None, None),
    ('fault-free, paper', 'paper', '', False, False, None, None),
    ('joint3@2.5 notice', 'all', 'joint3@2.5', True, False, 5.0, 3),
    ('joint3@2.5 effort', 'all', 'joint3@2.5', False, True, 5.0, 3),
)
"""The scenarios of ``--suite`` (docs/failures.md)."""


def summarise(name, records):
    """
    Return one Markdown table row per case of a scenario's records.

    Parameters
    ----------
    name : str
        The scenario's name (first column).
    records : list of dict
        The scenario's run records.

    Returns
    -------
    list of str

    """
    rows = []
    for case in CASES:
        recs = [r for r in records if r['case'] == case]
        if not recs:
            continue
        delays = [d - a for r in recs if r['failed_at_s'] and r['detected_at_s'][0] is not None
                  for d, a in [(min(x for x in r['detected_at_s'] if x is not None),
                                r['failed_at_s'][0])]]
        missed = sum(1 for r in recs if r['failed_at_s'] and
                     all(x is None for x in r['detected_at_s']))
        verdict_delay = [r['verdict_at_s'] - r['failed_at_s'][0] for r in recs
                         if r['verdict_at_s'] is not None and r['failed_at_s']]
        peaks = np.max([r['effort_peak'] for r in recs], axis=0)
        res = np.max([r['residual_peak'] for r in recs], axis=0)

        def rng(vals, scale=1.0, fmt='{:.3g}'):
            if not vals:
                return '-'
            lo, hi = min(vals) * scale, max(vals) * scale
            return fmt.format(lo) if lo == hi else f'{fmt.format(lo)}-{fmt.format(hi)}'

        maxes = [r['max_mm'] for r in recs if r['max_mm'] is not None]
        rows.append(
            f'| {name} | {case} | {len(recs)} | {sum(r["false_alarm"] for r in recs)} '
            f'| {rng(delays, 1e3, "{:.0f}")}{f" ({missed} missed)" if missed else ""} '
            f'| {rng(maxes)} | {rng(verdict_delay, 1e3, "{:.0f}")} '
            f'| {", ".join(sorted({r["verdict"] for r in recs}))} '
            f'| {sum(r["diverged_at_s"] is not None for r in recs)} '
            f'| {", ".join(f"{v:.3g}" for v in peaks)} '
            f'| {"yes" if all(r["effort_ok"] for r in recs) else "NO"} '
            f'| {", ".join(f"{v:.3g}" for v in res)} |')
    return rows


SUITE_HEADER = ('| scenario | case | runs | false alarms | detection delay (ms) | max (mm) '
                '| verdict delay (ms) | verdict | diverged | effort peak (N m) | within '
                'limits | fault-free residual peak (N m) |\n'
                '|---|---|---:|---:|---|---|---|---|---:|---|---|---|')


def _seeds(spec):
    lo, sep, hi = str(spec).partition('-')
    try:
        return list(range(int(lo), int(hi) + 1)) if sep else list(range(int(lo)))
    except ValueError:
        raise SystemExit(f'failure_offline: --seeds: expected N or A-B, got {spec!r}') from None


def _parse(argv):
    ap = argparse.ArgumentParser(
        prog='failure_offline', description='Offline joint-failure scenarios: '
        'a joint fails mid-task, the momentum residual (or effort, or a notice) detects it, '
        'the law switches or gives up (cannot_track); one record per run in '
        f'{DEFAULT_OUT}.')
    ap.add_argument('--actuated', choices=('all', 'paper'), default='all',
                    help="'all': every joint driven at start (default); 'paper': joint 3 free")
    ap.add_argument('--fail', default='', help='jointN@T[,jointM@T2] (1-based joint, s); '
                    'none: fault-free runs (false alarms)')
    ap.add_argument('--seeds', default='0-9', help='A-B or N (0..N-1); default 0-9')
    ap.add_argument('--cases', nargs='+', choices=CASES, default=list(CASES))
    ap.add_argument('--notice', action='store_true',
                    help='the failure is reported by the driver (notice path)')
    ap.add_argument('--effort', action='store_true',
                    help='measured effort available: also the effort detector')
    ap.add_argument('--no-detect', action='store_true',
                    help='no residual/effort detection (with --notice: notices only)')
    ap.add_argument('--no-internal-check', action='store_true',
                    help='verdict from r and det(Da Da^T) only (what the law does without '
                    'the internal-motion check)')
    ap.add_argument('--margin', type=float, default=DEFAULT_MARGIN)
    ap.add_argument('--ticks', type=int, default=DEFAULT_TICKS)
    ap.add_argument('--suite', action='store_true',
                    help='every scenario of docs/failures.md (ignores --fail, --actuated, '
                    '--notice, --effort); prints the tables')
    ap.add_argument('--only', nargs='+', default=None, metavar='TEXT',
                    help='with --suite: only the scenarios whose name contains one of these')
    ap.add_argument('--levels', action='store_true',
                    help='only measure the fault-free residual levels and print them')
    ap.add_argument('--out', default=None, help=f'records JSON (default {DEFAULT_OUT}); "" '
                    'to skip writing')
    return ap.parse_args(argv)


def main(argv=None):
    """Console entry ``python -m freejoint_core.failure_offline``."""
    args = _parse(sys.argv[1:] if argv is None else argv)
    seeds = _seeds(args.seeds)
    if args.levels:
        for case in args.cases:
            lv = measure_levels(case, seeds, args.actuated)
            print(f'{case} {args.actuated}: levels {np.round(lv, 3).tolist()} N m')
        return 0
    suite = SUITE if args.suite else (
        ('', args.actuated, args.fail, args.notice, args.effort, None, None),)
    records = []
    rows = []
    t0 = time.perf_counter()
    out = DEFAULT_OUT if args.out is None else args.out
    for name, actuated, spec, notice, effort, duration, n_seeds in suite:
        if args.only and not any(x in name for x in args.only):
            continue
        fail = parse_fail(spec) if spec else []
        recs = []
        for case in args.cases:
            for seed in seeds[:n_seeds]:
                rec, _ = run_failure_case(case, seed, fail, actuated=actuated, notice=notice,
                                          effort=effort, detect=not args.no_detect,
                                          margin=args.margin, ticks=args.ticks,
                                          duration=duration,
                                          internal_check=not args.no_internal_check)
                rec['scenario'] = name or spec or 'fault-free'
                recs.append(rec)
                print(json.dumps({k: v for k, v in rec.items() if k != 'switches'}),
                      flush=True)
        records.extend(recs)
        rows.extend(summarise(name or spec or 'fault-free', recs))
        if out:
            _write(out, records)
    print(f'failure_offline: {len(records)} runs, {time.perf_counter() - t0:.1f} s wall')
    print(SUITE_HEADER)
    print('\n'.join(rows))
    if out:
        print(f'records written to {out}')
    return 0


def _write(path, records):
    os.makedirs(os.path.dirname(path) or '.', exist_ok=True)
    with open(path, 'w') as fh:
        json.dump(records, fh, indent=1)


if __name__ == '__main__':
    sys.exit(main())
