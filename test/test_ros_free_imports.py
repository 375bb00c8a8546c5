"""
The parameter schemas and the arm description import in a Python without ROS.

The modules are imported in one fresh interpreter in which rclpy and every ROS message,
service and middleware package is refused (``sys.modules[name] = None`` for the named
ones, a finder refusing any ``*_msgs`` / ``*_srvs`` / ``*_interfaces`` / ``rosidl_*`` /
``rmw*`` package): an import that pulls any of them in, however indirectly, fails the test.
"""
import subprocess
import sys
import textwrap

ROS_FREE = (
    'freejoint_common.schema',
    'freejoint_common.setpoint',
    'freejoint_common.cdr',
    'freejoint_planner.stream',
    'freejoint_common.arm_description',
    'freejoint_control.params',
    'freejoint_sim.params',
    'freejoint_planner.params',
    'freejoint_control.loop',
    'freejoint_core.laws',
    'freejoint_core.guards',
    'freejoint_control.readiness',
    'freejoint_control.failures',
    'freejoint_core.internal',
    'freejoint_core.failure',
    'freejoint_core.spatial_law',
    'freejoint_core.spatial_plant',
    'freejoint_core.spatial_offline',
    'freejoint_core.spatial_map',
    'freejoint_planner.spatial_planning',
    'freejoint_tools.view_arm',
)
"""Modules that must import without rclpy (the nodes' schemas and what they build on)."""

BLOCKER = textwrap.dedent("""
    import importlib.abc
    import sys

    BLOCKED = ('rclpy', 'rpyutils', 'rcl_interfaces', 'builtin_interfaces', 'std_msgs',
               'sensor_msgs', 'freejoint_msgs', 'rosgraph_msgs', 'rosidl_runtime_py',
               'rosidl_parser', 'rosbag2_py', 'launch', 'launch_ros', 'ament_index_python')
    for name in BLOCKED:
        sys.modules[name] = None


    class RefuseRos(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            top = name.partition('.')[0]
            if (top.endswith(('_msgs', '_srvs', '_interfaces')) or top.startswith('rosidl')
                    or top.startswith('rmw') or top.startswith('rcl')):
                raise ImportError('ROS package %s imported' % name)
            return None


    sys.meta_path.insert(0, RefuseRos())
""")


def imports_without_ros(modules):
    """Import each of ``modules`` in one fresh Python that refuses ROS; return the failures."""
    code = BLOCKER + textwrap.dedent("""
        import traceback
        for module in %r:
            try:
                __import__(module)
            except ImportError as exc:
                print('%%s: %%s' %% (module, exc))
                traceback.print_exc(file=sys.stdout)
    """) % (list(modules),)
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    return run.stdout


def test_the_schemas_and_the_arm_description_import_in_a_python_without_rclpy_or_ros():
    failures = imports_without_ros(ROS_FREE)
    assert failures == ''


def test_a_module_that_imports_rclpy_fails_the_check():
    failures = imports_without_ros(['freejoint_common.node_tools'])
    assert failures.startswith('freejoint_common.node_tools: ')
    assert 'rcl' in failures.splitlines()[0]          # rclpy or rcl_interfaces refused
