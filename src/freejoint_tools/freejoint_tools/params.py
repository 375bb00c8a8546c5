"""
Parameters of the recorder, the player and the viewer: their schemas (no ROS types).

Both are read-only (set at start-up); the entries they share (``topics``, ``exclude``,
``queue_depth``) are built once by :func:`topic_selection` / :func:`queue_depth`. Each
node's config is the validated ``{name: value}`` dict with the topic lists without empty
names and, for the recorder, ``custom_data`` parsed into a dict
(``freejoint_common.node_tools.NodeParameters`` declares and validates them).
"""

from freejoint_common import contract
from freejoint_common.schema import above, one_of, Param, Schema

from .bagfile import COMPRESSIONS

LIST_KEYS = ('topics', 'exclude', 'ready_topics')
"""String-array entries whose empty names are dropped (rclpy cannot declare an empty
string array with a default, so they default to [''])."""
MAX_QUEUE_DEPTH = 1_000_000


def _topic_names(value):
    bad = [v for v in value if v and (not isinstance(v, str) or ' ' in v)]
    return f'bad topic name {bad[0]!r}' if bad else None


def parse_custom_data(items):
    """
    Parse ``['key=value', ...]`` into a dict; raise ValueError naming a bad item.

    Keys are non-empty and unique; values may be empty.
    """
    out = {}
    for item in items or []:
        key, sep, value = str(item).partition('=')
        key = key.strip()
        if not sep or not key:
            raise ValueError('custom_data item %r is not key=value' % item)
        if key in out:
            raise ValueError('custom_data key %r given twice' % key)
        out[key] = value.strip()
    return out


def _custom_data(value):
    try:
        parse_custom_data(v for v in value if v)
    except ValueError as exc:
        return str(exc).replace('custom_data ', '', 1)
    return None


def _compression(value):
    if value not in COMPRESSIONS:
        return f"must be one of {', '.join(COMPRESSIONS)}, got {value!r}"
    return None


def topic_selection(verb, everything):
    """Return the ``topics`` / ``exclude`` entries of a node that ``verb``s topics."""
    return (
        Param('topics', [''], f'Topics to {verb}; empty list = {everything}', read_only=True,
              validator=_topic_names),
        Param('exclude', [''], f'Topics not to {verb}', read_only=True,
              validator=_topic_names),
    )


def queue_depth(default, description):
    """Return the ``queue_depth`` entry (messages per topic)."""
    return Param('queue_depth', default, description, (1, MAX_QUEUE_DEPTH), read_only=True)


def _config(values):
    """Return the config dict: the topic lists without empty names, custom_data a dict."""
    config = dict(values)
    for name in LIST_KEYS:
        if name in config:
            config[name] = [v for v in (config[name] or []) if v]
    if 'custom_data' in config:
        config['custom_data'] = parse_custom_data(v for v in config['custom_data'] if v)
    return config


RECORDER = Schema((
    Param('output', '', 'Bag directory to create (default bags/rosbag2_<date-time>); must not '
          'exist unless overwrite is true', read_only=True),
    topic_selection('record', 'every topic with a publisher'),
    Param('custom_data', [''], 'Run information as key=value items (e.g. case=horizontal, '
          'variant=robust, seed=0), stored in metadata.yaml custom_data and at once in the '
          'MCAP file', read_only=True, validator=_custom_data),
    Param('overwrite', False,
          'Replace an existing bag directory at output (only one holding bag files)',
          read_only=True),
    Param('discovery_period', 0.05, 'Wall period of topic discovery (s)', (0.01, 10.0),
          read_only=True, validator=above(0.0, ' s')),
    Param('flush_period', 0.25, 'Wall period of closing the MCAP chunk and flushing the file '
          '(s): the most a SIGKILL can lose', (0.01, 60.0), read_only=True,
          validator=above(0.0, ' s')),
    Param('chunk_size', 1 << 20, 'MCAP chunk size (bytes); a chunk also closes at every flush',
          (4096, 1 << 28), read_only=True),
    Param('compression', 'none', "MCAP chunk compression: 'none' or 'zstd' (rosbag2's MCAP "
          'storage option compression: Zstd; every MCAP reader decompresses the chunks)',
          read_only=True, validator=_compression),
    Param('graph_topics', True, 'Subscribe to the freejoint graph topics (docs/GRAPH.md) at '
          'start, with their contract types and QoS, so a run that starts before discovery '
          'loses nothing', read_only=True),
    Param('ready_topics', [t.name for t in contract.GRAPH_TOPICS
                           if t not in (contract.CLOCK, contract.CONTROLLER_READINESS)],
          '~/status answers success once each of these topics has a matched publisher; with '
          'use_sim_time also /clock (the log times come from it; a real-time graph has none)',
          read_only=True, validator=_topic_names),
    Param('executor', 'events', "rclpy executor: 'events' (rclpy.experimental.EventsExecutor) "
          "or 'single_threaded'", read_only=True,
          validator=one_of(('events', 'single_threaded'))),
    Param('batch_period', 0.01, 'Wall period (s) of taking what arrived on every recorded topic '
          '(the subscriptions are not dispatched by the executor): one wake-up per period '
          'instead of one per message', (0.001, 0.1), read_only=True),
    queue_depth(5000, 'Subscription queue depth (messages) per topic'),
), build=_config)
"""The recorder's parameters."""


def _bag(value):
    return None if value else 'no bag given (-p bag:=<directory>)'


PLAYER = Schema((
    Param('bag', '', 'Bag directory to play', read_only=True, validator=_bag),
    Param('rate', 1.0, 'Playback speed factor (2.0 = twice as fast)', (0.001, 1000.0),
          read_only=True, validator=above(0.0)),
    Param('clock', True,
          'Publish /clock from the log times (the recorded /clock is not republished)',
          read_only=True),
    topic_selection('play', 'all'),
    Param('start_delay', 0.0, 'Wall time to wait before the first message (s)', (0.0, 3600.0),
          read_only=True),
    Param('wait_for_subscribers', 0,
          'Wait until every publisher has this many matched subscriptions', (0, 1000),
          read_only=True),
    Param('wait_timeout', 10.0,
          'Longest wait for subscribers, and for acknowledgements at the end (s)',
          (0.0, 3600.0), read_only=True),
    queue_depth(1000, 'Publisher depth where the recording does not know it'),
), build=_config)
"""The player's parameters."""


VIEWER = Schema((
    Param('host', '127.0.0.1', 'address the Foxglove WebSocket server binds to (0.0.0.0: '
          'every interface; the default serves this machine only)', read_only=True),
    Param('port', 8765, 'TCP port of the Foxglove WebSocket server (0: any free port, '
          'logged)', (0, 65535), read_only=True),
    Param('description_file', '', 'URDF of the arm for /tf and /robot_description; empty = '
          "the graph's /robot_description (the simulator's), the shipped paper_arm.urdf "
          '(freejoint_description) until it arrives', read_only=True),
    Param('joint_states_topic', 'joint_states', 'JointState topic the transforms are '
          'computed from', read_only=True),
    Param('tf_rate', 50.0, 'most /tf updates per second sent to clients (joint_states '
          'arrive at up to 1 kHz)', (0.1, 1000.0)),
    Param('services', ['/freejoint_planner/plan_circle=freejoint_msgs/srv/PlanCircle'],
          'services offered to clients, each as name=pkg/srv/Type', read_only=True),
    Param('call_timeout', 5.0, 'seconds to wait for a node to answer a parameter request or '
          'a service call', (0.1, 60.0)),
    Param('discovery_period', 2.0, 'seconds between looks for new topics and nodes',
          (0.1, 60.0)),
))
"""The viewer's parameters (declared by ``freejoint_tools.viewer``, which checks ``tf_rate``
changes itself)."""
