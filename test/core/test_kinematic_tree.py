"""The URDF's link frames (what the viewer sends as /tf) against the arm model's kinematics."""
import math

from freejoint_core.errors import FreejointValueError
from freejoint_core.kinematic_tree import KinematicTree, quat_mul, quat_rotate
from freejoint_core.models import make_model
from freejoint_core.urdf import four_link_arm, FOUR_LINK_Q0, paper_arm
import numpy as np
import pytest


@pytest.mark.parametrize('arm', [paper_arm(), four_link_arm()], ids=['paper', 'four_link'])
def test_end_effector_frame_is_the_models_forward_kinematics(arm):
    tree = KinematicTree(arm.urdf)
    model = make_model(arm.params)
    rng = np.random.default_rng(0)
    for q in [np.zeros(arm.params.n), np.array(FOUR_LINK_Q0[:arm.params.n])] + [
            rng.uniform(-math.pi, math.pi, arm.params.n) for _ in range(20)]:
        frames = tree.frame_positions(dict(zip(arm.joint_names, q)))
        assert frames[arm.ee_link][:2] == pytest.approx(model.fk(q), abs=1e-12)


def test_one_transform_per_urdf_joint_named_as_the_urdf_links():
    arm = paper_arm()
    tree = KinematicTree(arm.urdf)
    assert tree.root == arm.base_link == 'base_link'
    assert tree.moving == arm.joint_names
    out = tree.transforms({'joint1': 0.5, 'joint2': -1.0, 'joint3': 2.0})
    assert [(p, c) for p, c, _, _ in out] == [('base_link', 'link1'), ('link1', 'link2'),
                                              ('link2', 'link3'), ('link3', 'ee_link')]
    _, _, xyz, rot = out[1]
    assert xyz == (0.5, 0.0, 0.0)
    assert rot == pytest.approx((0.0, 0.0, math.sin(-0.5), math.cos(-0.5)))
    assert out[3][3] == (0.0, 0.0, 0.0, 1.0)


def test_origin_rotation_and_axis_compose_as_robot_state_publisher():
    urdf = """<robot name="r"><link name="a"/><link name="b"/>
      <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
        <origin xyz="1 2 3" rpy="0 0 1.5707963267948966"/><axis xyz="1 0 0"/></joint></robot>"""
    (_, _, xyz, rot), = KinematicTree(urdf).transforms({'j': math.pi / 2})
    assert xyz == (1.0, 2.0, 3.0)
    # child y axis: rotated about the joint's x (-> z), then the origin's yaw leaves z.
    assert quat_rotate(rot, [0.0, 1.0, 0.0]) == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    # child x axis: the origin's yaw turns it to the parent's y.
    assert quat_rotate(rot, [1.0, 0.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)
    assert quat_mul((0, 0, 0, 1), rot) == pytest.approx(rot)


@pytest.mark.parametrize('text, what', [
    ('', 'empty'),
    ('<robot', 'not well-formed'),
    ('<model/>', 'expected <robot>'),
    ('<robot><link name="a"/><joint name="j" type="floating"><parent link="a"/>'
     '<child link="a"/></joint></robot>', "type 'floating'"),
    ('<robot><link name="a"/><joint name="j" type="fixed"><parent link="a"/>'
     '<child link="b"/></joint></robot>', "child link 'b'"),
    ('<robot><link name="a"/><link name="b"/></robot>', 'one root link'),
    ('<robot><link name="a"/><link name="b"/><joint name="j" type="revolute">'
     '<parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint></robot>', 'zero axis'),
])
def test_bad_descriptions_are_refused_naming_the_problem(text, what):
    with pytest.raises(FreejointValueError, match='robot_description: .*' + what.replace(
            '(', r'\(')):
        KinematicTree(text)


def test_non_finite_joint_position_is_refused_naming_the_joint():
    tree = KinematicTree(paper_arm().urdf)
    with pytest.raises(FreejointValueError, match="positions: joint 'joint2'"):
        tree.transforms({'joint2': float('nan')})
