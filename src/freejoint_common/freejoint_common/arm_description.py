"""
The arm a node works on: the paper's Table I arm, or a planar arm read from URDF.

The simulator, the controller and the planner take the arm from the same parameters
(``ARM_SPECS``), as ros2_control's controller_manager and robot_state_publisher take it:

* ``robot_description``: the URDF text, or ``description_file``: a path to it (not both);
* ``passive_joints``: the names of the free joints (a URDF has no such element);
* ``gravity``: the gravity vector in the URDF's base frame; ``[0, 0, 0]`` (default) takes
  the vector of the node's ``case`` (``horizontal``: ``0 0 -9.81``, ``vertical``:
  ``0 -9.81 0``, ``freejoint_core.urdf.GRAVITY_BY_CASE``). A zero vector loses no arm:
  gravity along the joint axes exerts no torque, so it is the horizontal case.

With none of them given (the defaults: no description, ``passive_joints = [joint3]``,
gravity from ``case``) the arm is ``freejoint_core.arm.table1(case)`` exactly as before
(the closed-form 3-link kernel; the lockstep graph equals the offline runner to 0 m).
Anything else is parsed by ``freejoint_core.urdf.parse_urdf`` (the shipped
``paper_arm.urdf`` when no description is given), which refuses an arm the core does not
model with one line naming the problem. :func:`resolve_arm` is plain Python (no ROS).
"""

import collections
from dataclasses import dataclass
import math
import os

from freejoint_common.schema import Param, Spec
from freejoint_core.arm import ArmParams, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.urdf import GRAVITY_BY_CASE, load_urdf, parse_urdf, SHIPPED
from freejoint_core.urdf import shipped_urdf_path

PAPER_JOINTS = ('joint1', 'joint2', 'joint3')
"""Joint names of the paper's arm (``paper_arm.urdf``), base to tip."""
PAPER_PASSIVE = ['joint3']
"""Passive joint of the paper's arm: the default of ``passive_joints``."""
PACKAGE_SCHEME = 'package://'
"""Prefix of a path in a ROS package's share directory (``package://<pkg>/<path>``)."""
ROBOT_DATA_PACKAGE = 'example-robot-data'
"""The package of the spatial example arms (ROS ``ros-jazzy-example-robot-data``, PyPI
``example-robot-data``: ``package://example-robot-data/robots/<arm>/urdf/<file>.urdf``)."""
NO_GRAVITY = [0.0, 0.0, 0.0]
"""Default of ``gravity``: take the vector of ``case``."""

ARM_SPECS = (
    Spec('robot_description', '',
         'URDF text of the arm (as robot_state_publisher and ros2_control take it): a '
         'planar serial chain of revolute joints about parallel axes, in its own frames '
         "(freejoint_core.urdf); '' = description_file, or the paper's "
         'Table I arm if that is empty too', read_only=True),
    Spec('description_file', '',
         "path of the arm's URDF, read at start-up (when robot_description is empty); "
         'package://<pkg>/<path> is share/<pkg>/<path> (the shipped ones: '
         'package://freejoint_description/urdf/paper_arm.urdf, four_link_arm.urdf)',
         read_only=True),
    Spec('passive_joints', list(PAPER_PASSIVE),
         'names of the passive (free, unactuated) joints of the arm; at least two joints '
         "stay active (the task is the end effector's x, y); the paper's arm: joint3",
         read_only=True),
    Spec('tip_link', '',
         'link of the URDF whose origin is the task point (the end effector), as '
         "kinematics_interface's tip; '' = the chain's last link (past the last revolute "
         'joint along a single fixed end-effector joint; sensor and camera branches are not '
         'the chain)', read_only=True),
    Spec('task_dim', 2,
         'task dimension m: 2 = a planar arm (x, y in the plane of its joint axes; the '
         'paper), 3 = a spatial arm (the tip position in the base frame, any serial URDF on '
         'Pinocchio: freejoint_core.spatial_model; needs robot_description or '
         'description_file and tip_link)', (2, 3), read_only=True),
    Spec('base_link', '',
         'spatial arms (task_dim 3): the link the chain starts from, fixed in the world, as '
         "kinematics_interface's base; '' = the URDF's root link", read_only=True),
    Spec('gravity', list(NO_GRAVITY),
         'gravity [m/s^2] in the base frame of the URDF, any direction (the task frame '
         'turns to put its in-plane part along -y, joint 1 then carries a zero-angle '
         'offset: freejoint_core.urdf); '
         '[0, 0, 0] = the vector of case (horizontal: 0 0 -9.81, vertical: 0 -9.81 0); a '
         'spatial arm (task_dim 3): [0, 0, 0] = 0 0 -9.81'),
)
"""The arm parameters, the same entries in every node that needs the arm."""


@dataclass(frozen=True)
class NodeArm:
    """
    The arm a node was configured with.

    Attributes
    ----------
    params : ArmParams or SpatialArm
        The real parameters (``table1(case)`` for the default arm); a spatial arm's
        ``SpatialArm`` (``n``, ``r``, ``active``, ``passive`` as ``ArmParams``).
    joint_names : tuple of str, (n,)
        All joints, base to tip (the order of the model).
    active_names : tuple of str, (r,)
        The active joints, base to tip.
    urdf_arm : UrdfArm or None
        The parsed description; None for the default arm (no URDF parsed).
    source : str
        What the arm was taken from, for the start-up line.
    spatial : SpatialArm or None
        The real spatial arm (``task_dim`` 3), None for a planar one.

    """

    params: ArmParams
    joint_names: tuple
    active_names: tuple
    urdf_arm: object
    source: str
    spatial: object = None

    @property
    def described(self):
        """Return True for an arm read from a URDF (planar or spatial), False for Table I."""
        return self.urdf_arm is not None or self.spatial is not None

    @property
    def task_dim(self):
        """Return the task dimension m (2: planar; 3: spatial, the tip position)."""
        return self.spatial.m if self.spatial is not None else 2

    def nominal(self, scale):
        """
        Return the nominal model at ``scale`` (masses, inertias, COM levers times it).

        ``ArmParams.scaled`` of a planar arm, ``SpatialArm.nominal`` of a spatial one (the
        last few kept: a parameter change that leaves them builds no model again).
        """
        if self.spatial is None:
            return self.params.scaled(scale)
        key = (id(self.spatial), float(scale))
        entry = _NOMINALS.get(key)      # holds the arm: its id is not reused while kept
        if entry is None:
            entry = _NOMINALS[key] = (self.spatial, self.spatial.nominal(scale))
            while len(_NOMINALS) > _KEEP:
                _NOMINALS.pop(next(iter(_NOMINALS)))
        return entry[1]

    @property
    def joint_offsets(self):
        """Offsets [rad] the core adds to the URDF's joint angles, (n,); () for none."""
        return self.urdf_arm.joint_offsets if self.urdf_arm is not None else ()

    def to_model(self, q):
        """Return the core's joint angles (tuple, (n,)) of measured ones (``UrdfArm.to_model``)."""
        return self.urdf_arm.to_model(q) if self.joint_offsets else tuple(q)

    def to_joints(self, q):
        """Return the measured joint angles (tuple, (n,)) of the core's (``UrdfArm.to_joints``)."""
        return self.urdf_arm.to_joints(q) if self.joint_offsets else tuple(q)

    def description(self):
        """
        Return the arm as a ``UrdfArm`` (the shipped ``paper_arm.urdf`` for the default).

        Raises
        ------
        FreejointValueError
            If the shipped URDF cannot be found or read.

        """
        if self.urdf_arm is not None:
            return self.urdf_arm
        gravity = -self.params.gravity
        case = 'vertical' if gravity else 'horizontal'
        return load_urdf(shipped_urdf_path('paper_arm'), PAPER_PASSIVE, GRAVITY_BY_CASE[case])


def _gravity(value, case):
    try:
        vec = [float(v) for v in value]
    except (TypeError, ValueError):
        raise FreejointValueError(
            f'gravity: expected 3 numbers [m/s^2] (x, y, z in the base frame), got '
            f'{value!r}') from None
    if len(vec) != 3 or not all(math.isfinite(v) for v in vec):
        raise FreejointValueError(
            f'gravity: expected 3 finite numbers [m/s^2] (x, y, z in the base frame), got '
            f'{vec}')
    if vec == NO_GRAVITY:
        return None, GRAVITY_BY_CASE[case]
    return vec, tuple(vec)


def resolve_arm(values):
    """
    Return the arm of the node's parameters (resolved once per distinct arm input).

    The arm of the last few distinct values of ``case`` and the ``ARM_SPECS`` entries is
    kept: the checks and the config builder of a schema, which each ask for the arm, and
    a parameter change that leaves the arm's parameters as they were, parse no URDF and
    build no model again.

    Parameters
    ----------
    values : dict
        ``case`` and the entries of ``ARM_SPECS``.

    Returns
    -------
    NodeArm

    Raises
    ------
    FreejointValueError
        One line naming the parameter (``robot_description: ...``,
        ``passive_joints: ...``, ...).

    """
    key = _arm_key(values)
    try:
        arm = _RESOLVED.get(key)
    except TypeError:       # a value of no hashable kind: refused by _resolve, naming it
        return _resolve(values)
    if arm is None:
        arm = _resolve(values)
        _RESOLVED[key] = arm
        while len(_RESOLVED) > _KEEP:
            _RESOLVED.popitem(last=False)
    else:
        _RESOLVED.move_to_end(key)
    return arm


_KEEP = 8
"""How many distinct arms :func:`resolve_arm` keeps."""
_RESOLVED = collections.OrderedDict()
"""``{arm key: NodeArm}``, least recently used first."""
_NOMINALS = {}
"""``{(id of a spatial arm, scale): (the arm, its nominal SpatialArm)}`` (``NodeArm.nominal``)."""


def _arm_key(values):
    """Return a hashable key of what the arm depends on (its parameters, the prefixes)."""
    def frozen(value):
        if isinstance(value, (list, tuple)):
            return tuple(frozen(v) for v in value)
        return (type(value).__name__, value)
    path = values['description_file'] or ''
    prefixes = os.environ.get('AMENT_PREFIX_PATH', '') if path else ''
    return (frozen(values['case']), frozen(values['robot_description']), frozen(path),
            frozen(values['passive_joints']), frozen(values['gravity']), prefixes,
            frozen(values.get('tip_link', '')), frozen(values.get('task_dim', 2)),
            frozen(values.get('base_link', '')))


def _resolve(values):
    """
    Return the arm of the node's parameters (parsed: no cache).

    Parameters
    ----------
    values : dict
        ``case`` and the entries of ``ARM_SPECS``.

    Returns
    -------
    NodeArm

    Raises
    ------
    FreejointValueError
        One line naming the parameter (``robot_description: ...``,
        ``passive_joints: ...``, ...).

    """
    case = values['case']
    if case not in GRAVITY_BY_CASE:
        raise FreejointValueError(f'case: expected one of {tuple(GRAVITY_BY_CASE)}, got '
                                  f'{case!r}')
    text = values['robot_description'] or ''
    path = values['description_file'] or ''
    if text and path:
        raise FreejointValueError(
            'description_file: give robot_description or description_file, not both')
    passive = list(values['passive_joints'] or ())
    given, gravity = _gravity(values['gravity'], case)
    tip = values.get('tip_link') or ''
    task_dim = values.get('task_dim', 2)
    if task_dim == 3:
        return _resolve_spatial(text, path, passive, given, values.get('base_link') or '', tip)
    if task_dim != 2 or isinstance(task_dim, bool):
        raise FreejointValueError(
            f'task_dim: expected 2 (a planar arm) or 3 (a spatial arm), got {task_dim!r}')
    if not text and not path and passive == PAPER_PASSIVE and given is None and not tip:
        params = table1(case)
        return NodeArm(params=params, joint_names=PAPER_JOINTS,
                       active_names=tuple(PAPER_JOINTS[i] for i in params.active),
                       urdf_arm=None, source=f'Table I ({case})')
    if text:
        arm = parse_urdf(text, passive, gravity, tip)
        source = f'robot_description ({arm.name})'
    elif path:
        arm = load_urdf(package_path(path), passive, gravity, tip)
        source = f'description_file {path}'
    else:
        arm = parse_urdf(_paper_text(), passive, gravity, tip)
        source = 'paper_arm.urdf'
    active = tuple(name for name in arm.joint_names if name not in arm.passive_joints)
    frame = arm.task_frame
    if frame != ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        source += ', tip %s, task frame: origin (%s) x (%s) y (%s) in the base frame' % (
            arm.ee_link, *(' '.join('%g' % v for v in vec) for vec in frame))
    return NodeArm(params=arm.params, joint_names=arm.joint_names, active_names=active,
                   urdf_arm=arm, source='%s, passive %s, gravity (%s)' % (
                       source, list(arm.passive_joints), ' '.join('%g' % g for g in gravity)))


def _resolve_spatial(text, path, passive, gravity, base, tip):
    """Return the ``NodeArm`` of a spatial arm (``task_dim`` 3; see ``_resolve``)."""
    from freejoint_core.spatial_model import GRAVITY, root_link, SpatialArm
    if not text and not path:
        raise FreejointValueError(
            'task_dim: 3 (a spatial arm) needs robot_description or description_file')
    if not tip:
        raise FreejointValueError(
            'tip_link: a spatial arm (task_dim 3) needs the link of its task point')
    if path:
        source = f'description_file {path}'
        file = package_path(path)
        try:
            with open(file, encoding='utf-8') as fh:
                text = fh.read()
        except OSError as exc:
            raise FreejointValueError(
                f'description_file: cannot read {file} ({exc.strerror})') from None
    else:
        source = 'robot_description'
    base = base or root_link(text)
    grav = tuple(gravity) if gravity is not None else GRAVITY
    try:
        arm = SpatialArm(text, base, tip, passive, 3, 1.0, grav)
    except FreejointValueError as exc:      # name the node's parameter, not the argument
        what, _, why = str(exc).partition(': ')
        name = {'passive': 'passive_joints', 'urdf': 'description_file' if path else
                'robot_description'}.get(what, what)
        raise FreejointValueError(f'{name}: {why}') from None
    active = tuple(arm.joint_names[i] for i in arm.active)
    return NodeArm(params=arm, joint_names=arm.joint_names, active_names=active,
                   urdf_arm=None, spatial=arm, source='%s (spatial, %s -> %s), passive %s, '
                   'gravity (%s)' % (source, base, tip, list(passive),
                                     ' '.join('%g' % g for g in grav)))


def package_path(path):
    """
    Return the file a ``description_file`` names (``package://<pkg>/<path>`` resolved).

    ``package://<pkg>/<path>`` (the ROS URDF convention) is ``share/<pkg>/<path>`` of the
    first prefix of ``AMENT_PREFIX_PATH`` that has it; the shipped descriptions
    (``package://freejoint_description/urdf/<name>.urdf``) are also found in the source
    tree and ``package://example-robot-data/...`` in the PyPI wheel's share directory (the
    PyPI install). Any other path is returned as given.

    Raises
    ------
    FreejointValueError
        ``description_file: ...`` if a ``package://`` path is not found.

    """
    if not path.startswith(PACKAGE_SCHEME):
        return path
    pkg, _, rest = path[len(PACKAGE_SCHEME):].partition('/')
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        candidate = os.path.join(prefix, 'share', pkg, rest)
        if prefix and os.path.isfile(candidate):
            return candidate
    name = os.path.basename(rest)[:-len('.urdf')]
    if pkg == 'freejoint_description' and rest == 'urdf/%s.urdf' % name and name in SHIPPED:
        return shipped_urdf_path(name)
    if pkg == ROBOT_DATA_PACKAGE:       # the PyPI wheel's share directory (a cmeel prefix)
        from freejoint_core.spatial_model import robot_data_dir
        candidate = os.path.join(os.path.dirname(robot_data_dir()), rest)
        if os.path.isfile(candidate):
            return candidate
    raise FreejointValueError(
        f'description_file: {path} not found (share/{pkg}/{rest} of no prefix of '
        f'AMENT_PREFIX_PATH)')


def _paper_text():
    path = shipped_urdf_path('paper_arm')
    with open(path, encoding='utf-8') as fh:
        return fh.read()


def joint_list(name, value, arm, default, names_of_arm):
    """
    Return a joint-name parameter: the arm's names when left at the paper default.

    Parameters
    ----------
    name : str
        The parameter (``joint_names`` or ``joints``).
    value : sequence of str
        Its value.
    arm : NodeArm
        The arm.
    default : sequence of str
        The parameter's default (the paper arm's names).
    names_of_arm : tuple of str
        What the default stands for on ``arm`` (all joints, or the active ones).

    Returns
    -------
    tuple of str
        ``names_of_arm`` if ``value`` is the default, else ``value`` (the caller checks it
        against the arm).

    """
    names = tuple(value)
    if arm.described and list(names) == list(default):
        return tuple(names_of_arm)
    return names


def arm_joint_names(values, arm):
    """
    Return ``(joint_names, joints)`` of a node: the parameters, or the arm's at the defaults.

    Left at their defaults (the paper arm's ``joint1..3`` / ``joint1, joint2``) with a URDF
    arm, ``joint_names`` are the URDF's revolute joints and ``joints`` its active ones,
    base to tip; given, they are returned as given (the caller checks them).

    Parameters
    ----------
    values : dict
        ``joint_names`` and ``joints``.
    arm : NodeArm
        The arm (:func:`resolve_arm`).

    Returns
    -------
    tuple of (tuple of str, tuple of str)

    """
    return (joint_list('joint_names', values['joint_names'], arm, PAPER_JOINTS,
                       arm.joint_names),
            joint_list('joints', values['joints'], arm, PAPER_JOINTS[:2], arm.active_names))


def _followed(index):
    """Return what ``joint_names`` (0) / ``joints`` (1) follow: the arm's joints, active ones."""
    def follows(values):
        arm = resolve_arm(values)
        return list(arm.joint_names if index == 0 else arm.active_names)
    return follows


ARM_JOINT_NAMES = Param(
    'joint_names', list(PAPER_JOINTS),
    'names of all joints in model order (base to tip), passive ones included; not given: '
    "the arm's (the URDF's revolute joints; the paper arm's joint1..3), declared with them "
    'so that a read-back answers the names in use', read_only=True, follows=_followed(0))
"""``joint_names`` of a node with an arm: declared with the arm's names when not given."""
ARM_JOINTS = Param(
    'joints', list(PAPER_JOINTS[:2]),
    'active joints in the order of the effort command (JointGroupEffortController); not '
    "given: the arm's active joints, base to tip (the paper arm's joint1, joint2), declared "
    'with them so that a read-back answers the names in use', read_only=True,
    follows=_followed(1))
"""``joints`` of a node with an arm: declared with the arm's active joints when not given."""
