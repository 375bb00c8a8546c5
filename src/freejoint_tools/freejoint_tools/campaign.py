"""
Robustness campaigns: thousands of closed-loop runs over what a lab is unsure of.

``fj campaign run FILE`` (or ``ros2 run freejoint_tools campaign run FILE``) reads a
campaign file (YAML, below), checks all of it before any run starts (a bad file ends
with one line naming the field, exit status 2), expands its design into runs, advances
them in chunks with the batched simulator (``freejoint_core.batch``: the offline runner's
loop, numba-compiled, threads over runs) in this process, or with ``--address`` on a
Ray cluster (one Ray task per chunk, retried when a worker dies), and writes one
Parquet row per run.  ``fj campaign report RESULTS`` prints the summary table and
draws the figures (success rate and worst error over every pair of axes, the paper's
point marked, the 50 % success contour as the boundary of the region where the law
holds).  docs/campaigns.md documents the file and the figures.

Campaign file::

    name: paper_vertical          # label (and the default output folder bags/campaigns/NAME)
    arm: paper                    # Table I, or a 3-link URDF arm whose last joint is free:
                                  # {urdf: PATH, passive_joints: [NAME], tip_link: LINK,
                                  #  gravity: [x, y, z]} (gravity: default the case's),
                                  # or a spatial arm's directory (below)
    case: vertical                # horizontal (Case 1) | vertical (Case 2, gravity)
    task: {centre: [0.0, 0.0], radius: 0.2, duration: 5.0}   # the desired circle
    duration: 5.0                 # run length (s); dt 0.001, dt_sub 0.0005 by default
    controller: {K: [100, 100]}   # controller-node parameters (its schema checks them)
    success: {max_mm: 20.0}       # a run holds: not diverged and these bounds kept
    design: {kind: grid}          # grid | lhs | random (lhs/random: samples, seed)
    seeds: 10                     # seeds 0..9 per design point
    fixed: {dist_bound: 0.5}      # values of axes not varied (default: the paper's point)
    axes:                         # what varies: values: [...] or range: [lo, hi] (+ steps)
      scale: {range: [0.3, 1.5], steps: 7}
      dist_bound: {values: [0.0, 0.5, 1.0, 2.0]}

A spatial arm (``arm: DIR``: a directory of ``fj arm init``, or ``config/ur5``,
``config/panda``; relative to the campaign file) runs its offline twin
(``freejoint_tools.arm_twin.twin``: its files' start posture, law, circle and hold, as
``make offline ARM=DIR``) per run; axes ``scale`` (the controller's ``nominal_scale``),
``dist_bound`` and ``seed`` (:data:`SPATIAL_AXES`); ``duration`` (default the circle and
the hold) and ``success`` as above; ``case``, ``task``, ``dt``, ``dt_sub``, ``controller``
and ``laws`` are the arm's files' (refused).  Its columns: ``q3_*`` the free joint's
angles, ``min_det`` the smallest kappa, ``tau_peak_*`` NaN (the planar arm's joints).

Axes (:data:`AXES`): ``scale`` (masses, inertias and COM distances together) or
``scale_mass``, ``scale_inertia``, ``scale_lc``; ``dist_bound`` [N m], ``dist_type``
(``uniform`` | ``constant``); ``noise_q`` [rad], ``noise_qd`` [rad/s], ``noise_tau``
[N m] (standard deviations); ``delay`` [ticks]; ``lag`` [s]; ``q3_0_deg`` [deg];
``seed``.  A run's seed is its design point's seed axis value, else ``0 .. seeds-1``
(grid) or the run index (lhs, random).

Results folder: ``campaign.yaml`` (the file as read), ``chunks/`` (one Parquet file per
finished chunk, written whole then renamed: what a Ctrl-C or a lost worker leaves is
only finished chunks, and ``run`` again resumes, skipping them), ``results.parquet``
(every run, sorted by ``run_index``), after ``report`` ``summary.md`` and ``*.png``.
"""

import argparse
import hashlib
import itertools
import math
import os
import sys
import time

import numpy as np
import yaml

AXES = ('scale', 'scale_mass', 'scale_inertia', 'scale_lc', 'dist_bound', 'dist_type',
        'noise_q', 'noise_qd', 'noise_tau', 'delay', 'lag', 'q3_0_deg', 'seed')
"""Names an axis (or a ``fixed`` entry) may have."""
PAPER_POINT = {'scale': 0.7, 'scale_mass': 0.7, 'scale_inertia': 0.7, 'scale_lc': 0.7,
               'dist_bound': 0.5, 'dist_type': 'uniform', 'noise_q': 0.0, 'noise_qd': 0.0,
               'noise_tau': 0.0, 'delay': 0, 'lag': 0.0, 'q3_0_deg': 120.0, 'seed': 0}
"""The paper's point (Sec. 4): 70 % nominal, |d| <= 0.5 N m, exact sensors and actuators."""
_BOUNDS = {  # axis: (lowest, highest, lowest excluded, integer)
    # scale, scale_lc <= 2: Table I's COM (0.25 m) stays within its 0.5 m link.
    'scale': (0.0, 2.0, True, False), 'scale_mass': (0.0, 10.0, True, False),
    'scale_inertia': (0.0, 10.0, True, False), 'scale_lc': (0.0, 2.0, True, False),
    'dist_bound': (0.0, 1e3, False, False), 'noise_q': (0.0, 1.0, False, False),
    'noise_qd': (0.0, 100.0, False, False), 'noise_tau': (0.0, 1e3, False, False),
    'delay': (0, 1000, False, True), 'lag': (0.0, 10.0, False, False),
    'q3_0_deg': (-360.0, 360.0, False, False), 'seed': (0, 2 ** 63 - 1, False, True)}
TOP_KEYS = ('name', 'arm', 'case', 'task', 'duration', 'dt', 'dt_sub', 'laws', 'controller',
            'success', 'design', 'seeds', 'fixed', 'axes', 'chunk')
SPATIAL_AXES = ('scale', 'dist_bound', 'seed')
"""The axes of a spatial arm's campaign (its controller's nominal scale, its disturbance)."""
SPATIAL_FILE_KEYS = ('case', 'task', 'dt', 'dt_sub', 'controller', 'laws')
"""Campaign keys a spatial arm takes from its parameter files instead."""
DESIGNS = ('grid', 'lhs', 'random')
SUCCESS_KEYS = ('max_mm', 'rms_mm', 'final_mm')
DEFAULT_CHUNK = 250
INPUT_COLUMNS = ('run_index',) + tuple(a for a in AXES if a != 'scale')
METRIC_COLUMNS = ('rms_mm', 'max_mm', 'final_mm', 'tau_peak_1_nm', 'tau_peak_2_nm',
                  'q3_min_deg', 'q3_max_deg', 'q3_range_deg', 'min_det', 'theta_final_norm',
                  'diverged_at_s', 'ticks', 'holds')


class CampaignError(Exception):
    """A bad campaign file or results folder: one line naming the problem, exit status 2."""


# -- the campaign file ------------------------------------------------------------------


def _number(where, value, integer=False):
    if isinstance(value, str):   # YAML 1.1 reads 1e-3 (no dot) as a string
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CampaignError(f'{where}: expected a number, got {value!r}')
    if not math.isfinite(value):
        raise CampaignError(f'{where}: must be finite, got {value!r}')
    if integer and value != int(value):
        raise CampaignError(f'{where}: expected an integer, got {value!r}')
    return int(value) if integer else float(value)


def _axis_value(axis, where, value):
    if axis == 'dist_type':
        from freejoint_core.batch import DIST_TYPES
        if value not in DIST_TYPES:
            raise CampaignError(f'{where}: expected one of {list(DIST_TYPES)}, got {value!r}')
        return value
    lo, hi, strict, integer = _BOUNDS[axis]
    v = _number(where, value, integer)
    if v < lo or v > hi or (strict and v == lo):
        raise CampaignError(
            f'{where}: {v!r} is out of range ({"(" if strict else "["}{lo}, {hi}])')
    return v


def _check_axis(name, spec, kind):
    where = f'axes.{name}'
    if name not in AXES:
        raise CampaignError(f'{where}: unknown axis (known: {", ".join(AXES)})')
    if not isinstance(spec, dict):
        raise CampaignError(f'{where}: expected a mapping with values or range, got {spec!r}')
    unknown = sorted(set(spec) - {'values', 'range', 'steps'})
    if unknown:
        raise CampaignError(f'{where}.{unknown[0]}: unknown key (values, range, steps)')
    if ('values' in spec) == ('range' in spec):
        raise CampaignError(f'{where}: give exactly one of values or range')
    if 'values' in spec:
        vals = spec['values']
        if not isinstance(vals, list) or not vals:
            raise CampaignError(f'{where}.values: expected a non-empty list, got {vals!r}')
        if 'steps' in spec:
            raise CampaignError(f'{where}.steps: only with range')
        return {'values': [_axis_value(name, f'{where}.values[{i}]', v)
                           for i, v in enumerate(vals)]}
    rng = spec['range']
    if name == 'dist_type':
        raise CampaignError(f'{where}.range: dist_type takes values, not a range')
    if not isinstance(rng, list) or len(rng) != 2:
        raise CampaignError(f'{where}.range: expected [low, high], got {rng!r}')
    lo = _axis_value(name, f'{where}.range[0]', rng[0])
    hi = _axis_value(name, f'{where}.range[1]', rng[1])
    if not lo < hi:
        raise CampaignError(f'{where}.range: low must be < high, got {rng!r}')
    if kind == 'grid':
        steps = spec.get('steps')
        if steps is None:
            raise CampaignError(f'{where}.steps: a grid range needs steps (>= 2)')
        steps = _number(f'{where}.steps', steps, integer=True)
        if steps < 2 or steps > 10000:
            raise CampaignError(f'{where}.steps: expected 2 .. 10000, got {steps}')
        vals = np.linspace(lo, hi, steps)
        if _BOUNDS[name][3]:
            vals = np.unique(np.round(vals).astype(np.int64))
        return {'values': vals.tolist()}
    if 'steps' in spec:
        raise CampaignError(f'{where}.steps: only in a grid design')
    return {'range': [lo, hi]}


def _check_controller(given):
    """
    Return the Gains of the controller-node parameters ``given`` (their schema checks).

    The laws' own gains (``vsc.phi``, ``freejoint_core.laws.gain_schema``) are checked by
    their declarations and left to :func:`_law_params`.
    """
    from freejoint_core.control import Gains
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.laws import gain_schema
    if not isinstance(given, dict):
        raise CampaignError(f'controller: expected a mapping of parameters, got {given!r}')
    try:
        from freejoint_control.params import GAIN_NAMES, SCHEMA
    except ImportError:   # without the ROS workspace: the core's own checks of the gains
        SCHEMA = None
        GAIN_NAMES = ('K', 'Lambda', 'R', 'Gamma', 'sigma', 'epsilon', 'h_form', 'theta0',
                      'robust', 'det_threshold')
    used = GAIN_NAMES + ('theta_max', 'effort_limits')
    fields = {}
    law_gains = {g.name: g for g in gain_schema()}
    for name, value in given.items():
        where = f'controller.{name}'
        if name in law_gains:
            problem = law_gains[name].reason(value)
            if problem:
                raise CampaignError(f'controller.{problem}')
            continue
        if SCHEMA is not None and name not in SCHEMA:
            raise CampaignError(f'{where}: not a parameter of the controller node')
        if name not in used:
            raise CampaignError(f'{where}: a node parameter the offline loop does not model '
                                f'(campaigns take {", ".join(used)})')
        if SCHEMA is not None:
            problem = SCHEMA[name].reason(value)
            if problem:
                raise CampaignError(f'controller.{problem}')
        key = 'tau_limit' if name == 'effort_limits' else name
        fields[key] = tuple(value) if isinstance(value, list) else value
    if 'tau_limit' in fields:
        fields['tau_limit'] = fields['tau_limit'][:2]
    try:
        return Gains(**fields)
    except (FreejointValueError, TypeError) as exc:
        raise CampaignError(f'controller.{exc}') from None


def load(path):
    """
    Read and check a campaign file; return the campaign as a plain dict.

    Parameters
    ----------
    path : str
        YAML file.

    Returns
    -------
    dict
        Normalised campaign (``axes`` with explicit ``values`` or ``range``, defaults
        filled in) plus ``'_gains'`` (``freejoint_core.control.Gains``) and ``'_text'``
        (the file's text).

    Raises
    ------
    CampaignError
        Naming the field at fault.

    """
    try:
        with open(path, encoding='utf-8') as f:
            text = f.read()
    except OSError as exc:
        raise CampaignError(f'{path}: cannot read: {exc.strerror}') from None
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CampaignError(f'{path}: not YAML: {str(exc).splitlines()[0]}') from None
    camp = parse(raw, os.path.dirname(os.path.abspath(path)))
    camp['_text'] = text
    return camp


def parse(raw, base_dir='.'):
    """
    Check a campaign given as a dict (the parsed YAML); see :func:`load`.

    ``base_dir``: what a spatial arm's relative directory is relative to (the file's).
    """
    from freejoint_core.arm import CASES, table1
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.offline import initial_state
    from freejoint_core.trajectory import CircleQuintic
    if not isinstance(raw, dict):
        raise CampaignError(f'campaign: expected a mapping, got {type(raw).__name__}')
    unknown = sorted(set(raw) - set(TOP_KEYS))
    if unknown:
        raise CampaignError(f'{unknown[0]}: unknown key (known: {", ".join(TOP_KEYS)})')
    c = {}
    name = raw.get('name', 'campaign')
    if not isinstance(name, str) or not name or not all(ch.isalnum() or ch in '_-.'
                                                        for ch in name):
        raise CampaignError(f'name: expected letters, digits, _ - . only, got {name!r}')
    c['name'] = name
    arm = raw.get('arm', 'paper')
    if isinstance(arm, str) and arm != 'paper':
        return _parse_spatial(raw, c, os.path.normpath(os.path.join(base_dir, arm)))
    case = raw.get('case', 'vertical')
    if case not in CASES:
        raise CampaignError(f'case: expected one of {list(CASES)}, got {case!r}')
    c['case'] = case
    if isinstance(arm, dict):
        c['arm'], real = _urdf_arm(arm, case)
        c['_arms'] = {False: real, True: real}
    elif arm == 'paper':
        c['arm'] = 'paper'
        real = table1(case)
    else:
        raise CampaignError(f"arm: expected 'paper', {{urdf: PATH, ...}} or a spatial arm's "
                            f'directory, got {arm!r}')
    task = raw.get('task', {})
    if not isinstance(task, dict) or set(task) - {'centre', 'radius', 'duration'}:
        raise CampaignError(f'task: expected a mapping of centre, radius, duration, got {task!r}')
    try:
        CircleQuintic(**task)
    except (FreejointValueError, TypeError) as exc:
        raise CampaignError(f'task.{exc}') from None
    c['task'] = {'centre': [float(v) for v in task.get('centre', (0.0, 0.0))],
                 'radius': float(task.get('radius', 0.2)),
                 'duration': float(task.get('duration', 5.0))}
    for key, default in (('duration', c['task']['duration']), ('dt', 1e-3), ('dt_sub', 5e-4)):
        v = _number(key, raw.get(key, default))
        if v <= 0.0:
            raise CampaignError(f'{key}: must be > 0, got {v}')
        c[key] = v
    if c['duration'] / c['dt'] > 1e6:
        raise CampaignError(f'duration: {c["duration"]} s is more than 1e6 ticks')
    from freejoint_core.batch import check_grid
    try:
        check_grid(c['dt'], c['dt_sub'], c['duration'])
    except FreejointValueError as exc:
        raise CampaignError(str(exc)) from None
    c['_gains'] = _check_controller(raw.get('controller') or {})
    c['controller'] = dict(raw.get('controller') or {})
    c['_law_params'] = {k: float(v) for k, v in c['controller'].items() if '.' in k}
    if 'laws' in raw:
        c['laws'] = _check_laws(raw['laws'])
    _parse_runs(raw, c)
    # Every initial passive angle must have an initial state (inverse kinematics).
    q3s = set()
    spec = c['axes'].get('q3_0_deg')
    if spec is None:
        q3s.add(c['fixed'].get('q3_0_deg', PAPER_POINT['q3_0_deg']))
    elif 'values' in spec:
        q3s.update(spec['values'])
    else:
        q3s.update(np.linspace(spec['range'][0], spec['range'][1], 721).tolist())
    start = CircleQuintic(**c['task']).sample(0.0)[0]
    _check_lc(c, real)
    for q3 in sorted(q3s):
        try:
            initial_state(real, q3, start)
        except FreejointValueError:
            raise CampaignError(f'axes.q3_0_deg: {q3:g} deg: no configuration puts the end '
                                f'effector on the start of the task') from None
    return c


def _parse_runs(raw, c):
    """Check what every campaign has: success, design, seeds, axes, fixed, chunk (into c)."""
    success = raw.get('success', {'max_mm': 20.0})
    if not isinstance(success, dict) or not success:
        raise CampaignError(f'success: expected a mapping of bounds, got {success!r}')
    for key, v in success.items():
        if key not in SUCCESS_KEYS:
            raise CampaignError(f'success.{key}: unknown bound (known: {", ".join(SUCCESS_KEYS)})')
        if _number(f'success.{key}', v) <= 0.0:
            raise CampaignError(f'success.{key}: must be > 0, got {v}')
    c['success'] = {k: float(v) for k, v in success.items()}
    design = raw.get('design', {'kind': 'grid'})
    if not isinstance(design, dict) or design.get('kind') not in DESIGNS:
        raise CampaignError(f'design.kind: expected one of {list(DESIGNS)}, got '
                            f'{design.get("kind") if isinstance(design, dict) else design!r}')
    kind = design['kind']
    allowed = {'kind'} if kind == 'grid' else {'kind', 'samples', 'seed'}
    bad = sorted(set(design) - allowed)
    if bad:
        raise CampaignError(f'design.{bad[0]}: not a key of a {kind} design')
    c['design'] = {'kind': kind}
    if kind != 'grid':
        samples = _number('design.samples', design.get('samples', 0), integer=True)
        if samples < 1 or samples > 10 ** 7:
            raise CampaignError(f'design.samples: expected 1 .. 1e7, got {samples}')
        c['design']['samples'] = samples
        c['design']['seed'] = _axis_value('seed', 'design.seed', design.get('seed', 0))
    seeds = _number('seeds', raw.get('seeds', 1), integer=True)
    if seeds < 1 or seeds > 10 ** 6:
        raise CampaignError(f'seeds: expected 1 .. 1e6, got {seeds}')
    c['seeds'] = seeds
    axes = raw.get('axes')
    if not isinstance(axes, dict) or not axes:
        raise CampaignError('axes: expected a mapping of at least one axis')
    c['axes'] = {k: _check_axis(k, v, kind) for k, v in axes.items()}
    if 'seed' in c['axes'] and seeds != 1:
        raise CampaignError('seeds: give either seeds or a seed axis')
    if 'scale' in c['axes'] and any(a in c['axes'] for a in
                                    ('scale_mass', 'scale_inertia', 'scale_lc')):
        raise CampaignError('axes.scale: varies all three groups; drop scale_mass, '
                            'scale_inertia, scale_lc or scale')
    fixed = raw.get('fixed') or {}
    if not isinstance(fixed, dict):
        raise CampaignError(f'fixed: expected a mapping, got {fixed!r}')
    c['fixed'] = {}
    for k, v in fixed.items():
        if k not in AXES:
            raise CampaignError(f'fixed.{k}: unknown axis (known: {", ".join(AXES)})')
        if k in c['axes']:
            raise CampaignError(f'fixed.{k}: also an axis')
        c['fixed'][k] = _axis_value(k, f'fixed.{k}', v)
    chunk = _number('chunk', raw.get('chunk', DEFAULT_CHUNK), integer=True)
    if chunk < 1 or chunk > 100000:
        raise CampaignError(f'chunk: expected 1 .. 100000, got {chunk}')
    c['chunk'] = chunk


def _parse_spatial(raw, c, arm_dir):
    """Check the campaign of a spatial arm's directory (module notes); return it."""
    from freejoint_tools.arm_twin import arm_info, run_ticks
    given = [k for k in SPATIAL_FILE_KEYS if k in raw]
    if given:
        raise CampaignError(f'{given[0]}: a spatial arm takes it from its parameter files '
                            f'({arm_dir}/<node>.yaml)')
    try:
        c['_info'] = arm_info(arm_dir)
        ticks = run_ticks(arm_dir)
    except (OSError, ValueError) as exc:
        raise CampaignError(f'arm: {exc}') from None
    c['arm'] = {'dir': arm_dir}
    c['case'] = 'spatial'
    c['task'] = None
    c['dt'], c['dt_sub'], c['controller'] = 1e-3, None, {}
    duration = _number('duration', raw.get('duration', ticks * 1e-3))
    if not 0.0 < duration <= 1e3:
        raise CampaignError(f'duration: expected 0 .. 1000 s, got {duration}')
    c['duration'] = duration
    _parse_runs(raw, c)
    for where, names in (('axes', c['axes']), ('fixed', c['fixed'])):
        bad = sorted(set(names) - set(SPATIAL_AXES))
        if bad:
            raise CampaignError(f'{where}.{bad[0]}: not an axis of a spatial arm (its axes: '
                                f'{", ".join(SPATIAL_AXES)})')
    return c


def _check_laws(laws):
    """Return the list of registered law names a campaign compares."""
    from freejoint_core.laws import LAWS
    if not isinstance(laws, list) or not laws:
        raise CampaignError(f'laws: expected a non-empty list of law names, got {laws!r}')
    for i, name in enumerate(laws):
        if name not in LAWS or name == 'spatial':
            known = [k for k in LAWS if k != 'spatial']
            raise CampaignError(f'laws[{i}]: expected one of {known}, got {name!r}')
    if len(set(laws)) != len(laws):
        raise CampaignError(f'laws: a law named twice in {laws}')
    return list(laws)


URDF_ARM_KEYS = ('urdf', 'passive_joints', 'tip_link', 'gravity')
"""Keys of a URDF ``arm`` entry (``urdf`` required)."""


def _urdf_arm(arm, case):
    """Return the normalised ``arm`` entry of a URDF arm and its real ``ArmParams``."""
    from freejoint_common.arm_description import package_path
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.urdf import GRAVITY_BY_CASE, parse_urdf
    bad = sorted(set(arm) - set(URDF_ARM_KEYS))
    if bad:
        raise CampaignError(f'arm.{bad[0]}: unknown key (known: {", ".join(URDF_ARM_KEYS)})')
    path = arm.get('urdf')
    if not isinstance(path, str) or not path:
        raise CampaignError(f'arm.urdf: expected the path of a URDF file, got {path!r}')
    passive = arm.get('passive_joints', ['joint3'])
    tip = arm.get('tip_link', '')
    if not isinstance(tip, str):
        raise CampaignError(f'arm.tip_link: expected a link name, got {tip!r}')
    gravity = arm.get('gravity', list(GRAVITY_BY_CASE[case]))
    try:
        text_path = package_path(path)
        with open(text_path, encoding='utf-8') as f:
            text = f.read()
    except (OSError, FreejointValueError) as exc:
        raise CampaignError(f'arm.urdf: cannot read {path}: '
                            f'{getattr(exc, "strerror", None) or exc}') from None
    try:
        urdf = parse_urdf(text, passive, gravity, tip)
    except FreejointValueError as exc:
        raise CampaignError(f'arm: {path}: {exc}') from None
    real = urdf.params
    if real.n != 3 or real.passive != (2,):
        raise CampaignError(
            f'arm.passive_joints: campaigns run 3-link arms whose last joint alone is passive '
            f'(the batch kernel); {path} has {real.n} joints {list(urdf.joint_names)}, '
            f'passive {list(urdf.passive_joints)}')
    entry = {'urdf': path, 'passive_joints': list(urdf.passive_joints), 'tip_link': tip,
             'gravity': [float(g) for g in urdf.gravity_vector],
             'sha256': hashlib.sha256(text.encode()).hexdigest()[:16]}
    return entry, real


def _check_lc(c, real):
    """Refuse a COM scale that puts a nominal link's centre of mass beyond its end."""
    lc_max = min(length / com for length, com in zip(real.lengths, real.com))
    for name in ('scale', 'scale_lc'):
        spec = c['axes'].get(name)
        values = ([c['fixed'][name]] if name in c['fixed'] else []) if spec is None else (
            spec['values'] if 'values' in spec else list(spec['range']))
        for v in values:
            if v > lc_max + 1e-12:
                where = f'axes.{name}' if spec is not None else f'fixed.{name}'
                raise CampaignError(
                    f"{where}: {v:g} puts a nominal centre of mass beyond its link's end "
                    f'(this arm: at most {lc_max:.4g})')


# -- the design -------------------------------------------------------------------------


def _lhs(n, d, seed):
    """Latin hypercube: (n, d) points in [0, 1), one per stratum per column, seeded."""
    rng = np.random.default_rng([24, 0, seed])
    u = np.empty((n, d))
    for j in range(d):
        u[:, j] = (rng.permutation(n) + rng.random(n)) / n
    return u


def design(camp):
    """
    Expand a checked campaign into its runs.

    Parameters
    ----------
    camp : dict
        From :func:`load` / :func:`parse`.

    Returns
    -------
    dict of str to numpy.ndarray, each (n,)
        ``run_index`` and every :data:`AXES` name but ``scale`` (a varied ``scale``
        sets the three groups); ``dist_type`` as strings.

    """
    axes = camp['axes']
    kind = camp['design']['kind']
    names = list(axes)
    if kind == 'grid':
        points = list(itertools.product(*[axes[a]['values'] for a in names]))
        cols = {a: [p[j] for p in points] for j, a in enumerate(names)}
        n_pts = len(points)
    else:
        n_pts = camp['design']['samples']
        dseed = camp['design']['seed']
        if kind == 'lhs':
            u = _lhs(n_pts, len(names), dseed)
        else:
            u = np.random.default_rng([24, 0, dseed]).random((n_pts, len(names)))
        cols = {}
        for j, a in enumerate(names):
            spec = axes[a]
            if 'values' in spec:
                vals = spec['values']
                cols[a] = [vals[min(int(x * len(vals)), len(vals) - 1)] for x in u[:, j]]
            else:
                lo, hi = spec['range']
                x = lo + (hi - lo) * u[:, j]
                if _BOUNDS[a][3]:
                    x = np.minimum(np.floor(lo + (hi - lo + 1) * u[:, j]), hi).astype(np.int64)
                cols[a] = x.tolist()
    seeds = camp['seeds']
    n = n_pts * seeds
    out = {'run_index': np.arange(n, dtype=np.int64)}
    point = dict(PAPER_POINT)
    point.update(camp['fixed'])
    if 'scale' in camp['fixed']:
        for g in ('scale_mass', 'scale_inertia', 'scale_lc'):
            point[g] = camp['fixed']['scale'] if g not in camp['fixed'] else point[g]
    for a in AXES:
        if a == 'scale':
            continue
        src = 'scale' if a.startswith('scale_') and 'scale' in cols else a
        if src in cols:
            vals = np.repeat(np.array(cols[src], dtype=object), seeds)
        else:
            vals = np.array([point[a]] * n, dtype=object)
        if a == 'dist_type':
            out[a] = vals.astype(str)
        elif _BOUNDS[a][3]:
            out[a] = vals.astype(np.int64)
        else:
            out[a] = vals.astype(float)
    if 'seed' not in cols and 'seed' not in camp['fixed']:
        if kind == 'grid':
            out['seed'] = np.tile(np.arange(seeds, dtype=np.int64), n_pts)
        else:
            out['seed'] = np.arange(n, dtype=np.int64)
    return out


def _batch_runs(rows, case):
    from freejoint_core.batch import DIST_TYPES
    runs = {a: rows[a] for a in AXES if a not in ('scale', 'dist_type')}
    runs['dist_type'] = np.array([DIST_TYPES.index(v) for v in rows['dist_type']],
                                 dtype=np.int64)
    runs['vertical'] = np.full(len(rows['run_index']), case == 'vertical')
    return runs


def run_chunk(camp, rows):
    """
    Simulate the runs ``rows`` (a slice of :func:`design`); return their result columns.

    Parameters
    ----------
    camp : dict
        Checked campaign.
    rows : dict of str to numpy.ndarray
        Input columns of the runs.

    Returns
    -------
    dict of str to numpy.ndarray
        ``rows`` and :data:`METRIC_COLUMNS`.

    """
    from freejoint_core.batch import simulate_law
    from freejoint_core.trajectory import CircleQuintic
    if camp['case'] == 'spatial':
        return _spatial_chunk(camp, rows)
    res = simulate_law(_batch_runs(rows, camp['case']), camp['_gains'],
                       law=camp.get('_law', 'robust'), law_params=camp['_law_params'],
                       dt=camp['dt'], dt_sub=camp['dt_sub'], duration=camp['duration'],
                       trajectory=CircleQuintic(**camp['task']), arms=camp.get('_arms'))
    return _results(camp, rows, res)


def _results(camp, rows, res):
    """Return the result columns of ``rows`` and the runs' metrics ``res`` (and ``holds``)."""
    out = dict(rows)
    for k, v in res.items():
        out[k] = v
    out['q3_range_deg'] = res['q3_max_deg'] - res['q3_min_deg']
    holds = ~np.isfinite(res['diverged_at_s'])
    for key, bound in camp['success'].items():
        holds &= res[key] <= bound
    out['holds'] = holds
    return {k: out[k] for k in INPUT_COLUMNS + METRIC_COLUMNS}


def _spatial_chunk(camp, rows):
    """:func:`run_chunk` of a spatial arm: its offline twin per run (module notes)."""
    from freejoint_tools.arm_twin import twin
    cols = {k: np.full(len(rows['run_index']), np.nan) for k in METRIC_COLUMNS
            if k not in ('q3_range_deg', 'holds')}
    ticks = int(round(camp['duration'] / camp['dt']))
    for i in range(len(rows['run_index'])):
        record, trace = twin(camp['arm']['dir'], int(rows['seed'][i]), ticks,
                             sim={'dist_bound': float(rows['dist_bound'][i])},
                             controller={'nominal_scale': float(rows['scale_mass'][i])})
        err = 1e3 * np.linalg.norm(trace['p'] - trace['p_d'], axis=1)
        free = np.degrees(trace['q'][:, record_free(trace, camp)])
        values = {'rms_mm': record['rms_mm'], 'max_mm': record['max_mm'],
                  'final_mm': err[-1], 'q3_min_deg': free.min(), 'q3_max_deg': free.max(),
                  'min_det': float(np.min(trace['kappa'])),
                  'theta_final_norm': float(np.linalg.norm(trace['theta'][-1])),
                  'diverged_at_s': (np.nan if record['diverged_at_s'] is None
                                    else record['diverged_at_s']),
                  'ticks': len(err)}
        for k, v in values.items():
            cols[k][i] = v
    cols['ticks'] = cols['ticks'].astype(np.int64)
    return _results(camp, rows, cols)


def record_free(trace, camp):
    """Return the column of the trace's ``q`` that is the arm's (first) free joint."""
    from freejoint_tools.arm_twin import arm_configs
    if '_free' not in camp:
        real = arm_configs(camp['arm']['dir'])[0].arm.spatial
        camp['_free'] = real.passive[0]
    return camp['_free']


# -- results files ----------------------------------------------------------------------


def _table(cols):
    import pyarrow as pa
    return pa.table({k: cols[k] for k in INPUT_COLUMNS + METRIC_COLUMNS})


def _write_parquet(table, path):
    import pyarrow.parquet as pq
    tmp = path + '.tmp'
    pq.write_table(table, tmp, compression='zstd')
    os.replace(tmp, path)


def _chunk_path(out_dir, i):
    return os.path.join(out_dir, 'chunks', f'chunk_{i:06d}.parquet')


def _fingerprint(camp):
    keys = ('arm', 'case', 'task', 'duration', 'dt', 'dt_sub', 'controller', 'success',
            'design', 'seeds', 'fixed', 'axes', 'chunk')
    extra = [camp[k] for k in ('laws', '_law') if k in camp]   # none: a one-law campaign
    return hashlib.sha256(repr([camp[k] for k in keys] + extra).encode()).hexdigest()[:16]


class Progress:
    """A one-line progress bar on stderr: runs done, rate, time left."""

    def __init__(self, total, done=0, stream=None):
        self.total = total
        self.start_done = done
        self.done = done
        self.t0 = time.monotonic()
        self.stream = sys.stderr if stream is None else stream
        self.tty = hasattr(self.stream, 'isatty') and self.stream.isatty()

    def update(self, n):
        """Count ``n`` more runs done and redraw."""
        self.done += n
        el = time.monotonic() - self.t0
        rate = (self.done - self.start_done) / el if el > 0 else 0.0
        left = (self.total - self.done) / rate if rate > 0 else math.inf
        width = 30
        fill = int(width * self.done / self.total) if self.total else width
        line = (f'[{"#" * fill}{"." * (width - fill)}] {self.done}/{self.total} runs, '
                f'{rate:.0f} runs/s, {"?" if math.isinf(left) else f"{left:.0f} s"} left')
        self.stream.write(('\r' if self.tty else '') + line + ('' if self.tty else '\n'))
        self.stream.flush()

    def close(self):
        """End the line."""
        if self.tty:
            self.stream.write('\n')
            self.stream.flush()


def _slice(rows, lo, hi):
    return {k: v[lo:hi] for k, v in rows.items()}


def run(camp, out_dir, address=None, progress=True, max_chunks=None):
    """
    Run a checked campaign into ``out_dir`` (resuming what is there); return the results path.

    Parameters
    ----------
    camp : dict
        From :func:`load`.
    out_dir : str
        Results folder (created; a folder of another campaign is refused).
    address : str, optional
        Ray cluster address (``HOST:PORT`` or ``auto``; ``local`` starts Ray in this
        process); None runs in this process.
    progress : bool
        Draw the progress bar.
    max_chunks : int, optional
        Stop after this many new chunks (tests of resume).

    Returns
    -------
    str or None
        ``out_dir/results.parquet``, or None when stopped before the end.

    """
    if 'laws' in camp and '_law' not in camp:
        _start(camp, out_dir)
        paths = [run(dict(camp, _law=law), os.path.join(out_dir, law), address, progress,
                     max_chunks) for law in camp['laws']]
        return None if None in paths else out_dir
    rows = design(camp)
    n = len(rows['run_index'])
    chunk = camp['chunk']
    spans = [(i, lo, min(lo + chunk, n)) for i, lo in enumerate(range(0, n, chunk))]
    os.makedirs(os.path.join(out_dir, 'chunks'), exist_ok=True)
    _start(camp, out_dir)
    todo = [s for s in spans if not os.path.exists(_chunk_path(out_dir, s[0]))]
    if max_chunks is not None:
        todo = todo[:max_chunks]
    done_runs = n - sum(hi - lo for _, lo, hi in
                        [s for s in spans if not os.path.exists(_chunk_path(out_dir, s[0]))])
    bar = Progress(n, done_runs) if progress else None
    try:
        if address is None:
            for i, lo, hi in todo:
                _write_parquet(_table(run_chunk(camp, _slice(rows, lo, hi))),
                               _chunk_path(out_dir, i))
                if bar:
                    bar.update(hi - lo)
        else:
            _run_ray(camp, rows, todo, out_dir, address, bar)
    except KeyboardInterrupt:
        if bar:
            bar.close()
        kept = sum(os.path.exists(_chunk_path(out_dir, s[0])) for s in spans)
        print(f'campaign: stopped; {kept} of {len(spans)} chunks kept in {out_dir}/chunks '
              '(run the same command again to resume)', file=sys.stderr)
        raise
    if bar:
        bar.close()
    if not all(os.path.exists(_chunk_path(out_dir, s[0])) for s in spans):
        return None
    return merge(out_dir, n)


def _start(camp, out_dir):
    """Stamp ``out_dir`` with the campaign (refusing another's folder); write its file."""
    os.makedirs(out_dir, exist_ok=True)
    stamp = os.path.join(out_dir, 'fingerprint')
    fp = _fingerprint(camp)
    if os.path.exists(stamp):
        with open(stamp) as f:
            if f.read().strip() != fp:
                raise CampaignError(f'{out_dir}: holds the results of another campaign '
                                    '(remove it or choose another --out)')
    else:
        with open(stamp, 'w') as f:
            f.write(fp + '\n')
    with open(os.path.join(out_dir, 'campaign.yaml'), 'w', encoding='utf-8') as f:
        f.write(camp.get('_text') or yaml.safe_dump(
            {k: v for k, v in camp.items() if not k.startswith('_')}))


def merge(out_dir, n):
    """Join the chunk files into ``results.parquet`` sorted by run index; check each run once."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    files = sorted(os.listdir(os.path.join(out_dir, 'chunks')))
    tables = [pq.read_table(os.path.join(out_dir, 'chunks', f)) for f in files
              if f.endswith('.parquet')]
    table = pa.concat_tables(tables).sort_by('run_index')
    idx = table.column('run_index').to_numpy()
    if len(idx) != n or not np.array_equal(idx, np.arange(n)):
        raise CampaignError(f'{out_dir}: the chunks hold {len(idx)} rows for {n} runs '
                            '(some run missing or counted twice)')
    path = os.path.join(out_dir, 'results.parquet')
    _write_parquet(table, path)
    return path


def _ray_task(camp, rows, threads):
    import numba
    numba.set_num_threads(threads)
    return run_chunk(camp, rows)


def ray_tasks(address, fn, shared, jobs, on_result, retries=5):
    """
    Run ``fn(shared, *args)`` as one Ray task per job; hand each result to the driver.

    The Ray plumbing of campaigns, shared with ``freejoint_tools.spatial_map``: one CPU a
    task, a task whose worker dies retried (``retries`` times; an exception raised by
    ``fn`` is not retried, it ends the call), ``shared`` put in the object store once.

    Parameters
    ----------
    address : str
        Ray cluster address (``HOST:PORT`` or ``auto``; ``local`` starts Ray in this
        process).  Ray is shut down on return.
    fn : callable
        A module-level function (the workers import it by name).
    shared : object
        First argument of every task (picklable).
    jobs : iterable of (key, tuple)
        A key for the driver and the task's other arguments.
    on_result : callable
        ``on_result(key, result)``, called in this process as each task finishes (in
        the order they finish).
    retries : int
        Retries of a task whose worker died.

    """
    import ray
    if address == 'local':
        ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False)
    else:
        ray.init(address=address, log_to_driver=False, configure_logging=False)
    try:
        task = ray.remote(num_cpus=1, max_retries=retries, retry_exceptions=False)(fn)
        shared_ref = ray.put(shared)
        pending = {task.remote(shared_ref, *args): key for key, args in jobs}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                on_result(pending.pop(ref), ray.get(ref))
    finally:
        ray.shutdown()


def _run_ray(camp, rows, todo, out_dir, address, bar):
    def write(key, result):
        i, count = key
        path = _chunk_path(out_dir, i)
        if os.path.exists(path):   # never written twice
            return
        _write_parquet(_table(result), path)
        if bar:
            bar.update(count)

    ray_tasks(address, _ray_task, camp,
              [((i, hi - lo), (_slice(rows, lo, hi), 1)) for i, lo, hi in todo], write)


# -- the report -------------------------------------------------------------------------


def _read(results):
    import pyarrow.parquet as pq
    path = os.path.join(results, 'results.parquet') if os.path.isdir(results) else results
    if not os.path.exists(path):
        raise CampaignError(f'{results}: no results.parquet (has the campaign finished?)')
    folder = os.path.dirname(os.path.abspath(path))
    camp_path = os.path.join(folder, 'campaign.yaml')
    camp = load(camp_path) if os.path.exists(camp_path) else None
    return pq.read_table(path).to_pydict(), camp, folder


def _varied(cols, camp):
    names = [a for a in AXES if a != 'scale' and a != 'seed'
             and len(set(cols[a])) > 1 and a != 'dist_type']
    if camp is not None and 'scale' in camp['axes']:
        names = ['scale'] + [a for a in names if not a.startswith('scale_')]
        cols['scale'] = cols['scale_mass']
    return names


def _bins(values, axis, k=8):
    """Return (edges or None, labels, index per run) binning ``values``."""
    v = np.asarray(values, dtype=float)
    uniq = np.unique(v)
    if len(uniq) <= 12:
        idx = np.searchsorted(uniq, v)
        return uniq, [f'{u:g}' for u in uniq], idx
    edges = np.linspace(v.min(), v.max(), k + 1)
    idx = np.clip(np.searchsorted(edges, v, side='right') - 1, 0, k - 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    return centres, [f'{c:.3g}' for c in centres], idx


def _bin_rows(cols, names):
    """Yield ``(axis, label, selection)`` per non-empty value (bin) of each axis."""
    for a in names:
        _, labels, idx = _bins(cols[a], a)
        for b, lab in enumerate(labels):
            sel = idx == b
            if sel.any():
                yield a, lab, sel


def summary(cols, names):
    """Return the summary table (Markdown): overall, then per value (bin) of each axis."""
    holds = np.asarray(cols['holds'])
    mx = np.asarray(cols['max_mm'])
    div = np.isfinite(np.asarray(cols['diverged_at_s'], dtype=float))
    lines = [f'runs: {len(holds)}, law holds in {holds.mean():.1%}, diverged {div.sum()}, '
             f'worst max error {np.nanmax(mx):.3g} mm, median RMS '
             f'{np.median(cols["rms_mm"]):.3g} mm', '',
             '| axis | value | runs | holds | diverged | worst max (mm) | median rms (mm) |',
             '|---|---:|---:|---:|---:|---:|---:|']
    for a, lab, sel in _bin_rows(cols, names):
        lines.append(f'| {a} | {lab} | {sel.sum()} | {holds[sel].mean():.1%} '
                     f'| {div[sel].sum()} | {mx[sel].max():.3g} '
                     f'| {np.median(np.asarray(cols["rms_mm"])[sel]):.3g} |')
    return '\n'.join(lines)


def _save(fig, path):
    """Write ``fig`` to ``path`` (90 dpi) and close it; return the path."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _frame(ax, x, y, paper):
    """Label a cell plot's axes ``(name, centres, labels)``; star the paper's point."""
    (a, ca, la), (b, cb, lb) = x, y
    ax.set_xticks(range(len(la)), la, rotation=45, fontsize=7)
    ax.set_yticks(range(len(lb)), lb, fontsize=7)
    ax.set_xlabel(a)
    ax.set_ylabel(b)
    px = np.interp(paper[a], ca, np.arange(len(ca))) if a in paper else None
    py = np.interp(paper[b], cb, np.arange(len(cb))) if b in paper else None
    if px is not None and py is not None:
        ax.plot(px, py, marker='*', color='w', markeredgecolor='k', markersize=14)


def heatmaps(cols, names, folder, paper=PAPER_POINT):
    """Draw success rate and worst max error over every pair of axes; return the files."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    holds = np.asarray(cols['holds'], dtype=float)
    mx = np.asarray(cols['max_mm'], dtype=float)
    files = []
    for a, b in itertools.combinations(names, 2):
        ca, la, ia = _bins(cols[a], a)
        cb, lb, ib = _bins(cols[b], b)
        rate = np.full((len(cb), len(ca)), np.nan)
        worst = np.full((len(cb), len(ca)), np.nan)
        for x in range(len(ca)):
            for y in range(len(cb)):
                sel = (ia == x) & (ib == y)
                if sel.any():
                    rate[y, x] = holds[sel].mean()
                    worst[y, x] = mx[sel].max()
        fig, axs = plt.subplots(1, 2, figsize=(11, 4.4))
        for ax, data, title, cmap, kw in (
                (axs[0], rate, 'law holds (fraction of runs)', 'RdYlGn', {'vmin': 0, 'vmax': 1}),
                (axs[1], np.log10(np.maximum(worst, 1e-3)), 'worst max error (log10 mm)',
                 'viridis', {})):
            im = ax.imshow(data, origin='lower', aspect='auto', cmap=cmap, **kw)
            fig.colorbar(im, ax=ax)
            ax.set_title(title, fontsize=9)
            if data is rate and np.nanmin(rate) < 0.5 < np.nanmax(rate):
                ax.contour(np.nan_to_num(rate, nan=0.0), levels=[0.5], colors='k',
                           linewidths=1.5)
            _frame(ax, (a, ca, la), (b, cb, lb), paper)
        fig.suptitle(f"{a} x {b}: {len(holds)} runs (star: the paper's point; black: "
                     '50 % boundary)', fontsize=9)
        files.append(_save(fig, os.path.join(folder, f'heatmap_{a}__{b}.png')))
    return files


def comparison(per_law, names):
    """
    Return the laws side by side (Markdown): overall, then per value (bin) of each axis.

    Parameters
    ----------
    per_law : dict of str to dict
        Result columns of each law (the same runs).
    names : list of str
        The varied axes.

    """
    laws = list(per_law)
    lines = ['| law | runs | holds | diverged | worst max (mm) | median rms (mm) |',
             '|---|---:|---:|---:|---:|---:|']
    for law, cols in per_law.items():
        holds = np.asarray(cols['holds'])
        div = np.isfinite(np.asarray(cols['diverged_at_s'], dtype=float))
        lines.append(f'| {law} | {len(holds)} | {holds.mean():.1%} | {div.sum()} '
                     f'| {np.nanmax(cols["max_mm"]):.3g} '
                     f'| {np.median(cols["rms_mm"]):.3g} |')
    lines += ['', '| axis | value | runs | ' + ' | '.join(
        f'{law} holds | {law} worst max (mm)' for law in laws) + ' |',
        '|---|---:|---:|' + '---:|---:|' * len(laws)]
    for a, lab, sel in _bin_rows(per_law[laws[0]], names):
        cells = [f'{np.asarray(cols["holds"])[sel].mean():.0%} '
                 f'| {np.asarray(cols["max_mm"], dtype=float)[sel].max():.3g}'
                 for cols in per_law.values()]
        lines.append(f'| {a} | {lab} | {sel.sum()} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


LAW_COLOURS = ('k', 'tab:blue', 'tab:orange', 'tab:green', 'tab:red', 'tab:purple')


def boundaries(per_law, names, folder, paper=PAPER_POINT):
    """Draw each law's 50 % boundary over every pair of axes on one figure; return files."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    first = next(iter(per_law.values()))
    files = []
    for a, b in itertools.combinations(names, 2):
        ca, la, ia = _bins(first[a], a)
        cb, lb, ib = _bins(first[b], b)
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        handles = []
        for j, (law, cols) in enumerate(per_law.items()):
            holds = np.asarray(cols['holds'], dtype=float)
            rate = np.zeros((len(cb), len(ca)))
            for x in range(len(ca)):
                for y in range(len(cb)):
                    sel = (ia == x) & (ib == y)
                    rate[y, x] = holds[sel].mean() if sel.any() else np.nan
            colour = LAW_COLOURS[j % len(LAW_COLOURS)]
            lo, hi = np.nanmin(rate), np.nanmax(rate)
            label = (f'{law}: holds {np.nanmean(holds):.0%}' + (
                ' (>= 50 % in every cell)' if lo >= 0.5 else
                ' (< 50 % in every cell)' if hi < 0.5 else ''))
            if lo < 0.5 <= hi:
                ax.contour(np.nan_to_num(rate, nan=0.0), levels=[0.5], colors=colour,
                           linewidths=2.0)
            handles.append(plt.Line2D([], [], color=colour, lw=2, label=label))
        _frame(ax, (a, ca, la), (b, cb, lb), paper)
        ax.set_xlim(-0.5, len(ca) - 0.5)
        ax.set_ylim(-0.5, len(cb) - 0.5)
        ax.legend(handles=handles, fontsize=8, loc='best')
        ax.set_title(f"{a} x {b}: each law's 50 % boundary, {len(ia)} runs (star: the "
                     "paper's point)", fontsize=8)
        files.append(_save(fig, os.path.join(folder, f'boundary_{a}__{b}.png')))
    return files


def report_laws(folder, camp, figures=True):
    """Report each law of a comparison (its folder), then the laws side by side."""
    per_law = {}
    for law in camp['laws']:
        report(os.path.join(folder, law), figures=figures)
        per_law[law] = _read(os.path.join(folder, law))[0]
    names = _varied(per_law[camp['laws'][0]], camp)
    for cols in per_law.values():
        _varied(cols, camp)
    return _publish(os.path.join(folder, 'comparison.md'), comparison(per_law, names),
                    (lambda: boundaries(per_law, names, folder)) if figures and len(names) >= 2
                    else None)


def _publish(path, text, draw):
    """Write and print ``text``; draw the figures (``draw()``: their files) and name them."""
    with open(path, 'w') as f:
        f.write(text + '\n')
    print(text)
    for fig in draw() if draw is not None else ():
        print(f'figure: {fig}')
    return 0


def report(results, figures=True):
    """Print the summary of a results folder (or Parquet file), write summary.md and figures."""
    camp_path = os.path.join(results, 'campaign.yaml')
    if os.path.isdir(results) and os.path.exists(camp_path) and not os.path.exists(
            os.path.join(results, 'results.parquet')):
        camp = load(camp_path)
        if 'laws' in camp:
            return report_laws(results, camp, figures)
    cols, camp, folder = _read(results)
    names = _varied(cols, camp)
    return _publish(os.path.join(folder, 'summary.md'), summary(cols, names),
                    (lambda: heatmaps(cols, names, folder)) if figures and len(names) >= 2
                    else None)


# -- command line -----------------------------------------------------------------------


def _parser():
    ap = argparse.ArgumentParser(prog='campaign', description='Robustness campaigns of the '
                                 "paper's arm: fj campaign run FILE, fj campaign report DIR")
    sub = ap.add_subparsers(dest='verb', required=True)
    p = sub.add_parser('run', help='run a campaign file (resumes what its folder holds)')
    p.add_argument('file')
    p.add_argument('--out', default=None, help='results folder (default bags/campaigns/NAME)')
    p.add_argument('--address', default=None,
                   help='Ray cluster address (HOST:PORT, auto; local: Ray in this process)')
    p.add_argument('--no-progress', action='store_true')
    p.add_argument('--check', action='store_true', help='only check the file and count runs')
    p.add_argument('--report', action='store_true', help='report when done')
    p = sub.add_parser('report', help='summary table and figures of a results folder')
    p.add_argument('results')
    p.add_argument('--no-figures', action='store_true')
    return ap


def main(argv=None):
    """Console entry ``campaign`` (``fj campaign``); exit 2 on a bad file."""
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        if args.verb == 'report':
            return report(args.results, figures=not args.no_figures)
        camp = load(args.file)
        n = len(design(camp)['run_index']) * len(camp.get('laws', ('robust',)))
        if args.check:
            print(f'campaign {camp["name"]}: {n} runs, axes {", ".join(camp["axes"])}')
            return 0
        out = args.out or os.path.join('bags', 'campaigns', camp['name'])
        t0 = time.monotonic()
        path = run(camp, out, address=args.address, progress=not args.no_progress)
        wall = time.monotonic() - t0
        print(f'campaign {camp["name"]}: {n} runs, {wall:.1f} s wall '
              f'({n / wall:.3g} runs/s incl. resumed), results {path}')
        if args.report and path:
            return report(out)
        return 0
    except CampaignError as exc:
        print(f'campaign: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
