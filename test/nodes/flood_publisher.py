"""
Publish std_msgs/String on one topic as fast as possible, best effort, keep-last 1.

What makes a reader lose messages for real once it is starved of CPU (the transport's
queue to it overflows, and the samples it then receives skip sequence numbers, which the
middleware reports lost). Flooding alone does not do it on a fast machine: the reader's
receive thread can keep up.

Usage: flood_publisher.py --topic NAME --seconds S --summary FILE [--progress FILE]
[--stop-file FILE]

It waits (up to 30 s) for a matched subscription, prints ``flooding NAME`` when it starts
publishing, publishes for S seconds (or until the stop file exists, checked every
:data:`EVERY` messages), writes the count published so far to the progress file every
:data:`EVERY` messages (a test stopping the reader until a given number went by: a starved
machine publishes fewer per second), writes ``{"published": N}`` to the summary and exits
0 (1 if nothing matched).
"""

import argparse
import json
import os
import sys
import time

from freejoint_common.contract import profile
import rclpy
from std_msgs.msg import String

FLOOD_QOS = profile(1, reliable=False)
EVERY = 200
"""Messages between two writes of the progress file and two looks for the stop file."""


def main():
    """Flood ``--topic`` for ``--seconds``; write the count published."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--topic', required=True)
    parser.add_argument('--seconds', type=float, required=True)
    parser.add_argument('--summary', required=True)
    parser.add_argument('--progress')
    parser.add_argument('--stop-file')
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node('flood_publisher')
    pub = node.create_publisher(String, args.topic, FLOOD_QOS)
    deadline = time.monotonic() + 30.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    if pub.get_subscription_count() == 0:
        print('flood_publisher: no subscription on %s within 30 s' % args.topic,
              file=sys.stderr)
        return 1
    msg = String(data='x' * 64)
    print('flooding %s' % args.topic, flush=True)
    count = 0
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        pub.publish(msg)
        count += 1
        if count % EVERY == 0:
            if args.progress:
                with open(args.progress + '.tmp', 'w') as fh:
                    fh.write(str(count))
                os.replace(args.progress + '.tmp', args.progress)
            if args.stop_file and os.path.exists(args.stop_file):
                break
    with open(args.summary, 'w') as fh:
        json.dump({'published': count}, fh)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
