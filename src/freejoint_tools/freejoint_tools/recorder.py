"""
Recorder node: every topic of a run (or a list) into a rosbag2 bag with MCAP storage.

What ``ros2 bag record -s mcap`` does, for this workspace where rosbag2 is not installed:

* topics are discovered periodically (``discovery_period``, wall time), so publishers that
  join late are recorded from their first message on; ``topics: []`` (the default) records
  every topic with a publisher (hidden ``_``-topics only if listed), else only those listed;
* each subscription adapts to the publishers' offered QoS: reliable if all of them are,
  transient local if all of them are (the latched map and marker), keep-last with a deep
  queue (``queue_depth``) so nothing is dropped while the recorder catches up;
* messages are taken serialized (``raw=True``: the CDR bytes, no decode and re-encode) by
  the recorder itself, not dispatched by an executor one by one: the recording
  subscriptions live on a second node (``_<name>_takes``, hidden) that no executor spins,
  and every ``batch_period`` (10 ms, wall) the recorder takes everything each of them holds
  (``take_message``) and merges the takes of all topics by their receive time (the
  middleware's timestamp on reception), so the bag keeps the order of arrival. One wake-up
  per batch instead of one per message; the recorder's own node keeps ``~/status``, the
  timers and the parameters in its executor;
* log time = the receive time: in system time the middleware's reception timestamp, in sim
  time (``use_sim_time:=true``) the latest recorded ``/clock`` received before the message
  (see below). A message received less than 2 ms before a take began waits for the next
  batch, when everything received before it has been taken too (if one is taken after a
  later message was written all the same, its log time is still that of its receive time,
  and the summary counts it);
* the MCAP chunk is closed and handed to the OS every ``flush_period`` (wall s), so a
  SIGKILL loses at most that much of the tail; SIGINT and SIGTERM take what is already
  queued, then finalise the bag (summary, statistics, ``metadata.yaml``) and print what
  was received per topic (and any loss the middleware reported), the first stamp it got
  (system-time stamps, a real-time run's, in seconds from the recording's first stamp,
  first and last) and, for a lockstep stream on a grid (``joint_states``: ``t_k = k dt``),
  the ticks it missed (:class:`StampGrid`; also metadata.yaml ``custom_data``
  ``recorder_missed_ticks``);
* a write error (full disk) stops the writing (the bag stays readable up to it, see
  ``bagfile``), is logged once, and every message received from then on is counted ``not
  written`` for its topic (summary, ``~/status``, ``custom_data`` ``recorder_not_written``);
  the bag is still finalised on SIGINT/SIGTERM and the recorder exits 1 with one line.

Readiness: publishers that start together with the run (lockstep starts at the first
command) can be discovered late - Fast DDS sometimes needs seconds to discover one of
several participants started at once. The recorder therefore subscribes to the graph's
contract topics at start (``graph_topics``), and its service ``~/status``
(std_srvs/Trigger) answers ``success: true`` only once every topic of ``ready_topics``
(default: the graph's topics but ``/clock``, which a real-time graph does not have) and, in
sim time, ``/clock`` has a matched publisher; its message lists the matched publishers per
topic. A launcher that must lose nothing starts the nodes, waits for that,
then starts the run (e.g. the planner's ``~/plan_circle`` with ``autostart: false``).

Stopping a run: on one machine Fast DDS moves data through shared memory (rmw_fastrtps
with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` sets its transports itself), and a sample
the recorder has not taken yet is lost, without a report, when its publisher's process
exits. The recorder runs some ten ticks behind a loaded lockstep graph, so a launcher stops
the recorder's publishers only once it had time to catch up (e.g. stop the controller
first - the lockstep pauses - wait half a second, then the rest, the recorder last).
Messages the middleware does report lost (a publisher's depth-1000 history overrun while
the recorder was starved of CPU) are logged within a tenth of a second and counted in the
summary. Those message-lost events are read through a wait set of their own (a
SingleThreadedExecutor over a third node, ``_<name>_events``, spun for a moment every 0.1 s
and at close), never through the EventsExecutor: handed to it, rmw_fastrtps 8.4.3 (the
Jazzy wheels) enables its sample-lost listener, whose lock order is the reverse of
``rcl_take_event``'s, and a burst of losses then deadlocks the recorder (its executor and the
middleware's receive thread wait for each other; ros2/rmw_fastrtps#890). Without the
listener the middleware never takes the event's lock, and reading the event is safe.

Timestamps: with ``use_sim_time:=true`` the log times are sim time (the lockstep ``/clock``,
``t_k = k dt``), the same time base as the header stamps: a message's log time is the
latest recorded ``/clock`` that arrived before it, whenever the batch is taken. The
recorder takes ``/clock`` itself (also when it does not record it), so its node's
TimeSource does not subscribe to ``/clock`` (one dispatch per tick less); before the first
``/clock`` the log time is 0, and ``use_sim_time`` is read once at start.
``ros2 bag play --clock`` (and this package's player) publishes ``/clock`` from the log
times, so nodes replaying the bag with ``use_sim_time`` see a clock consistent with the
stamps of the data - which is what they need; with system-time log times the replayed
clock would be ~1.7e9 s while the stamps were ~0 s. The recorded ``/clock`` topic itself
is skipped by the player when it publishes its own clock (``ros2 bag play --clock`` users:
add ``--exclude-topics /clock``).
"""

import bisect
import datetime
import math
import operator
import os
import re
import shutil
import sys
import time

from freejoint_common import contract
from freejoint_common.clock import own_clock
from freejoint_common.contract import clock_ns, profile, RECORDER_STATUS
from freejoint_common.node_tools import NodeParameters
from freejoint_common.runner import Lifecycle, run
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from .bagfile import BagError, BagWriter, SYSTEM_TIME_NS
from .params import RECORDER
from .qos import profile_to_dict, subscription_qos
from .typedefs import DefinitionError, Definitions, message_class

DEFAULT_DIR = 'bags'
LOST_PERIOD = 0.1
"""Wall period (s) of reading the middleware's message-lost events (module docstring)."""
# The freejoint graph's topics (docs/GRAPH.md): name (relative = in the recorder's
# namespace), type, transient local. With graph_topics (default) the recorder subscribes to
# them at start - reliable, deep queue - so that it is matched with their publishers in the
# same discovery round as the other nodes and misses nothing of a run that starts at once
# (lockstep starts with the first command). If the publishers offer other QoS or another
# type the subscription is replaced by one adapted to them. Other topics are discovered.
GRAPH_TOPICS = tuple((t.name, t.type_name, t.latched) for t in contract.GRAPH_TOPICS)
# A batch writes what was received up to this long before the take began; later messages
# wait for the next batch, when everything received before them has surely been taken too
# (a message is timestamped on reception a little before it can be taken).
HOLD_NS = 2_000_000
CLOCK_TOPIC = contract.CLOCK.name
_RECEIVED = operator.itemgetter(0)
# Files an earlier run of the tools leaves in a bag directory (what overwrite may delete).
_OWN_FILES = ('metadata.yaml', 'metrics.json')
_OWN_SUFFIXES = ('.mcap', '.png', '.yaml.tmp', '.json.tmp', '.reserve')
# A stream is on a grid (lockstep: t_k = k dt) if at least this many distinct stamps are all
# a multiple of their smallest spacing, itself at least GRID_MIN_STEP_NS.
GRID_MIN_STAMPS = 10
GRID_MIN_STEP_NS = 1000
_GAPS_KEPT = 1000


def _refuse_sim_time_change(params, _values, _config):
    """Refuse a change of ``use_sim_time``: read once at start (the recorder takes /clock)."""
    if any(p.name == 'use_sim_time' for p in params):
        return ('use_sim_time is read once at start (the recorder takes /clock itself); '
                'restart the recorder to change it')
    return None


class StampGrid:
    """
    The stamps of one recorded stream: the first and last one and, on a grid, the ticks missing.

    Fed the header stamp (ns) of every message received, in receive order. Ticks are
    counted only for a lockstep stream: stamps of a sim clock (below ``SYSTEM_TIME_NS``;
    system-time stamps, a real-time run's, are Unix time and never ticks) whose distinct
    values are all multiples of their smallest spacing (the sim's ``joint_states`` in
    lockstep: ``t_k = k dt``); tick k is then ``stamp // step``, and a grid anchored at zero
    (the first stamp a multiple of the step) misses the ticks before the first stamp too.
    Repeated stamps (the sim's tick 0 while it waits for the first command) count once; a
    stamp earlier than the latest is counted, not gridded.
    """

    __slots__ = ('first', 'last', 'count', 'step', 'min_diff', 'gaps', 'backwards',
                 'off_grid')

    def __init__(self):
        self.first = None
        self.last = None
        self.count = 0           # distinct stamps, increasing
        self.step = 0            # gcd of the spacings
        self.min_diff = None
        self.gaps = []           # (stamp before, stamp after) of the wider spacings
        self.backwards = 0
        self.off_grid = False    # the gcd fell below GRID_MIN_STEP_NS: never a grid

    def add(self, t):
        """Take the stamp ``t`` (ns) of the next message received."""
        last = self.last
        if last is None:
            self.first = self.last = t
            self.count = 1
            return
        d = t - last
        if d == self.min_diff:                 # the usual spacing: nothing new to learn
            self.count += 1
            self.last = t
            return
        if d <= 0:
            if d:
                self.backwards += 1
            return
        self.count += 1
        self.last = t
        if self.off_grid:
            return
        step = math.gcd(self.step, d)
        self.step = step
        if step < GRID_MIN_STEP_NS:
            self.off_grid = True
            self.gaps = []
            return
        if self.min_diff is None or d < self.min_diff:
            first_diff = self.min_diff is None
            self.min_diff = d
            if not first_diff:
                return
        elif d == self.min_diff:
            return
        if len(self.gaps) < _GAPS_KEPT:
            self.gaps.append((last, t))

    def system_time(self):
        """Return True if the stamps are system time (Unix time: a real-time stream)."""
        return self.first is not None and self.first >= SYSTEM_TIME_NS

    def on_grid(self):
        """Return True if the stamps are a lockstep stream's grid (see the class notes)."""
        return (not self.off_grid and not self.backwards and self.count >= GRID_MIN_STAMPS
                and self.step == self.min_diff and not self.system_time())

    def missed(self):
        """
        Return ``(count, ranges)`` of the ticks missing, None if not on a grid.

        ``ranges`` are ``(first tick, last tick)`` pairs (at most the first 1000 gaps;
        ``count`` is exact): before the first stamp (grid anchored at zero) and between two.
        """
        if not self.on_grid():
            return None
        step = self.step
        ranges = []
        before = 0
        if self.first % step == 0 and self.first:
            before = self.first // step
            ranges.append((0, before - 1))
        inside = (self.last - self.first) // step + 1 - self.count
        for a, b in self.gaps:
            if b - a > step:
                ranges.append((a // step + 1, b // step - 1))
        return before + inside, ranges

    def describe(self, origin=None):
        """
        Return the first stamp and the ticks missed, for the end-of-run summary.

        System-time stamps (a real-time stream) are given as seconds from ``origin`` (ns:
        the first stamp of the recording; default this stream's first), first and last;
        sim-time stamps as they are (sim time starts at 0), with the ticks missed on a grid.
        """
        if self.first is None:
            return 'no stamp'
        if self.system_time():
            origin = self.first if origin is None else origin
            return 'first stamp %+.6f s, last %+.6f s (from the first stamp recorded)' % (
                (self.first - origin) * 1e-9, (self.last - origin) * 1e-9)
        text = 'first stamp %.6f s' % (self.first * 1e-9)
        missed = self.missed()
        if missed is None:
            return text
        step = self.step
        if self.first % step == 0:
            text += ' = tick %d' % (self.first // step)
        count, ranges = missed
        text += ' (grid %g ms), missed %s' % (step * 1e-6, _ticks_text(count, ranges))
        return text


def first_system_stamp(grids):
    """Return the earliest first stamp (ns) of the system-time streams among ``grids``."""
    firsts = [g.first for g in grids if g.system_time()]
    return min(firsts) if firsts else None


def ready_topic_names(names, sim_time):
    """
    Return the topics ``~/status`` waits for: ``names``, and ``/clock`` in sim time.

    A recorder in sim time takes its log times from ``/clock``, so it is ready only once
    ``/clock`` has a publisher too (the lockstep simulator); in system time (a real-time
    graph, which has no ``/clock``) only the topics named.
    """
    out = list(dict.fromkeys(names))
    if sim_time and CLOCK_TOPIC not in out:
        out.append(CLOCK_TOPIC)
    return out


def status_answer(ready_topics, matched, closed, problem, received, not_written):
    """
    Return ``(success, message)`` of a ``~/status`` answer.

    Parameters
    ----------
    ready_topics : list of str
        The topics waited for (:func:`ready_topic_names`).
    matched : dict
        ``{topic: matched publishers}``.
    closed : bool
        The bag is finalised.
    problem : str or None
        Why the bag is not whole (a write error), None if it is.
    received, not_written : int
        Messages received so far; of them, not written.

    Returns
    -------
    tuple of (bool, str)

    """
    waiting = [t for t in ready_topics if not matched.get(t)]
    success = not waiting and not closed and problem is None
    message = '%s; received %d; not written %d; matched publishers: %s' % (
        'closed' if closed else
        'cannot write the bag: %s' % problem if problem is not None else
        'recording' if success else 'waiting for ' + ', '.join(waiting),
        received, not_written, ', '.join('%s %d' % kv for kv in sorted(matched.items())))
    return success, message


def _ticks_text(count, ranges):
    if not count:
        return '0 ticks'
    shown = ', '.join(str(a) if a == b else '%d-%d' % (a, b) for a, b in ranges[:10])
    more = ', ...' if len(ranges) > 10 or sum(b - a + 1 for a, b in ranges) < count else ''
    return '%d tick%s: %s%s' % (count, 's' if count > 1 else '', shown, more)


def _is_stamped(msg_class, msgtype):
    """Return True if the message starts with its stamp (std_msgs/Header, or a Clock)."""
    if msgtype == 'rosgraph_msgs/msg/Clock':
        return True
    fields = msg_class.get_fields_and_field_types()
    first = next(iter(fields.items()), None)
    return first == ('header', 'std_msgs/Header')


def _never_called(data):
    """Stand for the callback of a subscription no executor dispatches (it is taken)."""


def _is_hidden(name):
    return any(part.startswith('_') for part in name.split('/') if part)


class Recorder(Node, Lifecycle):
    """Record the run's topics into a rosbag2 (v9, MCAP) bag; see the module notes."""

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        # Every parameter of params.RECORDER, read-only; a bad one raises (exit 2).
        self._param_loader = NodeParameters(self, RECORDER)
        self._param_loader.listen(check=_refuse_sim_time_change, watch=('use_sim_time',))
        self._params = self._param_loader.config
        p = self._params
        self.executor_kind = p['executor']
        self.batch_period = p['batch_period']
        # Sim time: log times come from the /clock messages the recorder takes itself, so
        # the node's TimeSource need not take every /clock too (a dispatch per tick).
        self._sim_time = self.get_parameter('use_sim_time').value is True
        if self._sim_time:
            own_clock(self)
        # The recorded topics' subscriptions live on a node no executor spins: nothing
        # dispatches them; take() takes what they hold every batch_period. Services, timers
        # and parameters stay on this node, in the executor. Their message-lost events go to
        # a third node, read by a wait-set executor of its own (never the EventsExecutor:
        # module docstring).
        # Both hidden (a leading underscore, as ros2 node list hides): helpers without
        # parameters, which a tool listing the graph's nodes (the viewer) passes over.
        self._takes_node, self._events_node = (
            Node('_%s_%s' % (self.get_name(), suffix), namespace=self.get_namespace(),
                 context=self.context, use_global_arguments=False, enable_rosout=False,
                 start_parameter_services=False) for suffix in ('takes', 'events'))
        self._lost_events = SingleThreadedExecutor(context=self.context)
        self._lost_events.add_node(self._events_node)
        self._lost_read = False  # a message-lost event was dispatched (by _read_lost)
        self._wanted = {self.resolve_topic_name(t) for t in p['topics']}
        self._excluded = {self.resolve_topic_name(t) for t in p['exclude']}
        output = p['output'] or os.path.join(
            DEFAULT_DIR, datetime.datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S'))
        if p['overwrite']:
            _remove_old_bag(output)
        self.writer = BagWriter(output, p['custom_data'], chunk_size=p['chunk_size'],
                                compression=p['compression'],
                                ros_distro=os.environ.get('ROS_DISTRO') or 'jazzy')
        self.output = output
        self._defs = Definitions()
        self._subs = {}          # topic -> subscription
        self._takers = []        # (topic or None for /clock only, handle, type), /clock first
        self._clock_only = None  # sim time, /clock not recorded: its subscription all the same
        self._pending = []       # (receive ns, topic, data) taken, written in a later batch
        self._clock_ns = None    # the latest /clock taken (ns), in receive order
        self._clocks = []        # (receive ns, /clock ns) of the recent /clock messages
        self._types = {}         # topic -> type of its subscription
        self._last_written = 0   # receive ns of the last message written
        self._late = 0           # messages taken after a later one was written
        self._channels = {}      # topic -> (bag channel id, type)
        self._unconfirmed = {}   # pre-subscribed topic -> (contract type, QoS) until seen
        self.received = {}       # topic -> messages received
        self.lost = {}           # topic -> messages the middleware reported lost
        self._grids = {}         # stamped topic -> StampGrid of what was received
        self._write_errors = {}   # topic -> messages the writer refused (not written)
        self.problem = None      # one line: why the bag is not whole (None: it is)
        self._skipped = set()
        self._warned = set()
        self._closed = False
        wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(p['discovery_period'], self._discover, clock=wall)
        self.create_timer(p['flush_period'], self._flush, clock=wall)
        self.create_timer(LOST_PERIOD, self._read_lost, clock=wall)
        self.get_logger().info('recording into %s (%s)' % (
            output, 'topics: ' + ', '.join(sorted(self._wanted)) if self._wanted
            else 'all topics'))
        if p['graph_topics']:
            self._presubscribe()
        if self._sim_time and not self._selected(CLOCK_TOPIC):
            self._clock_only = self._takes_node.create_subscription(
                message_class('rosgraph_msgs/msg/Clock'), CLOCK_TOPIC, _never_called,
                profile(p['queue_depth'], reliable=False), raw=True)
            self._update_takers()
        self._ready_topics = ready_topic_names(
            [self.resolve_topic_name(t) for t in p['ready_topics']], self._sim_time)
        self.create_service(RECORDER_STATUS.srv_type, RECORDER_STATUS.name, self._status)
        self._discover()

    # -- subscriptions ----------------------------------------------------------------
    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _selected(self, name):
        if self._wanted:
            if name not in self._wanted:
                return False
        elif _is_hidden(name):
            return False
        return name not in self._excluded

    def _presubscribe(self):
        """Subscribe to the graph's contract topics before any publisher exists."""
        for rel, msgtype, latched in GRAPH_TOPICS:
            name = self.resolve_topic_name(rel)
            if not self._selected(name):
                continue
            qos = profile(self._params['queue_depth'], latched=latched)
            if self._subscribe(name, msgtype, qos):
                self._unconfirmed[name] = (msgtype, qos)
                try:                   # parse the definitions now, not during the run
                    self._defs.lookup(msgtype)
                except DefinitionError:
                    pass               # said when the topic is registered

    def _discover(self):
        if self._closed:
            return
        for name, types in self.get_topic_names_and_types():
            if name in self._skipped or not self._selected(name):
                continue
            if name in self._subs and name not in self._unconfirmed:
                continue
            if len(types) != 1:
                self._warn_once(('types', name), 'not recording %s: it has several types %s'
                                % (name, ', '.join(types)))
                continue
            infos = self.get_publishers_info_by_topic(name)
            if not infos:
                continue
            if name in self._unconfirmed:
                self._confirm(name, types[0], infos)
            else:
                qos = subscription_qos([i.qos_profile for i in infos],
                                       self._params['queue_depth'])
                if self._subscribe(name, types[0], qos):
                    self._register(name, types[0], infos)

    def _confirm(self, name, msgtype, infos):
        """Keep a pre-subscription if the publishers match it, else replace it."""
        expected, qos = self._unconfirmed.pop(name)
        adapted = subscription_qos([i.qos_profile for i in infos], self._params['queue_depth'])
        compatible = msgtype == expected and (
            adapted.reliability == ReliabilityPolicy.RELIABLE
            or qos.reliability != ReliabilityPolicy.RELIABLE) and (
            adapted.durability == DurabilityPolicy.TRANSIENT_LOCAL
            or qos.durability != DurabilityPolicy.TRANSIENT_LOCAL)
        if not compatible:
            self.get_logger().warning(
                '%s: its publishers offer %s (%s, %s), not the graph contract; '
                'subscribing anew' % (name, msgtype, adapted.reliability.name.lower(),
                                      adapted.durability.name.lower()))
            self._unsubscribe(name)
            if name in self._channels and self._channels[name][1] != msgtype:
                self._warn_once(('retype', name), '%s: type changed; not recording' % name)
                self._skipped.add(name)
                return
            if not self._subscribe(name, msgtype, adapted):
                return
        self._register(name, msgtype, infos)

    def _subscribe(self, name, msgtype, qos):
        try:
            msg_class = message_class(msgtype)
        except (ImportError, AttributeError, ValueError) as exc:
            self._skipped.add(name)
            self.get_logger().error('not recording %s: type %s is not installed (%s)'
                                    % (name, msgtype, exc))
            return False
        self.received.setdefault(name, 0)
        self.lost.setdefault(name, 0)
        if _is_stamped(msg_class, msgtype):
            self._grids.setdefault(name, StampGrid())
        sub = self._takes_node.create_subscription(
            msg_class, name, _never_called, qos, raw=True,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._lost_callback(name)))
        for handler in sub.event_handlers:    # read by _read_lost's wait set
            self._events_node.add_waitable(handler)
        self._subs[name] = sub
        self._types[name] = msgtype
        self._update_takers()
        self.get_logger().info('recording %s [%s] (%s, %s)' % (
            name, msgtype, qos.reliability.name.lower(), qos.durability.name.lower()))
        return True

    def _unsubscribe(self, name):
        """Destroy a topic's subscription, after taking what it still holds."""
        self.take()
        self._read_lost()
        sub = self._subs.pop(name)
        self._update_takers()
        for handler in sub.event_handlers:
            self._events_node.remove_waitable(handler)
        self._takes_node.destroy_subscription(sub)

    def _update_takers(self):
        subs = sorted(self._subs.items(), key=lambda item: item[0] != CLOCK_TOPIC)
        if self._clock_only is not None:
            subs.insert(0, (None, self._clock_only))
        self._takers = [(name, sub.handle, sub.msg_type) for name, sub in subs]

    def _register(self, name, msgtype, infos=None):
        """Add the topic's channel to the bag (once): definition, hash, offered QoS."""
        if name in self._channels:
            return self._channels[name][0]
        if infos is None:
            infos = self.get_publishers_info_by_topic(name)
        advertised = str(infos[0].topic_type_hash or '') if infos else ''
        if not advertised.startswith('RIHS01_'):
            advertised = ''
        try:
            msgdef, digest = self._defs.lookup(msgtype)
        except DefinitionError as exc:
            msgdef, digest = '', ''
            self.get_logger().warning('recording %s without a message definition: %s'
                                      % (name, exc))
        if advertised and digest and advertised != digest:
            self.get_logger().warning(
                "%s: the publisher's type hash %s differs from the installed definition of "
                "%s (%s); the bag keeps the publisher's hash"
                % (name, advertised, msgtype, digest))
        channel = self.writer.add_topic(name, msgtype, msgdef, advertised or digest,
                                        [profile_to_dict(i.qos_profile) for i in infos])
        self._channels[name] = (channel, msgtype)
        return channel

    def take(self, final=False):
        """
        Take what every subscription holds and write it in receive order; return the count.

        The takes of all topics are merged by their receive time (the middleware's
        timestamp on reception), so the bag keeps the order of arrival and, in sim time,
        each message gets the latest /clock received before it. Messages received less
        than ``HOLD_NS`` before the take began wait for the next batch (a message that
        arrived just before them may not be takeable yet); ``final`` writes them all.
        """
        cutoff = time.time_ns() - HOLD_NS
        batch = self._pending
        before = len(batch)
        received = self.received
        for name, handle, msg_type in self._takers:
            take = handle.take_message
            taken = len(batch)
            try:
                with handle:
                    while True:
                        got = take(msg_type, True)
                        if got is None:
                            break
                        batch.append((got[1]['received_timestamp'] or time.time_ns(),
                                      name, got[0]))
            except InvalidHandle:      # destroyed at shutdown
                continue
            if name is not None:
                received[name] += len(batch) - taken
        count = len(batch) - before
        if not batch:
            return 0
        if count:
            batch.sort(key=_RECEIVED)          # stable: /clock first on equal times
        if final:
            ready, self._pending = batch, []
        else:
            split = bisect.bisect_right(batch, cutoff, key=_RECEIVED)
            ready, self._pending = batch[:split], batch[split:]
        if ready:
            self._write(ready)
            if self.writer.error is not None and self.problem is None:
                self._stopped_writing()
        return count

    def _write(self, ready):
        if ready[0][0] < self._last_written:   # rare: taken after a later message was written
            split = bisect.bisect_left(ready, self._last_written, key=_RECEIVED)
            self._write_late(ready[:split])
            ready = ready[split:]
            if not ready:
                return
        write = self.writer.write
        channels = self._channels
        grids = self._grids
        sim_time = self._sim_time
        clocks = self._clocks
        clock = self._clock_ns
        for received, name, data in ready:
            if name is None or name == CLOCK_TOPIC:
                t = clock_ns(data)
                if t is not None:
                    clock = t
                    clocks.append((received, t))
                if name is None:
                    continue
            grid = grids.get(name)
            if grid is not None:
                stamp = clock_ns(data)
                if stamp is not None:
                    grid.add(stamp)
            if not sim_time:
                stamp = received
            elif clock is not None:
                stamp = clock
            else:                              # no /clock yet: the node's clock (0)
                stamp = self.get_clock().now().nanoseconds
            try:
                entry = channels.get(name)
                write(entry[0] if entry else self._register(name, self._types[name]),
                      stamp, data)
            except (OSError, ValueError) as exc:
                self._write_error(name, exc)
        self._clock_ns = clock
        self._last_written = ready[-1][0]
        if len(clocks) > 8192:
            del clocks[:4096]

    def _write_late(self, late):
        """Write messages received before others already written: log time as if in order."""
        self._late += len(late)
        clocks = self._clocks
        for received, name, data in late:
            if name is None or name == CLOCK_TOPIC:
                t = clock_ns(data)
                if t is not None:
                    bisect.insort(clocks, (received, t), key=_RECEIVED)
                if name is None:
                    continue
            grid = self._grids.get(name)
            if grid is not None and clock_ns(data) is not None:
                grid.add(clock_ns(data))
            if self._sim_time:
                at = bisect.bisect_right(clocks, received, key=_RECEIVED)
                stamp = clocks[at - 1][1] if at else self.get_clock().now().nanoseconds
            else:
                stamp = received
            try:
                entry = self._channels.get(name)
                channel = entry[0] if entry else self._register(name, self._types[name])
                self.writer.write(channel, stamp, data)
            except (OSError, ValueError) as exc:
                self._write_error(name, exc)

    def _stopped_writing(self):
        """Say once that the file system refused a write; from then on the losses are counted."""
        self.problem = '%s: %s; the bag keeps its first %d bytes, every message from then ' \
            'on is counted lost (not written)' % (self.writer.mcap_path, self.writer.error,
                                                  self.writer.error_at)
        self.get_logger().error('cannot write the bag: %s' % self.problem)

    def not_written(self):
        """Return ``{topic: messages received that did not reach the file}``."""
        out = {name: self.writer.lost(entry[0]) for name, entry in self._channels.items()}
        for name, count in self._write_errors.items():
            out[name] = out.get(name, 0) + count
        return out

    def _write_error(self, name, exc):
        self._write_errors[name] = self._write_errors.get(name, 0) + 1
        self.get_logger().error('cannot write a message of %s: %s' % (name, exc),
                                throttle_duration_sec=5.0)

    def matched(self):
        """Return ``{topic: matched publishers}`` of the recorder's subscriptions."""
        out = {name: sub.get_publisher_count() for name, sub in self._subs.items()}
        if self._clock_only is not None:        # sim time, /clock taken but not recorded
            out[CLOCK_TOPIC] = self._clock_only.get_publisher_count()
        return out

    def _status(self, request, response):
        """~/status: success once every ready topic has a matched publisher; the count so far."""
        response.success, response.message = status_answer(
            self._ready_topics, self.matched(), self._closed, self.problem,
            sum(self.received.values()), sum(self.not_written().values()))
        return response

    def _read_lost(self):
        """Dispatch the pending message-lost events (a zero-timeout wait each, bounded)."""
        for _ in range(len(self._subs) + 1):
            self._lost_read = False
            self._lost_events.spin_once(timeout_sec=0.0)
            if not self._lost_read:
                return

    def _lost_callback(self, name):
        def on_lost(info):
            self._lost_read = True
            if info.total_count_change <= 0:
                return
            self.lost[name] += int(info.total_count_change)
            self.get_logger().warning('%s: the middleware reports %d message(s) lost' % (
                name, info.total_count_change))
        return on_lost

    # -- flushing and closing ---------------------------------------------------------
    def _flush(self):
        if self._closed:
            return
        self.writer.flush()
        if self.writer.error is not None and self.problem is None:
            self._stopped_writing()

    def total_received(self):
        """Return the number of messages received so far."""
        return sum(self.received.values())

    def on_shutdown(self):
        """Finalise the bag (the runner's shutdown): :meth:`close`."""
        self.close()

    def failure(self):
        """Return why not everything received reached the bag (exit 1), or None."""
        return self.problem

    def close(self):
        """
        Finalise the bag and log what was recorded per topic.

        Whatever happened before (a write error), the bag gets its summary and
        metadata.yaml if the file system allows it at all; ``problem`` then says what went
        wrong (one line), and the run notes go into metadata.yaml ``custom_data``.
        """
        if self._closed:
            return
        try:
            self.take(final=True)
        except Exception as exc:  # noqa: B902 - finalise the bag whatever the take said
            self.get_logger().error('cannot take the last messages: %s' % exc)
        finally:
            self._closed = True
            try:
                self._read_lost()
            except Exception as exc:  # noqa: B902 - finalise the bag whatever the read said
                self.get_logger().error('cannot read the message-lost events: %s' % exc)
            for name in list(self._subs):
                sub = self._subs.pop(name)
                for handler in sub.event_handlers:
                    self._events_node.remove_waitable(handler)
                self._takes_node.destroy_subscription(sub)
            self._takers = []
            self.writer.flush()                # the last chunk: its messages written or lost
            if self.writer.error is not None and self.problem is None:
                self._stopped_writing()
            self.writer.custom_data.update(self.run_notes())
            try:
                self.writer.close()
            except (BagError, OSError) as exc:
                self.problem = '%s%s' % (self.problem + '; ' if self.problem else '',
                                         'cannot finalise the bag: %s' % exc)
                self.get_logger().error(self.problem)
        lines = ['bag %s %s: %d messages on %d topics' % (
            self.output, 'finalised' if self.writer.closed and not self.problem else
            'closed after a problem', self.total_received(), len(self._channels))]
        not_written = self.not_written()
        origin = first_system_stamp(self._grids.values())
        if origin is not None:
            lines.append('  system-time stamps (real time) in s from the first stamp recorded, '
                         '%s UTC' % datetime.datetime.fromtimestamp(
                             origin * 1e-9, datetime.timezone.utc).strftime(
                                 '%Y-%m-%d %H:%M:%S.%f'))
        for name in sorted(self._channels):
            written = self.writer.count(self._channels[name][0])
            grid = self._grids.get(name)
            lines.append('  %s: received %d, written %d, not written %d, lost (middleware) %d%s'
                         % (name, self.received[name], written, not_written[name],
                            self.lost[name], '; ' + grid.describe(origin) if grid else ''))
        if self.problem:
            lines.append('  problem: %s' % self.problem)
        if self._write_errors:
            lines.append('  %d message(s) refused by the bag writer'
                         % sum(self._write_errors.values()))
        if self._late:
            lines.append('  %d message(s) taken after a later one was written (their log '
                         'time as if in order)' % self._late)
        self.get_logger().info('\n'.join(lines))
        self._log_plan_figures()

    def _log_plan_figures(self):
        """Log the run's figures against the plan, read back from the finalised bag."""
        from .plan_bag import plan_summary
        if not self.writer.closed or self.problem or not {
                contract.EE_POSITION.absolute, contract.SETPOINTS.absolute} <= set(self._channels):
            return
        try:
            line = plan_summary(self.output, self.writer.custom_data.get('case'))
        except Exception as exc:  # noqa: B902 - a summary line must not cost the bag
            self.get_logger().warn('no figures against the plan: %s' % exc)
        else:
            self.get_logger().info('against the plan: %s' % line)

    def run_notes(self):
        """
        Return what the recorder adds to ``custom_data`` at the end (only what went wrong).

        ``recorder_not_written`` (messages received that did not reach the file, per
        topic), ``recorder_error`` (why), ``recorder_missed_ticks`` (per stream on a grid:
        how many ticks are missing and which, e.g. the first ones of a recorder started
        after the run).
        """
        notes = {}
        lost = {n: c for n, c in sorted(self.not_written().items()) if c}
        if lost:
            notes['recorder_not_written'] = ', '.join('%s %d' % kv for kv in lost.items())
        if self.problem:
            notes['recorder_error'] = self.problem
        missed = []
        for name in sorted(self._grids):
            gaps = self._grids[name].missed()
            if gaps and gaps[0]:
                missed.append('%s %s' % (name, _ticks_text(*gaps)))
        if missed:
            notes['recorder_missed_ticks'] = '; '.join(missed)
        return notes

    def destroy_node(self):
        """Destroy the node and the ones that hold the recording subscriptions and events."""
        self._lost_events.shutdown()
        self._events_node.destroy_node()
        self._takes_node.destroy_node()
        super().destroy_node()


def received_count(status):
    """Return the message count a ``~/status`` answer reports ('received N'), or None."""
    match = re.search(r'; received (\d+);', status or '')
    return int(match.group(1)) if match else None


REPAIR_QUIET = 3.5
"""[s] How long the recorder's count must stay unchanged before a silent graph is taken as
recorded: longer than Fast DDS's reliable writers' heartbeat period (3 s by default, not
set in config/fastdds.xml), after which a sample a starved reader missed is sent again. A
shorter quiet can stop the publishers while a repair is due, and the sample is lost (a
loaded test machine lost the last 130 ticks of a lockstep run that way)."""


def wait_drained(read_status, quiet, timeout, pause):
    """
    Wait until the recorder's received count stays the same for ``quiet`` s.

    Meant for once the graph is silent (a lockstep simulator holding at ``max_steps``): a
    steady count then means the recorder has taken everything published.

    Parameters
    ----------
    read_status : callable
        Returns the message of a ``~/status`` answer ('' or None: no answer).
    quiet : float
        Seconds the count must stay unchanged.
    timeout : float
        Seconds to wait at most.
    pause : callable
        Called between two reads (spin the caller's node for a moment).

    Returns
    -------
    count : int or None
        The steady count (the last one read on timeout; None: never answered).
    settled : float
        Seconds from the call to the count's last change (on timeout: to the timeout).

    """
    start = time.monotonic()
    last, since = None, start
    while time.monotonic() < start + timeout:
        count = received_count(read_status())
        now = time.monotonic()
        if count != last:
            last, since = count, now
        elif count is not None and now - since >= quiet:
            return count, since - start
        pause()
    return last, time.monotonic() - start


def _remove_old_bag(path):
    if not os.path.exists(path):
        return
    if not os.path.isdir(path):
        raise BagError(path, 'exists and is not a bag directory, not overwriting')
    names = os.listdir(path)
    foreign = [n for n in names if n not in _OWN_FILES and not n.endswith(_OWN_SUFFIXES)]
    if foreign:
        raise BagError(path, 'holds %s, which is not a bag file; not overwriting' % foreign[0])
    shutil.rmtree(path)


def spin_until_stopped(node, executor, stop, drain_quiet=0.3, drain_max=3.0):
    """
    Take and write every ``batch_period`` until a signal; then take what is left.

    Between takes the executor runs this node's timers, services and events. After the
    signal the takes go on (bounded) until nothing came for ``drain_quiet`` s.
    """
    period = node.batch_period
    spin_once = executor.spin_once
    monotonic = time.monotonic
    next_take = monotonic() + period
    while stop.signum is None and rclpy.ok():
        wait = next_take - monotonic()
        if wait > 0.0:
            spin_once(timeout_sec=wait)
            continue
        node.take()
        next_take = max(next_take + period, monotonic() + 0.2 * period)
    deadline = monotonic() + drain_max
    last_change = monotonic()
    node.get_logger().info('stopping (signal %d) after %d messages; taking what is queued'
                           % (stop.signum or 0, node.total_received()))
    while rclpy.ok() and monotonic() < deadline:
        spin_once(timeout_sec=0.02)
        if node.take():
            last_change = monotonic()
        elif monotonic() - last_change >= drain_quiet:
            break


def main(args=None):
    """
    Run the recorder until SIGINT/SIGTERM; finalise the bag; exit 0.

    Exit 1 with one line ``recorder: error: ...`` on stderr if the bag cannot be created,
    or if not everything received reached it (a write error: the bag is still finalised);
    exit 2 with one fatal line ``bad parameter: <name>: <reason>`` on a bad start-up
    parameter (rclpy's range and type checks, the set-parameters callback), as every node.
    The signal only sets the runner's flag: the loop then drains the queues.
    """
    return run(Recorder, 'recorder', args, errors=(BagError, OSError),
               loop=lambda nodes, executor, stop: spin_until_stopped(nodes[0], executor, stop))


if __name__ == '__main__':
    sys.exit(main())
