"""
``fj arm init``: the three nodes' parameter files of a spatial arm from its URDF alone.

``fj arm init URDF --passive J [--tip T] [--base B] --out DIR [--radius R]`` writes
``DIR/sim.yaml``, ``DIR/controller.yaml``, ``DIR/planner.yaml`` (each on top of the
shipped ``config/<node>.yaml``, as ``config/ur5/``) and ``DIR/arm.yaml`` (what ``make demo
ARM=DIR`` and ``tools/arm_offline.py DIR`` read besides: the free joint, the hold, the
bound).  Everything comes from the URDF and one documented rule each:

* the chain ``base -> tip`` (default base: the URDF's root; tip: the one leaf link at the
  end of the longest chain of moving joints); its limits are not written: the controller
  takes a spatial arm's URDF limits where they are not given
  (``freejoint_control.params.arm_limits``: a free joint's bounds and a continuous
  joint's position bounds wide, as the shipped arms');
* the start posture: inverse kinematics of the tip to the first of :data:`TARGETS` (a
  point ahead of the base at a share of the reach ``L``) from deterministic seeds, the
  solution of largest ``kappa`` within the limits (margin :data:`LIMIT_MARGIN`; scaled
  down within :data:`PREFERRED_MARGIN` of a limit), then the
  free joints' rest posture (``gravity_carrying_free_joint``) - accepted when the
  planner's nominal loop stays :data:`LOOP_MARGIN` inside the active joints' limits and its
  own check (:func:`freejoint_planner.spatial_planning.check_spatial_plan`,
  with these gains) accepts the circle from it;
* the null-space gains: :func:`freejoint_core.arm_gains.nullspace_gains` (its docstring
  derives the rule); task gains ``K``, ``Lambda``, ``R``: the shipped per-row values
  (accelerations after the nominal inertia is inverted: arm-independent);
* the free joints' viscous damping in the simulator (``passive_damping``, a failed
  joint keeps its drivetrain): the floor that keeps them within their rated speed and
  position limits under the simulator's disturbance
  (:func:`freejoint_core.arm_gains.drivetrain_damping`, derived there) or their URDF
  ``<dynamics damping>`` where larger, capped at what the simulator's RK4 integrates
  stably; a floor above that cap is refused (:func:`free_damping`);
* the circle: radius ``min(0.1 m, L / 10)``, the planner's 5-s duration and facing plane.

A refusal is one line naming the cause and the numbers (:class:`ArmInitError`).
"""

import math
import os

from freejoint_core.arm_gains import nullspace_gains
from freejoint_core.errors import FreejointValueError
from freejoint_core.spatial_law import arm_reach, gravity_carrying_free_joint
from freejoint_core.spatial_law import task_conditioning
from freejoint_core.spatial_model import root_link, SpatialArm
import numpy as np

NOMINAL = 0.7
"""The controller's nominal_scale (config/controller.yaml)."""
TARGETS = ((0.5, 0.15), (0.45, 0.3), (0.55, 0.0), (0.4, 0.45), (0.6, 0.25), (0.35, 0.1))
"""Start tips tried, in order: (horizontal distance, height) from the first joint's
origin as shares of the reach ``L``, ahead of the base (+x of its frame)."""
SEEDS = 24
"""IK start postures per target: the middle of the limits, then uniform draws (seed 0)."""
LIMIT_MARGIN = 0.15
"""[rad] Distance a start posture keeps from every bounded joint's position limits."""
LOOP_MARGIN = 0.2
"""[rad] Distance the planner's nominal closed loop must keep from every bounded active
joint's limits (the real arm, the 70 % model and the disturbance depart from it)."""
PREFERRED_MARGIN = 0.5
"""[rad] Below this distance from a limit a solution's kappa counts in proportion."""
RADIUS = 0.1
"""[m] The circle's radius (at most a tenth of the reach)."""
HOLD_S = 10.0
"""[s] The hold after the circle in ``make demo ARM=DIR``."""
BOUND_MM = 3.0
"""[mm] The tracking bound ``make demo ARM=DIR`` checks."""


class ArmInitError(FreejointValueError):
    """Why an arm cannot be initialised (one line, with the numbers)."""


def tip_leaf(text, base):
    """Return the link at the end of the longest chain of moving joints from ``base``."""
    import xml.etree.ElementTree as ET
    robot = ET.fromstring(text)
    children = {}
    for joint in robot.findall('joint'):
        parent, child = joint.find('parent'), joint.find('child')
        if parent is None or child is None:
            continue
        moving = joint.get('type') != 'fixed'
        children.setdefault(parent.get('link'), []).append((child.get('link'), moving))

    def best(link):
        """Return (moving joints, depth, link) of the deepest leaf below ``link``."""
        out = (0, 0, link)
        for child, moving in children.get(link, ()):
            n, depth, leaf = best(child)
            out = max(out, (n + moving, depth + 1, leaf))
        return out
    return best(base)[2]


def joint_damping(text, names):
    """
    Return the smallest ``<dynamics damping>`` [N m s/rad] of the joints ``names`` (0: none).

    A failed joint keeps its drivetrain (docs/spatial.md): the simulator's
    ``passive_damping`` of the free joints is what their URDF says.
    """
    import xml.etree.ElementTree as ET
    robot = ET.fromstring(text)
    values = []
    for joint in robot.findall('joint'):
        if joint.get('name') in names:
            dyn = joint.find('dynamics')
            values.append(float(dyn.get('damping', 0.0)) if dyn is not None else 0.0)
    return min(values) if values else 0.0


def free_damping(real, q0, urdf_damping, given=None, run_s=None, log=None):
    """
    Return the simulator's ``passive_damping`` [N m s/rad] of the free joints (module notes).

    The floor of :func:`freejoint_core.arm_gains.drivetrain_damping` at the simulator's
    disturbance bound, control period and RK4 step (the simulator's defaults) over ``run_s``
    (default the planner's duration and :data:`HOLD_S`), or the URDF's ``urdf_damping``
    where larger, capped at what the RK4 integrates stably; ``given`` (``--passive-damping``,
    a lab's identified value) is taken as it is (capped), a warning logged when below the
    floor.

    Raises
    ------
    ArmInitError
        No damping within the cap meets the floor (the joint, the limit, the numbers).

    """
    from freejoint_core.arm_gains import drivetrain_damping
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    sim = SIM.defaults()
    if run_s is None:
        run_s = float(PLANNER.defaults()['duration']) + HOLD_S
    dist = float(sim['dist_bound'])
    rule = drivetrain_damping(real, q0, dist, float(sim['control_period']),
                              float(sim['dt_sub']), run_s)
    if given is None and rule.reason:
        raise ArmInitError(rule.reason)
    damping = max(urdf_damping, rule.floor) if given is None else float(given)
    if log is not None:
        log(f'passive_damping: floor {rule.floor:.4g} N m s/rad ({rule.joint}, its '
            f'{rule.cause} limit under the +-{dist:g} N m disturbance), URDF '
            f'{urdf_damping:g}, cap {rule.cap:.4g}'
            + ('' if given is None else f', given {damping:g}'))
        if damping > rule.cap:
            log(f'passive_damping: {damping:g} N m s/rad capped at {rule.cap:.4g}, what the '
                "simulator's RK4 integrates stably on the free joints' inertia")
        if given is not None and damping < rule.floor:
            log(f'passive_damping: the given {damping:g} N m s/rad is below the floor '
                f'{rule.floor:.4g}: {rule.joint} may pass its {rule.cause} limit')
    return min(damping, rule.cap)


def solve_ik(arm, target, q_init, iters=300, tol=1e-6):
    """
    Damped least-squares IK of the tip position, pulled to mid-range in the null space.

    Parameters
    ----------
    arm : SpatialArm
        The arm (its limits bound the search).
    target : numpy.ndarray, (3,)
        Tip position [m].
    q_init : numpy.ndarray, (n,)
        Start [rad].
    iters : int
        Iteration bound.
    tol : float
        Tip error accepted [m].

    Returns
    -------
    numpy.ndarray (n,) or None
        The posture (within the limits) or None (not converged).

    """
    lo, hi = arm.lower, arm.upper
    bounded = np.isfinite(lo) & np.isfinite(hi)
    mid = np.where(bounded, 0.5 * (np.where(bounded, lo, 0.0) + np.where(bounded, hi, 0.0)),
                   0.0)
    span = np.where(bounded, np.where(bounded, hi - lo, 1.0), 2.0 * math.pi)
    q = np.clip(np.array(q_init, dtype=float), lo, hi)
    for _ in range(iters):
        err = target - arm.fk(q)
        if np.linalg.norm(err) < tol:
            return q
        jac = arm.jacobian(q)[:3]
        jjt = jac @ jac.T + 2.5e-3 * np.eye(3)
        step = jac.T @ np.linalg.solve(jjt, err)
        proj = np.eye(arm.n) - np.linalg.pinv(jac, rcond=1e-6) @ jac
        step += proj @ (0.1 * (mid - q) / span ** 2)
        size = float(np.max(np.abs(step)))
        q = np.clip(q + step * min(1.0, 0.2 / size) if size > 0.0 else q, lo, hi)
    return None


def _kappa(arm, q, reach):
    terms = arm.terms(q, np.zeros(arm.n))
    da, _, maa = arm.decoupling(terms)
    return task_conditioning(da, maa, reach)[0]


def limit_margin(arm, q):
    """Return the smallest distance [rad] of ``q`` from a bounded joint's limits (inf: none)."""
    lo, hi = arm.lower, arm.upper
    gaps = np.concatenate([q - lo, hi - q])
    gaps = gaps[np.isfinite(gaps)]
    return float(np.min(gaps)) if gaps.size else math.inf


def loop_margin_refusal(nominal, loop):
    """Return why the nominal loop passes within ``LOOP_MARGIN`` of an active joint's limit."""
    for j in nominal.active:
        low = loop.q_min[j] - nominal.lower[j]
        high = nominal.upper[j] - loop.q_max[j]
        if min(low, high) < LOOP_MARGIN:
            end, bound = (loop.q_min[j], nominal.lower[j]) if low < high else \
                (loop.q_max[j], nominal.upper[j])
            return (f'the nominal closed loop takes {nominal.joint_names[j]} to {end:.4f} rad, '
                    f'within {LOOP_MARGIN} rad of its URDF limit {bound:.4f} rad')
    return ''


def start_posture(nominal, radius, duration, max_speed, max_acceleration, log=None):
    """
    Return the start posture, the plan check's verdict and the gains (module notes).

    Returns
    -------
    dict
        ``q0`` (n,), ``kd`` (r,), ``kp``, ``inertia`` (r,), ``kappa``, ``target``,
        ``verdict``.

    Raises
    ------
    ArmInitError
        No target gave a posture the planner's check accepts (the last reason).

    """
    from freejoint_planner.spatial_planning import check_spatial_plan, first_joint_origin
    from freejoint_planner.spatial_planning import reach_refusal, spatial_bounds
    from freejoint_planner.spatial_planning import SpatialCircle
    why = spatial_bounds(radius, duration, max_speed, max_acceleration)
    if why:
        raise ArmInitError(why)
    reach = arm_reach(nominal)
    origin = first_joint_origin(nominal)
    rng = np.random.default_rng(0)
    lo, hi = nominal.lower, nominal.upper
    draw_lo = np.where(np.isfinite(lo), lo, -math.pi)
    draw_hi = np.where(np.isfinite(hi), hi, math.pi)
    seeds = [np.clip(np.zeros(nominal.n), lo, hi)]
    seeds += [draw_lo + (draw_hi - draw_lo) * rng.random(nominal.n) for _ in range(SEEDS)]
    reasons = []
    for share, height in TARGETS:
        target = origin + reach * np.array([share, 0.0, height])
        why = reach_refusal(nominal, SpatialCircle(target, radius, duration), reach)[0]
        if why:     # before the IK: this start point's circle cannot be reached
            if log is not None:
                log(f'tip {np.round(target, 3).tolist()} m: {why}')
            reasons.append(why)
            continue
        found = []
        for seed in seeds:
            q = solve_ik(nominal, target, seed)
            if q is None or limit_margin(nominal, q) < LIMIT_MARGIN:
                continue
            found.append((_kappa(nominal, q, reach)
                          * min(1.0, limit_margin(nominal, q) / PREFERRED_MARGIN), q))
        if not found:
            if log is not None:
                log(f'tip {np.round(target, 3).tolist()} m: no IK solution')
            reasons.append(f'tip {np.round(target, 3).tolist()} m: no IK solution '
                           f'{LIMIT_MARGIN} rad inside the limits')
            continue
        kappa, q = max(found, key=lambda item: item[0])
        rest, why = gravity_carrying_free_joint(nominal, q)
        if rest is None:
            reasons.append(why)
            continue
        kd, kp, inertia = nullspace_gains(nominal, rest)
        verdict = check_spatial_plan(nominal, rest, np.zeros(nominal.n), radius, duration,
                                     max_speed, max_acceleration, kd=kd, kp=kp)
        if log is not None:
            log(f'tip {np.round(target, 3).tolist()} m: kappa {kappa:.3g}, joint inertias '
                f'{np.round(inertia, 4).tolist()} kg m^2 -> kd {np.round(kd, 4).tolist()}, kp '
                f"{kp:.4g}: {verdict.reason or 'accepted'}")
        reason = verdict.reason or loop_margin_refusal(nominal, verdict.loop)
        if verdict.reason == '' and reason and log is not None:
            log(reason)
        if reason:
            reasons.append(reason)
            continue
        return {'q0': rest, 'kd': kd, 'kp': kp, 'inertia': inertia, 'kappa': kappa,
                'target': target, 'verdict': verdict}
    raise ArmInitError('no start posture found: ' + '; '.join(reasons[-2:]))


def _floats(values):
    return '[' + ', '.join(repr(float(v)) for v in values) + ']'


def arm_files(urdf, passive, tip=None, base=None, radius=None, log=None,
              passive_damping=None, hold_s=HOLD_S):
    """
    Return ``{file name: YAML text}`` of an arm (module notes).

    Parameters
    ----------
    urdf : str
        Path of the URDF (kept as given, absolute).
    passive : sequence of str
        The free joints.
    tip, base : str, optional
        The chain's links (default: the URDF's root and the deepest moving leaf).
    radius : float, optional
        The circle's radius [m] (default ``min(RADIUS, L / 10)``).
    passive_damping : float, optional
        The free joints' viscous damping in the simulator [N m s/rad] (default:
        :func:`free_damping`'s rule).
    hold_s : float
        The hold after the circle [s] (``arm.yaml``; the run the damping rule covers), > 0.
    log : callable, optional
        Called with a line per start point tried.

    Raises
    ------
    ArmInitError, FreejointValueError
        One line naming the cause.

    """
    from freejoint_planner.params import SCHEMA as PLANNER
    path = os.path.abspath(urdf)
    try:
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
    except OSError as exc:
        raise ArmInitError(f'urdf: cannot read {urdf!r} ({exc})') from None
    base = base or root_link(text)
    tip = tip or tip_leaf(text, base)
    real = SpatialArm(text, base, tip, passive)
    nominal = real.nominal(NOMINAL)
    if not passive:
        raise ArmInitError('passive: name at least one free joint of the chain '
                           f'{real.joint_names}')
    if not (isinstance(hold_s, (int, float)) and math.isfinite(hold_s) and hold_s > 0.0):
        raise ArmInitError(f'hold: expected a finite number of seconds > 0, got {hold_s!r}')
    plan = PLANNER.defaults()
    reach = arm_reach(nominal)
    radius = float(radius) if radius is not None else min(RADIUS, reach / 10.0)
    found = start_posture(nominal, radius, float(plan['duration']), float(plan['max_speed']),
                          float(plan['max_acceleration']), log)
    arm = ('    task_dim: 3\n'
           f'    description_file: {path}\n'
           f'    base_link: {base}\n'
           f'    tip_link: {tip}\n'
           f"    passive_joints: [{', '.join(passive)}]\n")
    head = (f'# {os.path.basename(path)}, {base} -> {tip}, free: {", ".join(passive)}; written '
            'by fj arm init (freejoint_tools.arm_init).\n'
            '# On top of config/{node}.yaml: --params-file config/{node}.yaml '
            '--params-file <this file>.\n')
    loop = found['verdict'].loop
    damping = free_damping(real, found['q0'], joint_damping(text, set(passive)),
                           passive_damping, float(plan['duration']) + hold_s, log=log)
    sim = (head.format(node='sim')
           + f'# Start posture: IK of the tip to {np.round(found["target"], 4).tolist()} m '
           f'(kappa {found["kappa"]:.3g}), the free joints at rest.\n'
           '/**:\n  ros__parameters:\n' + arm
           + "    initial_joint_positions: '%s'\n" % ' '.join(
               repr(float(v)) for v in found['q0'])
           + ('' if damping <= 0.0 else
              "    # the free joints' drivetrain: the URDF's <dynamics damping> or the floor\n"
              '    # that keeps them within their limits under the disturbance, whichever is\n'
              '    # larger (freejoint_core.arm_gains.drivetrain_damping), unless given\n'
              f'    passive_damping: {damping!r}\n'))
    ctl = (head.format(node='controller')
           + "# nullspace_kd_joints: min(20, I_i / 2 ms) of the joints' effective "
           f'inertias I_i {np.round(found["inertia"], 5).tolist()} kg m^2,\n# nullspace_kp '
           '10 (freejoint_core.arm_gains);\n'
           '# effort_limits, joint_position_lower/upper, joint_velocity_limit: not given, the '
           "URDF's\n# (freejoint_control.params.arm_limits; free and continuous joints wide).\n"
           '/**:\n  ros__parameters:\n' + arm
           + '    law: spatial\n'
           '    K: [100.0, 100.0, 100.0]\n    Lambda: [50.0, 50.0, 50.0]\n'
           '    R: [2.0, 2.0, 2.0]\n'
           f'    nullspace_kd_joints: {_floats(found["kd"])}\n'
           f'    nullspace_kp: {found["kp"]!r}\n')
    planner = (head.format(node='planner')
               + f'# The check at init: {loop.describe()}.\n'
               '/**:\n  ros__parameters:\n' + arm
               + f'    radius: {radius!r}\n'
               f'    nullspace_kd_joints: {_floats(found["kd"])}\n'
               f'    nullspace_kp: {found["kp"]!r}\n')
    meta = ("# What make demo ARM=DIR and tools/arm_offline.py DIR read besides the nodes' "
            'files.\n'
            f'name: {os.path.splitext(os.path.basename(path))[0]}_'
            f'{"_".join(passive)}\n'
            f'passive_joint: {passive[0]}\n'
            f'hold_s: {float(hold_s)!r}\n'
            f'bound_mm: {BOUND_MM!r}\n')
    return {'sim.yaml': sim, 'controller.yaml': ctl, 'planner.yaml': planner,
            'arm.yaml': meta}


def init_arm(urdf, passive, out, tip=None, base=None, radius=None, log=None,
             passive_damping=None, hold_s=HOLD_S):
    """Write :func:`arm_files` into ``out`` (created); return the paths written."""
    files = arm_files(urdf, passive, tip, base, radius, log, passive_damping, hold_s)
    os.makedirs(out, exist_ok=True)
    paths = []
    for name, text in files.items():
        paths.append(os.path.join(out, name))
        with open(paths[-1], 'w', encoding='utf-8') as fh:
            fh.write(text)
    return paths
