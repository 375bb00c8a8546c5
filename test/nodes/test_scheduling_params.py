"""
thread_priority / cpu_affinity of the simulator and the controller, in their processes.

Read back from ``/proc/<pid>/task``: every thread of the node's process (executor and
middleware threads) must carry the scheduling asked for, at start-up and after
``set_parameters`` (what ``ros2 param set`` calls); bad values are refused with their
reason, and a process without the privilege logs why and runs on.
"""
import os
import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
CPUS = sorted(os.sched_getaffinity(0))
LAST = CPUS[-1]
WITHOUT_SYS_NICE = [sys.executable, '-c',
                    'import ctypes, os, sys; ctypes.CDLL(None).prctl(24, 23, 0, 0, 0); '
                    'os.execv(sys.argv[1], sys.argv[1:])']
"""Run a command with CAP_SYS_NICE dropped from the bounding set (PR_CAPBSET_DROP)."""


def _fifo_permitted():
    out = subprocess.run([sys.executable, '-c', 'import os; os.sched_setscheduler('
                          '0, os.SCHED_FIFO, os.sched_param(1))'], capture_output=True,
                         timeout=30)
    return out.returncode == 0


def _threads(pid):
    """Return [(policy, priority, cpus)] of every thread ``thread_priority`` applies to."""
    from freejoint_tools.harness import thread_scheduling
    return thread_scheduling(pid)[0]


def _best_effort_threads(pid):
    """Return [(policy, priority, cpus)] of the threads kept at the default scheduler."""
    from freejoint_tools.harness import thread_scheduling
    return thread_scheduling(pid)[1]


def _explain_stall(exc, proc, procs):
    """
    Raise ``exc`` again with what the stalled node did: its threads, then its Python stacks.

    For a node pinned to one CPU at SCHED_FIFO that does not finish its start-up or answer
    its parameter services: the report says which thread held the CPU (and any other
    real-time thread busy meanwhile), and SIGABRT makes the node's faulthandler
    (PYTHONFAULTHANDLER) print where its Python threads were.
    """
    from freejoint_tools.harness import thread_report
    report = thread_report(proc.pid)
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGABRT)
        try:
            proc.wait(10.0)
        except subprocess.TimeoutExpired:
            pass
    raise AssertionError('%s\n%s\nits log:\n%s' % (exc, report, procs.log(proc))) from exc


def _node_cmd(pkg, exe, config, *extra):
    return [os.path.join(ROOT, 'install', pkg, 'lib', pkg, exe), '--ros-args',
            '--params-file', os.path.join(CONFIG, config), *extra]


@pytest.mark.parametrize('pkg, exe, config, name, ready', [
    ('freejoint_control', 'controller_node', 'controller.yaml', 'controller_node',
     'controller ready'),
    ('freejoint_sim', 'sim_node', 'sim.yaml', 'sim_node', 'simulator ready')])
def test_every_thread_gets_the_priority_and_cpus_and_set_parameters_changes_them(
        procs, ros_node, wait, pkg, exe, config, name, ready):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    # Without the privilege (not root, no CAP_SYS_NICE / rtprio) only the affinity part is
    # checked here; the refusal itself is the next test's.
    prio = 10 if _fifo_permitted() else 0
    policy = os.SCHED_FIFO if prio else os.SCHED_OTHER
    proc = procs.start(name, _node_cmd(pkg, exe, config, '-p', 'thread_priority:=%d' % prio,
                                       '-p', 'cpu_affinity:=[%d]' % LAST),
                       env={'PYTHONFAULTHANDLER': '1'})   # SIGABRT: its Python stacks
    text = 'SCHED_FIFO 10' if prio else 'default scheduler'
    wait(lambda: 'process scheduling: %s on CPUs [%d]' % (text, LAST) in procs.log(proc),
         30.0, 'the node to report its scheduling')
    if prio:
        # At SCHED_FIFO the node says whether the kernel's real-time budget can throttle it.
        from freejoint_common.scheduling import rt_budget, rt_budget_note
        note = rt_budget_note(rt_budget())
        if note is not None:
            # Logged just after the scheduling line: waited for (bounded), not read at once.
            wait(lambda: note in procs.log(proc), 10.0, 'the real-time budget note')
        else:
            assert 'the kernel throttles SCHED_FIFO threads' not in procs.log(proc)
    wait(lambda: len(_threads(proc.pid)) >= 3
         and all(t == (policy, prio, [LAST]) for t in _threads(proc.pid)), 10.0,
         'every thread at %s on CPU %d: %s' % (text, LAST, _threads(proc.pid)))
    params = ParameterCalls(ros_node, name)
    try:
        wait(lambda: ready in procs.log(proc), 30.0, 'the node to be ready')
        res = params.set_parameters([Parameter('thread_priority', value=99),
                                     Parameter('cpu_affinity', value=[LAST + 64])])
    except (AssertionError, TimeoutError) as exc:
        _explain_stall(exc, proc, procs)
    assert [r.successful for r in res] == [False, False]
    # The descriptor's integer range refuses it before the node's own check.
    assert 'thread_priority' in res[0].reason and '98' in res[0].reason, res[0].reason
    assert res[1].reason.startswith('cpu_affinity: CPU %d is not available' % (LAST + 64))
    assert all(t == (policy, prio, [LAST]) for t in _threads(proc.pid))
    # The middleware's asynchronous writer (it can busy-wait): on the CPUs, not at FIFO.
    assert all(t == (os.SCHED_OTHER, 0, [LAST]) for t in _best_effort_threads(proc.pid))
    res = params.set_parameters([Parameter('thread_priority', value=0),
                                 Parameter('cpu_affinity', value=CPUS)])
    assert [r.successful for r in res] == [True, True], [r.reason for r in res]
    assert all(t == (os.SCHED_OTHER, 0, CPUS) for t in _threads(proc.pid)), _threads(proc.pid)
    assert proc.poll() is None
    assert procs.stop(proc) == 0


def test_without_the_privilege_the_node_says_why_and_runs_on(procs, ros_node, wait):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    proc = procs.start('controller_node', WITHOUT_SYS_NICE + _node_cmd(
        'freejoint_control', 'controller_node', 'controller.yaml',
        '-p', 'thread_priority:=10'))
    wait(lambda: 'controller ready' in procs.log(proc), 30.0, 'the controller to start')
    log = procs.log(proc)
    assert ('thread_priority 10 not applied: SCHED_FIFO priority 10 not permitted for this '
            'process (needs root, CAP_SYS_NICE or an rtprio limit >= 10: ulimit -r is ') in log
    assert 'running with thread_priority 0 (default scheduler on CPUs %s)' % CPUS in log
    assert all(t[:2] == (os.SCHED_OTHER, 0) for t in _threads(proc.pid))
    params = ParameterCalls(ros_node, 'controller_node')
    got = params.get_parameters(['thread_priority'])
    assert got[0].integer_value == 0
    res = params.set_parameters([Parameter('thread_priority', value=20)])
    assert not res[0].successful
    assert res[0].reason.startswith('SCHED_FIFO priority 20 not permitted')
    # Parameters that need no privilege still go through, and the node answers.
    res = params.set_parameters([Parameter('cpu_affinity', value=[LAST]),
                                 Parameter('epsilon', value=0.2)])
    assert [r.successful for r in res] == [True, True], [r.reason for r in res]
    assert all(t == (os.SCHED_OTHER, 0, [LAST]) for t in _threads(proc.pid))
    assert procs.stop(proc) == 0
