"""
Benchmark: a recorded bag's size and read time with plain and zstd MCAP chunks.

Each bag given is written again, once per compression, message for message with the same
chunk boundaries as the recording (a flush after each of its chunks, as the recorder's
``flush_period`` closed them) and the same topics, QoS and definitions; printed per bag
and compression: MCAP file size (bytes, and relative to the recording), the time to write
it, and the time to read every message back (``open_bag`` + ``Bag.messages``). Figures
only, nothing asserted.

Usage: ``. tools/env.sh && python bench/bag_compression.py [BAG ...]`` (default: the
bags of ``make demo``, bags/demo/horizontal and bags/demo/vertical).
"""

import argparse
import os
import shutil
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_BAGS = [os.path.join(ROOT, 'bags', 'demo', c) for c in ('horizontal', 'vertical')]


def rewrite(src, dst, compression):
    """Write the bag ``src`` again at ``dst`` with ``compression``; return seconds taken."""
    from mcap.reader import make_reader
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk, StreamReader

    from freejoint_tools.bagfile import BagWriter, open_bag
    bag = open_bag(src)
    start = time.perf_counter()
    writer = BagWriter(dst, bag.custom_data, chunk_size=1 << 30,
                       compression=compression)
    channels = {name: writer.add_topic(name, t.type, t.msgdef, t.type_hash, t.qos)
                for name, t in sorted(bag.topics.items())}
    with open(bag.files[0], 'rb') as fh:
        topics = {cid: c.topic for cid, c in make_reader(fh).get_summary().channels.items()}
        fh.seek(0)
        for record in StreamReader(fh, emit_chunks=True).records:
            if isinstance(record, Chunk):            # the recording's chunks, one by one
                for msg in breakup_chunk(record):
                    if isinstance(msg, Message):
                        writer.write(channels[topics[msg.channel_id]], msg.log_time,
                                     msg.data, msg.publish_time)
                writer.flush()
    writer.close()
    return time.perf_counter() - start


def read_all(path):
    """Return seconds to open the bag and read every message."""
    from freejoint_tools.bagfile import open_bag
    start = time.perf_counter()
    count = sum(1 for _ in open_bag(path).messages())
    return time.perf_counter() - start, count


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('bags', nargs='*', default=DEFAULT_BAGS)
    args = parser.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix='bag_compression_')
    try:
        print('%-40s %-5s %12s %7s %8s %8s %9s' % ('bag', 'chunk', 'MCAP bytes', 'ratio',
                                                   'write s', 'read s', 'messages'))
        for src in args.bags:
            original = None
            for compression in ('none', 'zstd'):
                dst = os.path.join(tmp, '%s_%s' % (os.path.basename(src), compression))
                wrote = rewrite(src, dst, compression)
                size = sum(os.path.getsize(os.path.join(dst, f)) for f in os.listdir(dst)
                           if f.endswith('.mcap'))
                original = original or size
                read, count = read_all(dst)
                print('%-40s %-5s %12d %7.3f %8.2f %8.2f %9d' % (
                    os.path.relpath(src, ROOT), compression, size, size / original, wrote,
                    read, count))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
