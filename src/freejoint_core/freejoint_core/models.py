"""
Choice of the arm model implementation: :func:`make_model`.

``arm.ArmModel`` is the general numpy reference; ``fast3.Arm3Model`` is the
closed-form scalar kernel of the 3-link arm with the same interface.  This
module picks one; it sits above both so that neither imports the other's user.

"""

from freejoint_core.arm import ArmModel, ArmParams
from freejoint_core.errors import FreejointValueError
from freejoint_core.fast3 import Arm3Model


def make_model(params):
    """
    Return the fastest model implementation for ``params``.

    Parameters
    ----------
    params : ArmParams
        Physical parameters.

    Returns
    -------
    ArmModel
        ``freejoint_core.fast3.Arm3Model`` (closed-form scalar kernel, same
        interface) when ``params.n == 3``, else the general ``ArmModel``.

    Raises
    ------
    FreejointValueError
        ``params`` is not an ``ArmParams`` (message names ``params``).

    """
    if not isinstance(params, ArmParams):
        raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
    if params.n == 3:
        return Arm3Model(params)
    return ArmModel(params)
