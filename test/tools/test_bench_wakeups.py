"""bench/graph.py's wake-up count: the voluntary context switches of a process's threads."""
import os
import subprocess
import sys
import time

from freejoint_tools.harness import load_source

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
graph_bench = load_source(os.path.join(ROOT, 'bench', 'graph.py'), 'graph_bench_wakeups')


def test_each_sleep_of_a_thread_counts_as_a_wake_up_of_its_process():
    before = graph_bench.proc_wakeups(os.getpid())
    for _ in range(40):
        time.sleep(1e-4)
    assert graph_bench.proc_wakeups(os.getpid()) - before >= 40


def test_a_process_that_is_gone_has_no_wake_ups():
    child = subprocess.Popen([sys.executable, '-c', 'pass'])
    assert child.wait(timeout=60) == 0
    assert graph_bench.proc_wakeups(child.pid) == 0
