"""
Tasks back to back offline: N circles, with or without rests, one record per circle.

The loop is the offline runner's (``freejoint_core.offline``: 1 ms control, RK4 plant at
``dt_sub``, 70 % nominal model, disturbance ``|d| <= 0.5 N m`` seeded by ``seed``) run
over a timeline of ``circles`` copies of the 5-s quintic circle; after every circle but
the last the setpoint rests at the circle's start point for ``rest`` s, after the last
for ``hold`` s.  Options (all off by default: the paper's law on the paper's start):

* ``start``: ``'paper'`` (q3 = 120 deg, the offline runner's), ``'hanging'`` (the free
  link hanging at the start point, :func:`freejoint_core.internal.hanging_pose`);
  4-link arm: ``'example'`` (``FOUR_LINK_Q0``) or ``'equilibrium'`` (the static
  equilibrium of the free base nearest it);
* ``stabilise``: keyword arguments of :class:`freejoint_core.internal.FreeLinkModulation`
  (r = m: the free link damped through a bounded modulation of the reference);
* ``nullspace``: :class:`freejoint_core.internal.NullSpace` (r > m);
* ``arm``: ``'paper'`` (Table I, joint 3 free, or every joint driven with
  ``actuated='all'``) or ``'four_link'`` (the shipped example, base joint free,
  simulated by MuJoCo, nominal model from Pinocchio).

Per circle (``circle`` from 1): ``rms_mm``, ``max_mm`` (the error to the planned path,
modulation included), ``effort_peak`` (per joint, N m), ``swing_deg`` (the free link's
swing amplitude about hanging at the circle's end, from its energy,
:func:`freejoint_core.internal.free_link_swing`; vertical paper arm only, else None),
``free_rate_dps`` (the free link's absolute rate at the circle's end), ``swing_max_deg``
(largest swing during the circle), ``null_speed_max`` (largest null-space speed of the
active joints, rad/s, r > m only), and over the rest after it: ``rest_swing_deg`` (at
its end), ``settle_s`` (time from the circle's end until the swing stays <= 2 deg, None
if not within the rest), ``rest_q3_range_deg``; ``diverged_at_s`` (the run's stop time
if it stopped in or after this circle's start, else None).  Circles never reached are
not recorded.
"""

import dataclasses
import math

import numpy as np

from .arm import ArmModel, CASES, NOMINAL_SCALE, table1
from .control import Gains
from .errors import FreejointValueError, positive
from .internal import (equilibrium_pose, free_link_swing, FreeLinkModulation, hanging_pose,
                       initial_state, null_space_velocity)
from .laws import make_law
from .plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant
from .trajectory import CircleQuintic

ARMS = ('paper', 'four_link')
STARTS = ('paper', 'hanging', 'example', 'equilibrium')
SETTLE_DEG = 2.0
"""Swing [deg] under which the free link counts as settled."""
FOUR_LINK_HANGING_GUESS = tuple(math.radians(a) for a in (-134.0, 149.0, 29.0, 29.0))
"""Start of the 4-link equilibrium search [rad]: the arm hanging below its free base."""
_BLOWUP = (ArithmeticError, ValueError, np.linalg.LinAlgError)


def arm_circle(arm):
    """Return the circle :func:`run_circles` runs for ``arm`` (one of ``ARMS``)."""
    if arm == 'paper':
        return CircleQuintic()
    from .urdf import FOUR_LINK_CIRCLE
    return CircleQuintic(**FOUR_LINK_CIRCLE)


def _setup(arm, case, actuated, nominal_scale, start, dt_sub, dist, seed):
    """Real arm, plant, nominal model and the circle of the chosen arm."""
    if arm == 'paper':
        real = table1(case)
        start_arm = real
        if actuated == 'all':
            real = dataclasses.replace(real, passive=())
        traj = arm_circle(arm)
        p0 = traj.sample(0.0)[0]
        if start == 'paper':
            q0 = initial_state(start_arm, start=p0)
        elif start == 'hanging':
            q0 = hanging_pose(start_arm, p0)
        else:
            raise FreejointValueError(f"start: expected 'paper' or 'hanging', got {start!r}")
        plant = Plant(real, dt_sub, dist_bound=dist, seed=seed, q0=q0)
        nominal = real.scaled(nominal_scale)
        return real, plant, nominal, None, traj
    from .mujoco_plant import MujocoPlant
    from .pin_model import PinArmModel
    from .urdf import four_link_arm, FOUR_LINK_Q0
    urdf_arm = four_link_arm(case)
    traj = arm_circle(arm)
    if start in ('example', 'paper'):
        q0 = np.array(FOUR_LINK_Q0)
    elif start == 'equilibrium':
        vert = four_link_arm('vertical').params
        q0 = equilibrium_pose(ArmModel(vert), traj.sample(0.0)[0], FOUR_LINK_HANGING_GUESS)
    else:
        raise FreejointValueError(f"start: expected 'example' or 'equilibrium', got {start!r}")
    plant = MujocoPlant(urdf_arm, dt_sub, dist_bound=dist, seed=seed, q0=q0)
    model = PinArmModel(urdf_arm, nominal_scale)
    return urdf_arm.params, plant, model.params, model, traj


def run_circles(case, variant='robust', seed=0, *, circles=1, rest=0.0, hold=0.0,
                arm='paper', actuated='paper', start='paper', stabilise=None, nullspace=None,
                dt=1e-3, dt_sub=DEFAULT_DT_SUB, nominal_scale=NOMINAL_SCALE,
                dist_bound=DEFAULT_DIST_BOUND, gains=None, diverge_m=0.5, diverge_qd=1000.0,
                record_trace=False, law='robust', law_params=None):
    """
    Run ``circles`` circles back to back and return one record per circle.

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        Gravity case.
    variant : {'robust', 'exact'}
        ``robust``: nominal ``nominal_scale``, disturbance ``dist_bound``; ``exact``:
        the real model, no disturbance.
    seed : int
        Disturbance seed.
    circles : int
        Number of circles, >= 1.
    rest, hold : float
        Rest after each circle but the last, hold after the last [s], >= 0; integer
        multiples of ``dt``.
    arm : {'paper', 'four_link'}
        The arm (module notes).
    actuated : {'paper', 'all'}
        Paper arm: joint 3 free, or every joint driven.
    start : str
        One of ``STARTS`` (module notes).
    stabilise : dict or None
        Keyword arguments of ``FreeLinkModulation`` (None: off).
    nullspace : NullSpace or None
        The controller's null-space option (None: off).
    dt, dt_sub : float
        Control period and plant step [s].
    nominal_scale, dist_bound : float
        Nominal/real ratio and disturbance bound [N m] of ``robust``.
    gains : Gains, optional
        Controller gains (the paper's by default).
    diverge_m, diverge_qd : float
        Error [m] and joint speed [rad/s] beyond which the run stops.
    record_trace : bool
        Also return per-tick ``t``, ``q``, ``qd``, ``e``, ``tau``, ``delta``.
    law, law_params
        The registered control law and the laws' own gains (``offline.run_case``).

    Returns
    -------
    records : list of dict
        One per circle reached (module notes for the keys).
    trace : dict or None

    """
    if case not in CASES:
        raise FreejointValueError(f'case: expected one of {CASES}, got {case!r}')
    if variant not in ('robust', 'exact'):
        raise FreejointValueError(f"variant: expected 'robust' or 'exact', got {variant!r}")
    if arm not in ARMS:
        raise FreejointValueError(f'arm: expected one of {ARMS}, got {arm!r}')
    if actuated not in ('paper', 'all') or (actuated == 'all' and arm != 'paper'):
        raise FreejointValueError(f"actuated: expected 'paper' (or 'all' for the paper arm), "
                                  f'got {actuated!r}')
    if start not in STARTS:
        raise FreejointValueError(f'start: expected one of {STARTS}, got {start!r}')
    if isinstance(circles, bool) or not isinstance(circles, (int, np.integer)) or circles < 1:
        raise FreejointValueError(f'circles: expected an int >= 1, got {circles!r}')
    dt = positive('dt', dt)
    rest = positive('rest', rest, allow_zero=True)
    hold = positive('hold', hold, allow_zero=True)
    n_sub = round(dt / positive('dt_sub', dt_sub))
    exact = variant == 'exact'
    dist = 0.0 if exact else dist_bound
    scale = 1.0 if exact else positive('nominal_scale', nominal_scale)
    real, plant, nominal, model, traj = _setup(arm, case, actuated, scale, start,
                                               dt_sub * 1.0, dist, seed)
    del n_sub
    ctrl = make_law(law, nominal, Gains() if gains is None else gains, model=model,
                    params=law_params, **({} if nullspace is None else {'nullspace': nullspace}))
    mod = None if stabilise is None else FreeLinkModulation(nominal, **dict(stabilise))
    swing_on = arm == 'paper' and actuated == 'paper' and real.gravity > 0.0
    act = list(real.active)
    null_model = ArmModel(nominal) if real.r > 2 and model is None else model

    n_circle = int(round(traj.duration / dt))
    n_rest = int(round(rest / dt))
    n_hold = int(round(hold / dt))
    for name, n_t, val in (('rest', n_rest, rest), ('hold', n_hold, hold)):
        if abs(n_t * dt - val) > 1e-9:
            raise FreejointValueError(f'{name}: {val} s is not a multiple of dt = {dt} s')
    p_start = tuple(traj.sample(0.0)[0])
    circle_des = [traj.sample_tuple(k * dt) for k in range(n_circle)]
    rest_des = p_start + (0.0, 0.0, 0.0, 0.0)

    records = []
    trace = {'t': [], 'q': [], 'qd': [], 'e': [], 'tau': [], 'delta': []} \
        if record_trace else None
    t_k = 0
    diverged = None
    isfinite = math.isfinite
    limit2 = diverge_m * diverge_m
    for c in range(circles):
        after = n_rest if c < circles - 1 else n_hold
        err = []
        eff = np.zeros(real.r)
        swing_max = 0.0
        null_max = 0.0
        end_state = None
        rest_swings = []
        rest_q3 = []
        for j in range(n_circle + after):
            des = circle_des[j] if j < n_circle else rest_des
            q, qd = plant.q, plant.qd
            if j == n_circle:
                end_state = (q, qd)
            try:
                sp = (des[0:2], des[2:4], des[4:6])
                if mod is not None:
                    sp = mod.step(q, qd, *sp, dt)
                out = ctrl.step(q, qd, *sp, dt)
                tau = out.tau
                ex, ey = (out.p - des[0:2]).tolist()
                if not (isfinite(ex) and isfinite(ey) and np.all(np.isfinite(tau))):
                    raise ArithmeticError('non-finite')
            except _BLOWUP:
                diverged = t_k * dt
                break
            e2 = ex * ex + ey * ey
            if j < n_circle:
                err.append(e2)
                np.maximum(eff, np.abs(tau), out=eff)
                if null_model is not None and j % 10 == 0:
                    null_max = max(null_max, null_space_velocity(
                        null_model.effective(q)[0], qd[act]))
            if swing_on:
                sw = free_link_swing(real, q, qd)
                if j < n_circle:
                    swing_max = max(swing_max, sw)
                else:
                    rest_swings.append(sw)
            if j >= n_circle:
                rest_q3.append(float(q[-1]))
            if record_trace:
                trace['t'].append(t_k * dt)
                trace['q'].append(q)
                trace['qd'].append(qd)
                trace['e'].append((ex, ey))
                trace['tau'].append(tau)
                trace['delta'].append(np.zeros(2) if mod is None else mod.delta.copy())
            if e2 > limit2 or float(np.max(np.abs(qd))) > diverge_qd:
                diverged = t_k * dt
                break
            try:
                plant.step(tau, dt)
            except _BLOWUP:
                diverged = (t_k + 1) * dt
                break
            t_k += 1
        if not err:
            break
        if end_state is None:
            end_state = (plant.q, plant.qd)
        q_end, qd_end = end_state
        err_mm = 1e3 * np.sqrt(np.array(err))
        settle = None
        if rest_swings:
            ok = np.degrees(rest_swings) <= SETTLE_DEG
            if ok[-1]:
                bad = np.nonzero(~ok)[0]
                settle = 0.0 if bad.size == 0 else float((bad[-1] + 1) * dt)
        records.append({
            'case': case,
            'variant': _label(variant, arm, actuated, start, stabilise, nullspace, rest),
            'seed': int(seed),
            'circle': c + 1,
            'rms_mm': float(math.sqrt(float(np.mean(err_mm * err_mm)))),
            'max_mm': float(err_mm.max()),
            'effort_peak': [float(v) for v in eff],
            'swing_deg': math.degrees(free_link_swing(real, q_end, qd_end)) if swing_on
            else None,
            'free_rate_dps': math.degrees(float(np.sum(qd_end))) if arm == 'paper' else None,
            'swing_max_deg': math.degrees(swing_max) if swing_on else None,
            'null_speed_max': null_max if null_model is not None else None,
            'rest_s': after * dt,
            'rest_swing_deg': math.degrees(rest_swings[-1]) if rest_swings else None,
            'settle_s': settle,
            'rest_q3_range_deg': [math.degrees(min(rest_q3)), math.degrees(max(rest_q3))]
            if rest_q3 else None,
            'diverged_at_s': diverged,
        })
        if diverged is not None:
            break
    if record_trace:
        trace = {k: np.array(v) for k, v in trace.items()}
    return records, trace


def _label(variant, arm, actuated, start, stabilise, nullspace, rest):
    """Variant label of a run: the options that are not the paper's, joined."""
    parts = [variant]
    if arm != 'paper':
        parts.append(arm)
    if actuated != 'paper':
        parts.append('all')
    if start != 'paper':
        parts.append(start)
    if stabilise is not None:
        parts.append('stab-' + dict(stabilise).get('mode', 'always'))
    if nullspace is not None:
        parts.append(f'ns{nullspace.kd:g}' if not isinstance(nullspace.kd, tuple) else 'ns')
        if nullspace.inverse == 'weighted':
            parts.append('weighted')
    parts.append(f'rest{rest:g}')
    return ' '.join(parts)


DEFAULT_OUT = 'bags/offline/circles.json'
NULLSPACE_KD = 5.0
"""Null-space damping [N m s/rad] that ``stabilised_options`` turns on for r > m."""
FOUR_LINK_TASK_GAINS = {'K': 200.0, 'Lambda': 100.0}
"""Task gains [1/s] of the 4-link example with its internal motion stabilised
(``stabilised_options``): twice the paper's K, Lambda. Vertical, 10 circles back to back,
seeds 0-9: max error 0.71-0.92 mm (the paper's gains: 2.2-2.8 mm), peak effort 9 N m either
way (docs/internal-motion.md)."""
MODULATION = {'delta_max': 0.01, 'k2_rest': 1.0, 'rest_after': 1.5}
"""``FreeLinkModulation`` options of ``stabilised_options`` (the rest its defaults): the
10-mm bound, and a settle step once the setpoint has rested 1.5 s (rate gain 0.2 -> 1.0;
2.0 pumped the swing up: docs/internal-motion.md)."""


HORIZONTAL_SETTLE = {'mode': 'settle', 'delta_max': 0.03, 'settle_window': 0.6}
"""``FreeLinkModulation`` options of the horizontal paper arm (``stabilised_options``): in
the first 0.6 s of each rest after a circle the free rotor is slowed by a shift of the end
effector of at most 3 cm (drive ``k2`` 0.2 m/s, saturated at ``k3 * 0.03`` = 0.27 m/s^2),
then the shift returns to 0 (``internal.SETTLE_RETURN_GAINS``). 30 circles with 1-s rests, seeds
0-9: none lost, max 0.83-1.13 mm (the paper's law loses seed 0 in circle 18); a 2-cm
bound that clipped the shift lost the arm (docs/internal-motion.md)."""


def stabilised_options(case, arm='paper', actuated='paper', delta_max=None):
    """
    Return the internal-motion stabilisation of an arm and case (``--stabilise``), as options.

    * paper arm, joint 3 free, vertical: start with the free link hanging and the free
      link damped through the bounded reference modulation (always on);
    * paper arm, joint 3 free, horizontal: no restoring force, the free link a free rotor
      that millimetres of end-effector motion cannot slow: the paper's law while tracking,
      and in the first 0.6 s of each rest after a task a shift of at most 3 cm that slows it
      (``HORIZONTAL_SETTLE``, ``mode='settle'``);
    * r > m (every joint driven, or the 4-link arm): null-space damping
      ``kd = NULLSPACE_KD``; the 4-link arm starts at its hanging equilibrium, with the
      task gains ``FOUR_LINK_TASK_GAINS``.

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        Gravity case.
    arm : {'paper', 'four_link'}
        The arm.
    actuated : {'paper', 'all'}
        Paper arm's actuation.
    delta_max : float or None
        Bound of the modulation's task deviation [m]; None: the class default.

    Returns
    -------
    dict
        ``start``, ``stabilise``, ``nullspace``, ``gains`` keywords of :func:`run_circles`.

    """
    from .internal import NullSpace
    if arm == 'four_link':
        return {'start': 'equilibrium', 'nullspace': NullSpace(kd=NULLSPACE_KD),
                'gains': Gains(**FOUR_LINK_TASK_GAINS)}
    if actuated == 'all':
        return {'nullspace': NullSpace(kd=NULLSPACE_KD)}
    if case == 'vertical':
        mod = dict(MODULATION)
        if delta_max is not None:
            mod['delta_max'] = delta_max
        return {'start': 'hanging', 'stabilise': mod}
    mod = dict(HORIZONTAL_SETTLE)
    if delta_max is not None:
        mod['delta_max'] = delta_max
    return {'stabilise': mod}


def write_circles(path, records):
    """
    Write per-circle records as a JSON list (parent directories created).

    Parameters
    ----------
    path : str
        Output file.
    records : list of dict
        From :func:`run_circles`.

    """
    import json
    import os
    parent = os.path.dirname(path)
    if parent:
        os.makedirs(parent, exist_ok=True)
    text = json.dumps(records, indent=1, allow_nan=False)
    with open(path + '.tmp', 'w', encoding='utf-8') as fh:
        fh.write(text + '\n')
    os.replace(path + '.tmp', path)


def summarize_circles(records, from_circle=2):
    """
    One summary row per (case, variant): the acceptance figures over seeds and circles.

    Parameters
    ----------
    records : list of dict
        From :func:`run_circles`.
    from_circle : int
        First circle of the "from circle 2 on" figures.

    Returns
    -------
    list of dict
        ``case``, ``variant``, ``runs``, ``diverged``, ``circles``, ``rms_mean_mm``,
        ``rms_worst_mm``, ``max_mm``, ``effort_peak`` (max over joints and circles >=
        ``from_circle``), ``effort_peak_all``, ``swing_end_max_deg`` (circles >=
        ``from_circle``), ``settle_max_s``, ``rest_swing_max_deg``.

    """
    groups = {}
    for r in records:
        groups.setdefault((r['case'], r['variant']), []).append(r)
    rows = []
    for (case, variant), recs in groups.items():
        runs = {r['seed'] for r in recs}
        div = {r['seed'] for r in recs if r['diverged_at_s'] is not None}
        late = [r for r in recs if r['circle'] >= from_circle] or recs
        swings = [r['swing_deg'] for r in late if r['swing_deg'] is not None]
        settles = [r['settle_s'] for r in recs if r['rest_s'] > 0]
        rest_sw = [r['rest_swing_deg'] for r in recs if r['rest_swing_deg'] is not None]
        rows.append({
            'case': case, 'variant': variant, 'runs': len(runs), 'diverged': len(div),
            'circles': len(recs),
            'rms_mean_mm': float(np.mean([r['rms_mm'] for r in recs])),
            'rms_worst_mm': max(r['rms_mm'] for r in recs),
            'max_mm': max(r['max_mm'] for r in recs),
            'effort_peak': max(max(r['effort_peak']) for r in late),
            'effort_peak_all': max(max(r['effort_peak']) for r in recs),
            'swing_end_max_deg': max(swings) if swings else None,
            'settle_max_s': (None if any(s is None for s in settles) else max(settles))
            if settles else None,
            'rest_swing_max_deg': max(rest_sw) if rest_sw else None,
        })
    return rows


def format_circle_summary(rows):
    """Format :func:`summarize_circles` rows as a Markdown table."""
    def f(v, fmt):
        return '-' if v is None else format(v, fmt)
    lines = ['| case | variant | runs | diverged | circles | rms mean / worst (mm) | max (mm) '
             '| peak effort c>=2 / all (N m) | swing at end c>=2 (deg) | rest swing (deg) '
             '| settle (s) |', '|---|---|---:|---:|---:|---|---:|---|---:|---:|---:|']
    for r in rows:
        lines.append(
            f'| {r["case"]} | {r["variant"]} | {r["runs"]} | {r["diverged"]} | {r["circles"]} '
            f'| {r["rms_mean_mm"]:.3g} / {r["rms_worst_mm"]:.3g} | {r["max_mm"]:.3g} '
            f'| {r["effort_peak"]:.3g} / {r["effort_peak_all"]:.3g} '
            f'| {f(r["swing_end_max_deg"], ".3g")} | {f(r["rest_swing_max_deg"], ".3g")} '
            f'| {f(r["settle_max_s"], ".3g")} |')
    return '\n'.join(lines)


def circle_study(cases, seeds, circles, rest, hold=0.0, stabilise=False, arm='paper',
                 actuated='paper', variant='robust', delta_max=None, progress=None,
                 **options):
    """
    Run :func:`run_circles` over cases and seeds.

    Parameters
    ----------
    cases : iterable of str
        Cases.
    seeds : iterable of int
        Seeds.
    circles : int
        Circles per run.
    rest, hold : float
        Rest between circles and hold after the last [s].
    stabilise : bool
        Apply :func:`stabilised_options`.
    arm, actuated, variant : str
        See :func:`run_circles`.
    delta_max : float or None
        Modulation bound [m] (with ``stabilise``).
    progress : callable, optional
        Called with each run's records.
    **options
        Further :func:`run_circles` keywords (override the stabilised ones).

    Returns
    -------
    list of dict
        All per-circle records.

    """
    out = []
    for case in cases:
        opts = stabilised_options(case, arm, actuated, delta_max) if stabilise else {}
        opts.update(options)
        for seed in seeds:
            recs, _ = run_circles(case, variant, seed, circles=circles, rest=rest, hold=hold,
                                  arm=arm, actuated=actuated, **opts)
            out.extend(recs)
            if progress is not None:
                progress(recs)
    return out
