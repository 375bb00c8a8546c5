"""
Offline closed-loop runner: the paper's simulation study (Sec. 4) without ROS.

Closed loop, tick ``k = 0 .. N-1`` with ``t_k = k dt`` and ``N = duration / dt``
(5000 ticks for 5 s at 1 ms)::

    (q, qd) = plant state at t_k
    (p_d, pd_d, pdd_d) = trajectory.sample(t_k)
    out = controller.step(q, qd, p_d, pd_d, pdd_d, dt)      -> tau_k
    plant.step(tau_k, dt)                                    -> state at t_{k+1}

The recorded ticks are ``t_0 .. t_{N-1}`` (0 .. 4.999 s): the state the last
plant step produces at ``t_N = duration`` is not a tick and is not recorded.
The ROS graph replicates exactly this loop, so its records equal these.

Variants (all with the paper's gains unless ``gains`` is given):

* ``robust``: nominal model ``table1(case).scaled(nominal_scale)`` (70 %),
  random joint disturbance ``|d_i| <= dist_bound`` (0.5 N m) seeded by ``seed``;
* ``robust_off``: as ``robust`` but ``Gains(robust=False)``: ``dv = 0`` and no
  adaptation (plain nominal inverse dynamics, eq. 15 with ``v_r = v``);
* ``exact``: nominal == real, no disturbance, robust term on.

Initial state: ``q3(0) = q3_0_deg`` (120 deg), ``q1, q2`` from
``ArmModel.ik(p_d(0), [q3], branch=+1)`` so the end effector starts on the
desired start point ``(0.2, 0)`` (for q3 = 120 deg: q1 = -78.46 deg,
q2 = 96.93 deg), at rest.

Fixed command delay (``delay_ticks = m``, default 0 = the loop above): the
command computed from the state of tick ``k`` acts over ``[t_{k+m},
t_{k+m+1}]``; over the first ``m`` periods, before any delayed command
arrives, the command of tick 0 acts (the arm is driven from the start, as if
the first command had been there; neither braked nor limp).  The recorded
torque of tick ``k`` is the one computed at ``k``.  With ``predict`` the law
runs on the state predicted for ``t_{k+m}`` by ``delay.StatePredictor`` (the
nominal model integrated under the commands already sent, see
``freejoint_core.delay``) and on the setpoint of ``t_k`` shifted to ``t_{k+m}``
by ``delay.extrapolate_setpoint``; the recorded error is still the measured
``p(t_k) - p_d(t_k)``.  Delayed runs are labelled ``<variant> d<m>`` (``+p``
with the predictor).  ``--delay-study`` prints the table of docs/delay.md.

Divergence: the run stops, without raising, at the first tick whose state or
controller output is not finite (or whose computation raises), whose
tracking error exceeds ``diverge_m`` (0.5 m), or whose fastest joint turns
faster than ``diverge_qd`` (1000 rad/s: half a radian per 0.5 ms RK4 step,
beyond which the integration no longer means anything); a tick with a finite state is
recorded even if it is the one that stops the run. ``diverged_at_s`` is that
tick's time (if the plant step itself fails, the next tick's time). Records
never hold NaN.
"""

import argparse
import dataclasses
import math
import sys
import time

import numpy as np

from .arm import CASES, DEFAULT_DT, NOMINAL_SCALE, table1
from .control import Gains
from .delay import DEFAULT_BIAS_GAIN, extrapolate_setpoint, StatePredictor
from .errors import FreejointValueError, positive
from .internal import DEFAULT_Q3_0_DEG, initial_state, NullSpace  # noqa: F401 (API)
from .law_base import finite_internal, internal_size, RunValues
from .laws import make_law
from .metrics import compute_record, format_summary, format_table, write_records
from .models import make_model
from .plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant
from .trajectory import CircleQuintic

VARIANTS = ('robust', 'robust_off', 'exact')
ACTUATED = ('paper', 'all')
DEFAULT_OUT = 'bags/offline/metrics.json'
# Errors that mean "the numbers blew up" inside the model/controller/plant.
_BLOWUP = (ArithmeticError, ValueError, np.linalg.LinAlgError)


def run_case(case, variant, seed, *, q3_0_deg=DEFAULT_Q3_0_DEG, dt=DEFAULT_DT,
             dt_sub=DEFAULT_DT_SUB, duration=5.0, nominal_scale=NOMINAL_SCALE,
             dist_bound=DEFAULT_DIST_BOUND, gains=None, record_trace=False,
             trajectory=None, diverge_m=0.5, diverge_qd=1000.0, delay_ticks=0, predict=False,
             bias_gain=DEFAULT_BIAS_GAIN, predict_ticks=None, echo=False, delay_jitter=0,
             actuated='paper', nullspace=None, law='robust', law_params=None,
             loss_rate=0.0, loss_burst=1):
    """
    Run one closed-loop case and return its metrics record (and trace).

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        Table I case (Case 1 / Case 2).
    variant : {'robust', 'robust_off', 'exact'}
        See the module notes.
    seed : int or None
        Disturbance seed (unused, but recorded, by ``exact``).
    q3_0_deg : float
        Initial passive joint angle (deg).
    dt : float
        Control period (s).
    dt_sub : float
        Plant RK4 step (s); ``dt`` must be an integer multiple.
    duration : float
        Run length (s); ``duration / dt`` ticks (an integer).
    nominal_scale : float
        Nominal/real ratio of masses, inertias and COM distances (robust variants).
    dist_bound : float
        Disturbance bound (N m) of the robust variants; ``exact`` uses 0.
    gains : Gains, optional
        Controller gains (paper's by default); ``robust_off`` forces
        ``robust=False``.
    record_trace : bool
        Also return the per-tick arrays.
    trajectory : CircleQuintic, optional
        Desired path; default the paper's circle (centre 0, r 0.2 m, 5 s).
    diverge_m : float
        Error (m) beyond which the run is stopped as diverged.
    diverge_qd : float
        Joint speed (rad/s) beyond which the run is stopped as diverged.
    delay_ticks : int
        Fixed command delay ``m`` (control periods), >= 0; see the module notes.
    predict : bool
        Compensate the delay with ``delay.StatePredictor`` (no effect at m = 0).
    bias_gain : float
        The predictor's ``bias_gain`` (0: plain nominal prediction).
    predict_ticks : int, optional
        Horizon of the predictor (periods), >= 0; default ``delay_ticks`` (a
        different value measures a mis-estimated delay).
    echo : bool
        The predictor is told the command applied over the last period (as
        ``joint_states.effort`` reports it) and takes its horizon from it
        (``StatePredictor.ticks_since``; ``predict_ticks`` when that fails).
    delay_jitter : int
        Variable delay (periods), >= 0: command k arrives at tick
        ``k + delay_ticks + j_k``, ``j_k`` uniform in ``0 .. delay_jitter`` (its own
        generator, seeded from ``seed``), in order (never before the previous
        one); each plant step applies the newest command arrived (a late one
        is held, one overtaken before its step is never applied).
    actuated : {'paper', 'all'}
        'paper': joint 3 free (Table I); 'all': every joint driven (r = 3 > m = 2, the
        start pose unchanged); the variant is labelled ``<variant> all``.
    law : str
        The registered control law (``freejoint_core.laws``; the node's parameter
        ``law``), built by ``make_law`` with ``gains``, ``law_params`` and ``nullspace``.
    law_params : mapping of str to float, optional
        The laws' own gains by namespaced name (``vsc.phi``).
    nullspace : freejoint_core.internal.NullSpace, optional
        The controller's null-space option (r > m); labelled ``+ns``.
    loss_rate : float
        Share of the states the controller does not answer, in [0, 1): missed in bursts
        of ``loss_burst`` consecutive ticks (tick 0 always answered), the burst starts
        drawn from their own generator seeded from ``seed``. A missed tick computes no
        command (the law does not step; its next step takes the stamps' gap as dt, at
        most 4 periods as the node clamps it) and the plant keeps the previous command
        one period longer, as a real-time loop that misses a state. Labelled
        ``L<rate>x<burst>``.
    loss_burst : int
        Consecutive states missed per burst (>= 1).

    Returns
    -------
    record : dict
        :func:`freejoint_core.metrics.compute_record` with ``source='offline'``.
    trace : dict or None
        With ``record_trace``: ``t`` (N,), ``q``, ``qd`` (N, 3), ``p``,
        ``p_d``, ``e`` (N, 2), ``tau`` (N, 2), ``theta`` (N, 5), ``det``,
        ``rho`` (N,), ``status`` (N,) int, over the recorded ticks; with
        the predictor also ``q_law``, ``qd_law`` (N, 3): the predicted state
        the law ran on.

    """
    if case not in CASES:
        raise FreejointValueError(f'case: expected one of {CASES}, got {case!r}')
    if variant not in VARIANTS:
        raise FreejointValueError(f'variant: expected one of {VARIANTS}, got {variant!r}')
    dt = positive('dt', dt)
    duration = positive('duration', duration)
    diverge_m = positive('diverge_m', diverge_m)
    diverge_qd = positive('diverge_qd', diverge_qd)
    n_ticks = int(round(duration / dt))
    if n_ticks < 1 or abs(n_ticks * dt - duration) > 1e-9 * duration:
        raise FreejointValueError(
            f'duration: {duration} s is not a positive integer multiple of dt = {dt} s')
    if isinstance(delay_ticks, bool) or not isinstance(delay_ticks, (int, np.integer)) \
            or delay_ticks < 0:
        raise FreejointValueError(f'delay_ticks: expected an int >= 0, got {delay_ticks!r}')
    if not isinstance(predict, (bool, np.bool_)):
        raise FreejointValueError(f'predict: expected a bool, got {predict!r}')
    delay_ticks = int(delay_ticks)
    if predict_ticks is None:
        predict_ticks = delay_ticks
    elif isinstance(predict_ticks, bool) or not isinstance(predict_ticks, (int, np.integer)) \
            or predict_ticks < 0:
        raise FreejointValueError(
            f'predict_ticks: expected None or an int >= 0, got {predict_ticks!r}')
    predict_ticks = int(predict_ticks)
    if not isinstance(echo, (bool, np.bool_)):
        raise FreejointValueError(f'echo: expected a bool, got {echo!r}')
    if isinstance(delay_jitter, bool) or not isinstance(delay_jitter, (int, np.integer)) \
            or delay_jitter < 0:
        raise FreejointValueError(f'delay_jitter: expected an int >= 0, got {delay_jitter!r}')
    delay_jitter = int(delay_jitter)
    if not (isinstance(loss_rate, (int, float)) and 0.0 <= loss_rate < 1.0):
        raise FreejointValueError(f'loss_rate: expected a share in [0, 1), got {loss_rate!r}')
    if isinstance(loss_burst, bool) or not isinstance(loss_burst, (int, np.integer)) \
            or loss_burst < 1:
        raise FreejointValueError(f'loss_burst: expected an int >= 1, got {loss_burst!r}')
    if gains is None:
        gains = Gains()
    elif not isinstance(gains, Gains):
        raise FreejointValueError(f'gains: expected Gains, got {type(gains).__name__}')
    if trajectory is None:
        trajectory = CircleQuintic()
    elif not isinstance(trajectory, CircleQuintic):
        raise FreejointValueError(
            f'trajectory: expected CircleQuintic, got {type(trajectory).__name__}')

    dt_sub = positive('dt_sub', dt_sub)
    n_sub = round(dt / dt_sub)
    if n_sub < 1 or abs(n_sub * dt_sub - dt) > 1e-9 * dt:
        raise FreejointValueError(
            f'dt_sub: dt = {dt} s is not an integer multiple of dt_sub = {dt_sub} s')
    if actuated not in ACTUATED:
        raise FreejointValueError(f'actuated: expected one of {ACTUATED}, got {actuated!r}')
    real = table1(case)
    start_arm = real
    if actuated == 'all':
        real = dataclasses.replace(real, passive=())
    if variant == 'exact':
        nominal, dist = real, 0.0
    else:
        nominal = real.scaled(positive('nominal_scale', nominal_scale))
        dist = dist_bound
    if variant == 'robust_off':
        gains = dataclasses.replace(gains, robust=False)
    px0, py0 = trajectory.sample(0.0)[0]
    q0 = initial_state(start_arm, q3_0_deg, (px0, py0))
    plant = Plant(real, dt_sub, dist_bound=dist, seed=seed, q0=q0)
    options = {} if nullspace is None else {'nullspace': nullspace}
    ctrl = make_law(law, nominal, gains, params=law_params, **options)
    label = variant + (' all' if actuated == 'all' else '') + ('+ns' if nullspace else '')
    if law != 'robust':
        label = f'{law} {label}'
    pred = None
    missed = loss_pattern(loss_rate, int(loss_burst), n_ticks, seed)
    pipeline = bool(delay_ticks or delay_jitter or missed)
    fk_real = make_model(real).fk
    if pipeline:
        label = f'{label} d{delay_ticks}' + (f'~{delay_jitter}' if delay_jitter else '') \
            + (f' L{loss_rate:g}x{loss_burst}' if missed else '') + ('+p' if predict else '')
        if predict and predict_ticks != delay_ticks:
            label += f'{predict_ticks}'
        if predict and echo:
            label += 'e'
        if predict:
            pred = StatePredictor(nominal, dt, dt_sub, bias_gain=bias_gain,
                                  max_ticks=max(delay_ticks + delay_jitter, predict_ticks, 1))
            h_pred = predict_ticks * dt
        jitter = np.random.default_rng([7919, 0 if seed is None else int(seed)]).integers(
            0, delay_jitter + 1, n_ticks).tolist() if delay_jitter else [0] * n_ticks
        arrive = []         # tick at which each computed command reaches the plant
        applied_at = []     # index of the command each plant step applied

    # What the law declares, read by name: its adaptive estimate (reported at the end), its
    # conditioning (the record's min_det) and its robust gain (the trace's); 0 / none otherwise.
    reported = RunValues(ctrl)
    has_rho = internal_size(ctrl, 'rho_hat') is not None
    theta = np.zeros(reported.theta_size)
    # Setpoints of every tick, through the same scalar path the graph uses.
    sample = trajectory.sample_tuple
    des = [sample(k * dt) for k in range(n_ticks)]
    t_arr = np.arange(n_ticks) * dt
    p_buf = np.empty((n_ticks, 2))
    tau_buf = np.empty((n_ticks, real.r))
    det_buf = np.empty(n_ticks)
    q3_buf = np.empty(n_ticks)
    if record_trace:
        q_buf = np.empty((n_ticks, 3))
        qd_buf = np.empty((n_ticks, 3))
        th_buf = np.empty((n_ticks, reported.theta_size))
        rho_buf = np.empty(n_ticks)
        st_buf = np.empty(n_ticks, dtype=np.int64)
        if pred is not None:
            ql_buf = np.empty((n_ticks, 3))
            qdl_buf = np.empty((n_ticks, 3))
    isfinite = math.isfinite
    passive = start_arm.passive[0]
    limit2 = diverge_m * diverge_m
    diverged = None
    n_rec = 0
    last_k = 0
    for k in range(n_ticks):
        t = k * dt
        pdx, pdy, vdx, vdy, adx, ady = des[k]
        q = plant.q
        qd = plant.qd
        if missed and k in missed:
            # Not answered: no law step, the previous command held one more period.
            px, py = fk_real(q).tolist()
            ex = px - pdx
            ey = py - pdy
            p_buf[k] = px, py
            tau_buf[k] = tau_buf[k - 1]
            det_buf[k] = det_buf[k - 1]
            q3_buf[k] = q[passive]
            if record_trace:
                q_buf[k] = q
                qd_buf[k] = qd
                th_buf[k] = theta
                rho_buf[k] = rho_buf[k - 1]
                st_buf[k] = st_buf[k - 1]
                if pred is not None:
                    ql_buf[k] = ql_buf[k - 1]
                    qdl_buf[k] = qdl_buf[k - 1]
            n_rec = k + 1
            w0, w1, w2 = qd.tolist()
            if ex * ex + ey * ey > limit2 or max(abs(w0), abs(w1), abs(w2)) > diverge_qd:
                diverged = t
                break
            try:
                pipeline_step(plant, tau_buf, arrive, applied_at, k,
                              delay_ticks + jitter[k], dt)
            except _BLOWUP:
                diverged = (k + 1) * dt
                break
            continue
        dt_law = dt if not missed else min(k - last_k, 4) * dt if k else dt
        last_k = k
        try:
            if pred is None:
                out = ctrl.step(q, qd, (pdx, pdy), (vdx, vdy), (adx, ady), dt_law)
            else:
                if echo and k:
                    applied = tau_buf[applied_at[k - 1]]
                    m_k = pred.ticks_since(applied)
                    m_k = predict_ticks if m_k is None else m_k
                    qp, qdp = pred.predict(q, qd, m_k, applied)
                    sp = extrapolate_setpoint((pdx, pdy), (vdx, vdy), (adx, ady), m_k * dt)
                else:
                    qp, qdp = pred.predict(q, qd, predict_ticks)
                    sp = extrapolate_setpoint((pdx, pdy), (vdx, vdy), (adx, ady), h_pred)
                out = ctrl.step(qp, qdp, *sp, dt_law)
                if not (finite_internal(out.internal) and all(map(isfinite, qdp.tolist()))):
                    raise ArithmeticError('non-finite prediction or estimate')
                pred.push(out.tau)
        except _BLOWUP:
            diverged = t
            break
        if pred is None:
            px, py = out.p.tolist()
        else:
            px, py = fk_real(q).tolist()
        tau_k = out.tau.tolist()
        internal = out.internal
        ex = px - pdx
        ey = py - pdy
        err2 = ex * ex + ey * ey
        if not (isfinite(err2) and all(map(isfinite, tau_k)) and finite_internal(internal)):
            diverged = t
            break
        p_buf[k] = px, py
        tau_buf[k] = tau_k
        det_buf[k] = reported.conditioning(out)
        q3_buf[k] = q[passive]
        theta = reported.theta(out)
        if record_trace:
            q_buf[k] = q
            qd_buf[k] = qd
            th_buf[k] = theta
            rho_buf[k] = internal['rho_hat'] if has_rho else 0.0
            st_buf[k] = out.status
            if pred is not None:
                ql_buf[k] = qp
                qdl_buf[k] = qdp
        n_rec = k + 1
        w0, w1, w2 = qd.tolist()
        if err2 > limit2 or max(abs(w0), abs(w1), abs(w2)) > diverge_qd:
            diverged = t
            break
        try:
            if pipeline:
                pipeline_step(plant, tau_buf, arrive, applied_at, k,
                              delay_ticks + jitter[k], dt)
            else:
                plant.step(out.tau, dt)
        except _BLOWUP:
            diverged = (k + 1) * dt
            break
    if n_rec == 0:   # cannot happen from a finite initial state, but never emit NaN
        raise FreejointValueError(
            f'gains: the first tick already fails (case {case}, variant {variant})')
    p_d = np.array([d[:2] for d in des[:n_rec]])
    record = compute_record(case, label, seed, t_arr[:n_rec], p_buf[:n_rec], p_d,
                            tau_buf[:n_rec], theta, q3_buf[:n_rec], det_buf[:n_rec],
                            diverged, 'offline')
    if not record_trace:
        return record, None
    trace = {
        't': t_arr[:n_rec], 'q': q_buf[:n_rec], 'qd': qd_buf[:n_rec], 'p': p_buf[:n_rec],
        'p_d': p_d, 'e': p_buf[:n_rec] - p_d, 'tau': tau_buf[:n_rec],
        'theta': th_buf[:n_rec], 'det': det_buf[:n_rec], 'rho': rho_buf[:n_rec],
        'status': st_buf[:n_rec],
    }
    if pred is not None:
        trace['q_law'] = ql_buf[:n_rec]
        trace['qd_law'] = qdl_buf[:n_rec]
    return record, trace


def loss_pattern(rate, burst, n_ticks, seed):
    """
    Return the set of ticks not answered: bursts of ``burst`` ticks, a share ``rate``.

    Between bursts the answered runs are geometric with mean ``burst (1 - rate) / rate``
    ticks (a burst starts after each answered tick with probability ``rate / (burst (1 -
    rate))``), so the expected share missed is ``rate``; tick 0 is always answered. Its
    own generator, seeded from ``seed`` (the disturbance's draws are unchanged).
    """
    if rate <= 0.0:
        return frozenset()
    start = rate / (burst * (1.0 - rate))
    draws = np.random.default_rng([104729, 0 if seed is None else int(seed)]).random(n_ticks)
    out = set()
    k = 1
    while k < n_ticks:
        if draws[k] < start:
            out.update(range(k, min(k + burst, n_ticks)))
            k += burst + 1      # the tick after a burst is answered
        else:
            k += 1
    return frozenset(out)


def pipeline_step(plant, tau_buf, arrive, applied_at, k, lag, dt):
    """
    Step the plant over tick ``k`` with the newest command arrived (a delayed loop).

    ``tau_buf[j]``: the command computed at tick j (<= k); ``lag``: the periods command
    ``k`` takes to arrive (it arrives at tick ``k + lag``, never before the previous one);
    ``arrive`` and ``applied_at`` are the caller's lists (empty at tick 0), appended to:
    each command's arrival tick and the command applied over each tick.
    """
    arrive.append(max(k + lag, arrive[-1] if k else 0))
    cur = applied_at[-1] if applied_at else 0
    while cur < k and arrive[cur + 1] <= k:
        cur += 1
    applied_at.append(cur)
    plant.step(tau_buf[cur], dt)


def run_all(seeds=range(10), cases=CASES, dt_sub=DEFAULT_DT_SUB, off_seeds=None,
            progress=None, delay_ticks=0, predict=False, bias_gain=DEFAULT_BIAS_GAIN,
            **delay_options):
    """
    Run the offline study: robust and robust_off over seeds, exact once, per case.

    Parameters
    ----------
    seeds : iterable of int
        Seeds of the ``robust`` runs.
    cases : iterable of str
        Cases to run.
    dt_sub : float
        Plant RK4 step (s).
    off_seeds : iterable of int, optional
        Seeds of the ``robust_off`` runs; default the same as ``seeds``.
    progress : callable, optional
        Called with each record as it completes.
    delay_ticks : int
        Fixed command delay of every run (periods), see :func:`run_case`.
    predict : bool
        Compensate it with the state predictor.
    bias_gain : float
        The predictor's bias observer gain.
    **delay_options
        ``predict_ticks``, ``echo``, ``delay_jitter``, ``actuated``, ``nullspace`` of
        :func:`run_case`.

    Returns
    -------
    list of dict
        Records in the order case, variant (robust, robust_off, exact), seed.

    """
    seeds = list(seeds)
    off_seeds = seeds if off_seeds is None else list(off_seeds)
    records = []
    for case in cases:
        jobs = [('robust', s) for s in seeds] + [('robust_off', s) for s in off_seeds]
        jobs.append(('exact', 0))
        for variant, seed in jobs:
            rec, _ = run_case(case, variant, seed, dt_sub=dt_sub, delay_ticks=delay_ticks,
                              predict=predict, bias_gain=bias_gain, **delay_options)
            records.append(rec)
            if progress is not None:
                progress(rec)
    return records


DELAY_STUDY_MS = (0, 1, 2, 3, 5, 10, 20)
DELAY_STUDY_OUT = 'bags/offline/delay_study.json'


def delay_study(delays_ms=DELAY_STUDY_MS, seeds=range(10), cases=CASES, progress=None,
                bias_gain=DEFAULT_BIAS_GAIN):
    """
    Tracking versus a fixed command delay, without and with the predictor.

    Parameters
    ----------
    delays_ms : iterable of int
        Delays (ms; control periods at dt = 1 ms), >= 0.
    seeds : iterable of int
        Disturbance seeds of the ``robust`` variant.
    cases : iterable of str
        Cases.
    progress : callable, optional
        Called with each record as it completes.
    bias_gain : float
        The predictor's bias observer gain (0: plain nominal prediction).

    Returns
    -------
    rows : list of dict
        Per case, delay and option (``'off'``, ``'on'``; ``'on'`` is not run
        at 0 ms, where it is the same loop): ``case``, ``delay_ms``,
        ``option``, ``runs``, ``worst_rms_mm``, ``worst_max_mm`` (over all
        seeds, a diverged run counted up to where it stopped), ``diverged``
        (count), ``diverged_at_s`` (earliest, or None).
    records : list of dict
        Every run's record (variant labelled ``robust d<m>[+p]``).

    """
    seeds = list(seeds)
    rows, records = [], []
    for case in cases:
        for m in delays_ms:
            for option in ('off', 'on'):
                if option == 'on' and m == 0:
                    continue
                recs = []
                for seed in seeds:
                    rec, _ = run_case(case, 'robust', seed, delay_ticks=m,
                                      predict=option == 'on', bias_gain=bias_gain)
                    recs.append(rec)
                    if progress is not None:
                        progress(rec)
                stops = [r['diverged_at_s'] for r in recs if r['diverged_at_s'] is not None]
                rows.append({
                    'case': case, 'delay_ms': m, 'option': option, 'runs': len(recs),
                    'worst_rms_mm': max(r['rms_mm'] for r in recs),
                    'worst_max_mm': max(r['max_mm'] for r in recs),
                    'diverged': len(stops), 'diverged_at_s': min(stops) if stops else None})
                records.extend(recs)
    return rows, records


def format_delay_table(rows):
    """Format :func:`delay_study` rows as a Markdown table."""
    lines = ['| case | delay (ms) | predictor | runs | worst RMS (mm) | worst max (mm) '
             '| diverged (first at) |', '|---|---:|---|---:|---:|---:|---|']
    for r in rows:
        div = '0' if not r['diverged'] else f'{r["diverged"]} ({r["diverged_at_s"]:.2f} s)'
        lines.append(f'| {r["case"]} | {r["delay_ms"]} | {r["option"]} | {r["runs"]} '
                     f'| {r["worst_rms_mm"]:.3g} | {r["worst_max_mm"]:.3g} | {div} |')
    return '\n'.join(lines)


_FIGURES = ('rms_mm', 'max_mm', 'final_mm', 'tau_peak_nm', 'theta_final', 'q3_range_deg',
            'min_det')


def compare_records(a, b):
    """
    Largest absolute change of every table figure between two record lists.

    Parameters
    ----------
    a, b : list of dict
        Records of the same runs in the same order.

    Returns
    -------
    dict
        ``'figures'``: figure name -> max absolute difference over the runs
        that completed in both lists (list figures flattened; 0.0 if none);
        ``'completed'``: number of such runs; ``'diverged'``: number of runs
        that diverged in both; ``'diverged_at_s'``: max change (s) of the
        divergence time over those; ``'mismatch'``: runs that diverged in one
        list only.

    """
    if len(a) != len(b):
        raise FreejointValueError(f'b: expected {len(a)} records, got {len(b)}')
    figs = dict.fromkeys(_FIGURES, 0.0)
    out = {'figures': figs, 'completed': 0, 'diverged': 0, 'diverged_at_s': 0.0,
           'mismatch': 0}
    for ra, rb in zip(a, b):
        if (ra['case'], ra['variant'], ra['seed']) != (rb['case'], rb['variant'], rb['seed']):
            raise FreejointValueError('b: records are not the same runs in the same order')
        da, db = ra['diverged_at_s'], rb['diverged_at_s']
        if da is None and db is None:
            out['completed'] += 1
            for name in _FIGURES:
                va = np.atleast_1d(np.asarray(ra[name], dtype=float))
                vb = np.atleast_1d(np.asarray(rb[name], dtype=float))
                figs[name] = max(figs[name], float(np.max(np.abs(va - vb))))
        elif da is not None and db is not None:
            out['diverged'] += 1
            out['diverged_at_s'] = max(out['diverged_at_s'], abs(da - db))
        else:
            out['mismatch'] += 1
    return out


def _parse(argv):
    ap = argparse.ArgumentParser(
        prog='offline', description='Offline closed-loop runs of the paper (no ROS): both '
        'cases, robust over seeds, robust_off, exact; prints the table, writes JSON.')
    ap.add_argument('--out', default=None,
                    help=f'records JSON (default {DEFAULT_OUT}; with a delay '
                    'bags/offline/delay_m<m>[_p].json; with --delay-study '
                    f'{DELAY_STUDY_OUT}); "" to skip writing')
    ap.add_argument('--seeds', type=int, default=10, help='seeds 0..N-1 (default 10)')
    ap.add_argument('--off-seeds', type=int, default=None,
                    help='seeds of robust_off (default: same as --seeds)')
    ap.add_argument('--cases', nargs='+', choices=CASES, default=list(CASES))
    ap.add_argument('--dt-sub', type=float, default=DEFAULT_DT_SUB,
                    help=f'plant RK4 step in s (default {DEFAULT_DT_SUB})')
    ap.add_argument('--compare-dt-sub', action='store_true',
                    help='also run with dt_sub/10 and print the max change of every figure')
    ap.add_argument('--theta', action='store_true', help='show theta_final in the table')
    ap.add_argument('--delay-ticks', type=int, default=0, metavar='M',
                    help='fixed command delay: the command of tick k acts from tick k + M '
                    '(default 0)')
    ap.add_argument('--predict', action='store_true',
                    help='compensate the delay with the nominal-model state predictor')
    ap.add_argument('--bias-gain', type=float, default=DEFAULT_BIAS_GAIN,
                    help='bias observer gain of the predictor (default '
                    f'{DEFAULT_BIAS_GAIN:g}; 0: plain nominal prediction)')
    ap.add_argument('--delay-jitter', type=int, default=0, metavar='J',
                    help='variable delay: each command arrives 0..J ticks later still '
                    '(in order; the plant applies the newest arrived)')
    ap.add_argument('--loss-rate', type=float, default=0.0, metavar='R',
                    help='share of the states not answered (the previous command held one '
                    'more period), in bursts of --loss-burst (default 0)')
    ap.add_argument('--loss-burst', type=int, default=1, metavar='B',
                    help='consecutive states missed per burst (default 1)')
    ap.add_argument('--predict-ticks', type=int, default=None, metavar='P',
                    help='predictor horizon (default: --delay-ticks)')
    ap.add_argument('--echo', action='store_true',
                    help='predictor horizon and observer from the applied command the plant '
                    'reports (joint_states.effort)')
    ap.add_argument('--law', default='robust',
                    help="the registered control law (default 'robust', the paper's; 'vsc', "
                    "'tdc', ...): its runs at the paper's point over the seeds, labelled "
                    '<law> robust (no robust_off runs); default --out '
                    'bags/offline/metrics_<law>.json')
    ap.add_argument('--law-param', action='append', default=[], metavar='NAME=VALUE',
                    help="a law's own gain, e.g. vsc.phi=0.05 (repeatable)")
    ap.add_argument('--actuated', choices=ACTUATED, default='paper',
                    help="'paper': joint 3 free (default); 'all': every joint driven "
                    '(r = 3 > m = 2)')
    ap.add_argument('--nullspace-kd', type=float, default=None, metavar='KD',
                    help='null-space damping of the active joints for r > m (N m s/rad, e.g. '
                    "3; default off: the paper's law); see docs/internal-motion.md")
    ap.add_argument('--weighted', action='store_true',
                    help='with --nullspace-kd: inertia-weighted inverse and dynamically '
                    'consistent projector instead of the pseudo-inverse ones')
    ap.add_argument('--circles', type=int, default=None, metavar='N',
                    help='tasks back to back: N circles per run, one record per circle to '
                    'bags/offline/circles.json (with --out: there); see docs/internal-motion.md')
    ap.add_argument('--rest', type=float, default=0.0, metavar='S',
                    help='with --circles: the setpoint rests S s at the start point between '
                    'circles (default 0: back to back)')
    ap.add_argument('--hold', type=float, default=0.0, metavar='S',
                    help='with --circles: hold S s after the last circle (settle metrics)')
    ap.add_argument('--stabilise', action='store_true',
                    help='with --circles: internal-motion stabilisation on (vertical paper '
                    'arm: hanging start + free-link damping by a bounded reference '
                    'modulation; horizontal paper arm: the free link slowed in the first '
                    '0.6 s of each rest; r > m: null-space damping)')
    ap.add_argument('--delta-max', type=float, default=None, metavar='M',
                    help="with --stabilise: bound of the modulation's task deviation (m)")
    ap.add_argument('--arm', choices=('paper', 'four_link'), default='paper',
                    help='with --circles: the paper arm (default) or the 4-link example')
    ap.add_argument('--start', default=None,
                    help='with --circles: start pose paper | hanging | example | equilibrium')
    ap.add_argument('--delay-study', action='store_true',
                    help='only the delay study of docs/delay.md: robust over the seeds, '
                    f'delays {", ".join(map(str, DELAY_STUDY_MS))} ms, predictor off and on')
    return ap.parse_args(argv)


def main(argv=None):
    """Console entry point ``offline`` (``python -m freejoint_core.offline``)."""
    args = _parse(sys.argv[1:] if argv is None else argv)
    if args.seeds < 1:
        raise SystemExit('offline: --seeds must be >= 1')
    if args.delay_ticks < 0 or args.delay_jitter < 0 or (args.predict_ticks or 0) < 0:
        raise SystemExit('offline: --delay-ticks, --delay-jitter and --predict-ticks must be '
                         '>= 0')
    if not 0.0 <= args.loss_rate < 1.0 or args.loss_burst < 1:
        raise SystemExit('offline: --loss-rate must lie in [0, 1), --loss-burst be >= 1')
    if not 0.0 <= args.bias_gain <= 1.0:
        raise SystemExit('offline: --bias-gain must lie in [0, 1]')
    if args.delay_study:
        return _main_delay_study(args)
    if args.circles is not None:
        return _main_circles(args)
    off = None if args.off_seeds is None else range(args.off_seeds)
    if args.law != 'robust':
        off = ()
        if args.out is None:
            args.out = f'bags/offline/metrics_{args.law}.json'
    t0 = time.perf_counter()
    records = run_all(range(args.seeds), args.cases, args.dt_sub, off,
                      delay_ticks=args.delay_ticks, predict=args.predict,
                      bias_gain=args.bias_gain, predict_ticks=args.predict_ticks,
                      echo=args.echo, delay_jitter=args.delay_jitter,
                      loss_rate=args.loss_rate, loss_burst=args.loss_burst,
                      **_internal_options(args))
    wall = time.perf_counter() - t0
    print(f'offline: {len(records)} runs, dt = 1 ms, dt_sub = {args.dt_sub:g} s, '
          f'{wall:.1f} s wall')
    delayed = args.delay_ticks or args.delay_jitter or args.loss_rate
    if delayed:
        print(f'command delay {args.delay_ticks} + 0..{args.delay_jitter} ticks, '
              f'{args.loss_rate:.0%} of the states missed in bursts of {args.loss_burst}, '
              f'predictor {f"on (bias_gain {args.bias_gain:g})" if args.predict else "off"}')
    if args.out is None:
        args.out = DEFAULT_OUT if not delayed else (
            f'bags/offline/delay_m{args.delay_ticks}'
            f'{f"j{args.delay_jitter}" if args.delay_jitter else ""}'
            f'{f"l{args.loss_rate:g}x{args.loss_burst}" if args.loss_rate else ""}'
            f'{"_p" if args.predict else ""}.json')
    print(format_table(records, theta=args.theta))
    print()
    print(format_summary(records))
    if args.out:
        write_records(args.out, records)
        print(f'\nrecords written to {args.out}')
    if args.compare_dt_sub:
        fine_dt = args.dt_sub / 10.0
        t0 = time.perf_counter()
        fine = run_all(range(args.seeds), args.cases, fine_dt, off)
        wall = time.perf_counter() - t0
        diff = compare_records(records, fine)
        print(f'\ndt_sub study: {args.dt_sub:g} s vs {fine_dt:g} s ({wall:.1f} s wall), '
              f'max |change| over the {diff["completed"]} runs completed in both:')
        units = {'rms_mm': 'mm', 'max_mm': 'mm', 'final_mm': 'mm', 'tau_peak_nm': 'N m',
                 'q3_range_deg': 'deg', 'min_det': '1/(kg^4 m^4)'}
        for name, value in diff['figures'].items():
            print(f'  {name:<14} {value:.3g} {units.get(name, "")}'.rstrip())
        print(f'  diverged in both: {diff["diverged"]} runs, divergence time changed by up to '
              f'{diff["diverged_at_s"]:.3g} s; diverged in one only: {diff["mismatch"]}')
    return 0


def _internal_options(args):
    """Return the ``actuated`` / ``nullspace`` keywords of :func:`run_case` from the CLI."""
    out = {}
    if args.law != 'robust' or args.law_param:
        out['law'] = args.law
        out['law_params'] = {}
        for item in args.law_param:
            name, _, value = item.partition('=')
            try:
                out['law_params'][name.strip()] = float(value)
            except ValueError:
                raise SystemExit(f'offline: --law-param: expected NAME=NUMBER, got {item!r}')
    if args.actuated != 'paper':
        out['actuated'] = args.actuated
    if args.nullspace_kd is not None:
        kind = {'inverse': 'weighted', 'projector': 'dynamic'} if args.weighted else {}
        out['nullspace'] = NullSpace(kd=args.nullspace_kd, **kind)
    return out


def _main_circles(args):
    from .circles import circle_study, DEFAULT_OUT as CIRCLES_OUT, format_circle_summary, \
        summarize_circles, write_circles
    if args.circles < 1 or args.rest < 0 or args.hold < 0:
        raise SystemExit('offline: --circles must be >= 1, --rest and --hold >= 0')
    opts = _internal_options(args)
    if args.start is not None:
        opts['start'] = args.start
    t0 = time.perf_counter()

    def progress(recs):
        last = recs[-1]
        print(f'  {last["case"]} {last["variant"]} seed {last["seed"]}: {len(recs)} circles, '
              f'max {max(r["max_mm"] for r in recs):.3g} mm, peak effort '
              f'{max(max(r["effort_peak"]) for r in recs):.3g} N m, diverged at '
              f'{last["diverged_at_s"]}', flush=True)

    records = circle_study(args.cases, range(args.seeds), args.circles, args.rest, args.hold,
                           stabilise=args.stabilise, arm=args.arm,
                           delta_max=args.delta_max, progress=progress, **opts)
    print(f'offline circles: {args.circles} per run, rest {args.rest:g} s, seeds '
          f'0-{args.seeds - 1}, stabilise {"on" if args.stabilise else "off"}, '
          f'{time.perf_counter() - t0:.1f} s wall')
    print(format_circle_summary(summarize_circles(records)))
    out = CIRCLES_OUT if args.out is None else args.out
    if out:
        write_circles(out, records)
        print(f'\nrecords written to {out}')
    return 0


def _main_delay_study(args):
    t0 = time.perf_counter()
    rows, records = delay_study(seeds=range(args.seeds), cases=args.cases,
                                bias_gain=args.bias_gain)
    print(f'offline delay study: {len(records)} runs, seeds 0-{args.seeds - 1}, bias_gain '
          f'{args.bias_gain:g}, {time.perf_counter() - t0:.1f} s wall')
    print(format_delay_table(rows))
    out = DELAY_STUDY_OUT if args.out is None else args.out
    if out:
        write_records(out, records)
        print(f'\nrecords written to {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
