"""
The controller's joint-state input: names mapped to the model's joints, the state checked.

:class:`StateReader` turns a JointState's names, positions and velocities (any order,
extra joints ignored) into the model's ``q``, ``qd`` [rad, rad/s], or says why it cannot:
a joint missing, arrays shorter than the names, a non-finite or implausible value
(``freejoint_core.guards.state_refusal``). The arm's joint offsets are added (the core's
angles). It keeps the state's efforts for the failure monitor. No ROS, no clock.
"""

import math

from freejoint_control.failures import finite_or_none
from freejoint_core.guards import state_refusal

NAME_MAP_CACHE = 16
"""Distinct JointState name lists whose mapping is kept."""
_isfinite = math.isfinite


class StateReader:
    """Map and check joint states (module notes); :meth:`configure` before the first."""

    def __init__(self):
        self.joint_names = ()
        self._name_maps = {}
        self._map_names = None
        self._map = None
        self._bounds = None
        self._offsets = ()
        self._effort = None

    def configure(self, joint_names, lower, upper, velocity_limit, offsets):
        """
        Take the model's joints and the plausible state's bounds and offsets.

        ``joint_names``: base to tip, passive ones included; ``lower``, ``upper``,
        ``velocity_limit``: ``state_refusal``'s bounds [rad, rad/s]; ``offsets``: added to
        the measured angles [rad] (empty: none).
        """
        if tuple(joint_names) != self.joint_names:
            self.joint_names = tuple(joint_names)
            self._name_maps.clear()
            self._map_names = self._map = None
        self._bounds = (lower, upper, velocity_limit)
        self._offsets = offsets

    def _joint_map(self, names):
        """Map a JointState name list to the model joints' indices (cached per list)."""
        key = tuple(names)
        found = self._name_maps.get(key)
        if found is None:
            want = self.joint_names
            missing = [n for n in want if n not in key]
            if missing:
                found = (None, 'JointState lacks joint(s) %s (has %s)' % (missing, list(key)),
                         'missing')
            else:
                found = (tuple(key.index(n) for n in want), '', '')
            if len(self._name_maps) >= NAME_MAP_CACHE:
                self._name_maps.clear()
            self._name_maps[key] = found
        self._map_names = names
        self._map = found
        return found

    def read(self, names, pos, vel):
        """
        Return ``(q, qd, kind, reason)`` of a joint state; ``q`` None when it is refused.

        Parameters
        ----------
        names : sequence of str
            Joint names (any order, extra joints ignored).
        pos, vel : sequence of float
            Positions [rad] and velocities [rad/s] in the order of ``names``.

        Returns
        -------
        q, qd : tuple of float, (n,), or None
            The core's angles (offsets added) and rates, model order.
        kind : str
            The kind of refusal ('missing', 'short', 'nonfinite', 'implausible'; '': none).
        reason : str
            Why it is refused ('' : taken).

        """
        found = self._map if names == self._map_names else self._joint_map(names)
        idx, reason, kind = found
        q = qd = None
        if idx is None:
            return q, qd, kind, reason
        try:
            if len(idx) == 3:
                i0, i1, i2 = idx
                q = (pos[i0], pos[i1], pos[i2])
                qd = (vel[i0], vel[i1], vel[i2])
            else:   # an arm of another number of joints (robot_description)
                q = tuple([pos[i] for i in idx])
                qd = tuple([vel[i] for i in idx])
        except (IndexError, ValueError):
            return None, None, 'short', (
                'JointState has %d names but %d positions and %d velocities' % (
                    len(names), len(pos), len(vel)))
        if not all(map(_isfinite, q + qd)):
            return None, qd, 'nonfinite', (
                'JointState has a non-finite position or velocity: q=%s qd=%s' % (
                    list(q), list(qd)))
        lower, upper, vlim = self._bounds
        implausible = state_refusal(q, qd, lower, upper, vlim)
        if implausible is not None:
            return None, qd, 'implausible', 'implausible state: ' + implausible
        if self._offsets:
            # the core's angles: the measured ones plus the arm's offsets (a URDF arm whose
            # task frame is turned to put gravity along -y)
            q = tuple([a + b for a, b in zip(q, self._offsets)])
        return q, qd, kind, reason

    def note_effort(self, effort):
        """Keep a state's efforts (in the order of its names; None: none) for :meth:`effort_of`."""
        self._effort = effort

    def effort_of(self, n):
        """Return the last state's efforts in model order (n), or None (none or not finite)."""
        eff = self._effort
        idx = self._map[0] if self._map is not None else None
        if eff is None or idx is None or len(eff) < len(self._map_names):
            return None
        return finite_or_none([eff[i] for i in idx], n)
