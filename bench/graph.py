"""
Benchmark: the running node graph (sim_node, controller_node, planner_node, recorder).

Two runs of the graph in each of two layouts: a process per node, started as ``make demo``
starts them (the installed executables with ``config/*.yaml`` and per-run overrides), and
the three nodes in one process (``ros2 run freejoint_bringup graph`` with the same files;
rows tagged ``[1 process]``). Each run is isolated in a ROS domain of its own with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, every wait bounded, every process stopped
(SIGINT, then SIGKILL) whatever happens:

* lockstep, 1 kHz, recorder on: the 5-s horizontal case (5000 ticks) - real-time factor
  (simulated / wall time, from the simulator's own per-step publish times of steps 0 and
  5000), per-tick wall time, state->command latency, ticks in the bag;
* real time, 1 kHz, recorder on, ``FREEJOINT_BENCH_RT_SECONDS`` (default 60) s of the
  paper's circle repeated, each asked for 0.5 s after the previous one's duration from the
  reply that accepted it (not on a fixed wall-clock grid: a late reply must not cut the
  running circle off), the horizontal case in each layout and the vertical case with a
  process per node: state->command latency p50 / p99 / max (from the
  simulator's publication of state k to its receipt of the command answering k), control
  periods without a fresh command (the command applied over period k did not answer state
  k, or none came), periods skipped; against the plan (``freejoint_core.plan_figures`` of
  the bag's ``ee_position`` and ``setpoints``): the end effector's max / rms error, the share
  of the plan's moving ticks within the case's bound (1.5 x the offline worst max), the time
  held or braked while the plan moved, the plans completed and how late; and the error
  against the controller's own reference (the bag's controller_state) against the offline
  runner's worst max / rms (seeds 0-9, same case);
* for both: CPU time per tick and peak resident memory (``VmHWM`` of ``/proc/<pid>/status``
  at the end of the run) of each node, and the machine's load average.

The times come from the simulator (parameters ``timing_file`` / ``timing_steps``: a
preallocated per-step array written once, no per-tick logging; ``freejoint_sim.timing``).
Benchmarks assert nothing; figures and targets go to ``bench/run_all.py``'s table.

Usage: ``. tools/env.sh && python bench/graph.py [--lockstep-only | --realtime-only]
[--separate-only | --composed-only | --loop-only] [--horizontal-only | --vertical-only]``;
``FREEJOINT_BENCH_RT_SECONDS=10`` for a quick real-time run.  Logs and bags stay in
``bags/bench/graph/`` (git-ignored).
"""

import os
import shutil
import signal
import sys
import time

from freejoint_common.contract import COMMANDS, CONTROLLER_STATE, EE_POSITION, JOINT_STATES
from freejoint_common.contract import lockstep_writer_overrides, NEVER_QUIET_TOPICS, SETPOINTS
from freejoint_tools.harness import Processes, ServiceCalls

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INSTALL = os.path.join(ROOT, 'install')
CONFIG = os.path.join(ROOT, 'config')
OUT = os.path.join(ROOT, 'bags', 'bench', 'graph')
CASE = 'horizontal'
SEED = 0
LOCKSTEP_TICKS = 5000
RT_SECONDS = float(os.environ.get('FREEJOINT_BENCH_RT_SECONDS', '60'))
RT_STARTUP_STEPS = 30000
"""Real time: steps the timing arrays hold beyond the measured window (start-up, stop)."""
NODES = ('sim_node', 'controller_node', 'echo_node', 'planner_node', 'graph', 'recorder')
STOP_ORDER = ('controller_node', 'echo_node', 'planner_node', 'sim_node', 'graph', 'recorder')
LAYOUTS = {'separate': '', 'composed': ' [1 process]', 'loop': ' [sim+controller 1 process]'}
"""Graph layouts and their tag in the rows: a process per node; the three nodes in one
process (bringup ``graph``); the control loop - sim and controller - in one process
(``graph --nodes sim controller``, as ros2_control keeps hardware and controllers in the
controller_manager's process) with the planner in its own."""
DRAIN_PAUSE = 1.0
"""Wall seconds between stopping the controller and the rest (the recorder catches up)."""
RT_READY_BEFORE_SIM = '[%s]' % ', '.join(t.name for t in (COMMANDS, CONTROLLER_STATE, SETPOINTS))
"""The recorder's ready_topics while the simulator is not started yet (real time)."""
RT_SIM_TOPICS = (JOINT_STATES.absolute, EE_POSITION.absolute)
OFFLINE_SEEDS = range(10)
PRIORITY = int(os.environ.get('FREEJOINT_BENCH_PRIORITY', '50'))
"""thread_priority of the simulator and the controller (SCHED_FIFO; 0 = default scheduler;
50 is ros2_control's controller_manager default)."""
AFFINITY = os.environ.get('FREEJOINT_BENCH_AFFINITY', '')
"""cpu_affinity of the simulator and the controller, e.g. '1' or '0,1' ('' = not set)."""


def scheduling_overrides(priority=None):
    """Return the sim's and the controller's thread_priority / cpu_affinity overrides."""
    items = ['thread_priority:=%d' % (PRIORITY if priority is None else priority)]
    if AFFINITY:
        items.append('cpu_affinity:=[%s]' % AFFINITY)
    return items


def executable(pkg, exe):
    """Return what ``ros2 run <pkg> <exe>`` starts: install/<pkg>/lib/<pkg>/<exe>."""
    return os.path.join(INSTALL, pkg, 'lib', pkg, exe)


def say(text):
    """Print a progress line at once."""
    print('[bench graph] ' + text, flush=True)


def load_average():
    """Return the 1-minute load average."""
    return os.getloadavg()[0]


# -- processes --------------------------------------------------------------------------
def proc_cpu_seconds(pid):
    """Return user + system CPU seconds of a process (0.0 if gone)."""
    try:
        with open('/proc/%d/stat' % pid) as f:
            fields = f.read().rsplit(')', 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def proc_wakeups(pid):
    """
    Return the voluntary context switches of every thread of a process (0 if gone).

    A thread's voluntary switch is a wait it entered (for a message, a timer, a lock):
    per tick, how many times the process slept and was woken. A process that finds
    several messages waiting when it wakes (it runs after others) wakes less than once
    per message, and spends less CPU per message. Threads that ended are not counted.
    """
    total = 0
    try:
        tids = os.listdir('/proc/%d/task' % pid)
    except OSError:
        return 0
    for tid in tids:
        try:
            with open('/proc/%d/task/%s/status' % (pid, tid)) as f:
                for line in f:
                    if line.startswith('voluntary_ctxt_switches:'):
                        total += int(line.split()[1])
                        break
        except OSError:
            continue            # the thread ended meanwhile
    return total


def machine_cpu_jiffies():
    """Return ``(idle, steal)`` jiffies of the whole machine (``/proc/stat``; idle + iowait)."""
    with open('/proc/stat') as f:
        fields = f.readline().split()
    return int(fields[4]) + int(fields[5]), int(fields[8])


def proc_vmhwm_mib(pid):
    """Return the peak resident set (VmHWM) of a process in MiB, None if gone."""
    try:
        with open('/proc/%d/status' % pid) as f:
            for line in f:
                if line.startswith('VmHWM:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


class Graph(Processes):
    """Node processes of one run (``freejoint_tools.harness``): measure, stop cleanly."""

    def __init__(self, log_dir, tag, env):
        super().__init__(log_dir, tag, env, cwd=ROOT)
        self._cpu = {}
        self._wakeups = {}

    def cpu(self):
        """Return {name: CPU seconds so far} (a process that exited: its last reading)."""
        for name, proc in self.procs.items():
            if proc.poll() is None:
                self._cpu[name] = proc_cpu_seconds(proc.pid)
        return dict(self._cpu)

    def wakeups(self):
        """Return {name: voluntary context switches so far} (:func:`proc_wakeups`)."""
        for name, proc in self.procs.items():
            if proc.poll() is None:
                self._wakeups[name] = proc_wakeups(proc.pid)
        return dict(self._wakeups)

    def vmhwm(self):
        """Return {name: VmHWM MiB}."""
        return {n: proc_vmhwm_mib(p.pid) for n, p in self.procs.items()}

    def stop_all(self, order=STOP_ORDER):
        """
        Stop every process (in ``order``, the rest after); return {name: exit code}.

        The controller first (the graph pauses: the lockstep sim waits, the real-time sim
        applies zero effort), then a pause for the recorder to take what is in flight (a
        shared-memory sample not yet taken dies with its publisher), the recorder last.
        """
        codes = {}
        names = [n for n in order if n in self.procs] + [
            n for n in self.procs if n not in order]
        one = self.procs.get('graph')
        if one is not None and one.poll() is None and 'recorder' in self.procs:
            one.send_signal(signal.SIGSTOP)     # the graph pauses, the recorder catches up
            time.sleep(DRAIN_PAUSE)
            one.send_signal(signal.SIGCONT)
        for name in names:
            codes[name] = self.stop(name, 60.0 if name == 'recorder' else 20.0)
            if name == 'controller_node' and 'recorder' in self.procs:
                time.sleep(DRAIN_PAUSE)
        return codes

    def diverged(self):
        """Return the simulator's warning/error log lines about a diverged plant (all runs)."""
        name = 'sim_node' if 'sim_node' in self.procs else 'graph'
        count = 0
        for path in self.procs[name].logs:
            with open(path) as f:
                count += sum(1 for line in f if 'diverg' in line.lower()
                             and ('[ERROR]' in line or '[WARN]' in line))
        return count


def node_cmd(pkg, exe, config, overrides):
    """Return a node's command line, as ``ros2 run`` with a params file and overrides."""
    cmd = [executable(pkg, exe), '--ros-args', '--params-file', os.path.join(CONFIG, config)]
    for item in overrides:
        cmd += ['-p', item]
    return cmd


def planner_scheduling():
    """
    Return the real-time planner's thread_priority override: 10 below sim and controller.

    The setpoint stream must not be starved by the SCHED_FIFO sim and controller (gaps of
    up to 0.3 s were seen with the planner at the default scheduler), but it must not
    preempt the control loop either.
    """
    return ['thread_priority:=%d' % (PRIORITY - 10)] if PRIORITY > 10 else []


def start_sim(graph, overrides, case=CASE, priority=None):
    """Start the simulator (its own process)."""
    graph.start('sim_node', node_cmd('freejoint_sim', 'sim_node', 'sim.yaml',
                                     ['case:=' + case, 'seed:=%d' % SEED] + overrides
                                     + scheduling_overrides(priority)))


def start_graph(graph, layout, bag, sim_overrides, ctl_overrides, planner_overrides,
                rec_overrides, custom, case=CASE, beside=None):
    """
    Start the recorder (unless ``bag`` is None) and the three nodes.

    ``layout`` 'separate': a process per node, as ``make demo`` starts them (the simulator
    only if ``sim_overrides`` is not None); 'composed': the three in one process,
    ``ros2 run freejoint_bringup graph`` with the same parameter files and overrides.
    ``beside``: ``(name, command)`` of a process started after the nodes ('separate' only;
    ``bench/echo.py``'s echo node).
    """
    if bag is not None:
        graph.start('recorder', [executable('freejoint_tools', 'recorder'), '--ros-args',
                                 '-p', 'output:=' + bag, '-p', 'topics:=[]',
                                 '-p', 'overwrite:=true', '-p', 'custom_data:=[%s]' % custom]
                    + [a for item in rec_overrides for a in ('-p', item)])
    sched = scheduling_overrides()
    sim = ['case:=' + case, 'seed:=%d' % SEED] + list(sim_overrides or []) + sched
    ctl = ['case:=' + case] + ctl_overrides + sched
    planner = ['case:=' + case] + (planner_overrides or ['autostart:=false'])
    if layout in ('composed', 'loop'):
        sim_, ctl_, planner_ = ([item.replace(':=', '=', 1) for item in items]
                                for items in (sim, ctl, planner))
        cmd = [executable('freejoint_bringup', 'graph'),
               '--sim-params', os.path.join(CONFIG, 'sim.yaml'), '--sim', *sim_,
               '--controller-params', os.path.join(CONFIG, 'controller.yaml'),
               '--controller', *ctl_]
        if layout == 'composed':
            graph.start('graph', cmd + ['--planner-params', os.path.join(CONFIG, 'planner.yaml'),
                                        '--planner', *planner_])
            return
        graph.start('graph', cmd + ['--nodes', 'sim', 'controller'])
        graph.start('planner_node', node_cmd('freejoint_planner', 'planner_node',
                                             'planner.yaml', planner))
        return
    if sim_overrides is not None:
        start_sim(graph, sim_overrides, case)
    graph.start('controller_node', node_cmd('freejoint_control', 'controller_node',
                                            'controller.yaml', ctl))
    graph.start('planner_node', node_cmd('freejoint_planner', 'planner_node', 'planner.yaml',
                                         planner))
    if beside is not None:
        graph.start(*beside)


# -- this process's ROS node (services only: nothing on the hot path) --------------------
class Client(ServiceCalls):
    """An rclpy node of the bench: recorder status, plan requests; spun only while used."""

    def __init__(self):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        rclpy.init()
        self.rclpy = rclpy
        node = rclpy.create_node('freejoint_bench')
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        super().__init__(node, executor)

    def close(self):
        """Destroy the node and shut rclpy down."""
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown()

    def controller_answers(self, timeout, count=20):
        """Wait until ``count`` controller_state messages arrived (briefly subscribed)."""
        from freejoint_msgs.msg import ControllerState
        got = []
        sub = self.node.create_subscription(ControllerState, 'controller_state',
                                            lambda raw: got.append(1), 10, raw=True)
        try:
            return self.spin_until(lambda: len(got) >= count, timeout, step=0.01)
        finally:
            self.node.destroy_subscription(sub)


def ros_params(name):
    """
    Return the parameter values of the node of config/<name>.

    Its schema's defaults overlaid with the file (which sets only what differs from them).
    """
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    schema = {'sim.yaml': SIM, 'controller.yaml': CONTROLLER, 'planner.yaml': PLANNER}[name]
    return schema.yaml_values(os.path.join(CONFIG, name))


def wait_for_file(path, graph, timeout, what):
    """Wait (bounded) until ``path`` exists; raise if a node exits or time runs out."""
    deadline = time.monotonic() + timeout
    while not os.path.exists(path):
        if graph.exited():
            raise RuntimeError('%s exited during the run (%s)' % (
                ', '.join(graph.exited()), graph.log_dir))
        if time.monotonic() > deadline:
            raise RuntimeError('%s: not done within %g s (logs in %s)'
                               % (what, timeout, graph.log_dir))
        time.sleep(0.05)


def _env(index):
    """Environment of run ``index`` (0-7): a ROS domain no other run of this bench uses."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(110 + (os.getpid() % 5) * 8 + index)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')
    return env


def _percentiles(values):
    import numpy as np
    if len(values) == 0:
        return None, None, None
    return (float(np.percentile(values, 50)), float(np.percentile(values, 99)),
            float(np.max(values)))


def _node_rows(prefix, cpu0, cpu1, hwm, ticks, exited=(), wakeups=None):
    rows = []
    for name in NODES:
        if name in cpu1:
            rows.append({'name': '%s: %s CPU per tick' % (prefix, name),
                         'value': None if name in exited else
                         1e6 * (cpu1[name] - cpu0.get(name, 0.0)) / max(ticks, 1),
                         'unit': 'us', 'target': None})
    if wakeups is not None:
        before, after = wakeups
        for name in NODES:
            if name in after and name not in exited:
                rows.append({'name': '%s: %s wake-ups per tick' % (prefix, name),
                             'value': (after[name] - before.get(name, 0)) / max(ticks, 1),
                             'unit': '', 'target': None})
    for name in NODES:
        if hwm.get(name) is not None:
            rows.append({'name': '%s: %s peak RSS (VmHWM)' % (prefix, name),
                         'value': hwm[name], 'unit': 'MiB', 'target': None})
    return rows


# -- lockstep ---------------------------------------------------------------------------
def wait_ready(client, record):
    """Wait for the recorder's status (or, without it, the planner's service, then 1 s)."""
    if record:
        ok, status = client.recorder_ready(60.0)
        if not ok:
            raise RuntimeError('recorder not ready after 60 s: %s' % status)
    else:
        from freejoint_msgs.srv import PlanCircle
        probe = client.node.create_client(PlanCircle, '/freejoint_planner/plan_circle')
        try:
            if not client.spin_until(probe.service_is_ready, 60.0):
                raise RuntimeError('the planner is not up after 60 s')
        finally:
            client.node.destroy_client(probe)
        client.spin_until(lambda: False, 1.0)


def lockstep(client, env, layout='separate', ticks=LOCKSTEP_TICKS, record=True,
             ctl_overrides=(), beside=None):
    """
    Run the 5-s case in lockstep, the recorder on if ``record``; return the rows.

    ``ctl_overrides``: the controller's ``name:=value`` overrides (none: as make demo);
    ``beside``: ``(name, command)`` of a process started beside the nodes (``start_graph``).
    """
    import numpy as np
    from freejoint_tools.bagfile import open_bag
    tag = 'lockstep' + LAYOUTS[layout]
    run_dir = os.path.join(OUT, 'lockstep_' + layout + ('' if record else '_no_recorder')
                           + ('_' + '_'.join(ctl_overrides) if ctl_overrides else '')
                           + ('_beside_' + beside[0] if beside else '')).replace(':=', '_')
    shutil.rmtree(run_dir, ignore_errors=True)
    timing_path = os.path.join(run_dir, 'timing.npz')
    bag = os.path.join(run_dir, 'bag') if record else None
    graph = Graph(os.path.join(run_dir, 'logs'), 'lockstep', env)
    load0 = load_average()
    say('%s: %d ticks, recorder %s, ROS_DOMAIN_ID %s, load %.2f'
        % (tag, ticks, 'on' if record else 'OFF', env['ROS_DOMAIN_ID'], load0))
    try:
        start_graph(graph, layout, bag,
                    ['timing_file:=' + timing_path, 'timing_steps:=%d' % (ticks + 1),
                     'max_steps:=%d' % ticks] + lockstep_writer_overrides('sim'),
                    lockstep_writer_overrides('controller') + list(ctl_overrides), [],
                    ['use_sim_time:=true',
                     # the drain wait below needs a count that goes quiet
                     'exclude:=[%s]' % ', '.join(NEVER_QUIET_TOPICS)],
                    'case=%s, variant=robust, seed=%d, max_ticks=%d' % (CASE, SEED, ticks),
                    beside=beside)
        wait_ready(client, record)
        answer = client.plan_circle(ros_params('planner.yaml'))
        if answer is None or not answer.accepted:
            raise RuntimeError('the planner did not start the circle: %s' % (
                'no answer' if answer is None else answer.reason))
        cpu0, wake0 = graph.cpu(), graph.wakeups()
        wait_for_file(timing_path, graph, 120.0 + ticks * 0.01, 'lockstep run')
        cpu1, wake1 = graph.cpu(), graph.wakeups()
        hwm = graph.vmhwm()
        lag = None
        if record:
            # The sim holds at max_steps: stop nothing before the recorder has it all.
            _count, lag = client.recorder_drained()
    finally:
        codes = graph.stop_all()
    load1 = load_average()
    t = np.load(timing_path)
    pub, rec = t['published'], t['received']
    wall = pub[ticks] - pub[0]
    sim_s = ticks * float(t['dt'])
    latency = (rec[:ticks] - pub[:ticks]) * 1e6
    p50, p99, pmax = _percentiles(latency[np.isfinite(latency)])
    counts = {}
    if record:
        for topic, info in open_bag(bag).topics.items():
            counts[topic] = info.count
    kept = counts.get('/controller_state', 0)
    say('%s: %.3f s simulated in %.3f s wall: %.2fx real time; latency p50 %.0f us, '
        'p99 %.0f us; bag: %d controller_state; exit codes %s; load %.2f -> %.2f'
        % (tag, sim_s, wall, sim_s / wall, p50, p99, kept, codes, load0, load1))
    rows = [
        {'name': '%s 1 kHz + recorder: real-time factor' % tag,
         'value': sim_s / wall, 'unit': 'x', 'target': '>= 2'} if record else
        {'name': '%s 1 kHz, NO recorder: real-time factor' % tag,
         'value': sim_s / wall, 'unit': 'x', 'target': None},
        {'name': '%s: wall time per tick' % tag, 'value': 1e6 * wall / ticks, 'unit': 'us',
         'target': None},
        {'name': '%s: state->command latency p50' % tag, 'value': p50, 'unit': 'us',
         'target': None},
        {'name': '%s: state->command latency p99' % tag, 'value': p99, 'unit': 'us',
         'target': None},
    ]
    if record:
        rows.append({'name': '%s: ticks missing in the bag' % tag,
                     'value': max(0, ticks - kept), 'unit': 'ticks', 'target': '<= 0'})
        rows.append({'name': '%s: recorder behind at the last tick (until drained)' % tag,
                     'value': lag, 'unit': 's', 'target': None})
    rows += _node_rows(tag, cpu0, cpu1, hwm, ticks + 100, wakeups=(wake0, wake1))
    rows.append({'name': '%s: load average (1 min) at the end' % tag, 'value': load1,
                 'unit': '', 'target': None})
    if not ctl_overrides and beside is None:
        LOCKSTEP_ROWS[(layout, record)] = rows
    return rows


LOCKSTEP_ROWS = {}
"""{(layout, recorder on): the rows of this process's last lockstep run} (``bench/echo.py``
takes the controller's and the simulator's CPU per tick from them when ``make bench`` ran
one)."""


# -- real time --------------------------------------------------------------------------
_BOUND = {}


def offline_bound(case=CASE):
    """Return the offline runner's worst max / rms tracking error [mm] over seeds 0-9."""
    from freejoint_core.offline import run_case
    if case not in _BOUND:
        worst_max = worst_rms = 0.0
        for seed in OFFLINE_SEEDS:
            record, _ = run_case(case, 'robust', seed)
            worst_max = max(worst_max, record['max_mm'])
            worst_rms = max(worst_rms, record['rms_mm'])
        _BOUND[case] = (worst_max, worst_rms)
    return _BOUND[case]


def tracking_error(bag, window_ns):
    """Return (max, rms) mm of |p - p_d| of the controller_state ticks stamped in window."""
    import numpy as np
    from freejoint_common.contract import to_ns
    from freejoint_tools.bagfile import open_bag
    lo, hi = window_ns
    err = []
    for _, msg in open_bag(bag).decode('/controller_state'):
        ns = to_ns(msg.header.stamp)
        if lo <= ns <= hi:
            err.append(np.hypot(msg.position[0] - msg.position_desired[0],
                                msg.position[1] - msg.position_desired[1]))
    if not err:
        return None, None, 0
    err = 1000.0 * np.asarray(err)
    return float(err.max()), float(np.sqrt(np.mean(err ** 2))), len(err)


def plan_rows(tag, bag, case, window_ns):
    """Return the rows of the figures against the plan of the states stamped in the window."""
    from freejoint_core.plan_figures import format_figures, SHARE_MET, tracking_bound_mm
    from freejoint_tools.plan_bag import bag_plan_figures
    bound = tracking_bound_mm(case)[0]
    try:
        fig = bag_plan_figures(bag, bound, window_ns)
    except ValueError as exc:
        say('%s: no figures against the plan: %s' % (tag, exc))
        return [{'name': '%s: figures against the plan' % tag, 'value': 0, 'unit': '',
                 'target': '>= 1'}]
    say('%s: against the plan: %s' % (tag, format_figures(fig)))
    share = None if fig['share'] is None else 100.0 * fig['share']
    return [
        {'name': '%s: end effector vs the plan max' % tag, 'value': fig['max_mm'],
         'unit': 'mm', 'target': None},
        {'name': '%s: end effector vs the plan rms' % tag, 'value': fig['rms_mm'],
         'unit': 'mm', 'target': None},
        {'name': "%s: plan's moving ticks within %.3g mm" % (tag, bound), 'value': share,
         'unit': '%', 'target': '>= %g' % (100.0 * SHARE_MET)},
        {'name': '%s: held or braked while the plan moved' % tag, 'value': fig['held_s'],
         'unit': 's', 'target': None},
        {'name': '%s: plans completed (of %d)' % (tag, len(fig['plans'])),
         'value': fig['plans_completed'], 'unit': 'plans', 'target': None},
        {'name': '%s: latest plan end behind its nominal end' % tag,
         'value': fig['late_max_s'], 'unit': 's', 'target': None}]


def bring_up_realtime(client, graph, layout, bag, case, sim, ctl=(), planner=(),
                      custom=None, reset=True):
    """
    Start a real-time graph with the recorder and wait until it runs; raise if it does not.

    The planner holds the start point (the configured circle, delayed "forever"), the
    controller answers from the first state on: the simulator starts last (separate
    processes), at rest on that point. Discovery can take seconds, so once the controller
    answers, the arm goes back to q(0) at rest (the simulator's ``~/reset``, if ``reset``).
    ``sim`` / ``ctl`` / ``planner``: extra overrides of each node.
    """
    composed = layout != 'separate'     # the sim starts with the controller
    sim = ['mode:=realtime'] + list(sim)
    start_graph(graph, layout, bag, sim if composed else None,
                ['lockstep:=false'] + list(ctl),
                ['use_sim_time:=false', 'autostart:=true', 'start_delay:=3600.0']
                + planner_scheduling() + list(planner),
                ['use_sim_time:=false', 'ready_topics:=' + RT_READY_BEFORE_SIM],
                custom or 'case=%s, variant=robust, seed=%d' % (case, SEED), case)
    deadline = time.monotonic() + 60.0
    while True:
        _raise_if_exited(graph)
        ok, status = client.recorder_ready(2.0)
        if ok:
            break
        if time.monotonic() > deadline:
            raise RuntimeError('recorder not ready after 60 s: %s' % status)
    if not composed:
        start_sim(graph, sim, case)
    if not client.spin_until(lambda: graph.exited() or all(
            ' %s 1' % t in client.recorder_status() for t in RT_SIM_TOPICS), 60.0):
        raise RuntimeError('the recorder did not match the simulator within 60 s')
    _raise_if_exited(graph)
    if not client.controller_answers(60.0):
        raise RuntimeError('the controller does not answer the simulator after 60 s')
    if reset:
        from std_srvs.srv import Trigger
        if client.call(Trigger, '/sim_node/reset', Trigger.Request(), 20.0, resend=2.0) is None:
            raise RuntimeError('the simulator did not answer ~/reset')
    client.spin_until(lambda: False, 1.0)   # the controller holds the start point


def _raise_if_exited(graph):
    exited = graph.exited()
    if exited:
        raise RuntimeError('%s exited at start-up (logs in %s): %s' % (
            ', '.join(exited), graph.log_dir, graph.tail(exited[0], 2).strip()))


class CircleLoop:
    """
    The configured circle asked for again and again, each from when the previous was accepted.

    A plan is asked for ``period`` s (the circle's duration + 0.5 s) after the reply that
    accepted the previous one: a late answer (discovery, a loaded machine) delays the next
    plan instead of cutting the running one off.

    ``follow``: each plan is followed to its outcome instead (``plan_outcome``, as a client
    of the ``follow_circle`` action waits for its result): the next is asked for ``rest``
    s after the outcome of the previous arrived, so a plan the feed hold made late runs to
    its end and is neither cut off nor followed by ``before`` (the arm put back) while it
    runs. A plan without an outcome :data:`OUTCOME_WAIT` s past its nominal end is
    recorded as such and the next asked for. :meth:`finish` asks for no more and lets the
    plan running now end (a run is judged with every plan it asked for closed).
    """

    OUTCOME_WAIT = 20.0
    """[s] How long past its duration a followed plan may take (its pauses: the planner's
    ``max_pause`` 5 s each, the feed ramps) before the loop gives up waiting."""

    def __init__(self, client, plan=None, period=None, strict=True, before=None,
                 retry=None, follow=False, rest=0.5):
        self.client = client
        self.strict = strict
        self.before = before
        """Called before each request but the first (e.g. the arm back at rest at q(0)); not
        before a retry of a refused one."""
        self.retry = retry
        """Seconds from a refused request to the next (``strict=False``; None: ``period``)."""
        self.refused = []
        """(monotonic time, reason) of the refused requests (``strict=False``)."""
        self.plan = plan or ros_params('planner.yaml')
        self.period = float(self.plan['duration']) + 0.5 if period is None else period
        self.next = time.monotonic()
        self.retrying = False
        self.accepted = []
        """Monotonic wall times of the accepting replies."""
        self.accepted_wall = []
        """System-clock times (s) of the accepting replies."""
        self.rest = float(rest)
        self.waiting = None
        """(plan id, monotonic deadline) of the followed plan without an outcome yet."""
        self.outcomes = {}
        """plan id -> freejoint_msgs/PlanOutcome received (``follow``)."""
        self.followed = []
        """Plan ids accepted while following, in order."""
        self.unanswered = []
        """Followed plan ids that had no outcome by their deadline."""
        self.finishing = False
        """No more plans asked for (:meth:`finish`)."""
        self._sub = None
        if follow:
            from freejoint_common.contract import PLAN_OUTCOME
            self._sub = client.node.create_subscription(
                PLAN_OUTCOME.msg_type, PLAN_OUTCOME.name,
                lambda msg: self.outcomes.setdefault(int(msg.plan_id), msg), PLAN_OUTCOME.qos)

    def _followed_done(self, now):
        """Return whether the followed plan (if any) has ended; set the next request."""
        if self.waiting is None:
            return True
        plan_id, deadline = self.waiting
        if plan_id in self.outcomes:
            self.waiting = None
            self.next = now + self.rest
            return False
        if now > deadline:
            self.unanswered.append(plan_id)
            self.waiting = None
            self.next = now
        return False

    def finish(self):
        """
        Ask for no more plans; return whether the followed plan running now has ended.

        Called in place of :meth:`poll` once a run's time is up: True when no followed plan
        is waiting for its outcome (it came, or the plan passed its deadline and is
        recorded in ``unanswered``).
        """
        self.finishing = True
        self._followed_done(time.monotonic())
        return self.waiting is None

    def poll(self):
        """Ask for the next circle if due; a refusal or silence raises if ``strict``."""
        now = time.monotonic()
        if self.finishing:
            return False
        if self._sub is not None and not self._followed_done(now):
            return False
        if now < self.next:
            return False
        if self.before is not None and self.accepted and not self.retrying:
            self.before()
        answer = self.client.plan_circle(self.plan)
        now = time.monotonic()
        if answer is None or not answer.accepted:
            reason = 'no answer' if answer is None else answer.reason
            if self.strict:
                raise RuntimeError('the planner did not start the circle: %s' % reason)
            self.refused.append((now, reason))
            self.next = now + (self.period if self.retry is None else self.retry)
            self.retrying = True
            return False
        self.retrying = False
        self.accepted.append(now)
        self.accepted_wall.append(time.time())
        self.next = now + self.period
        if self._sub is not None:
            self.followed.append(int(answer.plan_id))
            self.waiting = (int(answer.plan_id),
                            now + float(self.plan['duration']) + self.OUTCOME_WAIT)
        return True


def realtime(client, env, layout='separate', seconds=RT_SECONDS, case=CASE):
    """Run the graph in real time with the recorder for ``seconds``; return the rows."""
    import numpy as np
    tag = 'real time' + ('' if case == CASE else ' ' + case) + LAYOUTS[layout]
    run_dir = os.path.join(OUT, 'realtime_' + layout + ('' if case == CASE else '_' + case))
    shutil.rmtree(run_dir, ignore_errors=True)
    timing_path = os.path.join(run_dir, 'timing.npz')
    bag = os.path.join(run_dir, 'bag')
    graph = Graph(os.path.join(run_dir, 'logs'), 'realtime', env)
    steps = int(seconds * 1000) + RT_STARTUP_STEPS
    # A late (paused) circle runs on; a request the planner refuses (the controller not
    # ready: its readiness guard tripped) is asked again 0.5 s later, and counted.
    loop = CircleLoop(client, follow=True, rest=0.5, strict=False, retry=0.5)
    load0 = load_average()
    say('%s: %g s at 1 kHz, recorder on, each circle 0.5 s after the outcome of the previous, '
        'ROS_DOMAIN_ID %s, load %.2f'
        % (tag, seconds, env['ROS_DOMAIN_ID'], load0))
    exited = []
    try:
        bring_up_realtime(client, graph, layout, bag, case,
                          ['timing_file:=' + timing_path, 'timing_steps:=%d' % steps])
        start = time.monotonic()
        cpu0 = graph.cpu()
        idle0 = machine_cpu_jiffies()
        while time.monotonic() < start + seconds:
            exited = graph.exited()
            if exited:
                say('%s: %s exited during the run (logs in %s): %s' % (
                    tag, ', '.join(exited), graph.log_dir, graph.tail(exited[0], 3).strip()))
                break
            loop.poll()
            client.spin_until(lambda: False, 0.05)      # the outcomes come in
        end = time.monotonic()
        cpu1 = graph.cpu()
        idle1 = machine_cpu_jiffies()
        hwm = graph.vmhwm()
    finally:
        codes = graph.stop_all()
    diverged = graph.diverged()
    if diverged:
        say('%s: the simulator logged %d diverged integration(s) (plant held at its last '
            'finite state; logs in %s)' % (tag, diverged, graph.log_dir))
    load1 = load_average()
    t = np.load(timing_path)
    pub, rec, applied = t['published'], t['received'], t['applied']
    window = np.nonzero((pub >= start) & (pub <= end))[0]
    if len(window) < 2:
        raise RuntimeError('%s: the timing file holds no step of the window' % tag)
    k0, k1 = int(window[0]), int(window[-1])
    ks = np.arange(k0, k1)          # periods k -> k+1 inside the window
    latency = (rec[ks] - pub[ks]) * 1e6
    got = np.isfinite(latency)
    p50, p99, pmax = _percentiles(latency[got])
    stale = int(np.count_nonzero(applied[ks] != ks))
    expected = int(round((pub[k1] - pub[k0]) / float(t['dt'])))
    skipped = max(0, expected - (k1 - k0))
    gaps = np.diff(pub[k0:k1 + 1]) * 1e6
    max_mm, rms_mm, n_err = tracking_error(bag, (int(t['stamp_ns'][k0]),
                                                 int(t['stamp_ns'][k1])))
    bound_max, bound_rms = offline_bound(case)
    plan = plan_rows(tag, bag, case, (int(t['stamp_ns'][k0]), int(t['stamp_ns'][k1])))
    say('%s: %d periods in %.1f s, latency p50 %.0f us p99 %.0f us max %.0f us, %d '
        'without a fresh command (%d without any), %d skipped; tracking max %.3f mm rms %.3f '
        'mm over %d ticks (offline worst max %.3f, rms %.3f); %d plans; exit codes %s; '
        'load %.2f -> %.2f' % (tag, len(ks), end - start, p50, p99, pmax, stale,
                               int(np.count_nonzero(~got)), skipped, max_mm, rms_mm, n_err,
                               bound_max, bound_rms, len(loop.accepted), codes, load0,
                               load1))
    if loop.refused:
        say('%s: %d plan request(s) refused, the first: %s'
            % (tag, len(loop.refused), loop.refused[0][1]))
    rows = [
        {'name': '%s: seconds measured (of %g)' % (tag, seconds),
         'value': (pub[k1] - pub[k0]), 'unit': 's', 'target': '>= %g' % (0.99 * seconds)},
        {'name': '%s: nodes that exited during the run' % tag, 'value': len(exited),
         'unit': 'nodes', 'target': '<= 0'},
        {'name': '%s: plan requests refused (asked again 0.5 s later)' % tag,
         'value': len(loop.refused), 'unit': 'requests', 'target': None},
        {'name': '%s 1 kHz + recorder: latency p50' % tag,
         'value': p50 * 1e-3, 'unit': 'ms', 'target': None},
        {'name': '%s: state->command latency p99' % tag, 'value': p99 * 1e-3, 'unit': 'ms',
         'target': '<= 1'},
        {'name': '%s: state->command latency max' % tag, 'value': pmax * 1e-3,
         'unit': 'ms', 'target': None},
        {'name': '%s: periods without a fresh command' % tag,
         'value': stale, 'unit': 'periods', 'target': '<= 0'},
        {'name': '%s: periods skipped (timer behind)' % tag, 'value': skipped,
         'unit': 'periods', 'target': '<= 0'},
        {'name': '%s: plant diverged (sim log lines)' % tag, 'value': diverged,
         'unit': 'lines', 'target': '<= 0'},
        {'name': '%s: max gap between state publications' % tag,
         'value': gaps.max() * 1e-3, 'unit': 'ms', 'target': None},
        {'name': '%s: error vs controller reference max' % tag, 'value': max_mm,
         'unit': 'mm', 'target': '<= %.4g' % bound_max},
        {'name': '%s: error vs controller reference rms' % tag, 'value': rms_mm,
         'unit': 'mm', 'target': '<= %.4g' % bound_rms},
    ] + plan
    rows += _node_rows(tag, cpu0, cpu1, hwm, len(ks), exited)
    hz = os.sysconf('SC_CLK_TCK') * (end - start)
    used = sum(cpu1[n] - cpu0.get(n, 0.0) for n in cpu1) / (end - start)
    idle, steal = ((b - a) / hz for a, b in zip(idle0, idle1))
    say('%s: the graph used %.2f cores; the machine (%d CPUs) was idle %.2f cores, stolen %.2f'
        % (tag, used, os.cpu_count(), idle, steal))
    rows += [
        # A core free with the recorder on (a 2-core machine keeps one for the rest).
        {'name': '%s: CPU of the graph (every process of it)' % tag, 'value': used,
         'unit': 'cores', 'target': '<= 1'},
        {'name': '%s: CPU idle on the machine' % tag, 'value': idle, 'unit': 'cores',
         'target': '>= 1'},
        {'name': '%s: CPU stolen by the hypervisor' % tag, 'value': steal, 'unit': 'cores',
         'target': None},
        {'name': '%s: load average (1 min) at the end' % tag, 'value': load1, 'unit': '',
         'target': None}]
    return rows


RUNS = (('lockstep', 'separate', CASE), ('lockstep', 'composed', CASE),
        ('lockstep', 'loop', CASE), ('realtime', 'separate', CASE),
        ('realtime', 'separate', 'vertical'), ('realtime', 'composed', CASE),
        ('realtime', 'loop', CASE))
"""The runs of ``make bench``: both modes in each layout (the horizontal case), and the
vertical case in real time, a process per node."""


def run(which=RUNS):
    """Return the benchmark rows: list of dict(name, value, unit, target)."""
    missing = [exe for exe in (executable('freejoint_sim', 'sim_node'),
                               executable('freejoint_control', 'controller_node'),
                               executable('freejoint_planner', 'planner_node'),
                               executable('freejoint_tools', 'recorder'),
                               executable('freejoint_bringup', 'graph'))
               if not os.path.exists(exe)]
    if missing:
        raise RuntimeError('not built: %s (run tools/setup.sh)' % ', '.join(missing))
    rows = [{'name': 'graph runs: sim and controller thread_priority (SCHED_FIFO; 0 = off)%s'
             % (', cpu_affinity [%s]' % AFFINITY if AFFINITY else ''),
             'value': PRIORITY, 'unit': '', 'target': None}]
    say('sim and controller: thread_priority %d%s' % (
        PRIORITY, ', cpu_affinity [%s]' % AFFINITY if AFFINITY else ''))
    for i, (kind, layout, case) in enumerate(which):
        env = _env(i)
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']   # this process's node too
        client = Client()
        try:
            if kind == 'lockstep':
                rows += lockstep(client, env, layout)
            else:
                rows += realtime(client, env, layout, case=case)
        except (RuntimeError, OSError) as exc:
            say('%s %s (%s) run failed: %s' % (kind, case, layout, exc))
            rows.append({'name': '%s%s%s run completed' % (
                kind, '' if case == CASE else ' ' + case, LAYOUTS[layout]), 'value': 0,
                'unit': '', 'target': '>= 1'})
        finally:
            client.close()
    return rows


def main(argv):
    """Run the benchmark from the command line; print the rows."""
    which = [(k, lay, case) for k, lay, case in RUNS
             if not ('--lockstep-only' in argv and k != 'lockstep')
             and not ('--realtime-only' in argv and k != 'realtime')
             and not ('--separate-only' in argv and lay != 'separate')
             and not ('--composed-only' in argv and lay != 'composed')
             and not ('--loop-only' in argv and lay != 'loop')
             and not ('--horizontal-only' in argv and case != 'horizontal')
             and not ('--vertical-only' in argv and case != 'vertical')]
    for row in run(which):
        value = row['value']
        print('%-58s %12s %-8s %s' % (row['name'], 'n/a' if value is None else '%.4g' % value,
                                      row['unit'], row['target'] or ''))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
