"""
The planner's configuration, singularity map and path check (plain Python, no ROS).

The math is ``freejoint_core``'s: ``singularity_nlink.arm_region`` (the paper's 3-link map
``singularity.det_map`` / ``semi_singular`` for the paper's arm, the general batched map for
any other planar arm) and ``singularity.check_path`` (paper, Sec. 3.2) on the nominal arm
``table1(case).scaled(nominal_scale)`` and ``trajectory.CircleQuintic``. This module
bundles the map with what was computed from it, and samples a circle densely enough for
``check_path``; the node's parameters are its schema, ``freejoint_planner.params``.
"""

from dataclasses import dataclass, replace
import functools
import math
import time

from freejoint_core.arm import ArmModel, table1
from freejoint_core.control import Gains
from freejoint_core.errors import FreejointValueError
from freejoint_core.failure import assess_passive_set, CANNOT_TRACK, M_TASK
from freejoint_core.internal import free_link_swing
from freejoint_core.singularity import check_path
from freejoint_core.singularity_nlink import arm_region
from freejoint_core.trajectory import circle_peaks, CircleQuintic, plan_transition
from freejoint_core.trajectory import transition_limits
import numpy as np

# Largest arc length (m) between the points of a circle handed to check_path.
CHECK_STEP = 5e-4
AT_START = 1e-6
"""An arm at rest this close (m) to a circle's start (and no farther than the circle's own
largest step per tick) starts the circle there at once: no transition (the IK round-off of
a simulator started on the circle's start, an encoder's resolution)."""
JOIN_START, JOIN_WAIT, JOIN_REFUSED = 'start', 'wait', 'refused'
"""What :func:`join_from_arm` tells the node to do with a plan from rest."""


def circle_bounds(circle, model, max_speed, max_acceleration):
    """
    Return why a circle exceeds what the arm and the bounds allow, or '' if it does not.

    The nominal arm's reach annulus ``[r_min, r_max]`` gives the largest radius,
    ``(r_max - r_min) / 2``, and the farthest centre, ``r_max`` (the semi-singular check
    refines both); ``max_speed`` / ``max_acceleration`` bound the circle's peak speed and
    acceleration (``freejoint_core.trajectory.circle_peaks``), i.e. a shortest duration.
    The reason names the parameter (``radius``, ``centre``, ``duration``) to change.
    """
    lo, hi = model.region.reach
    if circle.radius > (hi - lo) / 2.0:
        return (f'radius: {circle.radius:g} m exceeds the largest circle the reach annulus '
                f'[{lo:.6g}, {hi:.6g}] m of the arm holds, {(hi - lo) / 2.0:.6g} m')
    dist = float(np.hypot(*circle.centre))
    if dist > hi:
        return (f'centre: ({circle.centre[0]:g}, {circle.centre[1]:g}) m is {dist:.6g} m from '
                f'the base, beyond the reach {hi:.6g} m')
    speed, acc = circle_peaks(circle)
    if speed > max_speed:
        return (f'duration: {circle.duration:g} s for radius {circle.radius:g} m peaks at '
                f'{speed:.6g} m/s, above max_speed {max_speed:g} m/s (duration >= '
                f'{circle.duration * speed / max_speed:.6g} s)')
    if acc > max_acceleration:
        return (f'duration: {circle.duration:g} s for radius {circle.radius:g} m peaks at '
                f'{acc:.6g} m/s^2, above max_acceleration {max_acceleration:g} m/s^2 '
                f'(duration >= {circle.duration * math.sqrt(acc / max_acceleration):.6g} s)')
    return ''


def make_circle(cfg):
    """Return the ``CircleQuintic`` of the configured circle in ``cfg`` (validated before)."""
    return CircleQuintic(centre=tuple(float(v) for v in cfg['centre']),
                         radius=float(cfg['radius']), duration=float(cfg['duration']),
                         start_angle=float(cfg['start_angle']),
                         direction=int(cfg['direction']))


def circle_check_points(circle, max_step=CHECK_STEP):
    """
    Return points of the circle for ``check_path``, shape (N, 2), m.

    Evenly spaced in angle with at most ``max_step`` of arc between neighbours, plus the
    circle's nearest and farthest points from the base: the semi-singular region is a
    union of annuli about the base, so the path's radial distance to it is smallest at
    one of those two points whenever the path avoids it, and the margin is exact.

    Parameters
    ----------
    circle : CircleQuintic
        The path.
    max_step : float
        Largest arc length between sampled points (m), > 0.

    Returns
    -------
    numpy.ndarray, shape (N, 2)

    """
    num = max(721, int(math.ceil(2.0 * math.pi * circle.radius / max_step)) + 1)
    pts = circle.points(num)
    centre = circle.centre
    dist = float(np.hypot(centre[0], centre[1]))
    if dist > 0.0:
        u = centre / dist
        pts = np.vstack((pts, centre - circle.radius * u, centre + circle.radius * u))
    return pts


@dataclass(frozen=True)
class SingularityModel:
    """
    A singularity map of the nominal arm and the region computed from it.

    Attributes
    ----------
    case : str
    nominal_scale : float
    resolution_deg : float
    eps_d : float
    nominal : ArmParams
        ``table1(case).scaled(nominal_scale)``.
    region : SemiSingularRegion
        ``arm_region(nominal, resolution_deg, eps_d)`` (``freejoint_core.singularity_nlink``).
    seconds : float
        Wall time the computation took (s).

    """

    case: str
    nominal_scale: float
    resolution_deg: float
    eps_d: float
    nominal: object
    region: object
    seconds: float

    @functools.cached_property
    def arm(self):
        """Return the nominal arm's ``ArmModel`` (:func:`end_effector`'s kinematics), once."""
        return ArmModel(self.nominal)

    def check(self, circle):
        """Return the ``PathCheck`` of a circle against this region (and the reach)."""
        return check_path(self.region, circle_check_points(circle))

    def check_points(self, points):
        """Return ``(ok, margin, reason)`` of path points, shape (N, 2) m (transitions)."""
        check = check_path(self.region, points)
        return check.ok, check.margin, check.reason

    def describe(self):
        """Return a one-line summary of the region (for the log)."""
        lo, hi = self.region.reach
        bands = ', '.join(f'[{a:.4f}, {b:.4f}]' for a, b in self.region.intervals) or 'none'
        # no case: the map holds no gravity (Da = J M^-1 B); the node logs the arm with its
        # gravity vector beside it
        return (f'semi-singular annuli {bands} m in reach [{lo:.4f}, {hi:.4f}] m '
                f'(nominal_scale {self.nominal_scale:g}, '
                f'resolution {self.resolution_deg:g} deg, eps_d {self.eps_d:g})')

    def usable(self):
        """
        Return the usable region in one line: the distances from the base a path may take.

        The reach annulus minus the semi-singular annuli (both about the base), e.g.
        ``usable: 0.0142 <= |p| <= 0.3528 m from the base (a path must stay within one
        of these annuli)``; what a ``~/plan_circle`` refusal names.
        """
        lo, hi = self.region.reach
        free, start = [], lo
        for a, b in np.asarray(self.region.intervals, dtype=float).reshape(-1, 2):
            if a > start:
                free.append((start, min(a, hi)))
            start = max(start, b)
        if start < hi:
            free.append((start, hi))
        if not free:
            return 'usable: none (the semi-singular annuli cover the reach)'
        return 'usable: ' + ' or '.join(f'{a:.4f} <= |p| <= {b:.4f} m' for a, b in free) + (
            ' from the base (a path must stay within one of these annuli)' if len(free) > 1
            else ' from the base')


def compute_model(case, nominal_scale, resolution_deg, eps_d, cells=True, arm=None):
    """
    Compute the singularity map and semi-singular region of the nominal arm.

    Parameters
    ----------
    case : str
        'horizontal' or 'vertical' (the map is the same for both: ``Da`` has no gravity).
    nominal_scale : float
        Nominal model = Table I scaled by this (paper: 0.7).
    resolution_deg : float
        Joint-space grid step (deg); 0.25 takes about 0.1 s.
    eps_d : float
        Criterion on ``|det(Da Da^T)|`` (paper: 1e-7).
    cells : bool
        ``arm_region``'s conservative cell test (arms other than the paper's 3-link one;
        False: the paper's sampled criterion alone).
    arm : ArmParams, optional
        The real arm (e.g. of a URDF, ``freejoint_common.arm_description``); default
        ``table1(case)``.

    Returns
    -------
    SingularityModel

    """
    start = time.perf_counter()
    nominal = (table1(case) if arm is None else arm).scaled(nominal_scale)
    # any planar arm; the paper's: closed form
    region = arm_region(nominal, resolution_deg, eps_d, cells=bool(cells))
    return SingularityModel(case=case, nominal_scale=float(nominal_scale),
                            resolution_deg=float(resolution_deg), eps_d=float(eps_d),
                            nominal=nominal, region=region,
                            seconds=time.perf_counter() - start)


# Largest semi_singular_map a side (cells): 2000 x 2000 int8 is a 4 MB message, and
# rasterising it takes about 20 float arrays of that many cells.
GRID_MAX_CELLS = 2000


def grid_bound(reach, cell):
    """Return why ``grid_resolution`` = ``cell`` makes the map too large, or ''."""
    side = 2 * math.ceil(float(reach[1]) / cell - 1e-9)
    if side > GRID_MAX_CELLS:
        return (f'grid_resolution: {cell:g} m gives a semi_singular_map of {side} x {side} '
                f'cells for the reach {reach[1]:.6g} m, above {GRID_MAX_CELLS} a side '
                f'(grid_resolution >= {2.0 * reach[1] / GRID_MAX_CELLS:.6g} m)')
    return ''


def grid_extent(reach, cell):
    """
    Return the occupancy grid's ``(x_min, x_max, y_min, y_max)`` (m) for a reach annulus.

    A square about the base whose half side is the arm's reach ``r_max`` rounded up to a
    whole number of cells, so the grid has ``2 ceil(r_max / cell)`` cells a side.
    """
    half = math.ceil(float(reach[1]) / cell - 1e-9) * cell
    return (-half, half, -half, half)


def joint_indices(joint_names, names):
    """
    Return where each of ``joint_names`` sits in a joint state's ``names``, None if missing.

    Parameters
    ----------
    joint_names : sequence of str, (n,)
        The arm's joints, base to tip (the model's order).
    names : sequence of str
        ``JointState.name`` (any order, extra joints allowed).

    Returns
    -------
    list of int or None

    """
    where = {name: i for i, name in enumerate(names)}
    try:
        return [where[name] for name in joint_names]
    except KeyError:
        return None


def end_effector(model, joint_names, names, positions, offsets=()):
    """
    Return the end effector's position (x, y) of a joint state, None if a joint is missing.

    Parameters
    ----------
    model : SingularityModel
        Its nominal arm gives the kinematics (lengths are exact: only masses are scaled).
    joint_names : sequence of str, (n,)
        The arm's joints, base to tip.
    names, positions : sequence
        ``JointState.name`` and ``.position`` (rad).
    offsets : sequence of float, (n,) or ()
        Added to the measured angles they give the model's [rad]
        (``NodeArm.joint_offsets``; () none).

    Returns
    -------
    numpy.ndarray, shape (2,), m, or None
        None also when a position is missing or not finite.

    """
    index = joint_indices(joint_names, names)
    if index is None or max(index, default=-1) >= len(positions):
        return None
    q = np.array([positions[i] for i in index], dtype=float)
    if not np.all(np.isfinite(q)):
        return None
    if offsets:
        q = q + np.asarray(offsets, dtype=float)
    return model.arm.fk(q)


def settle_gate_refusal(params):
    """
    Return why the settle gate cannot judge this arm ('' : it can).

    The gate judges the swing of a free last link under gravity
    (``freejoint_core.internal.free_link_swing``): the arm's last joint alone is passive,
    gravity is on and the link's effective inertia about its joint is positive.

    Parameters
    ----------
    params : freejoint_core.arm.ArmParams
        The nominal arm.

    Returns
    -------
    str

    """
    if tuple(params.passive) != (params.n - 1,):
        return (f'settle_swing_deg: the settle gate needs the arm whose last joint alone is '
                f'free, this one has passive joints {list(params.passive)}')
    try:
        free_link_swing(params, [0.0] * params.n, [0.0] * params.n)
    except FreejointValueError:
        return ('settle_swing_deg: the settle gate needs gravity (a free link with no '
                'restoring force has no swing to settle: the horizontal case)')
    return ''


def swing_deg(model, joint_names, names, positions, velocities, offsets=()):
    """
    Return the free last link's swing amplitude [deg] of a joint state, None if unknown.

    Parameters
    ----------
    model : SingularityModel
        Its nominal arm: the swing is the nominal model's estimate (the 70 % model of the
        paper's vertical arm, its com scaled too, puts a real 14.2-deg swing at 18.2 deg).
    joint_names : sequence of str, (n,)
        The arm's joints, base to tip.
    names, positions, velocities : sequence
        ``JointState.name``, ``.position`` [rad], ``.velocity`` [rad/s].
    offsets : sequence of float, (n,) or ()
        As :func:`end_effector`.

    Returns
    -------
    float in [0, 180] or None
        None when a joint, a position or a velocity is missing or not finite.

    """
    state = joint_state(joint_names, names, positions, velocities, offsets)
    return None if state is None else math.degrees(free_link_swing(model.nominal, *state))


def joint_state(joint_names, names, positions, velocities, offsets=()):
    """
    Return the arm's joint angles (the model's) and velocities in its order, None if unknown.

    Parameters
    ----------
    joint_names : sequence of str, (n,)
        The arm's joints, base to tip.
    names, positions, velocities : sequence
        ``JointState.name``, ``.position`` [rad], ``.velocity`` [rad/s].
    offsets : sequence of float, (n,) or ()
        As :func:`end_effector`.

    Returns
    -------
    tuple of list of float, ((n,), (n,)) or None
        None when a joint, a position or a velocity is missing or not finite.

    """
    index = joint_indices(joint_names, names)
    if index is None or max(index, default=-1) >= min(len(positions), len(velocities)):
        return None
    q = [float(positions[i]) for i in index]
    qd = [float(velocities[i]) for i in index]
    if not all(map(math.isfinite, q + qd)):
        return None
    if offsets:
        q = [a + b for a, b in zip(q, offsets)]
    return q, qd


ASSESS_HORIZON = 2.0
"""[s] How far :func:`after_failure` simulates the internal motion of the arm a failure
left (``freejoint_core.failure.assess_passive_set``): the paper's arm with joint 2 free
runs away within it on the paper's circle (vertical: in 1 s, horizontal: in 1-1.5 s), as
the controller's check over the whole path finds; 0.1-0.25 s of the planner's time."""


@dataclass(frozen=True)
class FailedArm:
    """
    What the planner plans for after a reported joint failure (:func:`after_failure`).

    Attributes
    ----------
    arm : ArmParams or None
        The real arm with the new passive set (None: the map's arm stays).
    refusal : str
        Why no plan is accepted from now on ('' : plans are checked on the map of ``arm``).
    note : str
        The line to log.

    """

    arm: object
    refusal: str
    note: str


def after_failure(arm, joint_names, name, state=None, trajectory=None, nominal_scale=0.7,
                  gains=None):
    """
    Return the arm the planner plans for once the joint ``name`` failed.

    The failed joint joins the passive set.  Fewer active joints than the task has
    (``r < m``) or an internal motion that runs away or grows (the controller's own
    check, ``freejoint_core.failure.assess_passive_set`` on the nominal arm from the
    arm's state along ``trajectory`` for :data:`ASSESS_HORIZON`) refuse every plan from
    then on, saying why; otherwise the node recomputes its map for the new arm and checks
    plans on it.  Without a state the internal motion is not assessed (the note says so).

    Parameters
    ----------
    arm : ArmParams
        The real arm the planner's map is of (its passive set: the joints free so far).
    joint_names : sequence of str, (n,)
        The arm's joints, base to tip.
    name : str
        The joint reported failed (``joint_failures``' ``data``).
    state : tuple of array_like, ((n,), (n,)), optional
        Joint angles [rad] and velocities [rad/s] of the arm now, base to tip.
    trajectory : CircleQuintic, optional
        The path to assess the internal motion along; default the paper's circle.
    nominal_scale : float
        The nominal model's scale of the real arm (the map's).
    gains : freejoint_core.control.Gains, optional
        The law's gains (its K and Lambda keep the simulated end effector on the path);
        default the paper's.

    Returns
    -------
    FailedArm

    """
    names = list(joint_names)
    if name not in names:
        return FailedArm(None, '', f'joint failure notice for {name!r} ignored: not a joint '
                         f'of {names}')
    j = names.index(name)
    if j in arm.passive:
        return FailedArm(None, '', f'{name} failed: it is free in the arm the map is of '
                         'already; plans are checked as before')
    passive = tuple(sorted(set(arm.passive) | {j}))
    free = [names[i] for i in passive]
    if arm.n - len(passive) < M_TASK:
        why = (f'{name} failed: {arm.n - len(passive)} active joint(s) left for the '
               f'{M_TASK}-D task (passive {free}): no plan can be tracked')
        return FailedArm(None, why, why)
    new = replace(arm, passive=passive)
    if state is None:
        return FailedArm(new, '', f'{name} failed: plans are checked on the map of the arm '
                         f'with passive {free} (its internal motion not assessed: no joint '
                         'state)')
    gains = gains or Gains()
    verdict = assess_passive_set(new.scaled(nominal_scale), new.passive, *state,
                                 trajectory or CircleQuintic(), 0.0, horizon=ASSESS_HORIZON,
                                 gains=(gains.K[0], gains.Lambda[0]))
    if verdict.verdict == CANNOT_TRACK:
        why = f'{name} failed: the arm with passive {free} cannot track: {verdict.reason}'
        return FailedArm(new, why, why)
    return FailedArm(new, '', f'{name} failed: plans are checked on the map of the arm with '
                     f'passive {free} (its internal motion assessed over {ASSESS_HORIZON:g} s: '
                     'held)')


READY, SETTLING, FAILED = 'ready', 'settling', 'cannot_plan'
"""The planner's states on ``/diagnostics`` (:func:`planner_status`)."""


def planner_status(failure_refusal, pending, settling):
    """
    Return the planner's state and its one-line message for ``/diagnostics``.

    Parameters
    ----------
    failure_refusal : str
        Why no plan is accepted since a joint failed ('' : none).
    pending : sequence of str
        Joints reported failed, assessed at the next plan request.
    settling : str or None
        The settle gate's reason ('settling: ...'), '' when settled, None when the gate is
        off.

    Returns
    -------
    tuple of (str, str)
        ``(FAILED | SETTLING | READY, message)``: ``FAILED`` while no plan can be tracked,
        ``SETTLING`` while the free link swings beyond the gate (the rest between
        tasks), else ``READY`` (saying what is pending or that the link settled).

    """
    if failure_refusal:
        return FAILED, failure_refusal
    if settling:
        return SETTLING, settling
    message = 'ready for a plan'
    if settling == '':
        message += ': the free link settled'
    if pending:
        message += (f"; {', '.join(pending)} reported failed: assessed at the next plan "
                    'request')
    return READY, message


def assess_failure(arm, joint_names, name, state, circle, nominal_scale, map_values):
    """
    Return :func:`after_failure`'s ``FailedArm`` and the map of its arm (None: none needed).

    ``map_values``: the planner's ``MAP_KEYS`` values (``compute_model``'s arguments); the
    other parameters are :func:`after_failure`'s.
    """
    out = after_failure(arm, joint_names, name, state, circle, nominal_scale)
    model = None
    if out.arm is not None and not out.refusal:
        model = compute_model(*map_values, arm=out.arm)
    return out, model


def transition_from_rest(position, circle, model, dt, max_duration, bounds=None):
    """
    Plan how a plan from rest reaches its circle's start from the arm's end effector.

    The transition starts at rest at ``position`` and ends at rest on the circle's start,
    held to the circle's own peak speed, acceleration and largest per-tick step (and to
    ``bounds``), its path checked against the region. An arm within ``AT_START`` (and one
    circle step) of the start needs none: the circle starts at once.

    Parameters
    ----------
    position : array_like, shape (2,)
        The arm's end effector (m).
    circle : CircleQuintic
        The plan's circle.
    model : SingularityModel
        Region the transition's path is checked against.
    dt : float
        Control period (s).
    max_duration : float
        Longest transition (s).
    bounds : tuple of float, optional
        ``(max_speed, max_acceleration)`` (m/s, m/s^2).

    Returns
    -------
    tuple
        ``(reason, choice)``: ``reason`` '' if the plan may start (``choice.segment``
        the transition, None if none is needed), else why not.

    """
    p0 = np.asarray(position, dtype=float)
    limits = transition_limits(circle, dt, (0.0, 0.0), (0.0, 0.0))
    if bounds is not None:
        limits = (min(limits[0], bounds[0]), min(limits[1], bounds[1]), limits[2])
    start = np.array(circle.sample_tuple(0.0)[:2])
    if float(np.hypot(*(p0 - start))) <= min(AT_START, limits[2]):
        p0 = start
    choice = plan_transition(p0, (0.0, 0.0), (0.0, 0.0), circle, dt,
                             max_duration=max_duration, path_check=model.check_points,
                             limits=limits)
    if not choice.ok:
        return (f'no safe transition from the arm at ({p0[0]:.4f}, {p0[1]:.4f}) m into the '
                f"circle's start ({start[0]:.4f}, {start[1]:.4f}) m: {choice.reason}"), choice
    return '', choice


def join_from_arm(plan, stream, model, position, wait_reason, max_duration, bounds=None):
    """
    Decide how a plan from rest starts: from where the arm is, wait for it, or not at all.

    Called before the stream's ``advance`` while the plan has not started and its join is
    open (``plan.joined`` false: accepted with nothing streamed and the arm's position not
    known then, or restarted on a new time base). Sets the plan's transition (anchored at
    its first tick) and ``joined`` when it may start.

    Parameters
    ----------
    plan : Plan
        The stream's plan (not started).
    stream : SetpointStream
        Its stream (``dt``).
    model : SingularityModel
        Region and kinematics.
    position : array_like, shape (2,), or None
        The arm's end effector (m), None if not known.
    wait_reason : str or None
        Without a position: why waiting for it is right (a joint state publisher is
        there, no state yet), or None: start at the circle's start as is (no arm known).
    max_duration : float
        Longest transition (s).
    bounds : tuple of float, optional
        ``(max_speed, max_acceleration)``.

    Returns
    -------
    tuple of (str, str)
        ``(action, text)``: ``JOIN_START`` (text: how it starts, for the log),
        ``JOIN_WAIT`` (text: ``wait_reason``) or ``JOIN_REFUSED`` (text: why; the caller
        drops the plan).

    """
    if plan.joined:
        return JOIN_START, ''
    if position is None:
        if wait_reason:
            return JOIN_WAIT, wait_reason
        plan.joined = True
        return JOIN_START, ("starts at its start point: the arm's position is not known "
                            '(no joint_states): a step if the arm is elsewhere')
    reason, choice = transition_from_rest(position, plan.trajectory, model, stream.dt,
                                          max_duration, bounds)
    if reason:
        return JOIN_REFUSED, reason
    plan.set_transition(choice.segment, choice.ticks)
    plan.joined = True
    return JOIN_START, describe_join(position, choice)


def describe_join(position, choice):
    """Return how a plan from rest starts, for the log (``choice``: its TransitionChoice)."""
    where = f'the arm at ({position[0]:.4f}, {position[1]:.4f}) m'
    if choice.segment is None:
        return f'starts at its start point ({where}, on it)'
    return (f'transition of {choice.ticks} ticks from {where} (peaks '
            f'{choice.peak_speed:.4g} m/s, {choice.peak_acceleration:.4g} m/s^2, '
            f'{choice.max_step * 1e3:.4g} mm per tick of at most {choice.limits[2] * 1e3:.4g}; '
            f'path margin {choice.margin:.4f} m) into its start')


def prepare_transition(stream, circle, model, max_duration, bounds=None, arm=None):
    """
    Decide how a newly accepted ``circle`` joins the stream: directly or by a transition.

    Parameters
    ----------
    stream : SetpointStream
        The planner's stream (read only).
    circle : CircleQuintic
        The new plan's circle (checked against the region before).
    model : SingularityModel
        Region and reach the transition's path is checked against.
    max_duration : float
        Longest transition (s).
    bounds : tuple of float, optional
        ``(max_speed, max_acceleration)`` (m/s, m/s^2): caps on the transition's limits
        (the circle's own peaks, or the start state's when faster).
    arm : array_like, shape (2,), optional
        The arm's end effector (m), if known: a plan from rest (nothing streamed yet on
        this time base) starts there (:func:`transition_from_rest`).

    Returns
    -------
    tuple
        ``(reason, choice, tick)``: ``reason`` '' if the plan may start, else why not;
        ``choice`` the ``TransitionChoice`` (None when nothing streamed yet on this time
        base and ``arm`` is None: the join is decided when the plan starts,
        :func:`join_from_arm`); ``tick`` the transition's first tick (the stream's first
        unpublished tick), None for a plan from rest (its own first tick).

    """
    pending = stream.pending()
    if pending is None:
        if arm is None:
            return '', None, None
        reason, choice = transition_from_rest(arm, circle, model, stream.dt, max_duration,
                                              bounds)
        return reason, choice, None
    k, state = pending
    busy = stream.in_transition(k)
    if busy is not None:
        end = busy.transition_end() * stream.dt_ns * 1e-9
        left = (busy.transition_end() - k) * stream.dt
        return (f'the transition into plan {busy.plan_id} runs until t = {end:.3f} s (ROS '
                f'time, {left:.3f} s from the first unpublished setpoint); a transition is '
                'never cut short (its circle is reached): try again after it'), None, None
    px, py, vx, vy, ax, ay = state
    limits = transition_limits(circle, stream.dt, (vx, vy), (ax, ay))
    if bounds is not None:
        limits = (min(limits[0], bounds[0]), min(limits[1], bounds[1]), limits[2])
    choice = plan_transition((px, py), (vx, vy), (ax, ay), circle, stream.dt,
                             max_duration=max_duration, path_check=model.check_points,
                             limits=limits)
    if not choice.ok:
        return f'no safe transition from the current setpoint: {choice.reason}', choice, None
    return '', choice, (k if choice.segment is not None else None)
