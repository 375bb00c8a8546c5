"""
Parameters of the planner node: its schema (no ROS types).

``SCHEMA`` lists every parameter once (name, default, description, range, read-only,
validator); ``freejoint_common.node_tools.NodeParameters`` declares it on the node and
validates every change with it; the node's config is the validated ``{name: value}``
dict. ``case``, ``nominal_scale`` and ``control_period`` are the entries the controller
(and the simulator) share (``freejoint_common.schema``), the arm the entries of
``freejoint_common.arm_description``; the configured circle's defaults are the core's
``CircleQuintic`` (the paper's circle). :func:`validate` checks some values alone (a
``~/plan_circle`` request). A spatial arm (``task_dim`` 3) takes ``radius``,
``duration`` and ``start_delay`` of the circle; :data:`PLANAR_ONLY` stay at their defaults.
"""

import inspect
import math

from freejoint_common.arm_description import ARM_SPECS
from freejoint_common.schema import CASE, CONTROL_PERIOD, FRAME_ID, NOMINAL_SCALE, Param
from freejoint_common.schema import nullspace_params, one_of, SCHEDULING, Schema
from freejoint_core.trajectory import CircleQuintic

_CIRCLE = {name: p.default for name, p in
           inspect.signature(CircleQuintic.__init__).parameters.items()
           if p.default is not inspect.Parameter.empty}
"""The paper's circle: the defaults of ``CircleQuintic``."""

READINESS_MODES = ('auto', 'required', 'ignore')
"""``readiness``: how the planner takes the controller's controller_readiness."""
# Parameters of the configured circle; an accepted change of any of them re-checks it.
CIRCLE_KEYS = ('centre', 'radius', 'duration', 'start_angle', 'direction', 'start_delay',
               'circles', 'rest', 'plane_normal')
# Parameters of the singularity map; an accepted change of any of them recomputes it.
MAP_KEYS = ('case', 'nominal_scale', 'resolution_deg', 'eps_d', 'singular_cells')


def _normal(value):
    """Refuse a plane normal that is not 3 finite numbers ([0, 0, 0]: the default plane)."""
    try:
        vec = [float(v) for v in value]
    except (TypeError, ValueError):
        return f'expected 3 numbers, got {value!r}'
    if len(vec) != 3 or not all(math.isfinite(v) for v in vec):
        return f'expected 3 finite numbers, got {value!r}'
    return None


def _even_steps(value):
    steps = 360.0 / float(value)
    if abs(steps - round(steps)) > 1e-9 * steps or round(steps) % 2:
        return f'360 / {value:g} must be an even integer (e.g. 0.25, 0.5, 1.0)'
    return None


def _direction(value):
    return None if value in (1, -1) else f'expected +1 or -1, got {value!r}'


def _centre(value):
    centre = list(value)
    if len(centre) != 2:
        return f'expected 2 values (x, y) in m, got {len(centre)}: {centre}'
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
               for v in centre):
        return f'expected finite numbers, got {centre}'
    return None


PARAMS = (
    CASE, NOMINAL_SCALE,
    Param('resolution_deg', 0.25,
          'Joint-space step of the singularity map (deg); 360 / value an even integer. 0.25 '
          'costs about 0.1 s. Changing it recomputes the map.', (0.1, 10.0),
          validator=_even_steps),
    Param('eps_d', 1e-7,
          'Semi-singular criterion on |det(Da Da^T)| (paper: 1e-7), > 0. Changing it '
          'recomputes the map.', (0.0, 1.0), exclusive_min=True),
    Param('singular_cells', True,
          'Map of an arm other than the paper 3-link one (freejoint_core.singularity_nlink): '
          'also flag every grid cell in which each 2 x 2 minor of Da changes sign '
          '(conservative; with more than 2 active joints the singular curves can reach every '
          'radius, and then every circle is refused); false = the paper sampled criterion '
          'alone. Changing it recomputes the map.'),
    Param('grid_resolution', 0.01, 'Cell size of the semi_singular_map OccupancyGrid (m).',
          (0.001, 0.5)),
    FRAME_ID,
    CONTROL_PERIOD,
    # >= 1: a setpoint must be out before its tick's state (0 races it); <= 1000 ticks
    # (1 s at 1 kHz; a firing's ticks go out in one `setpoints` message).
    Param('lookahead', 20,
          'Setpoints published ahead of ROS time (ticks), >= 1. Sim time: with /clock every '
          'N ticks, >= N - 1 (a smaller value is refused once N is known; found too small '
          'when N is learnt, it is raised to 2 N - 1).', (1, 1000)),
    Param('centre', list(_CIRCLE['centre']),
          'Circle centre (x, y) in m, base frame. The whole circle must stay in the usable '
          'region: distances from the base inside the reach and outside the semi-singular '
          'annuli of the map; every refusal (~/plan_circle answer, parameter set) names '
          'that region, and ~/plan_circle with execute false checks a circle without '
          'starting it.', validator=_centre),
    Param('radius', _CIRCLE['radius'], 'Circle radius (m), > 0.', (0.0, 10.0),
          exclusive_min=True),
    Param('duration', _CIRCLE['duration'], 'Time of the revolution (s), > 0.', (0.0, 3600.0),
          exclusive_min=True),
    # one revolution either way: a huge angle would lose the quintic's increments to
    # rounding (at 1e17 rad the ulp is 16 rad: the point would jump, not move)
    Param('start_angle', _CIRCLE['start_angle'],
          'Angle of the start point about the centre (rad), from +x, within one revolution '
          'either way.', (-2.0 * math.pi, 2.0 * math.pi)),
    Param('direction', _CIRCLE['direction'], '+1 counter-clockwise, -1 clockwise.',
          (-1, 1, 2), validator=_direction),
    Param('plane_normal', [0.0, 0.0, 0.0],
          "Spatial arms (task_dim 3): normal of the circle's plane in the base frame (3 "
          'values; the circle starts at the tip, its centre one radius away along the '
          "plane's first axis: freejoint_core.spatial_offline.circle_axes); [0, 0, 0] = the "
          'vertical plane facing the robot. Planar arms: leave it at [0, 0, 0].',
          validator=_normal),
    Param('circles', 1,
          'Revolutions of every plan, back to back: each but the last followed by '
          "rest; the stream is the offline circles runner's (freejoint_core.trajectory."
          'RepeatedCircle).', (1, 100000)),
    Param('rest', 0.0,
          'Rest (s) at the start point after each revolution of a plan but the last, a '
          'whole number of control periods.', (0.0, 3600.0)),
    Param('start_delay', 0.0,
          'Delay from the start of a plan to its motion (s); the start point is held '
          'meanwhile.', (0.0, 3600.0)),
    # end-effector bounds of every plan (circle and transition); the paper's circle peaks
    # at 0.471 m/s and 1.11 m/s^2
    Param('max_speed', 1.0,
          'Largest end-effector speed of a plan (m/s): a circle peaking above it is refused '
          '(paper circle: 0.471).', (0.0, 10.0), exclusive_min=True),
    Param('max_acceleration', 5.0,
          'Largest end-effector acceleration of a plan (m/s^2): a circle peaking above it is '
          'refused (paper circle: 1.11).', (0.0, 100.0), exclusive_min=True),
    Param('transition_max_duration', 60.0,
          "Longest transition (s) from the current setpoint into a new plan's start; none "
          'shorter within the bounds: the plan is refused.', (0.0, 600.0), exclusive_min=True),
    Param('settle_swing_deg', 0.0,
          'Settle gate: a plan_circle request that would start a plan is refused '
          "('settling: ...') while the free link swings more than this (deg, from the newest "
          'joint_states: freejoint_core.internal.free_link_swing) or no joint state tells; '
          '0 = off. For the arm whose last joint alone is free, with gravity; the '
          "controller's free_link_damping settles the link meanwhile.", (0.0, 180.0)),
    # feed hold and the plan's outcome (plan_goal, docs/feed_hold.md)
    Param('readiness', 'auto',
          "The controller's controller_readiness: a plan pauses (feed hold) while it says not "
          'ready, and a request to execute one (plan_circle, follow_circle) is refused. '
          "'auto': in real time a controller not heard (no publisher) is not ready, in sim "
          'time it is ready (lockstep: a controller that says nothing answers every state); '
          "'required': not heard is not ready in sim time too; 'ignore': never pause nor "
          'refuse for it (a controller without the topic).',
          validator=one_of(READINESS_MODES)),
    Param('feed_hold_time', 0.1,
          "Time (s) the plan's feed takes from full to a stop along its path when the "
          'controller turns not ready, at least 1.875 peak speed / max_acceleration (the '
          "stop's tangential deceleration within max_acceleration); the plan goes on "
          'half of it before it stands.', (0.0, 10.0), exclusive_min=True),
    Param('feed_resume_time', 0.5,
          "Time (s) the plan's feed takes from a stop back to full when the controller is "
          "ready again (at least as feed_hold_time's bound); at or above the controller's "
          'resume_time, so its blend from the arm to the held setpoint is over before full '
          'speed.', (0.0, 10.0), exclusive_min=True),
    Param('max_pause', 5.0,
          'Longest pause (s) for a not-ready controller: beyond it the plan ends '
          'PAUSED_TOO_LONG and stays stopped (a plan the controller was never ready for '
          'waits at its start without limit). A follow_circle goal may set its own.',
          (0.0, 3600.0), exclusive_min=True),
    Param('path_tolerance', 0.05,
          'Largest |end effector - setpoint| (m) while a plan moves at full feed (from '
          'feed_resume_time after a resume ramp), and from its path while it is paused: '
          'beyond it the plan stops along the path '
          'and ends PATH_TOLERANCE_VIOLATED (5 cm: an arm that far off its path is lost to '
          'the task, some 10 times the tracking bounds); 0 = not checked (the largest error '
          'is still reported). A follow_circle goal may set its own.', (0.0, 10.0)),
    Param('goal_tolerance', 0.0,
          "Largest |end effector - end point| (m) for a plan's success, within "
          "goal_time_tolerance of its end; 0 = success at the plan's end.", (0.0, 10.0)),
    Param('goal_time_tolerance', 1.0,
          "Time (s) after a plan's end to come within goal_tolerance.", (0.0, 3600.0)),
    nullspace_params(20.0, 10.0, read_only=False, role=(
        "Spatial arms: the controller's parameter, for the plan's nominal closed loop (give "
        'both nodes the same values: fj arm init writes them into both files; planar arms: '
        "not used; 20 and 10 = the shipped arms'). The controller's: ")),
    Param('autostart', True,
          'Start the configured circle at activation and after every accepted change of its '
          'parameters.'),
    ARM_SPECS,
    SCHEDULING,
)


def _check_rest(values):
    """Refuse a rest (or a revolution) that is not a whole number of control periods."""
    from freejoint_core.errors import FreejointValueError
    from freejoint_core.trajectory import RepeatedCircle
    if values['circles'] == 1 and values['rest'] == 0.0:
        return None         # one revolution: the circle itself, any duration
    try:
        RepeatedCircle(CircleQuintic(duration=values['duration']), values['circles'],
                       values['rest'], values['control_period'])
    except FreejointValueError as exc:
        return str(exc)
    return None


PLANAR_ONLY = ('centre', 'start_angle', 'direction', 'circles', 'rest')
"""Circle parameters a spatial arm's plan does not take (its circle starts at the tip)."""


def _check_spatial(values):
    """Refuse planar-only circle parameters for a spatial arm, and the converse."""
    if values.get('task_dim', 2) != 3:
        if list(values['plane_normal']) != DEFAULTS['plane_normal']:
            return (f"plane_normal: a spatial arm's (task_dim 3); a planar arm's circle lies "
                    f"in its plane: leave it at {DEFAULTS['plane_normal']!r}, got "
                    f"{list(values['plane_normal'])!r}")
        return None
    for name in PLANAR_ONLY:
        value = values[name]
        if (list(value) if isinstance(value, (list, tuple)) else value) != DEFAULTS[name]:
            return (f'{name}: does not apply to a spatial arm (task_dim 3: one revolution '
                    'of the circle from the tip, in the plane of plane_normal, '
                    f'freejoint_planner.spatial_planning); leave it at {DEFAULTS[name]!r}, '
                    f'got {values[name]!r}')
    return None


SCHEMA = Schema(PARAMS, (_check_rest, _check_spatial))
SPECS = SCHEMA.params
DEFAULTS = SCHEMA.defaults()
LOOKAHEAD_MAX = SCHEMA['lookahead'].bounds[1]
"""Largest ``lookahead`` (ticks)."""


def validate(cfg):
    """
    Return why some planner parameter values are invalid, or '' if they are valid.

    Parameters
    ----------
    cfg : dict
        Parameter name -> value (only the names present are checked; ``centre`` a
        sequence, ``direction`` an int, ...).

    Returns
    -------
    str
        The first problem found, naming the parameter, or ''.

    """
    return SCHEMA.reason(cfg) or ''
