"""
A joint fails in the lockstep graph: the same run as the offline runner (issue 23).

Runs the simulator, the controller and the planner in lockstep (``tools/demo.py``'s
harness, no recorder) with the fully actuated arm (``config/fully_actuated/``), the
simulator's ``fail_joint`` set (default ``joint3@2.5``) and the controller's
``joint_failures: detect`` (with the effort of joint_states; ``--no-effort``: the residual
only); then ``freejoint_core.failure_offline.run_failure_case`` on the
same case and seed, and prints, per case, the detection (from the controller's log), the
largest difference of the commands (controller_state ``effort``) and of the joint angles
(joint_states) between the graph and the offline runner, and the tracking error::

    . tools/env.sh && python bench/failure_graph.py [--cases vertical horizontal]
        [--fail joint3@2.5] [--seeds 0-9] [--duration 2.7] [--no-effort]

Exit 1 if a difference is above 1e-9 (the lockstep graph must equal the offline run to
round-off).
"""
import argparse
import math
import os
import re
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, 'config')
CASES = ('vertical', 'horizontal')
MS = 1_000_000
"""Nanoseconds per control period (1 ms)."""


def _demo():
    from freejoint_tools.harness import load_source
    return load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'demo')


def _overlay(directory, fail, effort):
    """Write the overlay files (the fully actuated arm, the failure) into ``directory``."""
    for node in ('controller', 'planner', 'sim'):
        with open(os.path.join(CONFIG, 'fully_actuated', node + '.yaml')) as fh:
            text = fh.read()
        if node == 'sim':
            text = text.rstrip('\n') + "\n    fail_joint: '%s'\n" % fail
        if node == 'controller' and not effort:
            text = text.rstrip('\n') + '\n    failure_use_effort: false\n'
        with open(os.path.join(directory, node + '.yaml'), 'w') as fh:
            fh.write(text)


def main(argv=None):
    """Run the cases; return the exit code."""
    ap = argparse.ArgumentParser(prog='failure_graph', description=__doc__.split('\n')[1])
    ap.add_argument('--cases', nargs='+', choices=CASES, default=list(CASES))
    ap.add_argument('--fail', default='joint3@2.5')
    ap.add_argument('--seeds', default='0', help='A or A-B (default 0)')
    ap.add_argument('--no-effort', action='store_true',
                    help="the controller ignores joint_states' effort (residual only)")
    ap.add_argument('--duration', type=float, default=2.7,
                    help='simulated time [s] per case (default 2.7)')
    args = ap.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')
    demo = _demo()
    from freejoint_common.contract import to_ns
    from freejoint_core.failure_offline import parse_fail, run_failure_case
    import numpy as np
    import rclpy
    from rclpy.experimental import EventsExecutor
    dt = 0.001
    n_ticks = int(round(args.duration / dt))
    out = tempfile.mkdtemp(prefix='failure_graph_')
    overlay = os.path.join(out, 'overlay')
    os.makedirs(overlay)
    _overlay(overlay, args.fail, not args.no_effort)
    rclpy.init()
    node = rclpy.create_node('failure_graph')
    executor = EventsExecutor()
    executor.add_node(node)
    failed = False
    try:
        lo, _, hi = args.seeds.partition('-')
        runs = [(case, seed) for case in args.cases
                for seed in range(int(lo), int(hi or lo) + 1)]
        for case, seed in runs:
            collector = demo.Collector(node)
            logs = os.path.join(out, 'logs', '%s_%d' % (case, seed))
            run = demo.run_graph(case, seed, n_ticks, round(dt * 1e9), collector, executor,
                                 out, logs, record=False, progress=lambda text: None,
                                 arm=overlay)
            states = {}
            for msg in collector.messages('controller_state'):
                states.setdefault(to_ns(msg.header.stamp), msg)
            joints = {}
            for msg in collector.messages('joint_states'):
                joints.setdefault(to_ns(msg.header.stamp), msg)
            collector.close()
            ticks = [k for k in range(n_ticks) if k * MS in states and k * MS in joints]
            if not ticks:
                print('%s seed %d: no tick collected (another graph in ROS domain %s?); '
                      'logs in %s' % (case, seed, os.environ['ROS_DOMAIN_ID'], logs))
                failed = True
                continue
            cmd = np.array([list(states[k * MS].effort) for k in ticks])
            q = np.array([list(joints[k * MS].position) for k in ticks])
            err = max(math.hypot(*(np.array(states[k * MS].position)
                                   - states[k * MS].position_desired)) for k in ticks)
            rec, trace = run_failure_case(case, seed, parse_fail(args.fail),
                                          duration=n_ticks * dt, record_trace=True,
                                          effort=not args.no_effort)
            d_cmd = float(np.max(np.abs(cmd - trace['tau'][ticks])))
            d_q = float(np.max(np.abs(q - trace['q'][ticks])))
            with open([p for p in run['logs'] if 'controller' in p][0]) as fh:
                found = re.findall(r'joint failure: (.*?failed at t = [0-9.]+ s \(detected '
                                   r'by \w+\))', fh.read())
            print('%s seed %d, %s: %d of %d ticks; graph: %s; offline: detected at %s by %s; '
                  'max |command difference| %.3g N m, max |q difference| %.3g rad, max '
                  'tracking error %.3f mm (offline %.3f mm); %.2f s wall'
                  % (case, seed, args.fail, len(ticks), n_ticks, found or 'no detection',
                     rec['detected_at_s'], rec['detected_by'], d_cmd, d_q, err * 1e3,
                     rec['max_mm'], run['wall_s']), flush=True)
            failed = failed or len(ticks) != n_ticks or d_cmd > 1e-9 or d_q > 1e-9
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    print('logs in %s' % out)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
