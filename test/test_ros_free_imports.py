"""
The parameter schemas and the arm description import in a Python without ROS.

Each module is imported in a fresh interpreter in which rclpy and every ROS message,
service and middleware package is refused (``sys.modules[name] = None`` for the named
ones, a finder refusing any ``*_msgs`` / ``*_srvs`` / ``*_interfaces`` / ``rosidl_*`` /
``rmw*`` package): an import that pulls any of them in, however indirectly, fails the test.
"""
import subprocess
import sys
import textwrap

import pytest

ROS_FREE = (
    'freejoint_common.schema',
    'freejoint_common.arm_description',
    'freejoint_control.params',
    'freejoint_sim.params',
    'freejoint_planner.params',
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


def import_without_ros(module):
    """Import ``module`` in a fresh Python that refuses ROS; return (exit code, stderr)."""
    code = BLOCKER + '\nimport %s\n' % module
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    return run.returncode, run.stderr


@pytest.mark.parametrize('module', ROS_FREE)
def test_the_module_imports_in_a_python_without_rclpy_or_ros_messages(module):
    code, err = import_without_ros(module)
    assert code == 0, err


def test_a_module_that_imports_rclpy_fails_the_check():
    code, err = import_without_ros('freejoint_common.node_tools')
    assert code != 0
    assert 'rclpy' in err or 'rcl_interfaces' in err or 'ROS package' in err
