"""
The controller's and the simulator's guards: plausibility checks and limits, in one place.

- :func:`state_refusal`: a measured joint state outside the plausible positions and speeds;
- :func:`setpoint_refusal`: a task-space setpoint beyond the reach, speed or acceleration;
- :func:`law_output_fault`: a law result that must not be commanded (a non-finite or
  out-of-range torque, a law state outside its bounds);
- :func:`limit_effort`: the torque limit and the rate limit of the command;
- :func:`clamp_dt`: the law's time step measured from state stamps, bounded;
- :func:`hold_effort`: the command a controller leaves a driver when it stops (the static
  gravity load of the active joints, safe to be held by a driver that keeps its last
  command; docs/real-time.md); :func:`damped_hold_effort`: the joint hold it answers
  every state with instead when the driver has no brakes and no watchdog;
- :func:`divergence_reason`: a simulated plant whose state is not a physical one any more
  (``freejoint_core.plant.Plant.step`` raises ``PlantDivergedError`` on a non-finite state;
  the simulator also stops at a joint faster than its ``divergence_speed`` or an angle
  beyond :data:`MAX_ANGLE`, where the integration no longer resolves the motion and the
  numbers only grow: a lost arm ran at over 1000 rad/s before it overflowed).

Each returns the reason (a string naming the value) or None, or the limited values; plain
floats and sequences, no ROS types.

"""

import math

MAX_ANGLE = 1e6
"""Largest plausible joint angle [rad]: some 160000 turns of a free joint."""

_isfinite = math.isfinite


def clamp_dt(dt, nominal, low=0.25, high=4.0):
    """
    Bound a time step measured from stamps to ``[low, high] * nominal``.

    Parameters
    ----------
    dt : float
        Measured step [s] (difference of consecutive state stamps).
    nominal : float
        Nominal control period [s], > 0.
    low, high : float
        Bounds as multiples of ``nominal``.

    Returns
    -------
    dt : float
        The bounded step [s] (``nominal`` when ``dt`` is not finite).
    clamped : bool
        True when ``dt`` was outside the range.

    """
    lo = low * nominal
    hi = high * nominal
    if not _isfinite(dt):
        return nominal, True
    if dt < lo:
        return lo, True
    if dt > hi:
        return hi, True
    return dt, False


def hold_effort(gravity, active, limits=None):
    """
    Return the stop command: the active joints' gravity load ``G_a(q)``, limited.

    What a controller sends when it stops (docs/real-time.md, "Stopping"), once, before it
    goes quiet: a driver that keeps applying its last command (ros2_control's forward
    command controller) then holds the active joints against gravity at the configuration
    the stop found, where zero effort lets a vertical arm fall and a stale tracking command
    (its acceleration and feedback terms) drives it on; the brakes, asked for at the same
    time, are what stops the arm.

    Parameters
    ----------
    gravity : sequence of float, (n,)
        Gravity torques ``G(q) = dV/dq`` of the model at the measured angles [N m] (the
        controller's nominal model: ``model.gravity_torque(q)``); 0 in a horizontal plane.
    active : sequence of int, (r,)
        Indices of the active joints in ``gravity`` (the model's order).
    limits : sequence of float, (r,), optional
        Per-joint torque limits [N m] (> 0), None: none.

    Returns
    -------
    list of float, (r,)
        The command clipped to ``[-limit, limit]`` [N m], in the order of ``active``; a
        non-finite term gives 0 for that joint (never a non-finite command).

    """
    return _limited([float(gravity[i]) for i in active], limits)


DAMPED_HOLD_DAMPING = 1.5
"""The damped hold's damping, times ``M~aa / stop_hold_time`` (see :func:`damped_hold_effort`)."""


def damped_hold_effort(gravity, active, inertia, q, qd, q_hold, hold_time, limits=None):
    """
    Return the damped joint hold: ``G_a + M~aa ((q_hold - q_a) / T^2 - 1.5 qd_a / T)``.

    What a controller answers every state with while it is not ready and its driver holds
    the last command (``readiness_action: damp``): the active joints held at ``q_hold`` on
    the gravity load, the free joints swinging on them.  Such a driver keeps each command
    until the next, for as long as the controller is stalled or its states are missed, so
    the gains are set by the longest interval ``T`` (``hold_time``) one command may be
    kept, on the effective inertia ``M~aa`` the active joints move (the free joints
    following).  Per mode of unit inertia, a torque ``-k x - d v`` held over ``T`` maps
    ``(x, v T)`` by ``[[1 - a/2, 1 - b/2], [-a, 1 - b]]`` with ``a = k T^2``, ``b = d T``;
    ``a = 1``, ``b = 1.5`` make both eigenvalues 0 (deadbeat: a command kept for exactly
    ``T`` stops the joint where it is to be held).  Kept for ``s T`` it is stable while
    ``1.5 s < 2``, i.e. up to ``1.33 T``, and up to ``1.9 T`` when the real inertia is the
    nominal one over 0.7 (the law's model error); answered every few milliseconds it is a
    joint PD of natural frequency ``1 / T`` and damping ratio 0.75.  The price is its
    stiffness: a gravity load the nominal model misses by ``e`` [N m] sags the joints by
    ``T^2 M~aa^-1 e`` [rad].

    Parameters
    ----------
    gravity : sequence of float, (n,)
        Gravity torques of the (nominal) model at ``q`` [N m].
    active : sequence of int, (r,)
        Indices of the active joints in ``gravity``, ``q`` and ``qd``.
    inertia : array_like, (r, r)
        ``M~aa(q)`` [kg m^2], the active joints' effective inertia
        (``freejoint_core.arm_gains.active_inertia``).
    q, qd : sequence of float, (n,)
        Measured angles [rad] and speeds [rad/s].
    q_hold : sequence of float, (r,)
        The active joints' angles to hold [rad].
    hold_time : float
        ``T`` [s] > 0: the longest a driver is to keep one command (``stop_hold_time``).
    limits : sequence of float, (r,), optional
        As in :func:`hold_effort`.

    Returns
    -------
    list of float, (r,)
        The command, limited and finite as :func:`hold_effort`'s.

    """
    stiff = 1.0 / (hold_time * hold_time)
    damp = DAMPED_HOLD_DAMPING / hold_time
    acc = [stiff * (q_hold[j] - q[i]) - damp * qd[i] for j, i in enumerate(active)]
    out = []
    for j, i in enumerate(active):
        row = inertia[j]
        out.append(float(gravity[i]) + sum(float(row[k]) * acc[k] for k in range(len(acc))))
    return _limited(out, limits)


def _limited(values, limits):
    """Return ``values`` within ``[-limit, limit]``, a non-finite one as 0."""
    out = []
    for j, g in enumerate(values):
        if not _isfinite(g):
            g = 0.0
        if limits is not None:
            lim = limits[j]
            g = lim if g > lim else -lim if g < -lim else g
        out.append(g)
    return out


def limit_effort(tau, limits, prev=None, max_step=None):
    """
    Clip torques to per-joint limits and, optionally, to a step from the previous command.

    Parameters
    ----------
    tau : sequence of float, (r,)
        Torques [N m] (finite).
    limits : sequence of float, (r,)
        Per-joint limits [N m], > 0: ``|tau_i| <= limits_i``.
    prev : sequence of float, (r,), optional
        Previous command [N m]; with ``max_step``, ``|tau_i - prev_i| <= max_step``.
    max_step : float, optional
        Largest change per tick [N m] (rate limit times dt).

    Returns
    -------
    tau : list of float, (r,)
        The limited torques.
    clipped : bool
        A torque limit bound.
    rate_limited : bool
        The step limit bound.

    """
    out = []
    clipped = False
    rated = False
    for i, x in enumerate(tau):
        lim = limits[i]
        if x > lim:
            x = lim
            clipped = True
        elif x < -lim:
            x = -lim
            clipped = True
        if max_step is not None and prev is not None:
            lo = prev[i] - max_step
            hi = prev[i] + max_step
            if x > hi:
                x = hi
                rated = True
            elif x < lo:
                x = lo
                rated = True
        out.append(x)
    return out, clipped, rated


def state_refusal(q, qd, lower, upper, vmax):
    """
    Return why a measured state is implausible, or None when it is within the limits.

    Parameters
    ----------
    q, qd : sequence of float, (n,)
        Joint positions [rad] and velocities [rad/s].
    lower, upper : sequence of float, (n,)
        Position limits [rad].
    vmax : sequence of float, (n,)
        Velocity limits [rad/s]: ``|qd_i| <= vmax_i``.

    Returns
    -------
    str or None

    """
    for i, x in enumerate(q):
        if not (_isfinite(x) and lower[i] <= x <= upper[i]):
            return 'joint %d position %r outside [%g, %g] rad' % (i, x, lower[i], upper[i])
    for i, x in enumerate(qd):
        if not (_isfinite(x) and -vmax[i] <= x <= vmax[i]):
            return 'joint %d velocity %r beyond %g rad/s' % (i, x, vmax[i])
    return None


def setpoint_refusal(sp, reach, vmax, amax, m=2):
    """
    Return why a setpoint is implausible, or None when it is within the bounds.

    Parameters
    ----------
    sp : sequence of float, (3 m,)
        Position, velocity and acceleration, m values each (planar:
        ``(px, py, vx, vy, ax, ay)``) [m, m/s, m/s^2].
    reach : float
        Largest distance of a reachable point from the base [m].
    vmax, amax : float
        Bounds on the setpoint's speed [m/s] and acceleration magnitude [m/s^2].
    m : int, optional
        Task dimension (default 2).

    Returns
    -------
    str or None

    """
    if len(sp) != 3 * m:
        return '%d values, expected %d (position, velocity, acceleration of %d each)' % (
            len(sp), 3 * m, m)
    for x in sp:
        if not _isfinite(x):
            return 'non-finite value in %s' % (list(sp),)
    if m == 2:
        r = math.hypot(sp[0], sp[1])
        v = math.hypot(sp[2], sp[3])
        a = math.hypot(sp[4], sp[5])
    else:
        r = math.hypot(*sp[0:m])
        v = math.hypot(*sp[m:2 * m])
        a = math.hypot(*sp[2 * m:3 * m])
    if not r <= reach:
        return 'position (%s) is %g m from the base, beyond the reach %g m' % (
            ', '.join('%g' % x for x in sp[0:m]), r, reach)
    if not v <= vmax:
        return 'velocity %g m/s beyond %g m/s' % (v, vmax)
    if not a <= amax:
        return 'acceleration %g m/s^2 beyond %g m/s^2' % (a, amax)
    return None


def law_output_fault(effort, limits, values, bounds):
    """
    Return why a law's result must not be commanded, or None when it may.

    Parameters
    ----------
    effort : sequence of float, (r,)
        The torques [N m] the law gave (command order).
    limits : sequence of float, (r,)
        Per-joint torque limits [N m]: ``|effort_i| <= limits_i`` (a law clips to them).
    values : sequence of float, (k,)
        The law's internal state after the step (``ControlLaw.state_values``).
    bounds : sequence of (float, float), (k,)
        Plausible range of each state value (``ControlLaw.state_bounds``).

    Returns
    -------
    str or None
        ``'torque [...]'`` or ``'<law state> [...]'``: a non-finite or out-of-range value.

    """
    for x, lim in zip(effort, limits):
        if not -lim <= x <= lim:
            return 'torque %r' % (list(effort),)
    isfinite = _isfinite
    for x, (lo, hi) in zip(values, bounds):
        if not (lo <= x <= hi and isfinite(x)):
            return 'law state %r' % (list(values),)
    return None


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
