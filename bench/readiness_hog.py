"""
Real time at the default scheduler beside a CPU hog, no plan: the arm stays put.

Starts the simulator (``mode: realtime``) and the controller (``lockstep: false``), both at
the default scheduler (no thread_priority), with ``--hogs`` numpy matrix loops beside them
(each a process multiplying 400 x 400 matrices without end), sends no plan, and watches
``ee_position`` and ``/diagnostics`` for ``--duration`` s.  Prints one JSON line per run:
the largest end-effector excursion from its first sample [mm] and where in the guard's
transitions it happened (:func:`guard_phase`), whether the simulator diverged, the
controller's readiness trips and states not answered, its ERROR statuses, the simulator's
brake engagements (and of them those the controller asked for on ``brake_request``), the
load average and the machine's own lateness beside the run (``bench/wakeup_probe.py``: its
latest wake-up, those over 10 ms, the latest in the second before the largest
excursion).  ``-s brake_timeout:=0.01`` and the like go to the simulator, ``-p`` to the
controller.  Used for docs/real-time.md::

    . tools/env.sh && python bench/readiness_hog.py --case vertical --runs 3

"""

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time

from freejoint_common.contract import DIAGNOSTICS, EE_POSITION, NS_PER_S, to_ns
from freejoint_tools.harness import node_cmd, Processes
import wakeup_probe  # bench/wakeup_probe.py (this script's folder is on sys.path)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HOG = 'import numpy as n; a=n.random.rand(400,400); [a@a for _ in iter(int,1)]'


LOG_STAMP = re.compile(r'^\[\w+\] \[(\d+)\.(\d+)\] \[controller_node\]: (.*)$')


def guard_phase(log, at_ns):
    """
    Say where the stamp ``at_ns`` [ns, system time] falls among the guard's transitions.

    The controller's log lines (``[LEVEL] [sec.nsec] [controller_node]: text``) that start
    tracking ('real-time loop ready') or stop it ('real-time loop not ready: N of M states
    answered so far' at once, or a judged window) are read with their stamps; the answer
    names the phase and the seconds since its transition, e.g. 'tracking 2 (0.31 s after
    it started)'.
    """
    events = []
    for line in log.splitlines():
        found = LOG_STAMP.match(line)
        if not found:
            continue
        ns = int(found.group(1)) * NS_PER_S + int(found.group(2).ljust(9, '0')[:9])
        text = found.group(3)
        if text.startswith('real-time loop ready'):
            events.append((ns, 'tracking'))
        elif text.startswith('real-time loop not ready') and 'waiting for' not in text:
            events.append((ns, 'braking'))
    current, since, count = None, None, {'tracking': 0, 'braking': 0}
    for ns, kind in events:
        if ns > at_ns:
            break
        if kind != current:         # a repeated line of the same phase starts nothing
            count[kind] += 1
            current, since = kind, ns
    if current is None:
        return 'before any release'
    return '%s %d (%.2f s after it started)' % (current, count[current], (at_ns - since) * 1e-9)


def one_run(case, duration, hogs, extra, log_dir, tag, sim_extra=()):
    """Run the graph once; return the figures (a dict)."""
    import rclpy
    from rclpy.node import Node
    procs = Processes(log_dir, tag=tag)
    hog_procs = [subprocess.Popen([sys.executable, '-c', HOG]) for _ in range(hogs)]
    rclpy.init(args=[])
    node = Node('readiness_hog_watch')
    ee = []
    statuses = []
    node.create_subscription(
        EE_POSITION.msg_type, EE_POSITION.name,
        lambda m: ee.append((m.point.x, m.point.y, to_ns(m.header.stamp))), EE_POSITION.qos)

    def on_diag(msg):
        for st in msg.status:
            if 'controller' in st.name and ord(st.level) >= 2:
                statuses.append(st.message)
    node.create_subscription(DIAGNOSTICS.msg_type, DIAGNOSTICS.name, on_diag, DIAGNOSTICS.qos)
    load0 = os.getloadavg()
    try:
        procs.start('sim', node_cmd('freejoint_sim', 'sim_node',
                                    os.path.join(ROOT, 'config', 'sim.yaml'),
                                    ['case:=' + case, 'mode:=realtime'] + list(sim_extra)))
        procs.start('controller', node_cmd('freejoint_control', 'controller_node',
                                           os.path.join(ROOT, 'config', 'controller.yaml'),
                                           ['case:=' + case, 'lockstep:=false'] + list(extra)))
        end = time.monotonic() + duration
        with wakeup_probe.Probes() as probes:   # the machine's own lateness beside it
            while time.monotonic() < end and not procs.exited():
                rclpy.spin_once(node, timeout_sec=0.1)
            wake = probes.stop()
        load1 = os.getloadavg()
    finally:
        for p in hog_procs:
            p.kill()
            p.wait()
        procs.stop_all(order=('controller', 'sim'))
        node.destroy_node()
        rclpy.shutdown()
    sim_log = procs.log('sim')
    ctl_log = procs.log('controller')
    excursion = at_ns = None
    if ee:
        x0, y0, _ = ee[0]
        # the first sample at the largest excursion (a braked arm repeats it)
        excursion, at_ns = max(((1000.0 * math.hypot(x - x0, y - y0), ns) for x, y, ns in ee),
                               key=lambda item: (item[0], -item[1]))
    stop_line = [ln for ln in ctl_log.splitlines() if 'controller stopped' in ln]
    near = None
    if wake is not None and at_ns is not None:
        # the machine's latest wake-up in the second before the largest excursion
        before = [ms for unix, ms, _cpu in wake['listed'] if 0.0 <= at_ns * 1e-9 - unix <= 1.0]
        near = max(before, default=0.0)
    return {
        'case': case, 'hogs': hogs, 'duration_s': duration, 'extra': list(extra),
        'sim_extra': list(sim_extra),
        'load_before': [round(v, 2) for v in load0], 'load_after': [round(v, 2) for v in load1],
        'ee_samples': len(ee), 'excursion_max_mm': excursion,
        'excursion_when': guard_phase(ctl_log, at_ns) if at_ns is not None else '',
        'sim_diverged': 'plant diverged' in sim_log,
        'brake_engagements': sim_log.count('brakes engaged at step'),
        'brakes_asked': sim_log.count('the controller asked (brake_request)'),
        'not_ready_lines': ctl_log.count('real-time loop not ready'),
        'ready_again_lines': ctl_log.count('real-time loop ready again'),
        'implausible_lines': ctl_log.count('implausible state'),
        'error_statuses': len(statuses),
        'first_error_status': statuses[0] if statuses else '',
        'controller_report': stop_line[-1].split('controller stopped: ')[-1] if stop_line else '',
        'machine_wake_max_ms': None if wake is None else wake['worst_ms'],
        'machine_wakes_over_10ms': None if wake is None else wake['late'],
        'machine_late_ms_in_the_second_before': near,
        'machine_probe_failure': probes.failure,
        'log_dir': log_dir}


def main(argv=None):
    """Run ``--runs`` runs; print a JSON line each."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--case', default='vertical', choices=('horizontal', 'vertical'))
    ap.add_argument('--runs', type=int, default=1)
    ap.add_argument('--duration', type=float, default=20.0)
    ap.add_argument('--hogs', type=int, default=2)
    ap.add_argument('-p', dest='extra', action='append', default=[],
                    help='an extra controller parameter, e.g. -p readiness_guard:=false')
    ap.add_argument('-s', dest='sim_extra', action='append', default=[],
                    help='an extra simulator parameter, e.g. -s thread_priority:=80')
    args = ap.parse_args(argv)
    base = tempfile.mkdtemp(prefix='readiness_hog_')
    for i in range(args.runs):
        row = one_run(args.case, args.duration, args.hogs, args.extra, base,
                      '%s_%d' % (args.case, i), args.sim_extra)
        print(json.dumps(row), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
