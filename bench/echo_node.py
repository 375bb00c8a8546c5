"""
A bare rclpy echo node: JointState in, Float64MultiArray out (the bench's baseline).

What any rclpy node answering the simulator's state with a command costs at least: it
subscribes to ``joint_states`` and publishes on ``effort_controller/commands`` with the
graph contract's types and QoS (``freejoint_common.contract``), and answers each state with
minus the velocities of the first two joints (a damper: harmless to a simulated arm),
labelled with the state's stamp as a lockstep simulator requires (``stamp_label``), nothing
else (no parameters beyond rclpy's, no diagnostics, no law). The executor is the one named
by the argument (``events``: rclpy's ``EventsExecutor``, as ``config/controller.yaml`` runs
the controller; ``single_threaded``: ``SingleThreadedExecutor``), driven by ``spin_once``
as the project's runner drives every node, until SIGINT / SIGTERM.

``--out TOPIC``: its commands on TOPIC instead (``bench/echo.py`` runs it beside the
controller in the lockstep graph, where the simulator must not take them).
``--priority N``: its threads at SCHED_FIFO N as the controller's ``thread_priority: N``
puts the controller's (``freejoint_common.scheduling``, threads started later included:
the runner's ``spin_until``); refused (no permission): said on stderr, the default
scheduler kept, as the controller does.

Usage: ``python bench/echo_node.py [events | single_threaded] [--out TOPIC]
[--priority N]`` (under ``. tools/env.sh``); ``bench/echo.py`` runs it.
"""

import sys

from freejoint_common.contract import COMMANDS, JOINT_STATES, stamp_label, to_ns
from freejoint_common.runner import spin_until, StopFlag
from freejoint_common.scheduling import process_scheduling
import rclpy
from std_msgs.msg import MultiArrayDimension

NODE_NAME = 'echo_node'


def make_executor(kind):
    """Return the rclpy executor ``kind`` names ('events' or 'single_threaded')."""
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    if kind == 'single_threaded':
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor()
    raise SystemExit('echo_node: executor must be events or single_threaded, got %r' % kind)


def take_option(argv, name, default):
    """Remove ``name VALUE`` from ``argv``; return VALUE (``default`` if absent)."""
    if name not in argv:
        return default
    i = argv.index(name)
    value = argv[i + 1]
    del argv[i:i + 2]
    return value


def main(argv):
    """Echo states as commands until SIGINT / SIGTERM."""
    out_topic = take_option(argv, '--out', COMMANDS.name)
    priority = int(take_option(argv, '--priority', '0'))
    kind = argv[0] if argv else 'events'
    stop = StopFlag().install()
    rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    executor = make_executor(kind)      # after init: an executor takes the default context
    node = rclpy.create_node(NODE_NAME)
    pub = node.create_publisher(COMMANDS.msg_type, out_topic, COMMANDS.qos)

    def echo(state):
        out = COMMANDS.msg_type()
        out.layout.dim = [MultiArrayDimension(label=stamp_label(to_ns(state.header.stamp)),
                                              size=2, stride=2)]
        out.data = [-v for v in state.velocity[:2]]
        pub.publish(out)

    node.create_subscription(JOINT_STATES.msg_type, JOINT_STATES.name, echo, JOINT_STATES.qos)
    executor.add_node(node)
    if priority:
        refused = process_scheduling().request(NODE_NAME, priority, ())
        if refused is not None:
            print('echo_node: --priority %d not applied: %s' % (priority, refused),
                  file=sys.stderr, flush=True)
    spin_until(executor, rclpy.ok, stop)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
