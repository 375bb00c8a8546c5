"""Process scheduling (thread_priority / cpu_affinity): validation, every thread, refusal."""

import json
import os
import subprocess
import sys
import textwrap

from freejoint_common.scheduling import validate_affinity, validate_priority
from freejoint_core.errors import FreejointValueError
import pytest

CPUS = sorted(os.sched_getaffinity(0))

DROP_SYS_NICE = 'import ctypes; ctypes.CDLL(None).prctl(24, 23, 0, 0, 0)\n'
"""Python that drops CAP_SYS_NICE from the bounding set (PR_CAPBSET_DROP); on exec a root
process then lacks it too."""

PROBE = textwrap.dedent("""
    import json, os, threading, time
    from freejoint_common.scheduling import ProcessScheduling

    def threads():
        out = {}
        for tid in map(int, os.listdir('/proc/self/task')):
            out[tid] = [os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority,
                        sorted(os.sched_getaffinity(tid))]
        return list(out.values())

    stop = threading.Event()
    workers = [threading.Thread(target=stop.wait) for _ in range(2)]
    for w in workers:
        w.start()
    sched = ProcessScheduling()
    steps = {}
    for label, owner, prio, cpus in STEPS:
        if label == 'new thread':
            late = threading.Thread(target=stop.wait)
            late.start()
            workers.append(late)
            steps[label] = [sched.refresh(), threads(), sched.describe()]
            continue
        reason = sched.request(owner, prio, cpus)
        steps[label] = [reason, threads(), sched.describe()]
    stop.set()
    print(json.dumps(steps))
""")


def _probe(steps, drop_sys_nice=False):
    code = (DROP_SYS_NICE if drop_sys_nice else '') + 'STEPS = %r\n' % (steps,) + PROBE
    if drop_sys_nice:
        # prctl applies to this process: exec a fresh interpreter that runs the probe.
        code = (DROP_SYS_NICE + 'import os, sys\n'
                'os.execv(sys.executable, [sys.executable, "-c", %r])\n'
                % ('STEPS = %r\n' % (steps,) + PROBE))
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def _fifo_permitted():
    """Return True if this machine lets this user's processes use SCHED_FIFO."""
    out = subprocess.run([sys.executable, '-c', 'import os; os.sched_setscheduler('
                          '0, os.SCHED_FIFO, os.sched_param(1))'], capture_output=True,
                         timeout=30)
    return out.returncode == 0


@pytest.mark.parametrize('value', [-1, 99, 1.5, True, '10'])
def test_a_bad_thread_priority_is_refused_naming_it(value):
    with pytest.raises(FreejointValueError, match=r'^thread_priority: expected'):
        validate_priority(value)


def test_thread_priority_accepts_0_for_the_default_scheduler_up_to_98():
    assert [validate_priority(v) for v in (0, 1, 50, 98)] == [0, 1, 50, 98]


def test_cpu_affinity_is_checked_against_the_processs_cpus():
    assert validate_affinity(None, [0, 1]) == ()
    assert validate_affinity([], [0, 1]) == ()
    assert validate_affinity([1, 0], [0, 1]) == (0, 1)
    with pytest.raises(FreejointValueError,
                       match=r'^cpu_affinity: CPU 5 is not available to this process'):
        validate_affinity([5], [0, 1])
    with pytest.raises(FreejointValueError, match=r'^cpu_affinity: CPU 1 named twice'):
        validate_affinity([1, 1], [0, 1])
    with pytest.raises(FreejointValueError, match=r'^cpu_affinity: expected CPU numbers'):
        validate_affinity(['1'], [0, 1])
    with pytest.raises(FreejointValueError, match=r'^cpu_affinity: expected CPU numbers'):
        validate_affinity([True], [0, 1])


def test_fifo_and_affinity_reach_every_thread_and_the_highest_request_wins():
    if not _fifo_permitted():
        # Without the privilege the request must be refused with the reason (below).
        return test_without_the_privilege_fifo_is_refused_with_the_reason_and_nothing_changes()
    last = CPUS[-1]
    steps = _probe([('a', 'sim', 10, [last]), ('new thread', None, None, None),
                    ('b', 'controller', 20, [CPUS[0]]), ('b off', 'controller', 0, None),
                    ('a off', 'sim', 0, None)])
    reason, threads, text = steps['a']
    assert reason is None and text == 'SCHED_FIFO 10 on CPUs [%d]' % last
    assert len(threads) >= 3
    assert all(t == [os.SCHED_FIFO, 10, [last]] for t in threads), threads
    reason, threads, _ = steps['new thread']
    assert reason is None and len(threads) >= 4
    assert all(t == [os.SCHED_FIFO, 10, [last]] for t in threads), threads
    reason, threads, _ = steps['b']
    assert reason is None
    assert all(t == [os.SCHED_FIFO, 20, sorted({CPUS[0], last})] for t in threads), threads
    # 'controller' back to every CPU at the default scheduler: 'sim' still asks for FIFO 10.
    reason, threads, _ = steps['b off']
    assert all(t == [os.SCHED_FIFO, 10, CPUS] for t in threads), threads
    reason, threads, text = steps['a off']
    assert reason is None and text == 'default scheduler on CPUs %s' % CPUS
    assert all(t == [os.SCHED_OTHER, 0, CPUS] for t in threads), threads


def test_without_the_privilege_fifo_is_refused_with_the_reason_and_nothing_changes():
    steps = _probe([('a', 'sim', 10, [CPUS[-1]]), ('b', 'sim', 0, [CPUS[-1]])],
                   drop_sys_nice=True)
    reason, threads, text = steps['a']
    assert reason.startswith('SCHED_FIFO priority 10 not permitted for this process (needs '
                             'root, CAP_SYS_NICE or an rtprio limit >= 10: ulimit -r is ')
    assert text == 'default scheduler on CPUs %s' % CPUS
    assert all(t == [os.SCHED_OTHER, 0, CPUS] for t in threads), threads
    # An affinity alone needs no privilege.
    reason, threads, text = steps['b']
    assert reason is None and text == 'default scheduler on CPUs [%d]' % CPUS[-1]
    assert all(t == [os.SCHED_OTHER, 0, [CPUS[-1]]] for t in threads), threads


def test_a_limited_real_time_budget_gets_a_note_with_the_longest_stall():
    from freejoint_common.scheduling import rt_budget_note
    # The kernel's default: 950000 of every 1000000 us -> a stall of up to 50 ms.
    note = rt_budget_note((950000, 1000000))
    assert note.startswith('the kernel throttles SCHED_FIFO threads after 950000 of every '
                           '1000000 us on a CPU (kernel.sched_rt_runtime_us)')
    assert 'stalls up to 50 ms' in note and 'kernel.sched_rt_runtime_us=-1' in note
    assert 'stalls up to 200 ms' in rt_budget_note((800000, 1000000))
    # No budget (-1), a budget of the whole period, or nothing readable: no note.
    assert rt_budget_note((-1, 1000000)) is None
    assert rt_budget_note((1000000, 1000000)) is None
    assert rt_budget_note(None) is None


def test_the_real_time_budget_is_read_from_the_kernel():
    from freejoint_common.scheduling import rt_budget
    with open('/proc/sys/kernel/sched_rt_runtime_us') as f:
        runtime = int(f.read())
    with open('/proc/sys/kernel/sched_rt_period_us') as f:
        period = int(f.read())
    assert rt_budget() == (runtime, period)
