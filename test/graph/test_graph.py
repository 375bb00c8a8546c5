"""
The node graph: simulator, controller and the real planner as separate processes.

They are started as ``ros2 run`` starts them, with the parameter files of ``config/``. In
lockstep the graph must reproduce the offline runner (``freejoint_core.offline``) exactly,
whatever the start order and whatever the order of the joints in the JointState; in real
time, a silent controller must leave the arm with zero effort.
"""
import functools
import os
import re

from freejoint_common.contract import clock_ns, JOINT_STATES
from freejoint_common.records import arrays_from_messages
from freejoint_core.metrics import compute_record, KEYS
from freejoint_core.offline import run_case
from freejoint_tools.harness import load_source
import numpy as np
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONFIG = os.path.join(ROOT, 'config')
RELAY = os.path.join(ROOT, 'test', 'nodes', 'ctl_joint_relay.py')
DT_NS = 1_000_000
NODES = {
    'sim': ('freejoint_sim', 'sim_node', 'sim.yaml', 'simulator ready'),
    'controller': ('freejoint_control', 'controller_node', 'controller.yaml',
                   'controller ready'),
    'planner': ('freejoint_planner', 'planner_node', 'planner.yaml', 'ready:'),
}
SIM_COMMAND_TIMEOUT = 'command_timeout:=30.0'
"""The simulator's command timeout in these runs (a test's own override comes after it).

config/sim.yaml's 0.5 s is what a user's lockstep run waits for a controller before zero
effort; here the graph is compared with the offline runner tick by tick, and a machine
stalling the controller or the planner for 0.5 s (the suite's other workers running graphs
beside, a slow host) would apply zero effort and change the run, not show a defect of the
graph (docs/performance.md, "The test suite"). A stall of 30 s
still fails the test.
"""


def _demo():
    """Import tools/demo.py (its Collector and the offline settings of config/)."""
    return load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'freejoint_demo')


demo = _demo()


class Run:
    """Start graph nodes, take the run's messages in this process, wait for ticks."""

    def __init__(self, procs, ros_node, wait):
        from rclpy.experimental import EventsExecutor
        self.procs = procs
        self.wait = wait
        self.collector = demo.Collector(ros_node)
        self.executor = EventsExecutor()
        self.executor.add_node(ros_node)
        self.started = {}

    def spin(self):
        self.executor.spin_once(timeout_sec=0.05)

    def start(self, name, *overrides, args=()):
        pkg, exe, params, ready = NODES[name]
        cmd = ['--ros-args', '--params-file', os.path.join(CONFIG, params), *args]
        if name == 'sim':
            overrides = (SIM_COMMAND_TIMEOUT, *overrides)
        for item in demo.collected_writer_args(name) + list(overrides):
            cmd += ['-p', item]
        proc = self.procs.start_node(pkg, exe, name, cmd)
        self.wait(lambda: ready in self.procs.log(proc) or proc.poll() is not None, 30.0,
                  '%s to start (log %s)' % (name, proc.log_path), spin=self.spin)
        assert proc.poll() is None, self.procs.log(proc)
        self.started[name] = proc
        return proc

    def matched(self, topics=('joint_states', 'ee_position', 'controller_state')):
        """Wait until this process has matched the publishers of ``topics``."""
        self.wait(lambda: self.collector.publishers_ready(topics), 60.0,
                  'matched publishers on %s' % (topics,), spin=self.spin)

    def ticks(self, n, timeout=240.0):
        """Wait until ticks 0..n-1 were published on every collected topic."""
        self.wait(lambda: self.collector.progress_ns() >= (n - 1) * DT_NS, timeout,
                  '%d ticks (logs: %s)' % (n, [p.log_path for p in self.started.values()]),
                  spin=self.spin)

    def first_seen_tick(self):
        """Return the first tick this process took on every topic (None before that)."""
        raw = self.collector.raw
        if not all(raw.values()):
            return None
        return max(clock_ns(msgs[0]) for msgs in raw.values()) // DT_NS

    def seen_ticks(self, count, within, timeout=60.0):
        """
        Wait until this process has taken ``count`` consecutive ticks on every topic.

        The first of them is the first tick it took on every topic, which must be at most
        ``within - count``: a process that discovers the node that starts the run late sees
        the run from a later tick on (the run goes on: the simulator has no max_steps).
        """
        self.wait(lambda: self.first_seen_tick() is not None and self.collector.progress_ns()
                  >= (self.first_seen_tick() + count - 1) * DT_NS, timeout,
                  '%d ticks seen (logs: %s)' % (count, [p.log_path
                                                        for p in self.started.values()]),
                  spin=self.spin)
        first = self.first_seen_tick()
        assert first <= within - count, 'this process saw the run only from tick %d' % first

    def stop(self):
        """Stop the nodes (simulator first); return their exit codes."""
        codes = {}
        for name in ('sim', 'controller', 'planner'):
            if name in self.started:
                codes[name] = self.procs.stop(self.started[name])
        return codes

    def arrays(self, n):
        return arrays_from_messages(self.collector.messages('controller_state'),
                                    self.collector.messages('joint_states'), 'joint3',
                                    max_ticks=n)

    def ee(self, n, dims=2):
        return demo.ee_trajectory(self.collector.messages('ee_position'), DT_NS, n, dims)


@functools.lru_cache(maxsize=None)
def _offline(case):
    """Return the offline runner's ``(record, trace)`` of ``case``, run once per worker."""
    return run_case(case, 'robust', 0, record_trace=True, **demo.offline_settings(CONFIG))


def _assert_ticks_equal_offline(run, case, n, complete=True):
    """
    Assert that the graph's ticks 0..n-1 are the offline runner's, within 1e-9.

    With ``complete=False`` ticks this process did not see (it may discover a node that
    starts the run later than the others do) are left out; 100 at least must be there.
    """
    _, trace = _offline(case)
    assert n <= len(trace['t'])
    arrays = run.arrays(None)
    k = np.rint(arrays['t'] * 1e9 / DT_NS).astype(int)
    keep = k < n
    k = k[keep]
    assert len(k) == n if complete else len(k) >= 100, '%d of %d ticks seen' % (len(k), n)
    for key in ('p', 'p_d', 'tau', 'theta', 'det'):
        assert np.max(np.abs(arrays[key][keep] - trace[key][k])) <= 1e-9, key
    assert np.max(np.abs(arrays['q_passive'][keep] - trace['q'][k, 2])) <= 1e-9
    if complete:
        assert np.max(np.abs(run.ee(n) - trace['p'][:n])) <= 1e-9


def test_the_collected_streams_writers_keep_as_many_ticks_as_this_processs_readers(ros_node):
    """
    In-process: the nodes given ``demo.collected_writer_args`` keep COLLECT_DEPTH messages.

    Their writers of joint_states, ee_position and controller_state do.  A reader stalled
    longer than the writer's history loses messages for good (docs/performance.md,
    "The test suite"); the graph runs here and in ``make demo`` give the
    nodes the depth of the collector's readers.
    """
    from rclpy.parameter import Parameter
    from freejoint_control.controller_node import ControllerNode
    from freejoint_sim.sim_node import SimNode
    depth = {}
    for name, kind, publishers in (('sim', SimNode, ('_pub_js', '_pub_ee')),
                                   ('controller', ControllerNode, ('_pub_state',))):
        items = [item.split(':=') for item in demo.collected_writer_args(name)]
        node = kind(parameter_overrides=[Parameter(key, value=int(value))
                                         for key, value in items])
        try:
            for attr in publishers:
                pub = getattr(node, attr)
                depth[pub.topic_name] = pub.qos_profile.depth
        finally:
            node.destroy_node()
    assert depth == {'/joint_states': demo.COLLECT_DEPTH, '/ee_position': demo.COLLECT_DEPTH,
                     '/controller_state': demo.COLLECT_DEPTH}
    collector = demo.Collector(ros_node)
    try:
        assert {sub.qos_profile.depth for sub in collector.subs.values()} == {demo.COLLECT_DEPTH}
    finally:
        collector.close()


def test_lockstep_graph_end_effector_equals_the_offline_runner_at_every_step(
        procs, ros_node, wait):
    run = Run(procs, ros_node, wait)
    run.start('sim')
    run.start('controller')
    run.matched()
    run.start('planner')
    n = 5000   # the full 5 s case: ticks t_0 .. t_4999 as the offline runner records them
    run.ticks(n)
    assert run.stop() == {'sim': 0, 'controller': 0, 'planner': 0}
    record, trace = _offline('horizontal')
    ee = run.ee(n)
    assert ee.shape == trace['p'].shape
    assert np.max(np.abs(ee - trace['p'])) <= 1e-9
    graph = compute_record('horizontal', 'robust', 0, source='graph', **run.arrays(n))
    for key in KEYS:
        if key in ('case', 'variant', 'seed', 'diverged_at_s'):
            assert graph[key] == record[key]
        elif key != 'source':
            assert graph[key] == pytest.approx(record[key], abs=1e-9, rel=0.0), key
    with open(run.started['sim'].log_path) as f:
        assert ': 0 command timeouts, 0 refused commands' in f.read()


def test_lockstep_tracking_stays_within_the_offline_error_bound(procs, ros_node, wait):
    run = Run(procs, ros_node, wait)
    run.start('sim', 'case:=vertical')
    run.start('controller', 'case:=vertical')
    run.matched()
    run.start('planner', 'case:=vertical')
    n = 2500   # half the vertical case: the fastest part of the circle
    run.ticks(n)
    run.stop()
    record, _ = _offline('vertical')
    arrays = run.arrays(n)
    err_mm = 1000.0 * np.hypot(*(arrays['p'] - arrays['p_d']).T)
    assert err_mm.max() <= record['max_mm'] + 1e-6
    _assert_ticks_equal_offline(run, 'vertical', n)


@pytest.mark.parametrize('order', [('controller', 'planner', 'sim'),
                                   ('sim', 'planner', 'controller'),
                                   ('planner', 'controller', 'sim')],
                         ids=['sim-last', 'controller-last', 'planner-first'])
def test_nodes_wire_up_in_any_start_order(order, procs, ros_node, wait):
    run = Run(procs, ros_node, wait)
    for name in order[:2]:
        run.start(name)
    if order[2] == 'planner':
        run.matched()
    run.start(order[2])
    n = 1000
    run.ticks(n)
    complete = order[2] == 'planner'
    if not complete:
        # This process may discover the last node (the one that starts the run) after the
        # run started, even after tick n (1000 ticks take ~0.5 s): then it compares the 100
        # ticks from the first it saw on, within the 5 s of the case (5000 ticks).
        n = 5000
        run.seen_ticks(100, n)
    assert run.stop() == {'sim': 0, 'controller': 0, 'planner': 0}
    # The run itself, as the simulator saw it, whatever this process saw of it: it started
    # at the first command and the controller answered every step in time, correctly
    # formed; the graph loses nothing (the other tests see every tick).
    with open(run.started['sim'].log_path) as f:
        sim_log = f.read()
    assert 'first command: running' in sim_log, sim_log
    stopped = re.search(r'simulator stopped at step (\d+) \(t = [0-9.]+ s\): '
                        r'0 command timeouts, 0 refused commands', sim_log)
    assert stopped and int(stopped.group(1)) >= 999, sim_log   # ticks 0..999 at least
    _assert_ticks_equal_offline(run, 'horizontal', n, complete=complete)


def test_joint_states_of_a_driver_in_another_order_drive_the_controller_as_the_sims_do(
        procs, ros_node, wait):
    run = Run(procs, ros_node, wait)
    run.start('sim')
    relay = procs.start_script(RELAY, 'relay')
    wait(lambda: 'relay ready' in procs.log(relay), 30.0, 'the relay', spin=run.spin)
    run.start('controller', args=['-r', 'joint_states:=driver/joint_states'])
    run.matched()
    run.start('planner')
    n = 1000
    run.ticks(n)
    run.stop()
    _assert_ticks_equal_offline(run, 'horizontal', n)


def test_stopping_the_controller_makes_the_sim_apply_zero_effort_within_its_timeout(
        procs, ros_node, wait):
    run = Run(procs, ros_node, wait)
    efforts = []
    ros_node.create_subscription(JOINT_STATES.msg_type, JOINT_STATES.name,
                                 lambda m: efforts.append(list(m.effort)), JOINT_STATES.qos)
    sim = run.start('sim', 'mode:=realtime', 'command_timeout:=0.3', 'publish_rate:=100.0',
                    'brake_timeout:=0.0')
    # States at 100 Hz for a 1-kHz loop: the readiness guard would (rightly) never start.
    controller = run.start('controller', 'lockstep:=false', 'readiness_guard:=false')
    run.start('planner', 'use_sim_time:=false')
    wait(lambda: efforts and efforts[-1][:2] != [0.0, 0.0], 60.0,
         'the controller driving the real-time simulator', spin=run.spin)
    assert procs.stop(controller) == 0
    # ros2_control would hold the last command forever; the simulator applies zero.
    wait(lambda: efforts[-1] == [0.0, 0.0, 0.0], 30.0, 'zero effort after the timeout',
         spin=run.spin)
    # The line may reach the log after the zero effort reaches this node (read at once
    # on a loaded machine, it was not there yet).
    line = ('no command on /effort_controller/commands for 0.3 s: zero effort (not holding '
            'the last one)')
    wait(lambda: line in procs.log(sim), 30.0, "the simulator's timeout line", spin=run.spin)
