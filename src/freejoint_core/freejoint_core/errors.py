"""Typed errors raised by the freejoint core when an argument is bad, and a shared check."""

import math


class FreejointValueError(ValueError):
    """A bad argument; the message starts with the argument's name."""


class PlantDivergedError(FreejointValueError):
    """The integration produced a non-finite state; the plant kept its last finite one."""


def positive(name, value, expected='a finite number > 0'):
    """
    Return ``value`` as a finite float > 0, or raise naming the argument.

    Parameters
    ----------
    name : str
        The argument's name (the message starts with it).
    value : object
        What was given.
    expected : str, optional
        What the message says was expected.

    Returns
    -------
    float

    Raises
    ------
    FreejointValueError
        ``value`` is not a number, not finite or not > 0.

    """
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a number, got {value!r}') from None
    if not math.isfinite(out) or out <= 0.0:
        raise FreejointValueError(f'{name}: expected {expected}, got {out}')
    return out
