"""Typed errors raised by the freejoint core when an argument is bad, and a shared check."""

import math


class FreejointValueError(ValueError):
    """A bad argument; the message starts with the argument's name."""


class PlantDivergedError(FreejointValueError):
    """The integration produced a non-finite state; the plant kept its last finite one."""


def positive(name, value, allow_zero=False):
    """
    Return ``value`` as a finite float > 0 (>= 0 with ``allow_zero``), or raise naming it.

    Parameters
    ----------
    name : str
        The argument's name (the message starts with it).
    value : object
        What was given.
    allow_zero : bool, optional
        Accept 0.

    Returns
    -------
    float

    Raises
    ------
    FreejointValueError
        ``value`` is not a number, not finite, negative, or 0 without ``allow_zero``.

    """
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a number, got {value!r}') from None
    if not math.isfinite(out) or out < 0.0 or (out == 0.0 and not allow_zero):
        bound = '>= 0' if allow_zero else '> 0'
        raise FreejointValueError(f'{name}: must be finite and {bound}, got {out}')
    return out
