"""Shared fixtures: an isolated ROS 2 domain per test run, and managed node processes."""
import os
import threading
import time

from freejoint_tools.harness import claim_ros_domain, clean_stale_fast_dds_shm, Processes
import pytest


def _domain():
    """
    Return this test process's ROS domain: FREEJOINT_TEST_DOMAIN, else one of its own.

    Under pytest-xdist (``make test`` runs three workers per two cores) the workers of
    one run prefer consecutive domains (modulo 100) from a base drawn from the run's id;
    otherwise 1 + pid % 100 is preferred. The domain is claimed (harness.claim_ros_domain):
    if another process of this machine holds the one preferred - a worker of another run
    whose draw coincided, a demo - the next free one is taken, so runs never share one.
    """
    given = os.environ.get('FREEJOINT_TEST_DOMAIN')
    if given:
        return int(given)
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    run = os.environ.get('PYTEST_XDIST_TESTRUNUID', '')
    if worker.startswith('gw') and run:
        return claim_ros_domain(1 + (int(run[:8], 16) + int(worker[2:])) % 100)
    return claim_ros_domain(1 + os.getpid() % 100)


# Every run (every xdist worker) gets its own domain and sees only this machine, so runs (and
# CI) never mix. Set before anything imports rclpy.
os.environ['ROS_DOMAIN_ID'] = str(_domain())
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')


def pytest_sessionstart(session):
    """Start from a /dev/shm without Fast DDS files of dead processes."""
    clean_stale_fast_dds_shm()


def _live_participants():
    """Return how many Fast DDS participants this process has (one 'dds.ev' thread each)."""
    count = 0
    for tid in os.listdir('/proc/self/task'):
        try:
            with open('/proc/self/task/%s/comm' % tid) as f:
                count += f.read().startswith('dds.ev')
        except OSError:
            pass
    return count


def pytest_sessionfinish(session, exitstatus):
    """
    Say so when participants outlive the tests (an executor or context left running).

    Fast DDS destroys them in its exit handlers and can deadlock there: the run would hang
    after its summary instead of exiting.
    """
    import gc
    gc.collect()
    left = _live_participants()
    if left:
        reporter = session.config.pluginmanager.get_plugin('terminalreporter')
        if reporter is not None:
            reporter.write_line('%d Fast DDS participant(s) of this process still alive at '
                                'the end: a test left an executor or an rclpy context '
                                'running' % left, red=True)


@pytest.fixture
def procs(tmp_path):
    """Give the test the process harness; stop what still runs at its end (logs in tmp_path)."""
    p = Processes(str(tmp_path), stop_timeout=10.0)
    yield p
    p.stop_all()
    clean_stale_fast_dds_shm()      # what a killed node left must not break the next test


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


def _entry_point(pkg, exe):
    """Return the function the installed executable ``exe`` of ``pkg`` runs (its main)."""
    from importlib.metadata import distribution
    points = [point for point in distribution(pkg).entry_points
              if point.group == 'console_scripts' and point.name == exe]
    assert len(points) == 1, (pkg, exe, points)
    return points[0].load()


@pytest.fixture
def run_main(capfd, monkeypatch):
    """
    Give the test a call of an executable's main in the test process.

    ``run_main(pkg, exe, argv)`` calls the ``main`` of the installed executable ``exe``
    of ``pkg`` (its console_scripts entry point) with ``argv`` (``sys.argv[1:]``), as its
    process would: rclpy.init, the node's constructor and parameter checks, the runner's
    lines; it asserts that main destroyed every middleware participant it made. It returns
    (main's return: the process's exit status, what main wrote to this process's stdout
    and stderr, rcutils' log lines included). Bounded: a node that took
    the value would run on; rclpy shut down after 60 s ends the runner's loop, main then
    returns 0. The runner installs signal handlers: the test runs in the main thread
    (pytest-xdist's workers' too).
    """
    def run(pkg, exe, argv):
        import rclpy
        from freejoint_common import scheduling
        main = _entry_point(pkg, exe)
        # A node made before the failure (the graph's sim) asks for the process's
        # scheduling: a scheduling state of this test's own, not the test process's.
        monkeypatch.setattr(scheduling, '_PROCESS', [])
        capfd.readouterr()
        before = _live_participants()
        deadline = threading.Timer(60.0, rclpy.try_shutdown)
        deadline.start()
        try:
            code = main([exe, *argv])
        finally:
            deadline.cancel()
            deadline.join()
        captured = capfd.readouterr()
        # Its node destroyed with it, even one whose constructor raised: a participant left
        # to a later garbage collection is destroyed beside the next test's, and Fast DDS
        # can deadlock there (the worker then hangs, its timeout thread without the GIL).
        left = _live_participants() - before
        assert left <= 0, '%s left %d participant(s) alive after its main returned' % (
            exe, left)
        return code, captured.out + captured.err
    return run


def _bad_parameter_line(code, output, name):
    """
    Assert a start refused for parameter ``name``; return its one line.

    Exit status 2, no traceback, one line of failure (FATAL, ERROR or error) in
    ``output``, saying ``bad parameter: <name>: ``.
    """
    assert code == 2, 'exit %s, expected 2:\n%s' % (code, output)
    assert 'Traceback' not in output, output
    failures = [line for line in output.splitlines()
                if 'FATAL' in line or 'ERROR' in line or 'error' in line.lower()]
    assert len(failures) == 1, 'expected one line, got:\n%s' % output
    assert 'bad parameter: %s: ' % name in failures[0], failures[0]
    return failures[0]


@pytest.fixture
def bad_parameter_line():
    """Give the test the check of a start refused for one parameter: ``(code, output, name)``."""
    return _bad_parameter_line
