"""
The simulator, controller and planner nodes in one process, spun by one executor.

What a component container does for rclcpp nodes, for the graph's rclpy nodes: the same
node classes, names, parameters, topics and services as ``sim_node``, ``controller_node``
and ``planner_node`` started one by one (docs/GRAPH.md holds for both), but the messages
between them take Fast DDS's intra-process path in the publishing thread: no
shared-memory hand-over and no wake-up of another process per message (the figures:
docs/performance.md). Nodes of other processes (recorder, RViz, a second controller)
see the same graph.

Usage (``ros2 run freejoint_bringup graph``): ``graph --sim-params config/sim.yaml
--controller-params config/controller.yaml --planner-params config/planner.yaml
[--sim case=vertical ...] [--controller case=vertical ...] [--planner case=vertical ...]
[--nodes sim controller planner] [--ros-args ...]``.

Each node gets its own parameter file and ``NAME=VALUE`` overrides (``-p NAME:=VALUE`` of
that node; outside ``--ros-args`` rcl would take ``NAME:=VALUE`` for a remapping): the files
of ``config/`` apply to any node name, so they cannot be given globally. Arguments after
``--ros-args`` apply to every node (remappings, log levels). SIGINT/SIGTERM stop the process
between callbacks; each node then logs its end-of-run line as it does alone.
"""

import argparse
import signal
import sys

NODES = ('sim', 'controller', 'planner')


def node_classes():
    """Return {name: node class} of the graph's nodes (imported on demand)."""
    from freejoint_control.controller_node import ControllerNode
    from freejoint_planner.planner_node import PlannerNode
    from freejoint_sim.sim_node import SimNode
    return {'sim': SimNode, 'controller': ControllerNode, 'planner': PlannerNode}


def node_args(params_file, overrides):
    """Return the node-specific ``cli_args``: its parameter file and ``-p`` overrides."""
    args = ['--ros-args']
    if params_file:
        args += ['--params-file', params_file]
    for item in overrides or ():
        name, sep, value = item.partition('=')
        if not sep or not name:
            raise SystemExit('graph: %r is not NAME=VALUE' % item)
        args += ['-p', '%s:=%s' % (name, value)]
    return args


def parse(argv):
    """Parse the non-ROS arguments."""
    ap = argparse.ArgumentParser(prog='graph', description=__doc__.strip().splitlines()[0])
    ap.add_argument('--nodes', nargs='+', choices=NODES, default=list(NODES),
                    help='nodes to host (default: all three)')
    for name in NODES:
        ap.add_argument('--%s-params' % name, metavar='FILE', default='',
                        help='parameter file of the %s node' % name)
        ap.add_argument('--%s' % name, nargs='+', action='extend', default=[],
                        metavar='NAME=VALUE', help='parameter overrides of the %s node' % name)
    return ap.parse_args(argv)


def spin(nodes):
    """Spin every node with one EventsExecutor until SIGINT/SIGTERM (flag, spin_once)."""
    import rclpy
    from freejoint_common.node_tools import spin_until
    from rclpy.experimental import EventsExecutor
    stop = []

    def on_signal(signum, frame):
        stop.append(signum)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    executor = EventsExecutor()
    for node in nodes.values():
        executor.add_node(node)
    spin_until(executor.spin_once, rclpy.ok, stop)


def finish(name, node):
    """Log the node's end-of-run line (and write the simulator's timing file)."""
    if hasattr(node, 'stop_stepping'):
        node.stop_stepping()
    if hasattr(node, 'report'):
        node.get_logger().info(node.report())
    if hasattr(node, 'write_timing'):
        node.write_timing()


def main(args=None):
    """Run the hosted nodes until SIGINT/SIGTERM."""
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions
    from rclpy.utilities import remove_ros_args
    from freejoint_common.node_tools import parameter_error
    from freejoint_core.errors import FreejointValueError
    argv = sys.argv if args is None else args
    options = parse(remove_ros_args(argv)[1:])
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    nodes = {}
    code = 0
    try:
        classes = node_classes()
        for name in NODES:
            if name in options.nodes:
                nodes[name] = classes[name](cli_args=node_args(
                    getattr(options, '%s_params' % name), getattr(options, name)))
        spin(nodes)
    except (FreejointValueError, ParameterException) as exc:  # as every node alone
        rclpy.logging.get_logger('graph').fatal('bad parameter: %s' % parameter_error(exc))
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        from freejoint_common.node_tools import GC_PAUSES
        for name, node in nodes.items():
            finish(name, node)
        if nodes:
            next(iter(nodes.values())).get_logger().info(GC_PAUSES.report())
        for node in nodes.values():
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
