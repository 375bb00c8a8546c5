"""
Measure how fast the planner streams setpoints in sim time (a benchmark helper, not a test).

Starts `planner_node` (use_sim_time, the paper's circle) and drives `/clock` from here:

* closed loop: publish /clock = k dt, wait for the setpoint of tick k + lookahead, repeat
  (the planner's trigger -> publish -> delivery round trip, as in lockstep);
* open loop: advance /clock one tick at a fixed rate (1, 2, 5, 10 kHz) for a while and
  count what arrives; "keeps up" means the last setpoint stays within the lookahead.

Usage: `. tools/env.sh && python test/nodes/planner_rate.py [--ticks 3000] [--seconds 2]`.
Prints one line per measurement and a JSON summary on the last line.
"""
import argparse
import json
import os
import signal
import subprocess
import sys
import time

from freejoint_msgs.msg import CartesianSetpoint
import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EXE = os.path.join(ROOT, 'install', 'freejoint_planner', 'lib', 'freejoint_planner',
                   'planner_node')
MS = 1_000_000
LOOKAHEAD = 20


def _stamp(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def _cpu_s(pid):
    """Return user + system CPU time (s) of a process so far (Linux /proc)."""
    with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--ticks', type=int, default=3000, help='closed-loop ticks')
    ap.add_argument('--seconds', type=float, default=2.0, help='open-loop time per rate')
    ap.add_argument('--rates', default='1000,2000,5000,10000', help='open-loop rates (Hz)')
    args = ap.parse_args()
    # 215-232: valid on Linux and outside the 1-100 the test runs take (test/conftest.py)
    os.environ.setdefault('ROS_DOMAIN_ID', str(215 + os.getpid() % 18))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    planner = subprocess.Popen([EXE, '--ros-args', '-p', 'use_sim_time:=true',
                                '-p', 'duration:=1000.0'],
                               stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    rclpy.init()
    node = rclpy.create_node('planner_rate_probe')
    executor = EventsExecutor()
    executor.add_node(node)
    spin_once = executor.spin_once
    state = {'last': -1, 'count': 0}

    def on_setpoint(msg):
        state['last'] = _stamp(msg)
        state['count'] += 1

    node.create_subscription(CartesianSetpoint, 'setpoint', on_setpoint,
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    pub = node.create_publisher(Clock, '/clock', 1000)
    summary = {}
    try:
        deadline = time.monotonic() + 30.0
        while pub.get_subscription_count() < 2 and time.monotonic() < deadline:
            spin_once(timeout_sec=0.05)

        def publish(now_ns):
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(now_ns, 1_000_000_000)
            pub.publish(msg)

        while state['last'] < LOOKAHEAD * MS and time.monotonic() < deadline:
            publish(0)
            spin_once(timeout_sec=0.05)
        if state['last'] < LOOKAHEAD * MS:
            sys.exit('planner did not answer /clock within 30 s')
        # closed loop
        k = 0
        cpu0 = _cpu_s(planner.pid)
        start = time.perf_counter()
        for k in range(1, args.ticks + 1):
            publish(k * MS)
            while state['last'] < (k + LOOKAHEAD) * MS:
                spin_once(timeout_sec=1.0)
        elapsed = time.perf_counter() - start
        cpu = (_cpu_s(planner.pid) - cpu0) / args.ticks
        rate = args.ticks / elapsed
        print(f'closed loop: {args.ticks} ticks in {elapsed:.3f} s = {rate:.0f} ticks/s '
              f'({elapsed / args.ticks * 1e6:.0f} us per /clock -> setpoint round trip); '
              f'planner CPU {cpu * 1e6:.0f} us per tick (at most {1 / cpu:.0f} ticks/s '
              'on one free core)')
        summary['closed_loop_ticks_per_s'] = round(rate)
        summary['planner_cpu_us_per_tick'] = round(cpu * 1e6)
        # open loop
        for hz in (int(r) for r in args.rates.split(',')):
            n = int(hz * args.seconds)
            first = k + 1
            count0 = state['count']
            start = time.perf_counter()
            max_lag = 0
            for i in range(n):
                k = first + i
                publish(k * MS)
                due = start + (i + 1) / hz
                while True:
                    spin_once(timeout_sec=0.0)
                    if time.perf_counter() >= due:
                        break
                max_lag = max(max_lag, k + LOOKAHEAD - state['last'] // MS)
            sent_s = time.perf_counter() - start
            settle = time.monotonic() + 5.0
            while state['last'] < (k + LOOKAHEAD) * MS and time.monotonic() < settle:
                spin_once(timeout_sec=0.01)
            got = state['count'] - count0
            summary[f'open_loop_{hz}_hz_received'] = got
            print(f'open loop {hz:5d} Hz: sent {n} /clock in {sent_s:.2f} s '
                  f'({n / sent_s:.0f}/s), received {got} setpoints, max lag behind '
                  f'now + lookahead {max_lag} ticks, caught up: '
                  f'{state["last"] >= (k + LOOKAHEAD) * MS}')
            summary[f'open_loop_{hz}_hz_max_lag_ticks'] = max_lag
            summary[f'open_loop_{hz}_hz_sent_per_s'] = round(n / sent_s)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        planner.send_signal(signal.SIGINT)
        planner.wait(10)
    print(json.dumps(summary))


if __name__ == '__main__':
    main()
