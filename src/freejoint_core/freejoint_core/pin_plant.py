"""
The RK4 plant of a URDF arm with Pinocchio's forward dynamics (ABA).

``PinPlant`` is ``freejoint_core.plant.Plant`` for any planar arm read from URDF: the
same forcing (torque and one disturbance draw held per control period, the same
``numpy.random.default_rng(seed)`` draws), the same classic RK4 at ``dt_sub``, with
``qdd = aba(q, qd, tau)`` from :class:`freejoint_core.pin_model.PinArmModel` instead
of the core's numpy ``ArmModel.forward_dynamics``.  For arms without the scalar
3-link kernel (n != 3) it is the fast RK4 engine (``bench/core_urdf.py`` prints both
engines' cost per period).
"""

from freejoint_core.errors import FreejointValueError
from freejoint_core.pin_model import PinArmModel
from freejoint_core.plant import DEFAULT_DT_SUB, Plant
from freejoint_core.urdf import UrdfArm
import pinocchio


class PinPlant(Plant):
    """
    The URDF arm integrated by RK4 on Pinocchio's ABA, with bounded random disturbances.

    Parameters
    ----------
    arm : UrdfArm
        The real arm (URDF, passive joints, gravity vector).
    dt_sub, dist_bound, seed, q0, qd0
        As :class:`freejoint_core.plant.Plant`.

    Attributes
    ----------
    params : ArmParams
        ``arm.params``.
    model : PinArmModel
        The Pinocchio model it integrates.
    q, qd, t, k, last_disturbance
        As :class:`freejoint_core.plant.PeriodPlant`.

    """

    def __init__(self, arm, dt_sub=DEFAULT_DT_SUB, dist_bound=0.5, seed=0, q0=None, qd0=None):
        if not isinstance(arm, UrdfArm):
            raise FreejointValueError(f'arm: expected UrdfArm, got {type(arm).__name__}')
        self.arm = arm
        self._setup(arm.params, PinArmModel(arm), dt_sub, dist_bound, seed, q0, qd0)
        self._fast = False
        if self.model._identity:    # revolute joints in core order: ABA straight on q, qd
            pin_model, pin_data = self.model.pin_model, self.model.pin_data

            def qdd(q, qd, tau):
                return pinocchio.aba(pin_model, pin_data, q, qd, tau).copy()
            self._qdd = qdd
        else:
            self._qdd = self.model.forward_dynamics
        self.reset()
