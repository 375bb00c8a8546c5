"""
Benchmark: the controller's and the simulator's CPU per lockstep tick against a bare echo.

Runs each in a ROS domain of its own (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``),
every wait bounded, every process stopped whatever happens:

* the echo: ``bench/echo_node.py`` (a bare rclpy node: ``joint_states`` in, a
  ``Float64MultiArray`` on ``effort_controller/commands`` out, the contract's QoS), once
  on the executor the controller runs on (``config/controller.yaml``: ``events``) and
  once on the ``single_threaded`` one, each driven in lockstep by this process: state k
  is published once the answer to k - 1 came, ``TICKS`` times after a warm-up; the echo
  process's CPU seconds (``/proc/<pid>/stat``) over the measured ticks, per tick;
* the graph in lockstep without the recorder (``bench/graph.py``'s lockstep run, the 5-s
  horizontal case, a process per node) with the echo started beside it
  (``beside_per_tick``: ``echo_node.py --out echo/commands``, answering every state the
  simulator publishes, its command taken by this process), its threads at the
  controller's scheduling (``--priority``: SCHED_FIFO at the bench's ``thread_priority``):
  the controller's and the echo's CPU and wake-ups per tick over the same ticks at the
  same time; twice, the controller's ``ControllerState`` every tick (the default) and
  thinned to 100 Hz (``THINNED``);
* the graph as ``make demo`` runs it (the recorder on): the controller's and the
  simulator's CPU per tick (the graph benchmark's own run when ``make bench`` ran it).

Rows: the CPU figures and wake-ups per tick and the ratios. The target compares the
controller with the echo beside it: both answer the same states from the same simulator
in the same run, whose CPU per tick moves from run to run by more than the target's
margin on a 2-vCPU VM (a wake-up costs more when four processes take turns than when
two do, and the other processes' timing differs run to run), so the echo driven alone or
in another run is not the comparison; and at the same scheduling, since an echo at the
default scheduler beside SCHED_FIFO nodes runs after them, finds several states waiting
and wakes about half as often per tick (docs/performance.md). Benchmarks assert nothing.
Usage: ``. tools/env.sh && python bench/echo.py``, or ``make bench BENCH=echo``.
"""

import os
import sys
import time

import graph as graph_bench

HERE = os.path.dirname(os.path.abspath(__file__))
ECHO_NODE = os.path.join(HERE, 'echo_node.py')
TICKS = graph_bench.LOCKSTEP_TICKS
WARMUP = 100
ECHO_DOMAIN_INDEX = 7
"""``graph._env`` index of the echo run (the graph's runs take 0..6)."""
THINNED = ('state_publish_rate:=100.0',)
"""The controller's overrides of the third graph run: its instrumentation thinned."""
BESIDE_TOPIC = 'echo/commands'
"""Where the echo beside the controller answers (the simulator does not take it)."""
TICK_TIMEOUT = 10.0
"""Seconds a state may wait for its answer before the run is given up."""


def drive_echo(client, ticks=TICKS, warmup=WARMUP):
    """
    Publish states in lockstep to the echo node; return the CPU seconds it spent on ``ticks``.

    Parameters
    ----------
    client : graph.Client
        The bench's rclpy node (its executor is spun here).
    ticks, warmup : int
        Measured ticks, and ticks before them (not measured).

    Returns
    -------
    callable
        ``measure(cpu) -> float``: runs the ticks and returns ``cpu()`` after minus before.

    """
    from freejoint_common.contract import COMMANDS, JOINT_STATES
    node = client.node
    answers = []
    pub = node.create_publisher(JOINT_STATES.msg_type, JOINT_STATES.name, JOINT_STATES.qos)
    sub = node.create_subscription(COMMANDS.msg_type, COMMANDS.name,
                                   lambda msg: answers.append(msg.data[0]), COMMANDS.qos)
    state = JOINT_STATES.msg_type()
    state.name = ['joint1', 'joint2', 'joint3']
    state.effort = [0.0, 0.0, 0.0]

    state.position = [0.0, 0.0, 0.0]

    def send(k):
        state.velocity = [-float(k), 0.0, 0.0]      # answered with k (minus the velocity)
        pub.publish(state)

    def answered(k):
        return bool(answers) and answers[-1] == float(k)

    def measure(cpu):
        try:
            if not client.spin_until(
                    lambda: pub.get_subscription_count() >= 1
                    and node.count_publishers(COMMANDS.name) >= 1, 60.0):
                raise RuntimeError('the echo node did not match within 60 s')
            for _ in range(30):       # the first state again until answered (matching)
                send(0)
                if client.spin_until(lambda: answered(0), 1.0):
                    break
            else:
                raise RuntimeError('the echo node did not answer within 30 s')
            cpu0 = None
            for k in range(1, warmup + ticks + 1):
                if k == warmup + 1:
                    cpu0 = cpu()
                send(k)
                if not client.spin_until(lambda: answered(k), TICK_TIMEOUT):
                    raise RuntimeError('no answer to state %d within %g s' % (k, TICK_TIMEOUT))
            return cpu() - cpu0
        finally:
            node.destroy_publisher(pub)
            node.destroy_subscription(sub)

    return measure


def controller_executor():
    """Return the executor ``config/controller.yaml`` runs the controller on."""
    from freejoint_control.params import SCHEMA
    return SCHEMA.yaml_values(os.path.join(graph_bench.CONFIG, 'controller.yaml'))['executor']


def echo_cpu_per_tick(executor, ticks=TICKS):
    """Return the echo node's CPU per lockstep tick [us] on ``executor`` (a run of its own)."""
    env = graph_bench._env(ECHO_DOMAIN_INDEX)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']
    run_dir = os.path.join(graph_bench.OUT, 'echo_' + executor)
    procs = graph_bench.Graph(os.path.join(run_dir, 'logs'), 'echo', env)
    client = graph_bench.Client()
    try:
        proc = procs.start_script(ECHO_NODE, 'echo_node', [executor])
        start = time.perf_counter()
        seconds = drive_echo(client, ticks)(lambda: graph_bench.proc_cpu_seconds(proc.pid))
        graph_bench.say('echo (%s executor): %d ticks in %.2f s wall, %.1f us CPU per tick'
                        % (executor, ticks, time.perf_counter() - start,
                           1e6 * seconds / ticks))
        return 1e6 * seconds / ticks
    finally:
        client.close()
        procs.stop_all(order=('echo_node',))


def _lockstep_run(record, ctl_overrides=(), beside=None, setup=None):
    """
    Run ``graph.lockstep`` (a process per node) in its own domain; return its rows.

    ``setup(client)`` runs on the bench's client first (a subscription, say).
    """
    env = graph_bench._env(0)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']
    client = graph_bench.Client()
    try:
        if setup is not None:
            setup(client)
        return graph_bench.lockstep(client, env, 'separate', record=record,
                                    ctl_overrides=ctl_overrides, beside=beside)
    finally:
        client.close()


def _per_tick(rows, nodes=('controller_node', 'echo_node', 'sim_node'), what='CPU per tick'):
    """Return ``{node: figure}`` of the rows ``lockstep: <node> <what>`` of ``nodes``."""
    names = {'lockstep: %s %s' % (node, what): node for node in nodes}
    return {names[row['name']]: row['value'] for row in rows if row['name'] in names}


def beside_per_tick(executor, ctl_overrides=()):
    """
    Return ``{node: CPU per lockstep tick [us]}``, ``{node: wake-ups per tick}`` beside.

    Of the controller, the simulator and an echo beside them.

    One lockstep run of the graph without the recorder and an echo node (on ``executor``)
    started beside it, answering every state on ``echo/commands`` (taken by this process,
    one reader as the controller's command has), its threads at the controller's
    scheduling (``--priority``: the bench's ``thread_priority``): both measured over the
    same ticks on the same machine at the same time, what no two runs can be
    (``ctl_overrides``: the controller's). Wake-ups: ``graph.proc_wakeups``.
    """
    from freejoint_common.contract import COMMANDS

    def take_echo_commands(client):
        client.node.create_subscription(COMMANDS.msg_type, BESIDE_TOPIC, lambda _msg: None,
                                        COMMANDS.qos)

    args = [sys.executable, ECHO_NODE, executor, '--out', BESIDE_TOPIC]
    if graph_bench.PRIORITY:
        args += ['--priority', str(graph_bench.PRIORITY)]
    rows = _lockstep_run(False, ctl_overrides, ('echo_node', args), take_echo_commands)
    return _per_tick(rows), _per_tick(rows, what='wake-ups per tick')


def graph_cpu_per_tick(record=True, ctl_overrides=()):
    """
    Return ``{node: CPU per lockstep tick [us]}`` of sim_node and controller_node.

    From the graph benchmark's lockstep run (a process per node, the recorder on if
    ``record``) if this process ran one (``make bench``: ``graph`` runs before ``echo``),
    else from a run of its own (with the controller's ``ctl_overrides``, always its own).
    """
    rows = None if ctl_overrides else graph_bench.LOCKSTEP_ROWS.get(('separate', record))
    if rows is None:
        rows = _lockstep_run(record, ctl_overrides)
    return _per_tick(rows, ('sim_node', 'controller_node'))


def run():
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    kind = controller_executor()
    echo = echo_cpu_per_tick(kind)
    other = 'single_threaded' if kind == 'events' else 'events'
    echo_other = echo_cpu_per_tick(other)
    rows = [
        {'name': 'lockstep: rclpy echo node CPU per tick, driven alone (%s)' % kind,
         'value': echo, 'unit': 'us'},
        {'name': 'lockstep: rclpy echo node CPU per tick, driven alone (%s)' % other,
         'value': echo_other, 'unit': 'us'},
    ]

    def ratio(value, base):
        return None if value is None or not base else value / base

    # Beside the controller in the same run (the target), its ControllerState every tick
    # (the default) and thinned to 100 Hz; the recorder off: the controller's command to
    # one reader, as the echo's.
    for tag, target, extra in (('', '<= 1.5', ()),
                               (', controller_state 100 Hz', None, THINNED)):
        nodes, wakeups = beside_per_tick(kind, extra)
        ctl, near = nodes.get('controller_node'), nodes.get('echo_node')
        graph_bench.say('CPU per lockstep tick, recorder off%s: controller %s us, an echo '
                        '(%s, %s) beside it %s us, simulator %s us; wake-ups per tick: '
                        'controller %s, echo %s' % (
                            tag, _us(ctl), kind, _scheduling(), _us(near),
                            _us(nodes.get('sim_node')), _us(wakeups.get('controller_node'), 2),
                            _us(wakeups.get('echo_node'), 2)))
        rows += [
            {'name': 'lockstep, recorder off%s: controller_node CPU per tick' % tag,
             'value': ctl, 'unit': 'us'},
            {'name': 'lockstep, recorder off%s: echo (%s) beside it, CPU per tick'
             % (tag, kind), 'value': near, 'unit': 'us'},
            {'name': 'lockstep, recorder off%s: controller / echo beside it' % tag,
             'value': ratio(ctl, near), 'unit': 'x', 'target': target},
            {'name': 'lockstep, recorder off%s: simulator / echo beside it' % tag,
             'value': ratio(nodes.get('sim_node'), near), 'unit': 'x'},
            {'name': 'lockstep, recorder off%s: controller wake-ups per tick' % tag,
             'value': wakeups.get('controller_node'), 'unit': ''},
            {'name': 'lockstep, recorder off%s: echo wake-ups per tick' % tag,
             'value': wakeups.get('echo_node'), 'unit': ''},
        ]
    # As make demo runs (the recorder on): the figures of the graph benchmark.
    nodes = graph_cpu_per_tick(True)
    ctl, sim = nodes.get('controller_node'), nodes.get('sim_node')
    graph_bench.say('CPU per lockstep tick, recorder on: controller %s us, simulator %s us'
                    % (_us(ctl), _us(sim)))
    rows += [
        {'name': 'lockstep, recorder on: controller_node CPU per tick', 'value': ctl,
         'unit': 'us'},
        {'name': 'lockstep, recorder on: sim_node CPU per tick', 'value': sim, 'unit': 'us'},
        {'name': 'lockstep, recorder on: controller / echo driven alone (%s)' % kind,
         'value': ratio(ctl, echo), 'unit': 'x'},
    ]
    return rows


def _us(value, digits=1):
    return 'n/a' if value is None else '%.*f' % (digits, value)


def _scheduling():
    """Return the scheduling the controller and the echo beside it run at."""
    return ('SCHED_FIFO %d as the controller' % graph_bench.PRIORITY if graph_bench.PRIORITY
            else 'default scheduler as the controller')


def main():
    """Run the benchmark from the command line; print the rows."""
    for row in run():
        value = row['value']
        print('%-58s %12s %-8s %s' % (row['name'], 'n/a' if value is None else '%.4g' % value,
                                      row['unit'], row.get('target') or ''))
    return 0


if __name__ == '__main__':
    sys.path.insert(0, HERE)
    sys.exit(main())
