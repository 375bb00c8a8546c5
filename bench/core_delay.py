"""
Benchmark: per-tick cost of the delay compensation (``freejoint_core.delay``).

Figures (printed; nothing is asserted): one controller tick's use of the
predictor, ``StatePredictor.predict(q, qd, m)`` followed by ``push(tau)``, for
the Table I nominal 3-link arm (vertical, 70 %) at dt = 1 ms, dt_sub = 0.5 ms
(the plant's step):

* scalar kernel with the bias observer (the default) for m = 1, 2, 5 periods;
* m = 5 with plain prediction (``bias_gain = 0``) and with dt_sub = 1 ms;
* m = 1 on the general numpy path (reference).

Timings are the median over a few repeats of ``time.perf_counter`` around many
calls.  Usage: ``PYTHONPATH=src/freejoint_core python bench/core_delay.py``.
"""

import os
import statistics
import sys
import time

try:
    import freejoint_core  # noqa: F401
except ImportError:  # run from a source checkout without the workspace installed
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__))), 'src', 'freejoint_core'))

from freejoint_core.arm import table1  # noqa: E402
from freejoint_core.delay import StatePredictor  # noqa: E402
import numpy as np  # noqa: E402

DT = 1e-3


def _tick_us(ticks, calls, repeats=5, **kwargs):
    """Median over ``repeats`` of the mean time of one predict + push [us]."""
    pred = StatePredictor(table1('vertical').scaled(0.7), DT, max_ticks=max(ticks, 1),
                          **kwargs)
    q = np.array([0.3, 1.2, 2.0])
    qd = np.array([0.4, -0.3, 0.8])
    tau = np.array([8.0, 4.0])
    for _ in range(ticks + 1):
        pred.push(tau)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            pred.predict(q, qd, ticks)
            pred.push(tau)
        times.append((time.perf_counter() - start) / calls * 1e6)
    return statistics.median(times)


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    rows = []
    for m in (1, 2, 5):
        rows.append({'name': f'delay predictor tick, m = {m} (scalar kernel, observer)',
                     'value': _tick_us(m, 4000), 'unit': 'us', 'target': None})
    rows.append({'name': 'delay predictor tick, m = 5, plain (bias_gain 0)',
                 'value': _tick_us(5, 4000, bias_gain=0.0), 'unit': 'us', 'target': None})
    rows.append({'name': 'delay predictor tick, m = 5, dt_sub = 1 ms',
                 'value': _tick_us(5, 4000, dt_sub=DT), 'unit': 'us', 'target': None})
    rows.append({'name': 'delay predictor tick, m = 1, general numpy (reference)',
                 'value': _tick_us(1, 200, use_fast=False), 'unit': 'us', 'target': None})
    return rows


def main():
    """Print the table."""
    rows = run()
    print('%-64s %12s %-5s %s' % ('figure', 'value', 'unit', 'target'))
    for r in rows:
        print('%-64s %12.4g %-5s %s' % (r['name'], r['value'], r['unit'], r['target'] or ''))


if __name__ == '__main__':
    main()
