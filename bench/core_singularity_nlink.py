"""
Benchmark: the singularity map of the shipped 4-link example arm (freejoint_core).

Figures (wall time, median of a few repeats, printed; nothing is asserted), nominal
``four_link_arm('horizontal').nominal(0.7)`` (joint 1 passive, 3 active):

* ``det_map_nlink`` over ``(q2, q3, q4)`` at 3 deg (120^3 samples) and 2 deg (180^3),
  and the time per sample at 2 deg;
* ``semi_singular_nlink`` (conservative cell test) on the 2 deg map.

Usage: ``PYTHONPATH=src/freejoint_core python bench/core_singularity_nlink.py``.
"""

import sys

from core_timing import per_call_us, print_rows
from freejoint_core.arm import NOMINAL_SCALE
from freejoint_core.singularity_nlink import det_map_nlink, semi_singular_nlink
from freejoint_core.urdf import four_link_arm


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    nominal = four_link_arm('horizontal').nominal(NOMINAL_SCALE)
    det_map_nlink(nominal, 10.0)  # warm-up (imports, caches)
    coarse = per_call_us(lambda: det_map_nlink(nominal, 3.0), 1, repeats=3) * 1e-6
    fine = per_call_us(lambda: det_map_nlink(nominal, 2.0), 1, repeats=3) * 1e-6
    dmap = det_map_nlink(nominal, 2.0)
    region = per_call_us(lambda: semi_singular_nlink(dmap), 1, repeats=3) * 1e-6
    return [
        {'name': 'singularity 4-link det_map_nlink 3 deg (120^3)', 'value': coarse,
         'unit': 's', 'target': None},
        {'name': 'singularity 4-link det_map_nlink 2 deg (180^3)', 'value': fine,
         'unit': 's', 'target': None},
        {'name': 'singularity 4-link map time per sample, 2 deg',
         'value': fine / dmap.det.size * 1e6, 'unit': 'us', 'target': None},
        {'name': 'singularity 4-link semi_singular_nlink on the 2 deg map',
         'value': region, 'unit': 's', 'target': None},
    ]


def main():
    """Print the rows as a table."""
    print_rows(run())
    return 0


if __name__ == '__main__':
    sys.exit(main())
