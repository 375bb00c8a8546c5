"""
Print the median table of several ``make bench`` results (bench.json files).

Each figure's value is the median over the files that hold it; the load averages of the
runs are printed under the table.  Usage:
``python bench/median.py bags/bench/run1.json bags/bench/run2.json bags/bench/run3.json
[--markdown]``.
"""
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from run_all import format_rows, meets  # noqa: E402


def median_rows(runs):
    """Return the rows of the first run with each value the median over ``runs``."""
    values = {}
    for run in runs:
        for row in run['figures']:
            if row['value'] is not None:
                values.setdefault(row['name'], []).append(row['value'])
    rows = []
    seen = set()
    for run in runs:
        for row in run['figures']:
            if row['name'] in seen:
                continue
            seen.add(row['name'])
            got = values.get(row['name'])
            rows.append(dict(row, value=statistics.median(got) if got else None,
                             runs=len(got or ())))
    return rows


def markdown(rows):
    """Return the rows as a Markdown table."""
    lines = ['| figure | median | unit | target | met |', '|---|---:|---|---|---|']
    for r in rows:
        ok = meets(r['value'], r.get('target'))
        value = 'n/a' if r['value'] is None else '%.4g' % r['value']
        lines.append('| %s | %s | %s | %s | %s |' % (
            r['name'], value, r['unit'], r.get('target') or '',
            '' if ok is None else ('yes' if ok else '**no**')))
    return '\n'.join(lines)


def main(argv):
    """Print the median table of the given bench.json files."""
    paths = [a for a in argv if not a.startswith('--')]
    if not paths:
        print(__doc__.strip())
        return 2
    runs = []
    for path in paths:
        with open(path) as f:
            runs.append(json.load(f))
    rows = median_rows(runs)
    print(markdown(rows) if '--markdown' in argv else format_rows(rows))
    for path, run in zip(paths, runs):
        load = run.get('load_average')
        print('%s: %s CPUs, load average at the end %s' % (
            path, run.get('cpu_count'), ', '.join('%.2f' % v for v in load) if load else '?'))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
