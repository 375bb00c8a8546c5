"""
One /clock delivery for a node that subscribes /clock itself (public rclpy API only).

Every rclpy node has a ``TimeSource`` that, with ``use_sim_time``, subscribes /clock and
sets the node's ROS clock from it. A node whose own /clock subscription drives its work
(the planner's stream, the recorder's log times) would get each /clock twice: once for
the TimeSource, once for itself. :func:`own_clock` destroys the TimeSource's
subscription, found among ``node.subscriptions`` by its callback (a ``TimeSource``'s
bound ``clock_callback``), now and after every accepted ``use_sim_time`` change; the
TimeSource still switches the node's ROS clock between system and ROS time on
``use_sim_time``. The node then sets its ROS clock itself from its /clock callback with
:func:`set_ros_time` (``ROSClock.set_ros_time_override``).
"""

from rclpy.clock import ClockType
from rclpy.time import Time
from rclpy.time_source import TimeSource

USE_SIM_TIME = 'use_sim_time'


def drop_time_source_subscription(node):
    """Destroy the /clock subscription(s) of ``node``'s TimeSource; return how many."""
    dropped = 0
    for sub in list(node.subscriptions):
        if isinstance(getattr(sub.callback, '__self__', None), TimeSource):
            node.destroy_subscription(sub)
            dropped += 1
    return dropped


def own_clock(node):
    """
    Keep ``node``'s TimeSource off /clock from now on (``node`` sets its ROS clock itself).

    The TimeSource subscribes /clock again when ``use_sim_time`` turns true: a
    post-set-parameters callback destroys that subscription after each such change.
    """
    drop_time_source_subscription(node)

    def after_set(params):
        if any(p.name == USE_SIM_TIME for p in params):
            drop_time_source_subscription(node)

    node.add_post_set_parameters_callback(after_set)


def set_ros_time(node, ns):
    """Set ``node``'s ROS clock to ``ns`` (effective while ``use_sim_time`` is true)."""
    node.get_clock().set_ros_time_override(Time(nanoseconds=ns, clock_type=ClockType.ROS_TIME))
