"""
A bare rclpy echo node: JointState in, Float64MultiArray out (the bench's baseline).

What any rclpy node answering the simulator's state with a command costs at least: it
subscribes to ``joint_states`` and publishes on ``effort_controller/commands`` with the
graph contract's types and QoS (``freejoint_common.contract``), and answers each state
with the positions of the first two joints, nothing else (no parameters beyond rclpy's,
no diagnostics, no law). A ``SingleThreadedExecutor`` drives it by ``spin_once``, as the
project's runner does, until SIGINT / SIGTERM.

Usage: ``python bench/echo_node.py`` (under ``. tools/env.sh``); ``bench/echo.py`` runs it.
"""

import signal
import sys

from freejoint_common.contract import COMMANDS, JOINT_STATES
import rclpy
from rclpy.executors import SingleThreadedExecutor

NODE_NAME = 'echo_node'


def main():
    """Echo states as commands until SIGINT / SIGTERM."""
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(True))
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node(NODE_NAME)
    pub = node.create_publisher(COMMANDS.msg_type, COMMANDS.name, COMMANDS.qos)

    def echo(state):
        out = COMMANDS.msg_type()
        out.data = list(state.position[:2])
        pub.publish(out)

    node.create_subscription(JOINT_STATES.msg_type, JOINT_STATES.name, echo, JOINT_STATES.qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    while not stop:
        executor.spin_once(timeout_sec=0.1)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
