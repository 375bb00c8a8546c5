"""
A link that starves the controller, for the graph tests: joint_states passed on, then not.

Republishes ``joint_states`` on ``driver/joint_states`` (the controller's input, remapped)
as they come until ``--pass`` s (wall time) after the controller first said it is ready
(``controller_readiness``), then drops every state of ``--gap`` s out of every
``--period`` s for ``--starve`` s (stalls of the link, as a stalled controller sees them:
bursts of missed states), then passes them on again. Says in its log when each phase
begins.
"""
import argparse
import time

from freejoint_common.contract import CONTROLLER_READINESS, JOINT_STATES, profile
import rclpy
from standin import spin

QOS = profile(100)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--pass', dest='passing', type=float, default=1.0)
    ap.add_argument('--starve', type=float, default=3.0)
    ap.add_argument('--gap', type=float, default=0.12)
    ap.add_argument('--period', type=float, default=0.4)
    args = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node('starving_relay')
    pub = node.create_publisher(JOINT_STATES.msg_type, 'driver/joint_states', QOS)
    start = [None]
    said = set()

    def say(phase):
        if phase not in said:
            said.add(phase)
            node.get_logger().info('relay: %s' % phase)

    def on_readiness(msg):
        if msg.ready and start[0] is None:
            start[0] = time.monotonic()
            say('the controller is ready')

    def relay(msg):
        if start[0] is None:
            pub.publish(msg)
            return
        t = time.monotonic() - start[0] - args.passing
        if 0.0 <= t < args.starve:
            say('starving')
            if t % args.period < args.gap:
                return
        elif t >= args.starve:
            say('passing again')
        pub.publish(msg)

    node.create_subscription(JOINT_STATES.msg_type, JOINT_STATES.name, relay, QOS)
    node.create_subscription(CONTROLLER_READINESS.msg_type, CONTROLLER_READINESS.name,
                             on_readiness, CONTROLLER_READINESS.qos)
    node.get_logger().info('relay ready')
    spin(node)


if __name__ == '__main__':
    main()
