"""The graph's three nodes in one process (freejoint_bringup graph) run the lockstep loop."""
import os

from freejoint_core.offline import run_case
from freejoint_tools.harness import load_source
import numpy as np
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
DT_NS = 1_000_000


def _offline_settings():
    """Return the offline runner's settings of config/ (tools/demo.py computes them)."""
    return load_source(os.path.join(ROOT, 'tools', 'demo.py'),
                       'freejoint_demo').offline_settings()


def test_one_process_graph_reproduces_the_offline_run_and_stops_cleanly(
        procs, ros_node, wait):
    from freejoint_msgs.srv import PlanCircle
    from freejoint_common.contract import EE_POSITION, LOCKSTEP_WRITER_DEPTH
    from freejoint_common.contract import lockstep_writer_overrides, profile, to_ns
    from rclpy.experimental import EventsExecutor
    graph = procs.start_node('freejoint_bringup', 'graph', 'graph', [
        '--sim-params', os.path.join(CONFIG, 'sim.yaml'),
        '--controller-params', os.path.join(CONFIG, 'controller.yaml'),
        '--planner-params', os.path.join(CONFIG, 'planner.yaml'),
        '--planner', 'autostart=false',
        # ee_position's writer keeps every tick this test reads: the contract's 1 s of history
        # is lost to a reader that a loaded host stalls for longer (as every lockstep run's)
        '--sim', *(item.replace(':=', '=', 1) for item in lockstep_writer_overrides('sim'))])
    executor = EventsExecutor()
    executor.add_node(ros_node)

    def spin():
        executor.spin_once(timeout_sec=0.05)

    points = {}

    def on_point(msg):
        points.setdefault(to_ns(msg.header.stamp), (msg.point.x, msg.point.y))

    sub = ros_node.create_subscription(EE_POSITION.msg_type, EE_POSITION.name, on_point,
                                       profile(LOCKSTEP_WRITER_DEPTH))
    wait(lambda: sub.get_publisher_count() > 0 or graph.poll() is not None, 60.0,
         'the graph process to publish ee_position', spin=spin)
    assert graph.poll() is None, procs.log(graph)
    client = ros_node.create_client(PlanCircle, '/freejoint_planner/plan_circle')
    wait(client.service_is_ready, 30.0, 'the planner service', spin=spin)
    future = client.call_async(PlanCircle.Request(centre=[0.0, 0.0], radius=0.2,
                                                  duration=5.0, start_angle=0.0, direction=1,
                                                  execute=True))
    wait(future.done, 30.0, 'the plan_circle answer', spin=spin)
    assert future.result().accepted, future.result().reason
    n = 300
    try:
        wait(lambda: all(k * DT_NS in points for k in range(n)), 120.0,
             '%d ticks of ee_position' % n, spin=spin)
    except AssertionError as e:
        missing = [k for k in range(n) if k * DT_NS not in points]
        raise AssertionError('%s: %d ticks received, %d of the first %d missing from tick %d; '
                             'the graph %s; its log ends:\n%s' % (
                                 e, len(points), len(missing), n, missing[0],
                                 'running' if graph.poll() is None else 'exited',
                                 procs.log(graph)[-3000:])) from None
    assert procs.stop(graph) == 0
    log = procs.log(graph)
    assert 'simulator stopped' in log and 'controller stopped' in log, log
    _, trace = run_case('horizontal', 'robust', 0, record_trace=True, **_offline_settings())
    graph_p = np.array([points[k * DT_NS] for k in range(n)])
    assert np.max(np.abs(graph_p - trace['p'][:n])) <= 1e-9
