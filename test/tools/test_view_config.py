"""The view's shipped files: the Foxglove layout, the URDF (robot_state_publisher), RViz."""
import json
import os
import re
import xml.etree.ElementTree as ET

from freejoint_core.kinematic_tree import KinematicTree
from freejoint_core.urdf import parse_urdf, shipped_urdf_path
from freejoint_tools.recorder import GRAPH_TOPICS
from freejoint_tools.typedefs import message_class
from freejoint_tools.viewer import DESCRIPTION_TOPIC, SPECS, TF_TOPIC
import pytest
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
LAYOUT = os.path.join(ROOT, 'config', 'foxglove_layout.json')
RVIZ = os.path.join(ROOT, 'config', 'freejoint.rviz')
SERVED = {'/' + rel.lstrip('/'): msgtype for rel, msgtype, _ in GRAPH_TOPICS}
SERVED[DESCRIPTION_TOPIC] = 'std_msgs/msg/String'
_PATH = re.compile(r'^(/[A-Za-z0-9_/]+)\.([A-Za-z0-9_]+)(?:\[(\d+)\])?$')


def _leaves(node):
    if isinstance(node, str):
        return [node]
    return _leaves(node['first']) + _leaves(node['second'])


def _spec(name):
    return next(s.default for s in SPECS if s.name == name)


def test_foxglove_layout_panels_all_configured_and_every_plot_path_is_a_served_field():
    with open(LAYOUT) as f:
        layout = json.load(f)
    panels = _leaves(layout['layout'])
    assert sorted(panels) == sorted(layout['configById'])
    kinds = {p.split('!')[0] for p in panels}
    assert {'3D', 'Plot', 'StateTransitions', 'Parameters', 'CallService'} <= kinds
    paths = [p['value'] for panel, cfg in layout['configById'].items()
             if panel.startswith(('Plot!', 'StateTransitions!')) for p in cfg['paths']]
    assert len(paths) >= 12
    for path in paths:
        m = _PATH.match(path)
        assert m, path
        topic, field, index = m.groups()
        assert topic in SERVED, path
        fields = message_class(SERVED[topic]).get_fields_and_field_types()
        assert field in fields, path
        assert (index is not None) == ('[' in fields[field] or 'sequence' in fields[field]), path
    wanted = {'/controller_state.error[0]', '/controller_state.effort[0]',
              '/joint_states.position[2]', '/controller_state.law_state[0]',
              '/controller_state.status'}
    assert wanted <= set(paths)


def test_foxglove_layout_3d_panel_shows_the_urdf_from_the_viewers_topics():
    with open(LAYOUT) as f:
        cfg = json.load(f)['configById']['3D!arm']
    urdf_layers = [v for v in cfg['layers'].values() if v['layerId'] == 'foxglove.Urdf']
    assert urdf_layers and urdf_layers[0]['topic'] == DESCRIPTION_TOPIC
    assert cfg['followTf'] == KinematicTree(_urdf()).root
    assert TF_TOPIC in cfg['topics']


def test_foxglove_layout_service_panel_request_is_a_plan_circle_request():
    from freejoint_msgs.srv import PlanCircle
    with open(LAYOUT) as f:
        cfg = json.load(f)['configById']['CallService!plan']
    served = [s.split('=')[0] for s in _spec('services')]
    assert cfg['serviceName'] in served
    request = json.loads(cfg['requestPayload'])
    assert set(request) == set(PlanCircle.Request.get_fields_and_field_types())
    PlanCircle.Request(**request)   # every value of the right type


def _urdf():
    with open(shipped_urdf_path('paper_arm')) as f:
        return f.read()


def test_shipped_urdf_is_one_consistent_tree_robot_state_publisher_can_publish():
    text = _urdf()
    root = ET.fromstring(text)
    links = {link.get('name') for link in root.findall('link')}
    joints = root.findall('joint')
    assert len({j.get('name') for j in joints}) == len(joints)
    for joint in joints:
        assert joint.find('parent').get('link') in links
        assert joint.find('child').get('link') in links
        if joint.get('type') == 'revolute':   # robot_state_publisher needs the limits
            limit = joint.find('limit')
            assert limit is not None and float(limit.get('lower')) < float(limit.get('upper'))
    tree = KinematicTree(text)
    children = [j.child for j in tree.joints]
    assert {tree.root, *children} == links and len(children) == len(links) - 1
    assert parse_urdf(text, ('joint3',)).joint_names == tree.moving


def test_urdf_joint_names_are_the_nodes_joint_names_defaults():
    from freejoint_control.params import SPECS as CONTROL_SPECS
    from freejoint_sim.params import SPECS as SIM_SPECS
    moving = list(KinematicTree(_urdf()).moving)
    for specs in (SIM_SPECS, CONTROL_SPECS):
        assert next(s.default for s in specs if s.name == 'joint_names') == moving
    from freejoint_sim.params import SCHEMA
    sim = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'sim.yaml'))
    assert sim['joint_names'] == moving


def test_rviz_config_shows_robot_model_tf_and_the_graphs_markers():
    with open(RVIZ) as f:
        cfg = yaml.safe_load(f)
    manager = cfg['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == KinematicTree(_urdf()).root
    displays = {d['Class']: d for d in manager['Displays']}
    model = displays['rviz_default_plugins/RobotModel']
    assert model['Description Source'] == 'Topic'
    assert model['Description Topic']['Value'] == DESCRIPTION_TOPIC
    assert 'rviz_default_plugins/TF' in displays
    for cls in ('Marker', 'Map', 'PointStamped'):
        topic = displays['rviz_default_plugins/' + cls]['Topic']['Value']
        assert topic in SERVED, topic


@pytest.mark.parametrize('name', ['host', 'port'])
def test_viewer_serves_this_machine_only_by_default(name):
    assert _spec(name) == {'host': '127.0.0.1', 'port': 8765}[name]


def test_viewer_requirement_is_the_pin_of_the_pypi_install():
    from freejoint_tools.viewer import FOXGLOVE_SDK
    with open(os.path.join(ROOT, 'tools', 'requirements.txt')) as f:
        pins = [line.strip() for line in f if line.startswith('foxglove-sdk==')]
    assert pins == [FOXGLOVE_SDK]


SPATIAL_ARMS = ('ur5', 'panda')


def _spatial(arm):
    """Return (layout configById, the arm's SpatialArm, its URDF text) of a shipped example."""
    from freejoint_common.arm_description import package_path
    from freejoint_core.spatial_model import SpatialArm
    with open(os.path.join(ROOT, 'config', 'foxglove_layout_%s.json' % arm)) as f:
        layout = json.load(f)
    with open(os.path.join(ROOT, 'config', arm, 'sim.yaml')) as f:
        values = yaml.safe_load(f)['/**']['ros__parameters']
    with open(package_path(values['description_file']), encoding='utf-8') as f:
        text = f.read()
    model = SpatialArm(text, values['base_link'], values['tip_link'], values['passive_joints'])
    return layout, model, text


@pytest.mark.parametrize('arm', SPATIAL_ARMS)
def test_spatial_layout_plots_its_arms_task_rows_active_torques_and_free_joint(arm):
    layout, model, _ = _spatial(arm)
    panels = _leaves(layout['layout'])
    assert sorted(panels) == sorted(layout['configById'])
    cfg = layout['configById']
    for panel, conf in cfg.items():
        for p in conf.get('paths', ()):
            topic, field, index = _PATH.match(p['value']).groups()
            assert field in message_class(SERVED[topic]).get_fields_and_field_types(), p
    values = {name: [p['value'] for p in cfg[name]['paths']]
              for name in ('Plot!error', 'Plot!torques', 'Plot!passive')}
    assert values['Plot!error'] == ['/controller_state.error[%d]' % i for i in range(3)]
    assert values['Plot!torques'] == ['/controller_state.effort[%d]' % i
                                      for i in range(model.r)]
    (free,) = model.passive
    assert values['Plot!passive'] == ['/joint_states.position[%d]' % free,
                                      '/joint_states.velocity[%d]' % free]
    assert model.joint_names[free] in cfg['Plot!passive']['title']


@pytest.mark.parametrize('arm', SPATIAL_ARMS)
def test_spatial_layout_3d_panel_shows_the_urdf_frames_and_paths_in_perspective(arm):
    from freejoint_tools.viewer import PATHS_TOPIC
    layout, _, text = _spatial(arm)
    cfg = layout['configById']['3D!arm']
    urdf_layers = [v for v in cfg['layers'].values() if v['layerId'] == 'foxglove.Urdf']
    assert urdf_layers and urdf_layers[0]['topic'] == DESCRIPTION_TOPIC
    assert cfg['followTf'] == KinematicTree(text).root
    assert cfg['cameraState']['perspective'] is True
    assert {TF_TOPIC, PATHS_TOPIC, '/planned_path', '/ee_position'} <= set(cfg['topics'])
    assert '/semi_singular_map' not in cfg['topics']     # planar arms only


@pytest.mark.parametrize('arm', SPATIAL_ARMS)
def test_spatial_layout_plan_request_keeps_the_planar_only_fields_at_their_defaults(arm):
    from freejoint_msgs.srv import PlanCircle
    layout, _, _ = _spatial(arm)
    request = json.loads(layout['configById']['CallService!plan']['requestPayload'])
    assert set(request) == set(PlanCircle.Request.get_fields_and_field_types())
    PlanCircle.Request(**request)
    assert (request['centre'], request['start_angle'], request['direction']) == ([0.0, 0.0],
                                                                                 0.0, 1)
    assert request['radius'] == 0.1 and request['execute'] is True
