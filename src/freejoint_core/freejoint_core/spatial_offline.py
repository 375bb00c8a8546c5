"""
Offline study of spatial arms with a free joint.

Run ``python -m freejoint_core.spatial_offline`` (``--help``).

One run (:func:`run_case`): the arm starts at rest in the rest posture of
:func:`freejoint_core.spatial_law.gravity_carrying_free_joint` near its planned posture
(:data:`CASES`; a free joint that must carry gravity is refused there), and its tip
follows a circle of radius 0.1 m in the vertical plane facing the robot (spanned by the
horizontal direction across the base-to-tip line and the vertical), starting and ending
at the start point: a quintic time law over ``t_move`` (5 s), then a hold of ``t_hold``
(10 s).  Task m = 3 (tip position).

Plant: :class:`freejoint_core.spatial_plant.SpatialPlant`, the URDF's Pinocchio model
(real masses), ABA integrated by RK4 at ``dt_sub`` (0.5 ms), torque and one disturbance
draw ``uniform(-0.5, 0.5)`` N m per joint (free joints included; seeded) held over the
control period ``dt`` (1 ms), as the simulator node integrates it.  Law:
:class:`freejoint_core.spatial_law.SpatialControlLaw` (the controller's law ``spatial``)
on the 70 % nominal model (masses, inertias and COM levers), weighted inverse,
dynamically consistent projector, null-space damping ``kd`` and posture stiffness ``kp``
towards the start posture (the redundant joints would drift otherwise: the Panda's joint
6 past its URDF limit in the hold), URDF effort limits; called
as the controller's loop calls it in lockstep (the measured state of tick k, the setpoint
of tick k, ``dt``).  With ``inverse='pseudo'`` or ``kf > 0`` the bare
:class:`freejoint_core.spatial_law.SpatialLaw` (the study's options).

:func:`run_twin` is the same run for any arm, law and start posture: the offline runner
of the lockstep graph (``make demo ARM=ur5``), whose trace it returns too.

Reported per run: rms and max tip error over the whole run [mm], the largest
``|tau_i| / effort_i`` and ``|qd_i| / velocity_i`` (URDF limits; the active joints and,
apart, the free joint), the max error over the
last second of the hold, and ``diverged``.
"""

import argparse
import json
import math
import sys
import time

from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import NullSpace
from freejoint_core.law_base import RunValues
from freejoint_core.laws import make_law
from freejoint_core.spatial_law import gravity_carrying_free_joint, SpatialGains
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_plant import SpatialPlant
import numpy as np

#: case -> (arm, free joint, planned start posture [rad])
CASES = {
    'ur5_wrist2': ('ur5', 'wrist_2_joint', (0.0, -1.2, 1.6, -1.97, -1.5708, 0.0)),
    'panda_j7': ('panda', 'panda_joint7', (0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.785)),
}
RADIUS = 0.1
T_MOVE = 5.0
T_HOLD = 10.0
DT = 1e-3
DT_SUB = 5e-4
NOMINAL = 0.7
DIST = 0.5
KD = 20.0
KP = 10.0
KF = 0.0


def quintic(tau):
    """``s = 10 tau^3 - 15 tau^4 + 6 tau^5`` and its first two derivatives in ``tau``."""
    return (tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau),
            30.0 * tau * tau * (1.0 - tau) ** 2,
            60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau))


def circle_axes(p0, normal=None):
    """
    Return the in-plane axes ``(e1, e2)`` of the circle from ``p0`` (each (3,), unit).

    The circle starts at ``p0`` (its centre is ``p0 - radius e1``) and first moves along
    ``e2``. Default (``normal`` None): the vertical plane facing
    the robot, ``e1`` the horizontal direction across the base-to-tip line (towards -x of
    it), ``e2 = z``. With ``normal`` (3,): the plane through ``p0`` normal to it, ``e1`` the
    default's ``e1`` projected onto it (``z``'s when that vanishes), ``e2 = n x e1``
    (counter-clockwise about ``n``); the default plane's own normal gives the default axes.

    Raises
    ------
    FreejointValueError
        ``normal`` not 3 finite numbers of non-zero length.

    """
    across = np.array([-p0[1], p0[0], 0.0])
    across = across / np.linalg.norm(across)
    if normal is None:
        return -across, np.array([0.0, 0.0, 1.0])
    n = np.asarray(normal, dtype=float)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
        raise FreejointValueError(f'normal: expected 3 finite numbers, not all 0, got '
                                  f'{normal!r}')
    n = n / np.linalg.norm(n)
    for guess in (-across, np.array([0.0, 0.0, 1.0])):
        e1 = guess - (guess @ n) * n
        if np.linalg.norm(e1) > 1e-6:
            break
    e1 = e1 / np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def circle(p0, radius, t, t_move, normal=None):
    """
    Setpoint of the circle at ``t`` (module notes).

    Parameters
    ----------
    p0 : numpy.ndarray, (3,)
        Start (and end) point [m].
    radius : float
        [m].
    t : float
        Time [s].
    t_move : float
        Duration of the circle [s].
    normal : array_like, (3,), optional
        Normal of the circle's plane (:func:`circle_axes`); default the vertical plane
        facing the robot.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray), each (3,)
        Position [m], velocity [m/s], acceleration [m/s^2].

    """
    e1, e2 = circle_axes(p0, normal)
    centre = p0 - radius * e1
    s, sd, sdd = quintic(t / t_move) if t < t_move else (1.0, 0.0, 0.0)
    sd, sdd = sd / t_move, sdd / t_move ** 2
    ang = 2.0 * math.pi * s
    c, si = math.cos(ang), math.sin(ang)
    w = 2.0 * math.pi
    pos = centre + radius * (c * e1 + si * e2)
    dpos = radius * w * (-si * e1 + c * e2)
    ddpos = radius * (-w * w * (c * e1 + si * e2))
    return pos, dpos * sd, ddpos * sd * sd + dpos * sdd


def run_case(case, seed, *, t_move=T_MOVE, t_hold=T_HOLD, dt=DT, nominal=NOMINAL,
             dist=DIST, kd=KD, kf=KF, inverse='weighted', t_stop=None, dt_sub=DT_SUB,
             kp=KP, passive_damping=0.0):
    """
    One closed-loop run (module notes).

    Parameters
    ----------
    case : str
        Key of :data:`CASES`.
    seed : int
        Disturbance seed.
    t_move, t_hold, dt : float
        Circle duration, hold duration, control period [s].
    nominal : float
        Nominal factor of the law's model.
    dist : float
        Disturbance bound [N m].
    kd : float
        Null-space damping [N m s/rad].
    kf : float
        Free-joint damping through the null space [1/s] (``SpatialLaw``).
    inverse : {'weighted', 'pseudo'}
        Right inverse (and projector) of the law.
    t_stop : float, optional
        End the run early at this time [s] (tests).
    dt_sub : float
        RK4 step of the plant [s]; ``dt`` an integer multiple of it.
    kp : float
        Null-space posture stiffness [N m/rad] towards the start posture (the controller's
        ``nullspace_kp``; the weighted law without ``kf`` only).
    passive_damping : float
        Viscous damping [N m s/rad] of the free joint's drivetrain in the plant
        (:func:`run_twin`).

    Returns
    -------
    dict
        Metrics (module notes) and ``tick_us``, the mean wall time of one control tick.

    Raises
    ------
    FreejointValueError
        Unknown case, or its free joint must carry gravity (the one-line reason).

    """
    if case not in CASES:
        raise FreejointValueError(f'case: expected one of {sorted(CASES)}, got {case!r}')
    name, free, q_plan = CASES[case]
    real = known_arm(name, [free])
    q0, why = start_posture(real.nominal(nominal), q_plan)
    if q0 is None:
        raise FreejointValueError(why)
    if inverse == 'weighted' and kf == 0.0:
        law = make_law('spatial', real.nominal(nominal), SpatialGains(task_dim=3))
        law.set_nullspace_gains(kd, kp)
    else:
        proj = 'dynamic' if inverse == 'weighted' else 'kinematic'
        law = make_law('spatial', real.nominal(nominal), SpatialGains(task_dim=3),
                       nullspace=NullSpace(kd=kd, inverse=inverse, projector=proj),
                       free_damping=kf)
    out = run_twin(real, q0, law, seed, t_move=t_move, t_hold=t_hold, dt=dt, dt_sub=dt_sub,
                   dist=dist, t_stop=t_stop, passive_damping=passive_damping)
    out.pop('trace')
    return dict({'case': case, 'seed': seed, 'inverse': inverse, 'kd': kd, 'kp': kp, 'kf': kf,
                 'passive_damping': passive_damping},
                **out)


def start_posture(nominal, q_plan):
    """
    Return the start posture near ``q_plan`` (``gravity_carrying_free_joint``) and why not.

    Parameters
    ----------
    nominal : SpatialArm
        The nominal model (the planner's).
    q_plan : sequence of float, (n,)
        Planned start posture [rad].

    Returns
    -------
    (numpy.ndarray (n,) or None, str)
        The rest posture (None: refused) and the one-line reason of a refusal.

    """
    return gravity_carrying_free_joint(nominal, np.array(q_plan, dtype=float))


def run_twin(real, q0, law, seed, *, t_move=T_MOVE, t_hold=T_HOLD, dt=DT, dt_sub=DT_SUB,
             dist=DIST, radius=RADIUS, t_stop=None, normal=None, passive_damping=0.0):
    """
    One run of the lockstep graph, offline: plant, setpoints and law as the nodes run them.

    Tick k: the state ``(q_k, qd_k)`` (lists, as the controller reads a JointState), the
    setpoint ``circle(p0, radius, k dt, t_move)`` (``p0`` the tip at ``q0``), ``law.step``
    with ``dt``, then the plant steps one period with the torque.

    Parameters
    ----------
    real : SpatialArm
        The real arm (the plant's).
    q0 : array_like, (n,)
        Start posture [rad], at rest.
    law : SpatialControlLaw or SpatialLaw
        The controller's law (its nominal model inside).
    seed : int
        Disturbance seed.
    t_move, t_hold, dt, dt_sub, dist, radius : float
        Circle and hold durations [s], control period and RK4 step [s], disturbance bound
        [N m], circle radius [m].
    t_stop : float, optional
        End the run early at this time [s].
    normal : array_like, (3,), optional
        Normal of the circle's plane (:func:`circle_axes`; the planner's
        ``plane_normal``); default the vertical plane facing the robot.
    passive_damping : float
        Viscous damping [N m s/rad] of the free joints' drivetrain in the plant (the
        simulator's ``passive_damping``; the law is not told).

    Returns
    -------
    dict
        ``rms_mm``, ``max_mm``, ``hold_last_s_max_mm``, ``tau_ratio``, ``vel_ratio``,
        ``vel_ratio_free``, ``diverged``, ``tick_us`` (module notes),
        ``active_outside_limits`` and ``free_outside_limits`` (the active, the free joints
        that left their URDF position limits, names), and ``trace``:
        ``{'p', 'p_d', 'q': (K, 3 / 3 / n) arrays, 'tau': (K, r), 'kappa': (K,),
        'theta': (K, k)}`` of ticks 0..K-1 (``kappa`` the law's conditioning, ``theta``
        its estimate ``theta_hat`` after the tick, k = 0 for a law without one).

    """
    reported = RunValues(law)
    plant = SpatialPlant(real, dt_sub, dist, seed, q0, passive_damping=passive_damping)
    p0 = real.fk(np.asarray(q0, dtype=float))
    steps = int(round(((t_move + t_hold) if t_stop is None else t_stop) / dt))
    last = int(round(1.0 / dt))
    act, free = list(real.active), list(real.passive)
    err = np.empty(steps)
    trace = {'p': np.empty((steps, 3)), 'p_d': np.empty((steps, 3)),
             'q': np.empty((steps, real.n)), 'tau': np.empty((steps, real.r)),
             'kappa': np.empty(steps), 'theta': np.empty((steps, reported.theta_size))}
    tau_ratio = vel_ratio = vel_free = 0.0
    diverged = False
    t_law = 0.0
    limit = real.effort[act]
    k = 0
    for k in range(steps):
        q, qd = plant.q, plant.qd
        p_d, v_d, a_d = circle(p0, radius, k * dt, t_move, normal)
        c0 = time.perf_counter()
        out = law.step(q.tolist(), qd.tolist(), p_d.tolist(), v_d.tolist(), a_d.tolist(), dt)
        t_law += time.perf_counter() - c0
        err[k] = np.linalg.norm(out.e)
        trace['p'][k], trace['p_d'][k], trace['q'][k], trace['tau'][k] = out.p, p_d, q, out.tau
        trace['kappa'][k] = reported.conditioning(out)
        trace['theta'][k] = reported.theta(out)
        tau_ratio = max(tau_ratio, float(np.max(np.abs(out.tau) / limit)))
        try:
            plant.step(out.tau, dt)
        except FreejointValueError:
            diverged = True
        q, qd = plant.q, plant.qd
        if diverged or err[k] > 1.0:
            diverged = True
            break
        vel = np.abs(qd) / real.velocity
        vel_ratio = max(vel_ratio, float(np.max(vel[act])))
        vel_free = max(vel_free, float(np.max(vel[free]))) if free else 0.0
    n = k + 1
    err = err[:n]
    q_run = trace['q'][:n]

    def outside(joints):
        """Names of ``joints`` that left their URDF position limits in the run."""
        return [real.joint_names[j] for j in joints
                if np.any(q_run[:, j] < real.lower[j]) or np.any(q_run[:, j] > real.upper[j])]
    return {
        'rms_mm': 1e3 * float(np.sqrt(np.mean(err ** 2))),
        'max_mm': 1e3 * float(np.max(err)),
        'hold_last_s_max_mm': 1e3 * float(np.max(err[-last:])),
        'tau_ratio': tau_ratio, 'vel_ratio': vel_ratio, 'vel_ratio_free': vel_free,
        'active_outside_limits': outside(act), 'free_outside_limits': outside(free),
        'diverged': diverged,
        'tick_us': 1e6 * t_law / n,
        'trace': {key: val[:n] for key, val in trace.items()},
    }


def main(argv=None):
    """Command line: run cases over seeds, print one JSON line per run."""
    ap = argparse.ArgumentParser(prog='python -m freejoint_core.spatial_offline',
                                 description=__doc__.split('\n')[1])
    ap.add_argument('--case', action='append', choices=sorted(CASES))
    ap.add_argument('--seeds', type=int, default=10, help='seeds 0..N-1')
    ap.add_argument('--t-move', type=float, default=T_MOVE)
    ap.add_argument('--t-hold', type=float, default=T_HOLD)
    ap.add_argument('--kd', type=float, default=KD)
    ap.add_argument('--kp', type=float, default=KP)
    ap.add_argument('--kf', type=float, default=KF)
    ap.add_argument('--inverse', choices=('weighted', 'pseudo'), default='weighted')
    ap.add_argument('--passive-damping', type=float, default=0.0, metavar='B',
                    help="viscous damping [N m s/rad] of the free joint's drivetrain in the "
                         "plant (the simulator's passive_damping; default 0: frictionless)")
    args = ap.parse_args(argv)
    for case in args.case or sorted(CASES):
        for seed in range(args.seeds):
            rec = run_case(case, seed, t_move=args.t_move, t_hold=args.t_hold, kd=args.kd,
                           kp=args.kp, kf=args.kf, inverse=args.inverse,
                           passive_damping=args.passive_damping)
            print(json.dumps({k: round(v, 4) if isinstance(v, float) else v
                              for k, v in rec.items()}), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
