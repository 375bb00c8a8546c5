"""
Benchmark: the viewer's cost to the lockstep graph while no Foxglove client is connected.

The lockstep 5-s horizontal case with the recorder, a process per node (as ``make demo``,
``graph.lockstep``), alternately without and with ``viewer`` running in the same ROS
domain (``make demo VIEW=1``), ``FREEJOINT_BENCH_VIEWER_RUNS`` (default 3) runs of each.
Figures: the median real-time factor of each, their ratio, and the CPU time the viewer
process took during the runs with it (per tick). Benchmarks assert nothing.

Usage: ``. tools/env.sh && python bench/viewer.py``. Logs stay in ``bags/bench/viewer/``.
"""

import os
import statistics
import sys
import time

from freejoint_tools.harness import Processes
import graph

RUNS = int(os.environ.get('FREEJOINT_BENCH_VIEWER_RUNS', '3'))
OUT = os.path.join(graph.ROOT, 'bags', 'bench', 'viewer')
RTF = 'lockstep 1 kHz + recorder: real-time factor'


def _start_viewer(env, index):
    """Start the viewer (its log viewer_<index>.log); return its harness once it is ready."""
    viewer = Processes(OUT, env=env, cwd=graph.ROOT)
    proc = viewer.start('viewer', [graph.executable('freejoint_tools', 'viewer'),
                                   '--ros-args', '-p', 'port:=0'],
                        log_name='viewer_%d' % index)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and proc.poll() is None:
        if 'viewer ready' in viewer.log(proc):
            return viewer
        time.sleep(0.1)
    viewer.stop_all()
    raise RuntimeError('the viewer did not start (log %s)' % proc.log_path)


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    factors = {False: [], True: []}
    viewer_cpu = []
    for i in range(2 * RUNS):
        with_viewer = bool(i % 2)
        env = graph._env(i % 8)
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']
        client = graph.Client()
        viewer = None
        try:
            if with_viewer:
                viewer = _start_viewer(env, i)
                cpu0 = graph.proc_cpu_seconds(viewer.procs['viewer'].pid)
            rows = graph.lockstep(client, env, 'separate')
            if with_viewer:
                viewer_cpu.append(graph.proc_cpu_seconds(viewer.procs['viewer'].pid) - cpu0)
        finally:
            if viewer is not None:
                viewer.stop_all()
            client.close()
        factor = next(r['value'] for r in rows if r['name'] == RTF)
        factors[with_viewer].append(factor)
        graph.say('viewer bench: run %d, viewer %s: %.2fx real time'
                  % (i, 'running (no client)' if with_viewer else 'off', factor))
    off, on = statistics.median(factors[False]), statistics.median(factors[True])
    ticks = graph.LOCKSTEP_TICKS
    return [
        {'name': 'lockstep + recorder, no viewer: real-time factor (median of %d)' % RUNS,
         'value': off, 'unit': 'x', 'target': None},
        {'name': 'same, viewer running, no client: real-time factor (median)',
         'value': on, 'unit': 'x', 'target': None},
        {'name': 'viewer running, no client / no viewer: real-time factor ratio',
         'value': on / off, 'unit': '', 'target': '>= 0.95'},
        {'name': 'viewer CPU per tick while no client is connected',
         'value': 1e6 * statistics.median(viewer_cpu) / ticks, 'unit': 'us', 'target': None},
    ]


def main():
    """Print the rows."""
    for row in run():
        target = row['target'] or ''
        print('%-62s %10.4g %-4s %s' % (row['name'], row['value'], row['unit'], target))
    return 0


if __name__ == '__main__':
    sys.exit(main())
