"""
A stand-in planner for the node tests: streams the paper's circle as setpoints.

Lockstep (default): on every ``/clock`` message it publishes each not yet published tick
``t_k <= now + lookahead * dt`` (``CircleQuintic().sample_tuple(k * dt)``, stamp k * dt_ns),
as docs/GRAPH.md asks of the planner.  ``--realtime``: on a wall timer at 1/dt, stamps from
the system clock, the same lookahead.  ``--count N`` stops publishing after N ticks.
"""
import argparse

from freejoint_core.trajectory import CircleQuintic
from freejoint_msgs.msg import CartesianSetpoint
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                 reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--dt', type=float, default=0.001)
    ap.add_argument('--lookahead', type=int, default=20)
    ap.add_argument('--realtime', action='store_true')
    ap.add_argument('--count', type=int, default=-1)
    args, rest = ap.parse_known_args()
    rclpy.init(args=rest)
    node = rclpy.create_node('ctl_setpoints')
    pub = node.create_publisher(CartesianSetpoint, 'setpoint', QOS)
    traj = CircleQuintic()
    dt_ns = round(args.dt * 1e9)
    state = {'next': 0, 'start': None}
    msg = CartesianSetpoint()
    msg.plan_id = 1

    def publish_up_to(now_ns, offset_ns=0):
        while state['next'] * dt_ns <= now_ns + args.lookahead * dt_ns:
            k = state['next']
            if 0 <= args.count <= k:
                return
            px, py, vx, vy, ax, ay = traj.sample_tuple(k * args.dt)
            stamp_ns = offset_ns + k * dt_ns
            msg.header.stamp.sec = stamp_ns // 1_000_000_000
            msg.header.stamp.nanosec = stamp_ns % 1_000_000_000
            msg.position = [px, py]
            msg.velocity = [vx, vy]
            msg.acceleration = [ax, ay]
            msg.plan_time = k * args.dt
            msg.final = k * args.dt > traj.duration
            pub.publish(msg)
            state['next'] = k + 1

    if args.realtime:
        def tick():
            now = node.get_clock().now().nanoseconds
            if state['start'] is None:
                state['start'] = now
            publish_up_to(now - state['start'], state['start'])
        node.create_timer(args.dt, tick)
    else:
        node.create_subscription(
            Clock, '/clock',
            lambda m: publish_up_to(m.clock.sec * 1_000_000_000 + m.clock.nanosec),
            QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    node.get_logger().info('streaming setpoints')
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
