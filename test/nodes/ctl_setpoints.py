"""
A stand-in planner for the node tests: streams the paper's circle as setpoints.

Lockstep (default): on every ``/clock`` message it publishes each not yet published tick
``t_k <= now + lookahead * dt`` (``CircleQuintic().sample_tuple(k * dt)``, stamp k * dt_ns),
as docs/GRAPH.md asks of the planner.  ``--realtime``: on a wall timer at 1/dt, stamps from
the system clock, the same lookahead.  ``--count N`` stops publishing after N ticks.
"""
import argparse

from freejoint_common.contract import CLOCK, profile, seconds_to_ns, SETPOINT, stamp_from_ns
from freejoint_common.contract import to_ns
from freejoint_core.trajectory import CircleQuintic
import rclpy
from rclpy.executors import ExternalShutdownException

QOS = profile(100, latched=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--dt', type=float, default=0.001)
    ap.add_argument('--lookahead', type=int, default=20)
    ap.add_argument('--realtime', action='store_true')
    ap.add_argument('--count', type=int, default=-1)
    args, rest = ap.parse_known_args()
    rclpy.init(args=rest)
    node = rclpy.create_node('ctl_setpoints')
    pub = node.create_publisher(SETPOINT.msg_type, SETPOINT.name, QOS)
    traj = CircleQuintic()
    dt_ns = seconds_to_ns(args.dt)
    state = {'next': 0, 'start': None}
    msg = SETPOINT.msg_type()
    msg.plan_id = 1

    def publish_up_to(now_ns, offset_ns=0):
        while state['next'] * dt_ns <= now_ns + args.lookahead * dt_ns:
            k = state['next']
            if 0 <= args.count <= k:
                return
            px, py, vx, vy, ax, ay = traj.sample_tuple(k * args.dt)
            stamp_ns = offset_ns + k * dt_ns
            stamp_from_ns(stamp_ns, msg.header.stamp)
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
        node.create_subscription(CLOCK.msg_type, CLOCK.name,
                                 lambda m: publish_up_to(to_ns(m.clock)),
                                 profile(10, reliable=False))
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
