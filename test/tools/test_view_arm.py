"""
What the viewer shows of a spatial arm (``freejoint_tools.view_arm``), in one process.

The link frames of ``/tf`` against Pinocchio's placements, the arm model's tip, a second
implementation of the URDF tree (``freejoint_core.kinematic_tree``) and hand values; the
URDF served to Foxglove (meshes reachable, missing ones replaced, one note); the paths.
"""
import math
import os
import xml.etree.ElementTree as ET

from freejoint_core.errors import FreejointValueError
from freejoint_core.kinematic_tree import KinematicTree, quat_mul, quat_rotate
from freejoint_core.spatial_model import known_arm, KNOWN_ARMS, robot_data_dir
from freejoint_core.urdf import shipped_urdf_path
from freejoint_tools.view_arm import FILES_PACKAGE, link_frames, serve_description
from freejoint_tools.view_arm import SpatialTree, Trail
import numpy as np
import pinocchio as pin
import pytest

UR5_POSTURE = (0.3, -1.2, 1.6, -1.97, -1.5708, 0.7)
"""The demo's start posture with the pan and wrist 3 turned."""


def _text(arm):
    with open(os.path.join(robot_data_dir(), KNOWN_ARMS[arm][0]), encoding='utf-8') as fh:
        return fh.read()


def _rotation(q):
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    return np.column_stack([quat_rotate(q, e) for e in np.eye(3)])


def _compose(transforms, root):
    """Return {link: (position, quaternion)} in the root frame from parent -> child transforms."""
    poses = {root: (np.zeros(3), (0.0, 0.0, 0.0, 1.0))}
    for parent, child, xyz, rot in transforms:
        p_pos, p_rot = poses[parent]
        poses[child] = (p_pos + quat_rotate(p_rot, xyz), quat_mul(p_rot, rot))
    return poses


def _ur5_positions(q):
    return dict(zip(known_arm('ur5').joint_names, q))


def test_ur5_frames_of_every_link_compose_to_pinocchios_placement_of_the_link():
    text = _text('ur5')
    tree = link_frames(text)
    assert isinstance(tree, SpatialTree) and tree.root == 'world'
    model = pin.buildModelFromXML(text)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.array(UR5_POSTURE))
    poses = _compose(tree.transforms(_ur5_positions(UR5_POSTURE)), tree.root)
    links = {link.get('name') for link in ET.fromstring(text).findall('link')}
    assert set(poses) == links
    for link, (pos, rot) in poses.items():
        placement = data.oMf[model.getFrameId(link, pin.FrameType.BODY)]
        assert pos == pytest.approx(placement.translation, abs=1e-12), link
        assert _rotation(rot) == pytest.approx(placement.rotation, abs=1e-12), link


def test_ur5_tip_frame_is_the_arm_models_tip_placement():
    arm = known_arm('ur5', ['wrist_2_joint'])
    tree = SpatialTree(_text('ur5'))
    rng = np.random.default_rng(0)
    for q in [np.array(UR5_POSTURE)] + [rng.uniform(arm.lower, arm.upper) for _ in range(10)]:
        pos, rot = _compose(tree.transforms(_ur5_positions(q)), tree.root)['tool0']
        p, R = arm.placement(q)
        assert pos == pytest.approx(p, abs=1e-12)
        assert _rotation(rot) == pytest.approx(R, abs=1e-12)


def test_ur5_at_zero_posture_frames_are_the_hand_computed_lengths():
    # At q = 0 the arm lies along x: shoulder height d1 = 0.089159, upper arm 0.425,
    # forearm 0.39225; the side offsets 0.13585 - 0.1197 (elbow), + 0.093 (wrist 2) and
    # + 0.0823 (tool) along y; wrist 3 hangs 0.09465 below the wrist (two quarter turns
    # about y point its z down). The URDF writes a quarter turn as 1.57079632679 rad
    # (5e-12 short): hence 1e-10.
    tree = SpatialTree(_text('ur5'))
    transforms = tree.transforms({})
    assert transforms[0] == ('world', 'base_link', (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    parent, child, xyz, rot = transforms[1]
    assert (parent, child) == ('base_link', 'shoulder_link')
    assert xyz == pytest.approx((0.0, 0.0, 0.089159), abs=1e-15)
    assert rot == pytest.approx((0.0, 0.0, 0.0, 1.0), abs=1e-15)
    poses = _compose(transforms, tree.root)
    hand = {'upper_arm_link': (0.0, 0.13585, 0.089159),
            'forearm_link': (0.425, 0.01615, 0.089159),
            'wrist_1_link': (0.81725, 0.01615, 0.089159),
            'wrist_2_link': (0.81725, 0.10915, 0.089159),
            'wrist_3_link': (0.81725, 0.10915, -0.005491),
            'tool0': (0.81725, 0.19145, -0.005491)}
    for link, xyz in hand.items():
        assert poses[link][0] == pytest.approx(xyz, abs=1e-10), link
    half_turn_y = np.diag([-1.0, 1.0, -1.0])
    assert _rotation(poses['wrist_3_link'][1]) == pytest.approx(half_turn_y, abs=1e-10)


@pytest.mark.parametrize('arm', ['ur5', 'panda'])
def test_frames_equal_the_urdf_tree_composed_by_hand_at_random_postures(arm):
    # KinematicTree composes each joint's origin and motion itself (numpy, no Pinocchio).
    text = _text(arm)
    tree, other = SpatialTree(text), KinematicTree(text)
    rng = np.random.default_rng(1)
    for _ in range(20):
        positions = {name: rng.uniform(-3.0, 3.0) for name in tree.moving}
        positions.update({name: 0.02 for name in tree.moving if 'finger' in name})
        for (p, c, xyz, rot), (p2, c2, xyz2, rot2) in zip(tree.transforms(positions),
                                                          other.transforms(positions)):
            assert (p, c) == (p2, c2)
            assert xyz == pytest.approx(xyz2, abs=1e-12)
            assert _rotation(rot) == pytest.approx(_rotation(rot2), abs=1e-12)
            assert rot[3] >= 0.0 and math.fsum(v * v for v in rot) == pytest.approx(1.0)


def test_joints_missing_from_the_joint_states_are_drawn_at_their_locked_value():
    # The Panda's joint states carry its seven chain joints: the fingers (locked at 0 by
    # the arm model) still get their frames, at the joint origins.
    text = _text('panda')
    tree = SpatialTree(text)
    chain = known_arm('panda').joint_names
    transforms = tree.transforms(dict(zip(chain, np.linspace(-1.0, 1.0, 7))))
    children = [c for _, c, _, _ in transforms]
    links = {link.get('name') for link in ET.fromstring(text).findall('link')}
    assert sorted(children) == sorted(links - {tree.root})
    finger = next(t for t in transforms if t[1] == 'panda_leftfinger')
    assert finger[2] == pytest.approx((0.0, 0.0, 0.0584), abs=1e-12)
    moved = next(t for t in tree.transforms({'panda_finger_joint1': 0.03})
                 if t[1] == 'panda_leftfinger')
    assert moved[2] == pytest.approx((0.0, 0.03, 0.0584), abs=1e-12)


def test_a_non_finite_position_is_refused_naming_the_joint():
    tree = SpatialTree(_text('ur5'))
    with pytest.raises(FreejointValueError, match="positions: joint 'elbow_joint'"):
        tree.transforms({'elbow_joint': float('nan')})


@pytest.mark.parametrize('name', ['paper_arm', 'four_link_arm'])
def test_planar_arms_keep_their_kinematic_tree_and_their_urdf_text(name):
    with open(shipped_urdf_path(name), encoding='utf-8') as fh:
        text = fh.read()
    assert type(link_frames(text)) is KinematicTree
    served = serve_description(text)
    assert served.text is text and served.assets == {} and served.note == ''


@pytest.mark.parametrize('arm', ['ur5', 'panda'])
def test_every_mesh_uri_of_the_served_urdf_is_served_with_the_file_it_names(arm):
    text = _text(arm)
    served = serve_description(text)
    assert served.text is text and served.note == ''   # package:// URIs stay: fetchAsset
    uris = {m.get('filename') for m in ET.fromstring(text).iter('mesh')}
    assert uris and set(served.assets) == uris
    share = os.path.dirname(robot_data_dir())     # share/example-robot-data
    for uri in uris:
        assert uri.startswith('package://example-robot-data/')
        path = os.path.join(share, uri[len('package://example-robot-data/'):])
        assert served.assets[uri] == path and os.path.isfile(path)
        with open(path, 'rb') as fh:
            assert served.asset(uri) == fh.read()


def test_only_the_urdfs_meshes_and_files_beside_them_are_served(tmp_path):
    meshes = tmp_path / 'pkg' / 'meshes'
    meshes.mkdir(parents=True)
    (meshes / 'link.dae').write_bytes(b'dae')
    (meshes / 'skin.png').write_bytes(b'png')
    (tmp_path / 'pkg' / 'secret.txt').write_bytes(b'no')
    text = ('<robot name="r"><link name="a"><visual><geometry><mesh filename='
            '"package://pkg/meshes/link.dae"/></geometry></visual></link></robot>')

    def resolve(uri):
        return str(tmp_path / uri[len('package://'):])
    served = serve_description(text, resolve_package=resolve)
    assert served.asset('package://pkg/meshes/link.dae') == b'dae'
    assert served.asset('package://pkg/meshes/skin.png') == b'png'       # a texture beside it
    for uri in ('package://pkg/secret.txt', 'package://pkg/meshes/../secret.txt',
                'package://pkg/meshes/nothing.png', 'package://other/meshes/skin.png',
                'file://%s' % (tmp_path / 'pkg' / 'secret.txt')):
        assert served.asset(uri) is None, uri


def test_a_mesh_named_by_path_is_renamed_to_a_package_uri_the_viewer_serves(tmp_path):
    (tmp_path / 'meshes').mkdir()
    (tmp_path / 'meshes' / 'a.stl').write_bytes(b'solid a')
    (tmp_path / 'meshes' / 'b.stl').write_bytes(b'solid b')
    text = ('<robot name="r"><link name="a">'
            '<visual><geometry><mesh filename="meshes/a.stl"/></geometry></visual>'
            '<collision><geometry><mesh filename="file://%s"/></geometry></collision>'
            '</link></robot>' % (tmp_path / 'meshes' / 'b.stl'))
    served = serve_description(text, base_dir=str(tmp_path))
    got = [m.get('filename') for m in ET.fromstring(served.text).iter('mesh')]
    assert got == ['package://%s%s' % (FILES_PACKAGE, tmp_path / 'meshes' / name)
                   for name in ('a.stl', 'b.stl')]
    assert [served.asset(uri) for uri in got] == [b'solid a', b'solid b']
    assert served.note == ''


def _ur5_with(replacements):
    text = _text('ur5')
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new)
    return text


VISUAL = 'package://example-robot-data/robots/ur_description/meshes/ur5/visual/forearm.dae'
COLLISION = 'package://example-robot-data/robots/ur_description/meshes/ur5/collision/forearm.stl'


def test_a_missing_visual_mesh_falls_back_to_the_links_collision_mesh_with_one_note():
    text = _ur5_with([(VISUAL, VISUAL.replace('forearm.dae', 'gone.dae'))])
    served = serve_description(text)
    link = next(link for link in ET.fromstring(served.text).findall('link')
                if link.get('name') == 'forearm_link')
    assert [m.get('filename') for m in link.iter('mesh')] == [COLLISION, COLLISION]
    assert VISUAL.replace('forearm.dae', 'gone.dae') not in served.text
    assert served.missing == (('forearm_link', VISUAL.replace('forearm.dae', 'gone.dae')),)
    assert '\n' not in served.note
    assert served.note.startswith('1 mesh not found (first: %s of link forearm_link)'
                                  % VISUAL.replace('forearm.dae', 'gone.dae'))
    assert 'forearm_link drawn with their collision geometry' in served.note
    assert link_frames(served.text).transforms({})   # still a URDF the viewer draws


def test_a_link_without_any_mesh_found_is_drawn_as_lines_to_its_child_joint_frames():
    # forearm_link's child joint (wrist_1_joint) sits at (0, 0, 0.39225) in its frame.
    gone = [(VISUAL, 'package://example-robot-data/nowhere/a.dae'),
            (COLLISION, 'package://example-robot-data/nowhere/a.stl')]
    served = serve_description(_ur5_with(gone))
    link = next(link for link in ET.fromstring(served.text).findall('link')
                if link.get('name') == 'forearm_link')
    assert link.findall('collision') == []
    (visual,) = link.findall('visual')
    cylinder = visual.find('geometry/cylinder')
    assert float(cylinder.get('length')) == pytest.approx(0.39225, abs=1e-15)
    origin = [float(v) for v in visual.find('origin').get('xyz').split()]
    rpy = [float(v) for v in visual.find('origin').get('rpy').split()]
    assert origin == pytest.approx([0.0, 0.0, 0.39225 / 2], abs=1e-15)
    assert rpy == pytest.approx([0.0, 0.0, 0.0], abs=1e-15)     # z already along the line
    assert len(served.missing) == 2 and '\n' not in served.note
    assert served.note.startswith('2 meshes not found')
    assert 'forearm_link as lines between the joint frames' in served.note


def test_lines_between_joint_frames_point_at_the_child_joint_origin():
    text = ('<robot name="r"><link name="a"><visual><geometry><mesh filename="x.dae"/>'
            '</geometry></visual></link><link name="b"/>'
            '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
            '<origin xyz="0.3 -0.4 1.2"/><axis xyz="0 0 1"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    served = serve_description(text)
    visual = ET.fromstring(served.text).find('link/visual')
    rpy = [float(v) for v in visual.find('origin').get('rpy').split()]
    roll, pitch, yaw = rpy
    # URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll); the cylinder's axis is its z
    axis = (math.cos(yaw) * math.sin(pitch), math.sin(yaw) * math.sin(pitch), math.cos(pitch))
    assert axis == pytest.approx(np.array([0.3, -0.4, 1.2]) / 1.3, abs=1e-12)
    assert float(visual.find('geometry/cylinder').get('length')) == pytest.approx(1.3)
    assert served.note.startswith('1 mesh not found (first: x.dae of link a)')


def test_trail_keeps_points_a_spacing_apart_and_starts_again_when_time_goes_back():
    trail = Trail(spacing=0.001, limit=4)
    assert trail.add(0, (0.0, 0.0, 0.0), 'base_link')
    assert not trail.add(1, (0.0005, 0.0, 0.0))            # closer than the spacing
    assert trail.add(2, (0.001, 0.0, 0.0))
    assert not trail.add(3, (float('nan'), 0.0, 0.0))
    assert trail.add(4, (0.5, 0.5))                         # planar: z = 0
    assert trail.points == [(0.0, 0.0, 0.0), (0.001, 0.0, 0.0), (0.5, 0.5, 0.0)]
    for k in range(5, 8):
        trail.add(k, (float(k), 0.0, 0.0))
    assert len(trail.points) == 4 and trail.points[0] == (0.5, 0.5, 0.0)   # oldest dropped
    assert trail.add(0, (9.0, 9.0, 9.0), 'world')           # a new run: sim time from 0
    assert trail.points == [(9.0, 9.0, 9.0)] and trail.frame_id == 'world'
