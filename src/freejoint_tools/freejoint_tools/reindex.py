"""
reindex: finalise the bag of a recorder that was killed (what ``ros2 bag reindex`` does).

A recorder killed without warning (SIGKILL, power loss) leaves ``<bag>/<bag>_0.mcap``
without its summary and footer (its last chunk possibly cut short) and no
``metadata.yaml``: rosbags and mcap's indexed reader refuse such a file. ``reindex <bag>``
reads the MCAP file (plain or zstd chunks) with mcap's StreamReader (:func:`scan_mcap`, the
pass :func:`open_bag` makes over a cut bag too) up to where it is cut, keeps every complete
chunk (a chunk with all its message indexes; a whole last chunk whose indexes were cut
short gets them rebuilt from its messages), cuts off the incomplete tail, appends the
summary (schemas, channels, statistics, chunk and metadata indexes) and footer in place,
and writes ``metadata.yaml`` from what the file holds; the run information comes from the
MCAP run record (``freejoint_run``). Nothing is copied: it works on a full disk too. A
finalised bag is left as it is (exit 0).

Usage: ``ros2 run freejoint_tools reindex <bag directory>`` (or ``python -m
freejoint_tools.reindex``). One line per bag on stdout; an error is one line
``reindex: error: <file>: <problem>`` on stderr and exit code 1.
"""

import argparse
import glob
import os
import sys

from .bagfile import (_dump_yaml, bag_information, BagError, finalise_mcap, index_tail,
                      METADATA_FILE, open_bag, RESERVE_SUFFIX, scan_mcap, write_metadata_yaml)


def reindex(path, ros_distro=None):
    """
    Finalise the bag at ``path`` (directory) in place; return a one-line report.

    Raises
    ------
    BagError
        Naming the file: not a bag, several MCAP files, unreadable or unwritable.

    """
    path = os.fspath(path)
    if not os.path.isdir(path):
        raise BagError(path, 'no such bag directory')
    if os.path.exists(os.path.join(path, METADATA_FILE)):
        try:
            bag = open_bag(path)
        except BagError:
            bag = None
        if bag is not None and bag.finalised:
            return '%s: finalised already (%d messages), nothing to do' % (
                path, bag.message_count)
    files = sorted(f for f in os.listdir(path) if f.endswith('.mcap'))
    if not files:
        raise BagError(path, 'not a rosbag2 bag (no .mcap file)')
    if len(files) > 1:
        raise BagError(path, 'holds %d MCAP files (%s); only one-file bags are supported'
                       % (len(files), ', '.join(files)))
    mcap_path = os.path.join(path, files[0])
    contents = scan_mcap(mcap_path)
    if contents.header.profile != 'ros2':
        raise BagError(mcap_path, "MCAP profile is %r, not 'ros2' (not a ROS 2 bag)"
                       % contents.header.profile)
    indexed = index_tail(mcap_path, contents)
    cut = contents.size - contents.end if not indexed else 0
    topics = contents.topics()
    info = bag_information(files[0], [t for _, t in topics],
                           [contents.counts.get(cid, 0) for cid, _ in topics],
                           contents.start_ns, contents.end_ns, contents.run_record(),
                           ros_distro or os.environ.get('ROS_DISTRO') or 'jazzy')
    was_finalised = contents.finalised
    # the space the recorder kept for finalising (left behind when it was killed)
    for stale in glob.glob(os.path.join(glob.escape(path), '.*' + RESERVE_SUFFIX)):
        os.remove(stale)
    finalise_mcap(mcap_path, {'serialized_metadata': _dump_yaml(info)}, contents)
    write_metadata_yaml(path, info)
    what = ('MCAP file finalised already' if was_finalised else
            'summary rebuilt from %d complete chunk(s)%s%s' % (
                len(contents.chunk_indexes),
                ", the last one's message indexes rebuilt (cut short)" if indexed else '',
                ', incomplete tail of %d bytes cut off' % cut if cut else ''))
    return '%s: %d messages on %d topics; %s; metadata.yaml written' % (
        path, contents.message_count, len(topics), what)


def main(argv=None):
    """Reindex each bag given; exit 0, or 1 with one line if one cannot be."""
    parser = argparse.ArgumentParser(
        prog='reindex', description='Rebuild metadata.yaml and the MCAP summary of a bag '
        'whose recorder was killed (what ros2 bag reindex does).')
    parser.add_argument('bags', nargs='+', help='bag directories')
    args = parser.parse_args(argv)
    code = 0
    for bag in args.bags:
        try:
            print(reindex(bag))
        except BagError as exc:
            print('reindex: error: %s' % exc, file=sys.stderr)
            code = 1
    return code


if __name__ == '__main__':
    sys.exit(main())
