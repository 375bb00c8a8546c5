"""
The parameters of every freejoint node, as ros2 param, rqt_reconfigure and Foxglove see them.

- Every name ``list_parameters`` gives comes back from one ``get_parameters`` call with a
  value (rclpy's GetParameters answers nothing at all when one requested name has no value:
  ``ros2 param dump`` then prints ``ros__parameters: {}``).
- ``fj param dump`` (ros2 param dump's YAML) given back as ``--params-file`` starts a node
  with equal parameters.
- Every schema entry, and nothing else of the node's, is declared on the running node
  with its descriptor (description, read-only, range).
- A bad start-up parameter (range, type, the node's validator) ends the process with one
  line naming the parameter and the reason, exit status 2, no traceback. Every row of
  ``BAD_START`` runs in this process through the ``main`` its executable runs (the same
  parameter checks and runner, the line read from this process's stdout and stderr); one
  row per executable is started as a process too (what only a process shows: its exit
  status, a Python that exits after the line).

Every node process is started as ``ros2 run`` would (install/<pkg>/lib/<pkg>/<exe>).
"""
import os
import subprocess

import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
FJ = os.path.join(ROOT, 'install', 'freejoint_tools', 'lib', 'freejoint_tools', 'fj')
NODES = ('sim_node', 'controller_node', 'planner_node', 'recorder', 'player')


def _node(kind, tmp_path, make_bag, config=True):
    """
    Return (package, executable, node name, ros arguments) of the node ``kind``.

    ``config``: with its file of config/ (else on its defaults: rcl drops a ``-p`` whose
    type differs from the params file's value of the same name, without a word).
    """
    if not config and kind in ('sim_node', 'controller_node', 'planner_node'):
        return _node(kind, tmp_path, make_bag)[:3] + ([],)
    if kind == 'sim_node':
        return ('freejoint_sim', 'sim_node', '/sim_node',
                ['--params-file', os.path.join(CONFIG, 'sim.yaml')])
    if kind == 'controller_node':
        return ('freejoint_control', 'controller_node', '/controller_node',
                ['--params-file', os.path.join(CONFIG, 'controller.yaml')])
    if kind == 'planner_node':
        return ('freejoint_planner', 'planner_node', '/freejoint_planner',
                ['--params-file', os.path.join(CONFIG, 'planner.yaml')])
    if kind == 'recorder':
        return ('freejoint_tools', 'recorder', '/recorder',
                ['-p', 'output:=%s' % (tmp_path / 'recorded'), '-p', 'overwrite:=true',
                 '-p', 'graph_topics:=false'])
    bag = str(tmp_path / 'played')
    if not os.path.isdir(bag):
        make_bag(bag, 20)
    # It waits (and answers parameter services) until its topics have a subscriber.
    return ('freejoint_tools', 'player', '/player',
            ['-p', 'bag:=%s' % bag, '-p', 'wait_for_subscribers:=1',
             '-p', 'wait_timeout:=120.0'])


def _schema(kind):
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    from freejoint_tools.params import PLAYER, RECORDER
    return {'sim_node': SIM, 'controller_node': CONTROLLER, 'planner_node': PLANNER,
            'recorder': RECORDER, 'player': PLAYER}[kind]


def _assert_schema_declared_with_descriptors(client, schema):
    """Assert that ``client``'s node declares every entry of ``schema`` as described, only."""
    names = [p.name for p in schema]
    listed = set(client.list_parameters())
    assert set(names) <= listed, sorted(set(names) - listed)
    extra = sorted(n for n in listed - set(names)
                   if n not in ('use_sim_time', 'start_type_description_service')
                   and not n.startswith('qos_overrides.'))
    assert extra == [], 'declared outside the schema: %s' % extra
    descriptors = client.describe_parameters(names)
    assert [d.name for d in descriptors] == names
    for entry, desc in zip(schema, descriptors):
        assert desc.description == entry.description, entry.name
        assert desc.read_only == entry.read_only, entry.name
        ranges = [(r.from_value, r.to_value, r.step)
                  for r in list(desc.floating_point_range) + list(desc.integer_range)]
        if entry.bounds is None:
            assert ranges == [], entry.name
        else:
            step = entry.bounds[2] if len(entry.bounds) > 2 else (
                1 if isinstance(entry.default, int) else 0.0)
            assert ranges == [(entry.bounds[0], entry.bounds[1], step)], entry.name


def _all_parameters(client):
    """Return {name: ParameterValue} from one list_parameters and one get_parameters call."""
    name = client.target
    names = sorted(client.list_parameters())
    values = client.get_parameters(names)
    assert len(values) == len(names), (
        '%s/get_parameters answered %d values for the %d names of list_parameters (a '
        'parameter without a value?)' % (name, len(values), len(names)))
    unset = [n for n, v in zip(names, values) if v.type == 0]
    assert not unset, '%s: parameters without a value: %s' % (name, unset)
    return dict(zip(names, values))


def _plain(values):
    from rclpy.parameter import parameter_value_to_python
    return {n: parameter_value_to_python(v) for n, v in values.items()}


@pytest.mark.parametrize('kind', NODES)
def test_the_node_declares_its_schema_as_described_with_values_and_its_dump_restarts_it_equal(
        kind, procs, ros_node, tmp_path, make_bag):
    # One node process for both: its declarations and descriptors, then its values in one
    # get; the dump of these values starts a second process with equal parameters.
    from freejoint_tools.harness import ParameterCalls
    pkg, exe, name, args = _node(kind, tmp_path, make_bag)
    first = procs.start_node(pkg, exe, exe, ['--ros-args', *args])
    client = ParameterCalls(ros_node, name, timeout=30.0)
    _assert_schema_declared_with_descriptors(client, _schema(kind))
    before = _all_parameters(client)
    assert len(before) >= 5, sorted(before)
    dumped = subprocess.run([FJ, 'param', 'dump', name, '--timeout', '30'],
                            capture_output=True, text=True, timeout=120)
    assert dumped.returncode == 0, dumped.stderr
    assert dumped.stdout.startswith('%s:\n  ros__parameters:\n' % name), dumped.stdout[:200]
    assert first.poll() is None, procs.log(first)
    procs.stop(first)
    params_file = tmp_path / 'dump.yaml'
    params_file.write_text(dumped.stdout)
    second = procs.start_node(pkg, exe, exe + '_again',
                              ['--ros-args', '--params-file', str(params_file)])
    after = _all_parameters(ParameterCalls(ros_node, name, timeout=30.0))
    assert second.poll() is None, procs.log(second)
    assert _plain(after) == _plain(before)
    assert {n: v.type for n, v in after.items()} == {n: v.type for n, v in before.items()}


BAD_START = [
    # node, parameter, bad value, what is wrong (a word of the reason)
    ('sim_node', 'dt_sub', '-1.0', 'range'),
    ('sim_node', 'seed', 'abc', 'type'),
    ('sim_node', 'mode', 'bogus', 'mode'),
    ('controller_node', 'nominal_scale', '1000.0', 'range'),
    ('controller_node', 'K', '[150, 150]', 'type'),
    ('controller_node', 'K', '[-1.0, 100.0]', '> 0'),
    ('planner_node', 'radius', '-0.2', 'range'),
    ('planner_node', 'lookahead', 'abc', 'type'),
    ('planner_node', 'resolution_deg', '0.7', 'even integer'),
    ('recorder', 'chunk_size', '1', 'range'),
    ('recorder', 'discovery_period', 'abc', 'type'),
    ('recorder', 'executor', 'bogus', 'executor'),
    ('recorder', 'compression', 'lz4', 'must be one of none, zstd'),
    ('player', 'rate', '0.0', 'range'),
    ('player', 'rate', 'abc', 'type'),
    ('player', 'bag', "''", 'no bag given'),
    # freejoint_bringup graph: the nodes in one process, overrides per node
    ('graph', 'controller.nominal_scale', '1000.0', 'range'),
    ('graph', 'sim.seed', 'abc', 'type'),
    ('graph', 'controller.K', '[-1.0,100.0]', '> 0'),
]
AS_PROCESS = [row for row in BAD_START if row[:3] in {
    # one row per executable: rclpy's checks and the schemas' validators both among them;
    # the graph's sim node is made before the controller fails, and shut down
    ('sim_node', 'dt_sub', '-1.0'),
    ('controller_node', 'K', '[-1.0, 100.0]'),
    ('planner_node', 'lookahead', 'abc'),
    ('recorder', 'compression', 'lz4'),
    ('player', 'bag', "''"),
    ('graph', 'controller.nominal_scale', '1000.0'),
}]
"""The rows started as a process too (what only a process shows: its exit status)."""


def _bad_start(kind, param, value, tmp_path, make_bag):
    """
    Return (package, executable, arguments, parameter name) of a start with one bad value.

    ``param``: the parameter's name (for ``graph``: ``<node>.<name>``), set to ``value``.
    """
    if kind == 'graph':
        node, param = param.split('.')
        return ('freejoint_bringup', 'graph',
                ['--nodes', 'sim', 'controller', '--%s' % node, '%s=%s' % (param, value)],
                param)
    pkg, exe, _, args = _node(kind, tmp_path, make_bag, config=False)
    return pkg, exe, ['--ros-args', *args, '-p', '%s:=%s' % (param, value)], param


REASONS = {'range': 'out of range', 'type': 'of type'}
"""The words of rclpy's range and type refusals (other rows: the reason's own words)."""


@pytest.mark.parametrize('kind, param, value, reason', BAD_START,
                         ids=['%s-%s=%s' % row[:3] for row in BAD_START])
def test_a_bad_start_up_parameter_makes_the_executables_main_log_one_line_naming_it_and_return_2(
        kind, param, value, reason, tmp_path, make_bag, run_main, bad_parameter_line):
    # In this process: rclpy.init, the node's constructor, its parameter checks and the
    # runner's line, as the executable runs them; main's return is the process's status.
    pkg, exe, args, name = _bad_start(kind, param, value, tmp_path, make_bag)
    code, out = run_main(pkg, exe, args)
    line = bad_parameter_line(code, out, name)
    assert REASONS.get(reason, reason) in line, line


@pytest.mark.parametrize('kind, param, value, reason', AS_PROCESS,
                         ids=['%s-%s=%s' % row[:3] for row in AS_PROCESS])
def test_a_bad_start_up_parameter_ends_the_node_with_one_line_naming_it_and_exit_2(
        kind, param, value, reason, tmp_path, make_bag, bad_parameter_line):
    # What only the process shows, once per executable (every row: the test above).
    pkg, exe, args, name = _bad_start(kind, param, value, tmp_path, make_bag)
    done = subprocess.run([os.path.join(ROOT, 'install', pkg, 'lib', pkg, exe), *args],
                          capture_output=True, text=True, timeout=120)
    line = bad_parameter_line(done.returncode, done.stdout + done.stderr, name)
    assert REASONS.get(reason, reason) in line, line
