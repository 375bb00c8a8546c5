"""
Link frames of a URDF from joint positions: what robot_state_publisher computes for ``/tf``.

Every joint of the description gives one transform, parent link -> child link: the joint's
``<origin>`` (translation, then rotation by roll, pitch, yaw about fixed x, y, z), then for
a revolute or continuous joint the rotation by its position about its ``<axis>`` (for a
prismatic joint the translation along it). Fixed joints give their origin alone. No ROS
types: the viewer turns the result into messages.
"""

from dataclasses import dataclass
import math
import xml.etree.ElementTree as ET

from freejoint_core.errors import FreejointValueError
import numpy as np

_MOVING = ('revolute', 'continuous', 'prismatic')
_KNOWN = _MOVING + ('fixed',)


@dataclass(frozen=True)
class TreeJoint:
    """
    One joint of the tree.

    Attributes
    ----------
    name, kind, parent, child : str
        Joint name, URDF type, parent and child link names.
    xyz : tuple of float, (3,)
        Origin translation [m] in the parent link's frame.
    rotation : tuple of float, (4,)
        Origin rotation as a unit quaternion ``(x, y, z, w)``.
    axis : tuple of float, (3,)
        Unit axis in the joint frame (``(1, 0, 0)`` if the URDF gives none).

    """

    name: str
    kind: str
    parent: str
    child: str
    xyz: tuple
    rotation: tuple
    axis: tuple


def _floats(text, name, what):
    try:
        vals = tuple(float(v) for v in (text or '').split())
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise FreejointValueError(
            f'robot_description: joint {name!r}: {what} must be three finite numbers, '
            f'got {text!r}')
    return vals


def quat_mul(a, b):
    """
    Return the Hamilton product ``a * b`` of quaternions ``(x, y, z, w)``.

    Parameters
    ----------
    a : sequence of float, (4,)
        Left factor.
    b : sequence of float, (4,)
        Right factor.

    Returns
    -------
    tuple of float, (4,)

    """
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def _axis_angle(axis, angle):
    s = math.sin(0.5 * angle)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(0.5 * angle))


def _rpy_quat(rpy):
    roll, pitch, yaw = rpy
    return quat_mul(quat_mul(_axis_angle((0.0, 0.0, 1.0), yaw),
                             _axis_angle((0.0, 1.0, 0.0), pitch)),
                    _axis_angle((1.0, 0.0, 0.0), roll))


def quat_rotate(q, v):
    """
    Rotate the vector ``v`` by the unit quaternion ``q = (x, y, z, w)``.

    Parameters
    ----------
    q : sequence of float, (4,)
        Unit quaternion.
    v : sequence of float, (3,)
        Vector.

    Returns
    -------
    numpy.ndarray, (3,)

    """
    x, y, z, w = q
    u = np.array([x, y, z])
    v = np.asarray(v, dtype=float)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def robot_root(text):
    """
    Parse URDF text and return its ``<robot>`` element.

    Parameters
    ----------
    text : str
        The URDF text (``robot_description``).

    Returns
    -------
    xml.etree.ElementTree.Element
        The root element, tag ``robot``.

    Raises
    ------
    FreejointValueError
        ``robot_description: ...`` if the text is empty, not XML or not a ``<robot>``.

    """
    if not isinstance(text, str) or not text.strip():
        raise FreejointValueError('robot_description: expected URDF text, got an empty value')
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise FreejointValueError(f'robot_description: not well-formed XML ({exc})') from None
    if root.tag != 'robot':
        raise FreejointValueError(
            f'robot_description: root element is <{root.tag}>, expected <robot>')
    return root


class KinematicTree:
    """
    The joints of a URDF, in an order where every parent comes before its children.

    Parameters
    ----------
    text : str
        The URDF text (``robot_description``).

    Raises
    ------
    FreejointValueError
        ``robot_description: ...`` naming the problem: not XML, not a ``<robot>``, a joint
        without name, type, parent or child, an unknown link, a link with two parent
        joints, a joint type this module does not handle, a zero axis, or a loop.

    """

    def __init__(self, text):
        root = robot_root(text)
        links = [link.get('name') for link in root.findall('link')]
        if not all(links) or len(set(links)) != len(links):
            raise FreejointValueError(
                'robot_description: every <link> needs a name, each name once')
        joints = {}
        for elem in root.findall('joint'):
            joint = self._joint(elem, set(links))
            if joint.name in joints:
                raise FreejointValueError(
                    f'robot_description: joint {joint.name!r} is defined twice')
            joints[joint.name] = joint
        by_child = {}
        for joint in joints.values():
            if joint.child in by_child:
                raise FreejointValueError(
                    f'robot_description: link {joint.child!r} is the child of two joints '
                    f'({by_child[joint.child].name!r}, {joint.name!r})')
            by_child[joint.child] = joint
        roots = [name for name in links if name not in by_child]
        if len(roots) != 1:
            raise FreejointValueError(
                f'robot_description: expected one root link, found {roots}')
        ordered, frontier = [], [roots[0]]
        while frontier:
            parent = frontier.pop(0)
            for joint in joints.values():
                if joint.parent == parent:
                    ordered.append(joint)
                    frontier.append(joint.child)
        if len(ordered) != len(joints):
            raise FreejointValueError(
                'robot_description: the joints do not form a tree from the root link')
        self.root = roots[0]
        self.joints = tuple(ordered)
        self.moving = tuple(j.name for j in ordered if j.kind in _MOVING)

    @staticmethod
    def _joint(elem, links):
        name = elem.get('name')
        kind = elem.get('type')
        if not name:
            raise FreejointValueError('robot_description: a <joint> has no name')
        if kind not in _KNOWN:
            raise FreejointValueError(
                f'robot_description: joint {name!r}: type {kind!r} not handled '
                f'(expected one of {_KNOWN})')
        ends = []
        for tag in ('parent', 'child'):
            node = elem.find(tag)
            link = node.get('link') if node is not None else None
            if link not in links:
                raise FreejointValueError(
                    f'robot_description: joint {name!r}: {tag} link {link!r} is not a <link>')
            ends.append(link)
        origin = elem.find('origin')
        xyz = _floats(origin.get('xyz', '0 0 0') if origin is not None else '0 0 0',
                      name, 'origin xyz')
        rpy = _floats(origin.get('rpy', '0 0 0') if origin is not None else '0 0 0',
                      name, 'origin rpy')
        axis_elem = elem.find('axis')
        axis = _floats(axis_elem.get('xyz', '1 0 0') if axis_elem is not None else '1 0 0',
                       name, 'axis')
        norm = math.sqrt(sum(a * a for a in axis))
        if norm == 0.0:
            raise FreejointValueError(f'robot_description: joint {name!r}: zero axis')
        return TreeJoint(name=name, kind=kind, parent=ends[0], child=ends[1], xyz=xyz,
                         rotation=_rpy_quat(rpy), axis=tuple(a / norm for a in axis))

    def transforms(self, positions):
        """
        Return the transform of every joint for the given joint positions.

        Parameters
        ----------
        positions : mapping of str to float
            Position [rad or m] of each moving joint by name; a moving joint missing
            from it is at 0 (robot_state_publisher leaves its frame out instead: here
            the whole tree is always given).

        Returns
        -------
        list of (str, str, tuple of float (3,), tuple of float (4,))
            ``(parent, child, translation [m], rotation (x, y, z, w))`` per joint, parents
            first.

        Raises
        ------
        FreejointValueError
            ``positions: ...`` naming a joint whose position is not finite.

        """
        out = []
        for joint in self.joints:
            xyz, rot = joint.xyz, joint.rotation
            if joint.kind in _MOVING:
                value = float(positions.get(joint.name, 0.0))
                if not math.isfinite(value):
                    raise FreejointValueError(
                        f'positions: joint {joint.name!r} is not finite ({value})')
                if joint.kind == 'prismatic':
                    shift = quat_rotate(rot, np.asarray(joint.axis) * value)
                    xyz = tuple(float(a + b) for a, b in zip(xyz, shift))
                else:
                    rot = quat_mul(rot, _axis_angle(joint.axis, value))
            out.append((joint.parent, joint.child, tuple(xyz), tuple(rot)))
        return out

    def frame_positions(self, positions):
        """
        Return the origin of every link in the root link's frame.

        Parameters
        ----------
        positions : mapping of str to float
            As :meth:`transforms`.

        Returns
        -------
        dict of str to numpy.ndarray (3,)
            Link name -> origin [m] in the root frame (the root at zero).

        """
        poses = {self.root: (np.zeros(3), (0.0, 0.0, 0.0, 1.0))}
        for parent, child, xyz, rot in self.transforms(positions):
            p_pos, p_rot = poses[parent]
            poses[child] = (p_pos + quat_rotate(p_rot, xyz), quat_mul(p_rot, rot))
        return {name: pos for name, (pos, _) in poses.items()}
