"""
What the viewer shows of an arm, without ROS: link frames, the URDF it serves, its meshes.

* :func:`link_frames` picks the frames of ``/tf``: a planar arm (a URDF
  ``freejoint_core.urdf.parse_urdf`` reads) keeps ``freejoint_core.kinematic_tree``; any
  other URDF - a spatial arm, the UR5 or the Panda of example-robot-data - gets
  :class:`SpatialTree`, Pinocchio's forward kinematics of the whole URDF tree.
* :func:`serve_description` makes the URDF's meshes reachable by Foxglove. ``package://``
  URIs stay as they are: Foxglove asks the server it is connected to for them (the
  WebSocket protocol's ``fetchAsset``, capability ``assets``, as foxglove_bridge serves
  them) and the viewer answers with the file's bytes (:meth:`ServedDescription.asset`);
  a mesh named by a file path (absolute, ``file://`` or relative to the URDF's file) is
  renamed ``package://freejoint_viewer/<absolute path>`` and served the same way. A mesh
  not found falls back to the link's collision geometry, else to lines between the
  link's joint frames; ``ServedDescription.note`` says so in one line.
* :class:`Trail` keeps a path (the tip, the setpoints) as points for a line marker.
"""

from dataclasses import dataclass, field
import math
import os
import posixpath
from urllib.parse import unquote, urlparse
import xml.etree.ElementTree as ET

from freejoint_core.errors import FreejointValueError
from freejoint_core.kinematic_tree import KinematicTree, robot_root
import numpy as np

PACKAGE_SCHEME = 'package://'
FILES_PACKAGE = 'freejoint_viewer'
"""The package name under which the viewer serves meshes a URDF names by file path."""
LINE_RADIUS = 0.008
"""Radius [m] of the cylinders drawn between joint frames for a link whose mesh is missing."""
_REMOTE = ('http://', 'https://')


def is_planar(text):
    """Return True if ``text`` is a planar arm the planar model reads (``parse_urdf``)."""
    from freejoint_core.urdf import parse_urdf
    try:
        parse_urdf(text)
    except FreejointValueError:
        return False
    return True


def link_frames(text):
    """
    Return the link frames of a URDF for ``/tf``: KinematicTree if planar, else SpatialTree.

    A URDF that is not planar and that Pinocchio cannot read gets KinematicTree too (the
    viewer's frames before spatial arms).

    Raises
    ------
    FreejointValueError
        ``robot_description: ...`` if neither reads it.

    """
    if is_planar(text):
        return KinematicTree(text)
    try:
        return SpatialTree(text)
    except FreejointValueError:
        return KinematicTree(text)


def _quaternion(rot):
    """Return the unit quaternion ``(x, y, z, w)`` of a rotation matrix (w >= 0)."""
    import pinocchio as pin
    x, y, z, w = (float(v) for v in pin.Quaternion(np.asarray(rot)).coeffs())
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    return (x, y, z, w)


class SpatialTree:
    """
    Link frames of any URDF from Pinocchio's forward kinematics (what robot_state_publisher sends).

    One transform per URDF joint, parent link -> child link (the placement of the child
    link's frame in the parent link's), fixed joints included; a moving joint missing from
    the positions is at its locked value, 0 clipped into its limits (as
    ``freejoint_core.spatial_model.SpatialArm`` locks the joints off its chain, e.g. the
    Panda's fingers), so every link always has its frame.

    Parameters
    ----------
    text : str
        URDF text.

    Attributes
    ----------
    root : str
        The root link.
    joints : tuple of (str, str)
        ``(parent, child)`` link names per URDF joint, parents first.
    moving : tuple of str
        The moving joints (Pinocchio's order).

    Raises
    ------
    FreejointValueError
        ``robot_description: ...`` if the URDF is no tree or Pinocchio cannot read it.

    """

    def __init__(self, text):
        import pinocchio as pin
        tree = KinematicTree(text)
        try:
            model = pin.buildModelFromXML(text)
        except (RuntimeError, ValueError) as exc:
            raise FreejointValueError(
                f'robot_description: Pinocchio cannot read it ({exc})') from None
        self._pin = pin
        self.model = model
        self.data = model.createData()
        self.root = tree.root
        self.joints = tuple((j.parent, j.child) for j in tree.joints)
        body = pin.FrameType.BODY
        self._frames = {}
        for parent, child in self.joints:
            for link in (parent, child):
                if link not in self._frames:
                    if not model.existFrame(link, body):
                        raise FreejointValueError(
                            f"robot_description: link {link!r} has no frame in Pinocchio's "
                            'model')
                    self._frames[link] = model.getFrameId(link, body)
        self.moving = tuple(model.names[1:])
        self._slots = {}
        q_ref = np.zeros(model.nq)
        for j in range(1, model.njoints):
            idx, nq = model.joints[j].idx_q, model.joints[j].nq
            if nq == 1:
                q_ref[idx] = min(max(0.0, model.lowerPositionLimit[idx]),
                                 model.upperPositionLimit[idx])
            elif nq == 2:       # continuous: (cos, sin)
                q_ref[idx] = 1.0
            else:
                raise FreejointValueError(
                    f'robot_description: joint {model.names[j]!r} has {nq} configuration '
                    'entries; the viewer draws 1-degree-of-freedom joints')
            self._slots[model.names[j]] = (idx, nq)
        self._q_ref = q_ref

    def configuration(self, positions):
        """
        Return Pinocchio's configuration of joint positions by name.

        Parameters
        ----------
        positions : mapping of str to float
            Position [rad or m] of moving joints by name; names of no joint are ignored.

        Raises
        ------
        FreejointValueError
            ``positions: ...`` naming a joint whose position is not finite.

        """
        q = self._q_ref.copy()
        for name, (idx, nq) in self._slots.items():
            if name not in positions:
                continue
            value = float(positions[name])
            if not math.isfinite(value):
                raise FreejointValueError(f'positions: joint {name!r} is not finite ({value})')
            if nq == 1:
                q[idx] = value
            else:
                q[idx], q[idx + 1] = math.cos(value), math.sin(value)
        return q

    def placements(self, positions):
        """Return ``{link: (translation (3,), rotation (3, 3))}`` in the root link's frame."""
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, self.configuration(positions))
        placed = self.data.oMf
        return {link: (np.array(placed[f].translation), np.array(placed[f].rotation))
                for link, f in self._frames.items()}

    def transforms(self, positions):
        """
        Return the transform of every URDF joint (as ``KinematicTree.transforms``).

        Returns
        -------
        list of (str, str, tuple of float (3,), tuple of float (4,))
            ``(parent, child, translation [m], rotation (x, y, z, w))``, parents first.

        """
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, self.configuration(positions))
        out = []
        for parent, child in self.joints:
            rel = self.data.oMf[self._frames[parent]].actInv(self.data.oMf[self._frames[child]])
            out.append((parent, child, tuple(float(v) for v in rel.translation),
                        _quaternion(rel.rotation)))
        return out


@dataclass(frozen=True)
class ServedDescription:
    """
    The URDF text the viewer serves and the files behind its mesh URIs.

    Attributes
    ----------
    text : str
        The URDF to serve (the given text itself, unchanged, when every mesh is found
        under its ``package://`` URI or the URDF has none).
    assets : dict of str to str
        Mesh URI (as in ``text``) -> the file it is.
    missing : tuple of (str, str)
        ``(link, filename)`` of each mesh not found.
    note : str
        One line on the missing meshes and what was drawn instead ('' if none).

    """

    text: str
    assets: dict = field(default_factory=dict)
    missing: tuple = ()
    note: str = ''

    def asset(self, uri):
        """
        Return the bytes behind ``uri``, or None if the viewer does not serve it.

        Served: the URIs of the URDF's meshes and, for textures a mesh names relative to
        itself, files under a served mesh's directory (never outside it).
        """
        path = self.assets.get(uri)
        if path is None:
            path = self._beside_a_mesh(uri)
        if path is None:
            return None
        try:
            with open(path, 'rb') as fh:
                return fh.read()
        except OSError:
            return None

    def _beside_a_mesh(self, uri):
        if not uri.startswith(PACKAGE_SCHEME) or '\\' in uri:
            return None
        norm = posixpath.normpath(uri[len(PACKAGE_SCHEME):])
        if norm.startswith(('..', '/')) or '/../' in '/' + norm + '/':
            return None
        for served, path in self.assets.items():
            folder = posixpath.dirname(served[len(PACKAGE_SCHEME):])
            if norm.startswith(folder + '/'):
                candidate = os.path.join(os.path.dirname(path), norm[len(folder) + 1:])
                real_dir = os.path.realpath(os.path.dirname(path))
                if os.path.realpath(candidate).startswith(real_dir + os.sep) and \
                        os.path.isfile(candidate):
                    return candidate
        return None


def resolve_mesh(filename, base_dir=None, resolve_package=None):
    """
    Return the file a URDF mesh ``filename`` names, or None if it is not found.

    Parameters
    ----------
    filename : str
        ``package://<pkg>/<path>``, ``file://<path>``, an absolute path, or a path relative
        to ``base_dir``.
    base_dir : str or None
        Directory of the URDF file (None: relative paths are not found).
    resolve_package : callable or None
        ``package://`` URI -> path, raising FreejointValueError if not found (default
        ``freejoint_common.arm_description.package_path``: share/<pkg> of
        AMENT_PREFIX_PATH, example-robot-data in the PyPI wheel).

    """
    if not filename:
        return None
    if filename.startswith(PACKAGE_SCHEME):
        if resolve_package is None:
            from freejoint_common.arm_description import package_path as resolve_package
        try:
            path = resolve_package(filename)
        except FreejointValueError:
            return None
    elif filename.startswith('file://'):
        path = unquote(urlparse(filename).path)
    elif os.path.isabs(filename):
        path = filename
    elif base_dir and '://' not in filename:
        path = os.path.join(base_dir, filename)
    else:
        return None
    return os.path.abspath(path) if os.path.isfile(path) else None


def _fmt(values):
    return ' '.join(repr(float(v)) for v in values)


def _lines_visual(child_origins):
    """Return ``<visual>`` elements: a thin cylinder from the link's origin to each point."""
    out = []
    for xyz in child_origins:
        v = np.asarray(xyz, dtype=float)
        length = float(np.linalg.norm(v))
        if length < 1e-6:
            continue
        u = v / length
        pitch = math.atan2(math.hypot(u[0], u[1]), u[2])
        yaw = math.atan2(u[1], u[0])
        visual = ET.Element('visual', name='joint_frames_line')
        ET.SubElement(visual, 'origin', xyz=_fmt(v / 2.0), rpy=_fmt((0.0, pitch, yaw)))
        geometry = ET.SubElement(visual, 'geometry')
        ET.SubElement(geometry, 'cylinder', radius=repr(LINE_RADIUS), length=repr(length))
        out.append(visual)
    return out


def serve_description(text, base_dir=None, resolve_package=None):
    """
    Return the URDF to serve and its assets: meshes reachable, missing ones replaced.

    Parameters
    ----------
    text : str
        URDF text.
    base_dir : str or None
        Directory of the URDF's file, for meshes named relative to it.
    resolve_package : callable or None
        As :func:`resolve_mesh`.

    Returns
    -------
    ServedDescription
        ``text`` is the given one unchanged when nothing had to change; otherwise mesh
        paths renamed ``package://freejoint_viewer/<path>``, a ``<visual>`` whose mesh is
        missing replaced by the link's first usable ``<collision>`` geometry (its origin
        and geometry; the visual's material kept), else by thin cylinders from the link's
        origin to each child joint's origin (lines between the joint frames), and
        ``<collision>`` elements whose mesh is missing left out.

    Raises
    ------
    FreejointValueError
        ``robot_description: ...`` if the text is not a URDF.

    """
    root = robot_root(text)
    assets, missing = {}, []
    collision_links, line_links = [], []
    changed = False
    child_origins = {}
    for joint in root.findall('joint'):
        parent, origin = joint.find('parent'), joint.find('origin')
        if parent is None:
            continue
        try:
            xyz = [float(v) for v in (origin.get('xyz', '0 0 0') if origin is not None
                                      else '0 0 0').split()]
        except ValueError:
            continue
        if len(xyz) == 3 and all(math.isfinite(v) for v in xyz):
            child_origins.setdefault(parent.get('link'), []).append(xyz)

    def usable(elem):
        """Resolve ``elem``'s mesh in place; True if it can be drawn."""
        nonlocal changed
        mesh = elem.find('geometry/mesh')
        if mesh is None:
            return True          # a primitive (or nothing to draw)
        name = mesh.get('filename', '')
        if name.startswith(_REMOTE):
            return True          # Foxglove fetches URLs itself
        if name in assets:
            return True
        path = resolve_mesh(name, base_dir, resolve_package)
        if path is None:
            return False
        uri = name
        if not name.startswith(PACKAGE_SCHEME):
            uri = PACKAGE_SCHEME + FILES_PACKAGE + path.replace(os.sep, '/')
            mesh.set('filename', uri)
            changed = True
        assets[uri] = path
        return True

    for link in root.findall('link'):
        name = link.get('name', '')
        fine = []
        for elem in link.findall('collision'):
            if usable(elem):
                fine.append(elem)
            else:
                missing.append((name, elem.find('geometry/mesh').get('filename', '')))
                link.remove(elem)
                changed = True
        drew_lines = False
        for elem in link.findall('visual'):
            if usable(elem):
                continue
            missing.append((name, elem.find('geometry/mesh').get('filename', '')))
            changed = True
            at = list(link).index(elem)
            link.remove(elem)
            if fine:
                for tag in ('origin', 'geometry'):
                    old = elem.find(tag)
                    if old is not None:
                        elem.remove(old)
                for tag in ('origin', 'geometry'):
                    new = fine[0].find(tag)
                    if new is not None:
                        elem.insert(0 if tag == 'origin' else len(elem), _copy(new))
                link.insert(at, elem)
                if name not in collision_links:
                    collision_links.append(name)
            elif not drew_lines:
                drew_lines = True
                for k, line in enumerate(_lines_visual(child_origins.get(name, ()))):
                    link.insert(at + k, line)
                line_links.append(name)
    if not changed:
        return ServedDescription(text, assets)
    note = ''
    if missing:
        parts = []
        if collision_links:
            parts.append('%s drawn with their collision geometry' % ', '.join(collision_links))
        if line_links:
            parts.append('%s as lines between the joint frames' % ', '.join(line_links))
        note = ('%d mesh%s not found (first: %s of link %s)%s' % (
            len(missing), 'es' if len(missing) > 1 else '', missing[0][1], missing[0][0],
            ': ' + '; '.join(parts) if parts else ''))
    return ServedDescription(ET.tostring(root, encoding='unicode'), assets, tuple(missing),
                             note)


def _copy(elem):
    return ET.fromstring(ET.tostring(elem))


class Trail:
    """
    A path as points for a line marker: each point at least ``spacing`` from the last.

    Parameters
    ----------
    spacing : float
        Least distance [m] between kept points.
    limit : int
        Most points kept (the oldest dropped first).

    Attributes
    ----------
    points : list of tuple of float (3,)
        The kept points, oldest first.
    frame_id : str
        The frame of the last point added.

    """

    def __init__(self, spacing=1e-3, limit=20000):
        self.spacing = float(spacing)
        self.limit = int(limit)
        self.points = []
        self.frame_id = ''
        self._last_ns = None

    def clear(self):
        """Forget every point."""
        self.points = []
        self._last_ns = None

    def add(self, stamp_ns, point, frame_id=''):
        """
        Add a point stamped ``stamp_ns``; return True if the trail changed.

        A stamp earlier than the last one (sim time restarting with the next run) starts
        the trail again; a point with a non-finite coordinate is ignored; 2 values are a
        planar point (z = 0).
        """
        p = tuple(float(v) for v in point)
        if len(p) == 2:
            p = p + (0.0,)
        if len(p) != 3 or not all(math.isfinite(v) for v in p):
            return False
        changed = False
        if self._last_ns is not None and stamp_ns < self._last_ns:
            self.points = []
            changed = True
        self._last_ns = stamp_ns
        self.frame_id = frame_id
        if self.points and math.dist(p, self.points[-1]) < self.spacing:
            return changed
        self.points.append(p)
        if len(self.points) > self.limit:
            del self.points[:len(self.points) - self.limit]
        return True
