"""
The offline twin of ``make demo ARM=<arm>`` over seeds: one JSON line per seed, then a verdict.

Usage: ``python tools/arm_offline.py ARM [--seeds 10] [--first 0] [--t-stop S]`` with ARM a shipped
spatial arm (ur5, panda), a directory of ``fj arm init``, or a URDF with ``--passive J
[--tip T] [--base B]`` (``fj arm init`` into ``bags/offline/<name>/`` first, as ``make demo
ARM=file.urdf PASSIVE=J`` does into ``bags/demo/``). Each seed runs
``tools/demo.py``'s ``spatial_offline`` (the graph's twin: the parameter files of the
three nodes, the law the controller builds, the planner's circle, the hold) and reports
the tip error against the plan [mm], the peak effort and speed shares of the URDF limits,
the joints that left their URDF position limits (free ones included), the smallest
distance of any joint from its URDF position limits over the run (``limit_margin_rad``,
the joint named; continuous joints have none) and divergence.
Exit status 1 if a seed misses the bound of arm.yaml (3 mm), leaves a limit or diverges.
"""

import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import demo  # noqa: E402  (tools/demo.py: the twin and the arm's entry)
OUT = os.path.join(demo.ROOT, 'bags', 'offline')
"""Where a URDF's arm is initialised (``bags/offline/<name>/``)."""
from freejoint_tools.arm_twin import limit_margin  # noqa: E402, I100

KEYS = ('rms_mm', 'max_mm', 'hold_last_s_max_mm', 'tau_ratio', 'vel_ratio', 'vel_ratio_free',
        'active_outside_limits', 'free_outside_limits', 'diverged_at_s')


def main(argv=None):
    """Run the seeds; return the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('arm', help='ur5, panda, a directory of fj arm init or a URDF')
    ap.add_argument('--seeds', type=int, default=10, help='seeds FIRST..FIRST+N-1')
    ap.add_argument('--first', type=int, default=0, metavar='FIRST', help='first seed (0)')
    ap.add_argument('--t-stop', type=float, help='end each run at this time [s] (tests)')
    ap.add_argument('--passive', action='append', metavar='JOINT',
                    help='with ARM a URDF: its free joint (fj arm init --passive, repeat)')
    ap.add_argument('--tip', help='with ARM a URDF: the tip link (fj arm init --tip)')
    ap.add_argument('--base', help='with ARM a URDF: the base link (fj arm init --base)')
    args = ap.parse_args(argv)
    if args.arm.endswith('.urdf'):
        from freejoint_core.errors import FreejointValueError
        from freejoint_tools.arm_twin import from_urdf
        if not args.passive:
            ap.error('a URDF needs --passive JOINT')
        try:
            args.arm = from_urdf(args.arm, args.passive, OUT, args.tip, args.base,
                                 log=lambda line: print('fj arm init: ' + line, flush=True))
        except FreejointValueError as exc:
            print('arm_offline: fj arm init %s: refused: %s' % (args.arm, exc))
            return 2
    elif args.passive or args.tip or args.base:
        ap.error('--passive, --tip and --base go with a URDF')
    arm = args.arm if args.arm in demo.ARMS else os.path.abspath(args.arm)
    info = demo.arm_info(arm)
    if 'spatial' not in info:
        raise SystemExit('arm_offline: %s is not a spatial arm' % args.arm)
    n_ticks = demo.spatial_ticks(arm) if args.t_stop is None else \
        int(round(args.t_stop / demo.offline_settings()['dt']))
    real = demo.spatial_configs(arm)[0].arm.spatial
    failed = 0
    worst = 0.0
    margin = math.inf
    for seed in range(args.first, args.first + args.seeds):
        record, trace = demo.spatial_offline(arm, seed, n_ticks)
        row = {'arm': info['spatial'], 'seed': seed}
        row.update({key: record[key] for key in KEYS})
        row['limit_margin_rad'], row['limit_margin_joint'] = limit_margin(real,
                                                                          trace['q'])
        margin = min(margin, row['limit_margin_rad'])
        bad = (record['max_mm'] > info['bound_mm'] or record['diverged_at_s'] is not None
               or record['active_outside_limits'] or record['free_outside_limits']
               or record['tau_ratio'] > 1.0 or record['vel_ratio'] > 1.0
               or record['vel_ratio_free'] > 1.0)
        failed += bool(bad)
        worst = max(worst, record['max_mm'])
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v
                          for k, v in row.items()}), flush=True)
    print('%s: %d seeds, worst max %.3f mm (bound %g mm), worst limit margin %.3f rad, '
          '%d seed(s) failing' % (info['spatial'], args.seeds, worst, info['bound_mm'], margin,
                                  failed))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
