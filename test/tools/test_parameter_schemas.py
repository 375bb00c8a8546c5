"""
The parameter schemas (freejoint_common.schema) are the one place of each parameter.

- A parameter shared by nodes is one entry (the same object) in each schema, and a
  default the core also uses is the core's constant (the same object), not a copy.
- The node modules declare nothing themselves (no declare_parameter, descriptor or
  set-parameters callback of their own) and never pair a parameter name with a value.
- Every name in config/*.yaml is an entry of its node's schema, and the files build.
- A params file sets only what differs from the schema's default (config/four_link/*.yaml:
  from config/*.yaml's value under it): a default lives in one place.
- docs/parameters.md is what tools/gen_parameters.py generates from the schemas.

Adding a parameter is then: its entry in the node's params.py, and the code that uses it
(config field and the node's use of it); the loader declares, validates and applies it.
"""
import ast
import os

from freejoint_common import arm_description, schema
from freejoint_control.params import GAIN_NAMES, gains, SCHEMA as CONTROLLER
from freejoint_core import arm, offline, plant
from freejoint_core.control import Gains
from freejoint_planner.params import SCHEMA as PLANNER
from freejoint_sim.params import SCHEMA as SIM
from freejoint_tools.harness import load_source
from freejoint_tools.params import PLAYER, RECORDER
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SRC = os.path.join(ROOT, 'src')
NODE_MODULES = {
    'freejoint_sim/freejoint_sim/sim_node.py': SIM,
    'freejoint_control/freejoint_control/controller_node.py': CONTROLLER,
    'freejoint_planner/freejoint_planner/planner_node.py': PLANNER,
    'freejoint_tools/freejoint_tools/recorder.py': RECORDER,
    'freejoint_tools/freejoint_tools/player.py': PLAYER,
}
CONFIGS = {'sim.yaml': SIM, 'controller.yaml': CONTROLLER, 'planner.yaml': PLANNER}
OVERLAYS = ('four_link', 'fully_actuated', 'stabilised', 'ur5', 'panda')
"""The overlay folders of config/ (a node's file in each, where the overlay needs one)."""
# What only the generic loader (node_tools.NodeParameters) may call.
LOADER_ONLY = ('declare_parameter', 'declare_parameters', 'add_on_set_parameters_callback',
               'ParameterDescriptor', 'FloatingPointRange', 'IntegerRange')


def test_a_parameter_shared_by_nodes_is_one_entry_in_each_schema():
    for name in ('case', 'nominal_scale', 'control_period'):
        assert CONTROLLER[name] is PLANNER[name], name
    for name in ('control_period', 'frame_id'):
        assert SIM[name] is getattr(schema, name.upper()), name
    for name in ('joint_names', 'joints'):
        assert SIM[name] is CONTROLLER[name] is getattr(arm_description, 'ARM_' + name.upper())
    for name in ('robot_description', 'description_file', 'passive_joints', 'gravity'):
        assert SIM[name] is CONTROLLER[name] is PLANNER[name], name
    for name in ('thread_priority', 'cpu_affinity'):
        assert SIM[name] is CONTROLLER[name] is PLANNER[name], name


def test_a_default_the_core_uses_too_is_the_cores_constant():
    assert CONTROLLER['nominal_scale'].default is arm.NOMINAL_SCALE
    assert SIM['control_period'].default is offline.DEFAULT_DT
    assert SIM['dt_sub'].default is plant.DEFAULT_DT_SUB
    assert SIM['dist_bound'].default is plant.DEFAULT_DIST_BOUND
    assert SIM['initial_passive_deg'].default is offline.DEFAULT_Q3_0_DEG
    core = Gains()
    for name in GAIN_NAMES:     # the core's field names are the parameter names
        default = CONTROLLER[name].default
        assert (tuple(default) if isinstance(default, list) else default) == getattr(
            core, name), name
    assert gains(CONTROLLER.defaults()) == core


def _loader_calls(tree):
    """Return the names of loader-only functions a module calls or names."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr in LOADER_ONLY:
            found.append(node.attr)
        elif isinstance(node, ast.Name) and node.id in LOADER_ONLY:
            found.append(node.id)
    return found


def _paired_values(tree, names):
    """Return (line, name) where a parameter name sits next to a literal value."""
    def literal(node):
        return isinstance(node, (ast.Constant, ast.List, ast.Tuple)) and not (
            isinstance(node, ast.Constant) and isinstance(node.value, str))

    def is_name(node):
        return isinstance(node, ast.Constant) and node.value in names

    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            found += [(node.lineno, k.value) for k, v in zip(node.keys, node.values)
                      if k is not None and is_name(k) and (literal(v) or isinstance(
                          v, ast.Tuple))]
        elif isinstance(node, (ast.Tuple, ast.List, ast.Call)):
            items = node.args if isinstance(node, ast.Call) else node.elts
            found += [(node.lineno, a.value) for a, b in zip(items, items[1:])
                      if is_name(a) and literal(b)]
    return found


@pytest.mark.parametrize('path', sorted(NODE_MODULES))
def test_a_node_module_declares_no_parameter_and_repeats_no_default(path):
    names = {p.name for p in NODE_MODULES[path]}
    with open(os.path.join(SRC, path)) as fh:
        tree = ast.parse(fh.read())
    assert _loader_calls(tree) == [], path
    assert _paired_values(tree, names) == [], path


def test_the_node_module_checks_find_a_declaration_and_a_copied_default():
    # the planner's table before its schema, and a hand-declared parameter
    planner_table = ("PARAMETERS = {'nominal_scale': (0.7, 'Nominal model', {}),\n"
                     "              'radius': (0.2, 'Circle radius', {})}\n")
    declared = "node.declare_parameter('nominal_scale', 0.7, ParameterDescriptor())\n"
    getter = "scale = values.get('nominal_scale', 0.7)\n"
    names = {'nominal_scale', 'radius'}
    assert _paired_values(ast.parse(planner_table), names) == [(1, 'nominal_scale'),
                                                               (1, 'radius')]
    assert _paired_values(ast.parse(declared), names) == [(1, 'nominal_scale')]
    assert _loader_calls(ast.parse(declared)) == ['declare_parameter', 'ParameterDescriptor']
    assert _paired_values(ast.parse(getter), names) == [(1, 'nominal_scale')]


def _repeated_values(schema, path, under=()):
    """Return the names ``path`` sets to the value they have without it (``under`` files)."""
    import yaml
    with open(path) as fh:
        given = yaml.safe_load(fh)['/**']['ros__parameters']
    before = schema.yaml_values(*under)
    return sorted(n for n, v in given.items() if n in schema and v == before[n])


@pytest.mark.parametrize('name', sorted(CONFIGS))
def test_a_params_file_sets_no_parameter_to_the_value_it_has_anyway(name):
    base = os.path.join(ROOT, 'config', name)
    assert _repeated_values(CONFIGS[name], base) == [], (
        '%s repeats schema defaults: remove them (the default lives in the schema)' % base)
    for example in OVERLAYS:
        overlay = os.path.join(ROOT, 'config', example, name)
        if not os.path.exists(overlay):
            continue
        assert _repeated_values(CONFIGS[name], overlay, [base]) == [], (
            '%s repeats values it has from %s or the schema: remove them' % (overlay, base))


def test_the_repeated_value_check_finds_a_default_and_an_overlay_repeat(tmp_path):
    base = tmp_path / 'controller.yaml'
    base.write_text('/**:\n  ros__parameters:\n    executor: events\n    K: [100.0, 100.0]\n'
                    '    hold_stiffness: 3.0\n')
    overlay = tmp_path / 'overlay.yaml'
    overlay.write_text('/**:\n  ros__parameters:\n    hold_stiffness: 3.0\n    robust: false\n')
    assert _repeated_values(CONTROLLER, str(base)) == ['K']
    assert _repeated_values(CONTROLLER, str(overlay), [str(base)]) == ['hold_stiffness']


def test_the_parameter_reference_is_generated_from_the_schemas():
    gen = load_source(os.path.join(ROOT, 'tools', 'gen_parameters.py'), 'gen_parameters')
    for path, text in gen.outputs().items():
        with open(path) as fh:
            assert fh.read() == text, (
                '%s is stale (a schema changed): run `%s`' % (path, gen.COMMAND))
    with open(gen.OUTPUT) as fh:
        committed = fh.read()
    documented = [node[4] for node in gen.nodes()]
    assert all(any(s is d for d in documented) for s in NODE_MODULES.values())
    from freejoint_tools.params import VIEWER
    assert any(VIEWER is d for d in documented)
    for node_schema in documented:
        for p in node_schema:
            assert '| `%s` |' % p.name in committed, p.name


def test_every_parameter_table_of_graph_md_is_a_generated_schema_table():
    gen = load_source(os.path.join(ROOT, 'tools', 'gen_parameters.py'), 'gen_parameters')
    with open(gen.GRAPH) as fh:
        text = fh.read()
    tables = list(gen.TABLE.finditer(text))
    assert tables, 'docs/GRAPH.md has no generated parameter table'
    outside = gen.TABLE.sub('', text)
    assert '| default |' not in outside, 'a hand-written parameter table in docs/GRAPH.md'


@pytest.mark.parametrize('name', sorted(CONFIGS))
def test_every_name_of_a_params_file_is_a_schema_entry_and_the_file_builds(name):
    import yaml
    for folder in ('',) + OVERLAYS:
        path = os.path.join(ROOT, 'config', folder, name)
        if folder and not os.path.exists(path):
            continue
        with open(path) as fh:
            given = yaml.safe_load(fh)['/**']['ros__parameters']
        unknown = sorted(set(given) - {p.name for p in CONFIGS[name]} - {'use_sim_time'})
        assert unknown == [], (path, unknown)
    CONFIGS[name].from_yaml(os.path.join(ROOT, 'config', name))


def test_a_files_overrides_are_what_it_sets_apart_from_the_defaults_as_ros2_p_items(tmp_path):
    path = tmp_path / 'overlay.yaml'
    path.write_text('/**:\n  ros__parameters:\n    free_link_damping: true\n'
                    '    free_link_delta_max: 0.03\n    lockstep: true\n    use_sim_time: true\n')
    # lockstep true is the default, use_sim_time not a schema entry: neither is given.
    assert CONTROLLER.overrides(str(path)) == ['free_link_damping:=true',
                                               'free_link_delta_max:=0.03']
