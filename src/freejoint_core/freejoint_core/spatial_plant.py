"""
The simulated spatial arm: Pinocchio's ABA of a URDF chain integrated by RK4.

``SpatialPlant`` is ``freejoint_core.plant.Plant`` for a
:class:`freejoint_core.spatial_model.SpatialArm` (the real arm: the URDF's masses): the
same forcing (actuator torque on the active joints and one
``numpy.random.default_rng(seed).uniform(-dist_bound, dist_bound, n)`` draw, both held
over the control period), the same classic RK4 at ``dt_sub`` and the same divergence and
failure handling (``PeriodPlant``), with ``qdd = aba(q, qd, tau)`` of the chain. The free
joints get the disturbance only, and, with ``passive_damping`` b > 0, the viscous torque
``-b qd_j`` of the drivetrain a failed joint keeps (gearbox and motor still turn with it;
evaluated at every RK4 stage; the controller is not told: to the law it is part of the
disturbance). The simulator and the offline runner (``freejoint_core.spatial_offline``)
integrate the arm with it.
"""

import math

from freejoint_core.errors import FreejointValueError
from freejoint_core.plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant
from freejoint_core.spatial_model import SpatialArm
import numpy as np


class SpatialPlant(Plant):
    """
    A spatial arm integrated by RK4 on Pinocchio's ABA, with bounded random disturbances.

    Parameters
    ----------
    arm : SpatialArm
        The real arm (chain, free joints, gravity).
    dt_sub : float
        RK4 step [s], > 0; a control period must be an integer multiple of it.
    dist_bound : float
        Bound [N m] of the uniform joint disturbance, >= 0 (0: none).
    seed : int or None
        Seed of the disturbance draws.
    q0, qd0 : array_like, (n,), optional
        Initial angles [rad] and rates [rad/s] (default zeros).
    passive_damping : float
        Viscous damping [N m s/rad] of each free joint, >= 0 (0: the paper's frictionless
        free joint).

    Attributes
    ----------
    params, model : SpatialArm
        ``arm`` (``n``, ``r``, ``active``; ``fk``, ``jacobian``, limits).
    damping : numpy.ndarray, (n,)
        Viscous damping per joint [N m s/rad]: ``passive_damping`` on the free joints, 0
        elsewhere.
    q, qd, t, k, last_disturbance, last_effort, failed
        As :class:`freejoint_core.plant.PeriodPlant`.

    Raises
    ------
    FreejointValueError
        Naming the argument that is bad.

    """

    def __init__(self, arm, dt_sub=DEFAULT_DT_SUB, dist_bound=DEFAULT_DIST_BOUND, seed=0,
                 q0=None, qd0=None, passive_damping=0.0):
        if not isinstance(arm, SpatialArm):
            raise FreejointValueError(f'arm: expected SpatialArm, got {type(arm).__name__}')
        self.arm = arm
        self.damping = passive_damping_vector(arm, passive_damping)
        self._setup(arm, arm, dt_sub, dist_bound, seed, q0, qd0)
        self._fast = False
        self._qdd = arm.forward_dynamics
        if self.damping.any():
            aba, b = arm.forward_dynamics, self.damping
            self._qdd = lambda q, qd, tau: aba(q, qd, tau - b * qd)
        self.reset()


def passive_damping_vector(arm, passive_damping):
    """
    Return the per-joint viscous damping (n,) [N m s/rad] of a failed joint's drivetrain.

    Parameters
    ----------
    arm : SpatialArm
        The arm (``n``, ``passive``).
    passive_damping : float
        Damping [N m s/rad] of each free joint, finite and >= 0.

    Raises
    ------
    FreejointValueError
        Naming ``passive_damping`` when it is not a finite number >= 0.

    """
    try:
        b = float(passive_damping)
    except (TypeError, ValueError):
        raise FreejointValueError(
            f'passive_damping: expected a number [N m s/rad], got {passive_damping!r}') \
            from None
    if not (math.isfinite(b) and b >= 0.0):
        raise FreejointValueError(
            f'passive_damping: must be finite and >= 0 N m s/rad, got {passive_damping!r}')
    out = np.zeros(arm.n)
    out[list(arm.passive)] = b
    return out
