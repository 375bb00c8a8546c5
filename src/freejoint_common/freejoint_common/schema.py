"""
Declarative parameter schemas of the freejoint nodes (plain Python, no ROS).

As ros2_controllers' generate_parameter_library YAML: one :class:`Param` per parameter
(name, default, description, bounds, read-only, validator) and one :class:`Schema` per
node (its params, the cross-parameter checks and the function building the node's
config object from a complete, valid ``{name: value}`` dict). The node's loader
(``freejoint_common.node_tools.NodeParameters``) declares every entry with its
``ParameterDescriptor``, validates at start-up and in the set-parameters callback with the
reason :meth:`Schema.reason` gives, and hands the node the built config; the demo and the
tests build the same config from a YAML file (:meth:`Schema.from_yaml`) without ROS.

Validators: a function ``value -> reason or None``; the reason is prefixed with the
parameter's name. A validator may also raise ``FreejointValueError`` with a message that
already starts with the name. A schema-level check is a function ``values -> reason or
None`` whose reason names the parameter to change itself.
"""

from dataclasses import dataclass, field
import math

from freejoint_common.scheduling import MAX_PRIORITY, validate_affinity, validate_priority
from freejoint_core.arm import CASES, DEFAULT_DT, NOMINAL_SCALE as PAPER_NOMINAL_SCALE
from freejoint_core.errors import FreejointValueError


@dataclass(frozen=True)
class Param:
    """
    One parameter: name, default, description, optional (min, max), read-only, validator.

    The type is the default's (bool, int, float, str or a list of one of them); an int
    default with bounds gets an integer range, a float one a floating-point range (both
    inclusive, as ``ParameterDescriptor`` ranges; ``exclusive_min`` refuses the lower bound
    itself, with the reason). A default of None declares an empty
    integer array (rclpy cannot declare an empty typed array with a default): the node
    reads None, ``ros2 param get`` / ``dump`` show ``[]``. ``follows``: a callable of the
    other parameters' values giving the value in use when this one is not given (the
    joints of the arm's URDF); the node declares it with that value, so a read-back tells
    what the node uses (``default`` is the paper arm's, the one documented).
    """

    name: str
    default: object
    description: str
    bounds: tuple = None
    read_only: bool = False
    validator: object = None
    exclusive_min: bool = False
    follows: object = field(default=None, compare=False)

    def reason(self, value):
        """Return why ``value`` is not valid for this parameter (naming it), or None."""
        problem = _type_problem(self.default, value)
        if problem is None and self.validator is not None:
            try:
                problem = self.validator(value)
            except FreejointValueError as exc:
                return str(exc)
        if (problem is None and isinstance(self.default, float)
                and not math.isfinite(value)):
            problem = f'expected a finite number, got {value}'
        if problem is None and self.bounds is not None and not isinstance(value, list):
            lo, hi = self.bounds[:2]
            if value < lo or (self.exclusive_min and value <= lo) or value > hi:
                low = '(' if self.exclusive_min else '['
                problem = f'expected a value in {low}{lo:.6g}, {hi:.6g}], got {value:g}'
        return None if problem is None else f'{self.name}: {problem}'


Spec = Param
"""One parameter entry (the name the nodes' schemas used before :class:`Param`)."""


def unique_names(name, value):
    """Return ``value`` as a tuple of unique non-empty names, or raise naming ``name``."""
    names = tuple(value)
    if not names or any(not isinstance(v, str) or not v for v in names):
        raise FreejointValueError(f'{name}: expected non-empty joint names, got {list(names)}')
    if len(set(names)) != len(names):
        raise FreejointValueError(f'{name}: joint names must be unique, got {list(names)}')
    return names


def _type_problem(default, value):
    """Return why ``value`` is not of the type of ``default``, or None."""
    if default is None:
        if value is None or (isinstance(value, (list, tuple)) and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value)):
            return None
        return f'expected a list of integers, got {value!r}'
    if isinstance(default, bool):
        return None if isinstance(value, bool) else f'expected true or false, got {value!r}'
    if isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
        return None if ok else f'expected an integer, got {value!r}'
    if isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        return None if ok else f'expected a number, got {value!r}'
    if isinstance(default, str):
        return None if isinstance(value, str) else f'expected a string, got {value!r}'
    if not isinstance(value, (list, tuple)):
        return f'expected a list, got {value!r}'
    return None


def above(lower, unit=''):
    """Return a validator: a number strictly above ``lower``."""
    def check(value):
        if not value > lower:
            return f'must be > {lower:g}{unit}, got {value}'
        return None
    return check


def one_of(choices):
    """Return a validator: one of ``choices``."""
    def check(value):
        if value not in choices:
            return f'expected one of {tuple(choices)}, got {value!r}'
        return None
    return check


def raises(func):
    """Return a validator of a function raising ``FreejointValueError`` naming the parameter."""
    def check(value):
        func(value)
        return None
    return check


class ParameterValues:
    """
    A node's config: what ``build`` derived (its fields), and every parameter by name.

    Mixed into a config dataclass that has a ``values`` field (the validated
    ``{name: value}`` dict): ``config.<name>`` is the field of that name if the config
    has one, else the parameter's value, as generate_parameter_library's ``params.<name>``.
    A parameter the node reads as it is needs no field: its schema entry and its use.
    """

    def __getattr__(self, name):
        """Return the value of the parameter ``name`` (no field of that name)."""
        values = self.__dict__.get('values')
        if values is not None and name in values:
            return values[name]
        raise AttributeError(f'{type(self).__name__} has no field or parameter {name!r}')


@dataclass(frozen=True)
class LoopConfig(ParameterValues):
    """
    What the configs of the control loop's nodes (simulator, controller) both derive.

    Attributes
    ----------
    values : dict
        The validated ``{name: value}`` dict (``config.<name>`` of any parameter).
    joint_names : tuple of str
        All joints of the arm in model order (base to tip), passive ones included.
    joints : tuple of str
        The commanded (active) joints in the order of the effort command.
    lockstep : bool
        True: the deterministic lockstep loop; False: real time.
    dt : float
        Control period [s].
    dt_ns : int
        Control period [ns].

    """

    values: dict = field(repr=False, hash=False)
    joint_names: tuple
    joints: tuple
    lockstep: bool
    dt: float
    dt_ns: int


class Schema:
    """
    The parameters of one node: entries, cross-parameter checks, config builder.

    Parameters
    ----------
    params : iterable of Param or of iterables of Param
        The entries (groups shared by several nodes are spliced in).
    checks : sequence of callable, optional
        ``values -> reason or None``, run once every entry is valid.
    build : callable, optional
        ``values -> config`` for valid values (default: the values dict itself). It may
        still raise ``FreejointValueError`` naming a parameter (a check that needs the
        built objects, e.g. inverse kinematics of the initial state).

    """

    def __init__(self, params, checks=(), build=None):
        flat = []
        for item in params:
            flat.extend(item if isinstance(item, (tuple, list)) else (item,))
        self.params = tuple(flat)
        self.by_name = {p.name: p for p in self.params}
        if len(self.by_name) != len(self.params):
            names = [p.name for p in self.params]
            raise ValueError('parameters declared twice: %s'
                             % sorted({n for n in names if names.count(n) > 1}))
        self.checks = tuple(checks)
        self._build = build

    def __iter__(self):
        """Iterate over the entries."""
        return iter(self.params)

    def __contains__(self, name):
        """Return True if ``name`` is a parameter of the schema."""
        return name in self.by_name

    def __getitem__(self, name):
        """Return the entry named ``name``."""
        return self.by_name[name]

    def defaults(self):
        """Return ``{name: default}`` (lists copied)."""
        return {p.name: list(p.default) if isinstance(p.default, (list, tuple)) else p.default
                for p in self.params}

    def values(self, given=None):
        """Return the defaults updated with ``given``; an unknown name raises naming it."""
        values = self.defaults()
        for name, value in (given or {}).items():
            if name not in self.by_name:
                raise FreejointValueError(f'{name}: not a parameter of this node')
            values[name] = value
        return values

    def reason(self, values):
        """
        Return why ``values`` are not valid (naming the parameter), or None.

        Only the entries present in ``values`` are checked; the cross-parameter checks run
        when every entry is present.
        """
        for name, value in values.items():
            param = self.by_name.get(name)
            if param is not None:
                problem = param.reason(value)
                if problem is not None:
                    return problem
        if len(values) < len(self.params) or any(n not in values for n in self.by_name):
            return None
        for check in self.checks:
            try:
                problem = check(values)
            except FreejointValueError as exc:
                return str(exc)
            if problem:
                return problem
        return None

    def config(self, values):
        """Validate a complete ``values`` dict and build the config; raise naming the parameter."""
        missing = [n for n in self.by_name if n not in values]
        if missing:
            raise FreejointValueError(f'{missing[0]}: no value given')
        problem = self.reason(values)
        if problem:
            raise FreejointValueError(problem)
        return dict(values) if self._build is None else self._build(values)

    def yaml_values(self, *paths, node='/**'):
        """
        Return the values a node started with ``--params-file`` ``paths`` takes.

        The defaults overlaid with the ``ros__parameters`` of each file in turn (a later file
        overrides an earlier one, as repeated ``--params-file`` arguments do). ``node`` is the
        files' top-level key (``/**`` matches every node); names the schema does not have
        (``use_sim_time``, ``qos_overrides``) are ignored. Not validated (see :meth:`config`).
        """
        import yaml
        values = self.defaults()
        for path in paths:
            with open(path) as fh:
                doc = yaml.safe_load(fh) or {}
            given = (doc.get(node) or {}).get('ros__parameters') or {}
            values.update({k: v for k, v in given.items() if k in self})
        return values

    def overrides(self, path, node='/**'):
        """
        Return the ``-p`` items (``name:=value``) of what a parameter file sets.

        Those of its values (:meth:`yaml_values`) that differ from the defaults, in ros2's
        ``--ros-args -p`` form (``true`` / ``false`` for booleans): a file's settings
        given to a node started without it.
        """
        defaults = self.defaults()
        items = []
        for name, value in self.yaml_values(path, node=node).items():
            if value != defaults[name]:
                text = ('true' if value else 'false') if isinstance(value, bool) else str(value)
                items.append('%s:=%s' % (name, text))
        return items

    def from_yaml(self, *paths, node='/**'):
        """Return the config of ``--params-file`` YAML files (defaults for what they omit)."""
        return self.config(self.yaml_values(*paths, node=node))


SCHEDULING = (
    Param('thread_priority', 0,
          'SCHED_FIFO priority (1..%d) of every thread of this process (executor and '
          'middleware threads), as the controller_manager thread_priority of ros2_control; '
          '0 = the default scheduler. Needs root, CAP_SYS_NICE or an rtprio limit: refused '
          'with the reason otherwise' % MAX_PRIORITY, (0, MAX_PRIORITY),
          validator=raises(validate_priority)),
    Param('cpu_affinity', None,
          'CPUs every thread of this process may run on (integer array, e.g. [1]); not set = '
          'every CPU the process started with', validator=raises(validate_affinity)),
)
"""Real-time scheduling parameters (``freejoint_common.scheduling``) of a node process."""

EXECUTOR = Param('executor', 'single_threaded',
                 "rclpy executor: 'single_threaded' or 'events' "
                 '(rclpy.experimental.EventsExecutor)', read_only=True,
                 validator=one_of(('single_threaded', 'events')))
"""The executor the node runs on (sim, controller)."""


# -- entries shared by several nodes (one default, one description, one check) ------------
def _whole_ns(value):
    if abs(value * 1e9 - round(value * 1e9)) > 1e-3:
        return f'{value:g} s is not a whole number of nanoseconds'
    return None


def _frame(value):
    return None if value.strip() else 'expected a frame name, got an empty string'


CASE = Param('case', CASES[0],
             "arm case (Table I): 'horizontal' (no gravity) or 'vertical' (9.81 m/s^2 along "
             '-y)', validator=one_of(CASES))
"""The arm's case (sim: the real arm; controller, planner: the nominal model's)."""
NOMINAL_SCALE = Param('nominal_scale', PAPER_NOMINAL_SCALE,
                      'nominal model = Table I real parameters with masses, inertias and COM '
                      'distances times this factor (paper: %g); the controller and the planner '
                      'must use the same' % PAPER_NOMINAL_SCALE, (0.01, 100.0))
"""The nominal model of the controller's law and of the planner's singularity map."""
CONTROL_PERIOD = Param('control_period', DEFAULT_DT,
                       'control period dt [s]: the lockstep grid t_k = k dt, the step of the '
                       'simulator, the adaptation update, the setpoint stamps; the same for '
                       'every node', (1e-5, 1.0), read_only=True, validator=_whole_ns)
"""The control grid every node of the graph shares."""
FRAME_ID = Param('frame_id', 'base_link',
                 'frame of the arm base: of ee_position (sim), of the setpoints, map and '
                 'marker (planner)', validator=_frame)


# -- the null space of the law (controller: the law's; planner: its nominal closed loop) --
NULLSPACE_MAX = 1e4
"""[N m s/rad, N m/rad] Upper bound of a null-space damping or posture stiffness."""
_NULLSPACE_TEXT = {
    'nullspace_kd': 'null-space damping [N m s/rad] of the active joint rates when more '
                    'joints are driven than the task has (r > 2, '
                    "freejoint_core.internal.NullSpace); 0 = none (the paper's law exactly)",
    'nullspace_kd_joints': 'spatial law: null-space damping per active joint [N m s/rad] (r '
                           'values, the active joints base to tip), in place of nullspace_kd; '
                           '[0.0] (default) = nullspace_kd for every joint. fj arm init sets '
                           "it from the joints' effective inertia (freejoint_core.arm_gains)",
    'nullspace_kp': "null-space posture stiffness [N m/rad] of the spatial law (law 'spatial'): "
                    "the active joints are pulled to their angles at the law's first tick "
                    'after start-up or ~/reset, through the null space (the task untouched), so '
                    'that they do not drift over a long hold; 0 = none. Planar laws: must be 0',
}


def nullspace_dampings(value):
    """
    Return why ``value`` is not a list of null-space dampings, or None (``nullspace_kd_joints``).

    One or more finite numbers [N m s/rad], each in ``[0, NULLSPACE_MAX]``.
    """
    try:
        vals = [float(v) for v in value]
    except (TypeError, ValueError):
        return f'expected a list of numbers, got {value!r}'
    if not vals or not all(0.0 <= v <= NULLSPACE_MAX for v in vals):     # NaN fails too
        return f'expected one or more values in [0, {NULLSPACE_MAX:g}], got {vals}'
    return None


def nullspace_params(kd=0.0, kp=0.0, read_only=True, role=''):
    """
    Return the null-space parameters ``nullspace_kd``, ``nullspace_kd_joints``, ``nullspace_kp``.

    One declaration (bounds, check, meaning) for the controller, whose law runs with them,
    and the planner, whose nominal closed loop of a spatial plan must run with the same.

    Parameters
    ----------
    kd, kp : float
        Defaults of ``nullspace_kd`` [N m s/rad] and ``nullspace_kp`` [N m/rad].
    read_only : bool
        Declared read-only (the controller's: its law is built at start-up).
    role : str
        What the node does with them, put before the meaning (the planner's).

    """
    def text(name):
        return role + _NULLSPACE_TEXT[name]
    return (Param('nullspace_kd', float(kd), text('nullspace_kd'), (0.0, NULLSPACE_MAX),
                  read_only=read_only),
            Param('nullspace_kd_joints', [0.0], text('nullspace_kd_joints'),
                  read_only=read_only, validator=nullspace_dampings),
            Param('nullspace_kp', float(kp), text('nullspace_kp'), (0.0, NULLSPACE_MAX),
                  read_only=read_only))


def nullspace_kd(values):
    """
    Return the null-space damping in use: ``nullspace_kd_joints`` (a tuple), or ``nullspace_kd``.

    ``nullspace_kd_joints: [0.0]`` (its default) means ``nullspace_kd`` for every joint (a
    float); a mapping without it reads as that default.
    """
    per_joint = tuple(float(v) for v in values.get('nullspace_kd_joints', (0.0,)))
    return float(values.get('nullspace_kd', 0.0)) if per_joint == (0.0,) else per_joint


def nullspace_options(values):
    """
    Return the null-space options of ``make_law`` a node's parameters give (none at rest).

    ``nullspace_kd`` (:func:`nullspace_kd`: per joint or for all) when not 0,
    ``nullspace_kp`` when not 0: a law with a null space takes them, one without refuses
    them on an arm with joints to spare.
    """
    out = {}
    kd = nullspace_kd(values)
    if kd != 0.0:
        out['nullspace_kd'] = kd
    kp = float(values.get('nullspace_kp', 0.0))
    if kp != 0.0:
        out['nullspace_kp'] = kp
    return out
