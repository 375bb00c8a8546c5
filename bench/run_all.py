"""
Run every benchmark, print one table and write it to bags/bench/bench.json.

Each module in MODULES has `run() -> list of dict(name, value, unit, target)`; `target` is
a string such as '<= 20' or '>= 2' (or None). Benchmarks print figures; they assert nothing.
Usage: python bench/run_all.py [--only MODULE ...] [--out PATH]; `make bench BENCH="graph echo"`
runs only those modules.
"""
import argparse
import importlib
import json
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
MODULES = ['core_law_plant', 'core_delay', 'core_map_offline', 'core_singularity_nlink',
           'core_urdf', 'core_spatial_map', 'tools_recorder', 'graph', 'echo', 'viewer']


def meets(value, target):
    """Return True/False if `value` meets `target` ('<= x' or '>= x'), None if no target."""
    if not target or value is None:
        return None
    op, bound = target.split()
    return value <= float(bound) if op == '<=' else value >= float(bound)


def format_rows(rows):
    """Return the benchmark table as text."""
    lines = ['%-58s %14s %-8s %-10s %s' % ('figure', 'value', 'unit', 'target', 'met')]
    for r in rows:
        ok = meets(r['value'], r.get('target'))
        value = r['value']
        shown = 'n/a' if value is None else ('%.4g' % value)
        lines.append('%-58s %14s %-8s %-10s %s' % (
            r['name'], shown, r['unit'], r.get('target') or '',
            '' if ok is None else ('yes' if ok else 'NO')))
    return '\n'.join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--only', nargs='*', default=None, help='modules to run')
    parser.add_argument('--out', default=os.path.join(ROOT, 'bags', 'bench', 'bench.json'))
    args = parser.parse_args(argv)
    sys.path.insert(0, HERE)
    rows = []
    for name in args.only or MODULES:
        start = time.perf_counter()
        print('[bench] %s ...' % name, flush=True)
        try:
            module = importlib.import_module(name)
        except ImportError as exc:
            print('[bench] %s: not available (%s)' % (name, exc), flush=True)
            continue
        try:
            module_rows = module.run()
        except Exception as exc:  # one broken benchmark must not cost the whole table
            print('[bench] %s failed: %s: %s' % (name, type(exc).__name__, exc), flush=True)
            module_rows = [{'name': '%s completed' % name, 'value': 0, 'unit': '',
                            'target': '>= 1'}]
        for row in module_rows:
            row.setdefault('target', None)
            row['module'] = name
            rows.append(row)
        print('[bench] %s done in %.1f s' % (name, time.perf_counter() - start), flush=True)
    table = format_rows(rows)
    print(table)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, 'w') as f:
        json.dump({'cpu_count': os.cpu_count(), 'machine': platform.machine(),
                   'load_average': os.getloadavg(),
                   'python': platform.python_version(), 'figures': rows}, f, indent=2)
    print('[bench] written to %s' % os.path.relpath(args.out, ROOT))
    return 0


if __name__ == '__main__':
    sys.exit(main())
