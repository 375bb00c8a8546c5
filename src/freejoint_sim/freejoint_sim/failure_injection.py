"""
Joint failures the simulator injects, without ROS.

A failure is scheduled by the parameter ``fail_joint`` (``'joint3@2.5'``: the joint's
actuator and brake fail from simulation time 2.5 s; several joined by ``,``; ``''``: none)
or by the service ``~/fail_joint`` (from the next step).  The plant takes it
(``freejoint_core.plant.PeriodPlant.fail_joint``): from the first step that starts at or
after that time the joint gets no torque, the disturbance only.  :class:`Injector` keeps
the schedule, tells when a failure has taken effect (the node logs it and reports it on
``/diagnostics``) and zeroes the failed joints' effort in ``joint_states``.
"""

import math

from freejoint_core.errors import FreejointValueError


def parse_fail_joint(text, joint_names, active):
    """
    Parse the parameter ``fail_joint``.

    Parameters
    ----------
    text : str
        ``'<joint>@<t>[,<joint>@<t>...]'`` (joint names, times [s] >= 0) or ``''``.
    joint_names : sequence of str
        The arm's joints, model order.
    active : sequence of int
        The driven joints (model indices): only those can fail.

    Returns
    -------
    list of (int, float)
        Model index and time [s], in the order given.

    Raises
    ------
    FreejointValueError
        ``fail_joint: ...`` naming what is wrong.

    """
    out = []
    if not str(text).strip():
        return out
    for item in str(text).split(','):
        name, sep, at = item.strip().partition('@')
        try:
            t = float(at) if sep else math.nan
        except ValueError:
            t = math.nan
        if not math.isfinite(t) or t < 0.0:
            raise FreejointValueError(
                f'fail_joint: expected <joint>@<time s >= 0>[,...], e.g. joint3@2.5, got '
                f'{item.strip()!r}')
        if name not in joint_names:
            raise FreejointValueError(
                f'fail_joint: {name!r} is not a joint of {list(joint_names)}')
        j = list(joint_names).index(name)
        if j not in active:
            raise FreejointValueError(f'fail_joint: {name} is passive already (no actuator '
                                      'to fail)')
        out.append((j, t))
    return out


class Injector:
    """
    The simulator's failure schedule on one plant.

    Parameters
    ----------
    plant : freejoint_core.plant.PeriodPlant
        The plant (``fail_joint``, ``failed``, ``t``).
    joint_names : sequence of str
        Model order.

    Attributes
    ----------
    taken : list of (str, float, str)
        Failures that have taken effect: joint name, time [s], how scheduled
        (``'parameter'`` or ``'service'``).

    """

    def __init__(self, plant, joint_names):
        self.plant = plant
        self.names = tuple(joint_names)
        self._pending = {}
        self.taken = []

    def schedule(self, joint, at_s, how):
        """Schedule joint (model index) to fail at ``at_s`` [s] (``how`` for the record)."""
        self.plant.fail_joint(joint, at_s)
        at = self.plant.failures[joint]
        if all(name != self.names[joint] for name, _, _ in self.taken):
            self._pending[joint] = (at, how)
        return at

    def check(self):
        """
        Return the failures that took effect with the last step: [(name, t, how)].

        Cheap when nothing is pending (the per-step call).
        """
        if not self._pending:
            return ()
        failed = self.plant.failed
        new = []
        for j in sorted(self._pending):
            if j in failed:
                at, how = self._pending.pop(j)
                new.append((self.names[j], at, how))
        self.taken.extend(new)
        return new

    @property
    def scheduled(self):
        """Return whether any failure is scheduled or has taken effect."""
        return bool(self._pending or self.taken)

    def effort(self, applied):
        """
        Put what the scheduled joints received over the last step into ``applied``.

        ``applied`` (n, model order) holds the command; a joint failed over the step got
        no torque (``plant.last_effort``: 0), so its effort in joint_states reads 0.
        """
        last = self.plant.last_effort
        for j in self.plant.failures:
            applied[j] = last[j]
