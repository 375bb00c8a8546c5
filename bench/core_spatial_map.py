"""
Benchmark: the sampled singularity map of a spatial arm (freejoint_core.spatial_map).

Figures (printed; nothing is asserted), UR5 (wrist_2 free) and Panda (joint 7 free), m = 3,
nominal 0.7:

* the cost of one sample: the map's path (``spatial_map.evaluate`` over a chunk of 10^4
  postures: Pinocchio's ``computeMinverse`` + ``computeFrameJacobian`` per posture, the
  rest batched), and the law's per-tick path it replaces (``terms`` + ``decoupling`` +
  ``task_conditioning``, posture by posture);
* the wall time of a whole map (``spatial_map.compute_map``) in this process (one core);
* with ``--ray``: the same map on a two-node Ray cluster started on this machine
  (``ray start``, one CPU a node: two workers; bench/campaign.py's ``Cluster``, stopped at
  the end) through ``freejoint_tools.spatial_map.ray_map``, and whether it equals the
  in-process map exactly; with ``--workers N`` also in N worker processes.

Each figure is measured ``--repeats`` times (default 3) and printed with the worst and the
load average (``os.getloadavg``) around it: the machine is shared.

Usage: ``python bench/core_spatial_map.py [--samples 1000000] [--repeats 3] [--ray]
[--workers 2] [--arm panda] [--quick]`` in the workspace (``. tools/env.sh``);
``make bench BENCH=core_spatial_map`` (or ``--quick``) runs ``run()``: the per-sample costs
and a 10^5-sample UR5 map, once.
"""

import argparse
import os
import sys
import time

from core_timing import print_rows
from freejoint_core import spatial_map as sm
import numpy as np

ARMS = (('ur5', 'wrist_2_joint'), ('panda', 'panda_joint7'))
CHUNK = 10000
LAW_SAMPLES = 1000


def _load():
    return os.getloadavg()[0]


def per_sample_us(spec):
    """Return (map path, law path) cost of one sample [us] of ``spec``'s arm."""
    from freejoint_core.spatial_law import task_conditioning
    q = sm.postures(spec, 0)
    t0 = time.perf_counter()
    sm.evaluate(spec, q)
    fast = (time.perf_counter() - t0) / len(q) * 1e6
    arm, reach, zero = spec.arm, spec.reach, np.zeros(spec.arm.n)
    t0 = time.perf_counter()
    for x in q[:LAW_SAMPLES]:
        da, _, maa = arm.decoupling(arm.terms(x, zero))
        task_conditioning(da, maa, reach)
    law = (time.perf_counter() - t0) / LAW_SAMPLES * 1e6
    return fast, law


def timed(fun):
    """Return (result, wall [s], CPU of this process [s], load before, load after)."""
    load0 = _load()
    c0 = os.times()
    t0 = time.perf_counter()
    out = fun()
    wall = time.perf_counter() - t0
    c1 = os.times()
    return out, wall, (c1.user + c1.system) - (c0.user + c0.system), load0, _load()


def same(a, b):
    """Return True if two maps are equal, array for array."""
    return (a.samples, a.near, a.kappa_max) == (b.samples, b.near, b.kappa_max) and all(
        np.array_equal(getattr(a, k), getattr(b, k))
        for k in ('hist', 'voxels', 'count', 'near_count', 'kappa_low', 'worst'))


def run():
    """Return the benchmark rows for bench/run_all.py (one measurement each)."""
    rows = []
    for name, free in ARMS:
        spec = sm.known_spec(name, [free], samples=CHUNK, chunk=CHUNK)
        sm.evaluate(spec, sm.postures(spec, 0)[:10])   # warm-up
        fast, law = per_sample_us(spec)
        rows.append({'name': f'spatial map {name}: per sample (map path)', 'value': fast,
                     'unit': 'us', 'target': None})
        rows.append({'name': f'spatial map {name}: per sample (law path, per tick)',
                     'value': law, 'unit': 'us', 'target': None})
    spec = sm.known_spec('ur5', ['wrist_2_joint'], samples=100000, chunk=CHUNK)
    _, wall, _, _, _ = timed(lambda: sm.compute_map(spec))
    rows.append({'name': 'spatial map ur5: 10^5 samples in process', 'value': wall,
                 'unit': 's', 'target': None})
    return rows


def main(argv=None):
    """Measure and print the figures (module notes)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument('--samples', type=int, default=1000000)
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--arm', default='ur5', choices=[a for a, _ in ARMS],
                    help='the arm of the whole-map figures')
    ap.add_argument('--ray', action='store_true', help='also on a two-node Ray cluster')
    ap.add_argument('--workers', type=int, default=0, help='also in N worker processes')
    ap.add_argument('--quick', action='store_true', help='only run(): the make bench rows')
    args = ap.parse_args(argv)
    if args.quick:
        print_rows(run())
        return 0
    print(f'{os.cpu_count()} cores, load average {_load():.2f} at start', flush=True)
    for name, free in ARMS:
        spec = sm.known_spec(name, [free], samples=CHUNK, chunk=CHUNK)
        sm.evaluate(spec, sm.postures(spec, 0)[:10])
        runs = []
        for _ in range(args.repeats):
            load0 = _load()
            runs.append(per_sample_us(spec) + (load0, _load()))
        fast = [r[0] for r in runs]
        law = [r[1] for r in runs]
        print(f'{name} ({free} free): per sample, map path {", ".join(f"{v:.1f}" for v in fast)}'
              f' us (worst {max(fast):.1f}); law path {", ".join(f"{v:.1f}" for v in law)} us '
              f'(worst {max(law):.1f}); load {min(r[2] for r in runs):.2f}-'
              f'{max(r[3] for r in runs):.2f}', flush=True)
    free = dict(ARMS)[args.arm]
    spec = sm.known_spec(args.arm, [free], samples=args.samples, chunk=CHUNK)
    ref = None
    walls = []
    for _ in range(args.repeats):
        out, wall, cpu, l0, l1 = timed(lambda: sm.compute_map(spec))
        walls.append(wall)
        if ref is None:
            ref = out
        print(f'{args.arm}: {args.samples} samples in process: {wall:.1f} s wall, {cpu:.1f} s '
              f'CPU ({wall / args.samples * 1e6:.1f} us a sample), load {l0:.2f}-{l1:.2f}, '
              f'same map as the first: {same(out, ref)}', flush=True)
    print(f'  worst {max(walls):.1f} s', flush=True)
    print('\n'.join('  ' + line for line in ref.summary(0)), flush=True)
    if args.workers:
        walls = []
        for _ in range(args.repeats):
            out, wall, _, l0, l1 = timed(lambda: sm.compute_map(spec, args.workers))
            walls.append(wall)
            print(f'{args.arm}: {args.samples} samples in {args.workers} worker processes: '
                  f'{wall:.1f} s wall, load {l0:.2f}-{l1:.2f}, same map as in process: '
                  f'{same(out, ref)}', flush=True)
        print(f'  worst {max(walls):.1f} s', flush=True)
    if not args.ray:
        return 0
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from campaign import Cluster
    from freejoint_tools.spatial_map import ray_map
    cluster = None
    try:
        cluster = Cluster()
        t0 = time.perf_counter()
        cluster.start()
        print(f'Ray cluster up in {time.perf_counter() - t0:.1f} s: {cluster.address}, '
              f'2 nodes x 1 CPU, load {_load():.2f}', flush=True)
        walls = []
        for _ in range(args.repeats):
            out, wall, _, l0, l1 = timed(lambda: ray_map(spec, cluster.address))
            walls.append(wall)
            print(f'{args.arm}: {args.samples} samples on Ray, 2 workers: {wall:.1f} s wall '
                  f'(ray.init to shutdown), load {l0:.2f}-{l1:.2f}, same map as in process: '
                  f'{same(out, ref)}', flush=True)
        print(f'  worst {max(walls):.1f} s', flush=True)
    finally:
        if cluster is not None:
            cluster.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
