"""
The simulator, controller and planner nodes in one process, spun by one executor.

What a component container does for rclcpp nodes, for the graph's rclpy nodes: the same
node classes, names, parameters, topics and services as ``sim_node``, ``controller_node``
and ``planner_node`` started one by one (docs/GRAPH.md holds for both), but the messages
between them take Fast DDS's intra-process path in the publishing thread: no
shared-memory hand-over and no wake-up of another process per message (the figures:
docs/performance.md). Nodes of other processes (recorder, RViz, a second controller)
see the same graph. Each node is a ``freejoint_common.runner.Lifecycle``: the runner adds
them to one EventsExecutor, as ros2/examples' ``composed.py`` does.

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


def main(args=None):
    """Run the hosted nodes in one executor until SIGINT/SIGTERM (``runner.run``)."""
    from freejoint_common.runner import run
    from rclpy.utilities import remove_ros_args
    argv = sys.argv if args is None else args
    options = parse(remove_ros_args(argv)[1:])

    def make():     # a generator: the nodes made before a failure are shut down too
        classes = node_classes()
        for name in NODES:
            if name in options.nodes:
                yield classes[name](cli_args=node_args(
                    getattr(options, '%s_params' % name), getattr(options, name)))

    return run(make, 'graph', argv, executor_kind='events')


if __name__ == '__main__':
    sys.exit(main())
