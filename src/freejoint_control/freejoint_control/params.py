"""
Parameters of the controller node: declaration table and validation (no ROS types).

``SPECS`` lists every parameter once (name, default, description, scalar range,
read-only).  :func:`build_config` turns a complete ``{name: value}`` dict into a
validated :class:`Config` or raises ``FreejointValueError`` naming the parameter, so
the node uses the same check at start-up and in its set-parameters callback.

"""

from dataclasses import dataclass
import math

from freejoint_common.node_tools import SCHEDULING_SPECS, Spec, unique_names
from freejoint_common.scheduling import validate_affinity, validate_priority
from freejoint_core.arm import ArmParams, table1
from freejoint_core.control import Gains
from freejoint_core.errors import FreejointValueError


SPECS = (
    Spec('case', 'horizontal',
         "arm case of the nominal model: 'horizontal' (no gravity) or 'vertical' (9.81)"),
    Spec('nominal_scale', 0.7,
         'nominal model = Table I real parameters with masses, inertias and COM distances '
         'times this factor (paper: 0.7)', (0.01, 100.0)),
    Spec('joint_names', ['joint1', 'joint2', 'joint3'],
         'names of all joints in model order (base to tip), passive ones included',
         read_only=True),
    Spec('joints', ['joint1', 'joint2'],
         'active joints in the order of the effort command (JointGroupEffortController)',
         read_only=True),
    Spec('control_period', 0.001,
         'control period dt [s] of the adaptation update and of the lockstep grid',
         (1e-5, 1.0), read_only=True),
    Spec('lockstep', True,
         'true: answer the state stamped t_k only with the setpoint stamped t_k; '
         'false (real time): with the newest setpoint stamped <= t_k + dt/2',
         read_only=True),
    Spec('K', [100.0, 100.0], 'diagonal of K (2 values > 0) [1/s]'),
    Spec('Lambda', [50.0, 50.0], 'diagonal of Lambda (2 values > 0) [1/s]'),
    Spec('R', [2.0, 2.0], 'diagonal of R (2 values > 0)'),
    Spec('Gamma', [0.01] * 5, 'diagonal of the adaptation gain Gamma (5 values >= 0)'),
    Spec('sigma', [0.1] * 5, 'diagonal of the sigma-modification (5 values >= 0)'),
    Spec('epsilon', 0.1, 'chattering bound epsilon of h_alpha (> 0)', (1e-12, 1e6)),
    Spec('h_form', 'sum',
         "h_alpha: 'sum' = ||a|| + epsilon (paper), 'sat' = max(||a||, epsilon)"),
    Spec('theta0', [0.0] * 5,
         'initial adaptive estimate theta_hat(0) (5 values >= 0); setting it restarts '
         'theta_hat from it'),
    Spec('robust', True, 'robust term and adaptation on (false: nominal inverse dynamics)'),
    Spec('det_threshold', 1e-7,
         '|det(Da Da^T)| below which the damped pseudo-inverse is used (> 0)', (1e-300, 1.0)),
    Spec('effort_limits', [300.0, 200.0],
         'per-joint torque limit [N m] (> 0, one per active joint in the order of joints); '
         'the paper runs peak at 13 / 11 (horizontal) and 133 / 74 (vertical)'),
    Spec('effort_rate_limit', 20000.0,
         'largest torque change [N m/s] per joint after a (re)start, a hold, a reset or a '
         'zero-effort answer, until the command has caught up with the law', (1.0, 1e9)),
    Spec('stale_timeout', 0.5,
         'wall time [s] (lockstep) or state-stamp time (real time) without a fresh setpoint '
         'after which the controller holds (or commands zero, see on_stale_setpoint); wall '
         'time without a state after which zero effort is commanded', (1e-3, 3600.0)),
    Spec('on_stale_setpoint', 'hold',
         "no fresh setpoint: 'hold' the end effector where it is (full law, gravity "
         "included) or command 'zero' effort"),
    Spec('resume_time', 0.5,
         'time [s of state stamps] of the quintic blend from the hold to the streamed '
         'setpoint (0: switch at once)', (0.0, 60.0)),
    Spec('hold_stiffness', 2.0,
         'K and Lambda are multiplied by this while holding (and brought back to 1 over '
         'the resume blend): the static error of the law against the error of the nominal '
         'model, e.g. its 70 % gravity, is 1 / (K Lambda), so 2 quarters the sag of a held '
         'arm; 1 = the gains of the paper throughout; hold_stiffness * (K + Lambda) * '
         'control_period <= 1', (1.0, 10.0)),
    Spec('resume_max_velocity', 1.0,
         'bound [m/s] on the peak speed of the blend: a larger offset blends for longer '
         'than resume_time (1.875 offset / resume_max_velocity)', (1e-3, 100.0)),
    Spec('resume_max_acceleration', 5.0,
         'bound [m/s^2] on the peak acceleration of the blend: a larger offset blends for '
         'longer than resume_time (sqrt(5.77 offset / resume_max_acceleration))', (1e-3, 1e4)),
    Spec('max_state_age', 0.1,
         'real time: a state older than this [s] when it is taken (a backlog after a stall '
         'or at start-up) is skipped without a command (0 = never skip)', (0.0, 3600.0)),
    Spec('carry_forward_time', 0.02,
         'real time: a late setpoint (older than the state) is carried forward along its '
         'velocity and acceleration for at most this long [s]; older, the controller holds '
         '(with on_stale_setpoint: hold)', (0.0, 3600.0)),
    Spec('theta_max', [100.0] * 5,
         'element-wise bound of theta_hat (5 values > 0, <= 1e6), clamped inside the update'),
    Spec('joint_position_lower', [-1000.0, -1000.0, -1000.0],
         'plausible joint positions [rad], lower bound per joint of joint_names'),
    Spec('joint_position_upper', [1000.0, 1000.0, 1000.0],
         'plausible joint positions [rad], upper bound per joint of joint_names'),
    Spec('joint_velocity_limit', [100.0, 100.0, 100.0],
         'plausible joint speed [rad/s] per joint of joint_names (> 0)'),
    Spec('setpoint_max_velocity', 5.0, 'largest plausible setpoint speed [m/s]',
         (1e-6, 1e3)),
    Spec('setpoint_max_acceleration', 50.0,
         'largest plausible setpoint acceleration [m/s^2]', (1e-6, 1e5)),
    Spec('delay_compensation', 'off',
         "'off' or 'predict' (real time only): the law runs on the state predicted with the "
         'nominal model (freejoint_core.delay.StatePredictor) to when the command takes '
         'effect, ceil(state age / control_period) periods (at least 1) ahead'),
    Spec('executor', 'single_threaded',
         "rclpy executor: 'single_threaded' or 'events' (rclpy.experimental.EventsExecutor)",
         read_only=True),
) + SCHEDULING_SPECS

DEFAULTS = {s.name: s.default for s in SPECS}
EXECUTORS = ('single_threaded', 'events')
ON_STALE = ('hold', 'zero')
DELAY_COMPENSATION = ('off', 'predict')
GAIN_MAX = {'K': 1e4, 'Lambda': 1e4, 'R': 1e3, 'Gamma': 1e3, 'sigma': 1e3}
"""Upper bounds of the gain vectors (K, Lambda in 1/s; beyond them the law is meaningless
at any control rate this node runs; (K + Lambda) * control_period <= 1 is checked too)."""
THETA_MAX_MAX = 1e6
"""Upper bound of theta_max (and so of theta0)."""


@dataclass(frozen=True)
class Config:
    """Validated controller configuration."""

    nominal: ArmParams
    gains: Gains
    joint_names: tuple
    joints: tuple
    cmd_index: tuple
    dt: float
    dt_ns: int
    lockstep: bool
    stale_timeout: float
    executor: str
    effort_limits: tuple
    effort_rate_limit: float
    on_stale_setpoint: str
    resume_time: float
    hold_stiffness: float
    resume_max_velocity: float
    resume_max_acceleration: float
    carry_forward_time: float
    max_state_age: float
    position_lower: tuple
    position_upper: tuple
    velocity_limit: tuple
    reach: float
    setpoint_max_velocity: float
    setpoint_max_acceleration: float
    delay_compensation: str


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
    nominal = table1(values['case'])
    try:
        nominal = nominal.scaled(values['nominal_scale'])
    except FreejointValueError as exc:
        raise FreejointValueError('nominal_' + str(exc)) from None
    joint_names = unique_names('joint_names', values['joint_names'])
    if len(joint_names) != nominal.n:
        raise FreejointValueError(
            f'joint_names: the arm has {nominal.n} joints, got {len(joint_names)} names')
    joints = unique_names('joints', values['joints'])
    active_names = [joint_names[i] for i in nominal.active]
    if sorted(joints) != sorted(active_names):
        raise FreejointValueError(
            f'joints: expected the {nominal.r} active joints {active_names} in any order, '
            f'got {list(joints)}')
    cmd_index = tuple(active_names.index(name) for name in joints)
    if values['h_form'] not in ('sum', 'sat'):
        raise FreejointValueError(f"h_form: expected 'sum' or 'sat', got {values['h_form']!r}")
    dt = float(values['control_period'])
    if not dt > 0.0:
        raise FreejointValueError(f'control_period: must be > 0, got {dt}')
    for name, upper in GAIN_MAX.items():
        vals = _floats(name, values[name])
        if any(v > upper for v in vals):
            raise FreejointValueError(f'{name}: values must be <= {upper:g}, got {vals}')
    for i, (k, lam) in enumerate(zip(_floats('K', values['K']),
                                     _floats('Lambda', values['Lambda']))):
        if (k + lam) * dt > 1.0:
            raise FreejointValueError(
                f'K: K[{i}] + Lambda[{i}] = {k + lam:g} 1/s is beyond 1 / control_period = '
                f'{1.0 / dt:g} 1/s (the discrete loop would be unstable)')
    stiff = float(values['hold_stiffness'])
    if not 1.0 <= stiff <= 10.0:
        raise FreejointValueError(f'hold_stiffness: must be in [1, 10], got {stiff}')
    for i, (k, lam) in enumerate(zip(_floats('K', values['K']),
                                     _floats('Lambda', values['Lambda']))):
        if stiff * (k + lam) * dt > 1.0:
            raise FreejointValueError(
                f'hold_stiffness: {stiff:g} x (K[{i}] + Lambda[{i}]) = {stiff * (k + lam):g} '
                f'1/s is beyond 1 / control_period = {1.0 / dt:g} 1/s (the held loop would '
                f'be unstable)')
    theta_max = _floats('theta_max', values['theta_max'])
    if len(theta_max) != 5 or any(not 0.0 < v <= THETA_MAX_MAX for v in theta_max):
        raise FreejointValueError(
            f'theta_max: expected 5 values in (0, {THETA_MAX_MAX:g}], got {list(theta_max)}')
    theta0 = _floats('theta0', values['theta0'])
    if len(theta0) == 5 and any(t > m for t, m in zip(theta0, theta_max)):
        raise FreejointValueError(f'theta0: values must be <= theta_max {list(theta_max)}, '
                                  f'got {list(theta0)}')
    limits = _floats('effort_limits', values['effort_limits'])
    if len(limits) != len(joints) or any(not 0.0 < v <= 1e6 for v in limits):
        raise FreejointValueError(
            f'effort_limits: expected {len(joints)} values in (0, 1e6] N m (one per joint of '
            f'joints {list(joints)}), got {list(limits)}')
    core_limit = tuple(limits[joints.index(name)] for name in active_names)
    try:
        gains = Gains(K=tuple(values['K']), Lam=tuple(values['Lambda']), R=tuple(values['R']),
                      Gamma=tuple(values['Gamma']), sigma=tuple(values['sigma']),
                      eps=values['epsilon'], h_form=values['h_form'],
                      theta0=tuple(values['theta0']), robust=bool(values['robust']),
                      det_threshold=values['det_threshold'], tau_limit=core_limit,
                      theta_max=theta_max)
    except FreejointValueError as exc:
        raise FreejointValueError(_ros_names(str(exc))) from None
    if values['on_stale_setpoint'] not in ON_STALE:
        raise FreejointValueError(f'on_stale_setpoint: expected one of {ON_STALE}, got '
                                  f'{values["on_stale_setpoint"]!r}')
    rate = float(values['effort_rate_limit'])
    if not rate > 0.0:
        raise FreejointValueError(f'effort_rate_limit: must be > 0, got {rate}')
    resume = float(values['resume_time'])
    if not resume >= 0.0:
        raise FreejointValueError(f'resume_time: must be >= 0, got {resume}')
    comp = values['delay_compensation']
    if comp not in DELAY_COMPENSATION:
        raise FreejointValueError(
            f'delay_compensation: expected one of {DELAY_COMPENSATION}, got {comp!r}')
    if comp == 'predict' and bool(values['lockstep']):
        raise FreejointValueError(
            "delay_compensation: 'predict' is for real time (lockstep: false); in lockstep "
            'the simulator waits for the command, there is no delay to compensate')
    n = nominal.n
    lower = _floats('joint_position_lower', values['joint_position_lower'])
    upper = _floats('joint_position_upper', values['joint_position_upper'])
    vlim = _floats('joint_velocity_limit', values['joint_velocity_limit'])
    for name, vals in (('joint_position_lower', lower), ('joint_position_upper', upper),
                       ('joint_velocity_limit', vlim)):
        if len(vals) != n:
            raise FreejointValueError(f'{name}: expected {n} values (one per joint of '
                                      f'joint_names), got {list(vals)}')
    if any(not lo < hi for lo, hi in zip(lower, upper)):
        raise FreejointValueError(f'joint_position_upper: each bound must be above '
                                  f'joint_position_lower {list(lower)}, got {list(upper)}')
    if any(not v > 0.0 for v in vlim):
        raise FreejointValueError(f'joint_velocity_limit: values must be > 0, got {list(vlim)}')
    stale = float(values['stale_timeout'])
    if not stale > 0.0:
        raise FreejointValueError(f'stale_timeout: must be > 0, got {stale}')
    if values['executor'] not in EXECUTORS:
        raise FreejointValueError(
            f'executor: expected one of {EXECUTORS}, got {values["executor"]!r}')
    validate_priority(values['thread_priority'])
    validate_affinity(values['cpu_affinity'])
    return Config(nominal=nominal, gains=gains, joint_names=joint_names, joints=joints,
                  cmd_index=cmd_index, dt=dt, dt_ns=round(dt * 1e9),
                  lockstep=bool(values['lockstep']), stale_timeout=stale,
                  executor=values['executor'], effort_limits=limits, effort_rate_limit=rate,
                  on_stale_setpoint=values['on_stale_setpoint'], resume_time=resume,
                  hold_stiffness=stiff,
                  resume_max_velocity=float(values['resume_max_velocity']),
                  resume_max_acceleration=float(values['resume_max_acceleration']),
                  carry_forward_time=float(values['carry_forward_time']),
                  max_state_age=float(values['max_state_age']),
                  position_lower=lower, position_upper=upper, velocity_limit=vlim,
                  reach=float(sum(nominal.lengths)),
                  setpoint_max_velocity=float(values['setpoint_max_velocity']),
                  setpoint_max_acceleration=float(values['setpoint_max_acceleration']),
                  delay_compensation=comp)


def _floats(name, value):
    """Return ``value`` as a tuple of finite floats, or raise naming ``name``."""
    try:
        vals = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a list of numbers, got {value!r}') from None
    if not all(math.isfinite(v) for v in vals):
        raise FreejointValueError(f'{name}: values must be finite, got {list(vals)}')
    return vals


def _ros_names(text):
    """Name the parameter as the node calls it (core field Lam is Lambda, eps is epsilon)."""
    for core, ros in (('Lam:', 'Lambda:'), ('eps:', 'epsilon:')):
        if text.startswith(core):
            return ros + text[len(core):]
    return text
