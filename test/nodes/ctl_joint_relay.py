"""
A stand-in for a real driver's joint_state_broadcaster, for the graph tests.

Republishes every ``joint_states`` message on ``driver/joint_states`` with the joints in
another order and two extra joints (a gripper and a wrist that the arm model does not
have), as a real robot's driver may publish them.
"""
from freejoint_common.contract import JOINT_STATES, profile
import rclpy
from sensor_msgs.msg import JointState
from standin import spin

QOS = profile(100)
ORDER = ('gripper', 'joint3', 'joint1', 'wrist', 'joint2')


def main():
    rclpy.init()
    node = rclpy.create_node('ctl_joint_relay')
    pub = node.create_publisher(JointState, 'driver/joint_states', QOS)

    def relay(msg):
        names = list(msg.name)
        out = JointState()
        out.header = msg.header
        out.name = list(ORDER)
        for field in ('position', 'velocity', 'effort'):
            values = getattr(msg, field)
            setattr(out, field, [float(values[names.index(n)]) if n in names else 0.25
                                 for n in ORDER])
        pub.publish(out)

    node.create_subscription(JOINT_STATES.msg_type, JOINT_STATES.name, relay, QOS)
    node.get_logger().info('relay ready')
    spin(node)


if __name__ == '__main__':
    main()
