"""bench/wakeup_probe.py: the lateness of wake-ups, from synthetic times; one real probe."""
import json
import os
import subprocess
import sys

from freejoint_tools.harness import load_source
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PROBE = os.path.join(ROOT, 'bench', 'wakeup_probe.py')
probe = load_source(PROBE, 'wakeup_probe')


def test_a_wake_up_is_late_by_its_gap_less_the_period_and_listed_over_the_threshold():
    wakes = probe.LateWakeups(period=1e-3, threshold=10e-3, kept=2)
    # gaps 1.0, 1.5, 12.0, 1.0, 31.0, 11.5 ms after the previous wake-up
    before = 100.0
    for k, gap in enumerate((1.0, 1.5, 12.0, 1.0, 31.0, 11.5)):
        now = before + gap * 1e-3
        wakes.note(before, now, 1000.0 + k)
        before = now
    got = wakes.summary()
    assert got['wakeups'] == 6
    assert got['worst_ms'] == pytest.approx(30.0)
    assert got['late'] == 3                     # 11, 30 and 10.5 ms late
    assert [unix for unix, _ in got['listed']] == [1004.0, 1002.0]   # the latest two
    assert [ms for _, ms in got['listed']] == pytest.approx([30.0, 11.0])


def test_no_wake_up_is_no_lateness_and_bad_arguments_are_named():
    assert probe.LateWakeups().summary() == {'wakeups': 0, 'worst_ms': 0.0, 'late': 0,
                                             'listed': []}
    for kwargs, name in (({'period': 0.0}, 'period'), ({'threshold': -1.0}, 'threshold'),
                         ({'kept': -1}, 'kept')):
        with pytest.raises(ValueError, match=name):
            probe.LateWakeups(**kwargs)


def test_the_cpus_summaries_merge_into_the_worst_and_the_sums():
    a = {'cpu': 0, 'priority': 99, 'wakeups': 10, 'worst_ms': 3.0, 'late': 1,
         'listed': [[5.0, 12.0]]}
    b = {'cpu': 1, 'priority': 0, 'wakeups': 7, 'worst_ms': 40.0, 'late': 2,
         'listed': [[6.0, 40.0], [7.0, 11.0]]}
    assert probe.merge([a, b]) == {'cpus': [0, 1], 'priority': 0, 'wakeups': 17,
                                   'worst_ms': 40.0, 'late': 3,
                                   'listed': [[6.0, 40.0, 1], [5.0, 12.0, 0],
                                              [7.0, 11.0, 1]]}


def test_the_probe_runs_a_process_per_cpu_and_prints_its_summary(tmp_path):
    out = tmp_path / 'probe.json'
    done = subprocess.run([sys.executable, PROBE, '--seconds', '0.3', '--priority', '0',
                           '--out', str(out)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert got == json.loads(out.read_text())
    assert got['cpus'] == sorted(os.sched_getaffinity(0)) and got['priority'] == 0
    assert got['wakeups'] > 10 * len(got['cpus'])   # ~300 a CPU; a slow machine fewer


def test_a_probe_that_cannot_run_gives_no_figures_and_says_why():
    probes = probe.Probes(priority=0, cpus=[4095], seconds=0.1)    # no such CPU here
    for proc in probes.procs.started:
        proc.wait(30.0)
    assert probes.stop() is None
    assert probes.failure.startswith('cpu4095.json: exit 1, '), probes.failure
    assert 'OSError' in probes.failure and 'Invalid argument' in probes.failure, probes.failure
    assert not os.path.exists(probes.dir)
