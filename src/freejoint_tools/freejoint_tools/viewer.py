"""
Live view of the freejoint graph in Foxglove: ``viewer`` (foxglove-sdk's WebSocket server).

What a Foxglove client (the app, or any client of Foxglove's WebSocket protocol) gets:

* every graph topic (the recorder's ``GRAPH_TOPICS`` and whatever else is discovered, e.g.
  ``/diagnostics``) as raw CDR with the ``ros2msg`` schema the recorder writes to its bags
  (``freejoint_tools.typedefs``);
* ``/tf``: the arm's link frames as ``foxglove.FrameTransforms``, computed from
  ``joint_states`` with the URDF's kinematic tree (``freejoint_core.kinematic_tree``; a
  spatial arm - a URDF the planar model does not read, e.g. the UR5 or the Panda - with
  Pinocchio's forward kinematics of the whole tree, joints missing from the joint states
  at their locked value: ``freejoint_tools.view_arm``), one transform per URDF joint,
  parent and child named as the URDF's links; at most
  ``tf_rate`` per second, stamped with the time the viewer received the joint state (the
  clock of Foxglove's live view, as the other messages' log times: a lockstep run's sim
  time starts at 0 again with the next run, and older frames would stay ahead of it);
* ``/robot_description``: the URDF text (``std_msgs/msg/String``), for the 3D panel's URDF
  layer: the graph's own ``/robot_description`` (the simulator's, transient local) once it
  arrives, so that the graph has one source of the arm; ``description_file`` instead if
  given (``package://`` resolved); the shipped ``paper_arm.urdf`` until then. Its meshes
  are served over the same connection (the protocol's assets capability: Foxglove fetches
  ``package://`` URIs from the server it is connected to); meshes named by file path are
  renamed ``package://freejoint_viewer/<path>``, a missing one is drawn as the link's
  collision geometry or as lines between its joint frames, with one warning
  (``view_arm.serve_description``);
* ``/viewer/paths`` (a spatial arm only): the tip's path (``ee_position``) and the
  setpoints' (``setpoints``) as ``foxglove.SceneUpdate`` lines in 3-D, at most
  ``1 / PATH_PERIOD`` per second, started again when sim time restarts;
* the parameters of every node of the graph, as ``<node>.<parameter>``
  (``/controller_node.K``), read and set through rclpy's ``AsyncParameterClient``; a
  refused set is answered with the unchanged value and a warning status naming the
  parameter and the node's reason; changes made elsewhere (``ros2 param set``) reach the
  clients that subscribed to parameter updates (``/parameter_events``, subscribed only
  while one does);
* the services named in ``services`` (default the planner's ``plan_circle``), called
  with CDR requests.

Nothing is taken from the graph while no client looks: a ROS subscription exists only
while at least one client subscribes to its channel (best effort, so a slow viewer never
holds back a reliable publisher; the latched map and path transient local), and the
discovery of new topics is a graph query every ``discovery_period`` seconds. All rclpy
work happens on the executor thread: the server's callbacks (its own threads) queue it and
wake the executor with a guard condition, and wait for parameter and service answers.
"""

import concurrent.futures
import math
import os
import queue
import sys
import threading
import time

from freejoint_common.arm_description import package_path
from freejoint_common.contract import EE_POSITION, PLANNED_PATH, profile, ROBOT_DESCRIPTION
from freejoint_common.contract import SEMI_SINGULAR_MAP, setpoint_samples, SETPOINTS
from freejoint_common.contract import stamp_from_ns, to_ns
from freejoint_common.node_tools import declare
from freejoint_common.runner import Lifecycle, run
from freejoint_core.errors import FreejointValueError
from freejoint_core.kinematic_tree import KinematicTree
from freejoint_core.urdf import shipped_urdf_path
from rcl_interfaces.msg import ParameterType as RosType
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter as RosParameter
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import deserialize_message, serialize_message

from .params import VIEWER
from .recorder import _is_hidden, GRAPH_TOPICS
from .resend import first_answer, Wakeup
from .typedefs import DefinitionError, Definitions, message_class
from .view_arm import link_frames, serve_description, Trail

TF_TOPIC = '/tf'
PATHS_TOPIC = '/viewer/paths'
PATH_PERIOD = 0.1
"""Seconds between updates of the paths of a spatial arm (``/viewer/paths``)."""
PATH_COLOURS = {'tip': (1.0, 0.45, 0.0, 1.0), 'setpoint': (0.1, 0.6, 1.0, 1.0)}
RESEND = 0.5
"""Seconds before a parameter request still unanswered is sent again (see ``_await``)."""
DESCRIPTION_TOPIC = ROBOT_DESCRIPTION.name
# Topics low-rate and latched: subscribed reliable, transient local (the last one arrives
# when a client subscribes); every other one best effort, volatile.
LATCHED = (SEMI_SINGULAR_MAP.name, PLANNED_PATH.name)

SPECS = VIEWER.params
"""The viewer's parameters (``freejoint_tools.params.VIEWER``)."""

_HINTS = {RosType.PARAMETER_DOUBLE: 'Float64', RosType.PARAMETER_DOUBLE_ARRAY: 'Float64Array',
          RosType.PARAMETER_BYTE_ARRAY: 'ByteArray'}


def service_definitions(defs, srvtype):
    """
    Return the ``ros2msg`` texts ``(request, response)`` of a service type.

    Parameters
    ----------
    defs : Definitions
        The recorder's definitions (its type store gets the two message types).
    srvtype : str
        ``pkg/srv/Type``.

    Raises
    ------
    DefinitionError
        Naming the type if its ``.srv`` cannot be found or parsed.

    """
    from rosbags.typesys import get_types_from_msg

    from .typedefs import _share_dir
    pkg, kind, name = (srvtype.split('/') + ['', '', ''])[:3]
    if kind != 'srv' or not pkg or not name:
        raise DefinitionError('%s: not a service type name (pkg/srv/Type)' % srvtype)
    path = os.path.join(_share_dir(pkg), 'srv', name + '.srv')
    try:
        with open(path, encoding='utf-8') as fh:
            text = fh.read()
    except OSError:
        raise DefinitionError('%s: no definition file %s' % (srvtype, path))
    parts = text.split('\n---')
    if len(parts) != 2:
        raise DefinitionError('%s: %s is not request --- response' % (srvtype, path))
    out = []
    for suffix, part in zip(('_Request', '_Response'), parts):
        full = '%s/srv/%s%s' % (pkg, name, suffix)
        if full not in defs.store.fielddefs:
            try:
                # rosbags names a parsed type pkg/srv/msg/Name: registered as pkg/srv/Name
                types = {full: get_types_from_msg(part.lstrip('-\n'), full).popitem()[1]}
            except Exception as exc:  # rosbags parser errors
                raise DefinitionError('%s: cannot parse %s: %s' % (srvtype, path, exc))
            for _, fields in types.values():
                for dep in Definitions._nested(fields):
                    defs.lookup(dep)
            defs.store.register(types)
        out.append(defs.store.generate_msgdef(full, ros_version=2)[0])
    return tuple(out)


def to_foxglove(name, value_msg):
    """Return a foxglove ``Parameter`` from an rcl_interfaces ``ParameterValue``."""
    import foxglove
    if value_msg is None or value_msg.type == RosType.PARAMETER_NOT_SET:
        return foxglove.Parameter(name)
    value = parameter_value_to_python(value_msg)
    if not isinstance(value, (str, bool, int, float, bytes)):
        value = bytes(value) if value_msg.type == RosType.PARAMETER_BYTE_ARRAY else list(value)
    hint = _HINTS.get(value_msg.type)
    return foxglove.Parameter(name, value=value, type=getattr(foxglove.ParameterType, hint)
                              if hint else None)


def from_foxglove(name, value, current):
    """
    Return the rclpy ``Parameter`` to set from a client's value.

    Whole numbers become floats where the parameter holds floats (a client typing
    ``[-1, 100]`` for ``K``); other types are as the client sent them, and the node's
    own checks refuse what does not fit.
    """
    floats = (RosType.PARAMETER_DOUBLE, RosType.PARAMETER_DOUBLE_ARRAY)
    if current is not None and current.type in floats:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = float(value)
        elif isinstance(value, list) and all(isinstance(v, (int, float)) and
                                             not isinstance(v, bool) for v in value):
            value = [float(v) for v in value]
    if value is None:
        return RosParameter(name, RosParameter.Type.NOT_SET)
    return RosParameter(name, value=value)


class Viewer(Node, Lifecycle):
    """The graph's topics, transforms, parameters and services over Foxglove's protocol."""

    executor_kind = 'single_threaded'   # guard conditions wake it

    def __init__(self, **kwargs):
        super().__init__('viewer', **kwargs)
        self.values = declare(self, SPECS)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        path = package_path(self.values['description_file'] or shipped_urdf_path('paper_arm'))
        try:
            with open(path, encoding='utf-8') as fh:
                text = fh.read()
        except OSError as exc:
            raise FreejointValueError('description_file: cannot read %r (%s)' % (path, exc))
        self._server = None
        self._paths = None       # the SceneUpdate channel of a spatial arm's paths
        self._paths_dirty = False
        self._trails = {name: Trail() for name in PATH_COLOURS}
        self._take(text, os.path.dirname(os.path.abspath(path)))
        self.defs = Definitions()
        self._tasks = queue.SimpleQueue()
        self._wake = self.create_guard_condition(self._run_tasks)
        self._lock = threading.Lock()
        self._channels = {}      # topic -> (foxglove.Channel, msgtype)
        self._subscribed = {}    # foxglove channel topic -> number of client subscriptions
        self._ros_subs = {}      # ROS topic -> Subscription
        self._param_clients = {}
        self._service_clients = {}
        self._param_watch = set()    # parameters clients want updates of
        self._events_sub = None
        self._tf_last = 0.0
        self._tf_period = 1.0 / self.values['tf_rate']
        self._server = self._start_server()
        self._advertise_graph()
        self.create_timer(self.values['discovery_period'], self._discover)
        if not self.values['description_file']:
            # One source of the arm: the graph's latched /robot_description replaces the
            # shipped URDF when it arrives (a URDF arm of the simulator's).
            self.create_subscription(ROBOT_DESCRIPTION.msg_type, ROBOT_DESCRIPTION.name,
                                     self._on_description, ROBOT_DESCRIPTION.qos)
        self.get_logger().info(
            'viewer ready: ws://%s:%d (Foxglove: open connection, Foxglove WebSocket); URDF %s%s'
            % (self.values['host'], self._server.port, path, self._describe_spatial()))

    def _take(self, text, base_dir):
        """
        Make ``text`` the arm of /tf, of the URDF channel and of the assets served.

        Raises FreejointValueError (``robot_description: ...``) if it is no URDF the viewer
        can draw; the arm shown so far stays.
        """
        tree = link_frames(text)
        served = serve_description(text, base_dir)
        self.source, self.urdf, self.tree, self._served = text, served.text, tree, served
        if served.note:
            self._status_warning('%s: %s' % (ROBOT_DESCRIPTION.name, served.note))
        if self.spatial:
            for trail in self._trails.values():
                trail.clear()
            if self._paths is None:
                from foxglove.channels import SceneUpdateChannel
                self._paths = SceneUpdateChannel(PATHS_TOPIC)
                self.create_timer(PATH_PERIOD, self._flush_paths)
            self._paths_dirty = True

    @property
    def spatial(self):
        """Return True if the arm shown is a spatial one (its frames from Pinocchio)."""
        return not isinstance(self.tree, KinematicTree)

    def _describe_spatial(self):
        if not self.spatial:
            return ''
        return ' (spatial arm: frames by Pinocchio, %d mesh files served, paths on %s)' % (
            len(self._served.assets), PATHS_TOPIC)

    def _on_description(self, msg):
        """Take the graph's /robot_description as the arm of /tf and of the URDF channel."""
        if msg.data == self.source:
            return
        try:
            self._take(msg.data, None)
        except FreejointValueError as exc:
            self.get_logger().warn('%s not taken: %s' % (ROBOT_DESCRIPTION.name, exc))
            return
        self.get_logger().info('URDF from %s (%d characters)%s'
                               % (ROBOT_DESCRIPTION.name, len(msg.data),
                                  self._describe_spatial()))
        with self._lock:
            watched = DESCRIPTION_TOPIC in self._subscribed
        if watched:
            self._channels[DESCRIPTION_TOPIC][0].log(
                serialize_message(ROBOT_DESCRIPTION.msg_type(data=self.urdf)),
                log_time=time.time_ns())

    def _asset(self, uri):
        """Server callback (fetchAsset): the bytes of a mesh of the URDF served, else None."""
        return self._served.asset(uri)

    # -- parameters of the viewer itself ------------------------------------------------
    def _on_set_parameters(self, params):
        for p in params:
            if p.name == 'tf_rate':
                if not isinstance(p.value, float) or not 0.1 <= p.value <= 1000.0:
                    return SetParametersResult(successful=False,
                                               reason='tf_rate: expected 0.1..1000 Hz')
                self._tf_period = 1.0 / p.value
        return SetParametersResult(successful=True)

    # -- the executor thread ------------------------------------------------------------
    def _submit(self, fn, *args):
        """Run ``fn(*args)`` on the executor thread; return a concurrent Future of it."""
        fut = concurrent.futures.Future()
        self._tasks.put((fut, fn, args))
        self._wake.trigger()
        return fut

    def _run_tasks(self):
        while True:
            try:
                fut, fn, args = self._tasks.get_nowait()
            except queue.Empty:
                return
            try:
                fut.set_result(fn(*args))
            except Exception as exc:  # handed to the waiting server thread
                fut.set_exception(exc)

    def _await(self, make_future, resend=RESEND):
        """
        From a server thread: start an rclpy request on the executor thread, wait for it.

        With ``resend`` (s) the request is sent again while unanswered, the first answer
        returned (``call_timeout`` s in all): rmw_fastrtps drops a response sent before the
        server has matched this client's reader, which a request to a node discovered a
        moment ago can meet. ``resend=None`` for a request that must not run twice.
        """
        timeout = self.values['call_timeout']
        wakeup = Wakeup()

        def send():             # the request is made on the executor thread
            return self._submit(lambda: wakeup.watch(make_future())).result(timeout)
        answer, _ = first_answer(send, wakeup, timeout, resend)
        if answer is None:
            raise TimeoutError('no answer within %g s' % timeout)
        return answer.result()

    # -- the server ----------------------------------------------------------------------
    def _start_server(self):
        import foxglove
        from foxglove.websocket import Capability
        services = []
        for item in self.values['services']:
            name, sep, srvtype = item.partition('=')
            if not sep or not name.startswith('/'):
                raise FreejointValueError(
                    'services: expected /name=pkg/srv/Type, got %r' % item)
            try:
                req, resp = service_definitions(self.defs, srvtype)
            except DefinitionError as exc:
                raise FreejointValueError('services: %s' % exc)
            schema = foxglove.ServiceSchema(
                name=srvtype,
                request=foxglove.MessageSchema(encoding='cdr', schema=foxglove.Schema(
                    name=srvtype + '_Request', encoding='ros2msg', data=req.encode())),
                response=foxglove.MessageSchema(encoding='cdr', schema=foxglove.Schema(
                    name=srvtype + '_Response', encoding='ros2msg', data=resp.encode())))
            services.append(foxglove.Service(name, schema=schema,
                                             handler=self._service_handler(name, srvtype)))
        try:
            return foxglove.start_server(
                name='freejoint viewer', host=self.values['host'], port=self.values['port'],
                capabilities=[Capability.Parameters, Capability.Services],
                supported_encodings=['cdr'], services=services, server_listener=self,
                asset_handler=self._asset)
        except Exception as exc:  # address in use, bad host
            raise FreejointValueError('port: cannot serve on %s:%d (%s)'
                                      % (self.values['host'], self.values['port'], exc))

    def _advertise(self, topic, msgtype):
        import foxglove
        if topic in self._channels:
            return
        try:
            text, _ = self.defs.lookup(msgtype)
        except DefinitionError as exc:
            self.get_logger().warn('not served: %s (%s)' % (topic, exc))
            self._channels[topic] = (None, msgtype)
            return
        schema = foxglove.Schema(name=msgtype, encoding='ros2msg', data=text.encode())
        self._channels[topic] = (foxglove.Channel(topic, schema=schema, message_encoding='cdr'),
                                 msgtype)

    def _advertise_graph(self):
        from foxglove.channels import FrameTransformsChannel
        self._tf = FrameTransformsChannel(TF_TOPIC)
        self._advertise(DESCRIPTION_TOPIC, ROBOT_DESCRIPTION.type_name)
        for rel, msgtype, _ in GRAPH_TOPICS:
            self._advertise(self.resolve_topic_name(rel), msgtype)

    def _discover(self):
        for topic, types in self.get_topic_names_and_types():
            if len(types) == 1 and topic not in self._channels and not _is_hidden(topic) \
                    and topic not in (TF_TOPIC, '/rosout', '/parameter_events'):
                self._advertise(topic, types[0])

    # -- subscriptions: only while a client looks ----------------------------------------
    def on_subscribe(self, client, channel):
        """Server callback: a client subscribed to ``channel``."""
        with self._lock:
            self._subscribed[channel.topic] = self._subscribed.get(channel.topic, 0) + 1
        if channel.topic == PATHS_TOPIC:
            self._paths_dirty = True     # the new client gets the paths so far
        self._submit(self._update_subscriptions, channel.topic)

    def on_unsubscribe(self, client, channel):
        """Server callback: a client unsubscribed (or left)."""
        with self._lock:
            count = self._subscribed.get(channel.topic, 0) - 1
            if count > 0:
                self._subscribed[channel.topic] = count
            else:
                self._subscribed.pop(channel.topic, None)
        self._submit(self._update_subscriptions, None)

    def _wanted(self):
        with self._lock:
            topics = set(self._subscribed)
        wanted = {t for t in topics if t not in (TF_TOPIC, DESCRIPTION_TOPIC, PATHS_TOPIC)}
        js = self.resolve_topic_name(self.values['joint_states_topic'])
        if TF_TOPIC in topics:
            wanted.add(js)
        if PATHS_TOPIC in topics:
            wanted |= set(self._path_sources())
        return wanted

    def _path_sources(self):
        """Return ``{ROS topic: (trail name, message class)}`` of the paths."""
        return {self.resolve_topic_name(EE_POSITION.name): ('tip', EE_POSITION.msg_type),
                self.resolve_topic_name(SETPOINTS.name): ('setpoint', SETPOINTS.msg_type)}

    def _update_subscriptions(self, new_topic):
        wanted = self._wanted()
        for topic in list(self._ros_subs):
            if topic not in wanted:
                self.destroy_subscription(self._ros_subs.pop(topic))
        for topic in wanted - set(self._ros_subs):
            msgtype = self._channels.get(topic, (None, None))[1]
            if msgtype is None:
                continue
            latched = topic.rsplit('/', 1)[-1] in LATCHED
            qos = profile(10, reliable=latched, latched=latched)
            self._ros_subs[topic] = self.create_subscription(
                message_class(msgtype), topic, self._forwarder(topic), qos, raw=True)
        if new_topic == DESCRIPTION_TOPIC:
            msg = ROBOT_DESCRIPTION.msg_type(data=self.urdf)
            self._channels[DESCRIPTION_TOPIC][0].log(serialize_message(msg),
                                                     log_time=time.time_ns())

    def _forwarder(self, topic):
        channel = self._channels[topic][0]
        js = topic == self.resolve_topic_name(self.values['joint_states_topic'])
        trail, msg_class = self._path_sources().get(topic, (None, None))
        from sensor_msgs.msg import JointState

        def forward(raw):
            now = time.time_ns()
            if channel is not None and topic in self._subscribed:
                channel.log(raw, log_time=now)
            if js and TF_TOPIC in self._subscribed and \
                    now * 1e-9 - self._tf_last >= self._tf_period:
                self._tf_last = now * 1e-9
                self._send_tf(deserialize_message(raw, JointState), now)
            if trail is not None and self._paths is not None and \
                    PATHS_TOPIC in self._subscribed:
                self._add_to_path(trail, deserialize_message(raw, msg_class))
        return forward

    def _add_to_path(self, name, msg):
        """Add a tip position (PointStamped) or setpoints (CartesianSetpoints) to its path."""
        trail = self._trails[name]
        if name == 'tip':
            added = trail.add(to_ns(msg.header.stamp), (msg.point.x, msg.point.y, msg.point.z),
                              msg.header.frame_id)
        else:
            added = False
            try:
                samples = setpoint_samples(msg)
            except ValueError as exc:
                self.get_logger().warning('setpoints not drawn: %s' % exc,
                                          throttle_duration_sec=10.0)
                samples = ()
            for sp in samples:
                added = trail.add(sp.stamp_ns, sp.position, msg.header.frame_id) or added
        if added:
            self._paths_dirty = True

    def _flush_paths(self):
        """Send the paths if they changed (timer, every PATH_PERIOD s)."""
        if not self._paths_dirty or self._paths is None or PATHS_TOPIC not in self._subscribed:
            return
        self._paths_dirty = False
        from foxglove.messages import Color, Duration, LinePrimitive, LinePrimitiveLineType
        from foxglove.messages import Point3, Pose, Quaternion, SceneEntity, SceneUpdate
        from foxglove.messages import Vector3
        from foxglove.schemas import Timestamp
        now = time.time_ns()
        stamp = stamp_from_ns(now)
        stamp = Timestamp(stamp.sec, stamp.nanosec)
        entities = []
        for name, trail in self._trails.items():
            lines = []
            if len(trail.points) >= 2:
                r, g, b, a = PATH_COLOURS[name]
                lines.append(LinePrimitive(
                    type=LinePrimitiveLineType.LineStrip,
                    pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0),
                              orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                    thickness=3.0, scale_invariant=True, color=Color(r=r, g=g, b=b, a=a),
                    points=[Point3(x=x, y=y, z=z) for x, y, z in trail.points]))
            entities.append(SceneEntity(
                timestamp=stamp, frame_id=trail.frame_id or self.tree.root, id=name + '_path',
                lifetime=Duration(sec=0, nsec=0), frame_locked=True, lines=lines))
        self._paths.log(SceneUpdate(entities=entities), log_time=now)

    def _send_tf(self, msg, now):
        from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Vector3
        from foxglove.schemas import Timestamp
        positions = {n: p for n, p in zip(msg.name, msg.position) if math.isfinite(p)}
        stamp = stamp_from_ns(now)
        stamp = Timestamp(stamp.sec, stamp.nanosec)
        try:
            frames = self.tree.transforms(positions)
        except FreejointValueError:   # non-finite positions were left out above
            return
        self._tf.log(FrameTransforms(transforms=[
            FrameTransform(timestamp=stamp, parent_frame_id=parent, child_frame_id=child,
                           translation=Vector3(x=t[0], y=t[1], z=t[2]),
                           rotation=Quaternion(x=r[0], y=r[1], z=r[2], w=r[3]))
            for parent, child, t, r in frames]), log_time=now)

    # -- parameters of the graph's nodes --------------------------------------------------
    def _nodes(self):
        own = self.get_fully_qualified_name()
        out = []
        for name, ns in self.get_node_names_and_namespaces():
            full = (ns.rstrip('/') + '/' + name) if ns != '/' else '/' + name
            if full != own and not _is_hidden(full):
                out.append(full)
        return sorted(set(out))

    def _client(self, node):
        client = self._param_clients.get(node)
        if client is None:
            client = self._param_clients[node] = AsyncParameterClient(self, node)
        return client

    def _ready(self, node):
        client = self._submit(self._client, node).result(self.values['call_timeout'])
        deadline = time.monotonic() + self.values['call_timeout']
        while not client.services_are_ready():
            if time.monotonic() > deadline:
                return None
            time.sleep(0.02)
        return client

    def _get(self, node, names=None):
        """Return ``{name: ParameterValue}`` of ``node`` (every parameter if ``names`` None)."""
        client = self._ready(node)
        if client is None:
            raise TimeoutError('no parameter services within %g s'
                               % self.values['call_timeout'])
        if names is None:
            names = list(self._await(lambda: client.list_parameters()).result.names)
        if not names:
            return {}
        values = self._await(lambda: client.get_parameters(names)).values
        if len(values) != len(names):   # a value-less parameter: ask one by one
            values = [(self._await(lambda n=n: client.get_parameters([n])).values or [None])[0]
                      for n in names]
        return dict(zip(names, values))

    def on_get_parameters(self, client, param_names, request_id=None):
        """Server callback: the values of ``param_names`` (every node's if empty)."""
        wanted = {}
        if param_names:
            for full in param_names:
                node, _, name = full.partition('.')
                wanted.setdefault(node, []).append(name)
        else:
            wanted = dict.fromkeys(self._nodes())
        out = []
        for node, names in wanted.items():
            try:
                values = self._get(node, names)
            except Exception as exc:  # timeout, node gone
                self._status_warning('get parameters of %s: %s' % (node, exc or 'timed out'))
                continue
            out.extend(to_foxglove('%s.%s' % (node, n), v) for n, v in values.items())
        return out

    def on_set_parameters(self, client, parameters, request_id=None):
        """Server callback: set parameters; answer every one with its value afterwards."""
        by_node = {}
        for p in parameters:
            node, _, name = p.name.partition('.')
            by_node.setdefault(node, []).append((name, p.get_value()))
        out = []
        for node, items in by_node.items():
            try:
                current = self._get(node, [n for n, _ in items])
                client_ = self._ready(node)
                if client_ is None:
                    raise TimeoutError('node %s not found' % node)
                request = [from_foxglove(n, v, current.get(n)) for n, v in items]
                results = self._await(lambda: client_.set_parameters(request)).results
                for (name, _), result in zip(items, results):
                    if not result.successful:
                        self._status_warning('set %s.%s refused: %s'
                                             % (node, name, result.reason))
                after = self._get(node, [n for n, _ in items])
            except Exception as exc:  # timeout, node gone, unconvertible value
                self._status_warning('set parameters of %s failed: %s'
                                     % (node, exc or 'timed out'))
                continue
            out.extend(to_foxglove('%s.%s' % (node, n), v) for n, v in after.items())
        return out

    def on_parameters_subscribe(self, param_names):
        """Server callback: clients want updates of ``param_names`` (/parameter_events)."""
        with self._lock:
            self._param_watch.update(param_names)
        self._submit(self._update_parameter_events)

    def on_parameters_unsubscribe(self, param_names):
        """Server callback: no client wants updates of ``param_names`` any more."""
        with self._lock:
            self._param_watch.difference_update(param_names)
        self._submit(self._update_parameter_events)

    def _update_parameter_events(self):
        from rcl_interfaces.msg import ParameterEvent
        from rclpy.qos import qos_profile_parameter_events
        if self._param_watch and self._events_sub is None:
            self._events_sub = self.create_subscription(
                ParameterEvent, '/parameter_events', self._on_parameter_event,
                qos_profile_parameter_events)
        elif not self._param_watch and self._events_sub is not None:
            self.destroy_subscription(self._events_sub)
            self._events_sub = None

    def _on_parameter_event(self, event):
        changed = [to_foxglove('%s.%s' % (event.node, p.name), p.value)
                   for p in list(event.new_parameters) + list(event.changed_parameters)
                   if '%s.%s' % (event.node, p.name) in self._param_watch]
        if changed:
            self._server.publish_parameter_values(changed)

    def _status_warning(self, text):
        from foxglove import StatusLevel
        self.get_logger().warn(text)
        if self._server is not None:
            self._server.publish_status(text, StatusLevel.Warning)

    # -- services --------------------------------------------------------------------------
    def _service_handler(self, name, srvtype):
        srv_class = message_class(srvtype)

        def handler(request):
            if request.encoding != 'cdr':
                raise ValueError('%s: expected a cdr request, got %s' % (name, request.encoding))
            ros_request = deserialize_message(request.payload, srv_class.Request)

            def client():
                c = self._service_clients.get(name)
                if c is None:
                    c = self._service_clients[name] = self.create_client(srv_class, name)
                return c
            cli = self._submit(client).result(self.values['call_timeout'])
            deadline = time.monotonic() + self.values['call_timeout']
            while not cli.service_is_ready():
                if time.monotonic() > deadline:
                    raise RuntimeError('%s: service not available' % name)
                time.sleep(0.02)
            try:
                response = self._await(lambda: cli.call_async(ros_request), resend=None)
            except (TimeoutError, concurrent.futures.TimeoutError):
                raise RuntimeError('%s: no answer within %.1f s'
                                   % (name, self.values['call_timeout']))
            return serialize_message(response)
        return handler

    def on_shutdown(self):
        """Stop the server (clients see the connection close)."""
        self._server.stop()


FOXGLOVE_SDK = 'foxglove-sdk==0.30.3'
"""The pip requirement of the viewer (pinned in tools/requirements.txt; no rosdep key)."""


def main(args=None):
    """Run the viewer until SIGINT/SIGTERM; exit 2 on a bad start-up parameter."""
    try:
        import foxglove  # noqa: F401
    except ImportError as exc:
        print('viewer: error: foxglove-sdk is not installed (%s): pip install %s'
              % (exc, FOXGLOVE_SDK), file=sys.stderr)
        return 1
    return run(Viewer, 'viewer', args)


if __name__ == '__main__':
    sys.exit(main())
