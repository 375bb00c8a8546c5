"""Planar serial arms from URDF: the shipped descriptions and the one-line refusals."""

import math

from freejoint_core.arm import table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.urdf import (GRAVITY_BY_CASE, GRAVITY_HORIZONTAL, GRAVITY_VERTICAL_VECTOR,
                                 load_urdf, paper_arm, parse_urdf, SHIPPED, shipped_urdf_path)
import pytest


def _paper_text():
    with open(shipped_urdf_path('paper_arm'), encoding='utf-8') as f:
        return f.read()


def _replace_in_joint(text, joint, old, new):
    """Replace ``old`` by ``new`` inside the <joint name=joint> element only."""
    start = text.index(f'<joint name="{joint}"')
    end = text.index('</joint>', start)
    body = text[start:end]
    assert old in body
    return text[:start] + body.replace(old, new, 1) + text[end:]


def _drop_inertial(text, link):
    start = text.index('<inertial>', text.index(f'<link name="{link}">'))
    end = text.index('</inertial>', start) + len('</inertial>')
    return text[:start] + text[end:]


def _replace_in_link(text, link, old, new):
    start = text.index(f'<link name="{link}">')
    end = text.index('</link>', start)
    body = text[start:end]
    assert old in body
    return text[:start] + body.replace(old, new, 1) + text[end:]


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_shipped_paper_urdf_gives_the_table1_parameters(case):
    arm = paper_arm(case)
    assert arm.params == table1(case)
    assert arm.joint_names == ('joint1', 'joint2', 'joint3')
    assert arm.passive_joints == ('joint3',)
    assert arm.base_link == 'base_link' and arm.ee_link == 'ee_link'
    assert arm.gravity_vector == GRAVITY_BY_CASE[case]


def test_nominal_model_scales_masses_inertias_and_com_like_armparams_scaled():
    arm = paper_arm('vertical')
    assert arm.nominal(0.7) == table1('vertical').scaled(0.7)


def test_every_shipped_urdf_parses_as_a_planar_arm():
    for name in SHIPPED:
        arm = load_urdf(shipped_urdf_path(name), (), GRAVITY_HORIZONTAL)
        assert arm.params.n >= 3
        assert arm.params.passive == ()


def test_horizontal_gravity_along_the_joint_axes_gives_no_gravity_torque():
    assert parse_urdf(_paper_text(), ['joint3'], (0.0, 0.0, -9.81)).params.gravity == 0.0
    assert parse_urdf(_paper_text(), ['joint3'], GRAVITY_VERTICAL_VECTOR).params.gravity == 9.81


def test_passive_joints_are_stored_in_chain_order():
    arm = parse_urdf(_paper_text(), ['joint2'], GRAVITY_HORIZONTAL)
    assert arm.params.passive == (1,) and arm.params.active == (0, 2)


def test_inertial_rotated_about_z_keeps_izz():
    text = _replace_in_link(_paper_text(), 'link2', 'xyz="0.25 0 0" rpy="0 0 0"',
                            'xyz="0.25 0 0" rpy="0 0 0.7"')
    assert parse_urdf(text, ['joint3']).params.inertias[1] == pytest.approx(0.1, abs=1e-15)


def test_inertial_rotated_about_x_moves_iyy_into_izz():
    text = _replace_in_link(_paper_text(), 'link2', 'xyz="0.25 0 0" rpy="0 0 0"',
                            'xyz="0.25 0 0" rpy="1.5707963267948966 0 0"')
    # rotating by 90 deg about x swaps the y and z axes: izz becomes iyy (0.1 here too).
    text = _replace_in_link(text, 'link2', 'iyy="0.1"', 'iyy="0.07"')
    assert parse_urdf(text, ['joint3']).params.inertias[1] == pytest.approx(0.07, abs=1e-15)


def test_fixed_mount_before_joint1_is_part_of_the_base():
    text = _paper_text().replace(
        '<link name="base_link"/>', '<link name="world"/><joint name="mount" type="fixed">'
        '<parent link="world"/><child link="base_link"/><origin xyz="0 0 0.8"/></joint>'
        '<link name="base_link"/>')
    arm = parse_urdf(text, ['joint3'], GRAVITY_VERTICAL_VECTOR)
    assert arm.params == table1('vertical') and arm.base_link == 'base_link'


def test_fixed_mount_shifting_the_base_in_the_plane_moves_the_task_frame_only():
    text = _paper_text().replace(
        '<link name="base_link"/>', '<link name="world"/><joint name="mount" type="fixed">'
        '<parent link="world"/><child link="base_link"/><origin xyz="0.1 0 0"/></joint>'
        '<link name="base_link"/>')
    arm = parse_urdf(text, ['joint3'])
    assert arm.params == table1('horizontal')
    assert arm.task_frame == ((0.1, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))


REFUSALS = [
    ('prismatic', lambda t: _replace_in_joint(t, 'joint2', 'type="revolute"', 'type="prismatic"'),
     ['joint3'], "joint 'joint2': type 'prismatic' is not supported"),
    ('floating', lambda t: _replace_in_joint(t, 'joint2', 'type="revolute"', 'type="floating"'),
     ['joint3'], "joint 'joint2': type 'floating' is not supported"),
    ('planar', lambda t: _replace_in_joint(t, 'joint1', 'type="revolute"', 'type="planar"'),
     ['joint3'], "joint 'joint1': type 'planar' is not supported"),
    ('axis along x', lambda t: _replace_in_joint(t, 'joint2', '<axis xyz="0 0 1"/>',
                                                 '<axis xyz="1 0 0"/>'),
     ['joint3'], "joint 'joint2': axis (1 0 0 in the base frame) is not parallel to the axis "
     "of joint 'joint1' (0 0 1)"),
    ('tilted axis', lambda t: _replace_in_joint(t, 'joint3', '<axis xyz="0 0 1"/>',
                                                '<axis xyz="0 0.1 1"/>'),
     ['joint3'], "joint 'joint3': axis (0 0.0995037 0.995037 in the base frame) is not "
     'parallel'),
    ('axis -z', lambda t: _replace_in_joint(t, 'joint3', '<axis xyz="0 0 1"/>',
                                            '<axis xyz="0 0 -1"/>'),
     ['joint3'], "joint 'joint3': axis points opposite to the axis of joint 'joint1'"),
    ('rotated joint frame', lambda t: _replace_in_joint(t, 'joint2', 'rpy="0 0 0"',
                                                        'rpy="0.3 0 0"'),
     ['joint3'], "joint 'joint2': axis (0 -0.29552 0.955336 in the base frame) is not "
     'parallel'),
    ('missing inertial', lambda t: _drop_inertial(t, 'link2'),
     ['joint3'], "link 'link2' has no <inertial>"),
    ('com off the axis', lambda t: _replace_in_link(t, 'link1', 'xyz="0.25 0 0"',
                                                    'xyz="0.25 0.01 0"'),
     ['joint3'], "link 'link1': centre of mass off the link axis"),
    ('com beyond the tip', lambda t: _replace_in_link(t, 'link1', 'xyz="0.25 0 0"',
                                                      'xyz="0.6 0 0"'),
     ['joint3'], "link 'link1': centre of mass at x = 0.6 m, must lie on the link"),
    ('zero mass', lambda t: _replace_in_link(t, 'link3', '<mass value="1.0"/>',
                                             '<mass value="0"/>'),
     ['joint3'], "link 'link3': mass (0) and izz (0.1) must be > 0"),
    ('no end effector', lambda t: t.replace(
        '<joint name="ee_joint" type="fixed">\n    <parent link="link3"/>\n    '
        '<child link="ee_link"/>\n    <origin xyz="0.5 0 0" rpy="0 0 0"/>\n  </joint>\n  '
        '<link name="ee_link"/>', ''),
     ['joint3'], 'no end effector'),
    ('two moving branches', lambda t: t.replace(
        '</robot>', '<joint name="extra" type="continuous"><parent link="link1"/>'
        '<child link="cam"/><axis xyz="0 0 1"/></joint><link name="cam"/></robot>'),
     ['joint3'], "link 'link1' has 2 child joints with moving joints below (joint2, extra)"),
    ('continuous with limits', lambda t: _replace_in_joint(
        t, 'joint2', 'type="revolute"', 'type="continuous"'),
     ['joint3'], "joint 'joint2': continuous joint with position limits"),
    ('revolute without limit', lambda t: _replace_in_joint(
        t, 'joint2', '<limit lower="-6.283185307179586" upper="6.283185307179586" '
        'effort="100" velocity="100"/>', ''),
     ['joint3'], "joint 'joint2': revolute joint without <limit>"),
    ('joint off the link axis', lambda t: _replace_in_joint(
        t, 'joint3', 'xyz="0.5 0 0"', 'xyz="0.5 0.02 0"'),
     ['joint3'], "joint 'joint3': must sit on the line of link 'link1' at zero angles"),
    ('unknown passive', lambda t: t, ['joint4'],
     "passive_joints: 'joint4' is not a revolute joint of the URDF (joints: joint1, joint2, "
     'joint3)'),
    ('fixed joint named passive', lambda t: t, ['ee_joint'],
     "passive_joints: 'ee_joint' is not a revolute joint"),
    ('two passive of three', lambda t: t, ['joint2', 'joint3'],
     'passive_joints: 2 passive of 3 joints leaves 1 active; the task (x, y) needs at least 2'),
    ('not xml', lambda t: t[:200], ['joint3'], 'robot_description: not well-formed XML'),
]


@pytest.mark.parametrize('label,edit,passive,message', REFUSALS, ids=[r[0] for r in REFUSALS])
def test_unsupported_description_is_refused_with_one_line_naming_the_problem(
        label, edit, passive, message):
    text = edit(_paper_text())
    with pytest.raises(FreejointValueError) as info:
        parse_urdf(text, passive, GRAVITY_HORIZONTAL)
    text = str(info.value)
    assert message in text
    assert '\n' not in text


@pytest.mark.parametrize('gravity,message', [
    ((0.0, -9.81), 'gravity: expected 3 finite numbers'),
    ((0.0, float('nan'), 0.0), 'gravity: expected 3 finite numbers'),
    ('down', 'gravity: expected 3 numbers'),
])
def test_gravity_vector_the_core_cannot_represent_is_refused(gravity, message):
    with pytest.raises(FreejointValueError, match=message.replace('(', r'\(').replace(')', r'\)')):
        parse_urdf(_paper_text(), ['joint3'], gravity)


def test_gravity_in_the_plane_off_minus_y_turns_the_task_frame_and_offsets_joint_1():
    # the paper's arm (axes +z, links along +x) with gravity along +x of its base frame:
    # y against it (-x), x = y x z = (0 1 0); the straight arm (+x) at -90 deg in that frame
    arm = parse_urdf(_paper_text(), ['joint3'], (9.81, 0.0, 0.0))
    assert arm.task_frame == ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0))
    assert arm.joint_offsets == (-math.pi / 2, 0.0, 0.0)
    assert arm.params.gravity == 9.81
    assert arm.params.lengths == parse_urdf(_paper_text(), ['joint3']).params.lengths


def test_passive_joints_given_as_one_string_is_refused():
    with pytest.raises(FreejointValueError, match='passive_joints: expected a list'):
        parse_urdf(_paper_text(), 'joint3')


def test_unreadable_description_file_is_refused_naming_it(tmp_path):
    with pytest.raises(FreejointValueError, match='description_file: cannot read'):
        load_urdf(str(tmp_path / 'nope.urdf'), ['joint3'])


def test_empty_description_is_refused():
    with pytest.raises(FreejointValueError, match='robot_description: expected URDF text'):
        parse_urdf('  ', ['joint3'])
