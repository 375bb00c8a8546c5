"""own_clock: one /clock delivery for a node that subscribes /clock itself (public API)."""
from freejoint_common.clock import own_clock, set_ros_time
import pytest
import rclpy
from rclpy.clock import ClockType
from rclpy.parameter import Parameter
from rclpy.time_source import TimeSource


@pytest.fixture
def sim_time_node():
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('clock_probe', context=context, parameter_overrides=[
        Parameter('use_sim_time', value=True)])
    yield node
    node.destroy_node()
    rclpy.shutdown(context=context)


def time_source_subscriptions(node):
    return [s for s in node.subscriptions
            if isinstance(getattr(s.callback, '__self__', None), TimeSource)]


def test_the_time_source_subscription_is_gone_and_stays_gone_across_use_sim_time(
        sim_time_node):
    node = sim_time_node
    assert len(time_source_subscriptions(node)) == 1     # rclpy's own /clock subscription
    own_clock(node)
    assert time_source_subscriptions(node) == []
    node.set_parameters([Parameter('use_sim_time', value=False)])
    node.set_parameters([Parameter('use_sim_time', value=True)])
    assert time_source_subscriptions(node) == []
    assert node.get_clock().ros_time_is_active          # the switch still works


def test_the_node_sets_its_ros_clock_itself(sim_time_node):
    node = sim_time_node
    own_clock(node)
    set_ros_time(node, 1_500_000_000)
    now = node.get_clock().now()
    assert now.nanoseconds == 1_500_000_000 and now.clock_type == ClockType.ROS_TIME
