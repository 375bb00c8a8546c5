"""
Diagnosis: the controller node as its executable runs it, with its start-up timeline logged.

``bench/scenarios.py controller_restart --probe`` restarts the controller with this file
(``python bench/controller_probe.py <the node's arguments>``) instead of its executable:
it logs, as ``[PROBE] [<system time>] ...`` lines in the node's log, the process start (from
/proc), the imports done, ``rclpy.init`` done, the node built, each matched event of the
node's publishers and subscriptions (rclpy's ``PublisherEventCallbacks`` /
``SubscriptionEventCallbacks`` ``matched``) and the first message of each subscription.
For measurements only: it wraps ``Node.create_publisher`` / ``create_subscription`` of this
process to add the callbacks.
"""

import os
import sys
import time

T_MAIN = time.time()


def process_start():
    """Return the system time [s] this process started (/proc/self/stat starttime)."""
    with open('/proc/self/stat') as f:
        ticks = int(f.read().rsplit(')', 1)[1].split()[19])
    with open('/proc/uptime') as f:
        uptime = float(f.read().split()[0])
    return time.time() - (uptime - ticks / os.sysconf('SC_CLK_TCK'))


def say(what):
    """Print one timestamped probe line (system time, as rcutils stamps its lines)."""
    print('[PROBE] [%.9f] %s' % (time.time(), what), flush=True)


def main():
    """Run controller_node's main with the probes in place."""
    start = process_start()
    from freejoint_control import controller_node
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    from rclpy.node import Node
    say('process started %.9f, interpreter %.3f s, imports done (%.3f s)'
        % (start, T_MAIN - start, time.time() - T_MAIN))
    create_publisher, create_subscription = Node.create_publisher, Node.create_subscription

    def matched(kind, topic):
        def callback(info):
            say('matched %s %s: %d now (%d in all)'
                % (kind, topic, info.current_count, info.total_count))
        return callback

    def probed_publisher(self, msg_type, topic, *args, **kwargs):
        kwargs['event_callbacks'] = PublisherEventCallbacks(matched=matched('publisher', topic))
        return create_publisher(self, msg_type, topic, *args, **kwargs)

    def probed_subscription(self, msg_type, topic, callback, *args, **kwargs):
        kwargs['event_callbacks'] = SubscriptionEventCallbacks(
            matched=matched('subscription', topic))
        first = []

        def probed(msg):
            if not first:
                first.append(True)
                say('first message on %s' % topic)
            return callback(msg)
        return create_subscription(self, msg_type, topic, probed, *args, **kwargs)

    Node.create_publisher = probed_publisher
    Node.create_subscription = probed_subscription
    node_class = controller_node.ControllerNode
    build = node_class.__init__

    def probed_init(self, *args, **kwargs):
        say('rclpy initialised, building the node')
        build(self, *args, **kwargs)
        say('node built')
    node_class.__init__ = probed_init
    return controller_node.main()


if __name__ == '__main__':
    sys.exit(main())
