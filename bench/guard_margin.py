"""
What share of missed states and what delay the law tolerates: the readiness guard's margins.

Offline (``freejoint_core.offline.run_case``, no ROS): the robust variant (70 % nominal
model, disturbance on, the paper's gains), seeds 0-9, both cases, the paper's circle,
under the loss and delay patterns real-time bags show - a delay of 1-3 ms varying from one
command to the next (``delay_ticks`` 1, ``delay_jitter`` 2) and states not answered in
bursts (``loss_rate``, ``loss_burst``: the previous command held one more period per state
missed). A setting is tolerated when every seed stays within the case's bound (1.5 x the
undelayed loop's worst max error, as ``make soak`` judges a run). Prints the table of
docs/real-time.md and the thresholds it gives; writes the records as JSON.

    python bench/guard_margin.py                      # both cases, ~260 runs
    python bench/guard_margin.py --cases vertical --rates 0.1 0.2 --bursts 5

The law runs at the arm's real-time chattering bound (``realtime_epsilon``,
``freejoint_control.readiness.REALTIME_EPSILON``; with ``--predict`` the paper's) unless
``--epsilon`` is given. The shipped uncompensated thresholds
(``freejoint_control.readiness.MEASURED``) come from these, at the real-time bound, and a
fixed delay (``freejoint_core.offline.run_case(..., delay_ticks=M)``)::

    python bench/guard_margin.py --rates 0.05 0.1 0.2 0.3
    python bench/guard_margin.py --cases vertical --rates 0.05 0.1 0.2 --bursts 10
    python bench/guard_margin.py --cases vertical --delay 2 --rates 0.05 0.1 --bursts 1 5

The ``predict`` ones were measured at the paper's bound (``--epsilon 0.1 --predict``).

Exit code 0 whatever the figures (a benchmark).
"""

import argparse
import json
import os
import sys
import time

from freejoint_control.readiness import realtime_epsilon
from freejoint_core.arm import table1
from freejoint_core.control import Gains
from freejoint_core.offline import run_case

CASES = ('horizontal', 'vertical')
RATES = (0.05, 0.1, 0.2, 0.3)
BURSTS = (1, 5, 20)
BOUND_FACTOR = 1.5
"""The soak's bound: 1.5 x the undelayed loop's worst max error over the seeds."""


def worst(records):
    """Return (worst max mm, diverged count) of a setting's records."""
    return (max(r['max_mm'] for r in records),
            sum(r['diverged_at_s'] is not None for r in records))


def study(cases, seeds, rates, bursts, delay, jitter, progress=print, with_zero=True,
          epsilon=None, **options):
    """
    Return rows: case, delay, loss rate, burst, worst max, diverged, within the bound.

    ``epsilon``: the law's chattering bound (None: the arm's real-time one,
    ``freejoint_control.readiness.REALTIME_EPSILON``); the bound is the paper's law's, the
    soak's.
    """
    rows = []
    records = []
    for case in cases:
        base = [run_case(case, 'robust', s)[0] for s in seeds]
        bound = BOUND_FACTOR * worst(base)[0]
        eps = realtime_epsilon(table1(case), 'predict' if options.get('predict') else 'off',
                               epsilon or 0.0, Gains().epsilon)[0]
        options['gains'] = Gains(epsilon=eps)
        settings = [(0.0, 1)] * with_zero + [(r, b) for r in rates for b in bursts]
        for rate, burst in settings:
            recs = [run_case(case, 'robust', s, delay_ticks=delay, delay_jitter=jitter,
                             loss_rate=rate, loss_burst=burst, **options)[0] for s in seeds]
            records += recs
            mx, div = worst(recs)
            within = sum(r['diverged_at_s'] is None and r['max_mm'] <= bound for r in recs)
            row = {'case': case, 'delay_ms': '%d-%d' % (delay, delay + jitter),
                   'predict': bool(options.get('predict')), 'epsilon': eps,
                   'loss_rate': rate, 'loss_burst': burst, 'worst_max_mm': mx,
                   'diverged': div, 'within': within, 'seeds': len(recs), 'bound_mm': bound}
            rows.append(row)
            progress('%-10s eps %.2g, delay %s ms, %3.0f %% missed in bursts of %2d: worst '
                     'max %8.3f mm, %d diverged, %d/%d within %.2f mm' % (
                         case, eps, row['delay_ms'], rate * 100, burst, mx, div, within,
                         len(recs), bound))
            sys.stdout.flush()
    return rows, records


def tolerated(rows, case, burst):
    """Return the largest loss rate below which every seed stayed within (bursts of ``burst``)."""
    ok = 0.0
    for row in sorted((r for r in rows if r['case'] == case and r['loss_burst'] == burst
                       or r['case'] == case and r['loss_rate'] == 0.0),
                      key=lambda r: r['loss_rate']):
        if row['within'] != row['seeds']:
            break
        ok = row['loss_rate']
    return ok


def main(argv=None):
    ap = argparse.ArgumentParser(prog='guard_margin', description=__doc__.strip().splitlines()[0])
    ap.add_argument('--cases', nargs='+', choices=CASES, default=list(CASES))
    ap.add_argument('--seeds', type=int, default=10)
    ap.add_argument('--rates', nargs='+', type=float, default=list(RATES))
    ap.add_argument('--bursts', nargs='+', type=int, default=list(BURSTS))
    ap.add_argument('--delay', type=int, default=1, help='least delay [periods] (default 1)')
    ap.add_argument('--jitter', type=int, default=2,
                    help='delay varying 0..J periods more (default 2: 1-3 ms)')
    ap.add_argument('--predict', action='store_true',
                    help='delay_compensation predict (the predictor told the applied command, '
                    'as joint_states.effort does: --echo of the offline runner)')
    ap.add_argument('--epsilon', type=float, default=None,
                    help="the law's chattering bound (default: the arm's real-time one, "
                    "freejoint_control.readiness.REALTIME_EPSILON; the paper's: 0.1)")
    ap.add_argument('--out', default='bags/offline/guard_margin.json')
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    options = {'predict': True, 'echo': True, 'predict_ticks': args.delay + 1} \
        if args.predict else {}
    rows, records = study(args.cases, range(args.seeds), args.rates, args.bursts, args.delay,
                          args.jitter, epsilon=args.epsilon, **options)
    print('%d settings, %.0f s wall' % (len(rows), time.perf_counter() - t0))
    for case in args.cases:
        for burst in args.bursts:
            print('%-10s delay %d-%d ms, bursts of %d: every seed within its bound up to %.0f %% '
                  'of the states missed (of those measured)' % (
                      case, args.delay, args.delay + args.jitter, burst,
                      tolerated(rows, case, burst) * 100))
    if args.out:
        os.makedirs(os.path.dirname(args.out) or '.', exist_ok=True)
        with open(args.out, 'w') as f:
            json.dump({'rows': rows, 'records': records}, f, indent=1)
        print('written to %s' % args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
