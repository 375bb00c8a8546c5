"""
A joint fails in the lockstep graph: the same run as the offline runner.

Runs the simulator, the controller and the planner in lockstep (``tools/demo.py``'s
harness, no recorder) with the fully actuated arm (``config/fully_actuated/``), the
simulator's ``fail_joint`` set (default ``joint3@2.5``) and the controller's
``joint_failures: detect`` (with the effort of joint_states; ``--no-effort``: the residual
only); then compares with ``freejoint_core.failure_offline.run_failure_case`` on the
same case and seed (``tools/demo.py``'s ``failure_comparison``, as ``make demo FAIL=``),
and prints, per case, the detection (from the controller's log), the planner's line on
it, the largest difference of the commands (controller_state ``effort``) and of the joint
angles (joint_states) between the graph and the offline runner, and the tracking error::

    . tools/env.sh && python bench/failure_graph.py [--cases vertical horizontal]
        [--fail joint3@2.5] [--seeds 0-9] [--duration 2.7] [--no-effort]
        [--free-link-damping]

``--free-link-damping``: the controller also takes
config/fully_actuated/free_link_damping.yaml (the freed link damped in the rests), the
offline runner ``FAILURE_FREE_LINK_DAMPING`` (give a ``--duration`` past the circle's 5 s).

Exit 1 if a difference is above 1e-9 (the lockstep graph must equal the offline run to
round-off).
"""
import argparse
import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = ('vertical', 'horizontal')
MS = 1_000_000
"""Nanoseconds per control period (1 ms)."""


def _demo():
    from freejoint_tools.harness import load_source
    return load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'demo')


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
    ap.add_argument('--free-link-damping', action='store_true',
                    help='the freed link damped in the rests '
                    '(config/fully_actuated/free_link_damping.yaml)')
    args = ap.parse_args(argv)
    os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')
    demo = _demo()
    import rclpy
    from rclpy.experimental import EventsExecutor
    dt_ns = MS
    n_ticks = int(round(args.duration / 1e-3))
    out = tempfile.mkdtemp(prefix='failure_graph_')
    node_args = {'sim': ['fail_joint:=' + args.fail]}
    if args.no_effort:
        node_args['controller'] = ['failure_use_effort:=false']
    damping = None
    if args.free_link_damping:
        from freejoint_control.params import SCHEMA
        from freejoint_core.failure_offline import FAILURE_FREE_LINK_DAMPING as damping
        node_args.setdefault('controller', []).extend(SCHEMA.overrides(os.path.join(
            ROOT, 'config', 'fully_actuated', 'free_link_damping.yaml')))
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
            run = demo.run_graph(case, seed, n_ticks, dt_ns, collector, executor, out, logs,
                                 record=False, progress=lambda text: None,
                                 overlays=(demo.FULLY_ACTUATED,), node_args=node_args)
            try:
                cmp = demo.failure_comparison(collector, case, seed, args.fail, n_ticks, dt_ns,
                                              run['logs'], effort=not args.no_effort,
                                              free_link_damping=damping)
            except RuntimeError as exc:
                print('%s seed %d: %s; logs in %s' % (case, seed, exc, logs))
                failed = True
                continue
            finally:
                collector.close()
            rec = cmp['offline']
            print('%s seed %d, %s: %d of %d ticks; graph: %s; planner: %s; offline: detected '
                  'at %s by %s; max |command difference| %.3g N m, max |q difference| %.3g '
                  'rad, max tracking error %.3f mm (offline %.3f mm); %.2f s wall'
                  % (case, seed, args.fail, cmp['ticks'], n_ticks,
                     cmp['found'] or 'no detection', cmp['planner'] or 'no line',
                     rec['detected_at_s'], rec['detected_by'], cmp['d_cmd'], cmp['d_q'],
                     cmp['max_mm'], rec['max_mm'], run['wall_s']), flush=True)
            failed = failed or cmp['ticks'] != n_ticks or cmp['d_cmd'] > 1e-9 or \
                cmp['d_q'] > 1e-9
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    print('logs in %s' % out)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
