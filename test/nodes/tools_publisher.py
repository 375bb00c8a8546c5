"""
A lockstep-like run without the real nodes: publishes what the graph publishes per tick.

Per control tick k (stamp t_k = k * dt): ``/clock`` (if --clock), ``joint_states``
(sensor_msgs/JointState, joints joint1..3), ``setpoints``
(freejoint_msgs/CartesianSetpoints of the tick's one setpoint, transient local) and
``controller_state`` (freejoint_msgs/ControllerState), each reliable keep-last 100 (the
graph's is 1000, ``freejoint_common.contract.STREAM_DEPTH``: a shallower history shows an
overrun sooner); before the ticks, once, the latched ``semi_singular_map``
(nav_msgs/OccupancyGrid) and ``planned_path`` (visualization_msgs/Marker), transient local
depth 1. Message contents are a pure function of k (:func:`tick_messages`).

Usage: tools_publisher.py --ticks N --rate HZ [--clock] [--subscribers M] [--summary FILE]
                          [--setpoint-volatile] [--recorder NODE]

It waits (up to 30 s) until every tick topic (and /clock) has at least M matched
subscriptions - and, with --recorder, until that recorder's ``~/status`` says its
subscriptions have matched their publishers (the readers' side of the match, which can
complete well after the writers' side: a message published before it is not received) -
then publishes the ticks at HZ (0: as fast as it can), waits until every
message is acknowledged, writes a JSON summary (per topic: messages published and the CDR bytes of
the last one, hex) and exits; or publishes until SIGINT with --ticks 0.
"""

import argparse
import json
import math
import signal
import sys
import time

from freejoint_common.contract import LATCHED_QOS, profile, stamp_from_ns
from freejoint_msgs.msg import CartesianSetpoints, ControllerState
from nav_msgs.msg import OccupancyGrid
import rclpy
from rclpy.serialization import serialize_message
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

DT_NS = 1_000_000
TICK_TOPICS = ('/joint_states', '/setpoints', '/controller_state')


def tick_messages(k):
    """Return ``(JointState, CartesianSetpoints, ControllerState)`` of tick k."""
    t_ns = k * DT_NS
    js = JointState()
    stamp_from_ns(t_ns, js.header.stamp)
    js.name = ['joint1', 'joint2', 'joint3']
    js.position = [0.1 * math.sin(k / 100.0), 1.0 + 0.2 * math.cos(k / 100.0),
                   0.5 * math.sin(k / 50.0)]
    js.velocity = [0.01 * k, -0.02 * k, 0.03 * k]
    js.effort = [math.sin(k), math.cos(k), 0.0]
    a = 2.0 * math.pi * (k % 5000) / 5000.0
    sp = CartesianSetpoints()
    sp.header.stamp = js.header.stamp
    sp.header.frame_id = 'base_link'
    sp.stamps = [t_ns]
    sp.position = [0.2 * math.cos(a), 0.2 * math.sin(a)]
    sp.velocity = [-0.2 * math.sin(a), 0.2 * math.cos(a)]
    sp.acceleration = [-0.2 * math.cos(a), -0.2 * math.sin(a)]
    sp.plan_id = [1]
    sp.plan_time = [t_ns * 1e-9]
    sp.final = [False]
    cs = ControllerState()
    cs.header.stamp = js.header.stamp
    cs.position_desired = sp.position
    cs.position_planned = sp.position
    cs.position = [sp.position[0] + 1e-3 * math.sin(k / 7.0),
                   sp.position[1] - 1e-3 * math.cos(k / 11.0)]
    cs.error = [cs.position[0] - sp.position[0], cs.position[1] - sp.position[1]]
    # Every task vector filled, as the controller does (m values): an empty float64[] is
    # serialized by these rclpy wheels with an alignment rosbags does not expect.
    cs.error_rate = [1e-2 * math.cos(k / 7.0), 2e-3 * math.sin(k / 11.0)]
    cs.sliding = [cs.error_rate[0] + 50.0 * cs.error[0], cs.error_rate[1] + 50.0 * cs.error[1]]
    cs.effort = [2.0 * math.sin(k / 13.0), -1.5 * math.cos(k / 17.0)]
    cs.joint_names = ['joint1', 'joint2']
    cs.law_state_names = ['theta_hat[%d]' % i for i in range(5)] + [
        'rho_hat', 'delta_v[0]', 'delta_v[1]']
    cs.law_state = [1e-5 * k, 2e-5 * k, 0.0, 1e-6 * k, 0.5, 0.25, -0.1, 0.1]
    cs.det_dd = 1e-3 + 1e-4 * math.sin(k / 3.0)
    cs.status = k % 2
    cs.message = '' if k % 2 == 0 else 'near singular'
    return js, sp, cs


def latched_messages():
    """Return the ``(OccupancyGrid, Marker)`` published once before the ticks."""
    grid = OccupancyGrid()
    grid.header.frame_id = 'base_link'
    grid.info.resolution = 0.05
    grid.info.width = 8
    grid.info.height = 6
    grid.info.origin.position.x = -0.2
    grid.info.origin.position.y = -0.15
    grid.data = [(i * 37) % 101 if i % 5 else -1 for i in range(48)]
    marker = Marker()
    marker.header.frame_id = 'base_link'
    marker.ns = 'planned_path'
    marker.type = Marker.LINE_STRIP
    marker.scale.x = 0.005
    marker.color.g = 1.0
    marker.color.a = 1.0
    return grid, marker


def recorder_ready(node, name, deadline, stop):
    """Call ``<name>/status`` until it answers success; return False at the deadline."""
    client = node.create_client(Trigger, name + '/status')
    try:
        while time.monotonic() < deadline and not stop:
            if client.wait_for_service(timeout_sec=0.1):
                future = client.call_async(Trigger.Request())
                rclpy.spin_until_future_complete(node, future, timeout_sec=max(
                    0.0, deadline - time.monotonic()))
                if future.done() and future.result().success:
                    print('tools_publisher: %s/status: %s'
                          % (name, future.result().message), flush=True)
                    return True
                time.sleep(0.05)   # poll period of the status, not a settle time
        return False
    finally:
        node.destroy_client(client)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument('--ticks', type=int, default=1000)
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--clock', action='store_true')
    parser.add_argument('--subscribers', type=int, default=1)
    parser.add_argument('--summary', default='')
    parser.add_argument('--setpoint-volatile', action='store_true',
                        help='offer setpoints volatile (not the graph contract)')
    parser.add_argument('--recorder', default='',
                        help="also wait until this recorder node's ~/status answers success")
    opts = parser.parse_args()
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('tools_publisher')
    # Depth 100, not the graph's 1000: an overloaded machine overflows this history, which
    # the recorder must then report (test_recorder). setpoints transient local as the
    # planner offers it (docs/GRAPH.md) unless --setpoint-volatile.
    tick_qos = profile(100)
    setpoint_qos = profile(100, latched=not opts.setpoint_volatile)
    latched = LATCHED_QOS
    pubs = {
        '/joint_states': node.create_publisher(JointState, '/joint_states', tick_qos),
        '/setpoints': node.create_publisher(CartesianSetpoints, '/setpoints', setpoint_qos),
        '/controller_state': node.create_publisher(ControllerState, '/controller_state',
                                                   tick_qos),
        '/semi_singular_map': node.create_publisher(OccupancyGrid, '/semi_singular_map',
                                                    latched),
        '/planned_path': node.create_publisher(Marker, '/planned_path', latched),
    }
    if opts.clock:
        pubs['/clock'] = node.create_publisher(Clock, '/clock', tick_qos)
    last = {}
    count = dict.fromkeys(pubs, 0)

    def publish(topic, msg):
        pubs[topic].publish(msg)
        count[topic] += 1
        last[topic] = msg

    grid, marker = latched_messages()
    publish('/semi_singular_map', grid)
    publish('/planned_path', marker)
    deadline = time.monotonic() + 30.0
    waited = TICK_TOPICS + (('/clock',) if opts.clock else ())
    while any(pubs[t].get_subscription_count() < opts.subscribers for t in waited):
        if time.monotonic() > deadline or stop:
            print('tools_publisher: no subscriber within 30 s', file=sys.stderr, flush=True)
            return 2
        time.sleep(0.01)
    if opts.recorder and not recorder_ready(node, opts.recorder, deadline, stop):
        print('tools_publisher: %s/status not ready within 30 s' % opts.recorder,
              file=sys.stderr, flush=True)
        return 2
    time.sleep(0.2)   # let the subscriptions' reliable handshakes settle
    print('tools_publisher: publishing', flush=True)
    t0 = time.monotonic()
    k = 0
    while (opts.ticks <= 0 or k < opts.ticks) and not stop:
        js, sp, cs = tick_messages(k)
        if opts.clock:
            clock = Clock()
            clock.clock = js.header.stamp
            publish('/clock', clock)
        publish('/joint_states', js)
        publish('/setpoints', sp)
        publish('/controller_state', cs)
        k += 1
        if opts.rate > 0:
            due = t0 + k / opts.rate
            while True:
                left = due - time.monotonic()
                if left <= 0:
                    break
                time.sleep(left if left > 0.002 else 0)
    elapsed = time.monotonic() - t0
    for pub in pubs.values():
        pub.wait_for_all_acked(rclpy.duration.Duration(seconds=10.0))
    summary = {'ticks': k, 'seconds': elapsed,
               'topics': {t: {'count': count[t],
                              'last': serialize_message(last[t]).hex() if t in last else ''}
                          for t in pubs}}
    if opts.summary:
        with open(opts.summary, 'w') as fh:
            json.dump(summary, fh)
    print('tools_publisher: published %d ticks in %.3f s' % (k, elapsed), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
