"""
The nodes take the arm from robot_description / description_file, and refuse one they cannot.

A URDF the core does not model (a prismatic, non-parallel or floating joint, a link
without inertial), a passive set leaving fewer than two active joints, or a
``passive_joints`` name the URDF does not have ends the simulator, the controller and the
planner at start-up with one line naming the parameter and the problem, exit status 2
(``freejoint_common.runner``), as any other bad start-up parameter. These start-up
refusals run in the test process, through the ``main`` each executable runs.
"""
import os
import re

import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
URDF_DIR = os.path.join(ROOT, 'src', 'freejoint_description', 'urdf')
FOUR_LINK = os.path.join(URDF_DIR, 'four_link_arm.urdf')
NODES = {
    'sim': ('freejoint_sim', 'sim_node'),
    'controller': ('freejoint_control', 'controller_node'),
    'planner': ('freejoint_planner', 'planner_node'),
}


def _four_link(edit=None):
    with open(FOUR_LINK) as f:
        text = f.read()
    return edit(text) if edit else text


def _joint2(attr_old, attr_new):
    """Edit the joint2 element of the 4-link URDF (its first occurrence of ``attr_old``)."""
    def edit(text):
        start = text.index('<joint name="joint2"')
        end = text.index('</joint>', start)
        block = text[start:end]
        assert attr_old in block
        return text[:start] + block.replace(attr_old, attr_new, 1) + text[end:]
    return edit


def _no_inertial(text):
    start = text.index('<link name="link2">')
    i0 = text.index('<inertial>', start)
    i1 = text.index('</inertial>', i0) + len('</inertial>')
    return text[:i0] + text[i1:]


REFUSALS = [
    # id, URDF edit, passive_joints, parameter named, what the line says after it
    ('prismatic', _joint2('type="revolute"', 'type="prismatic"'), '[joint1]',
     'robot_description', "joint 'joint2': type 'prismatic' is not supported"),
    ('axis_not_parallel', _joint2('<axis xyz="0 0 1"/>', '<axis xyz="1 0 0"/>'), '[joint1]',
     'robot_description', "joint 'joint2': axis (1 0 0 in the base frame) is not parallel to the "
     "axis of joint 'joint1'"),
    ('floating', _joint2('type="revolute"', 'type="floating"'), '[joint1]',
     'robot_description', "joint 'joint2': type 'floating' is not supported"),
    ('missing_inertial', _no_inertial, '[joint1]',
     'robot_description', "link 'link2' has no <inertial>"),
    ('one_active_left', None, '[joint1, joint2, joint3]',
     'passive_joints', '3 passive of 4 joints leaves 1 active; the task (x, y) needs at '
     'least 2'),
    ('unknown_passive_name', None, '[elbow]',
     'passive_joints', "'elbow' is not a revolute joint of the URDF"),
]


def _refused_at_start_up(node, values):
    """Raise what ``node`` refuses ``values`` with at start-up (its schema, the arm)."""
    from freejoint_common.arm_description import resolve_arm
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    if node == 'planner':       # the planner node resolves the arm from its values
        resolve_arm(PLANNER.values(values))
    else:
        schema = SIM if node == 'sim' else CONTROLLER
        schema.config(schema.values(values))


@pytest.mark.parametrize('node', sorted(NODES))
@pytest.mark.parametrize('case, edit, passive, param, reason', REFUSALS,
                         ids=[row[0] for row in REFUSALS])
def test_an_arm_the_core_cannot_model_is_refused_by_each_node_naming_the_parameter(
        node, case, edit, passive, param, reason, tmp_path):
    from freejoint_core.errors import FreejointValueError
    path = tmp_path / ('%s.urdf' % case)
    path.write_text(_four_link(edit))
    names = [name.strip() for name in passive.strip('[]').split(',')]
    with pytest.raises(FreejointValueError,
                       match=r'^%s: .*%s' % (param, re.escape(reason))):
        _refused_at_start_up(node, {'description_file': str(path), 'passive_joints': names})


@pytest.mark.parametrize('node, row', [('sim', 0), ('controller', 3), ('planner', 5)])
def test_an_arm_the_core_cannot_model_makes_the_nodes_main_log_one_line_naming_it_and_return_2(
        node, row, tmp_path, run_main, bad_parameter_line):
    # The runner's end of a refused arm (one refusal per node; each node's refusal of every
    # arm: the test above): one line, no traceback, main's return 2 (the process's exit
    # status; each executable's as a process: test_node_parameters.py).
    case, edit, passive, param, reason = REFUSALS[row]
    path = tmp_path / ('%s.urdf' % case)
    path.write_text(_four_link(edit))
    code, out = run_main(*NODES[node], ['--ros-args', '-p', 'description_file:=%s' % path,
                                        '-p', 'passive_joints:=%s' % passive])
    line = bad_parameter_line(code, out, param)
    assert re.search(r'bad parameter: %s: .*%s' % (param, re.escape(reason)), line), line


def test_a_description_file_that_cannot_be_read_is_named_and_main_returns_2(
        run_main, bad_parameter_line):
    code, out = run_main('freejoint_sim', 'sim_node',
                         ['--ros-args', '-p', 'description_file:=/nonexistent/arm.urdf'])
    line = bad_parameter_line(code, out, 'description_file')
    assert "bad parameter: description_file: cannot read '/nonexistent/arm.urdf'" in line, line


def test_robot_description_text_from_a_parameter_file_is_taken_as_the_arm(
        tmp_path, run_main, bad_parameter_line):
    # The way controller_manager / robot_state_publisher get it: the URDF text as a
    # parameter (here from a parameter file); the controller refuses the default effort
    # limits (two values) for the arm's three active joints, naming them from the URDF.
    text = _four_link()
    params = tmp_path / 'arm.yaml'
    params.write_text('/**:\n  ros__parameters:\n    passive_joints: [joint1]\n'
                      '    robot_description: |\n%s\n'
                      % '\n'.join('      ' + line for line in text.splitlines()))
    code, out = run_main('freejoint_control', 'controller_node',
                         ['--ros-args', '--params-file', str(params)])
    line = bad_parameter_line(code, out, 'effort_limits')
    assert ('bad parameter: effort_limits: expected 3 values in (0, 1e6] N m (one per joint '
            "of joints ['joint2', 'joint3', 'joint4'])") in line, line


CONFIG = os.path.join(ROOT, 'config')
FOUR_LINK_Q0 = [0.0, 1.0052314594852472, 1.3891119364177558, 2.2480117465074176]


def _sim_args(*files, overrides=()):
    args = ['--ros-args', '--params-file', os.path.join(CONFIG, 'sim.yaml')]
    for name in files:
        args += ['--params-file', os.path.join(CONFIG, name)]
    for item in overrides:
        args += ['-p', item]
    return args


def _spin(node):
    import rclpy
    return lambda: rclpy.spin_once(node, timeout_sec=0.05)


@pytest.mark.parametrize('engine', ['rk4', 'mujoco'])
def test_sim_takes_the_four_link_urdf_and_publishes_it_on_robot_description_latched(
        engine, procs, ros_node, wait):
    from freejoint_common.contract import JOINT_STATES, ROBOT_DESCRIPTION
    sim = procs.start_node('freejoint_sim', 'sim_node', 'sim', _sim_args(
        'four_link/sim.yaml', overrides=['engine:=%s' % engine]))
    wait(lambda: 'simulator ready' in procs.log(sim) or sim.poll() is not None, 30.0,
         'the simulator')
    assert sim.poll() is None, procs.log(sim)
    assert "four_link_arm.urdf, passive ['joint1'], gravity (0 0 -9.81)" in procs.log(sim)
    # Subscribed after the simulator published it: a transient-local subscription (as
    # RViz's and robot_state_publisher's) still gets it.
    texts, states = [], []
    ros_node.create_subscription(ROBOT_DESCRIPTION.msg_type, ROBOT_DESCRIPTION.name,
                                 lambda m: texts.append(m.data), ROBOT_DESCRIPTION.qos)
    ros_node.create_subscription(JOINT_STATES.msg_type, JOINT_STATES.name, states.append,
                                 JOINT_STATES.qos)
    wait(lambda: texts and states, 30.0, '/robot_description and joint_states',
         spin=_spin(ros_node))
    assert texts[0] == _four_link()
    assert list(states[0].name) == ['joint1', 'joint2', 'joint3', 'joint4']
    assert list(states[0].position) == FOUR_LINK_Q0
    assert procs.stop(sim) == 0


def test_sim_of_the_paper_arm_publishes_the_shipped_paper_urdf(procs, ros_node, wait):
    from freejoint_common.contract import ROBOT_DESCRIPTION
    sim = procs.start_node('freejoint_sim', 'sim_node', 'sim', _sim_args())
    wait(lambda: 'simulator ready: horizontal arm' in procs.log(sim) or sim.poll() is not None,
         30.0, 'the simulator')
    texts = []
    ros_node.create_subscription(ROBOT_DESCRIPTION.msg_type, ROBOT_DESCRIPTION.name,
                                 lambda m: texts.append(m.data), ROBOT_DESCRIPTION.qos)
    wait(lambda: texts, 30.0, '/robot_description', spin=_spin(ros_node))
    with open(os.path.join(URDF_DIR, 'paper_arm.urdf')) as f:
        assert texts[0] == f.read()
    assert procs.stop(sim) == 0


def test_viewer_takes_the_arm_from_the_simulators_robot_description(procs, wait):
    # One source of the arm: the viewer without description_file follows the graph's
    # latched /robot_description (its /tf and URDF channel), here the 4-link arm.
    sim = procs.start_node('freejoint_sim', 'sim_node', 'sim', _sim_args('four_link/sim.yaml'))
    viewer = procs.start_node('freejoint_tools', 'viewer', 'viewer',
                              ['--ros-args', '-p', 'port:=0'])
    line = 'URDF from /robot_description (%d characters)' % len(_four_link())
    wait(lambda: line in procs.log(viewer) or viewer.poll() is not None
         or sim.poll() is not None, 60.0, 'the viewer to take the URDF')
    assert line in procs.log(viewer), procs.log(viewer) + procs.log(sim)
    assert procs.stop(viewer) == 0
    assert procs.stop(sim) == 0


def test_the_controller_names_the_gravity_vector_it_was_given_not_the_case(procs, wait):
    # A vertical gravity given to the 4-link example (case left at horizontal): the ready
    # line names the arm and that vector, not 'horizontal'.
    proc = procs.start_node('freejoint_control', 'controller_node', 'controller', [
        '--ros-args', '--params-file', os.path.join(CONFIG, 'controller.yaml'),
        '--params-file', os.path.join(CONFIG, 'four_link', 'controller.yaml'),
        '-p', 'gravity:=[0.0, -9.81, 0.0]'])
    wait(lambda: 'controller ready' in procs.log(proc), 30.0,
         'the controller ready (log: %s)' % procs.log(proc))
    (line,) = [x for x in procs.log(proc).splitlines() if 'controller ready' in x]
    assert "four_link_arm.urdf, passive ['joint1'], gravity (0 -9.81 0)" in line, line
    assert 'horizontal' not in line, line
