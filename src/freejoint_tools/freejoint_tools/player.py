"""
Player node: republish a recorded bag with ``/clock``, as ``ros2 bag play --clock`` does.

Parameters: ``bag`` (the bag directory), ``rate`` (playback speed factor), ``clock``
(publish ``/clock`` from the bag's log times - sim time if it was recorded with
``use_sim_time`` - before each message whose time advanced; the recorded ``/clock`` topic
is then not republished), ``topics`` / ``exclude`` (which topics; default all),
``start_delay`` (wall s before the first message), ``wait_for_subscribers`` (wait until
every publisher has that many matched subscriptions, at most ``wait_timeout`` s),
``queue_depth`` (publisher depth where the recording does not know it).

Each topic is republished with the QoS recorded for it (reliability, durability; the
latched map and marker stay transient local), the messages as recorded (the serialized
bytes, no decode), in the bag's file order = the order the recorder received them, paced
by their log times divided by ``rate``. At the end the player waits until every reliable
subscriber acknowledged everything, logs what it played, and exits (code 0; 1 if the bag
cannot be read: one line naming the file; 2 on a bad parameter: one fatal line
``bad parameter: <name>: <reason>``, as every node).
"""

import sys
import time

from freejoint_common.contract import CLOCK, profile, stamp_from_ns
from freejoint_common.node_tools import NodeParameters
from freejoint_common.runner import Lifecycle, run
from rclpy.duration import Duration
from rclpy.node import Node

from .bagfile import BagError, open_bag
from .params import PLAYER
from .qos import publisher_qos
from .typedefs import message_class


class Player(Node, Lifecycle):
    """Republish a bag; see the module notes."""

    def __init__(self, **kwargs):
        super().__init__('player', **kwargs)
        # Every parameter of params.PLAYER, read-only; a bad one raises (exit 2).
        self._params = NodeParameters(self, PLAYER).config
        p = self._params
        self.bag = open_bag(p['bag'])
        for note in self.bag.notes:
            self.get_logger().warning(note)
        wanted = {self.resolve_topic_name(t) for t in p['topics']}
        excluded = {self.resolve_topic_name(t) for t in p['exclude']}
        if p['clock']:
            excluded.add(CLOCK.name)
        self._pubs = {}
        for name, topic in sorted(self.bag.topics.items()):
            if (wanted and name not in wanted) or name in excluded or not topic.count:
                continue
            try:
                msg_class = message_class(topic.type)
            except (ImportError, AttributeError, ValueError):
                self.get_logger().error('not playing %s: type %s is not installed'
                                        % (name, topic.type))
                continue
            self._pubs[name] = self.create_publisher(
                msg_class, name, publisher_qos(topic.qos, p['queue_depth']))
        self._clock_pub = None
        if p['clock']:
            self._clock_pub = self.create_publisher(CLOCK.msg_type, CLOCK.name,
                                                    profile(p['queue_depth']))
        self.played = dict.fromkeys(self._pubs, 0)

    def wait_for_subscribers(self):
        """Wait (bounded) until each publisher (/clock too) has the wanted subscribers; spin."""
        need = self._params['wait_for_subscribers']
        if not need:
            return True
        deadline = time.monotonic() + self._params['wait_timeout']
        pubs = list(self._pubs.values()) + ([self._clock_pub] if self._clock_pub else [])
        while time.monotonic() < deadline:
            if all(pub.get_subscription_count() >= need for pub in pubs):
                return True
            self.executor.spin_once(timeout_sec=0.01)  # parameter services answer meanwhile
        self.get_logger().warning('not every topic has %d subscriber(s) after %.1f s; '
                                  'playing anyway' % (need, self._params['wait_timeout']))
        return False

    def play(self):
        """Publish the bag's messages paced by their log times; return the count."""
        rate = self._params['rate']
        time.sleep(self._params['start_delay'])
        t0 = wall0 = last_clock = None
        due_ns = played = 0
        for name, log_time, _, data in self.bag.messages(self._pubs):
            if t0 is None:
                t0, wall0 = log_time, time.monotonic()
            due_ns = max(due_ns, log_time - t0)
            wait = wall0 + due_ns * 1e-9 / rate - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            if self._clock_pub is not None and (last_clock is None or log_time > last_clock):
                clock = CLOCK.msg_type(clock=stamp_from_ns(log_time))
                self._clock_pub.publish(clock)
                last_clock = log_time
            self._pubs[name].publish(data)
            self.played[name] += 1
            played += 1
        if not played:
            self.get_logger().warning('nothing to play')
        return played

    def finish(self):
        """Wait (bounded) until reliable subscribers acknowledged everything; log counts."""
        timeout = Duration(seconds=self._params['wait_timeout'])
        for pub in list(self._pubs.values()) + ([self._clock_pub] if self._clock_pub else []):
            pub.wait_for_all_acked(timeout)
        self.get_logger().info('played %d messages from %s: %s' % (
            sum(self.played.values()), self.bag.path,
            ', '.join('%s %d' % kv for kv in sorted(self.played.items()))))


def play_once(nodes, executor, stop):
    """Wait (bounded) for subscribers, play the bag once, finish (the player's loop)."""
    node = nodes[0]
    node.wait_for_subscribers()
    node.play()
    node.finish()


def main(args=None):
    """Play the bag once and exit (0; 1 if it cannot be read; 2: bad parameter)."""
    return run(Player, 'player', args, loop=play_once, errors=(BagError,),
               handle_signals=False)


if __name__ == '__main__':
    sys.exit(main())
