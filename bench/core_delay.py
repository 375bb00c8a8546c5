"""
Benchmark: per-tick cost of the delay compensation (``freejoint_core.delay``).

Figures (printed; nothing is asserted): one controller tick's use of the
predictor, ``StatePredictor.predict(q, qd, m)`` followed by ``push(tau)``, for
the Table I nominal 3-link arm (vertical, 70 %) at dt = 1 ms, dt_sub = 0.5 ms
(the plant's step):

* scalar kernel with the bias observer (the default) for m = 1, 2, 5 periods;
* m = 5 with plain prediction (``bias_gain = 0``) and with dt_sub = 1 ms;
* m = 1 on the general numpy path (reference).

Timings: ``core_timing.per_call_us``.  Usage:
``PYTHONPATH=src/freejoint_core python bench/core_delay.py``.
"""

from core_timing import per_call_us, print_rows
from freejoint_core.arm import NOMINAL_SCALE, table1
from freejoint_core.delay import StatePredictor
import numpy as np

DT = 1e-3


def _tick_us(ticks, calls, repeats=5, **kwargs):
    """Median over ``repeats`` of the mean time of one predict + push [us]."""
    pred = StatePredictor(table1('vertical').scaled(NOMINAL_SCALE), DT, max_ticks=max(ticks, 1),
                          **kwargs)
    q = np.array([0.3, 1.2, 2.0])
    qd = np.array([0.4, -0.3, 0.8])
    tau = np.array([8.0, 4.0])
    for _ in range(ticks + 1):
        pred.push(tau)

    def tick():
        pred.predict(q, qd, ticks)
        pred.push(tau)
    return per_call_us(tick, calls, repeats)


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
    print_rows(run())


if __name__ == '__main__':
    main()
