"""
Parameters of the simulator node: declaration table and validation (no ROS types).

``SPECS`` lists every parameter once; :func:`build_config` turns a complete
``{name: value}`` dict into a validated :class:`Config` (real arm, initial state by the
active joints' inverse kinematics ``ArmModel.ik``, branch +1, command mapping) or raises
``FreejointValueError`` naming the parameter.

"""

from dataclasses import dataclass
import math

from freejoint_common.arm_description import ARM_SPECS, joint_list, PAPER_JOINTS, resolve_arm
from freejoint_common.node_tools import SCHEDULING_SPECS, Spec, unique_names
from freejoint_common.scheduling import validate_affinity, validate_priority
from freejoint_core.arm import ArmModel, ArmParams
from freejoint_core.errors import FreejointValueError

MODES = ('lockstep', 'realtime')
ENGINES = ('rk4', 'mujoco')
EXECUTORS = ('single_threaded', 'events')
MAX_DIST_BOUND = 10.0
"""Upper bound [N m] of ``dist_bound``: 20 times the paper's 0.5 N m and about the peak
actuator torque of the horizontal case (11 N m); a disturbance as large as what the
actuators give is no longer one a tracking law rejects."""
MAX_PASSIVE_DEG = 360.0
"""Upper bound [deg] of ``|initial_passive_deg|``: one turn (larger angles repeat it)."""
MAX_DIVERGENCE_SPEED = 1e5
"""Upper bound [rad/s] of ``divergence_speed``."""


SPECS = (
    Spec('case', 'horizontal',
         "arm case (Table I real parameters): 'horizontal' (no gravity) or 'vertical' "
         '(9.81 m/s^2 along -y); the gravity of a URDF arm unless gravity is set; takes '
         'effect on reset'),
) + ARM_SPECS + (
    Spec('engine', 'rk4',
         "plant: 'rk4' (classic RK4 at dt_sub: the closed-form 3-link model, Pinocchio's "
         "ABA for other URDF arms) or 'mujoco' (MuJoCo's RK4 on the URDF, "
         'freejoint_core.mujoco_plant); takes effect on reset'),
    Spec('mode', 'lockstep',
         "'lockstep': own /clock, advance one control period per command; 'realtime': "
         'step on the wall clock and apply the latest command', read_only=True),
    Spec('joint_names', list(PAPER_JOINTS),
         'names of all joints in model order (base to tip), passive ones included; left '
         "at this default with a URDF arm: the URDF's revolute joints", read_only=True),
    Spec('joints', ['joint1', 'joint2'],
         'active joints in the order of the effort command (JointGroupEffortController); '
         "left at this default with a URDF arm: the arm's active joints, base to tip",
         read_only=True),
    Spec('control_period', 0.001,
         'step [s]: one command and one disturbance draw are held over it (the lockstep '
         'grid; the wall-clock step in real time)', (1e-5, 1.0), read_only=True),
    Spec('dt_sub', 0.0005,
         'RK4 integration step [s]; control_period must be an integer multiple; takes '
         'effect on reset', (1e-7, 1.0)),
    Spec('publish_rate', 1000.0,
         'real time: rate [Hz] of joint_states and ee_position, at most the step rate '
         '1 / control_period and a divisor of it (500 with control_period 0.001: the '
         'states of a 500 Hz driver); lockstep publishes every step', (0.1, 1e5)),
    Spec('clock_rate', 0.0,
         'lockstep: rate [Hz] of /clock in sim time (like gazebo_ros publish_rate): /clock '
         'goes out on the steps that are multiples of 1 / (clock_rate * control_period), '
         'which must be an integer >= 1, and always at step 0 and at max_steps; the state '
         'goes out every step. 0 = every step. A node streaming ahead of a /clock every N '
         'steps (the planner) needs a lookahead of at least N - 1 steps',
         (0.0, 1e6)),
    Spec('dist_bound', 0.5,
         'bound [N m] of the uniform random joint disturbance (0 = off, at most %g); takes '
         'effect on reset' % MAX_DIST_BOUND, (0.0, MAX_DIST_BOUND)),
    Spec('seed', 0, 'seed of the disturbance generator (>= 0); takes effect on reset'),
    Spec('initial_position', [0.2, 0.0],
         'initial end-effector position [m] (x, y); with initial_passive_deg gives q(0) by '
         'inverse kinematics (branch +1), at rest; takes effect on reset'),
    Spec('initial_passive_deg', 120.0,
         'initial passive joint angle [deg], within one turn; takes effect on reset',
         (-MAX_PASSIVE_DEG, MAX_PASSIVE_DEG)),
    Spec('initial_joint_positions', '',
         "q(0) [rad], every joint base to tip, as space-separated numbers (e.g. '0 1.0 1.4 "
         "2.2'), instead of initial_position and initial_passive_deg (which need an arm "
         "with one passive and two active joints); '' = those; takes effect on reset"),
    Spec('command_timeout', 0.5,
         'wall time [s] without a command after which zero effort is applied (and a '
         'warning given); lockstep: per step, after the first command', (1e-3, 3600.0)),
    Spec('start_braked', True,
         'real time: hold the arm at q(0) at rest (brakes engaged: no integration, the '
         'states still published at publish_rate) until the first accepted command, and '
         'again after ~/reset until the next one; false = the arm moves (a vertical arm '
         'falls) from the first step. Lockstep waits for the first command anyway'),
    Spec('brake_timeout', 0.05,
         'real time: no command for this long [s] after the last one engages the brakes, '
         'as a drive watchdog does: the arm stops where it is (every joint, the passive one '
         'included) and is held until the next accepted command; 0 = never (the last '
         'command is applied until command_timeout, then zero effort)', (0.0, 3600.0)),
    Spec('divergence_speed', 1000.0,
         'a joint speed above this [rad/s] (or a non-finite state, or an angle beyond 1e6 '
         'rad) is a diverged plant: the simulator stops integrating, publishes its last '
         'sane state and reports ERROR on /diagnostics until ~/reset',
         (1.0, MAX_DIVERGENCE_SPEED)),
    Spec('max_steps', 0,
         'lockstep: once step max_steps is published the simulator holds (no further '
         'step, no further message; later commands are ignored); 0 = run until stopped. '
         'A run of N control ticks uses N (the state at t = N dt is the last one)'),
    Spec('frame_id', 'base_link', 'frame of ee_position and of the arm base'),
    Spec('executor', 'single_threaded',
         "rclpy executor: 'single_threaded' or 'events' (rclpy.experimental.EventsExecutor)",
         read_only=True),
    Spec('timing_file', '',
         'measurement (bench/graph.py): path of a .npz file of per-step wall times (state '
         "publication, receipt of the command answering it); '' = off", read_only=True),
    Spec('timing_steps', 0,
         'measurement: steps recorded in timing_file (arrays preallocated; the file is '
         'written when they are full, or at shutdown)', read_only=True),
) + SCHEDULING_SPECS


@dataclass(frozen=True)
class Config:
    """Validated simulator configuration."""

    params: ArmParams
    arm: object
    engine: str
    q0: tuple
    joint_names: tuple
    joints: tuple
    cmd_to_active: tuple
    lockstep: bool
    dt: float
    dt_ns: int
    dt_sub: float
    publish_every: int
    dist_bound: float
    seed: int
    command_timeout: float
    frame_id: str
    executor: str
    timing_file: str = ''
    timing_steps: int = 0
    max_steps: int = 0
    clock_every: int = 1
    start_braked: bool = True
    divergence_speed: float = 1000.0
    brake_timeout: float = 0.05


def _multiple(name, big, small):
    """Return big / small if it is a positive integer (within 1e-9 relative), else raise."""
    n = round(big / small)
    if n < 1 or abs(n * small - big) > 1e-9 * big:
        raise FreejointValueError(name)
    return n


def _clock_every(rate, dt):
    """Return the steps from one /clock to the next for ``clock_rate`` (0: every step)."""
    rate = float(rate)
    if not (math.isfinite(rate) and rate >= 0.0):
        raise FreejointValueError(f'clock_rate: must be >= 0 Hz (0 = every step), got {rate}')
    if rate == 0.0:
        return 1
    step_rate = 1.0 / dt
    if rate > step_rate * (1.0 + 1e-9):
        raise FreejointValueError(f'clock_rate: {rate:g} Hz is above the step rate '
                                  f'{step_rate:g} Hz (1 / control_period)')
    return _multiple(f'clock_rate: {rate:g} Hz does not divide the step rate {step_rate:g} '
                     'Hz (1 / (clock_rate * control_period) must be an integer)', 1.0 / rate, dt)


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


def build_config(values):
    """
    Validate a complete parameter dict; return the :class:`Config`.

    Parameters
    ----------
    values : dict
        One value per name of ``SPECS``.

    Returns
    -------
    Config

    Raises
    ------
    FreejointValueError
        The message starts with the offending parameter's name.

    """
    arm = resolve_arm(values)
    params = arm.params
    if values['engine'] not in ENGINES:
        raise FreejointValueError(
            f'engine: expected one of {ENGINES}, got {values["engine"]!r}')
    if values['mode'] not in MODES:
        raise FreejointValueError(f'mode: expected one of {MODES}, got {values["mode"]!r}')
    joint_names = unique_names('joint_names', joint_list(
        'joint_names', values['joint_names'], arm, PAPER_JOINTS, arm.joint_names))
    if len(joint_names) != params.n:
        raise FreejointValueError(
            f'joint_names: the arm has {params.n} joints, got {len(joint_names)} names')
    joints = unique_names('joints', joint_list('joints', values['joints'], arm,
                                               ('joint1', 'joint2'), arm.active_names))
    active_names = [joint_names[i] for i in params.active]
    if sorted(joints) != sorted(active_names):
        raise FreejointValueError(
            f'joints: expected the {params.r} active joints {active_names} in any order, '
            f'got {list(joints)}')
    dt = float(values['control_period'])
    dt_sub = float(values['dt_sub'])
    if not (math.isfinite(dt) and dt > 0.0):
        raise FreejointValueError(f'control_period: must be > 0, got {dt}')
    if not (math.isfinite(dt_sub) and dt_sub > 0.0):
        raise FreejointValueError(f'dt_sub: must be > 0, got {dt_sub}')
    _multiple(f'dt_sub: control_period {dt} s is not an integer multiple of dt_sub '
              f'{dt_sub} s', dt, dt_sub)
    rate = float(values['publish_rate'])
    if not (math.isfinite(rate) and rate > 0.0):
        raise FreejointValueError(f'publish_rate: must be > 0, got {rate}')
    if rate > (1.0 / dt) * (1.0 + 1e-9):
        raise FreejointValueError(f'publish_rate: {rate:g} Hz is above the step rate '
                                  f'{1.0 / dt:g} Hz (1 / control_period): no more states '
                                  'than steps')
    every = _multiple(f'publish_rate: {rate} Hz does not divide the step rate '
                      f'{1.0 / dt:g} Hz', 1.0 / rate, dt)
    clock_every = _clock_every(values['clock_rate'], dt)
    dist = float(values['dist_bound'])
    if not (math.isfinite(dist) and 0.0 <= dist <= MAX_DIST_BOUND):
        raise FreejointValueError(
            f'dist_bound: must be in [0, {MAX_DIST_BOUND:g}] N m (the paper: 0.5; the '
            f'horizontal case peaks near 11 N m of actuator torque), got {dist}')
    seed = values['seed']
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise FreejointValueError(f'seed: expected an integer >= 0, got {seed!r}')
    start = tuple(values['initial_position'])
    if len(start) != 2 or not all(isinstance(v, float) and math.isfinite(v) for v in start):
        raise FreejointValueError(
            f'initial_position: expected 2 finite numbers (x, y) [m], got {list(start)}')
    passive = float(values['initial_passive_deg'])
    if not (math.isfinite(passive) and abs(passive) <= MAX_PASSIVE_DEG):
        raise FreejointValueError(
            f'initial_passive_deg: must be within one turn, [-{MAX_PASSIVE_DEG:g}, '
            f'{MAX_PASSIVE_DEG:g}] deg, got {passive}')
    q0 = _initial_joints(values['initial_joint_positions'], params)
    if q0 is None and (params.r != 2 or params.p != 1):
        raise FreejointValueError(
            f'initial_joint_positions: the arm has {params.r} active and {params.p} passive '
            f'joints: initial_position and initial_passive_deg need 2 and 1; give the '
            f'{params.n} joint angles')
    if q0 is None:
        try:
            q0 = ArmModel(params).ik(start, [math.radians(passive)], branch=1)
        except FreejointValueError as exc:
            raise FreejointValueError(
                f'initial_position: unreachable with initial_passive_deg = '
                f'{values["initial_passive_deg"]}: {exc}') from None
    timeout = float(values['command_timeout'])
    if not (math.isfinite(timeout) and timeout > 0.0):
        raise FreejointValueError(f'command_timeout: must be > 0, got {timeout}')
    if values['executor'] not in EXECUTORS:
        raise FreejointValueError(
            f'executor: expected one of {EXECUTORS}, got {values["executor"]!r}')
    timing_steps = values['timing_steps']
    if isinstance(timing_steps, bool) or not isinstance(timing_steps, int) or not (
            0 <= timing_steps <= 10_000_000):
        raise FreejointValueError(
            f'timing_steps: expected an integer in [0, 10000000], got {timing_steps!r}')
    max_steps = values['max_steps']
    if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 0:
        raise FreejointValueError(
            f'max_steps: expected an integer >= 0 (0 = no limit), got {max_steps!r}')
    timing_file = str(values['timing_file'])
    if timing_file and timing_steps < 1:
        raise FreejointValueError('timing_steps: must be >= 1 when timing_file is set')
    speed = float(values['divergence_speed'])
    if not (math.isfinite(speed) and 1.0 <= speed <= MAX_DIVERGENCE_SPEED):
        raise FreejointValueError(
            f'divergence_speed: must be in [1, {MAX_DIVERGENCE_SPEED:g}] rad/s, got {speed}')
    braked = values['start_braked']
    if not isinstance(braked, bool):
        raise FreejointValueError(f'start_braked: expected true or false, got {braked!r}')
    brake_timeout = float(values['brake_timeout'])
    if not (math.isfinite(brake_timeout) and 0.0 <= brake_timeout <= 3600.0):
        raise FreejointValueError(
            f'brake_timeout: must be in [0, 3600] s (0 = never), got {brake_timeout}')
    validate_priority(values['thread_priority'])
    validate_affinity(values['cpu_affinity'])
    return Config(params=params, arm=arm, engine=values['engine'],
                  q0=tuple(float(v) for v in q0), joint_names=joint_names,
                  joints=joints,
                  cmd_to_active=tuple(active_names.index(name) for name in joints),
                  lockstep=values['mode'] == 'lockstep', dt=dt, dt_ns=round(dt * 1e9),
                  dt_sub=dt_sub, publish_every=every, dist_bound=dist, seed=seed,
                  command_timeout=timeout, frame_id=str(values['frame_id']),
                  executor=values['executor'], timing_file=timing_file,
                  timing_steps=timing_steps, max_steps=max_steps, clock_every=clock_every,
                  start_braked=braked, divergence_speed=speed,
                  brake_timeout=brake_timeout)
