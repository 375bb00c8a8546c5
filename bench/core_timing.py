"""
What the core benchmarks (``bench/core_*.py``) share: the import path, the timer, the table.

Importing it makes ``freejoint_core`` importable from a source checkout without the
workspace installed (``src/freejoint_core`` on ``sys.path``).  Timings are the median
over a few repeats of ``time.perf_counter`` around many calls.
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


def per_call_us(fun, calls, repeats=5):
    """
    Return the median over ``repeats`` of the mean time per call of ``fun()`` [us].

    Parameters
    ----------
    fun : callable
        Called without arguments, ``calls`` times per repeat.
    calls : int
        Calls per repeat, >= 1.
    repeats : int
        Number of repeats, >= 1.

    Returns
    -------
    float
        [us].

    """
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            fun()
        times.append((time.perf_counter() - start) / calls * 1e6)
    return statistics.median(times)


def print_rows(rows, width=64):
    """
    Print benchmark rows as a table.

    Parameters
    ----------
    rows : list of dict
        Each with ``name``, ``value``, ``unit`` and ``target`` (None: no target).
    width : int
        Width of the figure column [characters].

    """
    print('%-*s %12s %-5s %s' % (width, 'figure', 'value', 'unit', 'target'))
    for r in rows:
        print('%-*s %12.4g %-5s %s' % (width, r['name'], r['value'], r['unit'],
                                       r['target'] or ''))
