"""
Measurement prototype of a warm standby controller (bench only, not a product feature).

``python bench/controller_standby.py [--takeover S] <the node's arguments>`` runs the
controller node as its executable does (give it another node name, ``-r
__node:=controller_standby``), built and discovered, its setpoints taken, but its
joint_states dropped unread (no law computed: a standby computing every tick alongside
doubled the controller's CPU and stalled the active loop on 2 vCPUs) and its
``effort_controller/commands`` and ``controller_state`` withheld, until no command has
been seen on ``effort_controller/commands`` for ``S`` s (default 0.03, below the
simulator's 0.05-s brake watchdog): then it takes the states and publishes (takes over,
from a hold at the arm's position, blended onto the stream as after a restart) and logs
``[PROBE] [<system time>] standby: taking over``. ``bench/scenarios.py controller_restart
--standby`` kills the active controller and measures the takeover. One standby at a time:
two would both take over.
"""

import sys
import time

from controller_probe import say


class _Gate:
    """A publisher whose ``publish`` passes only once ``open[0]`` is true."""

    def __init__(self, publisher, is_open):
        self._publisher = publisher
        self._open = is_open

    def publish(self, msg):
        if self._open[0]:
            self._publisher.publish(msg)

    def __getattr__(self, name):
        return getattr(self._publisher, name)


def main(argv):
    """Run controller_node's main as a standby (see the module notes)."""
    takeover = 0.03
    if len(argv) > 1 and argv[0] == '--takeover':
        takeover, argv = float(argv[1]), argv[2:]
    sys.argv = [sys.argv[0]] + argv
    from freejoint_control import controller_node
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    active = [False]
    create_publisher = Node.create_publisher
    create_subscription = Node.create_subscription

    def gated_subscription(self, msg_type, topic, callback, *args, **kwargs):
        if topic != 'joint_states':
            return create_subscription(self, msg_type, topic, callback, *args, **kwargs)

        def while_active(msg):
            if active[0]:
                callback(msg)
        return create_subscription(self, msg_type, topic, while_active, *args, **kwargs)
    Node.create_subscription = gated_subscription

    def gated_publisher(self, msg_type, topic, *args, **kwargs):
        publisher = create_publisher(self, msg_type, topic, *args, **kwargs)
        if topic in ('effort_controller/commands', 'controller_state'):
            return _Gate(publisher, active)
        return publisher
    Node.create_publisher = gated_publisher
    node_class = controller_node.ControllerNode
    build = node_class.__init__

    def standby_init(self, *args, **kwargs):
        build(self, *args, **kwargs)
        last = [None]

        def seen(_msg):
            last[0] = time.monotonic()

        def check():
            if not active[0] and last[0] is not None and \
                    time.monotonic() - last[0] > takeover:
                active[0] = True
                say('standby: taking over (no command for %.3f s)'
                    % (time.monotonic() - last[0]))
        create_subscription(self, Float64MultiArray, 'effort_controller/commands', seen,
                            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.create_timer(0.002, check)
        say('standby: ready, taking over after %g s without a command' % takeover)
    node_class.__init__ = standby_init
    return controller_node.main()


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
