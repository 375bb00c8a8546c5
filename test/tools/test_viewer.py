"""
The viewer seen by Foxglove's own WebSocket protocol client while the lockstep graph runs.

The client is ``@foxglove/ws-protocol``'s ``FoxgloveClient`` (npm, pinned in
``test/tools/ws_client/package.json``, installed there once with ``npm ci``), driven by
``ws_client/client.js``: commands on its stdin, events on its stdout, as JSON lines.
"""
import base64
import json
import math
import os
import queue
import re
import shutil
import struct
import subprocess
import threading
import time

from freejoint_core.kinematic_tree import quat_mul, quat_rotate
import numpy as np
import pytest

pytestmark = pytest.mark.ros

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CONFIG = os.path.join(ROOT, 'config')
CLIENT_DIR = os.path.join(HERE, 'ws_client')
NODES = (('freejoint_sim', 'sim_node', 'sim.yaml', 'simulator ready'),
         ('freejoint_control', 'controller_node', 'controller.yaml', 'controller ready'),
         ('freejoint_planner', 'planner_node', 'planner.yaml', 'ready:'))


@pytest.fixture(scope='module')
def ws_client_dir():
    """Give the client's directory with node_modules installed (``npm ci`` once if missing)."""
    if not shutil.which('node') or not shutil.which('npm'):
        pytest.fail("node and npm are needed for Foxglove's protocol client "
                    '(@foxglove/ws-protocol): not on PATH')
    if not os.path.isdir(os.path.join(CLIENT_DIR, 'node_modules', '@foxglove', 'ws-protocol')):
        done = subprocess.run(['npm', 'ci', '--no-audit', '--no-fund'], cwd=CLIENT_DIR,
                              capture_output=True, text=True, timeout=300)
        if done.returncode != 0:
            pytest.fail("cannot install Foxglove's protocol client (npm ci in %s, the "
                        'npm registry is needed once): %s' % (CLIENT_DIR,
                                                              done.stderr[-2000:]))
    return CLIENT_DIR


class Client:
    """The node client process: send commands, wait for events."""

    def __init__(self, directory, url):
        self.proc = subprocess.Popen(['node', os.path.join(directory, 'client.js'), url],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, bufsize=1)
        self.events = queue.Queue()
        self.seen = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            try:
                self.events.put(json.loads(line))
            except ValueError:
                self.events.put({'event': 'output', 'text': line})

    def send(self, **cmd):
        self.proc.stdin.write(json.dumps(cmd) + '\n')
        self.proc.stdin.flush()

    def wait(self, predicate, timeout, what):
        """Return the first event (new or seen before) for which ``predicate`` holds."""
        for event in self.seen:
            if predicate(event):
                self.seen.remove(event)
                return event
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                event = self.events.get(timeout=0.1)
            except queue.Empty:
                continue
            if predicate(event):
                return event
            self.seen.append(event)
        raise AssertionError('timed out after %.0f s waiting for %s; events: %s'
                             % (timeout, what, [str(e)[:200] for e in self.seen[-20:]]))

    def close(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(5.0)


def _pb_fields(buf):
    """Decode one protobuf message's wire format: yield (field number, wire type, value)."""
    i = 0

    def varint():
        nonlocal i
        shift = value = 0
        while True:
            b = buf[i]
            i += 1
            value |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                return value
    while i < len(buf):
        key = varint()
        field, wire = key >> 3, key & 7
        if wire == 0:
            yield field, wire, varint()
        elif wire == 1:
            yield field, wire, struct.unpack_from('<d', buf, i)[0]
            i += 8
        elif wire == 2:
            n = varint()
            yield field, wire, bytes(buf[i:i + n])
            i += n
        elif wire == 5:
            yield field, wire, buf[i:i + 4]
            i += 4
        else:
            raise ValueError('wire type %d' % wire)


def decode_frame_transforms(data):
    """Decode ``foxglove.FrameTransforms`` (protobuf): (parent, child, xyz, xyzw, stamp s)."""
    out = []
    for field, _, payload in _pb_fields(data):
        assert field == 1
        parent = child = ''
        xyz, rot = [0.0] * 3, [0.0] * 4   # proto3 leaves zeros out
        stamp = 0.0
        for f, _, v in _pb_fields(payload):
            if f == 1:
                stamp = sum(c * (1.0 if g == 1 else 1e-9) for g, _, c in _pb_fields(v))
            elif f == 2:
                parent = v.decode()
            elif f == 3:
                child = v.decode()
            elif f == 4:
                for g, _, c in _pb_fields(v):
                    xyz[g - 1] = c
            elif f == 5:
                for g, _, c in _pb_fields(v):
                    rot[g - 1] = c
        out.append((parent, child, xyz, rot, stamp))
    return out


def _cdr(msgtype, data):
    from freejoint_tools.typedefs import Definitions
    defs = Definitions()
    defs.lookup(msgtype)
    return defs.store.deserialize_cdr(data, msgtype)


def _viewer_subscribes(ros_node, topic):
    return any(info.node_name == 'viewer'
               for info in ros_node.get_subscriptions_info_by_topic(topic))


def test_foxglove_client_sees_the_running_graph_and_steers_it(procs, wait, ws_client_dir,
                                                              ros_node):
    viewer = procs.start_node('freejoint_tools', 'viewer', 'viewer',
                              ['--ros-args', '-p', 'port:=0'])
    wait(lambda: 'viewer ready' in procs.log(viewer) or viewer.poll() is not None, 30.0,
         'the viewer to start')
    port = int(re.search(r'ws://127\.0\.0\.1:(\d+)', procs.log(viewer)).group(1))
    for pkg, exe, params, ready in NODES:
        proc = procs.start_node(pkg, exe, exe, ['--ros-args', '--params-file',
                                                os.path.join(CONFIG, params)])
        wait(lambda: ready in procs.log(proc) or proc.poll() is not None, 60.0,
             '%s to start' % exe)
        assert proc.poll() is None, procs.log(proc)

    # No client: the viewer takes nothing from the graph.
    wait(lambda: ros_node.get_publishers_info_by_topic('/joint_states'), 30.0,
         'joint_states discovered')
    assert not _viewer_subscribes(ros_node, '/joint_states')
    assert not _viewer_subscribes(ros_node, '/controller_state')

    client = Client(ws_client_dir, 'ws://127.0.0.1:%d' % port)
    try:
        info = client.wait(lambda e: e['event'] == 'serverInfo', 30.0, 'serverInfo')
        assert {'parameters', 'services'} <= set(info['capabilities'])
        channels = {}
        while not {'/joint_states', '/tf', '/controller_state'} <= set(channels):
            event = client.wait(lambda e: e['event'] == 'advertise', 30.0, 'channels')
            channels.update({c['topic']: c for c in event['channels']})
        assert channels['/joint_states']['encoding'] == 'cdr'
        assert channels['/joint_states']['schemaEncoding'] == 'ros2msg'
        assert channels['/tf']['schemaName'] == 'foxglove.FrameTransforms'

        # Subscribe: messages of the running graph, decodable with the advertised schemas.
        client.send(op='subscribe', topics=['/joint_states', '/tf', '/controller_state'],
                    count=3)
        got = {}
        while len(got) < 3:
            event = client.wait(lambda e: e['event'] == 'message', 60.0, 'messages')
            got.setdefault(event['topic'], base64.b64decode(event['data']))
        wait(lambda: _viewer_subscribes(ros_node, '/joint_states'), 30.0,
             'the viewer to subscribe to joint_states', spin=None)
        js = _cdr('sensor_msgs/msg/JointState', got['/joint_states'])
        assert list(js.name) == ['joint1', 'joint2', 'joint3']
        assert all(math.isfinite(p) for p in js.position)
        state = _cdr('freejoint_msgs/msg/ControllerState', got['/controller_state'])
        assert len(state.effort) == 2 and all(math.isfinite(t) for t in state.effort)
        frames = decode_frame_transforms(got['/tf'])
        assert [(p, c) for p, c, _, _, _ in frames] == [
            ('base_link', 'link1'), ('link1', 'link2'), ('link2', 'link3'),
            ('link3', 'ee_link')]
        for parent, child, xyz, rot, stamp in frames:
            assert abs(stamp - time.time()) < 60.0   # the live view's clock
            assert xyz == pytest.approx([0.0, 0.0, 0.0] if child == 'link1'
                                        else [0.5, 0.0, 0.0])
            assert rot[0] == rot[1] == 0.0 and math.hypot(rot[2], rot[3]) == pytest.approx(1)

        # Parameters through the viewer: read K, set it (accepted), set [-1, 100] (refused).
        client.send(op='getParameters', names=['/controller_node.K'], id='get')
        values = client.wait(lambda e: e.get('id') == 'get', 30.0, 'K')['parameters']
        assert values == [{'name': '/controller_node.K', 'value': [100.0, 100.0],
                           'type': 'float64_array'}]
        client.send(op='setParameters', id='ok', parameters=[
            {'name': '/controller_node.K', 'value': [120.0, 130.0], 'type': 'float64_array'}])
        values = client.wait(lambda e: e.get('id') == 'ok', 30.0, 'K set')['parameters']
        assert values[0]['value'] == [120.0, 130.0]
        client.send(op='setParameters', id='bad', parameters=[
            {'name': '/controller_node.K', 'value': [-1, 100]}])
        values = client.wait(lambda e: e.get('id') == 'bad', 30.0, 'K refused')['parameters']
        assert values[0]['value'] == [120.0, 130.0]
        status = client.wait(lambda e: e['event'] == 'status', 10.0, 'the refusal')
        assert 'set /controller_node.K refused' in status['message']
        assert 'K' in status['message'].split('refused:', 1)[1], status['message']

        # A change made elsewhere (as ros2 param set) reaches a client that subscribed. The
        # viewer subscribes to /parameter_events when asked, and a change made before that
        # subscription matches the node's publisher (discovery: longer on a loaded machine)
        # reaches nobody: set a new value until one arrives.
        from freejoint_tools.harness import ParameterCalls
        from rclpy.parameter import Parameter
        client.send(op='subscribeParameterUpdates', names=['/controller_node.K'])
        params = ParameterCalls(ros_node, '/controller_node', timeout=30.0)
        deadline = time.monotonic() + 60.0
        gain = 110.0
        while True:
            assert params.set_parameters([Parameter('K', value=[gain, 100.0])])[0].successful
            try:
                update = client.wait(
                    lambda e, k=[gain, 100.0]: e['event'] == 'parameterValues'
                    and not e.get('id') and e['parameters'][0]['value'] == k, 2.0,
                    'the K update')
                break
            except AssertionError:
                if time.monotonic() > deadline:
                    raise
                gain += 1.0
        assert update['parameters'][0]['name'] == '/controller_node.K'

        # Every parameter of every node at once (what the parameter panel asks).
        client.send(op='getParameters', names=[], id='all')
        names = {p['name'] for p in client.wait(lambda e: e.get('id') == 'all', 60.0,
                                                'all parameters')['parameters']}
        assert {'/controller_node.nominal_scale', '/sim_node.case',
                '/freejoint_planner.autostart'} <= names

        # The planner's service: a path check (execute false leaves the run alone).
        from freejoint_msgs.srv import PlanCircle
        from rclpy.serialization import deserialize_message, serialize_message
        request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.2, duration=5.0,
                                     start_angle=0.0, direction=1, execute=False)
        client.wait(lambda e: e['event'] == 'advertiseServices', 10.0, 'services')
        client.send(op='callService', service='/freejoint_planner/plan_circle', callId=7,
                    data=base64.b64encode(serialize_message(request)).decode())
        answer = client.wait(lambda e: e.get('callId') == 7, 30.0, 'plan_circle')
        assert answer['event'] == 'serviceCallResponse', answer
        response = deserialize_message(base64.b64decode(answer['data']), PlanCircle.Response)
        assert response.accepted, response.reason
        assert response.margin > 0.2
    finally:
        client.close()
    # The client gone: no subscription left.
    wait(lambda: not _viewer_subscribes(ros_node, '/joint_states')
         and not _viewer_subscribes(ros_node, '/controller_state'), 30.0,
         'the viewer to drop its subscriptions')
    assert procs.stop(viewer) == 0


BAD_START = [
    ('port:=70000', 'port'),
    ('services:=[plan_circle]', 'services'),
    ('services:=[/x=freejoint_msgs/srv/Nothing]', 'services'),
    ('description_file:=/nonexistent.urdf', 'description_file'),
    ('tf_rate:=0.0', 'tf_rate'),
]
"""A bad start-up value -> the parameter the viewer's one line names."""


def _one_fatal_line(code, log, named):
    assert code == 2, log
    assert 'Traceback' not in log
    fatal = [line for line in log.splitlines() if 'FATAL' in line]
    assert len(fatal) == 1 and 'bad parameter: %s' % named in fatal[0], log


@pytest.mark.parametrize('override, named', BAD_START)
def test_viewer_bad_start_up_parameter_makes_main_log_one_line_and_return_2(
        override, named, run_main):
    # In this process, as the executable runs it: rclpy.init, the viewer's constructor and
    # its checks (all before its server starts), the runner's line; main's return is the
    # process's exit status (test/conftest.py, run_main).
    code, log = run_main('freejoint_tools', 'viewer',
                         ['--ros-args', '-p', 'port:=0', '-p', override])
    _one_fatal_line(code, log, named)


def test_viewer_bad_start_up_parameter_is_one_line_and_exit_2(procs, wait):
    # What only the process shows, once (every row: the test above).
    override, named = BAD_START[0]
    proc = procs.start_node('freejoint_tools', 'viewer', 'viewer',
                            ['--ros-args', '-p', 'port:=0', '-p', override])
    wait(lambda: proc.poll() is not None, 30.0, 'the viewer to exit')
    _one_fatal_line(proc.returncode, procs.log(proc), named)


def _decoder(channel):
    """Return a function decoding the channel's protobuf messages (from its advertised schema)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    assert channel['encoding'] == 'protobuf', channel
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel['schema']))
    pool = descriptor_pool.DescriptorPool()
    for proto in files.file:
        pool.Add(proto)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel['schemaName']))
    return cls.FromString


UR5_MESHES = 'package://example-robot-data/robots/ur_description/meshes/ur5/'


def test_foxglove_client_sees_a_spatial_arm_with_its_meshes_frames_and_paths(
        procs, wait, ws_client_dir, ros_node, tmp_path):
    """
    The UR5 (a copy of its URDF: the forearm's visual mesh gone, the base's named by path).

    The viewer against synthetic joint states, tip positions and setpoints published by
    the test (the spatial graph's topics; its running is the graph tests' business).
    """
    from freejoint_common.contract import EE_POSITION, JOINT_STATES, SETPOINTS
    from freejoint_common.contract import stamp_from_ns
    from freejoint_core.spatial_model import known_arm, robot_data_dir
    from freejoint_msgs.msg import CartesianSetpoints
    from freejoint_tools.view_arm import FILES_PACKAGE, SpatialTree
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState
    import xml.etree.ElementTree as ET
    with open(os.path.join(robot_data_dir(), 'ur_description/urdf/ur5_robot.urdf')) as f:
        original = f.read()
    share = os.path.dirname(robot_data_dir())
    base_dae = os.path.join(robot_data_dir(), 'ur_description/meshes/ur5/visual/base.dae')
    text = original.replace(UR5_MESHES + 'visual/forearm.dae', UR5_MESHES + 'visual/gone.dae')
    text = text.replace(UR5_MESHES + 'visual/base.dae', base_dae)
    urdf = tmp_path / 'ur5_copy.urdf'
    urdf.write_text(text)
    viewer = procs.start_node('freejoint_tools', 'viewer', 'viewer', [
        '--ros-args', '-p', 'port:=0', '-p', 'description_file:=%s' % urdf])
    wait(lambda: 'viewer ready' in procs.log(viewer) or viewer.poll() is not None, 60.0,
         'the viewer to start')
    log = procs.log(viewer)
    port = int(re.search(r'ws://127\.0\.0\.1:(\d+)', log).group(1))
    assert 'spatial arm: frames by Pinocchio' in log, log
    warnings = [line for line in log.splitlines() if 'not found' in line]
    assert len(warnings) == 1 and 'WARN' in warnings[0], log
    assert 'gone.dae of link forearm_link' in warnings[0]

    arm = known_arm('ur5')
    q = [0.3, -1.2, 1.6, -1.97, -1.5708, 0.7]
    pubs = {name: ros_node.create_publisher(topic.msg_type, topic.name, topic.qos)
            for name, topic in (('js', JOINT_STATES), ('ee', EE_POSITION), ('sp', SETPOINTS))}
    published = {'tip': [], 'setpoint': []}

    def publish(k):
        """Publish tick k: the posture q, a tip point and a setpoint 5 mm apart per tick."""
        stamp = stamp_from_ns(k * 1_000_000)
        point = (0.5, 0.1 + 0.005 * k, 0.3)
        setpoint = (0.5, 0.1 + 0.005 * k, 0.31)
        js = JointState(name=list(arm.joint_names), position=q)
        js.header.stamp = stamp
        pubs['js'].publish(js)
        ee = PointStamped()
        ee.header.stamp, ee.header.frame_id = stamp, 'base_link'
        ee.point.x, ee.point.y, ee.point.z = point
        pubs['ee'].publish(ee)
        sp = CartesianSetpoints(stamps=[k * 1_000_000], position=list(setpoint),
                                velocity=[0.0] * 3, acceleration=[0.0] * 3, plan_id=[1],
                                plan_time=[0.0], final=[False])
        sp.header.stamp, sp.header.frame_id = stamp, 'base_link'
        pubs['sp'].publish(sp)
        published['tip'].append(point)
        published['setpoint'].append(setpoint)

    client = Client(ws_client_dir, 'ws://127.0.0.1:%d' % port)
    try:
        info = client.wait(lambda e: e['event'] == 'serverInfo', 30.0, 'serverInfo')
        assert 'assets' in info['capabilities']
        channels = {}
        while not {'/tf', '/robot_description', '/viewer/paths'} <= set(channels):
            event = client.wait(lambda e: e['event'] == 'advertise', 30.0, 'channels')
            channels.update({c['topic']: c for c in event['channels']})
        assert channels['/viewer/paths']['schemaName'] == 'foxglove.SceneUpdate'

        # The URDF served: the gone visual mesh replaced by the forearm's collision mesh,
        # the base's path renamed to a package URI of the viewer's.
        client.send(op='subscribe', topics=['/robot_description'], count=1)
        event = client.wait(lambda e: e['event'] == 'message'
                            and e['topic'] == '/robot_description', 30.0, 'the URDF')
        served = _cdr('std_msgs/msg/String', base64.b64decode(event['data'])).data
        links = {link.get('name'): link for link in ET.fromstring(served).findall('link')}
        forearm = [m.get('filename') for m in links['forearm_link'].iter('mesh')]
        assert forearm == [UR5_MESHES + 'collision/forearm.stl'] * 2
        renamed = 'package://%s%s' % (FILES_PACKAGE, base_dae)
        assert links['base_link'].find('visual/geometry/mesh').get('filename') == renamed

        # Every mesh URI of it fetched over the connection (Foxglove's fetchAsset): the file.
        uris = sorted({m.get('filename') for m in ET.fromstring(served).iter('mesh')})
        assert len(uris) == 13      # 7 links x (visual, collision), the forearm's one twice
        asked = uris + ['package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf']
        for i, uri in enumerate(asked):
            client.send(op='fetchAsset', uri=uri, requestId=i)
        for i, uri in enumerate(asked):
            answer = client.wait(lambda e: e['event'] == 'fetchAssetResponse'
                                 and e['requestId'] == i, 30.0, 'asset %s' % uri)
            if uri.endswith('.urdf'):   # not a mesh of the URDF: not served
                assert answer['status'] == 1, answer
                continue
            path = base_dae if uri == renamed else os.path.join(
                share, uri[len('package://example-robot-data/'):])
            with open(path, 'rb') as f:
                assert answer['status'] == 0 and base64.b64decode(answer['data']) == f.read()

        # /tf and the paths from the published topics.
        decode_paths = _decoder(channels['/viewer/paths'])
        client.send(op='subscribe', topics=['/tf', '/viewer/paths'], count=1000)
        frames, paths, k = None, None, 0
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not (
                frames and paths and all(len(e.lines) and len(e.lines[0].points) >= 5
                                         for e in paths.entities)):
            publish(k)
            k += 1
            try:
                event = client.events.get(timeout=0.02)
            except queue.Empty:
                continue
            if event['event'] != 'message':
                continue
            if event['topic'] == '/tf':
                frames = decode_frame_transforms(base64.b64decode(event['data']))
            elif event['topic'] == '/viewer/paths':
                paths = decode_paths(base64.b64decode(event['data']))
        assert frames and paths, 'no /tf or /viewer/paths within 60 s (%d ticks)' % k
    finally:
        client.close()

    # /tf: one transform per URDF joint = the arm's frames at q; composed from the root,
    # tool0 lands where the arm model puts the tip.
    expected = SpatialTree(original).transforms(dict(zip(arm.joint_names, q)))
    assert [(p, c) for p, c, _, _, _ in frames] == [(p, c) for p, c, _, _ in expected]
    poses = {'world': (np.zeros(3), (0.0, 0.0, 0.0, 1.0))}
    for (parent, child, xyz, rot, _), (_, _, xyz2, rot2) in zip(frames, expected):
        assert xyz == pytest.approx(xyz2, abs=1e-15) and rot == pytest.approx(rot2, abs=1e-15)
        p_pos, p_rot = poses[parent]
        poses[child] = (p_pos + quat_rotate(p_rot, xyz), quat_mul(p_rot, rot))
    assert poses['tool0'][0] == pytest.approx(arm.placement(np.array(q))[0], abs=1e-12)

    # The paths: one line each in base_link, published points in their order (best effort:
    # those before the viewer's subscription matched are not in it).
    by_id = {e.id: e for e in paths.entities}
    assert set(by_id) == {'tip_path', 'setpoint_path'}
    for name in ('tip', 'setpoint'):
        entity = by_id[name + '_path']
        assert entity.frame_id == 'base_link' and len(entity.lines) == 1
        got = [(p.x, p.y, p.z) for p in entity.lines[0].points]
        at = [published[name].index(point) for point in got]
        assert len(got) >= 5 and at == sorted(set(at))
    assert procs.stop(viewer) == 0
