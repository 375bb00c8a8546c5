"""
A node's arm is resolved once per distinct value of its arm parameters.

What a ``ros2 param set`` runs in a node (``NodeParameters``' set-parameters callback:
the schema's checks, then its config builder) asks for the arm several times; the URDF
is parsed, and the controller's Pinocchio model of a non-3-link arm built, once per
change of the arm's parameters (``gravity`` is the one a running node takes), and not at
all for a change of any other parameter. Counted with the resolver, the URDF parser and
the model builder replaced by counting wrappers (no ROS: the schemas as the callback uses
them).
"""
import collections
import os

from freejoint_common import arm_description
import freejoint_control.params as control_params
from freejoint_core.errors import FreejointValueError
import freejoint_planner.params as planner_params
import freejoint_sim.params as sim_params
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, 'config')


def _four_link(node):
    return (os.path.join(CONFIG, node + '.yaml'),
            os.path.join(CONFIG, 'four_link', node + '.yaml'))


NODES = {
    # node: (schema module, YAML files of the 4-link example, a parameter off the arm)
    'controller': (control_params, _four_link('controller'), ('K', [12.0, 12.0])),
    'sim': (sim_params, _four_link('sim'), ('publish_rate', 100.0)),
    'planner': (planner_params, _four_link('planner'), ('max_speed', 0.5)),
}


@pytest.fixture
def counted(monkeypatch):
    """Count arm resolutions, URDF parses and nominal-model builds from an empty cache."""
    counts = collections.Counter()

    def counting(name, func):
        def wrapper(*args, **kwargs):
            counts[name] += 1
            return func(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(arm_description, '_RESOLVED', collections.OrderedDict())
    monkeypatch.setattr(arm_description, '_resolve',
                        counting('resolve', arm_description._resolve))
    monkeypatch.setattr(arm_description, 'parse_urdf',
                        counting('parse', arm_description.parse_urdf))
    monkeypatch.setattr(arm_description, 'load_urdf',
                        counting('parse', arm_description.load_urdf))
    monkeypatch.setattr(control_params, 'nominal_model',
                        counting('model', control_params.nominal_model))
    return counts


def _param_set(schema, values, name, value):
    """Return the values and config a set-parameters callback takes for ``name := value``."""
    changed = dict(values, **{name: value})
    return changed, schema.config(changed)


@pytest.mark.parametrize('node', sorted(NODES))
def test_setting_the_gravity_resolves_the_arm_and_parses_the_urdf_once(node, counted):
    module, files, _ = NODES[node]
    values = module.SCHEMA.yaml_values(*files)
    module.SCHEMA.config(values)                     # start-up
    counted.clear()
    _param_set(module.SCHEMA, values, 'gravity', [0.0, -9.0, 0.0])
    expected_resolutions = 0 if node == 'planner' else 1     # the planner's schema takes
    assert counted['resolve'] == expected_resolutions         # no arm (its node does)
    assert counted['parse'] == expected_resolutions
    assert counted['model'] == (1 if node == 'controller' else 0)


@pytest.mark.parametrize('node', sorted(NODES))
def test_setting_a_parameter_off_the_arm_resolves_no_arm_and_parses_no_urdf(node, counted):
    module, files, (name, value) = NODES[node]
    values = module.SCHEMA.yaml_values(*files)
    module.SCHEMA.config(values)
    counted.clear()
    _param_set(module.SCHEMA, values, name, value)
    assert counted['resolve'] == 0
    assert counted['parse'] == 0


@pytest.mark.parametrize('node', ['controller', 'sim'])
def test_start_up_resolves_the_arm_once_for_every_check_and_the_build(node, counted):
    module, files, _ = NODES[node]
    module.SCHEMA.config(module.SCHEMA.yaml_values(*files))
    assert counted['resolve'] == 1
    assert counted['parse'] == 1


def test_the_default_arm_is_resolved_once_without_parsing_a_urdf(counted):
    values = control_params.SCHEMA.defaults()
    control_params.SCHEMA.config(values)
    _param_set(control_params.SCHEMA, values, 'K', [12.0, 12.0])
    assert counted['resolve'] == 1
    assert counted['parse'] == 0
    assert counted['model'] == 0


def test_a_resolved_arm_is_the_same_object_for_equal_values_and_new_for_a_new_gravity(
        counted):
    values = control_params.SCHEMA.yaml_values(*_four_link('controller'))
    first = arm_description.resolve_arm(values)
    assert arm_description.resolve_arm(dict(values)) is first
    other = arm_description.resolve_arm(dict(values, gravity=[0.0, -9.0, 0.0]))
    assert other is not first
    assert other.params.gravity != first.params.gravity
    assert arm_description.resolve_arm(values) is first
    assert counted['resolve'] == 2


def test_a_refused_arm_is_refused_with_its_reason_on_every_request(counted):
    values = dict(control_params.SCHEMA.defaults(), passive_joints=['joint9'],
                  description_file='package://freejoint_description/urdf/paper_arm.urdf')
    for _ in range(2):
        with pytest.raises(FreejointValueError, match='passive_joints'):
            arm_description.resolve_arm(values)
    assert counted['resolve'] == 2      # a refusal is not kept: it names the parameter again


def test_the_cache_keeps_a_bounded_number_of_arms(counted):
    values = control_params.SCHEMA.defaults()
    for g in range(arm_description._KEEP + 3):
        arm_description.resolve_arm(dict(values, gravity=[0.0, -1.0 - g, 0.0]))
    assert len(arm_description._RESOLVED) == arm_description._KEEP


UR5 = 'package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf'


def _spatial(**given):
    values = dict(control_params.SCHEMA.defaults(), task_dim=3, description_file=UR5,
                  base_link='base_link', tip_link='tool0', passive_joints=['wrist_2_joint'])
    values.update(given)
    return values


def test_a_spatial_arm_is_resolved_once_and_its_nominal_model_built_once_per_scale(counted):
    first = arm_description.resolve_arm(_spatial())
    assert arm_description.resolve_arm(_spatial()) is first
    assert first.task_dim == 3 and first.described and first.urdf_arm is None
    assert first.joint_names[4] == 'wrist_2_joint' and first.spatial.passive == (4,)
    assert first.nominal(0.7) is first.nominal(0.7)
    assert first.nominal(0.7) is not first.nominal(0.5)
    assert first.nominal(0.7).scale == 0.7 and first.spatial.scale == 1.0
    # another tip is another arm
    other = arm_description.resolve_arm(_spatial(tip_link='wrist_3_link'))
    assert other is not first and other.spatial.tip_link == 'wrist_3_link'


@pytest.mark.parametrize('given, reason', [
    ({'tip_link': ''}, '^tip_link: a spatial arm'),
    ({'description_file': ''}, '^task_dim: 3 .* needs robot_description or description_file'),
    ({'task_dim': 4}, '^task_dim: expected 2 .* or 3'),
    ({'passive_joints': ['joint9']}, "^passive_joints: 'joint9' is not a joint of the chain"),
    ({'passive_joints': ['shoulder_pan_joint', 'elbow_joint', 'wrist_2_joint', 'wrist_3_joint']},
     '^passive_joints: 2 active joints cannot drive m = 3'),
    ({'base_link': 'nowhere'}, "^base_link: the URDF has no link 'nowhere'"),
    ({'description_file': 'package://example-robot-data/robots/none.urdf'},
     '^description_file: .*not found'),
])
def test_a_bad_spatial_arm_is_refused_naming_the_parameter(given, reason):
    with pytest.raises(FreejointValueError, match=reason):
        arm_description.resolve_arm(_spatial(**given))
