"""
The URDF's joint limits, watched on the simulated arm (no ROS types).

The plants integrate the arm without end stops or speed limits (the Panda's
free joint 7 turns far past its +-2.9 rad range and its rated speed under the joint
disturbance alone). A real arm would reach its stop, so the simulator says when a joint
passes its URDF limits: :class:`LimitWatch` notes, per joint, the first time its angle
leaves ``[lower, upper]`` and the first time its speed exceeds ``velocity``, and the
extremes met; the node logs each first passage once, lists the joints in its
``/diagnostics`` warning and in its end-of-run line.
"""

import math


class LimitWatch:
    """
    Watch joint angles and speeds against limits.

    Parameters
    ----------
    names : sequence of str, (n,)
        Joint names (model order).
    lower, upper : sequence of float, (n,)
        Position limits [rad]; a joint with ``lower >= upper`` or a non-finite bound has
        none (URDF continuous joints).
    velocity : sequence of float, (n,)
        Speed limits [rad/s]; non-finite or <= 0: none.

    Attributes
    ----------
    passed : dict
        ``{(name, 'position' | 'speed'): (t [s], value)}`` of each first passage.
    extremes : dict
        ``{name: (q_min, q_max, |qd| max)}`` over the run, of the joints that passed a
        limit.

    """

    def __init__(self, names, lower, upper, velocity):
        self.names = tuple(names)
        n = len(self.names)
        if not (len(lower) == len(upper) == len(velocity) == n):
            raise ValueError(f'lower, upper, velocity: expected {n} values each (one per '
                             f'joint of {list(self.names)})')
        self._pos = [(i, float(lo), float(hi)) for i, (lo, hi) in enumerate(zip(lower, upper))
                     if math.isfinite(lo) and math.isfinite(hi) and lo < hi]
        self._vel = [(i, float(v)) for i, v in enumerate(velocity)
                     if math.isfinite(v) and v > 0.0]
        self.passed = {}
        self._range = [[math.inf, -math.inf, 0.0] for _ in range(n)]

    def observe(self, t, q, qd):
        """
        Take one state; return the new first passages, a list of one-line texts.

        Parameters
        ----------
        t : float
            Its time [s].
        q, qd : sequence of float, (n,)
            Angles [rad] and rates [rad/s], model order.

        """
        ext = self._range
        for i, v in enumerate(q):
            e = ext[i]
            if v < e[0]:
                e[0] = v
            if v > e[1]:
                e[1] = v
            s = abs(qd[i])
            if s > e[2]:
                e[2] = s
        new = []
        for i, lo, hi in self._pos:
            v = q[i]
            if lo <= v <= hi or (self.names[i], 'position') in self.passed:
                continue
            self.passed[(self.names[i], 'position')] = (t, v)
            new.append(f'{self.names[i]} at {v:.4f} rad passed its URDF position limits '
                       f'[{lo:g}, {hi:g}] rad at t = {t:.3f} s')
        for i, lim in self._vel:
            v = abs(qd[i])
            if v <= lim or (self.names[i], 'speed') in self.passed:
                continue
            self.passed[(self.names[i], 'speed')] = (t, v)
            new.append(f'{self.names[i]} at {v:.4f} rad/s passed its URDF speed limit '
                       f'{lim:g} rad/s at t = {t:.3f} s')
        return new

    @property
    def extremes(self):
        """Return ``{name: (q_min, q_max, |qd| max)}`` of the joints that passed a limit."""
        return {name: tuple(self._range[i]) for i, name in enumerate(self.names)
                if (name, 'position') in self.passed or (name, 'speed') in self.passed}

    def summary(self):
        """Return the joints past a limit in one line ('' : none), with their extremes."""
        parts = []
        for name, (lo, hi, vmax) in self.extremes.items():
            kinds = [kind for kind in ('position', 'speed') if (name, kind) in self.passed]
            parts.append(f'{name} ({", ".join(kinds)}: {lo:.3f}..{hi:.3f} rad, '
                         f'{vmax:.3f} rad/s)')
        return '; '.join(parts)
