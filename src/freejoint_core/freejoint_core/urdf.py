"""
Planar serial arms from URDF: the core's ``ArmParams`` from a robot description.

Supported descriptions (anything else is refused with one line naming the problem), read
in their own frames (each joint's ``<origin>`` and ``<axis>`` composed from the root at
zero angles, as robot_state_publisher does):

* a tree of links whose chain from the root to the task point (``tip_link``, default the
  chain's last link: from the root into the one child joint below which something moves,
  past the last revolute joint along a single fixed end-effector joint) holds revolute
  (or continuous) joints and fixed joints; fixed mounts before joint 1 may shift and turn
  the arm anywhere (a base offset); branches off the chain with nothing moving below
  (sensors, cameras) are no part of the chain;
* every revolute axis of the chain, in the base frame, is the same unit vector ``a``
  (any direction: +-x, +-y, +-z or other): the arm moves in a plane normal to ``a``;
* at zero angles the arm is straight: every joint and the task point lie on one line
  in that plane (any direction ``x``); link i runs from joint i to joint i + 1 (the last
  one to the task point) and its length is that distance in the plane (offsets along
  ``a`` do not enter the planar dynamics);
* the task frame (the core's x, y: setpoints, circles, ``ee_position``) has its origin on
  joint 1's axis, x along the straight arm and y = a x x (``UrdfArm.task_frame``); for the
  shipped arms (axes +z, links along +x, joint 1 at the origin) it is the base frame.
  When gravity has a part in the plane that does not point along -y of that frame (an
  rrbot standing up: its straight zero pose points up, against gravity), the task frame is
  turned about the axis instead, y against that part of gravity and x = y x a, and joint
  1's zero angle becomes the angle ``joint_offsets[0]`` of the straight arm in it: the
  core's joint angles are the URDF's plus ``UrdfArm.joint_offsets`` (``to_model`` /
  ``to_joints``; only joint 1 moves, the others are relative angles);
* each moving link has its mass: the link itself with every link fixed to it folded in
  (a tool, a sensor); links without ``<inertial>`` or with zero mass add nothing; the
  folded centre of mass lies on the link's line, in ``(0, L]``; the moment of inertia is
  about ``a`` through that centre (parallel-axis sums).

Gravity and the passive joints are not URDF elements: they are given beside the
description.  Gravity is a vector in the base frame; its in-plane part points along -y of
the task frame (the core's convention; the frame is turned for it, above), its part along
the joint axes exerts no joint torque.  The horizontal case (Case 1) is
``GRAVITY_HORIZONTAL = (0, 0, -9.81)``, the vertical one (Case 2) ``GRAVITY_VERTICAL = (0,
-9.81, 0)``.

The nominal model of the controller is ``UrdfArm.nominal(scale)``: masses, inertias
and COM offsets of the URDF times ``scale``, as ``ArmParams.scaled``.
"""

from dataclasses import dataclass
import math
import os

from freejoint_core.arm import ArmParams, GRAVITY_VERTICAL
from freejoint_core.errors import FreejointValueError
from freejoint_core.kinematic_tree import robot_root
import numpy as np

GRAVITY_HORIZONTAL = (0.0, 0.0, -GRAVITY_VERTICAL)
"""Gravity vector [m/s^2] in the base frame for the arm moving in a horizontal plane."""

GRAVITY_VERTICAL_VECTOR = (0.0, -GRAVITY_VERTICAL, 0.0)
"""Gravity vector [m/s^2] in the base frame for the arm moving in a vertical plane."""

GRAVITY_BY_CASE = {'horizontal': GRAVITY_HORIZONTAL, 'vertical': GRAVITY_VERTICAL_VECTOR}
"""The paper's two cases as gravity vectors."""

SHIPPED = ('paper_arm', 'four_link_arm')
"""Names of the URDF files of the package freejoint_description (without ``.urdf``)."""

_TOL = 1e-12   # geometric tolerance (m, rad) for "on the axis" / "no rotation"
_REVOLUTE = ('revolute', 'continuous')
OFF_LINE = 1e-6
"""A link's (folded) centre of mass this far off its line, relative to its length, is on it:
the core's planar model has no offset across the link (a 1e-5 kg camera 5 cm beside a 1 kg
link moves it 5e-7 of its length)."""


@dataclass(frozen=True)
class UrdfArm:
    """
    A planar serial arm read from URDF, with its passive joints and gravity.

    Attributes
    ----------
    name : str
        The ``<robot name>``.
    urdf : str
        The URDF text it was read from.
    joint_names : tuple of str, (n,)
        The revolute joints, base to tip (the core's joint order).
    link_names : tuple of str, (n,)
        The child link of each joint.
    base_link : str
        The link joint 1 is mounted on (the root, or the last link of a fixed mount).
    ee_link : str
        The end-effector link (child of the fixed tip joint).
    passive_joints : tuple of str
        Names of the passive joints, in chain order.
    gravity_vector : tuple of float, (3,)
        Gravity [m/s^2] in the base frame.
    params : ArmParams
        The real parameters (lengths, masses, inertias, COM distances from the URDF;
        ``passive`` the indices of ``passive_joints``; ``gravity`` the part of
        ``gravity_vector`` along -y of the task frame).
    task_frame : tuple
        ``(origin, x, y)`` in the root link's frame (m, unit vectors): where the core's task
        coordinates lie (origin on joint 1's axis, x along the arm at zero angles, y =
        axis x x, or turned about the axis to put gravity along -y: module notes);
        ``((0, 0, 0), (1, 0, 0), (0, 1, 0))`` for an arm in the base x-y plane.
    joint_offsets : tuple of float, (n,) or ()
        Added to the URDF's joint angles [rad] they give the core's (``to_model``): the
        angle of the straight zero pose in a turned task frame on joint 1, 0 elsewhere;
        ``()`` when the frame is not turned (no offset).

    """

    name: str
    urdf: str
    joint_names: tuple
    link_names: tuple
    base_link: str
    ee_link: str
    passive_joints: tuple
    gravity_vector: tuple
    params: ArmParams
    task_frame: tuple = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    joint_offsets: tuple = ()

    def to_model(self, q):
        """
        Return the core's joint angles of the URDF's ``q`` (the offsets added).

        Parameters
        ----------
        q : sequence of float, (n,)
            Joint angles [rad] as the URDF (and ``joint_states``) measure them.

        Returns
        -------
        tuple of float, (n,)
            ``q`` itself (as a tuple) when the arm has no offset.

        """
        if not self.joint_offsets:
            return tuple(q)
        return tuple(a + b for a, b in zip(q, self.joint_offsets))

    def to_joints(self, q):
        """Return the URDF's joint angles [rad] of the core's ``q``, (n,): ``to_model`` undone."""
        if not self.joint_offsets:
            return tuple(q)
        return tuple(a - b for a, b in zip(q, self.joint_offsets))

    def nominal(self, scale):
        """
        Return the nominal parameters: masses, inertias and COM offsets times ``scale``.

        Parameters
        ----------
        scale : float
            Factor > 0 (the paper's nominal model is 0.7).

        Returns
        -------
        ArmParams

        """
        return self.params.scaled(scale)


def _floats(text, count, what):
    """Parse ``count`` whitespace-separated finite floats, or raise naming ``what``."""
    parts = (text or '').split()
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        raise FreejointValueError(f'{what}: expected {count} numbers, got {text!r}') from None
    if len(vals) != count or not all(math.isfinite(v) for v in vals):
        raise FreejointValueError(f'{what}: expected {count} finite numbers, got {text!r}')
    return vals


def _origin(elem, what):
    """Return ``(xyz, rpy)`` of the ``<origin>`` child of ``elem`` (zeros if absent)."""
    org = elem.find('origin')
    if org is None:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    return (_floats(org.get('xyz', '0 0 0'), 3, f'{what} origin xyz'),
            _floats(org.get('rpy', '0 0 0'), 3, f'{what} origin rpy'))


def _inertia_tensor(inertia, name):
    """Return the 3x3 inertia tensor [kg m^2] of an ``<inertia>`` element of link ``name``."""
    comps = {}
    for key in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'):
        (comps[key],) = _floats(inertia.get(key, '0'), 1,
                                f'robot_description: link {name!r} inertia {key}')
    return np.array([[comps['ixx'], comps['ixy'], comps['ixz']],
                     [comps['ixy'], comps['iyy'], comps['iyz']],
                     [comps['ixz'], comps['iyz'], comps['izz']]])


def _rpy_matrix(rpy):
    """Rotation matrix of URDF roll-pitch-yaw (fixed axes x, y, z)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _fmt(vals):
    return ' '.join(f'{v:g}' for v in vals)


def _inertial(link, name):
    """Return ``(mass, com_x, izz)`` of a moving link, or raise naming the link."""
    inertial = link.find('inertial') if link is not None else None
    if inertial is None:
        raise FreejointValueError(
            f'robot_description: link {name!r} has no <inertial> (a moving link needs its '
            f'mass, centre of mass and inertia)')
    mass_el = inertial.find('mass')
    if mass_el is None:
        raise FreejointValueError(f'robot_description: link {name!r}: <inertial> has no <mass>')
    (mass,) = _floats(mass_el.get('value'), 1, f'robot_description: link {name!r} mass')
    xyz, rpy = _origin(inertial, f'robot_description: link {name!r} inertial')
    if abs(xyz[1]) > _TOL:
        raise FreejointValueError(
            f'robot_description: link {name!r}: centre of mass off the link axis (y = '
            f'{xyz[1]:g} m); the model of the core needs it on the x axis of the link')
    inertia = inertial.find('inertia')
    if inertia is None:
        raise FreejointValueError(
            f'robot_description: link {name!r}: <inertial> has no <inertia>')
    tensor = _inertia_tensor(inertia, name)
    rot = _rpy_matrix(rpy)
    izz = float((rot @ tensor @ rot.T)[2, 2])
    return mass, xyz[0], izz


def _gravity(gravity):
    try:
        g = tuple(float(v) for v in gravity)
    except (TypeError, ValueError):
        raise FreejointValueError(
            f'gravity: expected 3 numbers (a vector in the base frame), got {gravity!r}') from None
    if len(g) != 3 or not all(math.isfinite(v) for v in g):
        raise FreejointValueError(
            f'gravity: expected 3 finite numbers (a vector in the base frame), got {gravity!r}')
    return g


def _named(root, tag):
    """Yield ``(name, element)`` of each ``<tag>``; refuse a missing or repeated name."""
    seen = set()
    for elem in root.findall(tag):
        name = elem.get('name')
        if not name:
            raise FreejointValueError(f'robot_description: a <{tag}> has no name')
        if name in seen:
            raise FreejointValueError(f'robot_description: {tag} {name!r} is defined twice')
        seen.add(name)
        yield name, elem


def parse_urdf(text, passive_joints=(), gravity=GRAVITY_HORIZONTAL, tip_link=''):
    """
    Read a planar serial arm from URDF text, in its own frames.

    Parameters
    ----------
    text : str
        The URDF (``robot_description``).
    passive_joints : sequence of str
        Names of the free (unactuated) joints; at least two joints must stay active.
    gravity : sequence of float, (3,)
        Gravity [m/s^2] in the base frame (see the module notes).
    tip_link : str
        The link whose origin is the task point (kinematics_interface's ``tip``); ''
        = the chain's last link (see the module notes).

    Returns
    -------
    UrdfArm

    Raises
    ------
    FreejointValueError
        One line naming the problem: ``robot_description: ...`` for the URDF,
        ``passive_joints: ...``, ``gravity: ...`` or ``tip_link: ...`` for the other
        arguments.

    """
    root = robot_root(text)
    if isinstance(passive_joints, str):
        raise FreejointValueError(
            f'passive_joints: expected a list of joint names, got the string {passive_joints!r}')
    passive_joints = tuple(passive_joints)
    if not all(isinstance(p, str) for p in passive_joints):
        raise FreejointValueError(
            f'passive_joints: expected joint names (strings), got {passive_joints!r}')
    gvec = _gravity(gravity)
    links, joint_of, children, base = _tree(root)
    chain = _chain(links, joint_of, children, base, tip_link or '')
    tip = chain[-1].find('child').get('link') if chain else base
    frames = _Frames(joint_of, children)
    revolute = [j for j in chain if j.get('type') in _REVOLUTE]
    for joint in chain:
        _check_joint(joint)
    if not revolute:
        raise FreejointValueError('robot_description: no revolute joint found from the root '
                                  f'link {base!r}')
    # the common axis: every revolute joint's axis in the base frame, at zero angles
    n = frames.axis(revolute[0])
    for joint in revolute[1:]:
        a = frames.axis(joint)
        if np.linalg.norm(a - n) > 1e-9:
            what = f"robot_description: joint {joint.get('name')!r}"
            if np.linalg.norm(a + n) <= 1e-9:
                raise FreejointValueError(
                    f'{what}: axis points opposite to the axis of joint '
                    f"{revolute[0].get('name')!r} ({_fmt(n)} in the base frame); a planar arm "
                    f'needs every joint counter-clockwise about the same axis')
            raise FreejointValueError(
                f'{what}: axis ({_fmt(a)} in the base frame) is not parallel to the axis of '
                f"joint {revolute[0].get('name')!r} ({_fmt(n)}); a planar arm needs every "
                f'revolute axis parallel')
    joint_names = [j.get('name') for j in revolute]
    link_names = [j.find('child').get('link') for j in revolute]
    # link i: from joint i to joint i + 1 (the last one to the tip), its in-plane vector
    lengths, direction = [], None
    ends = revolute[1:] + [None]
    for i, (joint, nxt) in enumerate(zip(revolute, ends)):
        vec = frames.between(joint, nxt, tip)
        flat = vec - float(vec @ n) * n
        length = float(np.sqrt(flat @ flat))
        what = (f"robot_description: joint {nxt.get('name')!r}" if nxt is not None else
                f'robot_description: the task point {tip!r}')
        if nxt is None and length <= _TOL:
            raise FreejointValueError(
                f'robot_description: no end effector: the task point {tip!r} sits on joint '
                f'{joint.get("name")!r} (link {link_names[i]!r} has no length); add a fixed '
                f'joint from {link_names[i]!r} to an end-effector link at its tip, or name '
                f'such a link as tip_link')
        if length <= _TOL:
            raise FreejointValueError(
                f'{what}: sits on the axis of joint {joint.get("name")!r}: link '
                f'{link_names[i]!r} has no length in the plane of the arm')
        unit = flat / length
        if direction is None:
            direction = unit
        elif np.linalg.norm(unit - direction) > 1e-9:
            raise FreejointValueError(
                f'{what}: must sit on the line of link {link_names[0]!r} at zero angles '
                f'(link {link_names[i]!r} runs along ({_fmt(unit)}), link {link_names[0]!r} '
                f'along ({_fmt(direction)}) in the base frame): the core takes zero angles as '
                f'a straight arm')
        lengths.append(length)
    side = np.cross(n, direction)
    masses, inertias, coms = [], [], []
    for i, joint in enumerate(revolute):
        mass, com, izz = frames.link_inertia(joint, ends[i], links, n, direction, side,
                                             lengths[i])
        masses.append(mass)
        coms.append(com)
        inertias.append(izz)
    for pname in passive_joints:
        if pname not in joint_names:
            raise FreejointValueError(
                f'passive_joints: {pname!r} is not a revolute joint of the URDF (joints: '
                f'{", ".join(joint_names)})')
    if len(set(passive_joints)) != len(passive_joints):
        raise FreejointValueError(f'passive_joints: names must be unique, got {passive_joints}')
    active = len(joint_names) - len(passive_joints)
    if active < 2:
        raise FreejointValueError(
            f'passive_joints: {len(passive_joints)} passive of {len(joint_names)} joints leaves '
            f'{active} active; the task (x, y) needs at least 2')
    passive_idx = tuple(sorted(joint_names.index(p) for p in passive_joints))
    for i, (lname, c, length) in enumerate(zip(link_names, coms, lengths)):
        if not 0.0 < c <= length:
            raise FreejointValueError(
                f'robot_description: link {lname!r}: centre of mass at x = {c:g} m, must lie '
                f'on the link, in (0, L] = (0, {length:g}]')
    for lname, m, izz in zip(link_names, masses, inertias):
        if m <= 0.0 or izz <= 0.0:
            raise FreejointValueError(
                f'robot_description: link {lname!r}: mass ({m:g}) and izz ({izz:g}) must be '
                f'> 0')
    x_axis, y_axis, gravity, offsets = _task_axes(np.asarray(gvec, dtype=float), n,
                                                  direction, side, len(joint_names))
    params = ArmParams(lengths=tuple(lengths), masses=tuple(masses),
                       inertias=tuple(inertias), com=tuple(coms), passive=passive_idx,
                       gravity=gravity)
    origin = frames.position(revolute[0])
    return UrdfArm(name=root.get('name', ''), urdf=text, joint_names=tuple(joint_names),
                   link_names=tuple(link_names),
                   base_link=revolute[0].find('parent').get('link'), ee_link=tip,
                   passive_joints=tuple(joint_names[i] for i in passive_idx),
                   gravity_vector=gvec, params=params,
                   task_frame=(tuple(float(v) for v in origin),
                               tuple(float(v) for v in x_axis),
                               tuple(float(v) for v in y_axis)),
                   joint_offsets=offsets)


def _task_axes(g, axis, direction, side, n):
    """
    Return the task frame's ``x, y`` axes, the core's gravity and the joint offsets.

    The frame along the straight arm (``direction``, ``side`` = axis x direction) when the
    in-plane part of gravity ``g`` points along its -y (or is nil); else turned about
    ``axis``: y against that part, x = y x axis, and joint 1's offset the angle of
    ``direction`` in it (module notes).

    Returns
    -------
    x, y : numpy.ndarray, (3,)
    gravity : float
        Magnitude [m/s^2] of the in-plane part (the core's ``ArmParams.gravity``).
    offsets : tuple of float, (n,) or ()

    """
    g_x, g_y = float(g @ direction), float(g @ side)
    if abs(g_x) <= _TOL and g_y <= 0.0:
        return direction, side, -g_y + 0.0, ()
    flat = g - float(g @ axis) * axis
    up = -flat / float(np.sqrt(flat @ flat)) + 0.0      # + 0.0: no -0 in the frame
    x_axis = np.cross(up, axis) + 0.0
    offset = math.atan2(float(direction @ up), float(direction @ x_axis))
    return x_axis, up, float(np.sqrt(flat @ flat)), (offset,) + (0.0,) * (n - 1)


def _tree(root):
    """Return ``(links, joint_of child, children of parent, root link)`` of a URDF."""
    links = dict(_named(root, 'link'))
    children = {}   # parent link -> joints
    joint_of = {}   # child link -> joint
    for jname, joint in _named(root, 'joint'):
        parent, child = joint.find('parent'), joint.find('child')
        if parent is None or child is None or not parent.get('link') or not child.get('link'):
            raise FreejointValueError(
                f'robot_description: joint {jname!r} needs <parent link> and <child link>')
        for end in (parent.get('link'), child.get('link')):
            if end not in links:
                raise FreejointValueError(
                    f'robot_description: joint {jname!r} refers to link {end!r}, not defined')
        if child.get('link') in joint_of:
            raise FreejointValueError(
                f'robot_description: link {child.get("link")!r} is the child of two joints')
        joint_of[child.get('link')] = joint
        children.setdefault(parent.get('link'), []).append(joint)
    roots = [name for name in links if name not in joint_of]
    if len(roots) != 1:
        raise FreejointValueError(
            f'robot_description: expected one root link, got {len(roots)} ({roots})')
    return links, joint_of, children, roots[0]


def _moves(link, children):
    """Return True if a moving joint lies below ``link``."""
    for joint in children.get(link, []):
        if joint.get('type') != 'fixed' or _moves(joint.find('child').get('link'), children):
            return True
    return False


def _chain(links, joint_of, children, base, tip_link):
    """
    Return the joints from the root to the task point, in order.

    ``tip_link`` given: the path to it. Else the chain's last link: from the root, into the
    one child joint below which something moves; past the last moving joint, along a
    single fixed joint (an end-effector joint) while there is exactly one; sensor and
    camera branches (fixed, nothing moving below) are not the chain.
    """
    if tip_link:
        if tip_link not in links:
            raise FreejointValueError(f'tip_link: no link {tip_link!r} in the URDF')
        path, link = [], tip_link
        while link in joint_of:
            joint = joint_of[link]
            path.append(joint)
            link = joint.find('parent').get('link')
        return path[::-1]
    path, link = [], base
    while True:
        out = children.get(link, [])
        moving = [j for j in out
                  if j.get('type') != 'fixed' or _moves(j.find('child').get('link'), children)]
        if len(moving) > 1:
            raise FreejointValueError(
                f'robot_description: link {link!r} has {len(moving)} child joints with moving '
                f'joints below ({", ".join(j.get("name") for j in moving)}); only serial '
                f'chains are supported')
        if moving:
            joint = moving[0]
        elif len(out) == 1 and path:
            joint = out[0]           # the end-effector joint
        else:
            return path
        path.append(joint)
        link = joint.find('child').get('link')


def _check_joint(joint):
    """Refuse a chain joint the planar model does not have (type, mimic, limits)."""
    jname, jtype = joint.get('name'), joint.get('type')
    what = f'robot_description: joint {jname!r}'
    if joint.find('mimic') is not None:
        raise FreejointValueError(f'{what}: <mimic> joints are not supported')
    if jtype in _REVOLUTE:
        limit = joint.find('limit')
        if jtype == 'revolute' and limit is None:
            raise FreejointValueError(f'{what}: revolute joint without <limit>')
        if jtype == 'continuous' and limit is not None and (
                limit.get('lower') is not None or limit.get('upper') is not None):
            raise FreejointValueError(
                f'{what}: continuous joint with position limits (lower/upper); use a '
                f'revolute joint')
    elif jtype != 'fixed':
        raise FreejointValueError(
            f'{what}: type {jtype!r} is not supported (revolute or continuous joints '
            f'about parallel axes, fixed joints between them)')


class _Frames:
    """Link frames at zero joint angles, in the base frame (rotation, origin)."""

    def __init__(self, joint_of, children):
        self._joint_of = joint_of
        self._children = children
        self._cache = {}

    def frame(self, link):
        """Return the rotation (3 x 3) and origin (3,) of ``link`` in the base frame."""
        if link not in self._cache:
            joint = self._joint_of.get(link)
            if joint is None:
                self._cache[link] = (np.eye(3), np.zeros(3))
            else:
                rot, pos = self.frame(joint.find('parent').get('link'))
                xyz, rpy = _origin(joint, f"robot_description: joint {joint.get('name')!r}")
                self._cache[link] = (rot @ _rpy_matrix(rpy), pos + rot @ np.array(xyz))
        return self._cache[link]

    def position(self, joint):
        """Return the joint's origin in the base frame."""
        return self.frame(joint.find('child').get('link'))[1]

    def axis(self, joint):
        """Return the joint's unit axis in the base frame (URDF default ``1 0 0``)."""
        what = f"robot_description: joint {joint.get('name')!r}"
        axis_el = joint.find('axis')
        axis = (_floats(axis_el.get('xyz'), 3, f'{what} axis') if axis_el is not None
                else (1.0, 0.0, 0.0))
        norm = math.sqrt(sum(a * a for a in axis))
        if norm == 0.0:
            raise FreejointValueError(f'{what}: axis is the zero vector')
        rot = self.frame(joint.find('child').get('link'))[0]
        return rot @ np.array([a / norm for a in axis])

    def between(self, joint, nxt, tip):
        """
        Return the vector from ``joint`` to ``nxt`` (None: to the link ``tip``), base frame.

        Summed joint by joint from ``joint``'s child link (each origin rotated into the base
        frame), so that one straight link gives its URDF numbers exactly.
        """
        target = nxt.find('child').get('link') if nxt is not None else tip
        start = joint.find('child').get('link')
        steps, link = [], target
        while link != start:
            step = self._joint_of[link]
            steps.append(step)
            link = step.find('parent').get('link')
        vec = np.zeros(3)
        for step in reversed(steps):
            rot = self.frame(step.find('parent').get('link'))[0]
            xyz, _ = _origin(step, f"robot_description: joint {step.get('name')!r}")
            vec = vec + rot @ np.array(xyz)
        return vec

    def _moving_group(self, joint, nxt):
        """Return the links moving with ``joint``'s link: it, and fixed descendants."""
        stop = None if nxt is None else nxt.find('child').get('link')
        group, todo = [], [joint.find('child').get('link')]
        while todo:
            link = todo.pop()
            group.append(link)
            for child in self._children.get(link, []):
                child_link = child.find('child').get('link')
                if child.get('type') == 'fixed' and child_link != stop:
                    todo.append(child_link)
        return group

    def link_inertia(self, joint, nxt, links, n, x, y, length):
        """
        Return ``(mass, com along the link, inertia about the axis at the COM)`` of link i.

        The link of ``joint`` with every link fixed to it (a tool, a sensor, a camera)
        folded in; links without ``<inertial>`` or with zero mass add nothing. The COM
        must lie on the link's line (y = 0 in the task frame, within ``OFF_LINE`` of the
        length: a sensor of 10 g a few cm beside a 1 kg link is on it).
        """
        origin = self.position(joint)
        parts = []
        own = joint.find('child').get('link')
        for name in self._moving_group(joint, nxt):
            inertial = links[name].find('inertial')
            if inertial is None or inertial.find('mass') is None:
                if name == own and len(self._moving_group(joint, nxt)) == 1:
                    _inertial(links[name], name)          # raises: no <inertial>
                continue
            mass, rel, izz = _inertial_frame(links[name], name, self.frame(name)[0], n)
            if mass == 0.0:
                continue
            rot, pos = self.frame(name)
            parts.append((name, mass, pos - origin if name != own else np.zeros(3), rel, izz))
        if not parts and links[own].find('inertial') is not None:
            mass, rel, izz = _inertial_frame(links[own], own, self.frame(own)[0], n)
            return mass, float(rel @ x), izz        # mass 0: refused by the caller
        if not parts:
            raise FreejointValueError(
                f'robot_description: link {own!r} has no <inertial> (a moving link needs its '
                f'mass, centre of mass and inertia)')
        coms = [offset + rel for _, _, offset, rel, _ in parts]
        if len(parts) == 1:
            _, mass, _, _, izz = parts[0]
            com = coms[0]
        else:
            mass = sum(p[1] for p in parts)
            com = sum(p[1] * c for p, c in zip(parts, coms)) / mass
            izz = 0.0
            for (_, m, _, _, i_c), c in zip(parts, coms):
                d = c - com
                d = d - float(d @ n) * n
                izz += i_c + m * float(d @ d)
        off = float(com @ y)
        if abs(off) > max(_TOL, OFF_LINE * length):
            raise FreejointValueError(
                f'robot_description: link {own!r}: centre of mass off the link axis (y = '
                f'{off:g} m{", with the links fixed to it" if len(parts) > 1 else ""}); the '
                f'model of the core needs it on the line of the link')
        return mass, float(com @ x), izz


def _inertial_frame(link, name, rot, n):
    """Return ``(mass, COM in base axes from the link origin, inertia about n at the COM)``."""
    inertial = link.find('inertial')
    mass_el = inertial.find('mass')
    (mass,) = _floats(mass_el.get('value'), 1, f'robot_description: link {name!r} mass')
    xyz, rpy = _origin(inertial, f'robot_description: link {name!r} inertial')
    inertia = inertial.find('inertia')
    if inertia is None:
        if mass == 0.0:
            return 0.0, np.zeros(3), 0.0
        raise FreejointValueError(
            f'robot_description: link {name!r}: <inertial> has no <inertia>')
    tensor = _inertia_tensor(inertia, name)
    full = rot @ _rpy_matrix(rpy)
    izz = float(n @ (full @ tensor @ full.T) @ n)
    return mass, rot @ np.array(xyz), izz


def load_urdf(path, passive_joints=(), gravity=GRAVITY_HORIZONTAL, tip_link=''):
    """
    Read a planar serial arm from a URDF file.

    Parameters
    ----------
    path : str
        The file (``description_file``).
    passive_joints, gravity, tip_link
        As :func:`parse_urdf`.

    Returns
    -------
    UrdfArm
        The arm the file describes.

    Raises
    ------
    FreejointValueError
        ``description_file: ...`` if it cannot be read, else as :func:`parse_urdf`.

    """
    try:
        with open(path, encoding='utf-8') as f:
            text = f.read()
    except (OSError, UnicodeDecodeError, TypeError) as exc:
        raise FreejointValueError(f'description_file: cannot read {path!r} ({exc})') from None
    return parse_urdf(text, passive_joints, gravity, tip_link)


def shipped_urdf_path(name):
    """
    Path of a URDF shipped in the package freejoint_description.

    Looks in ``share/freejoint_description/urdf`` of every prefix of
    ``AMENT_PREFIX_PATH``, then in the source tree next to this package.

    Parameters
    ----------
    name : str
        One of ``SHIPPED`` (``'paper_arm'``, ``'four_link_arm'``).

    Returns
    -------
    str

    Raises
    ------
    FreejointValueError
        Naming ``name`` if it is not shipped or not found.

    """
    if name not in SHIPPED:
        raise FreejointValueError(f'name: expected one of {SHIPPED}, got {name!r}')
    fname = name + '.urdf'
    candidates = [os.path.join(prefix, 'share', 'freejoint_description', 'urdf', fname)
                  for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
                  if prefix]
    here = os.path.dirname(os.path.realpath(__file__))
    candidates.append(os.path.join(here, '..', '..', 'freejoint_description', 'urdf', fname))
    for path in candidates:
        if os.path.isfile(path):
            return os.path.normpath(path)
    raise FreejointValueError(
        f'name: {fname} not found (share/freejoint_description/urdf of AMENT_PREFIX_PATH, '
        f'and the source tree)')


def paper_arm(case='horizontal'):
    """
    Return the shipped Table I URDF as a ``UrdfArm`` (joint3 passive).

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        The gravity vector ``GRAVITY_BY_CASE[case]``.

    Returns
    -------
    UrdfArm
        ``params`` equal to ``freejoint_core.arm.table1(case)``.

    """
    if case not in GRAVITY_BY_CASE:
        raise FreejointValueError(f'case: expected one of {tuple(GRAVITY_BY_CASE)}, got {case!r}')
    return load_urdf(shipped_urdf_path('paper_arm'), ('joint3',), GRAVITY_BY_CASE[case])


FOUR_LINK_PASSIVE = ('joint1',)
"""Passive joint of the shipped 4-link example: the base joint (see ``four_link_arm``)."""

FOUR_LINK_CIRCLE = {'centre': (0.25, 0.25), 'radius': 0.1}
"""The 4-link example's circle [m] (``CircleQuintic`` arguments; start ``(0.35, 0.25)``).

Its radial band about the base, 0.254-0.454 m, lies between the radii 0.2 and 0.5 m
of the folded collinear configurations, where ``Da`` is singular."""

FOUR_LINK_Q0 = (0.0, 1.0052314594852472, 1.3891119364177558, 2.2480117465074176)
"""Initial joint angles [rad] of the 4-link example: at rest on the circle's start."""


def four_link_arm(case='horizontal', passive_joints=FOUR_LINK_PASSIVE):
    """
    Return the shipped 4-link example URDF as a ``UrdfArm``.

    One passive joint (the base joint ``joint1`` by default) leaves r = 3 active
    joints for the 2-D task.  With the paper's law (70 % nominal, 0.5 N m
    disturbance) it tracks ``FOUR_LINK_CIRCLE`` from ``FOUR_LINK_Q0`` in the
    horizontal case (``test/core/test_four_link_example.py`` states the bound); in
    the vertical case the free base pivot under gravity is not stabilised by that
    law (the loop diverges within 0.2 s).

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        The gravity vector ``GRAVITY_BY_CASE[case]``.
    passive_joints : sequence of str
        Its passive joint(s); default ``FOUR_LINK_PASSIVE``.

    Returns
    -------
    UrdfArm

    """
    if case not in GRAVITY_BY_CASE:
        raise FreejointValueError(f'case: expected one of {tuple(GRAVITY_BY_CASE)}, got {case!r}')
    return load_urdf(shipped_urdf_path('four_link_arm'), passive_joints, GRAVITY_BY_CASE[case])
