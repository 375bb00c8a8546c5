"""
``fj``, the ROS user's commands without ros2cli, against running freejoint nodes.

The controller, the planner and the recorder run as ``ros2 run`` starts them; every
command runs as the user types it (the installed ``fj`` console script, a process of its
own) and must print what ``ros2`` prints, with a non-zero exit status on failure. A list
is run again until it shows what the test expects, at most ``LIST_WAIT`` s: what it prints
is checked here, not how fast discovery is at the load of a shared test machine (a node
can show up seconds after the others).
"""
import os
import re
import subprocess
import time

from freejoint_tools.harness import Processes
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
FJ = os.path.join(ROOT, 'install', 'freejoint_tools', 'lib', 'freejoint_tools', 'fj')


ANSI = re.compile(r'\x1b\[[0-9;]*m')
FAST_DDS_LOG = re.compile(r'^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d+ \[\w+ (Error|Warning|Info)\] ')
"""A line of Fast DDS's own log (colours removed), e.g. ``... [RTPS_TRANSPORT_SHM Error] Failed
init_port fastrtps_port7000: open_and_lock_file failed``: the shared-memory state a killed
process left in /dev/shm, whatever fj does."""


PARAM_TIMEOUT = '60'
"""fj's ``--timeout`` for a ``param`` command that gives none: its 10-s default is too short
for a node on a 2-core machine while the suite's other workers run SCHED_FIFO graphs (no
describe_parameters answer within 10 s from a live controller)."""


LIST_WAIT = 60.0
"""Seconds a list command is run again for until it shows the lines the test expects."""


def fj_list(*args, expect):
    """
    Run ``fj args...`` until its stdout lines include ``expect``; return the last run.

    At most ``LIST_WAIT`` s (then the last run is returned for the test's assertions); a run
    that fails is returned at once.
    """
    deadline = time.monotonic() + LIST_WAIT
    while True:
        done = fj(*args)
        if done.returncode != 0 or set(expect) <= set(done.stdout.splitlines()) or \
                time.monotonic() > deadline:
            return done


def fj(*args, timeout=120):
    """
    Run ``fj args...``; return the CompletedProcess (text).

    A ``param`` command without ``--timeout`` gets ``PARAM_TIMEOUT``. ``stderr`` is fj's own:
    Fast DDS's log lines are the middleware's (fj routes them to stderr,
    test_fj_output_stays_clean_of_what_libraries_write_to_stdout) and are dropped before the
    checks; ``middleware`` keeps them.
    """
    if args and args[0] == 'param' and '--timeout' not in args:
        args = (*args, '--timeout', PARAM_TIMEOUT)
    done = subprocess.run([FJ, *args], capture_output=True, text=True, timeout=timeout)
    lines = done.stderr.splitlines(keepends=True)
    done.middleware = ''.join(ln for ln in lines if FAST_DDS_LOG.match(ANSI.sub('', ln)))
    done.stderr = ''.join(ln for ln in lines if not FAST_DDS_LOG.match(ANSI.sub('', ln)))
    return done


@pytest.fixture(scope='module')
def graph(tmp_path_factory):
    """Start the controller (real time), the planner (system time) and the recorder."""
    logs = tmp_path_factory.mktemp('fj_nodes')
    procs = Processes(str(logs), stop_timeout=10.0)

    def start(pkg, exe, *args):
        procs.start_node(pkg, exe, exe, ['--ros-args', *args])

    # real time with no simulator: the controller says not ready (a lockstep one is ready
    # from the start), so a plan to execute is refused with its reason
    start('freejoint_control', 'controller_node', '--params-file',
          os.path.join(CONFIG, 'controller.yaml'), '-p', 'lockstep:=false')
    start('freejoint_planner', 'planner_node', '--params-file',
          os.path.join(CONFIG, 'planner.yaml'), '-p', 'use_sim_time:=false',
          '-p', 'autostart:=false')
    start('freejoint_tools', 'recorder', '-p', 'output:=%s' % (logs / 'bag'),
          '-p', 'graph_topics:=false')
    for name in ('/controller_node', '/freejoint_planner', '/recorder'):
        up = fj('param', 'list', name, '--timeout', '60')
        assert up.returncode == 0, 'node %s not up: %s' % (name, up.stderr)
    yield logs
    procs.stop_all()


def test_fj_node_list_shows_the_running_nodes_but_not_itself(graph):
    done = fj_list('node', 'list',
                   expect=('/controller_node', '/freejoint_planner', '/recorder'))
    assert done.returncode == 0, done.stderr
    names = done.stdout.split()
    assert {'/controller_node', '/freejoint_planner', '/recorder'} <= set(names)
    assert names == sorted(names) and not any('/_' in n for n in names)


def test_fj_topic_list_shows_the_graph_topics_with_their_types(graph):
    typed = ('/joint_states [sensor_msgs/msg/JointState]',
             '/setpoints [freejoint_msgs/msg/CartesianSetpoints]',
             '/controller_state [freejoint_msgs/msg/ControllerState]')
    done = fj_list('topic', 'list', '-t', expect=typed)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    for line in typed:
        assert line in lines, done.stdout
    names = fj_list('topic', 'list',
                    expect=('/joint_states', '/setpoints', '/controller_state'))
    names = names.stdout.splitlines()
    assert {'/joint_states', '/setpoints', '/controller_state'} <= set(names)
    assert names == sorted(names) and not any(' ' in n for n in names)


def test_fj_param_list_names_each_declared_parameter_indented_as_ros2_param(graph):
    done = fj('param', 'list', '/controller_node')
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert {'  K', '  nominal_scale', '  robust', '  cpu_affinity'} <= set(lines)
    assert lines == sorted(lines)
    typed = fj('param', 'list', 'controller_node', '--param-type').stdout.splitlines()
    assert '  K (type: double array)' in typed and '  robust (type: boolean)' in typed
    every = fj_list('param', 'list', expect=('/controller_node:', '/freejoint_planner:'))
    every = every.stdout.splitlines()
    assert '/controller_node:' in every and '/freejoint_planner:' in every


def test_fj_param_set_then_get_reads_the_new_value_back(graph):
    done = fj('param', 'set', '/controller_node', 'K', '[150.0, 150.0]')
    assert (done.returncode, done.stdout) == (0, 'Set parameter successful\n'), done.stderr
    got = fj('param', 'get', '/controller_node', 'K')
    assert got.stdout == "Double values are: array('d', [150.0, 150.0])\n", got.stderr
    assert fj('param', 'set', '/controller_node', 'nominal_scale', '0.8').returncode == 0
    assert fj('param', 'get', '/controller_node', 'nominal_scale').stdout == \
        'Double value is: 0.8\n'
    assert fj('param', 'set', '/controller_node', 'robust', 'false').returncode == 0
    assert fj('param', 'get', '/controller_node', 'robust', '--hide-type').stdout == 'False\n'
    assert fj('param', 'set', '/controller_node', 'robust', 'true').returncode == 0


def test_fj_param_set_refused_prints_the_nodes_reason_and_exits_1(graph):
    done = fj('param', 'set', '/controller_node', 'K', '[-1.0, 100.0]')
    assert done.returncode == 1
    assert done.stdout == ''
    assert done.stderr.startswith('Setting parameter failed: K: '), done.stderr
    assert '> 0' in done.stderr
    typed = fj('param', 'set', '/controller_node', 'K', '[150, 150]')  # integers
    assert typed.returncode == 1 and 'Setting parameter failed: ' in typed.stderr
    assert fj('param', 'get', '/controller_node', 'K', '--hide-type').stdout != \
        "array('d', [-1.0, 100.0])\n"


def test_fj_param_describe_shows_type_description_and_range(graph):
    done = fj('param', 'describe', '/controller_node', 'nominal_scale')
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[:2] == ['Parameter name: nominal_scale', '  Type: double']
    assert lines[2].startswith('  Description: ')
    assert lines[3:] == ['  Constraints:', '    Min value: 0.01', '    Max value: 100.0']
    ro = fj('param', 'describe', '/controller_node', 'control_period').stdout
    assert '    Read only: true' in ro


def test_fj_param_dump_prints_ros2_param_yaml_and_load_sets_a_file(graph, tmp_path):
    import yaml
    done = fj('param', 'dump', '/controller_node')
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith('/controller_node:\n  ros__parameters:\n')
    dumped = yaml.safe_load(done.stdout)['/controller_node']['ros__parameters']
    assert dumped['case'] == 'horizontal' and dumped['cpu_affinity'] == []
    assert isinstance(dumped['det_threshold'], float)
    (tmp_path / 'dump.yaml').write_text(done.stdout)
    back = fj('param', 'load', '/controller_node', str(tmp_path / 'dump.yaml'))
    assert back.returncode == 0, back.stderr  # read-only ones unchanged: skipped, said
    assert 'Set parameter control_period skipped: read-only, already 0.001' in back.stdout
    assert 'Set parameter K successful' in back.stdout
    params = tmp_path / 'tuned.yaml'
    params.write_text('/controller_node:\n  ros__parameters:\n    nominal_scale: 0.75\n'
                      '    det_threshold: 2.0e-07\n    Lambda: [40.0, 40.0]\n'
                      '    cpu_affinity: []\n')
    loaded = fj('param', 'load', '/controller_node', str(params))
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.splitlines() == [
        'Set parameter nominal_scale successful', 'Set parameter det_threshold successful',
        'Set parameter Lambda successful', 'Set parameter cpu_affinity successful']
    after = yaml.safe_load(fj('param', 'dump', 'controller_node').stdout)
    after = after['/controller_node']['ros__parameters']
    assert (after['nominal_scale'], after['det_threshold'], after['Lambda']) == \
        (0.75, 2e-07, [40.0, 40.0])
    params.write_text('/**:\n  ros__parameters:\n    nominal_scale: -3.0\n')
    refused = fj('param', 'load', '/controller_node', str(params), '--use-wildcard')
    assert refused.returncode == 1
    assert refused.stderr.startswith('Set parameter nominal_scale failed: '), refused.stderr
    assert fj('param', 'load', '/controller_node', str(params)).returncode == 1  # no section


def test_fj_service_call_plan_circle_answers_accepted_or_refused_with_the_reason(graph):
    done = fj('service', 'call', '/freejoint_planner/plan_circle',
              'freejoint_msgs/srv/PlanCircle',
              '{centre: [0.0, 0.0], radius: 0.2, duration: 5.0, start_angle: 0.0, '
              'direction: 1, execute: false}')
    assert done.returncode == 0, done.stderr
    assert 'requester: making request: freejoint_msgs.srv.PlanCircle_Request(' in done.stdout
    response = done.stdout.split('response:\n', 1)[1]
    assert response.startswith('freejoint_msgs.srv.PlanCircle_Response(accepted=True')
    refused = fj('service', 'call', '/freejoint_planner/plan_circle',
                 'freejoint_msgs/srv/PlanCircle', '{centre: [0, 0], radius: 2, duration: 5}')
    assert refused.returncode == 0, refused.stderr
    response = refused.stdout.split('response:\n', 1)[1]
    assert 'accepted=False' in response and "reason=''" not in response, response


def test_fj_action_list_and_send_goal_print_the_outcome_of_a_refused_follow_circle(graph):
    listed = fj_list('action', 'list', '-t', expect=(
        '/freejoint_planner/follow_circle [freejoint_msgs/action/FollowCircle]',))
    assert listed.returncode == 0, listed.stderr
    assert '/freejoint_planner/follow_circle [freejoint_msgs/action/FollowCircle]' in \
        listed.stdout.splitlines()
    # no simulator: the controller is not ready (it says so, or is not heard in real
    # time): the goal is accepted and aborted at once with the reason; exit status 1
    done = fj('action', 'send_goal', '/freejoint_planner/follow_circle',
              'freejoint_msgs/action/FollowCircle', '{radius: 0.2, duration: 5.0}', '-f',
              '--timeout', '60', '--service-timeout', '60')
    assert done.returncode == 1, done.stdout + done.stderr
    out = done.stdout
    assert out.startswith(('Sending goal:', 'Waiting for an action server')), out
    assert 'Goal accepted with ID: ' in out
    assert 'Result:\n    freejoint_msgs.action.FollowCircle_Result(outcome=' in out
    assert '\nOutcome: plan 0 CONTROLLER_NOT_READY: controller not ready: ' in out, out
    assert out.endswith('Goal finished with status: ABORTED\n'), out
    bad = fj('action', 'send_goal', '/freejoint_planner/follow_circle',
             'freejoint_msgs/action/FollowCircle', '{radios: 0.2}')
    assert bad.returncode == 1 and bad.stderr.startswith('Failed to populate field radios')


def test_fj_service_call_trigger_and_bad_requests(graph):
    done = fj('service', 'call', '/recorder/status', 'std_srvs/srv/Trigger')
    assert done.returncode == 0, done.stderr
    assert 'response:\nstd_srvs.srv.Trigger_Response(success=' in done.stdout
    bad_field = fj('service', 'call', '/freejoint_planner/plan_circle',
                   'freejoint_msgs/srv/PlanCircle', '{radios: 0.2}')
    assert bad_field.returncode == 1
    assert bad_field.stderr.startswith('Failed to populate field radios: ')
    bad_type = fj('service', 'call', '/recorder/status', 'std_srvs/srv/Nothing')
    assert bad_type.returncode == 1 and 'std_srvs/srv/Nothing' in bad_type.stderr


def test_fj_says_node_not_found_within_its_timeout_and_exits_1(graph):
    start = time.monotonic()
    done = fj('param', 'get', '/no_such_node', 'K', '--timeout', '1')
    assert done.returncode == 1
    assert done.stderr.startswith('Node not found: /no_such_node'), done.stderr
    assert time.monotonic() - start < 60.0
    missing = fj('service', 'call', '/no_such_service', 'std_srvs/srv/Trigger',
                 '--timeout', '1')
    assert missing.returncode == 1
    assert missing.stderr.startswith('Service not available: /no_such_service')
    unset = fj('param', 'get', '/controller_node', 'no_such_parameter')
    assert unset.returncode == 1 and unset.stderr == 'Parameter not set\n'


def test_fj_run_starts_an_executable_of_a_package_as_ros2_run():
    done = fj('run', 'freejoint_tools', 'analyze', '--help', timeout=60)
    assert done.returncode == 0 and 'usage' in done.stdout.lower(), done.stderr
    nothing = fj('run', 'freejoint_tools', 'nothing')
    assert nothing.returncode == 1 and 'No executable found' in nothing.stderr
    assert fj('run', 'no_such_package', 'x').stderr.startswith('Package not found')


@pytest.mark.skipif(not os.path.isfile(os.path.join(ROOT, '.stamps', 'venv'))
                    or 'system' in open(os.path.join(ROOT, '.stamps', 'venv')).read(),
                    reason='set up on a sourced ROS 2: ros2 run starts the nodes there')
def test_env_sh_puts_the_node_executables_and_fj_on_path():
    exes = ['sim_node', 'controller_node', 'planner_node', 'recorder', 'player', 'fj']
    done = subprocess.run(['bash', '-c', '. tools/env.sh && . tools/env.sh && '
                           'command -v %s && echo "$PATH"' % ' '.join(exes)],
                          cwd=ROOT, capture_output=True, text=True, timeout=60,
                          env={k: v for k, v in os.environ.items() if k != 'PATH'}
                          | {'PATH': '/usr/bin:/bin'})
    assert done.returncode == 0, done.stderr
    found = done.stdout.splitlines()
    assert [os.path.basename(p) for p in found[:-1]] == exes
    assert all(p.startswith(os.path.join(ROOT, 'install')) for p in found[:-1])
    path = found[-1].split(':')
    assert len(path) == len(set(path)), 'sourcing twice repeats PATH entries'


def test_fj_fills_nested_and_sequence_fields_of_a_request_from_yaml():
    import yaml

    from freejoint_tools.cli import CommandError, interface_class, set_message_fields
    srv = interface_class('rcl_interfaces/srv/SetParameters')
    request = srv.Request(check_fields=True)
    set_message_fields(request, yaml.safe_load(
        '{parameters: [{name: K, value: {type: 8, double_array_value: [150, 150.5]}}]}'))
    assert request.parameters[0].name == 'K'
    assert list(request.parameters[0].value.double_array_value) == [150.0, 150.5]
    circle = interface_class('freejoint_msgs/srv/PlanCircle').Request(check_fields=True)
    set_message_fields(circle, {'centre': [0, 1], 'radius': 1, 'direction': -1})
    assert (list(circle.centre), circle.radius, circle.direction) == ([0.0, 1.0], 1.0, -1)
    with pytest.raises(CommandError, match='parameters\\[0\\].nme'):
        set_message_fields(srv.Request(check_fields=True), {'parameters': [{'nme': 'K'}]})
    with pytest.raises(CommandError, match='Failed to populate field radius'):
        set_message_fields(circle, {'radius': 'big'})
    with pytest.raises(CommandError, match='direction'):
        set_message_fields(circle, {'direction': 300})  # int8


def test_fj_output_stays_clean_of_what_libraries_write_to_stdout():
    import sys
    code = ('import os; from freejoint_tools.cli import keep_stdout_for_output; '
            'keep_stdout_for_output(); os.write(1, b"[RTPS_TRANSPORT_SHM Error]\\n"); '
            'print("/controller_node:")')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=60)
    assert (done.returncode, done.stdout) == (0, '/controller_node:\n'), done.stderr
    assert '[RTPS_TRANSPORT_SHM Error]' in done.stderr
