"""
URDFs in their own frames: any common axis, link direction and base offset; branches.

Two descriptions written here by their published layout (not copied): an rrbot-like arm
(the two-link arm of gazebo_ros_demos: a base column, joints about y, links along z, a
laser and a camera on fixed joints at the top of the last link) and a 3-link arm along x
whose first joint sits off the base origin. Both are accepted unchanged with ``tip_link``
set, and the core's kinematics in their task frame match a hand computation. The rrbot
standing in its own world (gravity -z, its straight zero pose up) turns its task frame to
put gravity along -y, with joint 1's zero-angle offset; Pinocchio on the URDF in its own
angles cross-checks the gravity torques.
"""
import math

from freejoint_core.arm import ArmModel
from freejoint_core.errors import FreejointValueError
from freejoint_core.urdf import parse_urdf
import numpy as np
import pytest


def _box(mass, a, b, c):
    """Return the mass and inertia of a box a x b x c (m) about its centre (URDF)."""
    return (f'<mass value="{mass}"/><inertia ixx="{mass * (b * b + c * c) / 12}" ixy="0" '
            f'ixz="0" iyy="{mass * (a * a + c * c) / 12}" iyz="0" '
            f'izz="{mass * (a * a + b * b) / 12}"/>')


def _link(name, mass=None, xyz='0 0 0', size=(0.1, 0.1, 1.0)):
    if mass is None:
        return f'<link name="{name}"/>'
    return (f'<link name="{name}"><inertial><origin xyz="{xyz}" rpy="0 0 0"/>'
            f'{_box(mass, *size)}</inertial></link>')


def _joint(name, kind, parent, child, xyz, axis=None):
    out = (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
           f'<child link="{child}"/><origin xyz="{xyz}" rpy="0 0 0"/>')
    if axis:
        out += f'<axis xyz="{axis}"/>'
    if kind == 'continuous':
        out += '<dynamics damping="0.7"/>'
    return out + '</joint>'


# rrbot's layout with a third link in its own pattern: width 0.1, heights 2 / 1 / 1 / 1,
# axle offset 0.05, masses 1; joint1 at the top of the base column (z = 1.95), each next
# joint 0.9 above the one before, the laser 0.975 above joint3, the camera 0.9 above joint3
# and 0.05 to the side; both sensors 1e-5 kg.
RRBOT = ''.join([
    '<robot name="rrbot_like">', _link('world'),
    _joint('fixed', 'fixed', 'world', 'link1', '0 0 0'),
    _link('link1', 1.0, '0 0 1', (0.1, 0.1, 2.0)),
    _joint('joint1', 'continuous', 'link1', 'link2', '0 0.1 1.95', '0 1 0'),
    _link('link2', 1.0, '0 0 0.45'),
    _joint('joint2', 'continuous', 'link2', 'link3', '0 0.1 0.9', '0 1 0'),
    _link('link3', 1.0, '0 0 0.45'),
    _joint('joint3', 'continuous', 'link3', 'link4', '0 0.1 0.9', '0 1 0'),
    _link('link4', 1.0, '0 0 0.45'),
    _joint('hokuyo_joint', 'fixed', 'link4', 'hokuyo_link', '0 0 0.975'),
    _link('hokuyo_link', 1e-5, '0 0 0', (0.1, 0.1, 0.1)),
    _joint('camera_joint', 'fixed', 'link4', 'camera_link', '0.05 0 0.9'),
    _link('camera_link', 1e-5, '0 0 0', (0.05, 0.05, 0.05)),
    '</robot>'])

# A 3-link arm along x: joint_1 at (0.4, -0.2, 0.1) of base_link, links 0.3 / 0.25 / 0.2 m,
# a flange and tool0 at the tip, a massless marker frame on link_2.
ALONG_X = ''.join([
    '<robot name="three_along_x">', _link('base_link'),
    _joint('joint_1', 'continuous', 'base_link', 'link_1', '0.4 -0.2 0.1', '0 0 1'),
    _link('link_1', 2.0, '0.15 0 0', (0.3, 0.05, 0.05)),
    _joint('joint_2', 'continuous', 'link_1', 'link_2', '0.3 0 0.02', '0 0 1'),
    _link('link_2', 1.5, '0.1 0 0', (0.25, 0.05, 0.05)),
    _joint('marker', 'fixed', 'link_2', 'marker_frame', '0.1 0.05 0'), _link('marker_frame'),
    _joint('joint_3', 'continuous', 'link_2', 'link_3', '0.25 0 0', '0 0 1'),
    _link('link_3', 0.5, '0.1 0 0', (0.2, 0.05, 0.05)),
    _joint('flange', 'fixed', 'link_3', 'tool0', '0.2 0 0'), _link('tool0'),
    '</robot>'])

ALONG_AXIS = (0.0, -9.81, 0.0)     # rrbot lying down: gravity along its joint axes (y)


def test_the_rrbot_layout_is_accepted_unchanged_with_its_laser_as_the_tip():
    arm = parse_urdf(RRBOT, ['joint3'], ALONG_AXIS, tip_link='hokuyo_link')
    assert arm.joint_names == ('joint1', 'joint2', 'joint3')
    assert arm.passive_joints == ('joint3',)
    assert arm.base_link == 'link1' and arm.ee_link == 'hokuyo_link'
    # in-plane lengths: joint to joint 0.9 m, joint3 -> laser 0.975 m (the 0.1 m offsets
    # along y, the joint axes, do not enter)
    assert arm.params.lengths == pytest.approx((0.9, 0.9, 0.975), abs=1e-15)
    # task frame: origin on joint1, x up the straight arm (+z), y = axis x x = y x z = +x
    origin, x, y = arm.task_frame
    assert origin == pytest.approx((0.0, 0.1, 1.95)) and x == (0.0, 0.0, 1.0)
    assert y == (1.0, 0.0, 0.0)
    # link2 alone: 1 kg, COM 0.45 m up; izz of a 0.1 x 0.1 x 1 box about y: (0.01 + 1) / 12
    assert arm.params.masses[:2] == (1.0, 1.0) and arm.params.com[0] == pytest.approx(0.45)
    assert arm.params.inertias[0] == pytest.approx(1.01 / 12, abs=1e-15)
    # link4 with both sensors folded in: mass 1 + 2e-5 kg, COM along the link
    m = 1.0 + 2e-5
    com = (0.45 + 1e-5 * 0.975 + 1e-5 * 0.9) / m
    assert arm.params.masses[2] == pytest.approx(m, abs=1e-15)
    assert arm.params.com[2] == pytest.approx(com, abs=1e-12)
    # parallel axes about y (the axis): each part's own izz + m d^2 in the x-z plane
    izz = (1.01 / 12 + (0.45 - com) ** 2 + 1e-5 * 0.02 / 12 + 1e-5 * (0.975 - com) ** 2
           + 1e-5 * 0.005 / 12 + 1e-5 * (0.9 - com) ** 2 + 1e-5 * 0.05 ** 2)
    assert arm.params.inertias[2] == pytest.approx(izz, abs=1e-12)


def test_rrbot_kinematics_in_its_task_frame_match_a_hand_computation():
    arm = parse_urdf(RRBOT, ['joint3'], ALONG_AXIS, tip_link='hokuyo_link')
    q = np.array([0.4, -1.1, 0.5])
    # planar: x_t = sum L_i cos(phi_i), y_t = sum L_i sin(phi_i), phi = 0.4, -0.7, -0.2
    hand = (0.9 * math.cos(0.4) + 0.9 * math.cos(-0.7) + 0.975 * math.cos(-0.2),
            0.9 * math.sin(0.4) + 0.9 * math.sin(-0.7) + 0.975 * math.sin(-0.2))
    assert ArmModel(arm.params).fk(q) == pytest.approx(hand, abs=1e-15)


STANDING = (0.0, 0.0, -9.81)       # rrbot standing in its own world: gravity -z, its arm up


def test_rrbot_standing_turns_its_task_frame_to_put_gravity_along_minus_y():
    arm = parse_urdf(RRBOT, ['joint3'], STANDING, tip_link='hokuyo_link')
    # y against gravity (z), x = y x axis = (0 0 1) x (0 1 0) = (-1 0 0); origin on joint1
    assert arm.task_frame == ((0.0, 0.1, 1.95), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    # the straight zero pose points up: 90 deg in that frame, on joint 1 alone
    assert arm.joint_offsets == (math.pi / 2, 0.0, 0.0)
    assert arm.params.gravity == 9.81
    assert arm.to_model((0.4, -1.1, 0.5)) == (0.4 + math.pi / 2, -1.1, 0.5)
    back = arm.to_joints(arm.to_model((0.4, -1.1, 0.5)))
    assert back == pytest.approx((0.4, -1.1, 0.5), abs=1e-15)


def test_rrbot_standing_kinematics_match_a_hand_computation_in_its_turned_frame():
    arm = parse_urdf(RRBOT, ['joint3'], STANDING, tip_link='hokuyo_link')
    q = (0.4, -1.1, 0.5)
    # about y a link at angle phi points along (sin phi, 0, cos phi) in the world; the task
    # frame's x is -world x, its y is world z
    phi = (0.4, -0.7, -0.2)
    lengths = (0.9, 0.9, 0.975)
    hand = (-sum(L * math.sin(a) for L, a in zip(lengths, phi)),
            sum(L * math.cos(a) for L, a in zip(lengths, phi)))
    assert ArmModel(arm.params).fk(arm.to_model(q)) == pytest.approx(hand, abs=1e-15)


def test_rrbot_standing_gravity_torques_equal_pinocchios_on_the_urdf_in_its_own_angles():
    pin = pytest.importorskip('pinocchio')
    arm = parse_urdf(RRBOT, ['joint3'], STANDING, tip_link='hokuyo_link')
    model = pin.buildModelFromXML(RRBOT)
    model.gravity.linear = np.array(STANDING)
    data = model.createData()
    for q in ((0.4, -1.1, 0.5), (0.0, 0.0, 0.0), (2.0, 0.3, -2.5)):
        # continuous joints: Pinocchio's configuration is (cos, sin) per joint
        cfg = np.ravel([[math.cos(a), math.sin(a)] for a in q])
        pin_g = pin.computeGeneralizedGravity(model, data, cfg)
        core_g = ArmModel(arm.params).gravity_torque(arm.to_model(q))
        # the sensors' 1e-5 kg, folded onto the link's line, are all that differs
        assert core_g == pytest.approx(pin_g, abs=1e-5)
    # standing straight up, the arm's weight makes no torque about its joints
    assert ArmModel(arm.params).gravity_torque(arm.to_model((0.0, 0.0, 0.0))) == pytest.approx(
        (0.0, 0.0, 0.0), abs=1e-12)


def test_pinocchios_model_of_the_standing_rrbot_takes_the_cores_angles_in_its_task_frame():
    pytest.importorskip('pinocchio')
    from freejoint_core.pin_model import PinArmModel
    arm = parse_urdf(RRBOT, ['joint3'], STANDING, tip_link='hokuyo_link')
    core, pin_arm = ArmModel(arm.params), PinArmModel(arm)
    q = np.array(arm.to_model((0.4, -1.1, 0.5)))
    qd = np.array([0.3, -0.2, 0.5])
    assert pin_arm.fk(q) == pytest.approx(core.fk(q), abs=1e-12)
    assert pin_arm.jacobian(q) == pytest.approx(core.jacobian(q), abs=1e-12)
    assert pin_arm.jdot_qdot(q, qd) == pytest.approx(core.jdot_qdot(q, qd), abs=1e-12)
    assert pin_arm.gravity_torque(q) == pytest.approx(core.gravity_torque(q), abs=1e-5)


def test_the_arm_along_x_in_pinocchio_measures_from_its_task_frames_origin():
    pytest.importorskip('pinocchio')
    from freejoint_core.pin_model import PinArmModel
    arm = parse_urdf(ALONG_X, ['joint_3'], (0.0, -9.81, 0.0), tip_link='tool0')
    assert arm.joint_offsets == ()
    q = np.array([0.3, 0.8, -0.4])
    assert PinArmModel(arm).fk(q) == pytest.approx(ArmModel(arm.params).fk(q), abs=1e-12)


def test_rrbot_without_a_tip_link_ends_on_its_last_link_and_says_what_to_name():
    with pytest.raises(FreejointValueError, match="no end effector: the task point 'link4' sits "
                       "on joint 'joint3'.*or name such a link as tip_link"):
        parse_urdf(RRBOT, ['joint3'], ALONG_AXIS)


def test_a_tip_beside_the_arm_line_is_refused():
    with pytest.raises(FreejointValueError, match="the task point 'camera_link': must sit on the "
                       "line of link 'link2' at zero angles"):
        parse_urdf(RRBOT, ['joint3'], ALONG_AXIS, tip_link='camera_link')


def test_the_three_link_arm_along_x_off_the_origin_is_accepted_with_its_tool_as_tip():
    for tip in ('tool0', ''):                       # tool0 is the chain's last link too
        arm = parse_urdf(ALONG_X, ['joint_3'], tip_link=tip)
        assert arm.ee_link == 'tool0' and arm.base_link == 'base_link'
        assert arm.params.lengths == (0.3, 0.25, 0.2)
        assert arm.params.masses == (2.0, 1.5, 0.5) and arm.params.com == (0.15, 0.1, 0.1)
        assert arm.task_frame == ((0.4, -0.2, 0.1), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    # fk in the base frame: the task frame's origin plus the planar chain
    q = np.array([0.3, -0.5, 0.2])
    phi = np.cumsum(q)
    hand = (0.4 + 0.3 * math.cos(phi[0]) + 0.25 * math.cos(phi[1]) + 0.2 * math.cos(phi[2]),
            -0.2 + 0.3 * math.sin(phi[0]) + 0.25 * math.sin(phi[1]) + 0.2 * math.sin(phi[2]))
    got = np.array(arm.task_frame[0][:2]) + ArmModel(arm.params).fk(q)
    assert got == pytest.approx(hand, abs=1e-15)


def test_every_axis_along_minus_z_turns_the_task_frame_over():
    text = ALONG_X.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 -1"/>')
    arm = parse_urdf(text, ['joint_3'])
    # y = axis x x = (-z) x x = -y: angles counter-clockwise about -z, as the URDF turns
    assert arm.task_frame[1:] == ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0))
    assert arm.params.lengths == (0.3, 0.25, 0.2)


def test_a_moving_link_without_mass_is_refused_naming_it():
    text = ALONG_X.replace(_link('link_2', 1.5, '0.1 0 0', (0.25, 0.05, 0.05)),
                           _link('link_2'))
    with pytest.raises(FreejointValueError, match="link 'link_2' has no <inertial>"):
        parse_urdf(text, ['joint_3'])


def test_an_unknown_tip_link_is_refused_naming_it():
    with pytest.raises(FreejointValueError, match="tip_link: no link 'gripper' in the URDF"):
        parse_urdf(ALONG_X, ['joint_3'], tip_link='gripper')
