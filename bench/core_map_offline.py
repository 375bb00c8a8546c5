"""
Benchmark: singularity map and offline closed-loop run (freejoint_core).

Figures (wall time, median of a few repeats, printed; nothing is asserted):

* ``det_map`` of the Table I nominal arm at 1 deg (360 x 360) and 0.25 deg
  (1440 x 1440; target 0.1 s), and the batched general path at 1 deg;
* ``semi_singular`` on the 0.25 deg map;
* one 5-s offline case (5000 ticks, robust, 70 % nominal, disturbance) per
  case (target 0.5 s).

Usage: ``PYTHONPATH=src/freejoint_core python bench/core_map_offline.py``.
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

from freejoint_core.arm import NOMINAL_SCALE, table1  # noqa: E402
from freejoint_core.offline import run_case  # noqa: E402
from freejoint_core.singularity import det_map, semi_singular  # noqa: E402


def _median_time(fun, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fun()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    nominal = table1('horizontal').scaled(NOMINAL_SCALE)
    det_map(nominal, 1.0)  # warm-up (imports, caches)
    rows = [
        {'name': 'singularity det_map 1 deg (360x360), closed form',
         'value': _median_time(lambda: det_map(nominal, 1.0), 7), 'unit': 's',
         'target': '<= 0.01'},
        {'name': 'singularity det_map 0.25 deg (1440x1440), closed form',
         'value': _median_time(lambda: det_map(nominal, 0.25), 5), 'unit': 's',
         'target': '<= 0.1'},
        {'name': 'singularity det_map 1 deg, general batched path',
         'value': _median_time(lambda: det_map(nominal, 1.0, method='general'), 3),
         'unit': 's', 'target': None},
    ]
    fine = det_map(nominal, 0.25)
    rows.append({'name': 'singularity semi_singular on the 0.25 deg map',
                 'value': _median_time(lambda: semi_singular(fine), 3), 'unit': 's',
                 'target': None})
    for case in ('horizontal', 'vertical'):
        rows.append({'name': f'offline 5-s case wall time ({case}, robust, seed 0)',
                     'value': _median_time(lambda: run_case(case, 'robust', 0), 3),
                     'unit': 's', 'target': '<= 0.5'})
    return rows


def main():
    """Print the rows as a table."""
    rows = run()
    print(f'{"figure":<58} {"value":>10} {"unit":<5} {"target":<9}')
    for row in rows:
        print(f'{row["name"]:<58} {row["value"]:>10.4g} {row["unit"]:<5} '
              f'{row["target"] or "":<9}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
