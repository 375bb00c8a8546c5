"""
Planar serial arms from URDF: the core's ``ArmParams`` from a robot description.

Supported descriptions (anything else is refused with one line naming the problem):

* one serial chain from the root link (fixed mounts before joint 1 allowed if they
  neither rotate nor shift in x-y): revolute (or continuous) joints, every axis
  ``0 0 1`` in its joint frame and every joint origin without rotation, so all axes are
  parallel to the base z axis and the arm moves in the base x-y plane;
* joint 1 at the base origin (``x = y = 0``); joint i + 1 at ``(L_i, 0, z)`` in the
  frame of link i (``z`` free: it does not enter the planar dynamics), so link i runs
  along its x axis and the joint angles are the core's relative angles;
* one fixed joint after the last revolute one, at ``(L_n, 0, z)``: its child is the end
  effector (the task point); it carries no mass;
* every moving link has an ``<inertial>`` with mass > 0 and its centre of mass on the
  link's x axis (``y = 0``), at ``0 < x <= L``; the moment of inertia about the COM
  along z (``izz`` after the inertial origin's rotation) is the core's ``I_i``.

Gravity and the passive joints are not URDF elements: they are given beside the
description.  Gravity is a vector in the base frame; its in-plane part must point
along -y (the core's convention), its z part acts along the joint axes and exerts no
joint torque.  The horizontal case (Case 1) is ``GRAVITY_HORIZONTAL = (0, 0, -9.81)``,
the vertical one (Case 2) ``GRAVITY_VERTICAL = (0, -9.81, 0)``.

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
        The root link (base frame).
    ee_link : str
        The end-effector link (child of the fixed tip joint).
    passive_joints : tuple of str
        Names of the passive joints, in chain order.
    gravity_vector : tuple of float, (3,)
        Gravity [m/s^2] in the base frame.
    params : ArmParams
        The real parameters (lengths, masses, inertias, COM distances from the URDF;
        ``passive`` the indices of ``passive_joints``; ``gravity = -gravity_vector[1]``).

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
    comps = {}
    for key in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'):
        (comps[key],) = _floats(inertia.get(key, '0'), 1,
                                f'robot_description: link {name!r} inertia {key}')
    tensor = np.array([[comps['ixx'], comps['ixy'], comps['ixz']],
                       [comps['ixy'], comps['iyy'], comps['iyz']],
                       [comps['ixz'], comps['iyz'], comps['izz']]])
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
    if g[0] != 0.0 or g[1] > 0.0:
        raise FreejointValueError(
            f'gravity: the in-plane part of ({_fmt(g)}) must point along -y of the base '
            f'frame (x = 0, y <= 0): rotate the base frame of the URDF so that it does')
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


def parse_urdf(text, passive_joints=(), gravity=GRAVITY_HORIZONTAL):
    """
    Read a planar serial arm from URDF text.

    Parameters
    ----------
    text : str
        The URDF (``robot_description``).
    passive_joints : sequence of str
        Names of the free (unactuated) joints; at least two joints must stay active.
    gravity : sequence of float, (3,)
        Gravity [m/s^2] in the base frame (see the module notes).

    Returns
    -------
    UrdfArm

    Raises
    ------
    FreejointValueError
        One line naming the problem: ``robot_description: ...`` for the URDF,
        ``passive_joints: ...`` or ``gravity: ...`` for the other arguments.

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

    links = dict(_named(root, 'link'))
    children = {}   # parent link -> joints
    child_links = set()
    for jname, joint in _named(root, 'joint'):
        parent, child = joint.find('parent'), joint.find('child')
        if parent is None or child is None or not parent.get('link') or not child.get('link'):
            raise FreejointValueError(
                f'robot_description: joint {jname!r} needs <parent link> and <child link>')
        for end in (parent.get('link'), child.get('link')):
            if end not in links:
                raise FreejointValueError(
                    f'robot_description: joint {jname!r} refers to link {end!r}, not defined')
        if child.get('link') in child_links:
            raise FreejointValueError(
                f'robot_description: link {child.get("link")!r} is the child of two joints')
        child_links.add(child.get('link'))
        children.setdefault(parent.get('link'), []).append(joint)
    roots = [name for name in links if name not in child_links]
    if len(roots) != 1:
        raise FreejointValueError(
            f'robot_description: expected one root link, got {len(roots)} ({roots})')
    base = roots[0]

    joint_names, link_names, lengths, masses, inertias, coms = [], [], [], [], [], []
    ee_link = None
    current = base
    while True:
        out = children.get(current, [])
        if not out:
            break
        if len(out) > 1:
            raise FreejointValueError(
                f'robot_description: link {current!r} has {len(out)} child joints '
                f'({", ".join(j.get("name") for j in out)}); only serial chains are supported')
        joint = out[0]
        jname, jtype = joint.get('name'), joint.get('type')
        child = joint.find('child').get('link')
        what = f'robot_description: joint {jname!r}'
        if joint.find('mimic') is not None:
            raise FreejointValueError(f'{what}: <mimic> joints are not supported')
        xyz, rpy = _origin(joint, what)
        if ee_link is not None:
            raise FreejointValueError(
                f'{what}: joint after the end-effector joint; the fixed joint must be the last')
        if jtype in _REVOLUTE:
            axis_el = joint.find('axis')
            axis = (_floats(axis_el.get('xyz'), 3, f'{what} axis') if axis_el is not None
                    else (1.0, 0.0, 0.0))   # URDF default axis
            norm = math.sqrt(sum(a * a for a in axis))
            if norm == 0.0:
                raise FreejointValueError(f'{what}: axis is the zero vector')
            unit = tuple(a / norm for a in axis)
            if abs(unit[0]) > _TOL or abs(unit[1]) > _TOL:
                raise FreejointValueError(
                    f'{what}: axis ({_fmt(axis)}) is not parallel to z; a planar arm needs '
                    f'every revolute axis along z (0 0 1)')
            if unit[2] < 0.0:
                raise FreejointValueError(
                    f'{what}: axis ({_fmt(axis)}) points along -z; use 0 0 1 (joint angles are '
                    f'counter-clockwise about +z)')
            limit = joint.find('limit')
            if jtype == 'revolute' and limit is None:
                raise FreejointValueError(f'{what}: revolute joint without <limit>')
            if jtype == 'continuous' and limit is not None and (
                    limit.get('lower') is not None or limit.get('upper') is not None):
                raise FreejointValueError(
                    f'{what}: continuous joint with position limits (lower/upper); use a '
                    f'revolute joint')
        elif jtype == 'fixed':
            pass
        else:
            raise FreejointValueError(
                f'{what}: type {jtype!r} is not supported (revolute or continuous joints '
                f'about parallel z axes, then one fixed end-effector joint)')
        if any(abs(a) > _TOL for a in rpy):
            raise FreejointValueError(
                f'{what}: origin rpy ({_fmt(rpy)}) rotates the joint frame; the planar '
                f'model needs rpy = 0 0 0 (links along x, axes along z)')
        if not joint_names:
            if abs(xyz[0]) > _TOL or abs(xyz[1]) > _TOL:
                first = 'a fixed joint before joint 1' if jtype == 'fixed' else 'the first joint'
                raise FreejointValueError(
                    f'{what}: {first} must sit at the base origin (x = y = 0), got '
                    f'xyz = ({_fmt(xyz)})')
            if jtype == 'fixed':    # a mount (e.g. world -> base_link): same x-y frame
                base = current = child
                continue
        else:
            if abs(xyz[1]) > _TOL or xyz[0] <= 0.0:
                raise FreejointValueError(
                    f'{what}: must sit on the x axis of link {current!r} at x = L > 0 '
                    f'(y = 0), got xyz = ({_fmt(xyz)})')
            lengths.append(xyz[0])
        if jtype == 'fixed':
            ee_link = child
            ee = links[child].find('inertial')
            if ee is not None and ee.find('mass') is not None:
                (m_ee,) = _floats(ee.find('mass').get('value'), 1,
                                  f'robot_description: link {child!r} mass')
                if m_ee != 0.0:
                    raise FreejointValueError(
                        f'robot_description: end-effector link {child!r} has mass {m_ee:g}; '
                        f'put the mass of a tool in the inertial of link {current!r}')
        else:
            mass, com, izz = _inertial(links[child], child)
            joint_names.append(jname)
            link_names.append(child)
            masses.append(mass)
            coms.append(com)
            inertias.append(izz)
        current = child
    if not joint_names:
        raise FreejointValueError('robot_description: no revolute joint found from the root '
                                  f'link {base!r}')
    if ee_link is None:
        raise FreejointValueError(
            f'robot_description: no end effector: add a fixed joint from {current!r} to an '
            f'end-effector link at the tip (its x is the length of {current!r})')
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
    params = ArmParams(lengths=tuple(lengths), masses=tuple(masses),
                       inertias=tuple(inertias), com=tuple(coms), passive=passive_idx,
                       gravity=-gvec[1] + 0.0)
    return UrdfArm(name=root.get('name', ''), urdf=text, joint_names=tuple(joint_names),
                   link_names=tuple(link_names), base_link=base, ee_link=ee_link,
                   passive_joints=tuple(joint_names[i] for i in passive_idx),
                   gravity_vector=gvec, params=params)


def load_urdf(path, passive_joints=(), gravity=GRAVITY_HORIZONTAL):
    """
    Read a planar serial arm from a URDF file.

    Parameters
    ----------
    path : str
        The file (``description_file``).
    passive_joints, gravity
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
    return parse_urdf(text, passive_joints, gravity)


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
