"""
Measure how fast the planner streams setpoints in sim time (a benchmark helper, not a test).

Starts `planner_node` (use_sim_time, the paper's circle) and drives `/clock` from here:

* closed loop: publish /clock = k dt, wait for the setpoint of tick k + lookahead, repeat
  (the planner's trigger -> publish -> delivery round trip, as in lockstep);
* open loop: advance /clock one tick at a fixed rate (1, 2, 5, 10 kHz) for a while and
  count what arrives; "keeps up" means the last setpoint stays within the lookahead;
* replan: ``--replans`` ``~/plan_circle`` calls (execute) while the circle moves, one every
  1.3 s of sim time (/clock every 10 ticks between them): the answer time (the transition
  search from the current setpoint state), accepted / refused, and the largest change
  between consecutive setpoints vs the quintic circle's own.

Usage: `. tools/env.sh && python test/nodes/planner_rate.py [--ticks 3000] [--seconds 2]
[--replans 12]`.
Prints one line per measurement and a JSON summary on the last line.
"""
import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time

from freejoint_common.contract import CLOCK, profile, setpoint_samples, SETPOINTS
from freejoint_common.contract import stamp_from_ns
from freejoint_core.trajectory import CircleQuintic
from freejoint_msgs.srv import PlanCircle
import rclpy
from rclpy.experimental import EventsExecutor

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
EXE = os.path.join(ROOT, 'install', 'freejoint_planner', 'lib', 'freejoint_planner',
                   'planner_node')
MS = 1_000_000
LOOKAHEAD = 20


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
    ap.add_argument('--replans', type=int, default=12, help='plan_circle calls while moving')
    args = ap.parse_args()
    # 215-232: valid on Linux and outside the 1-100 the test runs take (test/conftest.py)
    os.environ.setdefault('ROS_DOMAIN_ID', str(215 + os.getpid() % 18))
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    planner = subprocess.Popen([EXE, '--ros-args', '-p', 'use_sim_time:=true',
                                '-p', 'duration:=60.0'],
                               stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    rclpy.init()
    node = rclpy.create_node('planner_rate_probe')
    executor = EventsExecutor()
    executor.add_node(node)
    spin_once = executor.spin_once
    state = {'last': -1, 'count': 0, 'p': None, 'step': 0.0}

    def on_setpoint(msg):
        stamp = msg.stamp_ns
        if state['p'] is not None and stamp == state['last'] + MS:
            state['step'] = max(state['step'], math.hypot(msg.position[0] - state['p'][0],
                                                          msg.position[1] - state['p'][1]))
        state['p'] = tuple(msg.position)
        state['last'] = stamp
        state['count'] += 1

    def on_setpoints(msg):
        for sp in setpoint_samples(msg):
            on_setpoint(sp)

    node.create_subscription(SETPOINTS.msg_type, SETPOINTS.name, on_setpoints, profile(1000))
    pub = node.create_publisher(CLOCK.msg_type, CLOCK.name, CLOCK.qos)
    summary = {}
    try:
        deadline = time.monotonic() + 30.0
        # the planner takes /clock once (its own subscription; rclpy's TimeSource detached)
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            spin_once(timeout_sec=0.05)

        def publish(now_ns):
            msg = CLOCK.msg_type(clock=stamp_from_ns(now_ns))
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
        # replan while moving
        client = node.create_client(PlanCircle, '/freejoint_planner/plan_circle')
        ready = time.monotonic() + 30.0
        while not client.service_is_ready() and time.monotonic() < ready:
            spin_once(timeout_sec=0.05)
        circles = [((0.05, 0.05), math.pi / 2, 1), ((-0.05, 0.02), math.pi, -1),
                   ((0.02, -0.06), -math.pi / 2, 1), ((0.0, 0.0), 0.0, -1)]
        state['step'] = 0.0
        k = (k + 9) // 10 * 10
        times, accepted = [], 0
        for i in range(args.replans):
            centre, angle, direction = circles[i % len(circles)]
            start = time.perf_counter()
            future = client.call_async(PlanCircle.Request(
                centre=list(centre), radius=0.2, duration=5.0, start_angle=angle,
                direction=direction, execute=True))
            while not future.done():
                spin_once(timeout_sec=0.1)
            times.append(time.perf_counter() - start)
            accepted += bool(future.result().accepted)
            for _ in range(130):                          # 1.3 s of sim time
                k += 10
                publish(k * MS)
                while state['last'] < (k + LOOKAHEAD) * MS:
                    spin_once(timeout_sec=1.0)
        ref = [CircleQuintic().sample_tuple(j * 1e-3)[:2] for j in range(5002)]
        own = max(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(ref, ref[1:]))
        times.sort()
        print(f'replan: {args.replans} plan_circle calls every 1.3 s while moving: '
              f'{accepted} accepted; answer median {times[len(times) // 2] * 1e3:.1f} ms, '
              f'max {times[-1] * 1e3:.1f} ms; largest setpoint step '
              f'{state["step"] * 1e3:.6f} mm (the circle\'s own {own * 1e3:.6f} mm)')
        summary['replan_accepted'] = accepted
        summary['replan_answer_median_ms'] = round(times[len(times) // 2] * 1e3, 1)
        summary['replan_answer_max_ms'] = round(times[-1] * 1e3, 1)
        summary['replan_largest_step_mm'] = state['step'] * 1e3
        summary['circle_own_step_mm'] = own * 1e3
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        planner.send_signal(signal.SIGINT)
        planner.wait(10)
    print(json.dumps(summary))


if __name__ == '__main__':
    main()
