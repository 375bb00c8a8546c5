"""
Offline closed-loop runner for an arm read from URDF (the node graph's loop, no ROS).

The loop of ``freejoint_core.offline`` for any arm ``freejoint_core.urdf`` accepts, tick
``k = 0 .. N-1`` at ``t_k = k dt``::

    (q, qd) = plant state at t_k
    out = make_law(law, arm.nominal(nominal_scale), gains).step(q, qd, p_d(t_k), ..., dt)
    plant.step(out.tau, dt)

with the nominal model from Pinocchio for n != 3 (:func:`nominal_model`, as the
controller node's) and the plant of :func:`make_plant` (the simulator node's
``engine``): ``rk4`` is
``freejoint_core.plant.Plant`` (closed-form kernel) for 3-link arms and
``freejoint_core.pin_plant.PinPlant`` (Pinocchio's ABA) otherwise, ``mujoco``
``freejoint_core.mujoco_plant.MujocoPlant``.  The simulator, controller and planner
nodes run the same loop on a URDF arm, so in lockstep the graph's records equal these
(``test/graph/test_arm_graph.py``).  The run stops (without raising) at the first
tick whose output is not finite or whose tracking error exceeds ``diverge_m``.
"""

import math

from freejoint_core.arm import NOMINAL_SCALE
from freejoint_core.control import Gains
from freejoint_core.errors import FreejointValueError, PlantDivergedError
from freejoint_core.law_base import RunValues
from freejoint_core.laws import make_law
from freejoint_core.metrics import compute_record
from freejoint_core.plant import DEFAULT_DT_SUB, Plant
from freejoint_core.urdf import UrdfArm
import numpy as np

ENGINES = ('rk4', 'mujoco')
"""Plant engines: classic RK4 on the core's or Pinocchio's dynamics, or MuJoCo."""


def make_plant(arm, engine='rk4', dt_sub=DEFAULT_DT_SUB, dist_bound=0.5, seed=0, q0=None):
    """
    Return the plant of a URDF arm for an engine.

    Parameters
    ----------
    arm : UrdfArm
        The real arm.
    engine : {'rk4', 'mujoco'}
        ``rk4``: ``Plant`` (closed-form kernel) for n = 3, ``PinPlant`` otherwise;
        ``mujoco``: ``MujocoPlant``.
    dt_sub, dist_bound, seed, q0
        As :class:`freejoint_core.plant.Plant`.

    Returns
    -------
    freejoint_core.plant.PeriodPlant

    """
    if not isinstance(arm, UrdfArm):
        raise FreejointValueError(f'arm: expected UrdfArm, got {type(arm).__name__}')
    kwargs = {'dist_bound': dist_bound, 'seed': seed, 'q0': q0}
    if engine == 'mujoco':
        from freejoint_core.mujoco_plant import MujocoPlant
        return MujocoPlant(arm, dt_sub, **kwargs)
    if engine != 'rk4':
        raise FreejointValueError(f'engine: expected one of {ENGINES}, got {engine!r}')
    if arm.params.n == 3:
        return Plant(arm.params, dt_sub, **kwargs)
    from freejoint_core.pin_plant import PinPlant
    return PinPlant(arm, dt_sub, **kwargs)


def nominal_model(arm, scale):
    """
    Return the implementation of a URDF arm's nominal model for the controller.

    Parameters
    ----------
    arm : UrdfArm
        The real arm.
    scale : float
        ``nominal_scale``.

    Returns
    -------
    PinArmModel or None
        Pinocchio's model of ``arm.nominal(scale)`` for n != 3 (several times faster
        than the general numpy path, ``bench/core_urdf.py``); None for 3 links (the
        controller's closed-form kernel).

    """
    if arm.params.n == 3:
        return None
    from freejoint_core.pin_model import PinArmModel
    return PinArmModel(arm, scale)


def run_arm(arm, trajectory, q0, *, label='urdf', seed=0, nominal_scale=NOMINAL_SCALE,
            dist_bound=0.5, dt=1e-3, dt_sub=DEFAULT_DT_SUB, n_ticks=None, engine='rk4',
            gains=None, diverge_m=0.5, law='robust', law_params=None):
    """
    Run the closed loop of a URDF arm; return its metrics record and per-tick trace.

    Parameters
    ----------
    arm : UrdfArm
        The real arm (passive joints, gravity).
    trajectory : freejoint_core.trajectory.CircleQuintic
        Desired end-effector path (``sample_tuple``, ``duration``).
    q0 : array_like, (n,)
        Initial joint angles [rad], at rest.
    label : str
        The record's ``case`` label.
    seed : int
        Disturbance seed.
    nominal_scale : float
        Nominal model = ``arm.nominal(nominal_scale)``.
    dist_bound : float
        Disturbance bound [N m].
    dt, dt_sub : float
        Control period and plant step [s].
    n_ticks : int, optional
        Ticks to run; default ``trajectory.duration / dt``.
    engine : {'rk4', 'mujoco'}
        The plant, :func:`make_plant`.
    gains : Gains, optional
        The paper's by default.
    diverge_m : float
        Tracking error [m] beyond which the run stops.
    law, law_params
        The registered control law and the laws' own gains (``offline.run_case``).

    Returns
    -------
    record : dict
        :func:`freejoint_core.metrics.compute_record` (``variant='robust'``).
    trace : dict
        ``t`` (N,), ``q``, ``qd`` (N, n), ``p``, ``p_d`` (N, 2), ``tau`` (N, r),
        ``theta`` (N, k) (the law's ``theta_hat``, k = 0 for a law without one), ``det``
        (N,) (its conditioning, 0 for a law without one).

    """
    if not isinstance(arm, UrdfArm):
        raise FreejointValueError(f'arm: expected UrdfArm, got {type(arm).__name__}')
    if n_ticks is None:
        n_ticks = int(round(trajectory.duration / dt))
    plant = make_plant(arm, engine, dt_sub, dist_bound, seed, q0)
    ctrl = make_law(law, arm.nominal(nominal_scale), Gains() if gains is None else gains,
                    model=nominal_model(arm, nominal_scale), params=law_params)
    n, r = arm.params.n, arm.params.r
    passive = arm.params.passive[0] if arm.params.passive else 0
    t = np.arange(n_ticks) * dt
    q_buf, qd_buf = np.empty((n_ticks, n)), np.empty((n_ticks, n))
    p_buf, pd_buf = np.empty((n_ticks, 2)), np.empty((n_ticks, 2))
    reported = RunValues(ctrl)
    tau_buf, th_buf = np.empty((n_ticks, r)), np.empty((n_ticks, reported.theta_size))
    det_buf = np.empty(n_ticks)
    diverged, done = None, 0
    for k in range(n_ticks):
        pdx, pdy, vdx, vdy, adx, ady = trajectory.sample_tuple(k * dt)
        q, qd = plant.q, plant.qd
        out = ctrl.step(q, qd, (pdx, pdy), (vdx, vdy), (adx, ady), dt)
        err = math.hypot(out.p[0] - pdx, out.p[1] - pdy)
        if not (math.isfinite(err) and np.isfinite(out.tau).all()):
            diverged = k * dt
            break
        q_buf[k], qd_buf[k], p_buf[k], pd_buf[k] = q, qd, out.p, (pdx, pdy)
        tau_buf[k], th_buf[k] = out.tau, reported.theta(out)
        det_buf[k] = reported.conditioning(out)
        done = k + 1
        if err > diverge_m:
            diverged = k * dt
            break
        try:
            plant.step(out.tau, dt)
        except PlantDivergedError:
            diverged = (k + 1) * dt
            break
    trace = {'t': t[:done], 'q': q_buf[:done], 'qd': qd_buf[:done], 'p': p_buf[:done],
             'p_d': pd_buf[:done], 'tau': tau_buf[:done], 'theta': th_buf[:done],
             'det': det_buf[:done]}
    record = compute_record(label, 'robust', seed, trace['t'], trace['p'], trace['p_d'],
                            trace['tau'], trace['theta'], trace['q'][:, passive],
                            trace['det'], diverged, 'offline')
    return record, trace
