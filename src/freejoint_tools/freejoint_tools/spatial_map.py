"""
Sampled singularity map of a spatial arm on the command line, in process or on Ray.

The math is ``freejoint_core.spatial_map`` (module notes there); this is its runner::

    python -m freejoint_tools.spatial_map --arm ur5 --free wrist_2_joint
        --samples 100000 [--workers N | --ray [ADDRESS]] [--out FILE.npz]

In this process by default (the chunks one after the other), in ``--workers N`` worker
processes, or with ``--ray`` as one Ray task per chunk through the campaign engine's Ray
plumbing (``freejoint_tools.campaign.ray_tasks``: ``--ray`` alone starts Ray in this
process, ``--ray HOST:PORT`` or ``auto`` uses a running cluster, whose drivers need its
token: ``RAY_AUTH_MODE=token RAY_AUTH_TOKEN=...``, docs/campaigns.md).  The chunks merge
exactly whatever ran them: the map is the same in-process, on N workers or on Ray.

``--urdf PATH --base-link LINK --tip-link LINK`` maps another URDF's chain.  Prints the
summary (share below ``kappa_min``, ``kappa`` quantiles, the smallest ``kappa`` with its
posture, the voxels with the largest near-singular share); ``--out`` writes the map
(``freejoint_core.spatial_map.load`` reads it back).  A bad argument ends with one line
naming it, exit status 2.
"""

import argparse
import os
import sys
import time

from freejoint_core import spatial_map as core
from freejoint_core.errors import FreejointValueError


def _task(spec, index):
    """Return the map of chunk ``index`` (one Ray task)."""
    return core.map_chunk(spec, index)


def ray_map(spec, address='local', progress=None):
    """
    Compute a map on Ray: one task per chunk, merged in this process as they come back.

    Parameters
    ----------
    spec : freejoint_core.spatial_map.MapSpec
        The map.
    address : str
        Ray address (``local``, ``auto``, ``HOST:PORT``; ``campaign.ray_tasks``).
    progress : callable, optional
        Called with the samples done after each chunk.

    Returns
    -------
    freejoint_core.spatial_map.SingularityMap
        The same map as ``core.compute_map(spec)``.

    """
    from freejoint_tools.campaign import ray_tasks
    state = {'map': core.empty(spec), 'chunks': set()}

    def merge(index, part):
        if index in state['chunks']:      # a retried task's result counts once
            return
        state['chunks'].add(index)
        state['map'] = core.merge([state['map'], part])
        if progress:
            progress(state['map'].samples)

    ray_tasks(address, _task, spec, [(i, (i,)) for i in range(spec.chunks)], merge)
    if len(state['chunks']) != spec.chunks:
        raise RuntimeError(f'ray_map: {len(state["chunks"])} of {spec.chunks} chunks came back')
    return state['map']


def spec_from_args(args):
    """Return the ``MapSpec`` of parsed command-line arguments (raises FreejointValueError)."""
    common = {'samples': args.samples, 'seed': args.seed, 'chunk': args.chunk,
              'voxel': args.voxel, 'm': args.task_dim, 'scale': args.scale,
              'kappa_min': args.kappa_min}
    if args.urdf:
        if args.arm:
            raise FreejointValueError('arm: give --arm or --urdf, not both')
        if not (args.base_link and args.tip_link):
            raise FreejointValueError('urdf: --urdf needs --base-link and --tip-link')
        try:
            with open(args.urdf, encoding='utf-8') as fh:
                text = fh.read()
        except OSError as exc:
            raise FreejointValueError(f'urdf: cannot read {args.urdf!r} ({exc})') from None
        return core.MapSpec(text, args.base_link, args.tip_link, tuple(args.free),
                            name=os.path.basename(args.urdf), **common)
    if args.base_link or args.tip_link:
        raise FreejointValueError('base_link: --base-link and --tip-link go with --urdf')
    return core.known_spec(args.arm or 'ur5', args.free, **common)


def _parser():
    ap = argparse.ArgumentParser(
        prog='python -m freejoint_tools.spatial_map',
        description='Sampled singularity map of a spatial arm (kappa of the nominal model '
        'over postures uniform within the URDF limits; freejoint_core.spatial_map)')
    ap.add_argument('--arm', default=None, help='ur5 or panda (example-robot-data); '
                    'default ur5 unless --urdf')
    ap.add_argument('--urdf', default=None, help='a URDF file instead of --arm')
    ap.add_argument('--base-link', default=None)
    ap.add_argument('--tip-link', default=None)
    ap.add_argument('--free', action='append', default=[], metavar='JOINT',
                    help='a free (passive) joint; repeat for more')
    ap.add_argument('--samples', type=int, default=100000)
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--chunk', type=int, default=core.DEFAULT_CHUNK,
                    help='samples per chunk (default %(default)s; part of the sampling)')
    ap.add_argument('--voxel', type=float, default=core.DEFAULT_VOXEL,
                    help='voxel side [m] (default %(default)s)')
    ap.add_argument('--task-dim', type=int, default=3, choices=(3, 6),
                    help='task rows of kappa: 3 tip position (default), 6 with orientation')
    ap.add_argument('--scale', type=float, default=core.NOMINAL_SCALE,
                    help="nominal model factor (default %(default)s, the controller's)")
    ap.add_argument('--kappa-min', type=float, default=core.KAPPA_MIN,
                    help="near-singular threshold (default %(default)s, the law's)")
    run = ap.add_mutually_exclusive_group()
    run.add_argument('--workers', type=int, default=1,
                     help='worker processes (default 1: this process)')
    run.add_argument('--ray', nargs='?', const='local', default=None, metavar='ADDRESS',
                     help='on Ray: alone, Ray started in this process; or HOST:PORT, auto')
    ap.add_argument('--top', type=int, default=5, help='voxels listed (default %(default)s)')
    ap.add_argument('--out', default=None, help='write the map (.npz)')
    ap.add_argument('--quiet', action='store_true', help='no progress line')
    return ap


def main(argv=None):
    """Run the command line; return the exit status (2: a bad argument)."""
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        spec = spec_from_args(args)
        if args.top < 0:
            raise FreejointValueError(f'top: expected >= 0, got {args.top}')
        if args.out and not os.path.isdir(os.path.dirname(os.path.abspath(args.out))):
            raise FreejointValueError(f'out: no folder {os.path.dirname(args.out)!r}')
        if args.workers < 1:
            raise FreejointValueError(f'workers: expected >= 1, got {args.workers}')
    except FreejointValueError as exc:
        print(f'spatial_map: {exc}', file=sys.stderr)
        return 2

    def progress(done):
        if not args.quiet:
            print(f'\r{done}/{spec.samples} samples', end='', file=sys.stderr, flush=True)

    t0 = time.monotonic()
    if args.ray:
        where = f'Ray ({args.ray})'
        result = ray_map(spec, args.ray, progress)
    else:
        where = f'{args.workers} worker process(es)' if args.workers > 1 else 'this process'
        result = core.compute_map(spec, args.workers, progress)
    wall = time.monotonic() - t0
    if not args.quiet:
        print(file=sys.stderr)
    print('\n'.join(result.summary(args.top)))
    print(f'{spec.samples} samples in {wall:.1f} s ({wall / spec.samples * 1e6:.1f} us a '
          f'sample, {where})')
    if args.out:
        result.save(args.out)
        print(f'map: {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
