"""
The offline twin of a spatial arm's graph, from its parameter files: the one path of every runner.

A spatial arm is a directory of node parameter files on top of ``config/<node>.yaml``:
``config/ur5/``, ``config/panda/`` (shipped) or one that ``fj arm init`` wrote (with its
``arm.yaml``: the run's name, the free joint, the hold, the bound).  :func:`twin` runs it
as the lockstep graph runs it (``freejoint_core.spatial_offline.run_twin``: the simulator's
arm, start posture, RK4 step, disturbance and free-joint damping, the law the controller
builds from its file, the planner's circle, then the hold).  ``make demo ARM=...``,
``make offline ARM=...`` (``tools/arm_offline.py``), ``make soak SOAK_ARGS='--arm ...'``
and a campaign whose ``arm`` is such a directory (``freejoint_tools.campaign``) all call it.
"""

import math
import os

SPATIAL_ARMS = {
    'ur5': {'passive_joint': 'wrist_2_joint', 'bound_mm': 3.0, 'spatial': 'ur5_wrist2',
            'hold_s': 10.0},
    'panda': {'passive_joint': 'panda_joint7', 'bound_mm': 3.0, 'spatial': 'panda_j7',
              'hold_s': 10.0}}
"""The shipped spatial arms (``config/<name>/``): the free joint recorded, the stated
tracking bound [mm], the run's case label (``freejoint_core.spatial_offline.CASES``) and
the hold after the circle [s]."""
NODES = ('sim', 'controller', 'planner')


def arm_info(arm):
    """
    Return what a spatial arm's runs read besides the nodes' files (:data:`SPATIAL_ARMS`).

    ``arm``: a directory with ``arm.yaml`` (``name``, ``passive_joint``, ``hold_s``,
    ``bound_mm``; ``spatial`` is its ``name``), or a shipped arm's directory or name.

    Raises
    ------
    FileNotFoundError
        Neither a shipped arm nor a directory with ``arm.yaml`` (named).

    """
    meta = os.path.join(arm, 'arm.yaml')
    if os.path.isfile(meta):
        import yaml
        with open(meta, encoding='utf-8') as fh:
            info = yaml.safe_load(fh)
        return {'passive_joint': str(info['passive_joint']),
                'bound_mm': float(info['bound_mm']), 'spatial': str(info['name']),
                'hold_s': float(info['hold_s'])}
    name = os.path.basename(os.path.normpath(arm))
    if name in SPATIAL_ARMS:
        return dict(SPATIAL_ARMS[name])
    raise FileNotFoundError(f'{arm}: neither a shipped spatial arm ({", ".join(SPATIAL_ARMS)}) '
                            f'nor a directory of fj arm init (no {meta})')


def from_urdf(urdf, passive, out_root, tip=None, base=None, log=None):
    """
    Return the directory ``fj arm init`` writes a URDF's arm into: ``out_root/<name>``.

    ``<name>`` is the URDF's file name without ``.urdf``; ``passive``, ``tip``, ``base`` and
    ``log`` as ``freejoint_tools.arm_init.init_arm`` takes them (which raises its refusal).
    """
    from freejoint_tools.arm_init import init_arm
    name = os.path.splitext(os.path.basename(urdf))[0]
    arm_dir = os.path.abspath(os.path.join(out_root, name))
    init_arm(urdf, passive, arm_dir, tip, base, log=log)
    return arm_dir


def arm_files(arm, node, config_dir=None):
    """Return the parameter files of ``node`` ('sim', ...): config's, then the arm's."""
    paths = [os.path.join(config_dir, node + '.yaml')] if config_dir else []
    own = os.path.join(arm, node + '.yaml')
    return paths + ([own] if os.path.exists(own) else [])


def arm_configs(arm, config_dir=None, sim=None, controller=None):
    """
    Return the simulator's and the controller's configs and the planner's values of ``arm``.

    Parameters
    ----------
    arm : str
        The arm's directory (its ``<node>.yaml`` files).
    config_dir : str, optional
        The directory of the shipped ``<node>.yaml`` the arm's files go on top of (as the
        graph's nodes read them); None: the nodes' schema defaults.
    sim, controller : dict, optional
        Values set over the files (a campaign's axes: ``dist_bound``, ``nominal_scale``).

    """
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    out = []
    for schema, node, given in ((SIM, 'sim', sim), (CONTROLLER, 'controller', controller)):
        values = schema.yaml_values(*arm_files(arm, node, config_dir))
        values.update(given or {})
        out.append(schema.config(values))
    out.append(PLANNER.yaml_values(*arm_files(arm, 'planner', config_dir)))
    return tuple(out)


def run_ticks(arm, config_dir=None):
    """Return the ticks of a run of ``arm``: the planner's circle, then the arm's hold."""
    sim, _, plan = arm_configs(arm, config_dir)
    return int(round((float(plan['duration']) + arm_info(arm)['hold_s']) / sim.dt))


def twin(arm, seed, n_ticks, config_dir=None, normal=None, sim=None, controller=None):
    """
    Return the offline twin's record and trace of a spatial arm (module notes).

    Parameters
    ----------
    arm : str
        The arm's directory.
    seed : int
        The disturbance seed.
    n_ticks : int
        Ticks to run (:func:`run_ticks` for the circle and the hold).
    config_dir : str, optional
        As :func:`arm_configs`.
    normal : array_like, (3,), optional
        The circle plane's normal (the planner's ``plane_normal`` given on the command
        line); default the planner file's.
    sim, controller : dict, optional
        As :func:`arm_configs`.

    Returns
    -------
    (dict, dict)
        ``freejoint_core.metrics.compute_record``'s record (case: the arm's ``spatial``
        label) with ``tau_ratio``, ``vel_ratio``, ``vel_ratio_free``,
        ``hold_last_s_max_mm``, ``active_outside_limits``, ``free_outside_limits``; the trace
        of ``run_twin`` (``trace['q']`` for :func:`limit_margin`).

    """
    from freejoint_control.loop import config_law
    from freejoint_core.metrics import compute_record
    from freejoint_core.spatial_offline import run_twin
    from freejoint_planner.spatial_planning import plane_normal
    import numpy as np
    sim, ctl, plan = arm_configs(arm, config_dir, sim, controller)
    law = config_law(ctl)
    dt = sim.dt
    duration = float(plan['duration'])
    out = run_twin(sim.arm.spatial, sim.q0, law, seed, t_move=duration,
                   t_hold=n_ticks * dt - duration, dt=dt, dt_sub=sim.dt_sub,
                   dist=sim.dist_bound, radius=float(plan['radius']),
                   passive_damping=sim.passive_damping,
                   normal=plane_normal(plan['plane_normal'] if normal is None else normal))
    trace = out['trace']
    n = len(trace['p'])
    passive = sim.arm.spatial.passive[0]
    record = compute_record(arm_info(arm)['spatial'], 'spatial', seed,
                            np.arange(n) * dt, trace['p'], trace['p_d'], trace['tau'],
                            trace['theta'], trace['q'][:, passive], trace['kappa'],
                            diverged_at_s=n * dt if out['diverged'] else None)
    record.update({key: out[key] for key in ('tau_ratio', 'vel_ratio', 'vel_ratio_free',
                                             'hold_last_s_max_mm', 'active_outside_limits',
                                             'free_outside_limits')})
    return record, trace


def limit_margin(real, q):
    """
    Return the smallest distance [rad] of the postures ``q`` (K, n) from the URDF limits.

    Over every tick and every joint with position limits (free ones included; negative:
    outside), and the joint it belongs to (inf and '' when no joint has limits).
    """
    import numpy as np
    gaps = np.minimum(q - real.lower, real.upper - q).min(axis=0)
    gaps = np.where(np.isfinite(gaps), gaps, np.inf)
    j = int(np.argmin(gaps))
    return (float(gaps[j]), real.joint_names[j]) if np.isfinite(gaps[j]) else (math.inf, '')
