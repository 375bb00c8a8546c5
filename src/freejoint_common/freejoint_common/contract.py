"""
The freejoint node graph contract (docs/GRAPH.md): the one source of its names and types.

Every node, the recorder, the player, the viewer, the demo, the bench and the tests take
from here:

* the topics (:class:`Topic`: name, message class, default QoS) and ``GRAPH_TOPICS``, the
  ones a run's recorder subscribes to from its start;
* the services (:class:`Service`: name, service class) and the planner's action
  (:class:`Action`);
* the QoS profiles, one name per profile (``STREAM_QOS``, ``REALTIME_STATE_QOS``,
  ``SETPOINT_QOS``, ``STANDBY_SETPOINT_QOS``, ``LATCHED_QOS``, ``CLOCK_PUBLISHER_QOS``,
  ``CLOCK_SUBSCRIPTION_QOS``, ``DIAGNOSTICS_QOS``) and :func:`profile` for a profile built
  from values (the recorder's and player's ``queue_depth``, a discovered publisher's offer);
* the stamps: :func:`to_ns` and :func:`stamp_from_ns` between ``builtin_interfaces/Time``
  and integer nanoseconds, :func:`clock_ns` of a serialized ``rosgraph_msgs/Clock``;
* the lockstep label of a command (``stamp_ns=<t_k>``, lockstep item 2):
  :func:`stamp_label`, :func:`label_stamp` and :func:`label_to_stamp`;
* a message taken serialized: :func:`read_serialized` (``freejoint_common.cdr``, else
  rclpy's deserialization);
* the layout of a ``setpoints`` batch (freejoint_msgs/CartesianSetpoints, flat arrays):
  :func:`setpoint_samples` reads it into ``freejoint_common.setpoint.SetpointSample`` records.

Names are relative (remappable) unless they start with ``/``.  A profile given to a
publisher or subscription with ``qos_overriding_options`` must be a copy
(``freejoint_common.node_tools.overridable``): rclpy writes the overrides into it.
"""

import struct
from typing import NamedTuple

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from freejoint_common.cdr import CdrError
from freejoint_common.setpoint import SetpointSample
from freejoint_msgs.action import FollowCircle
from freejoint_msgs.msg import CartesianSetpoints, ControllerReadiness, ControllerState
from freejoint_msgs.msg import PlanOutcome
from freejoint_msgs.srv import FailJoint, PlanCircle
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, String
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

# -- QoS ------------------------------------------------------------------------------------
STREAM_DEPTH = 1000
"""Keep-last depth of the run's streams: 1 s at 1 kHz, so lockstep and a recorder that
stalls for less than that lose nothing."""


def profile(depth, reliable=True, latched=False, **policies):
    """
    Return a keep-last QoS profile.

    Parameters
    ----------
    depth : int
        Keep-last depth (>= 1).
    reliable : bool, optional
        Reliable, else best effort.
    latched : bool, optional
        Transient local, else volatile.
    **policies
        Further ``QoSProfile`` keywords (``deadline``, ``lifespan``: a recorded offer).

    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        **policies)


def publisher_depth_override(topic, depth):
    """
    Return the ``-p`` item giving a node's publisher on ``topic`` a keep-last ``depth``.

    ``topic``: a :class:`Topic` of this contract (not remapped). The item is ros2's
    read-only ``qos_overrides./<topic>.publisher.depth``, taken at start-up by the nodes'
    overridable publishers.
    """
    return 'qos_overrides./%s.publisher.depth:=%d' % (topic.name.lstrip('/'), depth)


def is_latched(qos):
    """Return whether ``qos`` is transient local (a latched topic)."""
    return qos.durability == DurabilityPolicy.TRANSIENT_LOCAL


STREAM_QOS = profile(STREAM_DEPTH)
"""``joint_states``, ``ee_position``, commands, ``controller_state``: reliable, volatile."""
REALTIME_STATE_QOS = profile(1)
"""The controller's ``joint_states`` subscription in real time: the newest state only."""
SETPOINT_QOS = profile(STREAM_DEPTH, latched=True)
"""``setpoints``: transient local, so a controller started after the planner still gets the
ticks streamed ahead while the simulator waited for its first command."""
STANDBY_SETPOINT_QOS = profile(STREAM_DEPTH)
"""A hot spare's ``setpoints`` subscription: volatile (matches the transient-local
publisher), so a new spare is not sent the planner's history of old ticks (real time takes
the newest; the planner streams ahead)."""
LATCHED_QOS = profile(1, latched=True)
"""The map, the path marker, ``/robot_description``: reliable, transient local, depth 1."""
CLOCK_PUBLISHER_QOS = profile(STREAM_DEPTH)
"""The simulator's ``/clock``: reliable, as deep as the state (a lagging recorder loses
nothing)."""
CLOCK_SUBSCRIPTION_QOS = profile(STREAM_DEPTH, reliable=False)
"""A ``/clock`` subscription: best effort accepts any publisher (rclcpp's ClockQoS)."""
DIAGNOSTICS_QOS = QoSProfile(depth=10)
"""``/diagnostics`` (rclpy's default profile, depth 10, as diagnostic_updater)."""


# -- topics and services --------------------------------------------------------------------
class Topic(NamedTuple):
    """A topic of the graph: name, message class and the QoS its publisher offers."""

    name: str
    msg_type: type
    qos: QoSProfile

    @property
    def type_name(self):
        """Return the type as ``<package>/msg/<Name>`` (bag metadata, ``ros2 topic``)."""
        return type_name(self.msg_type)

    @property
    def absolute(self):
        """Return the name in the root namespace, unremapped (how a graph's bag names it)."""
        return self.name if self.name.startswith('/') else '/' + self.name

    @property
    def latched(self):
        """Return whether the topic is transient local."""
        return is_latched(self.qos)


def _on_node(node, name):
    """Return the full name of a node's ``~/`` (or relative) ``name`` (root namespace)."""
    return '/%s/%s' % (node.strip('/'), name[2:] if name.startswith('~/')
                       else name.lstrip('/'))


class Service(NamedTuple):
    """A service of a node: name (``~/`` = in the node's namespace) and service class."""

    name: str
    srv_type: type

    def of(self, node):
        """Return the service's full name on the node named ``node`` (root namespace)."""
        return _on_node(node, self.name)


class Action(NamedTuple):
    """An action of a node: name (``~/`` = in the node's namespace) and action class."""

    name: str
    action_type: type

    def of(self, node):
        """Return the action's full name on the node named ``node`` (root namespace)."""
        return _on_node(node, self.name)


def type_name(cls):
    """Return ``<package>/msg/<Name>`` (or ``srv``) of a message or service class."""
    package, kind = cls.__module__.split('.')[:2]
    return '%s/%s/%s' % (package, kind, cls.__name__)


CLOCK = Topic('/clock', Clock, CLOCK_PUBLISHER_QOS)
JOINT_STATES = Topic('joint_states', JointState, STREAM_QOS)
EE_POSITION = Topic('ee_position', PointStamped, STREAM_QOS)
COMMANDS = Topic('effort_controller/commands', Float64MultiArray, STREAM_QOS)
CONTROLLER_STATE = Topic('controller_state', ControllerState, STREAM_QOS)
SETPOINTS = Topic('setpoints', CartesianSetpoints, SETPOINT_QOS)
SEMI_SINGULAR_MAP = Topic('semi_singular_map', OccupancyGrid, LATCHED_QOS)
PLANNED_PATH = Topic('planned_path', Marker, LATCHED_QOS)
DIAGNOSTICS = Topic('/diagnostics', DiagnosticArray, DIAGNOSTICS_QOS)
ROBOT_DESCRIPTION = Topic('/robot_description', String, LATCHED_QOS)

CONTROLLER_READINESS = Topic('controller_readiness', ControllerReadiness, LATCHED_QOS)
"""Controller -> planner (and operator, recorder): the loop's readiness at start-up and at
each change (freejoint_msgs/ControllerReadiness; reliable, transient local, depth 1). A
planner pauses its plan while the controller is not ready and refuses a new one."""

PLAN_OUTCOME = Topic('plan_outcome', PlanOutcome, profile(10, latched=True))
"""Planner -> operator, recorder: how each plan ended (freejoint_msgs/PlanOutcome: the code,
why, lateness, pauses), and each refused request to execute one (plan_id 0); reliable,
transient local, depth 10 (a recorder or ``fj`` started later still reads the last ten)."""

GRAPH_TOPICS = (CLOCK, JOINT_STATES, EE_POSITION, COMMANDS, CONTROLLER_STATE, SETPOINTS,
                SEMI_SINGULAR_MAP, PLANNED_PATH, CONTROLLER_READINESS, PLAN_OUTCOME)
"""The run's topics a recorder subscribes to from its start (docs/GRAPH.md, Recording)."""
LOCKSTEP_STREAMS = {'sim': (JOINT_STATES, EE_POSITION), 'controller': (CONTROLLER_STATE,)}
"""Per node, the per-tick streams it writes whose every message a lockstep run's reader (the
recorder, a collector) keeps: :func:`lockstep_writer_overrides` deepens their writers."""
LOCKSTEP_WRITER_DEPTH = 20000
"""Keep-last depth of the writers of :data:`LOCKSTEP_STREAMS` in a run that must lose none.

A reliable writer can resend to a reader that fell behind only what its own history still
holds: with the contract's 1000 a reader stalled for 1000 ticks - well under a second of
wall time in lockstep, which runs faster than real time, on a loaded host - loses messages
for good. 20000 covers a 20-s run whole."""


def lockstep_writer_overrides(node, depth=LOCKSTEP_WRITER_DEPTH):
    """
    Return the ``-p`` items (``name:=value``) giving ``node``'s per-tick writers ``depth``.

    ``node``: 'sim' (joint_states, ee_position) or 'controller' (controller_state); any
    other node writes none of them (``[]``). See :func:`publisher_depth_override`.
    """
    return [publisher_depth_override(topic, depth) for topic in LOCKSTEP_STREAMS.get(node, ())]


NEVER_QUIET_TOPICS = ('/rosout', '/parameter_events', DIAGNOSTICS.name)
"""Topics every running node publishes on its own (its log, parameter events, its 1-Hz
diagnostics): a recorder whose drain is awaited once the lockstep simulator holds at
``max_steps`` (its received count must go quiet) is started with these excluded."""

RESET = Service('~/reset', Trigger)
"""Simulator and controller: back to the initial state."""
PLAN_CIRCLE = Service('~/plan_circle', PlanCircle)
"""Planner: check (and execute) a circle."""
FOLLOW_CIRCLE = Action('~/follow_circle', FollowCircle)
"""Planner: the circle of ``PLAN_CIRCLE`` as a goal with feedback and an outcome (feed hold,
path and goal tolerances; freejoint_msgs/action/FollowCircle)."""
RECORDER_STATUS = Service('~/status', Trigger)
"""Recorder: success once every graph topic has a matched publisher."""

# -- joint failures ----------------------------------------------------------------------------
FAILURE_NOTICE_QOS = profile(10, latched=True)
"""``joint_failures``: reliable, transient local (a controller started later still learns
of a failure already reported), depth 10."""
JOINT_FAILURES = Topic('joint_failures', String, FAILURE_NOTICE_QOS)
"""A driver's or operator's notice that a joint failed: ``data`` = the joint's name."""
FAIL_JOINT = Service('~/fail_joint', FailJoint)
"""Simulator: make a joint's actuator and brake fail from the next step."""

# -- brakes on request ---------------------------------------------------------------------
BRAKE_REQUEST = Topic('brake_request', String, profile(10))
"""Controller -> driver: engage the brakes now, where the arm is (``data``: why); reliable,
volatile (a request is for the arm now, never for a driver started later), depth 10. The
driver releases them at its next accepted command, as after its command watchdog
(the simulator's ``brake_timeout``), which stays the fallback of a driver without it."""
BRAKE_TIMEOUT_REQUEST = Topic('brake_timeout_request', Float64, profile(1, latched=True))
"""Controller -> driver (real time): from now on, brake after ``data`` s without a command
when that is shorter than the driver's own wait (``data`` 0: no request, the driver's own).
The controller asks for its ``hold_brake_timeout`` while its setpoint rests (a held arm
gains nothing from riding a stall on its last command) and 0 while it moves; sent when that
changes. Reliable, transient local, depth 1 (a driver started later learns the current
request). A driver without it keeps its own watchdog."""

# -- stamps ---------------------------------------------------------------------------------
NS_PER_S = 1_000_000_000


def to_ns(stamp):
    """Return the integer nanoseconds of a ``builtin_interfaces/Time`` (``sec``, ``nanosec``)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def setpoint_samples(msg):
    """
    Return the setpoints of a ``CartesianSetpoints`` batch, in the order sent.

    Parameters
    ----------
    msg : freejoint_msgs.msg.CartesianSetpoints
        ``stamps`` (n), ``position``, ``velocity``, ``acceleration`` (n m each, setpoint
        after setpoint), ``plan_id``, ``plan_time``, ``final`` (n each, or empty: 0, 0.0,
        False).

    Returns
    -------
    list of SetpointSample
        n of them, m = len(position) / n values per vector (tuples of float).

    Raises
    ------
    ValueError
        An array whose length does not fit n and m, named.

    """
    stamps = msg.stamps
    n = len(stamps)
    pos, vel, acc = msg.position, msg.velocity, msg.acceleration
    if n == 0:
        if len(pos) or len(vel) or len(acc):
            raise ValueError('setpoints: no stamps but %d position values' % len(pos))
        return []
    m, rest = divmod(len(pos), n)
    if rest or m == 0:
        raise ValueError('setpoints: position has %d values for %d stamps (n m expected)'
                         % (len(pos), n))
    for name, values in (('velocity', vel), ('acceleration', acc)):
        if len(values) != n * m:
            raise ValueError('setpoints: %s has %d values, position %d' % (
                name, len(values), n * m))
    extra = []
    for name, values, default in (('plan_id', msg.plan_id, 0),
                                  ('plan_time', msg.plan_time, 0.0),
                                  ('final', msg.final, False)):
        if len(values) not in (0, n):
            raise ValueError('setpoints: %s has %d values for %d stamps (n or none)'
                             % (name, len(values), n))
        extra.append(values if len(values) else [default] * n)
    ids, times, finals = (list(values) for values in extra)
    pos, vel, acc = list(pos), list(vel), list(acc)
    return [SetpointSample(int(stamps[i]), tuple(pos[j:j + m]), tuple(vel[j:j + m]),
                           tuple(acc[j:j + m]), int(ids[i]), float(times[i]),
                           bool(finals[i]))
            for i, j in zip(range(n), range(0, n * m, m))]


def stamp_from_ns(ns, stamp=None):
    """
    Return the ``builtin_interfaces/Time`` of a time in integer nanoseconds (>= 0).

    With ``stamp`` (a ``Time`` the caller keeps, e.g. a message's header stamp) its fields
    are set and it is returned: no new message on a per-tick path.
    """
    sec, nanosec = divmod(int(ns), NS_PER_S)
    if stamp is None:
        return Time(sec=sec, nanosec=nanosec)
    stamp.sec = sec
    stamp.nanosec = nanosec
    return stamp


def seconds_to_ns(seconds):
    """Return a time or duration [s] in integer nanoseconds, rounded to the nearest."""
    return int(round(seconds * 1e9))


def clock_ns(data):
    """
    Return the time [ns] at the start of a serialized message (CDR), None if too short.

    The first field of a ``rosgraph_msgs/Clock`` and the stamp of any message that starts
    with a ``std_msgs/Header``: read without deserializing (a 1 kHz raw subscription).
    """
    if len(data) < 12:
        return None
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    return sec * NS_PER_S + nanosec


# -- the lockstep label ---------------------------------------------------------------------
LABEL_PREFIX = 'stamp_ns='
"""A command's ``layout.dim[0].label`` is ``stamp_ns=<t_k ns>``: the state it answers."""


def stamp_label(ns):
    """Return the label of a command answering the state stamped ``ns``."""
    return LABEL_PREFIX + '%d' % ns


def label_stamp(dims):
    """
    Return the stamp [ns] a command's ``layout.dim`` names, or None.

    None without a dimension, without the ``stamp_ns=`` prefix, or with a value that is
    not an integer: a third-party command (taken as the answer to the current step).
    """
    return label_to_stamp(dims[0].label if dims else None)


def label_to_stamp(label):
    """Return the stamp [ns] of a command's first label (``stamp_ns=<ns>``), or None."""
    if label is None or not label.startswith(LABEL_PREFIX):
        return None
    try:
        return int(label[len(LABEL_PREFIX):])
    except ValueError:
        return None


def read_serialized(data, read, msg_type, fields):
    """
    Read a serialized message: ``read(data)``, else rclpy's deserialization.

    Parameters
    ----------
    data : bytes
        The message as taken (``raw=True``).
    read : callable
        A reader of ``freejoint_common.cdr`` (raises ``CdrError`` on what it cannot read).
    msg_type : type
        The message class, for ``rclpy.serialization.deserialize_message``.
    fields : callable
        ``fields(msg)``: the deserialized message as ``read`` would have returned it.

    Raises
    ------
    ValueError
        Neither can read it; the reason names both failures.

    """
    try:
        return read(data)
    except CdrError as exc:
        first = exc
    from rclpy.serialization import deserialize_message
    try:
        msg = deserialize_message(data, msg_type)
    except Exception as exc:    # noqa: B902 - rclpy raises several kinds on bad bytes
        raise ValueError('%s; rclpy cannot deserialize it either (%s)' % (first, exc)) \
            from None
    return fields(msg)
