"""Shared fixtures: an isolated ROS 2 domain per test run, and managed node processes."""
import os
import time

from freejoint_tools.harness import Processes
import pytest

# Every run gets its own domain and sees only this machine, so runs (and CI) never mix.
# Set before anything imports rclpy.
os.environ['ROS_DOMAIN_ID'] = str(os.environ.get('FREEJOINT_TEST_DOMAIN')
                                  or 1 + os.getpid() % 100)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')


@pytest.fixture
def procs(tmp_path):
    """Give the test the process harness; stop what still runs at its end (logs in tmp_path)."""
    p = Processes(str(tmp_path), stop_timeout=10.0)
    yield p
    p.stop_all()


def wait_for(predicate, timeout, what, spin=None, step=0.01):
    """Poll `predicate` (calling `spin()` between polls) until true or `timeout` s passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        if spin is not None:
            spin()
        else:
            time.sleep(step)
    raise AssertionError('timed out after %.1f s waiting for %s' % (timeout, what))


@pytest.fixture
def ros_node():
    """Give the test an rclpy node of its own (rclpy initialised for this test only)."""
    import rclpy
    rclpy.init()
    node = rclpy.create_node('freejoint_test_probe')
    yield node
    node.destroy_node()
    rclpy.try_shutdown()


@pytest.fixture
def wait():
    """Give the test `wait_for(predicate, timeout, what, spin=None)`."""
    return wait_for
