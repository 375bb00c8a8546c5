"""
Parameters of the controller node: its schema (no ROS types).

``SCHEMA`` lists every parameter once (name, default, description, range, read-only,
validator), the cross-parameter checks and :func:`build` of the :class:`Config` the node
reads; ``freejoint_common.node_tools.NodeParameters`` declares it on the node and applies
it at start-up and in the set-parameters callback. The gains' defaults are the core's
(``freejoint_core.control.Gains``, whose field names are these parameter names), the
nominal model's ``case`` / ``nominal_scale`` the entries the planner shares
(``freejoint_common.schema``). ``SPECS`` / :func:`build_config` are the entries and the
validated build (``FreejointValueError`` naming the parameter).

"""

from dataclasses import dataclass, field
import math

from freejoint_common.arm_description import ARM_JOINT_NAMES, arm_joint_names, ARM_JOINTS
from freejoint_common.arm_description import ARM_SPECS, resolve_arm
from freejoint_common.schema import above, CASE, CONTROL_PERIOD, EXECUTOR
from freejoint_common.schema import LoopConfig, NOMINAL_SCALE, nullspace_params, one_of
from freejoint_common.schema import Param
from freejoint_common.schema import SCHEDULING, Schema, unique_names
from freejoint_control.readiness import realtime_epsilon
from freejoint_core.arm import ArmModel, ArmParams
from freejoint_core.circles import HORIZONTAL_SETTLE, MODULATION
from freejoint_core.control import Gains, H_FORMS
from freejoint_core.errors import FreejointValueError
from freejoint_core.failure import DEFAULT_K_O, DEFAULT_MARGIN, DEFAULT_TICKS
from freejoint_core.laws import gain_schema, LAWS
from freejoint_core.urdf_offline import nominal_model

SPATIAL_LAW = 'spatial'
"""The law of a spatial arm (``freejoint_core.spatial_law.SpatialControlLaw``)."""
ON_STALE = ('hold', 'zero')
DELAY_COMPENSATION = ('off', 'predict')
FAILURE_MODES = ('off', 'notice', 'detect')
READINESS_ACTIONS = ('brake', 'damp', 'hold')
GAIN_MAX = {'K': 1e4, 'Lambda': 1e4, 'R': 1e3, 'Gamma': 1e3, 'sigma': 1e3}
"""Upper bounds of the gain vectors (K, Lambda in 1/s; beyond them the law is meaningless
at any control rate this node runs; (K + Lambda) * control_period <= 1 is checked too)."""
THETA_MAX_MAX = 1e6
"""Upper bound of theta_max (and so of theta0)."""
_DEFAULT = Gains()


def _floats(name, value):
    """Return ``value`` as a tuple of finite floats, or raise naming ``name``."""
    try:
        vals = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a list of numbers, got {value!r}') from None
    if not all(math.isfinite(v) for v in vals):
        raise FreejointValueError(f'{name}: values must be finite, got {list(vals)}')
    return vals


def _gain(name):
    """Return the validator of the ``Gains`` field ``name`` (the core's check, GAIN_MAX)."""
    upper = GAIN_MAX.get(name)

    def check(value):
        given = tuple(value) if isinstance(value, list) else value
        if name in TASK_GAINS and isinstance(given, tuple):
            Gains(**{name: given, 'task_dim': max(1, len(given))})   # the size: _check_task
        else:
            Gains(**{name: given})
        if upper is not None and any(v > upper for v in value):
            return f'values must be <= {upper:g}, got {tuple(float(v) for v in value)}'
        return None
    return check


def _h_form(value):
    return None if value in H_FORMS else f"expected 'sum' or 'sat', got {value!r}"


_LIMIT_DEFAULTS = {'effort_limits': (300.0, 200.0),
                   'joint_position_lower': (-1000.0,) * 3,
                   'joint_position_upper': (1000.0,) * 3,
                   'joint_velocity_limit': (100.0,) * 3}
WIDE = 1000.0
"""[rad, rad/s] A spatial arm's plausibility bounds of a free joint (not driven: its rated
limits are not the controller's to enforce) and of a continuous joint's position."""


def arm_limits(values, name):
    """
    Return the per-joint limit list ``name`` in use: as given, or a spatial arm's URDF's.

    Left at its default (the paper arm's), ``effort_limits`` of a spatial arm is its URDF's
    efforts of ``joints``; ``joint_position_lower`` / ``upper`` and ``joint_velocity_limit``
    its URDF's of ``joint_names``, a free joint's and a continuous joint's position bounds
    and a free joint's speed bound +-:data:`WIDE`. A planar arm keeps the defaults.
    """
    given = tuple(float(v) for v in values[name])
    if given != _LIMIT_DEFAULTS[name]:
        return given
    try:
        arm = resolve_arm(values)
    except (FreejointValueError, KeyError):
        return given
    spatial = arm.spatial
    if spatial is None:
        return given
    try:
        joint_names, joints = arm_joint_names(values, arm)
    except KeyError:                    # declared before joint_names / joints (follows)
        joint_names, joints = arm.joint_names, arm.active_names
    index = spatial.joint_names.index
    if name == 'effort_limits':
        return tuple(float(spatial.effort[index(j)]) for j in joints if j in spatial.joint_names)
    free = {spatial.joint_names[i] for i in spatial.passive}
    out = []
    for joint in joint_names:
        if joint not in spatial.joint_names:
            return given                # the check names the mismatch
        i = index(joint)
        wide = joint in free or (name != 'joint_velocity_limit'
                                 and joint in spatial.continuous)
        limit = {'joint_position_lower': spatial.lower[i],
                 'joint_position_upper': spatial.upper[i],
                 'joint_velocity_limit': spatial.velocity[i]}[name]
        out.append((-WIDE if name == 'joint_position_lower' else WIDE) if wide
                   else float(limit))
    return tuple(out)


def _follows_limits(name):
    """Return the ``follows`` of a limit list: the arm's, from the other values declared."""
    def follows(values):
        try:
            return list(arm_limits(dict(values, **{name: _LIMIT_DEFAULTS[name]}), name))
        except KeyError as exc:     # a parameter it reads is not declared yet
            raise FreejointValueError(f'{name}: follows {exc}') from None
    return follows


def _positive_floats(name):
    def check(value):
        vals = _floats(name, value)
        if any(not v > 0.0 for v in vals):
            return f'values must be > 0, got {list(vals)}'
        return None
    return check


def _theta_max(value):
    vals = _floats('theta_max', value)
    if len(vals) != 5 or any(not 0.0 < v <= THETA_MAX_MAX for v in vals):
        return f'expected 5 values in (0, {THETA_MAX_MAX:g}], got {list(vals)}'
    return None


# Joint failures (freejoint_control/failures.py); defaults: freejoint_core.failure.
FAILURE_PARAMS = (
    Param('joint_failures', 'off',
          "'off': no failure handling (the paper's law exactly); 'notice': a notice on "
          'joint_failures (std_msgs/String, the joint name) switches the law at the next '
          "tick; 'detect': notices and the momentum residual (and the effort the JointState "
          'reports, with failure_use_effort) detect a joint that lost its torque',
          read_only=True, validator=one_of(FAILURE_MODES)),
    Param('failure_observer_gain', DEFAULT_K_O,
          'gain K_O [1/s] of the momentum observer (its bandwidth); K_O * control_period < 2',
          (1e-3, 1e5), read_only=True, validator=above(0.0)),
    Param('failure_margin', DEFAULT_MARGIN,
          'a joint is flagged when |r_i| > failure_margin x its fault-free level '
          '(freejoint_core.failure.DEFAULT_LEVELS, docs/failures.md)', (1e-3, 1e3),
          read_only=True, validator=above(0.0)),
    Param('failure_ticks', DEFAULT_TICKS,
          'consecutive ticks over the threshold before a joint is flagged', (1, 10000),
          read_only=True),
    Param('failure_use_effort', True,
          "detect: also compare the command with the JointState's effort (a failed joint "
          'reads 0) when the state has one per joint', read_only=True),
    nullspace_params(),
)

# The free link's damping (r = m; freejoint_core.laws.FreeLinkDampedLaw).
FREE_LINK_PARAMS = (
    Param('free_link_damping', False,
          "true: the reference passes through the free link's damping before the law "
          '(freejoint_core.internal.FreeLinkModulation: a bounded shift of the setpoint, '
          'docs/internal-motion.md), for the arm whose last joint is free (r = m), or, '
          'with joint_failures, for the fully actuated 3-joint arm once a failure leaves its '
          'last joint alone free (off until then); '
          "false: the paper's law exactly", read_only=True),
    Param('free_link_delta_max', MODULATION['delta_max'],
          "bound [m] of the free link damping's shift of the reference (the task deviation "
          'it may add)', (1e-6, 1.0), read_only=True),
    Param('free_link_rest_damping', MODULATION['k2_rest'],
          "rate gain k2 [m/s] of the free link's damping once the setpoint has rested "
          'free_link_rest_after s (the settle step after a task; 0.2 while tracking)',
          (0.0, 10.0), read_only=True),
    Param('free_link_rest_after', MODULATION['rest_after'],
          'rest [s] of the setpoint after which free_link_rest_damping applies (rests '
          'between tasks shorter than this keep the tracking gain)', (0.0, 3600.0),
          read_only=True),
    Param('free_link_mode', 'always',
          "'always': the damping acts while tracking and at rest (the vertical arm); "
          "'settle': only in the first free_link_settle_window s of each rest of the "
          'setpoint after a task (not in a rest before the first), the shift bounded by '
          'free_link_delta_max without clipping, then back to 0 before the next task (the '
          'horizontal arm, whose free link is a free rotor: '
          'freejoint_core.circles.HORIZONTAL_SETTLE, docs/internal-motion.md); '
          "'rest': only while the setpoint rests (a link freed by a joint failure, damped "
          'in the rests after its task: config/fully_actuated/free_link_damping.yaml, '
          'docs/failures.md)',
          validator=one_of(('always', 'settle', 'rest')), read_only=True),
    Param('free_link_drive_max', 4.0,
          "saturation [m/s^2] of the free link damping's drive (the shift's acceleration "
          "input); in mode 'settle' k3 free_link_delta_max instead. Set to k3 "
          'free_link_delta_max (k3 = 9 /s^2) the filter alone bounds the shift, which is '
          'never clipped', (1e-6, 100.0), read_only=True),
    Param('free_link_settle_window', HORIZONTAL_SETTLE['settle_window'],
          "seconds of each rest in which free_link_mode 'settle' drives the shift (the rest "
          'between tasks must be about 0.4 s longer)', (1e-3, 3600.0), read_only=True),
)

LAW_GAIN_PARAMS = tuple(
    Param(g.name, float(g.default), f"law '{g.name.split('.')[0]}': {g.description}",
          g.bounds, read_only=True) for g in gain_schema())
"""The laws' own gains (``<law>.<gain>``, each law's ``gain_schema``); read by that law."""

PARAMS = (
    CASE, ARM_SPECS, NOMINAL_SCALE, ARM_JOINT_NAMES, ARM_JOINTS, CONTROL_PERIOD,
    Param('lockstep', True,
          'true: answer the state stamped t_k only with the setpoint stamped t_k; '
          'false (real time): with the newest setpoint stamped <= t_k + dt/2',
          read_only=True),
    Param('standby', False,
          'real time: start as a hot spare (controller_supervisor): publishers made, '
          'setpoints taken, not subscribed to joint_states, nothing published until SIGUSR1 '
          '(subscribes; the first state activates it); then it starts from the measured '
          'motion',
          read_only=True),
    Param('K', list(_DEFAULT.K), 'diagonal of K (m values > 0, m the task dimension of the '
          "arm's model: 2 for a planar arm) [1/s]", validator=_gain('K')),
    Param('Lambda', list(_DEFAULT.Lambda), 'diagonal of Lambda (m values > 0, m the task '
          "dimension of the arm's model: 2 for a planar arm) [1/s]", validator=_gain('Lambda')),
    Param('R', list(_DEFAULT.R), 'diagonal of R (m values > 0, m the task dimension of the '
          "arm's model: 2 for a planar arm)", validator=_gain('R')),
    Param('Gamma', list(_DEFAULT.Gamma), 'diagonal of the adaptation gain Gamma (5 values >= 0)',
          validator=_gain('Gamma')),
    Param('sigma', list(_DEFAULT.sigma), 'diagonal of the sigma-modification (5 values >= 0)',
          validator=_gain('sigma')),
    Param('epsilon', _DEFAULT.epsilon, 'chattering bound epsilon of h_alpha (> 0) in '
          "lockstep (the paper's); real time: realtime_epsilon", (1e-12, 1e6)),
    Param('realtime_epsilon', 0.0,
          'chattering bound epsilon of h_alpha in real time (lockstep: false), where each '
          'command acts 1-3 ms late and a driver may keep it through missed states; 0 = '
          'measured for the arm and delay_compensation (freejoint_control.readiness.'
          "REALTIME_EPSILON: 0.5 for the paper's arms uncompensated, docs/real-time.md), "
          'epsilon for one without a measurement',
          (0.0, 1e6)),
    Param('h_form', _DEFAULT.h_form,
          "h_alpha: 'sum' = ||a|| + epsilon (paper), 'sat' = max(||a||, epsilon)",
          validator=_h_form),
    Param('theta0', list(_DEFAULT.theta0),
          'initial adaptive estimate theta_hat(0) (5 values >= 0); setting it restarts '
          'theta_hat from it', validator=_gain('theta0')),
    Param('robust', _DEFAULT.robust,
          'robust term and adaptation on (false: nominal inverse dynamics)'),
    Param('det_threshold', _DEFAULT.det_threshold,
          '|det(Da Da^T)| below which the damped pseudo-inverse is used (> 0)', (1e-300, 1.0)),
    Param('effort_limits', [300.0, 200.0],
          'per-joint torque limit [N m] (> 0, one per active joint in the order of joints); '
          'the paper runs peak at 13 / 11 (horizontal) and 133 / 74 (vertical). A spatial '
          "arm (task_dim 3): not given, its URDF's efforts",
          follows=_follows_limits('effort_limits')),
    Param('effort_rate_limit', 20000.0,
          'largest torque change [N m/s] per joint after a (re)start, a hold, a reset or a '
          'zero-effort answer, until the command has caught up with the law (then off: the '
          "paper's vertical runs change torque at up to 1.1e5 N m/s while tracking)", (1.0, 1e9),
          validator=above(0.0)),
    Param('stale_timeout', 0.5,
          'wall time [s] (lockstep) or state-stamp time (real time) without a fresh setpoint '
          'after which the controller holds (or commands zero, see on_stale_setpoint); wall '
          'time without a state after which zero effort is commanded', (1e-3, 3600.0),
          validator=above(0.0)),
    Param('on_stale_setpoint', 'hold',
          "no fresh setpoint (and before the first one in real time): 'hold' the end "
          'effector where it is (reference fk(q) frozen at the onset, full law with gravity, '
          "STATUS_HOLDING) or command 'zero' effort (the arm goes limp); lockstep waits for "
          'the first setpoint', validator=one_of(ON_STALE)),
    Param('resume_time', 0.5,
          'time [s of state stamps] of the quintic blend from the hold to the streamed '
          'setpoint (0: switch at once)', (0.0, 60.0)),
    Param('hold_stiffness', 2.0,
          'K and Lambda are multiplied by this while holding (and brought back to 1 over '
          'the resume blend): the static error of the law against the error of the nominal '
          'model, e.g. its 70 % gravity, is 1 / (K Lambda), so 2 quarters the sag of a held '
          'arm; 1 = the gains of the paper throughout; hold_stiffness * (K + Lambda) * '
          'control_period <= 1', (1.0, 10.0)),
    Param('resume_max_velocity', 1.0,
          'bound [m/s] on the peak speed of the blend: a larger offset blends for longer '
          'than resume_time (1.875 offset / resume_max_velocity)', (1e-3, 100.0)),
    Param('resume_max_acceleration', 5.0,
          'bound [m/s^2] on the peak acceleration of the blend: a larger offset blends for '
          'longer than resume_time (sqrt(5.77 offset / resume_max_acceleration))', (1e-3, 1e4)),
    Param('late_periods', 10,
          'real time: a setpoint older than this many control periods is late '
          '(STATUS_SETPOINT_LATE, carried forward for at most carry_forward_time)', (1, 10000)),
    Param('max_state_age', 0.1,
          'real time: a state older than this [s] when it is taken (a backlog after a stall '
          'or at start-up) is skipped without a command (0 = never skip); normal ages are '
          '0.5-18 ms', (0.0, 3600.0)),
    Param('carry_forward_time', 0.02,
          'real time: a late setpoint (older than the state) is carried forward along its '
          'velocity and acceleration for at most this long [s]; older, the controller holds '
          "(with on_stale_setpoint: hold). Short: it bridges a planner's jitter, a dead "
          'planner must not drag the arm along', (0.0, 3600.0)),
    Param('theta_max', [100.0] * 5,
          'element-wise bound of theta_hat (5 values > 0, <= 1e6), clamped inside the update; '
          "the paper's runs reach at most 0.0039, 0.30, 0.0019, 8.0e-5, 6.7e-6",
          validator=_theta_max),
    Param('joint_position_lower', [-1000.0, -1000.0, -1000.0],
          'plausible joint positions [rad], lower bound per joint of joint_names; a state '
          'outside is refused like NaN (zero effort, STATUS_BAD_INPUT). Wide by default (joint1 '
          "turns continuously in the paper's runs, up to 32 rad): set the arm's URDF limits. "
          "A spatial arm: not given, its URDF's (a free or continuous joint: -1000)",
          follows=_follows_limits('joint_position_lower')),
    Param('joint_position_upper', [1000.0, 1000.0, 1000.0],
          'plausible joint positions [rad], upper bound per joint of joint_names. A '
          "spatial arm: not given, its URDF's (a free or continuous joint: 1000)",
          follows=_follows_limits('joint_position_upper')),
    Param('joint_velocity_limit', [100.0, 100.0, 100.0],
          'plausible joint speed [rad/s] per joint of joint_names (> 0). A spatial arm: not '
          "given, its URDF's (a free joint: 1000)",
          validator=_positive_floats('joint_velocity_limit'),
          follows=_follows_limits('joint_velocity_limit')),
    Param('setpoint_max_velocity', 5.0,
          'largest plausible setpoint speed [m/s]; a setpoint beyond it, its acceleration '
          "bound or the arm's reach is refused with the reason and dropped (none fresh left: "
          "hold); the paper's circle peaks at 0.47 m/s", (1e-6, 1e3)),
    Param('setpoint_max_acceleration', 50.0,
          'largest plausible setpoint acceleration [m/s^2]', (1e-6, 1e5)),
    Param('delay_compensation', 'off',
          "'off' or 'predict' (real time only): the law runs on the state predicted with the "
          'nominal model (freejoint_core.delay.StatePredictor) to when the command takes '
          'effect, ceil(state age / control_period) periods (at least 1) ahead',
          validator=one_of(DELAY_COMPENSATION)),
    EXECUTOR,
    SCHEDULING,
    Param('law', 'robust',
          "the control law (freejoint_core.laws registry): 'robust' = the paper's robust law "
          "with adaptation (planar arms); 'spatial' = the same law on a spatial arm "
          '(task_dim 3: inertia-weighted inverse, null-space damping nullspace_kd and '
          "posture nullspace_kp, efforts within the URDF's limits and effort_limits); "
          'another law is one module registering itself '
          '(freejoint_core.laws.register_law) and this value; takes effect at start-up',
          read_only=True, validator=one_of(LAWS)),
    *LAW_GAIN_PARAMS,
    Param('state_publish_rate', 0.0,
          'rate [Hz of state stamps] of controller_state (as ros2_control state publishers '
          'thin theirs): 0 = one per answered state; else at most one per 1/rate s, and '
          'every answer whose status differs from the last published one', (0.0, 1e6)),
    Param('readiness_guard', True,
          'real time: judge the loop (freejoint_control.readiness) over windows of state '
          'stamps - mean state->command delay against readiness_max_delay, states answered '
          'against readiness_min_answer_rate - and stop tracking while it cannot keep '
          'within them (readiness_action), saying why; lockstep is never judged'),
    Param('readiness_action', 'brake',
          "what a not-ready loop does: 'brake' = stop: answer the first state with the stop "
          'command (the gravity hold of the active joints, what a driver that keeps its '
          'last command then holds), ask for the brakes (readiness_brake_request), then '
          "send no command (a driver's watchdog brakes: the simulator's brake_timeout); "
          "'damp' = answer every state with a damped joint hold of the active joints "
          '(stop_hold_time, on the gravity load), which tolerates held commands the law '
          "does not but leaves the free link to swing or spin; 'hold' = for a driver that "
          'holds its last command and has no brakes to ask for (command_watchdog false in '
          'the simulator): hold the end effector with the law, answering every state '
          '(the law still runs on late states), until a gap in the states longer than '
          "readiness_hold_max_gap (the law's last command kept all along) or the hold off "
          'by more than readiness_hold_max_error (a following-error trip, '
          "readiness_max_error, goes to the law's hold too): from then "
          'on, until ready again, the damped joint hold; ready again after it, the '
          'controller says not ready for a plan until it has re-joined the setpoints '
          '(docs/real-time.md, docs/real-arm.md)',
          validator=one_of(READINESS_ACTIONS)),
    Param('stop_hold_time', 0.1,
          "readiness_action 'damp': the longest [s] the driver is to keep one command of "
          'the damped joint hold (a stalled controller, a burst of missed states): the '
          "hold's stiffness and damping are the active joints' effective inertia times "
          '1 / stop_hold_time^2 and 1.5 / stop_hold_time, stable for a command kept up to '
          '1.33 times as long (freejoint_core.guards.damped_hold_effort; docs/real-time.md)',
          (0.005, 1.0)),
    Param('readiness_brake_request', True,
          'real time: whenever the controller stops (a readiness trip with readiness_action '
          "'brake', or no joint_states for stale_timeout), ask the driver to brake now "
          '(brake_request), after the stop command, instead of leaving it to its command '
          'watchdog (if it has one)'),
    Param('hold_brake_timeout', 0.01,
          'real time: while the setpoint rests (no plan, a stale stream, or the newest '
          'setpoint with zero velocity and acceleration), ask the driver on '
          'brake_timeout_request to brake after this long [s] without a command when that '
          "is shorter than its own watchdog (the simulator's brake_timeout, 0.05 s); "
          'while the setpoint moves, ask for no shorter wait (short stalls ridden through '
          'on the last command). A held arm, its free link swinging included, gains '
          'nothing from a stall ridden open loop (docs/real-time.md); 0 = never ask',
          (0.0, 10.0)),
    Param('readiness_max_delay', 0.0,
          'trip: tolerated mean effective delay [s] (state age when taken, in whole control '
          'periods, plus the one period to the next step); 0 = measured for the arm and '
          'delay_compensation (freejoint_control.readiness.MEASURED, docs/real-time.md; '
          'an arm without a measurement: the strictest measured, with a warning)',
          (0.0, 10.0)),
    Param('readiness_min_answer_rate', 0.0,
          'trip: least share of the expected states (window span / control_period) the '
          'loop must answer per window; 0 = measured for the arm (as readiness_max_delay)',
          (0.0, 1.0)),
    Param('readiness_max_gap', 0,
          'trip: a ready loop stops at the first state after more consecutive states not '
          'answered than this (a stall of the loop); 0 = measured for the arm (as '
          'readiness_max_delay)', (0, 100000)),
    Param('readiness_hold_max_gap', 0.05,
          "readiness_action 'hold': the longest gap [s] between two states (the driver "
          "keeping the law's last command all through it) after which a not-ready spell "
          'goes on with the damped joint hold instead of the law; 0 = the law holds '
          'through any gap. The default: the vertical law was lost under 35-49 ms stalls '
          'and on 0.1-s gaps, the damped hold is stable to 1.33 stop_hold_time, and a '
          'switch costs the free link its hold (docs/real-time.md)', (0.0, 1.0)),
    Param('readiness_hold_max_error', 0.05,
          "readiness_action 'hold', not ready: the law's hold off by more than this [m] "
          'gives the rest of the spell to the damped joint hold; 0 = readiness_max_hold_error '
          '(else readiness_max_error). The default: offline, at the real-time bound, an '
          "isolated 40-60 ms stall of the driver's kept command carried the vertical hold "
          '4-26 mm off and the law recovered, while the damped joint hold lets a vertical free '
          'link fall (docs/real-time.md)', (0.0, 10.0)),
    Param('readiness_hold_stiffness', 1.0,
          "readiness_action 'hold': K and Lambda are multiplied by this, instead of "
          "hold_stiffness, in the law's hold after a trip by the loop's timing (a late "
          'mean delay, too few states answered, a gap): such a loop tolerates less gain, '
          'and a driver keeps each of its commands for longer. A following-error trip '
          '(the loop on time, the arm thrown off) holds at hold_stiffness. The default: in '
          'one process, a vertical loop answering 1 state in 10 after a gap, or stalled '
          '60-80 ms, lost the arm in 2-9 of 10 seeds at 2 and 1-3 at 1, while a reset of '
          'the arm under a silent loop lost it more often at 1 (docs/real-time.md); '
          'readiness_hold_stiffness * (K + Lambda) * control_period <= 1', (1.0, 10.0)),
    Param('readiness_stop_acceleration', 5.0,
          "readiness_action 'hold', a trip by the loop's timing while the reference moves: "
          "the law's hold starts by stopping the reference along its path (the last "
          "reference's osculating arc, the plan's own circle) on the feed hold's ramp, its "
          'tangential deceleration peaking at this [m/s^2] (a stop of T = 1.875 speed / '
          'this, speed T / 2 along), as the planner stops its plan; 0 = hold where the arm '
          'is at once (a step to zero velocity the driver keeps). The default: the '
          "planner's max_acceleration; in one process the stalls of a vertical soak run "
          'that lost the arm, replayed at four points of the circle for seeds 0-9, lost it '
          'in 9 of 40 runs held at once, in none stopped at 5 (docs/real-time.md)',
          (0.0, 1e4)),
    Param('readiness_resume_delay', 0.0,
          'resume: a window counts towards readiness (readiness_recover_windows of them in '
          'a row) at this mean effective delay [s] or less; 0 = measured for the arm (as '
          'readiness_max_delay)', (0.0, 10.0)),
    Param('readiness_resume_answer_rate', 0.0,
          'resume: ... and at this share of the expected states answered or more; 0 = '
          'measured for the arm (as readiness_max_delay)', (0.0, 1.0)),
    Param('readiness_window', 0.2,
          'window [s of state stamps] over which delay and answer rate are judged; one bad '
          'window stops tracking (at once when it already missed more states than the rate '
          'allows: with 0.2 s and 0.8, a stall over 40 ms, near where the driver brakes '
          'anyway); shorter stalls are within what the law rides out', (0.002, 60.0)),
    Param('readiness_max_error', 0.01,
          'real time: a tracking error [m] above this while the loop is judged ready stops '
          'tracking as a bad window does (readiness_action, the reason said; the recovery '
          'windows again): a loop late and lossy enough to destabilise the law within '
          'the delay and answer-rate bounds, a following-error stop as drives have; 0 = '
          'off. Above every real-time run that met its bound (vertical 5.5 mm)',
          (0.0, 10.0)),
    Param('readiness_max_hold_error', 0.0,
          "real time: the following-error stop's bound [m] while the end effector is held "
          'with no setpoint (none yet, or the stream stale), instead of readiness_max_error '
          "(0, the default: readiness_max_error). A vertical hold's own error is about 1 mm, "
          'so e.g. 0.003 stops a slow drift early; beside CPU hogs it also stopped '
          'horizontal holds, whose error reached 3 mm (docs/real-time.md)', (0.0, 10.0)),
    Param('readiness_recover_windows', 5,
          'consecutive good windows after which a not-ready loop tracks again (hysteresis)',
          (1, 100000)),
) + FAILURE_PARAMS + FREE_LINK_PARAMS


# -- cross-parameter checks ------------------------------------------------------------
def _nominal(values):
    """Return the nominal model of the arm and ``nominal_scale`` (both valid)."""
    return resolve_arm(values).nominal(values['nominal_scale'])


def _check_joints(values):
    n_model = _nominal(values)
    joint_names, joints = arm_joint_names(values, resolve_arm(values))
    joint_names = unique_names('joint_names', joint_names)
    if len(joint_names) != n_model.n:
        return f'joint_names: the arm has {n_model.n} joints, got {len(joint_names)} names'
    joints = unique_names('joints', joints)
    active_names = [joint_names[i] for i in n_model.active]
    if sorted(joints) != sorted(active_names):
        return (f'joints: expected the {n_model.r} active joints {active_names} in any order, '
                f'got {list(joints)}')
    return None


def _check_loop_rate(values):
    """(K + Lambda) dt <= 1, also when held (times either hold's stiffness): the discrete loop."""
    dt = float(values['control_period'])
    holds = [(name, float(values[name]))
             for name in ('hold_stiffness', 'readiness_hold_stiffness')]
    pairs = list(enumerate(zip(values['K'], values['Lambda'])))
    for i, (k, lam) in pairs:
        if (k + lam) * dt > 1.0:
            return (f'K: K[{i}] + Lambda[{i}] = {k + lam:g} 1/s is beyond 1 / control_period = '
                    f'{1.0 / dt:g} 1/s (the discrete loop would be unstable)')
    for i, (k, lam) in pairs:
        for name, scale in holds:
            if scale * (k + lam) * dt > 1.0:
                return (f'{name}: {scale:g} x (K[{i}] + Lambda[{i}]) = '
                        f'{scale * (k + lam):g} 1/s is beyond 1 / control_period = '
                        f'{1.0 / dt:g} 1/s (the held loop would be unstable)')
    return None


def _check_theta0(values):
    theta0, theta_max = tuple(values['theta0']), tuple(values['theta_max'])
    if any(t > m for t, m in zip(theta0, theta_max)):
        return (f'theta0: values must be <= theta_max {list(theta_max)}, '
                f'got {list(theta0)}')
    return None


def _check_effort_limits(values):
    joints = list(arm_joint_names(values, resolve_arm(values))[1])
    _floats('effort_limits', values['effort_limits'])
    limits = arm_limits(values, 'effort_limits')
    if len(limits) != len(joints) or any(not 0.0 < v <= 1e6 for v in limits):
        return (f'effort_limits: expected {len(joints)} values in (0, 1e6] N m (one per joint '
                f'of joints {joints}), got {list(limits)}')
    return None


def _check_delay_compensation(values):
    if values['delay_compensation'] == 'predict' and values['lockstep']:
        return ("delay_compensation: 'predict' is for real time (lockstep: false); in lockstep "
                'the simulator waits for the command, there is no delay to compensate')
    return None


def _check_state_bounds(values):
    n = resolve_arm(values).params.n
    for name in ('joint_position_lower', 'joint_position_upper', 'joint_velocity_limit'):
        _floats(name, values[name])
    lower, upper, vlim = (arm_limits(values, name) for name in (
        'joint_position_lower', 'joint_position_upper', 'joint_velocity_limit'))
    for name, vals in (('joint_position_lower', lower), ('joint_position_upper', upper),
                       ('joint_velocity_limit', vlim)):
        if len(vals) != n:
            return (f'{name}: expected {n} values (one per joint of joint_names), '
                    f'got {list(vals)}')
    if any(not lo < hi for lo, hi in zip(lower, upper)):
        return (f'joint_position_upper: each bound must be above joint_position_lower '
                f'{list(lower)}, got {list(upper)}')
    return None


def _check_standby(values):
    if values['standby'] and values['lockstep']:
        return ('standby: a hot spare is for real time (lockstep: false); in lockstep the '
                'simulator waits for one controller, there is nothing to take over')
    return None


def _check_task(values):
    # The task dimension of the arm: 2 for a planar arm (every planar model is an
    # ArmModel: Arm3Model, ArmModel, PinArmModel), 3 for a spatial one (its SpatialArm).
    m = resolve_arm(values).task_dim
    for name in TASK_GAINS:
        if len(values[name]) != m:
            return (f"{name}: expected {m} values (the task dimension of the arm's model), "
                    f'got {list(values[name])}')
    return None


def _check_spatial(values):
    """Refuse a spatial arm without the spatial law or with a planar-only option."""
    spatial = resolve_arm(values).spatial is not None
    if spatial != (values['law'] == SPATIAL_LAW):
        return (f"law: a spatial arm (task_dim 3) runs law '{SPATIAL_LAW}', a planar one "
                f"another law; got law '{values['law']}' with task_dim {values['task_dim']}")
    if not spatial:
        if values['nullspace_kp'] != 0.0:
            return ("nullspace_kp: the posture term is the spatial law's (task_dim 3); a "
                    'planar arm takes 0')
        if list(values['nullspace_kd_joints']) != [0.0]:
            return ("nullspace_kd_joints: the spatial law's (task_dim 3); a planar arm takes "
                    '[0.0] (nullspace_kd)')
        return None
    per_joint = list(values['nullspace_kd_joints'])
    active = resolve_arm(values).spatial.r
    if per_joint != [0.0] and len(per_joint) != active:
        return (f'nullspace_kd_joints: expected {active} values (one per active joint) or '
                f'[0.0], got {per_joint}')
    for name, planar in (('joint_failures', 'off'), ('delay_compensation', 'off'),
                         ('free_link_damping', False)):
        if values[name] != planar:
            return (f'{name}: planar arms only for now (a spatial arm, task_dim 3, needs '
                    f'{name}: {planar!r})')
    return None


def _check_failures(values):
    if values['joint_failures'] != 'off' and \
            values['failure_observer_gain'] * float(values['control_period']) >= 2.0:
        return ('failure_observer_gain: failure_observer_gain x control_period must be < 2 '
                '(the observer would be unstable)')
    return None


def _check_free_link(values):
    if not values['free_link_damping']:
        return None
    nominal = _nominal(values)
    m = ArmModel.task_dim
    if nominal.passive == (nominal.n - 1,) and nominal.r == m:
        return None
    if values['joint_failures'] != 'off' and nominal.passive == () and nominal.n == m + 1:
        return None     # on once a failure leaves the last joint alone free
    return (f'free_link_damping: needs the arm whose last joint alone is free (r = m = {m}), '
            f'or with joint_failures a fully actuated arm of {m + 1} joints; got passive '
            f'joints {list(nominal.passive)} of {nominal.n}')


CHECKS = (_check_joints, _check_loop_rate, _check_theta0, _check_effort_limits,
          _check_delay_compensation, _check_state_bounds, _check_standby, _check_task,
          _check_spatial, _check_failures, _check_free_link)


@dataclass(frozen=True)
class Config(LoopConfig):
    """
    Validated controller configuration: what is derived from several parameters.

    Besides the loop's fields (:class:`LoopConfig`): the nominal model (``ArmParams``; a
    spatial arm's ``SpatialArm``), the gains, the command order, the limits and the arm's
    joint offsets (added to the measured angles:
    ``NodeArm.joint_offsets``, model order), the laws' own gains (``law_params``,
    ``<law>.<gain>``). Every other parameter is ``config.<name>`` as validated.
    """

    nominal: ArmParams
    gains: Gains
    cmd_index: tuple
    effort_limits: tuple
    position_lower: tuple
    position_upper: tuple
    velocity_limit: tuple
    reach: float
    nominal_model: object = field(default=None, compare=False)
    joint_offsets: tuple = ()
    law_params: dict = field(default_factory=dict)


GAIN_NAMES = ('K', 'Lambda', 'R', 'Gamma', 'sigma', 'epsilon', 'h_form', 'theta0', 'robust',
              'det_threshold')
"""The parameters that are ``Gains`` fields of the same name."""


TASK_GAINS = ('K', 'Lambda', 'R')
"""The gains sized by the task dimension m."""


def gains(values, tau_limit=None, theta_max=None, task_dim=2):
    """
    Return the core's gains of a parameter dict (the fields named as the parameters).

    ``Gains`` for a planar task (``task_dim`` 2), ``SpatialGains`` for a spatial one (3;
    its torque within the smaller of the URDF's limits and ``tau_limit``).
    """
    fields = {name: (tuple(values[name]) if isinstance(values[name], list) else values[name])
              for name in GAIN_NAMES}
    if task_dim == 3:
        from freejoint_core.spatial_law import SpatialGains
        return SpatialGains(**fields, tau_limit=tau_limit, theta_max=theta_max, task_dim=3)
    return Gains(**fields, tau_limit=tau_limit, theta_max=theta_max, task_dim=task_dim)


def _nominal_model(values):
    """Pinocchio's nominal model of a URDF arm of other than 3 links, else None."""
    arm = resolve_arm(values).urdf_arm       # None for the paper's arm and a spatial one
    return None if arm is None else nominal_model(arm, values['nominal_scale'])


def build(values):
    """Return the :class:`Config` of a complete, valid parameter dict."""
    nominal = _nominal(values)
    joint_names, joints = arm_joint_names(values, resolve_arm(values))
    active_names = [joint_names[i] for i in nominal.active]
    limits = arm_limits(values, 'effort_limits')
    dt = float(values['control_period'])
    model = _nominal_model(values)
    arm = resolve_arm(values)
    if arm.spatial is not None:
        from freejoint_core.spatial_law import arm_reach
        reach, task_dim = arm_reach(nominal), arm.task_dim
    else:
        reach = float(sum(nominal.lengths))
        task_dim = (model if model is not None else ArmModel).task_dim
    law_values = values
    if not values['lockstep']:
        law_values = dict(values, epsilon=realtime_epsilon(
            arm.params, values['delay_compensation'], values['realtime_epsilon'],
            values['epsilon'])[0])
    return Config(
        values=dict(values), nominal=nominal,
        gains=gains(law_values, tuple(limits[joints.index(name)] for name in active_names),
                    _floats('theta_max', values['theta_max']), task_dim),
        joint_names=joint_names, joints=joints,
        cmd_index=tuple(active_names.index(name) for name in joints), dt=dt,
        dt_ns=round(dt * 1e9), lockstep=bool(values['lockstep']), effort_limits=limits,
        position_lower=arm_limits(values, 'joint_position_lower'),
        position_upper=arm_limits(values, 'joint_position_upper'),
        velocity_limit=arm_limits(values, 'joint_velocity_limit'),
        reach=reach, nominal_model=model, joint_offsets=tuple(arm.joint_offsets),
        law_params={p.name: float(values[p.name]) for p in LAW_GAIN_PARAMS})


SCHEMA = Schema(PARAMS, CHECKS, build)
SPECS = SCHEMA.params
DEFAULTS = SCHEMA.defaults()
build_config = SCHEMA.config
