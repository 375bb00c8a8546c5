"""
When the simulated plant counts as diverged (no ROS types).

``freejoint_core.plant.Plant.step`` raises ``PlantDivergedError`` on a non-finite state;
the simulator also stops at a finite but absurd one: a joint faster than its
``divergence_speed`` parameter or an angle beyond :data:`MAX_ANGLE`, where the integration
no longer resolves the motion and the numbers only grow (a lost arm ran at over 1000 rad/s
before it overflowed).

"""

import math

MAX_ANGLE = 1e6
"""Largest plausible joint angle [rad]: some 160000 turns of a free joint."""

_isfinite = math.isfinite


def divergence_reason(q, qd, max_speed, max_angle=MAX_ANGLE):
    """
    Return why the state (q, qd) is not a physical one, or None if it is.

    Parameters
    ----------
    q, qd : sequence of float, (n,)
        Joint angles [rad] and velocities [rad/s].
    max_speed : float
        Largest plausible joint speed [rad/s].
    max_angle : float
        Largest plausible absolute joint angle [rad].

    Returns
    -------
    str or None
        The first problem found, naming the joint (index from 0) and the value.

    """
    for i, (a, v) in enumerate(zip(q, qd)):
        if not (_isfinite(a) and _isfinite(v)):
            return 'joint %d: non-finite state (q = %r rad, qd = %r rad/s)' % (i, a, v)
        if abs(v) > max_speed:
            return 'joint %d: speed %.6g rad/s beyond divergence_speed %g rad/s' % (
                i, v, max_speed)
        if abs(a) > max_angle:
            return 'joint %d: angle %.6g rad beyond %g rad' % (i, a, max_angle)
    return None
