"""
A recording of the real lockstep graph gives the same record as its live messages.

The run is started (planner ``~/plan_circle``) only once the recorder's ``~/status`` says
every graph topic has a matched publisher, as a launcher that must lose nothing does.
"""
import os

from freejoint_common.contract import NEVER_QUIET_TOPICS
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
TICKS = 400
SETTLE = 1.0
"""Wall seconds between the recorder's readiness and the start of the run."""
HOLD_AFTER = 60
"""Ticks the simulator runs past TICKS before it holds (``max_steps``)."""


def test_bag_of_the_lockstep_graph_gives_the_live_record(procs, ros_node, wait, tmp_path,
                                                         same_record, start_circle,
                                                         recorder_drained, plan_check,
                                                         analyze):
    import rclpy
    from freejoint_common.contract import CONTROLLER_STATE, JOINT_STATES, profile

    from freejoint_common.records import arrays_from_messages, stamp_ns
    from freejoint_core.metrics import compute_record
    from freejoint_tools.analyze import analyse_bag
    from freejoint_tools.bagfile import open_bag
    live = {'states': [], 'joints': []}
    ros_node.create_subscription(CONTROLLER_STATE.msg_type, '/' + CONTROLLER_STATE.name,
                                 live['states'].append, profile(10000))
    ros_node.create_subscription(JOINT_STATES.msg_type, '/' + JOINT_STATES.name,
                                 live['joints'].append, profile(10000))
    bag_path = str(tmp_path / 'horizontal')
    recorder = procs.start_node('freejoint_tools', 'recorder', 'recorder', [
        '--ros-args', '-p', 'output:=%s' % bag_path, '-p', 'topics:=[]',
        '-p', 'exclude:=[%s]' % ', '.join(NEVER_QUIET_TOPICS),
        '-p', 'use_sim_time:=true',
        '-p', 'custom_data:=[case=horizontal, variant=robust, seed=0, max_ticks=%d]' % TICKS])
    wait(lambda: 'recording into' in procs.log(recorder), 30.0, 'the recorder')
    nodes = []
    extra = {'planner_node': ['-p', 'autostart:=false'],
             'sim_node': ['-p', 'max_steps:=%d' % (TICKS + HOLD_AFTER)]}
    for pkg, exe, conf in (('freejoint_planner', 'planner_node', 'planner.yaml'),
                           ('freejoint_sim', 'sim_node', 'sim.yaml'),
                           ('freejoint_control', 'controller_node', 'controller.yaml')):
        nodes.append(procs.start_node(pkg, exe, exe, [
            '--ros-args', '--params-file', os.path.join(CONFIG, conf)] + extra.get(exe, [])))

    # The recorder's readers have matched every publisher; the publishers' side of the match
    # (what makes a volatile writer send to it) can lag by tens of ms: let it settle.
    start_circle(SETTLE)
    wait(lambda: len(live['states']) > TICKS + HOLD_AFTER // 2, 120.0,
         'the graph to run %d ticks (sim: %s)' % (TICKS, procs.log(nodes[1])[-500:]),
         spin=lambda: rclpy.spin_once(ros_node, timeout_sec=0.01))
    # The simulator holds at max_steps: once the recorder's count is steady it has taken
    # every message (a node stopped earlier takes its unacknowledged samples with it).
    count, _ = recorder_drained(None, 60.0)       # recorder.REPAIR_QUIET
    assert count is not None, 'the recorder did not answer ~/status'
    for proc in reversed(nodes):
        procs.stop(proc)
    assert procs.stop(recorder) == 0
    bag = open_bag(bag_path)
    assert bag.finalised
    recorded = {stamp_ns(m) for _, m in bag.decode('/controller_state')}
    assert {stamp_ns(m) for m in live['states']} <= recorded
    assert min(recorded) == 0
    graph = compute_record('horizontal', 'robust', 0, source='graph', **arrays_from_messages(
        live['states'], live['joints'], 'joint3', max_ticks=TICKS))
    record, trace, warnings = analyse_bag(bag_path)
    assert warnings == []
    same_record(record, graph)

    # Against the plan: what make analyze prints is the independent per-sample check; in
    # lockstep every state has the setpoint of its own stamp, which the controller reports
    # as position_planned.
    check = plan_check.independent(bag_path, bound_mm=trace['plan']['bound_mm'])
    done = analyze(bag_path, '--no-plots')
    assert done.returncode == 0, done.stderr
    plan_check.assert_printed_equals(plan_check.analyze_line(done, 'horizontal'), check)
    assert check[3] > 0                                     # the circle moved
    setpoints = {}
    for _, msg in bag.decode('/setpoints'):
        for i, ns in enumerate(msg.stamps):
            setpoints[int(ns)] = list(msg.position[2 * i:2 * i + 2])
    planned = [(stamp_ns(m), list(m.position_planned)) for _, m in
               bag.decode('/controller_state') if len(m.position_planned)]
    assert len(planned) > TICKS // 2
    assert all(setpoints[ns] == p for ns, p in planned)
