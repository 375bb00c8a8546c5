"""
Parameters of the simulator node: its schema (no ROS types).

``SCHEMA`` lists every parameter once (name, default, description, range, read-only,
validator), the cross-parameter checks (the step grid: dt_sub, publish_rate, clock_rate;
the joints of the arm; the initial state) and :func:`build` of the :class:`Config` the
node reads (real arm, initial state by the active joints' inverse kinematics
``ArmModel.ik``, branch +1, command mapping; a spatial arm, ``task_dim`` 3: its
``initial_joint_positions`` within the URDF's position limits). The arm entries are
``freejoint_common.arm_description.ARM_SPECS``, the ones the controller and the planner
share are ``freejoint_common.schema``'s; the paper's defaults are the core's
(``DEFAULT_DT_SUB``, ``DEFAULT_DIST_BOUND``, ``DEFAULT_Q3_0_DEG``). ``SPECS`` /
:func:`build_config` are the entries and the validated build (``FreejointValueError``
naming the parameter).

"""

from dataclasses import dataclass, replace
import math

from freejoint_common.arm_description import ARM_JOINT_NAMES, arm_joint_names, ARM_JOINTS
from freejoint_common.arm_description import ARM_SPECS, resolve_arm
from freejoint_common.schema import CASE, CONTROL_PERIOD, EXECUTOR, FRAME_ID
from freejoint_common.schema import LoopConfig, one_of, Param, SCHEDULING, Schema
from freejoint_common.schema import unique_names
from freejoint_core.arm import ArmModel, ArmParams
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import equilibrium_pose, hanging_pose
from freejoint_core.offline import DEFAULT_Q3_0_DEG
from freejoint_core.plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB
from freejoint_sim.failure_injection import parse_fail_joint

MODES = ('lockstep', 'realtime')
ENGINES = ('rk4', 'mujoco')
START_POSES = ('paper', 'hanging')
MAX_DIST_BOUND = 10.0
"""Upper bound [N m] of ``dist_bound``: 20 times the paper's 0.5 N m and about the peak
actuator torque of the horizontal case (11 N m); a disturbance as large as what the
actuators give is no longer one a tracking law rejects."""
MAX_PASSIVE_DEG = 360.0
"""Upper bound [deg] of ``|initial_passive_deg|``: one turn (larger angles repeat it)."""
MAX_DIVERGENCE_SPEED = 1e5
"""Upper bound [rad/s] of ``divergence_speed``."""
MAX_TIMING_STEPS = 10_000_000
MAX_PASSIVE_DAMPING = 100.0
"""Upper bound [N m s/rad] of ``passive_damping``: 100 times the 1 N m s/rad MuJoCo
Menagerie gives every joint of its Franka Panda."""


def _within(lo, hi, text):
    """Return a validator: a finite number in [lo, hi], else ``text`` (formatted)."""
    def check(value):
        value = float(value)
        if not (math.isfinite(value) and lo <= value <= hi):
            return text.format(value=value)
        return None
    return check


def _seed(value):
    return None if value >= 0 else f'expected an integer >= 0, got {value!r}'


def _initial_position(value):
    start = tuple(value)
    if len(start) != 2 or not all(isinstance(v, float) and math.isfinite(v) for v in start):
        return f'expected 2 finite numbers (x, y) [m], got {list(start)}'
    return None


PARAMS = (
    replace(CASE, description=CASE.description + '; the gravity of a URDF arm unless gravity '
            'is set; takes effect on reset'),
    ARM_SPECS,
    Param('engine', 'rk4',
          "plant: 'rk4' (classic RK4 at dt_sub: the closed-form 3-link model, Pinocchio's "
          'ABA for other URDF arms and for a spatial arm, freejoint_core.spatial_plant) or '
          "'mujoco' (MuJoCo's RK4 on the URDF, freejoint_core.mujoco_plant); takes effect on "
          'reset', validator=one_of(ENGINES)),
    Param('mode', 'lockstep',
          "'lockstep': own /clock, advance one control period per command; 'realtime': "
          'step on the wall clock and apply the latest command', read_only=True,
          validator=one_of(MODES)),
    ARM_JOINT_NAMES, ARM_JOINTS, CONTROL_PERIOD,
    Param('dt_sub', DEFAULT_DT_SUB,
          'RK4 integration step [s]; control_period must be an integer multiple; takes '
          'effect on reset', (1e-7, 1.0)),
    Param('publish_rate', 1000.0,
          'real time: rate [Hz] of joint_states and ee_position, at most the step rate '
          '1 / control_period and a divisor of it (500 with control_period 0.001: the '
          'states of a 500 Hz driver); lockstep publishes every step', (0.1, 1e5)),
    Param('clock_rate', 0.0,
          'lockstep: rate [Hz] of /clock in sim time (like gazebo_ros publish_rate): /clock '
          'goes out on the steps that are multiples of 1 / (clock_rate * control_period), '
          'which must be an integer >= 1, and always at step 0 and at max_steps; the state '
          'goes out every step. 0 = every step. A node streaming ahead of a /clock every N '
          'steps (the planner) needs a lookahead of at least N - 1 steps',
          (0.0, 1e6), validator=_within(0.0, math.inf,
                                        'must be >= 0 Hz (0 = every step), got {value}')),
    Param('dist_bound', DEFAULT_DIST_BOUND,
          'bound [N m] of the uniform random joint disturbance (0 = off, at most %g); takes '
          'effect on reset' % MAX_DIST_BOUND, (0.0, MAX_DIST_BOUND),
          validator=_within(0.0, MAX_DIST_BOUND,
                            f'must be in [0, {MAX_DIST_BOUND:g}] N m (the paper: '
                            f'{DEFAULT_DIST_BOUND:g}; the horizontal case peaks near 11 N m '
                            'of actuator torque), got {value}')),
    Param('passive_damping', 0.0,
          "viscous damping [N m s/rad] of each free joint's drivetrain (a failed joint's "
          'gearbox and motor still turn with it; the controller is not told: to its law a '
          "disturbance); 0 = the paper's frictionless free joint; spatial arms (task_dim 3) "
          'only; takes effect on reset', (0.0, MAX_PASSIVE_DAMPING),
          validator=_within(0.0, MAX_PASSIVE_DAMPING,
                            f'must be in [0, {MAX_PASSIVE_DAMPING:g}] N m s/rad, got '
                            '{value}')),
    Param('seed', 0, 'seed of the disturbance generator (>= 0); takes effect on reset',
          validator=_seed),
    Param('initial_position', [0.2, 0.0],
          'initial end-effector position [m] (x, y); with initial_passive_deg gives q(0) by '
          'inverse kinematics (branch +1), at rest; planar arms only; takes effect on reset',
          validator=_initial_position),
    Param('initial_passive_deg', DEFAULT_Q3_0_DEG,
          'initial passive joint angle [deg], within one turn; planar arms only; takes '
          'effect on reset',
          (-MAX_PASSIVE_DEG, MAX_PASSIVE_DEG),
          validator=_within(-MAX_PASSIVE_DEG, MAX_PASSIVE_DEG,
                            f'must be within one turn, [-{MAX_PASSIVE_DEG:g}, '
                            f'{MAX_PASSIVE_DEG:g}] deg, got {{value}}')),
    Param('initial_joint_positions', '',
          "q(0) [rad], every joint base to tip, as space-separated numbers (e.g. '0 1.0 1.4 "
          "2.2'), instead of initial_position and initial_passive_deg (which need an arm "
          "with one passive and two active joints); '' = those; a spatial arm (task_dim 3) "
          "needs them, within the URDF's position limits; takes effect on reset"),
    Param('start_pose', 'paper',
          "'paper': q(0) as initial_position and initial_passive_deg (or "
          "initial_joint_positions) give it; 'hanging': the free link at rest under gravity"
          ': for the 3-link arm with joint 3 free, hanging straight down with the '
          'end effector at initial_position (freejoint_core.internal.hanging_pose); for '
          'another arm, the static equilibrium of its free joints nearest '
          'initial_joint_positions, the end effector where those put it '
          '(freejoint_core.internal.equilibrium_pose); needs gravity; planar arms only; '
          'takes effect on reset',
          validator=one_of(START_POSES)),
    Param('command_timeout', 0.5,
          'wall time [s] without a command after which zero effort is applied (and a '
          'warning given); lockstep: per step, after the first command', (1e-3, 3600.0)),
    Param('start_braked', True,
          'real time: hold the arm at q(0) at rest (brakes engaged: no integration, the '
          'states still published at publish_rate) until the first accepted command, and '
          'again after ~/reset until the next one; false = the arm moves (a vertical arm '
          'falls) from the first step. Lockstep waits for the first command anyway'),
    Param('command_watchdog', True,
          'real time: true = a drive with a command watchdog (brake_timeout, '
          'brake_timeout_at_rest, command_timeout) that brakes when asked (brake_request, '
          'brake_timeout_request); false = a driver that holds the last command, as '
          "ros2_control's forward_command_controller (JointGroupEffortController) does: "
          'every command is applied until the next one, with no watchdog, no timeout and no '
          'brakes but the start-up ones (start_braked, until the first command); the brake '
          'topics are ignored (docs/real-arm.md)'),
    Param('brake_timeout', 0.05,
          'real time: no command for this long [s] after the last one engages the brakes, '
          'as a drive watchdog does: the arm stops where it is (every joint, the passive one '
          'included) and is held until the next accepted command; 0 = never (the last '
          'command is applied until command_timeout, then zero effort)', (0.0, 3600.0),
          validator=_within(0.0, 3600.0, 'must be in [0, 3600] s (0 = never), got {value}')),
    Param('brake_timeout_at_rest', 0.01,
          "real time: the watchdog's wait [s] after a command that found the arm at rest "
          '(every joint slower than rest_speed): the last command of a held arm drives it '
          'open loop for nothing, so the brakes come sooner than brake_timeout (at most it); '
          '0 = brake_timeout', (0.0, 3600.0),
          validator=_within(0.0, 3600.0, 'must be in [0, 3600] s (0 = brake_timeout), got '
                            '{value}')),
    Param('rest_speed', 0.05,
          'real time: the arm is at rest for the watchdog when every joint (the passive '
          'ones included) is slower than this [rad/s]', (1e-6, 100.0),
          validator=_within(1e-6, 100.0, 'must be in [1e-6, 100] rad/s, got {value}')),
    Param('divergence_speed', 1000.0,
          'a joint speed above this [rad/s] (or a non-finite state, or an angle beyond 1e6 '
          'rad) is a diverged plant: the simulator stops integrating, publishes its last '
          "sane state and reports ERROR on /diagnostics until ~/reset. The controller's "
          'plausible speed (joint_velocity_limit, 100 rad/s) flags a diverging loop with '
          "the tracking error under 0.1 m, but a hot spare's takeover of the vertical arm "
          'passed it once (docs/real-time.md)',
          (1.0, MAX_DIVERGENCE_SPEED),
          validator=_within(1.0, MAX_DIVERGENCE_SPEED,
                            f'must be in [1, {MAX_DIVERGENCE_SPEED:g}] rad/s, got {{value}}')),
    Param('max_steps', 0,
          'lockstep: once step max_steps is published the simulator holds (no further '
          'step, no further message; later commands are ignored); 0 = run until stopped. '
          'A run of N control ticks uses N (the state at t = N dt is the last one)',
          validator=lambda v: None if v >= 0 else
          f'expected an integer >= 0 (0 = no limit), got {v!r}'),
    FRAME_ID,
    replace(EXECUTOR, default='single_threaded'),
    Param('timing_file', '',
          'measurement (bench/graph.py): path of a .npz file of per-step wall times (state '
          "publication, receipt of the command answering it); '' = off", read_only=True),
    Param('timing_steps', 0,
          'measurement: steps recorded in timing_file (arrays preallocated; the file is '
          'written when they are full, or at shutdown)', read_only=True,
          validator=lambda v: None if 0 <= v <= MAX_TIMING_STEPS else
          f'expected an integer in [0, {MAX_TIMING_STEPS}], got {v!r}'),
    SCHEDULING,
    # Joint failures (freejoint_sim/failure_injection.py).
    Param('fail_joint', '',
          "scheduled failures: '<joint>@<t>[,<joint>@<t>]' (e.g. 'joint3@2.5': the joint's "
          'actuator and brake fail from simulation time 2.5 s: no torque, the disturbance '
          "only, effort 0 in joint_states); '' = none; takes effect on reset (the service "
          '~/fail_joint: from the next step)'),
    Param('report_failures', False,
          'publish a notice on joint_failures (std_msgs/String, the joint name) when a '
          'failure takes effect, as a driver reporting the fault would; false: only the log '
          'line and /diagnostics say it', read_only=True),
)


def _multiple(name, big, small):
    """Return big / small if it is a positive integer (within 1e-9 relative), else raise."""
    n = round(big / small)
    if n < 1 or abs(n * small - big) > 1e-9 * big:
        raise FreejointValueError(name)
    return n


def _clock_every(rate, dt):
    """Return the steps from one /clock to the next for ``clock_rate`` (0: every step)."""
    rate = float(rate)
    if rate == 0.0:
        return 1
    step_rate = 1.0 / dt
    if rate > step_rate * (1.0 + 1e-9):
        raise FreejointValueError(f'clock_rate: {rate:g} Hz is above the step rate '
                                  f'{step_rate:g} Hz (1 / control_period)')
    return _multiple(f'clock_rate: {rate:g} Hz does not divide the step rate {step_rate:g} '
                     'Hz (1 / (clock_rate * control_period) must be an integer)', 1.0 / rate, dt)


def _publish_every(rate, dt):
    """Return the steps from one published state to the next for ``publish_rate``."""
    rate = float(rate)
    if rate > (1.0 / dt) * (1.0 + 1e-9):
        raise FreejointValueError(f'publish_rate: {rate:g} Hz is above the step rate '
                                  f'{1.0 / dt:g} Hz (1 / control_period): no more states '
                                  'than steps')
    return _multiple(f'publish_rate: {rate} Hz does not divide the step rate '
                     f'{1.0 / dt:g} Hz', 1.0 / rate, dt)


def _initial_joints(text, params):
    """Return ``initial_joint_positions`` as n floats, None if empty, or raise naming it."""
    if not str(text).strip():
        return None
    try:
        q0 = [float(v) for v in str(text).split()]
    except ValueError:
        q0 = None
    if q0 is None or len(q0) != params.n or not all(
            math.isfinite(v) and abs(v) <= 1e6 for v in q0):
        raise FreejointValueError(
            f'initial_joint_positions: expected {params.n} finite joint angles [rad] (one per '
            f'joint, base to tip), got {text!r}')
    return q0


def _joints(values, arm):
    """Return ``(joint_names, joints)`` of the arm, or raise naming the parameter."""
    params = arm.params
    joint_names, joints = arm_joint_names(values, arm)
    joint_names = unique_names('joint_names', joint_names)
    if len(joint_names) != params.n:
        raise FreejointValueError(
            f'joint_names: the arm has {params.n} joints, got {len(joint_names)} names')
    joints = unique_names('joints', joints)
    active_names = [joint_names[i] for i in params.active]
    if sorted(joints) != sorted(active_names):
        raise FreejointValueError(
            f'joints: expected the {params.r} active joints {active_names} in any order, '
            f'got {list(joints)}')
    return joint_names, joints


def _check_joints(values):
    _joints(values, resolve_arm(values))


def _check_steps(values):
    dt = float(values['control_period'])
    dt_sub = float(values['dt_sub'])
    _multiple(f'dt_sub: control_period {dt} s is not an integer multiple of dt_sub '
              f'{dt_sub} s', dt, dt_sub)
    _publish_every(values['publish_rate'], dt)
    _clock_every(values['clock_rate'], dt)


def _check_timing(values):
    if values['timing_file'] and values['timing_steps'] < 1:
        return 'timing_steps: must be >= 1 when timing_file is set'
    return None


def _check_fail_joint(values):
    arm = resolve_arm(values)
    parse_fail_joint(values['fail_joint'], _joints(values, arm)[0], arm.params.active)


CHECKS = (_check_joints, _check_steps, _check_timing, _check_fail_joint)


@dataclass(frozen=True)
class Config(LoopConfig):
    """
    Validated simulator configuration: what is derived from the parameters.

    Besides the loop's fields (:class:`LoopConfig`): the arm (``params``, ``arm``), its
    initial joint angles ``q0``, the command-to-active-joint map and the publication
    steps. Every other parameter is ``config.<name>`` as validated.
    """

    params: ArmParams
    arm: object
    q0: tuple
    cmd_to_active: tuple
    publish_every: int
    clock_every: int


def _hanging(values, params, guess):
    """Return q(0) of ``start_pose: hanging`` (the free joints at rest), or raise naming it."""
    if params.p == 0 or params.gravity <= 0.0:
        raise FreejointValueError(
            "start_pose: 'hanging' needs a passive joint and gravity (case vertical, or a "
            f'URDF arm with gravity), got {params.p} passive joints, gravity '
            f'{params.gravity:g} m/s^2')
    if params.n == 3 and params.passive == (2,) and guess is None:
        try:
            return hanging_pose(params, tuple(values['initial_position'])).tolist()
        except FreejointValueError as exc:
            raise FreejointValueError(f"start_pose: 'hanging' at initial_position: {exc}") \
                from None
    if guess is None:
        raise FreejointValueError(
            f"start_pose: 'hanging' for an arm of {params.n} joints, passive "
            f'{list(params.passive)}: give initial_joint_positions (the search starts there)')
    model = ArmModel(params)
    try:
        return equilibrium_pose(model, model.fk(guess), guess).tolist()
    except FreejointValueError as exc:
        raise FreejointValueError(f"start_pose: 'hanging' from initial_joint_positions: "
                                  f'{exc}') from None


PLANAR_ONLY = ('initial_position', 'initial_passive_deg', 'start_pose')
"""The parameters of a planar arm's initial state: refused for a spatial arm unless left at
their defaults."""


def _spatial_start(values, arm):
    """
    Return q(0) of a spatial arm (``task_dim`` 3), or raise naming the parameter.

    ``initial_joint_positions`` (n angles, base to tip) is required and each angle must lie
    within its joint's URDF position limits; the planar initial-state parameters
    (``PLANAR_ONLY``) must be at their defaults.
    """
    spatial = arm.spatial
    for name in PLANAR_ONLY:
        given, default = values[name], SCHEMA[name].default
        if (list(given) != list(default) if isinstance(default, list)
                else given != default):
            raise FreejointValueError(
                f'{name}: planar arms only (task_dim 2), got {given!r} for a '
                'spatial arm; it starts at initial_joint_positions')
    q0 = _initial_joints(values['initial_joint_positions'], spatial)
    if q0 is None:
        raise FreejointValueError(
            f'initial_joint_positions: a spatial arm (task_dim 3) starts at its {spatial.n} '
            f'joint angles [rad] {list(spatial.joint_names)}, got none')
    for name, q, lo, hi in zip(spatial.joint_names, q0, spatial.lower, spatial.upper):
        if not lo <= q <= hi:
            raise FreejointValueError(
                f'initial_joint_positions: {name} = {q!r} rad is outside its URDF limits '
                f'[{float(lo)!r}, {float(hi)!r}] rad')
    return q0


def build(values):
    """
    Return the :class:`Config` of a complete, valid parameter dict.

    The initial state may still be unreachable: raises naming ``initial_position``.
    """
    arm = resolve_arm(values)
    params = arm.params
    joint_names, joints = _joints(values, arm)
    active_names = [joint_names[i] for i in params.active]
    dt = float(values['control_period'])
    if arm.spatial is not None:
        q0 = _spatial_start(values, arm)
    else:
        if values['passive_damping'] != 0.0:
            raise FreejointValueError(
                'passive_damping: spatial arms only (task_dim 3), got '
                f"{values['passive_damping']!r} N m s/rad for a planar arm (its plants "
                "integrate the paper's frictionless free joint)")
        q0 = _planar_start(values, arm)
    return Config(values=dict(values), params=params, arm=arm,
                  q0=tuple(float(v) for v in q0), joint_names=joint_names, joints=joints,
                  cmd_to_active=tuple(active_names.index(name) for name in joints),
                  lockstep=values['mode'] == 'lockstep', dt=dt, dt_ns=round(dt * 1e9),
                  publish_every=_publish_every(values['publish_rate'], dt),
                  clock_every=_clock_every(values['clock_rate'], dt))


def _planar_start(values, arm):
    """Return q(0) of a planar arm (Table I or URDF), or raise naming the parameter."""
    params = arm.params
    passive = float(values['initial_passive_deg'])
    q0 = _initial_joints(values['initial_joint_positions'], params)
    if q0 is not None:
        q0 = list(arm.to_model(q0))       # given as the joints measure them
    if values['start_pose'] == 'hanging':
        q0 = _hanging(values, params, q0)
    if q0 is None and (params.r != 2 or params.p != 1):
        raise FreejointValueError(
            f'initial_joint_positions: the arm has {params.r} active and {params.p} passive '
            f'joints: initial_position and initial_passive_deg need 2 and 1; give the '
            f'{params.n} joint angles')
    if q0 is None:
        try:
            offsets = arm.joint_offsets or (0.0,) * params.n
            q0 = ArmModel(params).ik(tuple(values['initial_position']),
                                     [math.radians(passive) + offsets[params.passive[0]]],
                                     branch=1)
        except FreejointValueError as exc:
            raise FreejointValueError(
                f'initial_position: unreachable with initial_passive_deg = '
                f'{values["initial_passive_deg"]}: {exc}') from None
    return q0


SCHEMA = Schema(PARAMS, CHECKS, build)
SPECS = SCHEMA.params
build_config = SCHEMA.config
