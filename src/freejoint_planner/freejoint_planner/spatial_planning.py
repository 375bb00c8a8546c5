"""
Spatial plans: the offline runner's 3-D circle and its plan-time checks (no ROS).

A spatial arm (``NodeArm.spatial``, task_dim 3) gets one kind of plan: the circle of
``freejoint_core.spatial_offline.circle(p0, radius, t, duration)`` from the tip's start
point ``p0``, in the vertical plane facing the robot (spanned by the horizontal direction
across the base-to-tip line and the vertical) or the plane normal to the parameter
``plane_normal`` (``spatial_offline.circle_axes``), quintic over ``duration``, then held
(:class:`SpatialCircle`; its setpoints are that function's values at ``t = k dt``, not a
formula of this module). The planar ``centre``, ``start_angle`` and ``direction`` do not
apply: the circle starts at the tip.

Plan-time checks (:func:`check_spatial_plan`), each refusing with one line saying why:

* bounds (:func:`spatial_bounds`): the circle's peak speed and acceleration (the planar
  circle's, ``trajectory.circle_peaks``: same time law) within ``max_speed`` /
  ``max_acceleration``; every point of the circle within the arm's reach ``L``
  (``spatial_law.arm_reach``: the sum of the joint-to-joint distances to the tip, a bound
  on the tip's distance from the first joint's origin at any posture); a start point off
  the base's vertical axis (the facing plane is defined);
* a free joint that must carry gravity (``spatial_law.gravity_carrying_free_joint`` on the
  nominal model from the current posture);
* the nominal closed loop (:func:`nominal_loop`): the nominal model as plant, no
  disturbance, ``SpatialLaw`` with ``SpatialGains()`` and the weighted inverse, dynamic
  projector and null-space damping ``kd`` 20 as in ``spatial_offline``, from the current
  state over the circle and :data:`CHECK_HOLD` of its hold, at :data:`CHECK_PERIOD`;
  refused where ``kappa < kappa_min`` (1e-3), where an active joint leaves its URDF
  position limits, where the tip strays more than :data:`TRACK_BOUND` from the path (out
  of reach, or a singular posture the loop cannot pass) or where the loop diverges.

The check period :data:`CHECK_PERIOD` (2 ms, one RK4 step a period) is the coarsest
whose loop stays with the 1-ms loop on kappa and on the joints that move the tip
(``test_spatial_planning``); its cost and the comparison are in docs/spatial.md
("Planner"). The hold is checked for :data:`CHECK_HOLD` only: over a long hold the real
arm (70 % model, disturbance) departs from any nominal prediction by more than the check
could resolve; the controller's posture term (``nullspace_kp``) is what keeps the
redundant joints near the start there.

Free joints are not held to their URDF position limits (no torque can hold them; the
Panda's joint 7 turns 4.4 rad in the nominal loop of its circle): their range is reported
(:attr:`LoopCheck.free_outside`), not refused.
"""

from dataclasses import dataclass
import math
import time

from freejoint_core.arm_gains import joint_inertia, mode_steps, rule
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import NullSpace
from freejoint_core.laws import make_law
from freejoint_core.spatial_law import arm_reach, gravity_carrying_free_joint, SpatialGains
from freejoint_core.spatial_offline import circle, circle_axes, KD, KP
from freejoint_core.spatial_plant import SpatialPlant
from freejoint_core.trajectory import circle_peaks, CircleQuintic
import numpy as np
import pinocchio as pin

CHECK_PERIOD = 2e-3
"""[s] Period of the nominal closed loop of the check (module notes)."""
CHECK_HOLD = 1.0
"""[s] How much of the hold after the circle the nominal closed loop covers."""
TRACK_BOUND = 0.01
"""[m] Largest tip error of the nominal closed loop (it tracks to 3 mm at 2 ms where it
can: 1.5 mm UR5, 2.6 mm Panda, 3e-7 m at 1 ms)."""
AXIS_CLEARANCE = 1e-6
"""[m] Smallest horizontal distance of the start point from the base's vertical axis."""
REACH_POINTS = 721
"""Points of the circle checked against the reach (1/720 of a revolution apart)."""


class SpatialCircle:
    """
    The offline runner's circle from ``p0``: ``spatial_offline.circle(p0, radius, t, duration)``.

    Parameters
    ----------
    p0 : array_like, (3,)
        Start (and end) point [m], base frame, off the base's vertical axis.
    radius : float
        [m], > 0.
    duration : float
        Time of the revolution [s], > 0; held at its end after it.

    Attributes
    ----------
    task_dim : int
        3 (the stream publishes 3 values per vector).

    """

    task_dim = 3

    def __init__(self, p0, radius, duration, normal=None):
        p = np.array(p0, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise FreejointValueError(f'p0: expected 3 finite numbers [m], got {p0!r}')
        if math.hypot(p[0], p[1]) < AXIS_CLEARANCE:
            raise FreejointValueError(
                f"p0: the start point {np.round(p, 4).tolist()} m is on the base's vertical "
                'axis: the vertical plane facing the robot is not defined')
        for name, value in (('radius', radius), ('duration', duration)):
            if not (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and math.isfinite(value) and value > 0.0):
                raise FreejointValueError(f'{name}: expected a finite number > 0, got '
                                          f'{value!r}')
        p.setflags(write=False)
        self._p0, self._radius, self._duration = p, float(radius), float(duration)
        self._normal = plane_normal(normal)
        circle_axes(p, self._normal)        # refuses a bad normal now, naming it

    @property
    def p0(self):
        """Return the start point [m] (read-only array, (3,))."""
        return self._p0

    @property
    def radius(self):
        """Return the radius [m]."""
        return self._radius

    @property
    def duration(self):
        """Return the time of the revolution [s]."""
        return self._duration

    def sample(self, t):
        """
        Return position, velocity and acceleration at ``t`` [s] (arrays, (3,)).

        ``spatial_offline.circle(p0, radius, t, duration)``; before the start (``t < 0``:
        a start delay) its value at ``t = 0`` (the start point, at rest).
        """
        return circle(self._p0, self._radius, t if t > 0.0 else 0.0, self._duration,
                      self._normal)

    def sample_tuple(self, t):
        """Return ``(px, py, pz, vx, vy, vz, ax, ay, az)`` at ``t`` [s] (floats)."""
        pos, vel, acc = self.sample(t)
        return tuple(pos.tolist() + vel.tolist() + acc.tolist())

    def points(self, num=361):
        """Return ``num`` positions evenly spaced in time over the revolution, (num, 3) [m]."""
        return np.array([self.sample(t)[0] for t in np.linspace(0.0, self._duration, num)])

    def __repr__(self):
        return (f'SpatialCircle(p0={self._p0.tolist()}, radius={self._radius!r}, '
                f'duration={self._duration!r})')


def plane_normal(value):
    """
    Return the plane normal of a ``plane_normal`` value: None for the default plane.

    None or ``[0, 0, 0]`` (the parameter's default): the vertical plane facing the robot;
    else a tuple of 3 floats (checked by ``spatial_offline.circle_axes``).
    """
    if value is None:
        return None
    vec = tuple(float(v) for v in value)
    return None if vec == (0.0, 0.0, 0.0) else vec


def describe(radius, duration, p0=None):
    """Return a spatial circle in words (for refusals and the log)."""
    start = 'from the tip' if p0 is None else (
        'from [%s] m' % ', '.join('%.4f' % v for v in p0))
    return f'spatial circle radius {radius:.6g} m duration {duration:.6g} s {start}'


def spatial_bounds(radius, duration, max_speed, max_acceleration):
    """
    Return why a circle's peaks exceed ``max_speed`` / ``max_acceleration``, or ''.

    The time law is the planar circle's (angle ``2 pi s(t / duration)``, quintic ``s``),
    so the peaks are ``trajectory.circle_peaks`` of the planar circle of the same radius
    and duration; the reason names ``duration``, as the planar planner's does.
    """
    speed, acc = circle_peaks(CircleQuintic(radius=float(radius), duration=float(duration)))
    if speed > max_speed:
        return (f'duration: {duration:g} s for radius {radius:g} m peaks at {speed:.6g} m/s, '
                f'above max_speed {max_speed:g} m/s (duration >= '
                f'{duration * speed / max_speed:.6g} s)')
    if acc > max_acceleration:
        return (f'duration: {duration:g} s for radius {radius:g} m peaks at {acc:.6g} '
                f'm/s^2, above max_acceleration {max_acceleration:g} m/s^2 (duration >= '
                f'{duration * math.sqrt(acc / max_acceleration):.6g} s)')
    return ''


def first_joint_origin(arm):
    """Return the origin [m], (3,), of the arm's first chain joint (fixed in the base)."""
    pin.forwardKinematics(arm.model, arm.data, np.zeros(arm.n))
    return np.array(arm.data.oMi[1].translation)


def reach_refusal(arm, path, reach=None):
    """
    Return why a circle leaves the arm's reach ('' if it does not), and its reach margin.

    Parameters
    ----------
    arm : SpatialArm
        The arm (any scale: kinematics only).
    path : SpatialCircle
        The circle.
    reach : float, optional
        ``spatial_law.arm_reach(arm)`` if known [m].

    Returns
    -------
    (str, float)
        The reason ('' : within) and ``reach - max |p - o1|`` [m] over the circle's points
        (``o1`` the first joint's origin).

    """
    reach = arm_reach(arm) if reach is None else reach
    origin = first_joint_origin(arm)
    pts = path.points(REACH_POINTS)
    dist = np.linalg.norm(pts - origin, axis=1)
    i = int(np.argmax(dist))
    margin = reach - float(dist[i])
    if margin < 0.0:
        return (f'radius: the circle leaves the reach of the arm: its point '
                f'{np.round(pts[i], 4).tolist()} m is {dist[i]:.4f} m from the first joint '
                f'{arm.joint_names[0]} (origin {np.round(origin, 4).tolist()} m), beyond the '
                f'reach {reach:.4f} m'), margin
    return '', margin


@dataclass(frozen=True)
class LoopCheck:
    """
    The nominal closed loop of a plan (:func:`nominal_loop`).

    Attributes
    ----------
    reason : str
        Why the plan is refused ('' : accepted).
    kappa_min : float
        Smallest ``kappa`` met (up to the refusal).
    t_kappa_min : float
        Plan time [s] of it.
    max_error : float
        Largest tip error [m].
    steps : int
        Loop steps run.
    seconds : float
        Wall time of the loop [s].
    q_min, q_max : tuple of float, (n,)
        Joint ranges met [rad].
    free_outside : tuple of str
        Free joints that left their URDF position limits (reported, not refused).

    """

    reason: str
    kappa_min: float
    t_kappa_min: float
    max_error: float
    steps: int
    seconds: float
    q_min: tuple
    q_max: tuple
    free_outside: tuple

    def describe(self):
        """Return a one-line summary (for the log)."""
        text = (f'nominal closed loop: {self.steps} steps of {CHECK_PERIOD * 1e3:g} ms in '
                f'{self.seconds:.2f} s, kappa >= {self.kappa_min:.4g} (at t = '
                f'{self.t_kappa_min:.3f} s), tip error <= {self.max_error * 1e3:.3g} mm')
        if self.free_outside:
            text += (f"; free joint(s) {', '.join(self.free_outside)} beyond their URDF "
                     'position limits (free: not held, not refused)')
        return text


def nominal_loop(nominal, q, qd, path, hold=CHECK_HOLD, period=CHECK_PERIOD, kd=KD,
                 gains=None, kp=KP):
    """
    Run the nominal closed loop of a plan and judge it (module notes).

    Parameters
    ----------
    nominal : SpatialArm
        The nominal model (the plant and the law's model), m = 3.
    q, qd : array_like, (n,)
        Current joint angles [rad] and rates [rad/s].
    path : SpatialCircle
        The plan's circle (plan time 0 at the first step).
    hold : float
        Part of the hold covered after the circle [s], >= 0.
    period : float
        Loop period [s] (the law's ``dt`` and the plant's RK4 step).
    kd : float
        Null-space damping [N m s/rad].
    gains : SpatialGains, optional
        Default ``SpatialGains()`` (its ``kappa_min`` the threshold).
    kp : float
        Null-space posture stiffness [N m/rad] towards the active joints' angles of ``q``
        (the controller's ``nullspace_kp``: its posture is where the task began).

    Returns
    -------
    LoopCheck

    """
    t0 = time.perf_counter()
    gains = SpatialGains() if gains is None else gains
    posture = tuple(float(np.asarray(q, dtype=float)[i]) for i in nominal.active) if kp \
        else None
    nullspace = NullSpace(kd=kd, kp=kp if kp else 0.0, posture=posture, inverse='weighted',
                          projector='dynamic')
    law = make_law('spatial', nominal, gains, nullspace=nullspace)
    plant = SpatialPlant(nominal, period, 0.0, 0, q, qd)
    steps = int(math.floor((path.duration + hold) / period + 1e-9)) + 1
    lower, upper = nominal.lower, nominal.upper
    act, free = list(nominal.active), list(nominal.passive)
    names = nominal.joint_names
    q_min = np.full(nominal.n, np.inf)
    q_max = np.full(nominal.n, -np.inf)
    kmin, t_kmin, emax = math.inf, 0.0, 0.0
    reason = ''
    k = 0
    for k in range(steps):
        t = k * period
        x = plant.q
        np.minimum(q_min, x, out=q_min)
        np.maximum(q_max, x, out=q_max)
        bad = [j for j in act if not lower[j] <= x[j] <= upper[j]]
        if bad:
            j = bad[0]
            reason = (f'the nominal closed loop takes the active joint {names[j]} to '
                      f'{x[j]:.4f} rad at t = {t:.3f} s, outside its URDF limits '
                      f'[{lower[j]:.4f}, {upper[j]:.4f}] rad')
            stiff = too_stiff(nominal, x, kd, period)
            reason += f': {stiff}' if stiff else ''
            break
        p_d, v_d, a_d = path.sample(t)
        try:
            out = law.step(x, plant.qd, p_d, v_d, a_d, period)
        except FreejointValueError as exc:
            reason = f'the nominal closed loop failed at t = {t:.3f} s: {exc}'
            break
        err = float(np.linalg.norm(out.e))
        emax = max(emax, err)
        kappa = out.internal['kappa']
        if kappa < kmin:
            kmin, t_kmin = kappa, t
        if kappa < gains.kappa_min:
            reason = (f'the nominal closed loop passes a singular posture: kappa '
                      f'{kappa:.3g} < kappa_min {gains.kappa_min:g} at t = {t:.3f} s '
                      f'(tip at {np.round(out.p, 4).tolist()} m)')
            break
        if err > TRACK_BOUND:
            reason = (f'the nominal closed loop cannot follow the path: tip error '
                      f'{err * 1e3:.3g} mm at t = {t:.3f} s (> {TRACK_BOUND * 1e3:g} mm; '
                      f'kappa {kappa:.3g}): '
                      + (too_stiff(nominal, x, kd, period) or 'out of reach or through a '
                         'singular posture'))
            break
        try:
            plant.step(out.tau, period)
        except FreejointValueError as exc:
            reason = (f'the nominal closed loop diverged at t = {t:.3f} s: '
                      + (too_stiff(nominal, x, kd, period) or str(exc)))
            break
    outside = tuple(names[j] for j in free if q_min[j] < lower[j] or q_max[j] > upper[j])
    return LoopCheck(reason, kmin, t_kmin, emax, k + 1, time.perf_counter() - t0,
                     tuple(q_min.tolist()), tuple(q_max.tolist()), outside)


def too_stiff(nominal, q, kd, period=CHECK_PERIOD):
    """
    Return why the null-space damping ``kd`` is too stiff for the arm at ``q``, or ''.

    One step of ``period`` removes ``period lambda`` of an internal mode's rate
    (``freejoint_core.arm_gains.mode_steps``); above 1 the mode reverses each step, at 2 it
    grows. The reason names the joint that moves most in the stiffest mode, the ratio, and
    that joint's effective inertia and damping of ``fj arm init``'s rule.
    """
    if not np.any(np.asarray(kd, dtype=float) > 0.0):
        return ''
    steps, joints = mode_steps(nominal, q, kd, period)
    if not steps.size or steps[0] <= 1.0 + 1e-9:      # the rule scales to 1 exactly
        return ''
    i = nominal.joint_names.index(joints[0])
    a = nominal.active.index(i)
    inertia = joint_inertia(nominal, q)[a]
    given = np.broadcast_to(np.asarray(kd, dtype=float), (nominal.r,))[a]
    return (f'null-space damping too stiff for joint {joints[0]}: nullspace_kd {given:.4g} '
            f'N m s/rad on its effective inertia {inertia:.3g} kg m^2, one {period * 1e3:g}-ms '
            f'step removes {steps[0]:.3g} x the rate of its internal mode (> 1); fj arm '
            f"init's rule gives it {float(rule([inertia])[0]):.3g} (nullspace_kd_joints)")


@dataclass(frozen=True)
class SpatialVerdict:
    """
    What :func:`check_spatial_plan` found.

    Attributes
    ----------
    reason : str
        Why the plan is refused, one line ('' : accepted).
    circle : SpatialCircle or None
        The plan's circle (None when refused before it was made).
    margin : float
        Reach margin of the circle [m] (NaN when not computed).
    rest : numpy.ndarray or None
        The free joints' rest posture found from the current one (None: refused there).
    loop : LoopCheck or None
        The nominal closed loop (None when refused before it).

    """

    reason: str
    circle: object = None
    margin: float = math.nan
    rest: object = None
    loop: object = None

    def describe(self):
        """Return a one-line summary of an accepted plan's checks (for the log)."""
        parts = [f'reach margin {self.margin:.4f} m']
        if self.rest is not None and self.loop is not None:
            parts.append(self.loop.describe())
        return '; '.join(parts)


def check_spatial_plan(nominal, q, qd, radius, duration, max_speed, max_acceleration,
                       p0=None, reach=None, normal=None, kd=KD, kp=KP):
    """
    Check a spatial plan from the arm's state (module notes); the first refusal wins.

    Parameters
    ----------
    nominal : SpatialArm
        The nominal model (m = 3).
    q, qd : array_like, (n,)
        The arm's joint angles [rad] and rates [rad/s] now (the model's order).
    radius, duration : float
        The circle [m, s].
    max_speed, max_acceleration : float
        Bounds on its peaks [m/s, m/s^2].
    p0 : array_like, (3,), optional
        Start point [m]; default the tip at ``q`` (a plan from rest). A plan after a
        finished one starts where that one holds.
    reach : float, optional
        ``arm_reach(nominal)`` if known [m].
    normal : array_like, (3,), optional
        Normal of the circle's plane (the ``plane_normal`` parameter; None or zeros: the
        vertical plane facing the robot).
    kd, kp : float
        The controller's null-space damping [N m s/rad] and posture stiffness [N m/rad]
        (``nullspace_kd``, ``nullspace_kp``: the planner's parameters of the same names).

    Returns
    -------
    SpatialVerdict

    """
    reason = spatial_bounds(radius, duration, max_speed, max_acceleration)
    if reason:
        return SpatialVerdict(reason)
    q = np.asarray(q, dtype=float)
    qd = np.asarray(qd, dtype=float)
    try:
        path = SpatialCircle(nominal.fk(q) if p0 is None else p0, radius, duration, normal)
    except FreejointValueError as exc:
        return SpatialVerdict(str(exc))
    reason, margin = reach_refusal(nominal, path, reach)
    if reason:
        return SpatialVerdict(reason, path, margin)
    rest, why = gravity_carrying_free_joint(nominal, q)
    if rest is None:
        return SpatialVerdict(why, path, margin)
    loop = nominal_loop(nominal, q, qd, path, kd=kd, kp=kp)
    return SpatialVerdict(loop.reason, path, margin, rest, loop)


class SpatialRequest:
    """
    A spatial plan whose start point is not known yet: the tip when it starts (``at``).

    Parameters
    ----------
    radius, duration : float
        The circle [m, s] (checked before).

    """

    task_dim = 3

    def __init__(self, radius, duration, normal=None):
        self.radius, self.duration = float(radius), float(duration)
        self.normal = plane_normal(normal)

    def at(self, p0):
        """Return the :class:`SpatialCircle` from ``p0`` [m], (3,)."""
        return SpatialCircle(p0, self.radius, self.duration, self.normal)

    def __repr__(self):
        return f'SpatialRequest(radius={self.radius!r}, duration={self.duration!r})'


def start_point(stream):
    """
    Return where a new spatial plan on ``stream`` starts, or why it cannot start now.

    A spatial plan starts from rest (there is no 3-D transition): where the arm is when
    nothing was streamed on this time base (or no plan runs), else where the running plan
    holds at the stream's first unpublished tick, which must be at rest there (before
    that plan's motion or after it), so that the setpoints go on without a step.

    Parameters
    ----------
    stream : stream.SetpointStream
        The planner's stream (read only).

    Returns
    -------
    (numpy.ndarray (3,) or None, str)
        ``(p0, '')``: the running plan's setpoint at the first unpublished tick;
        ``(None, '')``: from the arm's tip; ``(None, reason)``: the running plan moves.

    """
    plan = stream.plan
    if stream.fresh() or plan is None or not isinstance(plan.trajectory, SpatialCircle):
        return None, ''
    circle_ = plan.trajectory
    k = stream.next_tick
    t = 0.0 if plan.start_tick is None or k <= plan.start_tick else (
        (k - plan.start_tick) * stream.dt)
    if t < circle_.duration and t > 0.0:
        end = plan.start_tick * stream.dt_ns * 1e-9 + circle_.duration
        return None, (f'the running plan {plan.plan_id} moves until t = {end:.3f} s (ROS '
                      'time): a spatial plan starts from rest (no 3-D transition); ask '
                      'again once it holds its end point')
    return circle_.sample(t)[0], ''
