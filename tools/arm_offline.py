"""
The offline twin of ``make demo ARM=<arm>`` over seeds: one JSON line per seed, then a verdict.

Usage: ``python tools/arm_offline.py ARM [--seeds 10] [--first 0] [--t-stop S]`` with ARM a shipped
spatial arm (ur5, panda) or a directory of ``fj arm init``. Each seed runs
``tools/demo.py``'s ``spatial_offline`` (the graph's twin: the parameter files of the
three nodes, the law the controller builds, the planner's circle, the hold) and reports
the tip error against the plan [mm], the peak effort and speed shares of the URDF limits,
the joints that left their URDF position limits (free ones included) and divergence.
Exit status 1 if a seed misses the bound of arm.yaml (3 mm), leaves a limit or diverges.
"""

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import demo  # noqa: E402  (tools/demo.py: the twin and the arm's entry)

KEYS = ('rms_mm', 'max_mm', 'hold_last_s_max_mm', 'tau_ratio', 'vel_ratio', 'vel_ratio_free',
        'active_outside_limits', 'free_outside_limits', 'diverged_at_s')


def main(argv=None):
    """Run the seeds; return the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('arm', help='ur5, panda or a directory of fj arm init')
    ap.add_argument('--seeds', type=int, default=10, help='seeds FIRST..FIRST+N-1')
    ap.add_argument('--first', type=int, default=0, metavar='FIRST', help='first seed (0)')
    ap.add_argument('--t-stop', type=float, help='end each run at this time [s] (tests)')
    args = ap.parse_args(argv)
    arm = args.arm if args.arm in demo.ARMS else os.path.abspath(args.arm)
    info = demo.arm_info(arm)
    if 'spatial' not in info:
        raise SystemExit('arm_offline: %s is not a spatial arm' % args.arm)
    settings = demo.offline_settings()
    dt = settings['dt']
    seconds = args.t_stop if args.t_stop is not None else settings['duration'] + info['hold_s']
    n_ticks = int(round(seconds / dt))
    failed = 0
    worst = 0.0
    for seed in range(args.first, args.first + args.seeds):
        record, _ = demo.spatial_offline(arm, seed, n_ticks)
        row = {'arm': info['spatial'], 'seed': seed}
        row.update({key: record[key] for key in KEYS})
        bad = (record['max_mm'] > info['bound_mm'] or record['diverged_at_s'] is not None
               or record['active_outside_limits'] or record['free_outside_limits']
               or record['tau_ratio'] > 1.0 or record['vel_ratio'] > 1.0
               or record['vel_ratio_free'] > 1.0)
        failed += bool(bad)
        worst = max(worst, record['max_mm'])
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v
                          for k, v in row.items()}), flush=True)
    print('%s: %d seeds, worst max %.3f mm (bound %g mm), %d seed(s) failing' % (
        info['spatial'], args.seeds, worst, info['bound_mm'], failed))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
