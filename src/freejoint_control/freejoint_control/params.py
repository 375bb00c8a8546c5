"""
Parameters of the controller node: declaration table and validation (no ROS types).

``SPECS`` lists every parameter once (name, default, description, scalar range,
read-only).  :func:`build_config` turns a complete ``{name: value}`` dict into a
validated :class:`Config` or raises ``FreejointValueError`` naming the parameter, so
the node uses the same check at start-up and in its set-parameters callback.

"""

from dataclasses import dataclass

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
    Spec('tau_limit', 0.0,
         'per-joint torque limit [N m] applied to every active joint; 0 = no limit',
         (0.0, 1e6)),
    Spec('stale_timeout', 0.5,
         'wall time [s] without a fresh state or setpoint after which zero effort is '
         'commanded', (1e-3, 3600.0)),
    Spec('executor', 'single_threaded',
         "rclpy executor: 'single_threaded' or 'events' (rclpy.experimental.EventsExecutor)",
         read_only=True),
) + SCHEDULING_SPECS

DEFAULTS = {s.name: s.default for s in SPECS}
EXECUTORS = ('single_threaded', 'events')


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
    limit = float(values['tau_limit'])
    if limit < 0.0:
        raise FreejointValueError(f'tau_limit: must be >= 0 (0 = no limit), got {limit}')
    try:
        gains = Gains(K=tuple(values['K']), Lam=tuple(values['Lambda']), R=tuple(values['R']),
                      Gamma=tuple(values['Gamma']), sigma=tuple(values['sigma']),
                      eps=values['epsilon'], h_form=values['h_form'],
                      theta0=tuple(values['theta0']), robust=bool(values['robust']),
                      det_threshold=values['det_threshold'],
                      tau_limit=limit if limit > 0.0 else None)
    except FreejointValueError as exc:
        raise FreejointValueError(_ros_names(str(exc))) from None
    dt = float(values['control_period'])
    if not dt > 0.0:
        raise FreejointValueError(f'control_period: must be > 0, got {dt}')
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
                  executor=values['executor'])


def _ros_names(text):
    """Name the parameter as the node calls it (core field Lam is Lambda, eps is epsilon)."""
    for core, ros in (('Lam:', 'Lambda:'), ('eps:', 'epsilon:')):
        if text.startswith(core):
            return ros + text[len(core):]
    return text
