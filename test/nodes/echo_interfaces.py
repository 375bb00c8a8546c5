"""
A second process for the interface tests: echoes every freejoint_msgs type back.

Each message received on `/probe/<Type>` is published again on `/probe/<Type>/echo`;
the `/probe/plan_circle` service answers PlanCircle requests (accepts radius < 1 m).
"""
from freejoint_msgs.msg import CartesianSetpoints, ControllerState
from freejoint_msgs.srv import PlanCircle
import rclpy
from standin import spin

TYPES = (CartesianSetpoints, ControllerState)


def main():
    rclpy.init()
    node = rclpy.create_node('freejoint_echo')
    for msg_type in TYPES:
        topic = '/probe/' + msg_type.__name__
        pub = node.create_publisher(msg_type, topic + '/echo', 10)
        node.create_subscription(msg_type, topic, pub.publish, 10)

    def plan(request, response):
        response.accepted = request.radius < 1.0
        response.reason = '' if response.accepted else 'radius %.3f m >= 1 m' % request.radius
        response.margin = 1.0 - request.radius
        response.plan_id = 7 if (response.accepted and request.execute) else 0
        return response

    node.create_service(PlanCircle, '/probe/plan_circle', plan)
    node.get_logger().info('echo ready')
    spin(node)


if __name__ == '__main__':
    main()
