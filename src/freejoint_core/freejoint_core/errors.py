"""Typed errors raised by the freejoint core when an argument is bad."""


class FreejointValueError(ValueError):
    """A bad argument; the message starts with the argument's name."""


class PlantDivergedError(FreejointValueError):
    """The integration produced a non-finite state; the plant kept its last finite one."""
