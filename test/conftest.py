"""Shared fixtures: an isolated ROS 2 domain per test run, and managed node processes."""
import os
import signal
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INSTALL = os.path.join(ROOT, 'install')

# Every run gets its own domain and sees only this machine, so runs (and CI) never mix.
# Set before anything imports rclpy.
os.environ['ROS_DOMAIN_ID'] = str(os.environ.get('FREEJOINT_TEST_DOMAIN')
                                  or 1 + os.getpid() % 100)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')


def executable(pkg, exe):
    """Return the path `ros2 run <pkg> <exe>` starts: install/<pkg>/lib/<pkg>/<exe>."""
    return os.path.join(INSTALL, pkg, 'lib', pkg, exe)


class Procs:
    """Start node processes; stop them (SIGINT, then SIGKILL) when the test ends."""

    def __init__(self, log_dir):
        self.log_dir = log_dir
        self.running = []

    def start(self, cmd, name, env=None):
        """Start `cmd` (list) with output to <log_dir>/<name>.log; return the Popen."""
        log_path = os.path.join(self.log_dir, name + '.log')
        log = open(log_path, 'w')
        full_env = dict(os.environ)
        full_env.update(env or {})
        full_env['PYTHONUNBUFFERED'] = '1'
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=full_env,
                                start_new_session=True)
        proc.log_path = log_path
        proc.log_file = log
        self.running.append(proc)
        return proc

    def start_node(self, pkg, exe, name, args=()):
        """Start an installed node exactly as `ros2 run pkg exe args...` would."""
        return self.start([executable(pkg, exe), *args], name)

    def start_script(self, path, name, args=()):
        """Start a Python script of the tests with this interpreter."""
        return self.start([sys.executable, path, *args], name)

    @staticmethod
    def log(proc):
        """Return what the process printed so far."""
        if not proc.log_file.closed:
            proc.log_file.flush()
        with open(proc.log_path) as f:
            return f.read()

    def stop(self, proc, timeout=10.0):
        """SIGINT the process, wait up to `timeout` s, then SIGKILL; return its exit code."""
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5.0)
        proc.log_file.close()
        return proc.returncode

    def stop_all(self):
        for proc in reversed(self.running):
            if not proc.log_file.closed:
                self.stop(proc)


@pytest.fixture
def procs(tmp_path):
    """Give the test a process starter; stop its processes at its end (logs in tmp_path)."""
    p = Procs(str(tmp_path))
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
