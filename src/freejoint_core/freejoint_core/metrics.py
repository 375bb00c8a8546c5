"""
Run metrics: one record format for the offline runner, the ROS graph and bags.

A *record* is a flat dict of plain Python values (JSON-serialisable):

============== ============ =====================================================
key            type         meaning
============== ============ =====================================================
case           str          'horizontal' (Case 1) or 'vertical' (Case 2)
variant        str          e.g. 'robust', 'robust_off', 'exact'
seed           int or None  disturbance seed
rms_mm         float        RMS over the recorded ticks of ``||p - p_d||`` (mm)
max_mm         float        maximum of ``||p - p_d||`` (mm)
final_mm       float        ``||p - p_d||`` at the last recorded tick (mm)
tau_peak_nm    [float] (r)  ``max_k |tau_i(t_k)|`` per active joint (N m)
theta_final    [float] (k)  adaptive estimate after the last tick: the law's declared
                            ``theta_hat`` (the paper's law: 5; a law without one: none)
q3_range_deg   [float] (2)  (min, max) of the passive joint angle (deg), as
                            integrated (not wrapped)
min_det        float        minimum of the law's conditioning (its ``conditioning``:
                            ``|det(Da Da^T)|`` of the nominal model; 0 for a law without)
diverged_at_s  float/None   time (s) of the tick where the run was stopped, or None
source         str          'offline', 'graph' or 'bag'
============== ============ =====================================================

Ticks are the control ticks ``t_k`` (s); every array passed to
:func:`compute_record` has one row per recorded tick.
"""

import json
import math
import os

import numpy as np

from .errors import FreejointValueError

KEYS = ('case', 'variant', 'seed', 'rms_mm', 'max_mm', 'final_mm', 'tau_peak_nm',
        'theta_final', 'q3_range_deg', 'min_det', 'diverged_at_s', 'source')


def _array(name, value, ndim_options):
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a numeric array, got {value!r}') from None
    if arr.ndim not in ndim_options:
        raise FreejointValueError(
            f'{name}: expected {" or ".join(f"{d}-D" for d in ndim_options)} array, '
            f'got shape {arr.shape}')
    if not np.all(np.isfinite(arr)):
        bad = np.nonzero(~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1))[0]
        raise FreejointValueError(f'{name}: non-finite value at row {int(bad[0])}')
    return arr


def _text(name, value):
    if not isinstance(value, str) or not value:
        raise FreejointValueError(f'{name}: expected a non-empty string, got {value!r}')
    return value


def compute_record(case, variant, seed, t, p, p_d, tau, theta, q_passive, det,
                   diverged_at_s=None, source='offline'):
    """
    Build a run record from per-tick arrays.

    Parameters
    ----------
    case, variant : str
        Labels (non-empty).
    seed : int or None
        Disturbance seed.
    t : array_like, shape (N,)
        Tick times (s), N >= 1, non-decreasing.
    p, p_d : array_like, shape (N, m)
        Measured and desired end-effector position (m); m = 2 (a planar arm) or 3 (the
        tip of a spatial arm).
    tau : array_like, shape (N, r)
        Active joint torques (N m).
    theta : array_like, shape (k,) or (N, k)
        Adaptive estimate; the last row (or the vector) is reported.
    q_passive : array_like, shape (N,) or (N, 1)
        Passive joint angle (rad).
    det : array_like, shape (N,)
        ``|det(Da Da^T)|`` of the nominal model per tick (a spatial arm: the law's
        scale-free ``kappa``).
    diverged_at_s : float or None
        Time (s) the run was stopped at, or None if it completed.
    source : str
        'offline', 'graph' or 'bag' (any non-empty string is accepted).

    Returns
    -------
    dict
        The record (keys :data:`KEYS`), plain Python floats/ints/lists.

    Raises
    ------
    FreejointValueError
        Naming the first bad argument (shape mismatch, empty, non-finite).

    """
    case = _text('case', case)
    variant = _text('variant', variant)
    source = _text('source', source)
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))):
        raise FreejointValueError(f'seed: expected an int or None, got {seed!r}')
    t = _array('t', t, (1,))
    n = t.shape[0]
    if n < 1:
        raise FreejointValueError('t: need at least one tick, got 0')
    if np.any(np.diff(t) < 0.0):
        raise FreejointValueError('t: tick times must be non-decreasing')
    p = _array('p', p, (2,))
    p_d = _array('p_d', p_d, (2,))
    m = p.shape[1]
    for name, arr in (('p', p), ('p_d', p_d)):
        if arr.shape != (n, m) or m not in (2, 3):
            raise FreejointValueError(f'{name}: expected shape ({n}, 2) or ({n}, 3), the '
                                      f'same for p and p_d, got {arr.shape}')
    tau = _array('tau', tau, (2,))
    if tau.shape[0] != n or tau.shape[1] < 1:
        raise FreejointValueError(f'tau: expected shape ({n}, r), got {tau.shape}')
    theta = _array('theta', theta, (1, 2))
    last_theta = theta if theta.ndim == 1 else theta[-1]
    if last_theta.ndim != 1 or (theta.ndim == 2 and theta.shape[0] != n):
        raise FreejointValueError(f'theta: expected shape (k,) or ({n}, k), got {theta.shape}')
    qp = _array('q_passive', q_passive, (1, 2))
    if qp.ndim == 2 and qp.shape[1] == 1:
        qp = qp[:, 0]
    if qp.shape != (n,):
        raise FreejointValueError(f'q_passive: expected shape ({n},), got {qp.shape}')
    det = _array('det', det, (1,))
    if det.shape != (n,):
        raise FreejointValueError(f'det: expected shape ({n},), got {det.shape}')
    if diverged_at_s is not None:
        try:
            diverged_at_s = float(diverged_at_s)
        except (TypeError, ValueError):
            raise FreejointValueError(
                f'diverged_at_s: expected a float or None, got {diverged_at_s!r}') from None
        if not math.isfinite(diverged_at_s):
            raise FreejointValueError(f'diverged_at_s: must be finite, got {diverged_at_s}')
    if m == 2:
        err_mm = 1000.0 * np.hypot(p[:, 0] - p_d[:, 0], p[:, 1] - p_d[:, 1])
    else:
        err_mm = 1000.0 * np.linalg.norm(p - p_d, axis=1)
    q3_deg = np.degrees(qp)
    return {
        'case': case,
        'variant': variant,
        'seed': None if seed is None else int(seed),
        'rms_mm': float(math.sqrt(float(np.mean(err_mm * err_mm)))),
        'max_mm': float(err_mm.max()),
        'final_mm': float(err_mm[-1]),
        'tau_peak_nm': [float(v) for v in np.abs(tau).max(axis=0)],
        'theta_final': [float(v) for v in last_theta],
        'q3_range_deg': [float(q3_deg.min()), float(q3_deg.max())],
        'min_det': float(np.abs(det).min()),
        'diverged_at_s': diverged_at_s,
        'source': source,
    }


def _check_records(records):
    if isinstance(records, dict):
        raise FreejointValueError('records: expected a list of records, got a dict')
    try:
        records = list(records)
    except TypeError:
        raise FreejointValueError(f'records: expected a list of dicts, got {records!r}') from None
    for i, rec in enumerate(records):
        if not isinstance(rec, dict):
            raise FreejointValueError(f'records: item {i} is not a dict')
        missing = [k for k in KEYS if k not in rec]
        if missing:
            raise FreejointValueError(f'records: item {i} lacks keys {missing}')
    return records


_COLUMNS = (
    # title, width, formatter
    ('case', 10, lambda r: str(r['case'])),
    ('variant', 10, lambda r: str(r['variant'])),
    ('seed', 4, lambda r: '-' if r['seed'] is None else str(r['seed'])),
    ('rms_mm', 9, lambda r: f'{r["rms_mm"]:.4g}'),
    ('max_mm', 9, lambda r: f'{r["max_mm"]:.4g}'),
    ('final_mm', 9, lambda r: f'{r["final_mm"]:.4g}'),
    ('tau_pk_Nm', 15, lambda r: ' '.join(f'{v:.3g}' for v in r['tau_peak_nm'])),
    ('q3_deg', 13, lambda r: '{:.0f}..{:.0f}'.format(*r['q3_range_deg'])),
    ('min_det', 9, lambda r: f'{r["min_det"]:.3g}'),
    ('diverged_s', 10, lambda r: '-' if r['diverged_at_s'] is None
     else f'{r["diverged_at_s"]:.3f}'),
    ('source', 7, lambda r: str(r['source'])),
)


SPATIAL_TITLES = {'q3_deg': 'free_deg', 'min_det': 'min_kappa'}
"""A spatial arm's titles of the passive angle range and of its conditioning (kappa)."""


def format_table(records, theta=False, titles=None):
    """
    Format records as a fixed-width text table (one row per record).

    Columns: case, variant, seed, rms/max/final error (mm, 4 significant
    digits), peak torques (N m), passive angle range (deg), minimum
    ``|det(Da Da^T)|``, divergence time (s, '-' if none), source; with
    ``theta=True`` also the final adaptive estimate.

    Parameters
    ----------
    records : list of dict
        Records as from :func:`compute_record`.
    theta : bool
        Append the ``theta_final`` column.
    titles : dict, optional
        Column titles to show instead (e.g. a spatial arm's ``{'q3_deg': 'wrist_2_deg',
        'min_det': 'min_kappa'}``: its free joint and its conditioning kappa); a column
        widens to its title. Default: :data:`SPATIAL_TITLES` when every record is a spatial
        arm's (variant 'spatial'), else the planar titles.

    Returns
    -------
    str
        Header, rule and rows, newline-separated (no trailing newline).

    """
    records = _check_records(records)
    if titles is None and records and all(r['variant'] == 'spatial' for r in records):
        titles = SPATIAL_TITLES
    cols = [((titles or {}).get(title, title), max(w, len((titles or {}).get(title, title))),
             fmt) for title, w, fmt in _COLUMNS]
    if theta:
        cols.append(('theta_final', 44,
                     lambda r: ' '.join(f'{v:.2e}' for v in r['theta_final'])))
    lines = ['  '.join(title.rjust(w) if i > 1 else title.ljust(w)
                       for i, (title, w, _) in enumerate(cols)).rstrip()]
    lines.append('-' * len(lines[0]))
    for rec in records:
        cells = []
        for i, (_, w, fmt) in enumerate(cols):
            txt = fmt(rec)
            cells.append(txt.rjust(w) if i > 1 else txt.ljust(w))
        lines.append('  '.join(cells).rstrip())
    return '\n'.join(lines)


def summarize(records):
    """
    Worst case over seeds per (case, variant, source).

    Parameters
    ----------
    records : list of dict
        Records as from :func:`compute_record`.

    Returns
    -------
    list of dict
        Per group, in first-seen order: ``case``, ``variant``, ``source``,
        ``runs``, ``worst_rms_mm``, ``worst_max_mm``, ``mean_rms_mm``,
        ``diverged`` (number of runs stopped early).

    """
    records = _check_records(records)
    groups = {}
    for rec in records:
        groups.setdefault((rec['case'], rec['variant'], rec['source']), []).append(rec)
    out = []
    for (case, variant, source), recs in groups.items():
        out.append({
            'case': case, 'variant': variant, 'source': source, 'runs': len(recs),
            'worst_rms_mm': max(r['rms_mm'] for r in recs),
            'worst_max_mm': max(r['max_mm'] for r in recs),
            'mean_rms_mm': sum(r['rms_mm'] for r in recs) / len(recs),
            'diverged': sum(r['diverged_at_s'] is not None for r in recs),
        })
    return out


def format_summary(records):
    """Format :func:`summarize` as a fixed-width table (worst case over seeds)."""
    rows = summarize(records)
    head = (f'{"case":<10}  {"variant":<10}  {"source":<7}  {"runs":>4}  '
            f'{"worst_rms_mm":>12}  {"mean_rms_mm":>11}  {"worst_max_mm":>12}  '
            f'{"diverged":>8}')
    lines = [head, '-' * len(head)]
    for s in rows:
        lines.append(f'{s["case"]:<10}  {s["variant"]:<10}  {s["source"]:<7}  '
                     f'{s["runs"]:>4}  {s["worst_rms_mm"]:>12.4g}  {s["mean_rms_mm"]:>11.4g}  '
                     f'{s["worst_max_mm"]:>12.4g}  {s["diverged"]:>8}')
    return '\n'.join(lines)


def write_records(path, records):
    """
    Write records to a JSON file as a plain list (parent directories are created).

    Parameters
    ----------
    path : str or os.PathLike
        Output file.
    records : list of dict
        Records as from :func:`compute_record` (finite floats only).

    Raises
    ------
    FreejointValueError
        Naming ``records`` if they are malformed or hold NaN/inf.

    """
    records = _check_records(records)
    path = os.fspath(path)
    parent = os.path.dirname(path)
    if parent:
        os.makedirs(parent, exist_ok=True)
    try:
        text = json.dumps(records, indent=1, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise FreejointValueError(f'records: not JSON-serialisable: {exc}') from None
    tmp = path + '.tmp'
    with open(tmp, 'w', encoding='utf-8') as fh:
        fh.write(text + '\n')
    os.replace(tmp, path)


def read_records(path):
    """
    Read records written by :func:`write_records`.

    Parameters
    ----------
    path : str or os.PathLike
        A file written by :func:`write_records`.

    Returns
    -------
    list of dict

    Raises
    ------
    FreejointValueError
        Naming ``path`` if the file is not a records file.

    """
    path = os.fspath(path)
    try:
        with open(path, encoding='utf-8') as fh:
            data = json.load(fh)
    except (OSError, json.JSONDecodeError) as exc:
        raise FreejointValueError(f'path: cannot read records from {path!r}: {exc}') from None
    if not isinstance(data, list):
        raise FreejointValueError(f'path: {path!r} is not a records file (a JSON list of records)')
    try:
        return _check_records(data)
    except FreejointValueError as exc:
        raise FreejointValueError(f'path: {path!r}: {exc}') from None
