"""
Soak: the real-time graph at 1 kHz, many runs per case, each judged against the offline bound.

``make soak`` runs, for each case (horizontal, vertical) and each of ``--runs`` runs (default
5) of ``--seconds`` s (default 30): a process per node as ``make demo`` starts them (the
installed executables with ``config/*.yaml``), the recorder on, the simulator and the
controller at SCHED_FIFO ``--priority`` (default 50: ``thread_priority``), the planner's
circle asked for again and again (each 0.5 s after the previous one's outcome; the arm put
back at q(0) after one that succeeded, :func:`rest_at_q0_after`). Each run
has a ROS domain of its own
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), every wait is bounded and every process is
stopped (SIGINT, then SIGKILL of its group) whatever happens. ``--hogs N`` adds N CPU hog
processes at normal priority beside the graph for the whole soak (each ends by itself after
the soak's expected length, and is killed at the end in any case).

Per run, from its bag and the simulator's per-step timing file:

* against the plan (``freejoint_core.plan_figures``, the bag read by
  ``freejoint_tools.plan_bag``): the end effector (``ee_position``) against the planner's
  setpoint interpolated at each state stamp of the measured window, rms / max (columns
  ``plan rms`` / ``plan max``), the share of the plan's moving ticks within the bound
  (``in %``), the time the controller held or the driver braked while the plan moved
  (``held s``), the plans completed and how late the latest ended (``late s``: the plan's
  time stood still that long, e.g. a feed hold), the largest distance from the end
  effector to the path of the plan it ran in (``path mm``), the controller's readiness
  guard trips (``trips``, its end-of-run line) and each plan's outcome;
* against the controller's own reference (``controller_state``: ``|position -
  position_desired|``, the reference held, blended or carried forward), column ``ref max``;
  with ``--stabilise`` or ``--fail-at`` over the ticks whose setpoint moves (the circles:
  every circle's max error), the largest error in the rests apart (column ``rest mm``);
* stale periods: control periods over which the simulator applied no command answering the
  newest state it had published (none, or an older one), and the longest run of them;
* holds: controller ticks with the ``STATUS_HOLDING`` bit (32);
* divergence: the simulator's warning/error log lines about a diverged plant, its
  ``/diagnostics`` messages saying so (when recorded), and a tracking error above 0.5 m;
  beside it the fastest joint of the run (``qd max``, :func:`joint_speed_max`), which tells
  a runaway from an arm parked off the plan by the damped joint hold;
* worst state age: the largest ``state_age`` of ``controller_state`` (the state's age when
  the command went out; every ``*age*`` field is kept in the JSON) and the largest
  state->command latency of the simulator's timing file;
* the largest |effort| per joint;
* the machine's lateness beside the run (``bench/wakeup_probe.py``: a SCHED_FIFO 99
  thread per CPU sleeping 1 ms): its latest wake-up [ms late] (column ``wake``) and the
  count of wake-ups over 10 ms late (``>10``), the latest 20 with their Unix times in the
  JSON. A stall there stalls every node, whatever its priority;
* the CPU over the run (:func:`cpu_shares`), in cores: the graph's nodes (column ``cpu``),
  the time the hypervisor took from the machine's CPUs (``steal``) and the machine's idle
  time (in the JSON): a graph that needs more than the machine has left falls behind.

The bound per case is 1.5 x the offline runner's worst max error over seeds 0-9 (3 x with
hogs; ``freejoint_core.plan_figures.tracking_bound_mm``). A run is met when at least 99 %
of the plan's moving ticks are within it (``plan_figures.plan_met``), or when each plan
off the bound says in its outcome that it paused (a feed hold; finished late) or was
aborted for a controller that was not ready, the arm within the bound of its path
meanwhile (``plan_figures.outcome_excuses``), and the plant did not diverge - whatever
the error against the controller's reference says (kept as ``met_reference``); each run
prints met / NOT met. Each circle is followed to its outcome (``plan_outcome``) before
the arm is put back and the next asked for, so a late circle runs to its end; the
circles asked for and those that succeeded are counted. The
table per run, the worst per case and the conditions (load average, priority, layout, CPU
count, hogs) are printed and written to ``bags/soak/soak.json``.

``--lockstep`` runs the same graph in lockstep instead, one circle per run of ``--seconds``
simulated seconds (the soak's check of its own overlays, bound and judgement in CI; no
real-time figure).

``--arm ARM`` (``ur5``, ``panda`` or a directory of ``fj arm init``) soaks a spatial arm
instead of the paper's two cases: the nodes get the arm's parameter files (``config/<arm>/``
or the directory's) on top of ``config/*.yaml``, as ``make demo ARM=...`` gives them, the
planner asks for the arm's circle (its radius and duration), and the run is judged against
the plan as the paper's arm is: its bound is the same 1.5 x (3 x with hogs) the offline
worst max error over seeds 0-9, of the arm's offline twin (``make offline ARM=...``,
the circle and the hold), run here.

Usage: ``. tools/env.sh && python bench/soak.py [--runs 5] [--seconds 30]
[--cases horizontal vertical | --arm ARM] [--lockstep] [--hogs N] [--priority 50]
[--driver hold-last] [--readiness-action brake|damp|hold] [--stalls LO HI] [--ctl
NAME:=VALUE ...]``. ``--driver hold-last`` meets a driver that holds its last command (no
watchdog, no brakes on request; the controller's ``readiness_action`` then ``hold`` unless
given). ``--stalls 20 50`` stalls each CPU for 20-50 ms every 0.5-2 s (a SCHED_FIFO 98 busy
loop, above the nodes' priority; the same pattern each soak): the stalls of a machine whose
host is busy, on demand. ``--ctl`` gives the controller parameters. Bags and logs stay in
``bags/soak/<case>_<run>/`` (git-ignored). Exit code 0 whatever the figures (a benchmark),
1 if a run could not be made.
"""

import argparse
import json
import math
import os
import platform
import shutil
import signal
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import graph as bench_graph  # noqa: E402 - bench/graph.py, the process harness
import wakeup_probe  # noqa: E402, I100 - bench/wakeup_probe.py, the machine's lateness
from freejoint_common.contract import CONTROLLER_STATE, EE_POSITION  # noqa: E402, I100
from freejoint_common.contract import JOINT_STATES, lockstep_writer_overrides  # noqa: E402
from freejoint_common.contract import setpoint_samples  # noqa: E402
from freejoint_common.contract import SETPOINTS, to_ns  # noqa: E402
from freejoint_common.scheduling import rt_budget  # noqa: E402
from freejoint_core.plan_figures import outcome_excuses, plan_met  # noqa: E402, I100
from freejoint_core.plan_figures import SHARE_MET  # noqa: E402

OUT = os.path.join(ROOT, 'bags', 'soak')
CASES = ('horizontal', 'vertical')
ARM_CASE = 'horizontal'
"""The nodes' ``case`` of a spatial arm (``--arm``): its gravity is its URDF base frame's."""
RETRY_S = 0.5
"""Seconds from a circle the planner refused (the controller not ready) to the next request."""
FINISH_STEPS = 60000
"""Real time: timing steps for the plan running when a run's time is up, which the run
waits for (``Session.wait``: its duration + ``CircleLoop.OUTCOME_WAIT`` s at most)."""
STATUS_HOLDING = 32
"""``freejoint_msgs/ControllerState.STATUS_HOLDING`` (the message's constant when it has it)."""
DIVERGED_MM = 500.0
"""A tracking error above this [mm] counts as a diverged run (the offline runner's 0.5 m)."""
HOG_CODE = ('import sys, time\n'
            'end = time.monotonic() + float(sys.argv[1])\n'
            'while time.monotonic() < end:\n'
            '    pass\n')
STALL_CODE = ('import os, random, sys, time\n'
              'cpu, lo, hi, life = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), '
              'float(sys.argv[4])\n'
              'os.sched_setaffinity(0, {cpu})\n'
              'os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(98))\n'
              'rng = random.Random(cpu)\n'
              'end = time.monotonic() + life\n'
              'while time.monotonic() < end:\n'
              '    time.sleep(rng.uniform(0.5, 2.0))\n'
              '    until = time.monotonic() + rng.uniform(lo, hi) / 1e3\n'
              '    while time.monotonic() < until:\n'
              '        pass\n')
"""A stall of one CPU: SCHED_FIFO 98 (above the graph's nodes), busy for lo-hi ms, every
0.5-2 s, its pattern seeded by the CPU's number."""


def say(text):
    """Print a progress line at once."""
    print('[soak] ' + text, flush=True)


def domain_env(index):
    """Environment of run ``index``: a ROS domain (150-229) no other run of this soak uses."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(150 + ((os.getpid() % 5) * 16 + index) % 80)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '0')
    return env


def conditions(priority, hogs):
    """Return the conditions of the soak: machine, load, scheduling, layout."""
    return {'cpu_count': os.cpu_count(), 'machine': platform.machine(),
            'kernel': platform.release(), 'load_average': list(os.getloadavg()),
            'thread_priority': priority, 'scheduling': 'SCHED_FIFO' if priority else 'OTHER',
            'planner_thread_priority': priority - 10 if priority > 10 else 0,
            'layout': 'a process per node (make demo)', 'hogs': hogs,
            'sched_rt_runtime_us': (rt_budget() or (None,))[0],
            'time_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime())}


def holding_bit():
    """Return the HOLDING status bit (the message's constant, else 32)."""
    try:
        from freejoint_msgs.msg import ControllerState
        return int(getattr(ControllerState, 'STATUS_HOLDING', STATUS_HOLDING))
    except ImportError:
        return STATUS_HOLDING


def effort_limits():
    """Return the controller's per-joint effort limits of config/controller.yaml (or None)."""
    ctl = bench_graph.ros_params('controller.yaml')
    limits = ctl.get('effort_limits')
    if limits:
        return [float(v) for v in limits]
    tau = float(ctl.get('tau_limit', 0.0) or 0.0)
    return [tau, tau] if tau > 0.0 else None


# -- CPU hogs ---------------------------------------------------------------------------
class Hogs:
    """
    N busy-loop processes at normal priority; each ends by itself after ``lifetime`` s.

    ``stalls`` (lo, hi) [ms]: a stalling process per CPU besides (:data:`STALL_CODE`).
    """

    def __init__(self, count, lifetime, stalls=None):
        self.procs = []
        for _ in range(count):
            self.procs.append(subprocess.Popen(
                [sys.executable, '-c', HOG_CODE, '%.0f' % lifetime],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        stallers = [subprocess.Popen(
            [sys.executable, '-c', STALL_CODE, str(cpu), '%g' % stalls[0], '%g' % stalls[1],
             '%.0f' % lifetime], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            start_new_session=True) for cpu in sorted(os.sched_getaffinity(0))] if stalls else []
        self.procs += stallers
        if stallers:
            time.sleep(0.5)
            for proc in stallers:
                if proc.poll() is not None:
                    err = proc.stderr.read().decode(errors='replace').strip().splitlines()
                    self.stop()
                    raise RuntimeError('--stalls needs SCHED_FIFO (root, CAP_SYS_NICE or an '
                                       'rtprio limit): %s' % (err[-1] if err else 'exited'))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    def stop(self):
        """SIGINT each hog, then SIGKILL after 2 s; wait for all (bounded)."""
        for proc in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in self.procs:
            try:
                proc.wait(2.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5.0)
        self.procs = []


# -- one real-time graph ----------------------------------------------------------------
class Session:
    """
    One real-time graph (a process per node, recorder on) in a ROS domain of its own.

    ``with Session(...) as s: s.up(); ...``: on leaving, every process is stopped (the
    controller first, the recorder last) and this process's rclpy is shut down, whatever
    happened. ``kill(name)`` is kill -9 of a node; ``restart(name)`` starts it again with
    the same command line (``replace``: {old override: new} items changed).
    """

    def __init__(self, name, index, case, seconds, sim=(), ctl=(), planner=(), reset=True,
                 timing=True, lockstep=False):
        self.name = name
        self.case = case
        self.dir = os.path.join(OUT, name)
        shutil.rmtree(self.dir, ignore_errors=True)
        os.makedirs(self.dir)
        self.bag = os.path.join(self.dir, 'bag')
        self.timing_path = os.path.join(self.dir, 'timing.npz') if timing else None
        self.env = domain_env(index)
        self.sim = list(sim)
        self.ctl, self.planner, self.reset = list(ctl), list(planner), reset
        self.lockstep = lockstep
        self.steps = int(round(seconds * 1000))
        if lockstep:
            self.sim += ['timing_file:=' + self.timing_path,
                         'timing_steps:=%d' % (self.steps + 1), 'max_steps:=%d' % self.steps]
            self.sim += lockstep_writer_overrides('sim')    # the recorder loses no tick
            self.ctl += lockstep_writer_overrides('controller')
        elif timing:
            self.sim += ['timing_file:=' + self.timing_path,
                         'timing_steps:=%d' % (int(seconds * 1000) + FINISH_STEPS
                                               + bench_graph.RT_STARTUP_STEPS)]
        self.client = None
        self.graph = bench_graph.Graph(os.path.join(self.dir, 'logs'), 'run', self.env)
        self.codes = {}
        self.restarts = {}
        self.killed = set()

    def __enter__(self):
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ['ROS_DOMAIN_ID'] = self.env['ROS_DOMAIN_ID']   # this process's node
        self.client = bench_graph.Client()
        return self

    def __exit__(self, *exc):
        try:
            self.codes = self.graph.stop_all()
        finally:
            self.client.close()

    def up(self):
        """Start the graph and wait until the controller holds the start point."""
        if self.lockstep:
            bench_graph.start_graph(
                self.graph, 'separate', self.bag, self.sim, self.ctl,
                self.planner + ['autostart:=false'],
                ['use_sim_time:=true',      # the drain wait needs a count that goes quiet
                 'exclude:=[%s]' % ', '.join(bench_graph.NEVER_QUIET_TOPICS)],
                'case=%s, variant=robust, seed=%d, soak=%s, mode=lockstep'
                % (self.case, bench_graph.SEED, self.name), self.case)
            bench_graph.wait_ready(self.client, True)
            return
        bench_graph.bring_up_realtime(
            self.client, self.graph, 'separate', self.bag, self.case, self.sim, self.ctl,
            self.planner, 'case=%s, variant=robust, seed=%d, soak=%s'
            % (self.case, bench_graph.SEED, self.name), reset=self.reset)

    def wait(self, seconds, loop=None):
        """
        Spin ``seconds`` s (asking for circles if ``loop``); raise if a node exited.

        A ``loop`` that follows its plans (``CircleLoop.finish``) then asks for no more
        and the spin goes on until the plan running at the end has its outcome (at most
        its duration + ``CircleLoop.OUTCOME_WAIT`` s).
        """
        end = time.monotonic() + seconds
        finishing = False
        while True:
            now = time.monotonic()
            if now >= end:
                if getattr(loop, 'finish', None) is None or loop.finish():
                    break
                finishing = True
            exited = [n for n in self.graph.exited() if n not in self.killed]
            if exited:
                raise RuntimeError('%s exited (logs in %s): %s' % (
                    ', '.join(exited), self.graph.log_dir,
                    self.graph.tail(exited[0], 3).strip()))
            if loop is not None and not finishing:
                loop.poll()
            self.client.spin_until(lambda: False,
                                   0.05 if finishing else min(0.05, max(0.0, end - now)))

    def kill(self, name):
        """Send SIGKILL to the node's process group (kill -9); return the system time (s)."""
        proc = self.graph.procs[name]
        now = time.time()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10.0)
        proc.log_file.close()
        self.killed.add(name)
        return now

    def restart(self, name, replace=None, prefix=()):
        """Start ``name`` again with its command line (after ``prefix``); return the time."""
        old = self.graph.procs[name]
        cmd = [(replace or {}).get(a, a) for a in getattr(old, 'cmd', old.args)]
        self.restarts[name] = self.restarts.get(name, 0) + 1
        now = time.time()
        self.graph.start(name, list(prefix) + cmd,
                         log_name='%s_%d' % (name, self.restarts[name] + 1))
        self.graph.procs[name].cmd = cmd
        self.killed.discard(name)
        return now

    def one_circle(self, plan):
        """
        Lockstep: ask for one circle, wait until the simulator holds at its last step.

        Returns an object with ``accepted`` (monotonic times of the accepting reply) and
        ``refused`` as :class:`bench_graph.CircleLoop` has them; raise if it is refused.
        """
        answer = self.client.plan_circle(plan)
        if answer is None or not answer.accepted:
            raise RuntimeError('the planner did not start the circle: %s' % (
                'no answer' if answer is None else answer.reason))
        done = bench_graph.CircleLoop(self.client, plan)
        done.accepted.append(time.monotonic())
        bench_graph.wait_for_file(self.timing_path, self.graph, 120.0 + self.steps * 0.05,
                                  'lockstep run')
        self.client.recorder_drained()      # the sim holds at max_steps: the bag complete
        return done

    def diverged_lines(self):
        """Return the simulator's log lines about a diverged plant."""
        return self.graph.diverged()

    def guard_trips(self):
        """Return the readiness guard's trips of the controller's end-of-run line (None)."""
        import re
        path = os.path.join(self.graph.log_dir, 'run_controller_node.log')
        try:
            with open(path, errors='replace') as f:
                found = re.findall(r'readiness guard: (\d+) trips', f.read())
        except OSError:
            return None
        return int(found[-1]) if found else None


# -- analysis ---------------------------------------------------------------------------
def stale_periods(timing_path, mono_window):
    """
    Return the simulator's timing figures of the periods inside ``mono_window``.

    Returns
    -------
    dict
        ``periods``, ``stale`` (periods whose applied command did not answer the newest
        state published), ``longest_stale`` (consecutive), ``latency_max_ms`` (largest
        state->command latency), ``latency_p99_ms``, ``stamp_window_ns`` (the stamps of
        the first and last state of the window), ``skipped`` (periods the sim dropped).

    """
    import numpy as np
    t = np.load(timing_path)
    pub, rec, applied, stamp = t['published'], t['received'], t['applied'], t['stamp_ns']
    published = np.isfinite(pub)
    lo, hi = mono_window
    window = np.nonzero(published & (pub >= lo) & (pub <= hi))[0]
    if len(window) < 2:
        raise RuntimeError('the timing file %s holds no step of the window' % timing_path)
    k0, k1 = int(window[0]), int(window[-1])
    idx = np.arange(len(pub))
    newest = np.maximum.accumulate(np.where(published, idx, -1))
    ks = np.arange(k0, k1)
    stale = applied[ks] != newest[ks]
    longest = run = 0
    for s in stale:
        run = run + 1 if s else 0
        longest = max(longest, run)
    latency = (rec[window] - pub[window]) * 1e3
    latency = latency[np.isfinite(latency)]
    return {'periods': int(len(ks)), 'stale': int(np.count_nonzero(stale)),
            'longest_stale': int(longest),
            'latency_max_ms': float(latency.max()) if len(latency) else None,
            'latency_p99_ms': float(np.percentile(latency, 99)) if len(latency) else None,
            'stamp_window_ns': (int(stamp[k0]), int(stamp[k1])),
            'skipped': int(t['dropped'])}


def stamp_ns(msg):
    """Return a header stamp in ns."""
    return to_ns(msg.header.stamp)


def controller_ticks(bag_path):
    """
    Return the bag's controller_state as arrays (one row per message, arrival order).

    Returns
    -------
    dict of numpy.ndarray
        ``log_ns``, ``stamp_ns``, ``err_mm`` (|p - p_d|), ``p`` (n, 2) [m], ``pd`` (n, 2),
        ``status``, ``effort`` (n, joints), and one array per ``*age*`` field of the
        message (as recorded).

    """
    import numpy as np
    from freejoint_tools.bagfile import open_bag
    msgs = open_bag(bag_path).decode(CONTROLLER_STATE.absolute)
    if not msgs:
        raise RuntimeError('no controller_state in %s' % bag_path)
    fields = [f for f in getattr(msgs[0][1], '__dataclass_fields__', {}) if 'age' in f]
    out = {'log_ns': np.array([lt for lt, _ in msgs], dtype=np.int64),
           'stamp_ns': np.array([stamp_ns(m) for _, m in msgs], dtype=np.int64),
           'p': np.array([list(m.position) for _, m in msgs]),
           'pd': np.array([list(m.position_desired) for _, m in msgs]),
           'status': np.array([int(m.status) for _, m in msgs], dtype=np.int64)}
    width = max(len(m.effort) for _, m in msgs)
    effort = np.full((len(msgs), width), np.nan)
    for i, (_, m) in enumerate(msgs):
        effort[i, :len(m.effort)] = m.effort
    out['effort'] = effort
    diff = out['p'] - out['pd']
    # 2 values (the planar arms: hypot, as before) or 3 (a spatial arm's tip)
    out['err_mm'] = 1000.0 * (np.hypot(*diff.T) if diff.shape[1] == 2
                              else np.linalg.norm(diff, axis=1))
    for f in fields:
        try:
            out['age:' + f] = np.array([float(getattr(m, f)) for _, m in msgs])
        except (TypeError, ValueError):
            pass
    return out


def plant_ticks(bag_path, joints=('joint1', 'joint2')):
    """
    Return what the plant did, from the simulator's and the planner's topics of the bag.

    Independent of the controller (a restarted controller's first ticks can reach the
    recorder seconds late, after discovery): the end effector (``ee_position``) against the
    planner's newest setpoint stamped at most half a period after the state (the
    controller's rule), and the effort the simulator applied (``joint_states.effort``).

    Returns
    -------
    dict of numpy.ndarray
        ``log_ns``, ``stamp_ns``, ``p`` (n, 2) [m], ``pd`` (n, 2) (NaN before the first
        setpoint), ``err_mm``, ``effort`` (n, len(joints)) [N m] (NaN where the
        joint_states of the stamp is missing).

    """
    import numpy as np
    from freejoint_tools.bagfile import open_bag
    bag = open_bag(bag_path)
    ee = bag.decode(EE_POSITION.absolute)
    if not ee:
        raise RuntimeError('no ee_position in %s' % bag_path)
    log_ns = np.array([lt for lt, _ in ee], dtype=np.int64)
    stamps = np.array([stamp_ns(m) for _, m in ee], dtype=np.int64)
    p = np.array([(m.point.x, m.point.y) for _, m in ee])
    setpoints, i = paired_setpoints(bag, stamps)
    pd = np.full_like(p, np.nan)
    ok = i >= 0
    if setpoints:
        sp = np.array([(m.position[0], m.position[1]) for m in setpoints])
        pd[ok] = sp[i[ok]]
    effort = np.full((len(ee), len(joints)), np.nan)
    index = {k: j for j, k in enumerate(stamps.tolist())}
    for _, msg in bag.decode(JOINT_STATES.absolute):
        j = index.get(stamp_ns(msg))
        if j is not None and msg.effort is not None and len(msg.effort):
            names = list(msg.name)
            effort[j] = [msg.effort[names.index(n)] if n in names else np.nan
                         for n in joints]
    return {'log_ns': log_ns, 'stamp_ns': stamps, 'p': p, 'pd': pd, 'effort': effort,
            'err_mm': 1000.0 * np.hypot(*(p - pd).T)}


def moving_setpoints(bag_path, stamps):
    """
    Return, per stamp, whether the planner's setpoint of that stamp moves (a task's tick).

    Parameters
    ----------
    bag_path : str
        The run's bag (its ``SETPOINTS`` topic).
    stamps : numpy.ndarray of int, (n,)
        Tick stamps [ns].

    Returns
    -------
    numpy.ndarray of bool, (n,)
        True where the setpoint the controller paired with that stamp (the newest stamped
        at most half a period after it) has a nonzero velocity or acceleration; False at
        rest and before the first setpoint.

    """
    import numpy as np
    from freejoint_tools.bagfile import open_bag
    setpoints, i = paired_setpoints(open_bag(bag_path), stamps)
    if not setpoints:
        return np.zeros(len(stamps), dtype=bool)
    flags = np.array([bool(any(m.velocity) or any(m.acceleration)) for m in setpoints])
    return np.where(i >= 0, flags[np.maximum(i, 0)], False)


def bag_setpoints(bag):
    """
    Yield ``(log_ns, setpoint)`` of every setpoint in the bag, in recorded order.

    The setpoints of the ``SETPOINTS`` batches (``freejoint_common.setpoint.SetpointSample``
    each), a batch's log time for each of its setpoints; nothing if the bag has no such topic.
    """
    if SETPOINTS.absolute in bag.topics:
        for log_ns, msg in bag.decode(SETPOINTS.absolute):
            for sp in setpoint_samples(msg):
                yield log_ns, sp


def paired_setpoints(bag, stamps):
    """
    Return the bag's setpoints and, per state stamp, the index of the one the controller paired.

    The controller's rule: the newest setpoint stamped at most half a period after the state.

    Parameters
    ----------
    bag : freejoint_tools.bagfile bag
        An open bag (its ``SETPOINTS`` topic; none: no setpoint).
    stamps : array_like of int, (n,)
        State stamps [ns].

    Returns
    -------
    setpoints : list of freejoint_common.setpoint.SetpointSample
        One per stamp (the last recorded), in stamp order.
    index : numpy.ndarray of int, (n,)
        Into ``setpoints``; -1 before the first setpoint (and everywhere without one).

    """
    import numpy as np
    by_stamp = {}
    for _, sp in bag_setpoints(bag):
        by_stamp[sp.stamp_ns] = sp
    stamps = np.asarray(stamps, dtype=np.int64)
    if not by_stamp:
        return [], np.full(len(stamps), -1, dtype=np.int64)
    sp_stamps = np.array(sorted(by_stamp), dtype=np.int64)
    half = int(np.median(np.diff(sp_stamps)) // 2) if len(sp_stamps) > 1 else 0
    index = np.searchsorted(sp_stamps, stamps + half, side='right') - 1
    return [by_stamp[k] for k in sp_stamps.tolist()], index


def diagnostics_diverged(bag_path):
    """Return the /diagnostics messages of the bag saying a plant diverged (0 if none)."""
    from freejoint_tools.bagfile import open_bag
    bag = open_bag(bag_path)
    if '/diagnostics' not in bag.topics:
        return 0
    count = 0
    for _, msg in bag.decode('/diagnostics'):
        for status in msg.status:
            level = status.level
            level = (int.from_bytes(level, 'little') if isinstance(level, (bytes, bytearray))
                     else int(level))
            text = ' '.join([status.message] + ['%s %s' % (kv.key, kv.value)
                                                for kv in status.values]).lower()
            if level >= 2 and 'diverg' in text:
                count += 1
                break
    return count


def joint_speed_max(bag_path, window_ns):
    """
    Return the fastest |joint velocity| [rad/s] of the bag's joint_states in ``window_ns``.

    Any joint, the passive ones included, as the simulator measured it: it tells an arm
    that ran away (a joint at hundreds of rad/s) from one parked off the plan by a stop
    (the damped joint hold: the free link swinging at a few rad/s), which the error
    against the plan does not. None without a state in the window.
    """
    from freejoint_tools.bagfile import open_bag
    lo, hi = window_ns
    fastest = None
    for _, msg in open_bag(bag_path).decode(JOINT_STATES.absolute):
        if lo <= stamp_ns(msg) <= hi and len(msg.velocity):
            speed = max(abs(v) for v in msg.velocity)
            if fastest is None or speed > fastest:
                fastest = speed
    return fastest


def summarise(ticks, mask):
    """Return tracking, holds, efforts and ages of the ticks selected by ``mask``."""
    import numpy as np
    err = ticks['err_mm'][mask]
    effort = np.abs(ticks['effort'][mask])
    out = {'ticks': int(np.count_nonzero(mask)),
           'max_mm': float(err.max()) if len(err) else None,
           'rms_mm': float(np.sqrt(np.mean(err ** 2))) if len(err) else None,
           'holds': int(np.count_nonzero(ticks['status'][mask] & holding_bit())),
           'effort_max': ([float(v) for v in np.nanmax(effort, axis=0)]
                          if len(effort) else None)}
    for key in ticks:
        if key.startswith('age:'):
            values = ticks[key][mask]
            out['max_' + key[4:]] = float(np.nanmax(values)) if len(values) else None
    return out


def bound_of(case, hogs, arm=None):
    """
    Return (bound mm, factor, offline worst max mm) of ``case``: the seeds run here.

    With ``arm`` (``--arm``): of the arm's offline twin over the same seeds (the circle and
    the hold, ``make offline ARM=arm``), run once per process.
    """
    from freejoint_core.plan_figures import BOUND_SEEDS, tracking_bound_mm
    if arm is None:
        return tracking_bound_mm(case, bool(hogs), recompute=True)
    if arm not in _ARM_MAX_MM:
        from freejoint_tools.arm_twin import run_ticks, twin
        where = arm_dir(arm)
        ticks = run_ticks(where, bench_graph.CONFIG)
        _ARM_MAX_MM[arm] = [twin(where, seed, ticks, bench_graph.CONFIG)[0]['max_mm']
                            for seed in BOUND_SEEDS]
    return tracking_bound_mm(case, bool(hogs), offline_max_mm=_ARM_MAX_MM[arm])


_ARM_MAX_MM = {}


def arm_dir(arm):
    """Return the directory of ``--arm``: ``config/<arm>/`` of a shipped one, else ``arm``."""
    from freejoint_tools.arm_twin import SPATIAL_ARMS
    return os.path.join(bench_graph.CONFIG, arm) if arm in SPATIAL_ARMS else os.path.abspath(arm)


def arm_label(arm):
    """Return the soak's name of a spatial arm: ``ur5``, ``panda`` or its directory's name."""
    from freejoint_tools.arm_twin import arm_info
    try:
        arm_info(arm_dir(arm))
    except FileNotFoundError as exc:
        raise SystemExit('soak: --arm %s' % exc) from None
    return os.path.basename(os.path.normpath(arm))


def arm_overrides(arm):
    """
    Return the (simulator, controller, planner) ``-p`` items of a spatial arm and its plan.

    The arm's files (``config/<arm>/<node>.yaml`` or those of an ``fj arm init``
    directory) as overrides on top of ``config/<node>.yaml``, and the planner's values
    (the circle the soak asks for) of both.
    """
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    from freejoint_tools.arm_twin import arm_configs, arm_files
    where = arm_dir(arm)
    items = [[item for path in arm_files(where, node) for item in schema.overrides(path)]
             for node, schema in (('sim', SIM), ('controller', CONTROLLER),
                                  ('planner', PLANNER))]
    plan = arm_configs(where, bench_graph.CONFIG)[2]
    return items[0], items[1], items[2], plan


def plan_row(bag, bound, window_ns):
    """
    Return the figures against the plan of the states stamped in ``window_ns`` (row items).

    ``freejoint_tools.plan_bag.bag_plan_figures`` of the bag with the run's bound, the
    per-tick arrays dropped; keys prefixed ``plan_`` (``plans`` per plan as listed).
    """
    from freejoint_tools.plan_bag import bag_plan_figures
    fig = bag_plan_figures(bag, bound, window_ns)
    out = {'plan_' + k: v for k, v in fig.items() if k not in ('error_mm', 'moving')}
    out['plan_share_pct'] = None if fig['share'] is None else 100.0 * fig['share']
    return out


def judge(row, bag, bound, window_ns):
    """
    Add the figures against the plan and the verdict to ``row`` (a run's).

    ``row`` holds ``max_mm`` (the error against the controller's reference, None without
    ticks), ``diverged_log_lines`` and ``diverged_diagnostics``; this adds
    :func:`plan_row`'s items of the states stamped in ``window_ns``, ``diverged`` (also a
    tracking error beyond ``DIVERGED_MM``), ``met_reference`` (the controller's reference
    within ``bound``: what it reports) and ``met`` (``plan_figures.plan_met``: 99 % of the
    plan's moving ticks within ``bound``, or the plan's outcome excuses it).
    """
    row.update(plan_row(bag, bound, window_ns))
    row['diverged'] = bool(row['diverged_log_lines'] or row['diverged_diagnostics']
                           or max(row['max_mm'] or 0.0, row['plan_max_mm'] or 0.0)
                           > DIVERGED_MM)
    row['met_reference'] = bool(row['max_mm'] is not None and row['max_mm'] <= bound
                                and not row['diverged'])
    excused, why = outcome_excuses(
        {'bound_mm': bound, 'plans': row.get('plan_plans') or []}, row.get('outcomes', {}))
    paths = [p['path_max_mm'] for p in row.get('plan_plans') or []
             if p.get('path_max_mm') is not None]
    row['plan_path_max_mm'] = max(paths) if paths else None
    row['excused'] = bool(excused and (row['plan_share'] or 0.0) < SHARE_MET)
    row['excuse'] = why
    row['met'] = plan_met({'share': row['plan_share']}, row['diverged'], excused)
    return row


# -- one soak run -----------------------------------------------------------------------
def rest_at_q0(client):
    """
    Put the arm back at rest at q(0) and theta_hat at theta0 (``~/reset`` of sim, controller).

    The next circle then starts as the offline runner's does, so its tracking is comparable
    with the offline bound.

    Back to back (``--back-to-back``) the vertical arm is not comparable: after a circle
    the end effector stops but the passive link keeps swinging (joint speeds of 1-4 rad/s,
    the law's internal motion, which it does not stabilise), the next circle starts from
    that, and the swing grows from circle to circle: offline, with no real-time effect at
    all, the paper's law loses the vertical arm on the 4th back-to-back circle (seed 0).
    """
    from std_srvs.srv import Trigger
    if client.call(Trigger, '/sim_node/reset', Trigger.Request(), 10.0, resend=2.0) is None:
        raise RuntimeError('no answer from /sim_node/reset')
    # A controller that is down (a restart scenario) starts from theta0 anyway.
    client.call(Trigger, '/controller_node/reset', Trigger.Request(), 2.0)
    client.spin_until(lambda: False, 0.2)     # the reset step and the hold settle


def rest_at_q0_after(client, loop):
    """
    Put the arm back at q(0) if the last circle ended at its start point; return whether.

    :func:`rest_at_q0` after a circle ``loop`` followed to SUCCEEDED (the circle closes at
    its start point: the reset moves the arm by its tracking error).
    A plan that ended otherwise (aborted: stopped along its path, the setpoint standing
    there) is not followed by a reset: it would move the arm away from the stream's standing
    setpoint to the start point at once, a jump no arm makes (the vertical arm 220 mm off
    its setpoint, the next plan aborted for the path tolerance at once). The next circle
    joins from where the arm stopped by the planner's transition instead, as it would on a
    real arm. No circle followed yet: reset.
    """
    outcome = loop.outcomes.get(loop.followed[-1]) if loop.followed else None
    if outcome is not None and outcome.code_name != 'SUCCEEDED':
        return False
    rest_at_q0(client)
    return True


STABILISED_OVERLAYS = {'vertical': 'stabilised', 'horizontal': 'stabilised_horizontal'}
"""The overlay of ``--stabilise`` per case (``freejoint_core.circles.
stabilised_options``): vertical config/stabilised/ (the free link starts hanging, its
damping on); horizontal config/stabilised_horizontal/ (the free rotor slowed in the first
0.6 s of each rest, the shift back by 1 s: back to back, the circles 1 s apart)."""
STABILISED_REST = 1.0
"""[s] Between the circles of ``--back-to-back --stabilise`` (the horizontal settle needs
its 0.6-s window and the shift's 0.4-s return; the paper's soak: 0.5 s)."""


def stabilised_overrides(case):
    """Return the (simulator, controller) ``-p`` items of ``--stabilise`` for ``case``."""
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_sim.params import SCHEMA as SIM
    overlay = os.path.join(ROOT, 'config', STABILISED_OVERLAYS[case])
    sim = os.path.join(overlay, 'sim.yaml')
    return (SIM.overrides(sim) if os.path.exists(sim) else [],
            CONTROLLER.overrides(os.path.join(overlay, 'controller.yaml')))


def fully_actuated_overrides(damped=False):
    """
    Return the (simulator, controller, planner) ``-p`` items of config/fully_actuated/.

    ``damped`` (``--fully-actuated --stabilise``): the controller's also take
    config/fully_actuated/free_link_damping.yaml (the link a failure frees, damped in
    the rests).
    """
    from freejoint_control.params import SCHEMA as CONTROLLER
    from freejoint_planner.params import SCHEMA as PLANNER
    from freejoint_sim.params import SCHEMA as SIM
    overlay = os.path.join(ROOT, 'config', 'fully_actuated')
    sim, ctl, planner = (schema.overrides(os.path.join(overlay, node + '.yaml'))
                         for schema, node in ((SIM, 'sim'), (CONTROLLER, 'controller'),
                                              (PLANNER, 'planner')))
    if damped:
        ctl = ctl + CONTROLLER.overrides(os.path.join(overlay, 'free_link_damping.yaml'))
    return sim, ctl, planner


FAIL_JOINT = 'joint3'
"""The joint ``--fail-at`` makes fail (the simulator's ``~/fail_joint``)."""


class FailAt:
    """
    One circle; ``after`` s past the reply that accepted it the simulator's joint fails.

    ``poll`` as ``graph.CircleLoop``'s; ``wall`` is the system time [s] of the
    ``~/fail_joint`` call (its answer, ``at``, the simulator's time of it).
    """

    def __init__(self, client, after):
        self.circles = bench_graph.CircleLoop(client, period=math.inf)
        self.client = client
        self.after = after
        self.wall = None
        self.answer = None

    @property
    def accepted(self):
        """Return the accepting replies' monotonic times (``CircleLoop.accepted``)."""
        return self.circles.accepted

    def poll(self):
        """Ask for the circle, then make the joint fail when due."""
        self.circles.poll()
        if self.wall is None and self.accepted and \
                time.monotonic() >= self.accepted[0] + self.after:
            from freejoint_msgs.srv import FailJoint
            self.wall = time.time()
            self.answer = self.client.call(FailJoint, '/sim_node/fail_joint',
                                           FailJoint.Request(joint=FAIL_JOINT), 10.0)
            if self.answer is None or not self.answer.success:
                raise RuntimeError('~/fail_joint: %s' % (
                    'no answer' if self.answer is None else self.answer.message))


def controller_detections(graph):
    """Return the controller's 'joint failure:' log lines (its detections)."""
    out = []
    for path in graph.procs['controller_node'].logs:
        with open(path) as f:
            out += [line.split('joint failure: ', 1)[1].strip() for line in f
                    if 'joint failure: ' in line]
    return out


def injected_at(graph):
    """Return the system time [s] of the simulator's 'joint failure injected' line, or None."""
    import re
    for path in graph.procs['sim_node'].logs:
        with open(path) as f:
            for line in f:
                found = re.match(r'\[\w+\] \[([0-9.]+)\] \[sim_node\]: joint failure injected',
                                 line)
                if found:
                    return float(found.group(1))
    return None


def driver_overrides(driver, action):
    """
    Return the (simulator, controller) ``-p`` items of ``--driver`` and ``--readiness-action``.

    ``hold-last``: the simulator as a driver that holds its last command (ros2_control's
    forward command controller: ``command_watchdog: false``, brake requests ignored); the
    controller's ``readiness_action`` as given (None: its configured one).
    """
    sim = ['command_watchdog:=false'] if driver == 'hold-last' else []
    ctl = [] if action is None else ['readiness_action:=%s' % action]
    return sim, ctl


def soak_run(case, index, run, seconds, hogs, back_to_back=False, stabilise=False,
             fully_actuated=False, fail_at=None, ctl_extra=(), driver='watchdog',
             action=None, arm=None, lockstep=False):
    """
    Make one run of ``case``; return its row (dict). ``ctl_extra``: controller items.

    ``arm``: a spatial arm (``--arm``; ``case`` its label, :func:`arm_label`).
    ``lockstep``: the graph in lockstep for ``seconds`` of simulated time, one circle (the
    soak's check of itself: its overlays, bound and judgement; no real-time figure).
    """
    name = '%s_%d' % (case, run)
    planner = []
    plan = None
    if arm is not None:
        sim, ctl, planner, plan = arm_overrides(arm)
    elif fully_actuated:
        sim, ctl, planner = fully_actuated_overrides(stabilise)
    else:
        sim, ctl = stabilised_overrides(case) if stabilise else ([], [])
    extra_sim, extra_ctl = driver_overrides(driver, action)
    sim, ctl = list(sim) + extra_sim, list(ctl) + extra_ctl + list(ctl_extra)
    bound, factor, worst = bound_of(case, hogs, arm)
    row = {'case': case, 'run': run, 'seconds': seconds, 'bound_mm': bound,
           'bound_factor': factor, 'offline_worst_max_mm': worst}
    if arm is not None:
        row['arm'] = arm
    load0 = os.getloadavg()[0]
    with Session(name, index, case if arm is None else ARM_CASE, seconds, sim=sim, ctl=ctl,
                 planner=planner, lockstep=lockstep) as s:
        row['ros_domain_id'] = s.env['ROS_DOMAIN_ID']
        s.up()
        if lockstep:
            loop = None
        elif fail_at is not None:
            loop = FailAt(s.client, fail_at)
        else:
            plan = plan or bench_graph.ros_params('planner.yaml')
            period = float(plan['duration']) + (STABILISED_REST if stabilise else 0.5)
            # a circle the planner refuses (the controller not ready) is asked for again
            # every RETRY_S; the run is judged from its bag, the refusals counted
            # each circle followed to its outcome (a paused plan finishes late), the
            # next asked for period - duration s after it
            loop = bench_graph.CircleLoop(
                s.client, plan, period, strict=False, retry=RETRY_S,
                before=None if back_to_back else (lambda: rest_at_q0_after(s.client, loop)),
                follow=True, rest=period - float(plan['duration']))
        # The machine's own lateness beside the run: a SCHED_FIFO 99 probe per CPU
        # (a stall there stalls every node; columns 'wake' and '>10').
        with wakeup_probe.Probes() as probes:
            cpu0, jiffies0 = s.graph.cpu(), bench_graph.machine_cpu_jiffies()
            start = wall0 = time.monotonic()
            if lockstep:
                loop = s.one_circle(plan or bench_graph.ros_params('planner.yaml'))
                start = -math.inf     # every step of the run (the timing file's)
            else:
                s.wait(seconds, loop)
            end = time.monotonic()
            cpu1, jiffies1 = s.graph.cpu(), bench_graph.machine_cpu_jiffies()
            wake = probes.stop()
    row.update(cpu_shares(cpu0, cpu1, jiffies0, jiffies1, end - wall0))
    if fully_actuated:
        row['failure_lines'] = controller_detections(s.graph)
        row['detections'] = len(row['failure_lines'])
        row['injected_wall_s'] = injected_at(s.graph)
    if wake is not None:
        row['wake_max_ms'], row['wake_late'] = wake['worst_ms'], wake['late']
        row['wake_priority'], row['wake_listed'] = wake['priority'], wake['listed'][:20]
    else:
        row['wake_failure'] = probes.failure
        say('%s run %d: no figures from the machine probe (%s)' % (case, run, probes.failure))
    row['lockstep'] = lockstep
    row['back_to_back'] = back_to_back
    row['stabilised'] = stabilise
    row['driver'], row['readiness_action'] = driver, action
    row['exit_codes'] = s.codes
    row['plans'] = len(loop.accepted)
    outcomes = getattr(loop, 'outcomes', {})
    row['outcomes'] = {pid: (outcomes[pid].code_name, int(outcomes[pid].pauses))
                       for pid in getattr(loop, 'followed', []) if pid in outcomes}
    row['outcome_lines'] = ['plan %d %s: %s (late %.3f s, %d pause(s) %.3f s)' % (
        pid, outcomes[pid].code_name, outcomes[pid].message, outcomes[pid].lateness,
        outcomes[pid].pauses, outcomes[pid].time_paused)
        for pid in getattr(loop, 'followed', []) if pid in outcomes]
    row['no_outcome'] = list(getattr(loop, 'unanswered', []))
    row['circles_asked'] = len(getattr(loop, 'followed', []))
    row['circles_succeeded'] = sum(1 for code, _ in row['outcomes'].values()
                                   if code == 'SUCCEEDED')
    waiting = getattr(loop, 'waiting', None)
    row['running_at_end'] = None if waiting is None else waiting[0]
    refused = getattr(loop, 'refused', [])
    row['refused'] = len(refused)
    row['refused_reasons'] = sorted({reason for _, reason in refused})[:5]
    row['load_before'], row['load_after'] = load0, os.getloadavg()[0]
    timing = stale_periods(s.timing_path, (start, end))
    lo, hi = timing.pop('stamp_window_ns')
    row.update(timing)
    row['stamp_window_ns'] = [lo, hi]
    ticks = controller_ticks(s.bag)
    window = (ticks['stamp_ns'] >= lo) & (ticks['stamp_ns'] <= hi)
    if stabilise or fail_at is not None:
        # Every circle's max error, over the whole circle: the ticks of a moving
        # setpoint. The rests are
        # reported apart: there the horizontal settle shifts the end effector on purpose
        # (up to free_link_delta_max), and after a failure the law leaves the new free
        # link's swing to itself (docs/failures.md).
        moving = moving_setpoints(s.bag, ticks['stamp_ns'])
        rest = summarise(ticks, window & ~moving)
        row['rest_max_mm'] = rest['max_mm']
        window &= moving
    row.update(summarise(ticks, window))
    if row.get('max_state_age') is not None:
        row['state_age_max_ms'] = 1e3 * row['max_state_age']
    row['diverged_log_lines'] = s.diverged_lines()
    row['guard_trips'] = s.guard_trips()
    row['diverged_diagnostics'] = diagnostics_diverged(s.bag)
    row['speed_max'] = joint_speed_max(s.bag, (lo, hi))
    judge(row, s.bag, bound, (lo, hi))
    if fully_actuated:
        row.update(failure_judgement(row, ticks, loop if fail_at is not None else None))
    row['bag'] = os.path.relpath(s.bag, ROOT)
    return row


def failure_judgement(row, ticks, fail):
    """
    Return the failure figures of a fully actuated run.

    No failure made: ``false_alarms`` = the controller's detections.  ``fail`` (a
    :class:`FailAt`): ``detected`` (the failed joint's first detection, its time from the
    controller's line, a state stamp in system time), ``delay_ms`` from the simulator's
    line saying the failure took effect (its log time; ``call_delay_ms`` from the
    ``~/fail_joint`` call), ``false_alarms`` = detections of other joints,
    ``max_after_mm`` the largest tracking error from the call on; ``met`` also asks for a
    detection within ``FAIL_DELAY_MS`` of it taking effect and no false alarm.
    """
    from freejoint_tools.analyze import DETECTED
    import numpy as np
    lines = row['failure_lines']
    if fail is None:
        return {'false_alarms': len(lines), 'met': row['met'] and not lines}
    if fail.wall is None:
        return {'false_alarms': len(lines), 'met': False, 'detected': None,
                'note': 'the joint was not made to fail (the run ended first)'}
    ours = [line for line in lines if line.startswith(FAIL_JOINT + ' failed at t = ')]
    delay = call_delay = None
    if ours:
        t = float(DETECTED.match(ours[0]).group(2))
        call_delay = (t - fail.wall) * 1e3
        if row.get('injected_wall_s') is not None:
            delay = (t - row['injected_wall_s']) * 1e3
    after = ticks['stamp_ns'] >= fail.wall * 1e9
    err = ticks['err_mm'][after]
    out = {'detected': ours[0] if ours else None, 'delay_ms': delay,
           'call_delay_ms': call_delay,
           'false_alarms': len(lines) - len(ours[:1]),
           'max_after_mm': float(np.max(err)) if len(err) else None,
           'fail_wall_s': fail.wall, 'fail_answer_at_s': fail.answer.at}
    out['met'] = bool(row['met'] and ours and delay is not None and delay <= FAIL_DELAY_MS
                      and out['false_alarms'] == 0)
    return out


def cpu_shares(cpu0, cpu1, jiffies0, jiffies1, seconds):
    """
    Return the graph's and the machine's CPU over a run, in cores.

    ``cpu0`` / ``cpu1``: ``{node: CPU seconds}`` of the graph's processes at the run's start
    and end (``bench_graph.Graph.cpu``); ``jiffies0`` / ``jiffies1``: the machine's
    ``(idle, steal)`` jiffies then (``bench_graph.machine_cpu_jiffies``); ``seconds``: the
    wall time between. ``graph_cores``: the nodes' CPU; ``idle_cores``: the machine's idle
    (and iowait) time; ``steal_cores``: the time the hypervisor gave the machine's CPUs to
    others - a graph that needs more cores than the machine has left it falls behind, in
    any controller. None when ``seconds`` is not positive.
    """
    if not seconds > 0.0:
        return {'graph_cores': None, 'idle_cores': None, 'steal_cores': None}
    tick = float(os.sysconf('SC_CLK_TCK'))
    used = sum(cpu1.get(name, 0.0) - cpu0.get(name, 0.0) for name in cpu1)
    return {'graph_cores': used / seconds,
            'idle_cores': (jiffies1[0] - jiffies0[0]) / tick / seconds,
            'steal_cores': (jiffies1[1] - jiffies0[1]) / tick / seconds}


FAIL_DELAY_MS = 50.0
"""A failure made by ``--fail-at`` must be detected within this (the offline detection
budget is 100 ms horizontal, 20 ms vertical; real time adds the service call and a period)."""


COLUMNS = (('case', '%-10s'), ('run', '%3s'), ('plan_rms_mm', '%7.3f'),
           ('plan_max_mm', '%7.3f'), ('plan_share_pct', '%5.1f'), ('plan_held_s', '%6.2f'),
           ('plan_late_max_s', '%6.2f'), ('bound_mm', '%6.2f'), ('max_mm', '%7.3f'),
           ('stale', '%6d'), ('longest_stale', '%5d'),
           ('holds', '%6d'), ('diverged', '%5s'), ('latency_max_ms', '%7.2f'),
           ('state_age_max_ms', '%7.2f'),
           ('plans', '%3d'), ('load_after', '%5.2f'), ('wake_max_ms', '%6.1f'),
           ('wake_late', '%4d'), ('rest_max_mm', '%7.3f'), ('plan_path_max_mm', '%7.3f'),
           ('guard_trips', '%5d'), ('speed_max', '%6.1f'), ('graph_cores', '%4.2f'),
           ('steal_cores', '%4.2f'), ('met', '%4s'))
HEADER = ('case', 'run', 'plan rms', 'plan max', 'in %', 'held s', 'late s', 'bound',
          'ref max', 'stale', 'run', 'holds', 'div',
          'lat ms', 'age ms', 'pl', 'load', 'wake', '>10', 'rest mm', 'path mm', 'trips',
          'qd max', 'cpu', 'steal', 'met')


def format_row(row):
    """Return one table line."""
    cells = []
    for (key, fmt), head in zip(COLUMNS, HEADER):
        value = row.get(key)
        width = int(''.join(c for c in fmt.split('.')[0] if c.isdigit()) or 0)
        if value is None:
            cells.append('%*s' % (max(width, len(head)), 'n/a'))
        elif key == 'met':
            cells.append('%*s' % (max(width, len(head)), 'met' if value else 'NOT'))
        elif key == 'diverged':
            cells.append('%*s' % (max(width, len(head)), 'YES' if value else 'no'))
        else:
            text = fmt % value
            cells.append('%*s' % (max(width, len(head)), text.strip()))
    return ' '.join(cells)


def format_header():
    """Return the table's header line."""
    return ' '.join('%*s' % (max(int(''.join(c for c in fmt.split('.')[0] if c.isdigit())
                                     or 0), len(head)), head)
                    for (_key, fmt), head in zip(COLUMNS, HEADER))


def worst_of(rows):
    """Return the worst figures of a case's rows."""
    done = [r for r in rows if r.get('max_mm') is not None]
    if not done:
        return {'runs': len(rows), 'completed': 0}
    judged = [r for r in done if r.get('plan_max_mm') is not None]
    shares = [r['plan_share_pct'] for r in judged if r.get('plan_share_pct') is not None]
    return {'runs': len(rows), 'completed': len(done),
            'plan_max_mm': max((r['plan_max_mm'] for r in judged), default=None),
            'plan_rms_mm': max((r['plan_rms_mm'] for r in judged), default=None),
            'plan_share_pct': min(shares, default=None),
            'plan_held_s': max((r['plan_held_s'] or 0.0 for r in judged), default=None),
            'plan_late_max_s': max((r['plan_late_max_s'] for r in judged
                                    if r.get('plan_late_max_s') is not None), default=None),
            'plans_completed': sum(r.get('plan_plans_completed', 0) for r in done),
            'plans_total': sum(len(r.get('plan_plans', ())) for r in done),
            'circles_ended': sum(r.get('circles_asked', 0)
                                 - (r.get('running_at_end') is not None) for r in done),
            'circles_succeeded': sum(r.get('circles_succeeded', 0) for r in done),
            'excused_runs': sum(1 for r in done if r.get('excused')),
            'max_mm': max(r['max_mm'] for r in done),
            'rms_mm': max(r['rms_mm'] for r in done),
            'stale': max(r['stale'] for r in done),
            'longest_stale': max(r['longest_stale'] for r in done),
            'holds': max(r['holds'] for r in done),
            'diverged_runs': sum(1 for r in done if r['diverged']),
            'latency_max_ms': max((r['latency_max_ms'] or 0.0) for r in done),
            'state_age_max_ms': max((r.get('state_age_max_ms') or 0.0) for r in done),
            'wake_max_ms': max((r.get('wake_max_ms') or 0.0) for r in done),
            'speed_max': max((r.get('speed_max') or 0.0) for r in done),
            'graph_cores': max((r.get('graph_cores') or 0.0) for r in done),
            'steal_cores': max((r.get('steal_cores') or 0.0) for r in done),
            'idle_cores': min((r['idle_cores'] for r in done
                               if r.get('idle_cores') is not None), default=None),
            'rest_max_mm': max((r.get('rest_max_mm') or 0.0) for r in done),
            'bound_mm': done[0]['bound_mm'],
            'met_runs': sum(1 for r in rows if r.get('met')),
            'met_reference_runs': sum(1 for r in rows if r.get('met_reference')),
            'all_met': all(r.get('met') for r in rows)}


def worst_lines(case, worst):
    """Return the summary lines of a case (:func:`worst_of`): against the plan, then the rest."""
    if not worst.get('completed'):
        return ['%-10s no run completed' % case]
    plan = ('%-10s worst of %d against the plan: max %s mm, rms %s mm, %s %% of the '
            "plan's moving ticks within %.3f mm, held or braked %s s while the plan moved, "
            '%d of %d plans completed%s: %d/%d runs met' % (
                case, worst['completed'], _text(worst['plan_max_mm'], '%.3f'),
                _text(worst['plan_rms_mm'], '%.3f'), _text(worst['plan_share_pct'], '%.1f'),
                worst['bound_mm'], _text(worst['plan_held_s'], '%.2f'),
                worst['plans_completed'], worst['plans_total'],
                '' if worst['plan_late_max_s'] is None
                else ', late by at most %.3f s' % worst['plan_late_max_s'],
                worst['met_runs'], worst['runs']))
    if worst.get('circles_ended'):
        plan += ('; %d of the %d circles asked for succeeded (each run waits for the one '
                 'running at its end; one without an outcome by its deadline left out), late '
                 'allowed; %d run(s) met by their outcomes' % (
                     worst['circles_succeeded'], worst['circles_ended'],
                     worst['excused_runs']))
    rest = ('%-10s vs the controller reference: max %.3f mm, rms %.3f mm; stale %d (longest '
            'run %d), holds %d, diverged runs %d (the fastest joint %.1f rad/s), latency max '
            '%.2f ms, state age max %.2f ms, '
            'machine wake-up late %.1f ms; %d/%d runs within the bound against the reference'
            % (case, worst['max_mm'], worst['rms_mm'], worst['stale'], worst['longest_stale'],
               worst['holds'], worst['diverged_runs'], worst['speed_max'],
               worst['latency_max_ms'],
               worst['state_age_max_ms'], worst['wake_max_ms'], worst['met_reference_runs'],
               worst['runs']))
    if worst['rest_max_mm']:
        rest += '; in the rests at most %.3f mm' % worst['rest_max_mm']
    if worst.get('idle_cores') is not None:
        rest += ('; the graph used up to %.2f cores, the machine idle down to %.2f, stolen '
                 'up to %.2f' % (worst['graph_cores'], worst['idle_cores'],
                                 worst['steal_cores']))
    return [plan, rest]


def _text(value, fmt):
    """Return ``fmt % value``, 'n/a' for None."""
    return 'n/a' if value is None else fmt % value


def parse(argv):
    """Return the command-line options."""
    ap = argparse.ArgumentParser(prog='soak', description=__doc__.strip().splitlines()[0])
    ap.add_argument('--runs', type=int, default=5, help='runs per case (default 5)')
    ap.add_argument('--seconds', type=float, default=30.0,
                    help='measured seconds per run (default 30)')
    ap.add_argument('--cases', nargs='+', choices=CASES, default=list(CASES))
    ap.add_argument('--arm', metavar='ARM',
                    help="a spatial arm in place of the paper's cases: ur5, panda or a "
                    'directory of fj arm init (its circle; bound from its offline twin)')
    ap.add_argument('--lockstep', action='store_true',
                    help='the graph in lockstep, one circle per run of --seconds simulated: '
                    "the soak's check of its own overlays and judgement, no real-time figure")
    ap.add_argument('--hogs', type=int, default=0,
                    help='CPU hog processes at normal priority beside the graph (default 0)')
    ap.add_argument('--priority', type=int, default=50,
                    help='thread_priority (SCHED_FIFO) of sim and controller (0 = off)')
    ap.add_argument('--back-to-back', action='store_true',
                    help='circles back to back, without putting the arm back at rest at q(0) '
                    'before each (the vertical arm then drifts beyond the paper: see '
                    'rest_at_q0)')
    ap.add_argument('--stabilise', action='store_true',
                    help='internal-motion stabilisation: vertical, the free link '
                    'starts hanging and the controller damps it (config/stabilised/); '
                    'horizontal, the free link slowed in the rests '
                    '(config/stabilised_horizontal/); back to back the circles 1 s apart; '
                    'with --fully-actuated the link a failure frees, damped in the rests '
                    '(config/fully_actuated/free_link_damping.yaml)')
    ap.add_argument('--fully-actuated', action='store_true',
                    help='the paper arm with all joints driven and joint failure detection on '
                    "(config/fully_actuated/): each run counts the controller's "
                    'detections (false alarms without --fail-at)')
    ap.add_argument('--fail-at', type=float, default=None, metavar='S',
                    help='with --fully-actuated: one circle per run, joint3 made to fail S s '
                    "after the plan's acceptance (the simulator's ~/fail_joint); reports the "
                    'detection delay and the error after it')
    ap.add_argument('--driver', choices=('watchdog', 'hold-last'), default='watchdog',
                    help='the simulator as a drive with a command watchdog and brakes on '
                    "request (default), or 'hold-last': a driver that applies its last "
                    'command until the next, with no watchdog and no brakes but the start-up '
                    "ones (ros2_control's forward command controller: command_watchdog "
                    'false); docs/real-arm.md')
    ap.add_argument('--readiness-action', choices=('brake', 'damp', 'hold'), default=None,
                    help="the controller's readiness_action (default: its config's, brake, "
                    'with --driver watchdog; hold with --driver hold-last, what '
                    'docs/real-arm.md prescribes for such a driver)')
    ap.add_argument('--stalls', nargs=2, type=float, default=None, metavar=('LO', 'HI'),
                    help='stall each CPU for LO-HI ms every 0.5-2 s (a SCHED_FIFO 98 busy '
                    'loop per CPU, above the nodes: what a machine that stalls does)')
    ap.add_argument('--ctl', nargs='+', default=[], metavar='NAME:=VALUE',
                    help="the controller's parameters beside the soak's own (as its -p items)")
    ap.add_argument('--out', default=os.path.join(OUT, 'soak.json'))
    args = ap.parse_args(argv)
    if any(':=' not in item for item in args.ctl):
        ap.error('--ctl: NAME:=VALUE items')
    if args.stalls is not None and not 0 < args.stalls[0] <= args.stalls[1] <= 500:
        ap.error('--stalls LO HI: 0 < LO <= HI <= 500 [ms]')
    if args.readiness_action is None and args.driver == 'hold-last':
        args.readiness_action = 'hold'
    if args.fail_at is not None and (not args.fully_actuated or args.fail_at < 0):
        ap.error('--fail-at needs --fully-actuated and S >= 0')
    if args.lockstep and (args.fully_actuated or args.driver != 'watchdog'):
        ap.error('--lockstep: one circle in lockstep; --fully-actuated, --driver do not apply')
    if args.arm is not None and (args.stabilise or args.fully_actuated):
        ap.error("--arm: the paper arm's options --stabilise, --fully-actuated do not apply")
    if args.runs < 1 or args.seconds <= 0 or args.hogs < 0 or not 0 <= args.priority <= 98:
        ap.error('--runs >= 1, --seconds > 0, --hogs >= 0, 0 <= --priority <= 98')
    return args


def stop_on_sigterm():
    """Make SIGTERM unwind like SIGINT (every ``finally`` runs: no node left running)."""
    def _exit(signum, _frame):
        raise SystemExit(128 + signum)
    signal.signal(signal.SIGTERM, _exit)


def main(argv=None):
    """Run the soak; print and write the tables; return the exit code."""
    args = parse(sys.argv[1:] if argv is None else argv)
    if args.arm is not None:
        args.cases = [arm_label(args.arm)]
    stop_on_sigterm()
    bench_graph.PRIORITY = args.priority
    os.makedirs(OUT, exist_ok=True)
    cond = conditions(args.priority, args.hogs)
    cond['circles'] = ('back to back' if args.back_to_back else
                       'each from rest at q(0): sim and controller ~/reset before each')
    cond['stabilised'] = args.stabilise
    cond['fully_actuated'] = args.fully_actuated
    cond['fail_at_s'] = args.fail_at
    cond['driver'] = args.driver
    cond['readiness_action'] = args.readiness_action or 'configured (brake)'
    cond['controller_parameters'] = args.ctl
    cond['stalls_ms'] = args.stalls
    say('%d run(s) x %g s per case %s, sim and controller thread_priority %d, %d hog(s), '
        '%d CPUs, load %.2f, driver %s, readiness_action %s' % (
            args.runs, args.seconds, ', '.join(args.cases), args.priority, args.hogs,
            os.cpu_count(), os.getloadavg()[0], args.driver, cond['readiness_action'])
        + ('' if args.stalls is None else ', each CPU stalled %g-%g ms every 0.5-2 s'
           % tuple(args.stalls))
        + ('' if not args.ctl else ', controller ' + ' '.join(args.ctl)))
    cond['arm'] = args.arm
    cond['lockstep'] = args.lockstep
    for case in args.cases:
        bound, factor, worst = bound_of(case, args.hogs, args.arm)
        say('%s: bound %.3f mm = %g x the offline worst max %.3f mm (seeds 0-9)'
            % (case, bound, factor, worst))
    rows = []
    failed = 0
    # The hogs outlive no soak: each ends after the soak's expected length plus a margin.
    lifetime = len(args.cases) * args.runs * (args.seconds + 60.0) + 120.0
    with Hogs(args.hogs, lifetime, args.stalls):
        index = 0
        for case in args.cases:
            for run in range(args.runs):
                say('%s run %d/%d: %g s' % (case, run + 1, args.runs, args.seconds))
                try:
                    row = soak_run(case, index, run, args.seconds, args.hogs, args.back_to_back,
                                   args.stabilise, args.fully_actuated, args.fail_at,
                                   ctl_extra=args.ctl, driver=args.driver,
                                   action=args.readiness_action, arm=args.arm,
                                   lockstep=args.lockstep)
                except Exception as exc:  # noqa: B902 - one bad run must not cost the soak
                    say('%s run %d failed: %s: %s' % (case, run, type(exc).__name__, exc))
                    row = {'case': case, 'run': run, 'error': str(exc), 'met': False}
                    failed += 1
                index += 1
                rows.append(row)
                say(format_row(row) if 'error' not in row else 'run not made')
                for line in row.get('outcome_lines', ()):
                    say('  ' + line)
                if row.get('excused'):
                    say('  met by the outcomes: ' + row['excuse'])
                if 'false_alarms' in row:
                    say('  failures: %s; false alarms %d%s' % (
                        '; '.join(row['failure_lines']) or 'none detected',
                        row['false_alarms'], '' if row.get('delay_ms') is None else
                        '; detected %.1f ms after it took effect (%.1f ms after the '
                        '~/fail_joint call), max %.3f mm after it' % (
                            row['delay_ms'], row['call_delay_ms'],
                            row['max_after_mm'] or math.nan)))
    cond['load_average_end'] = list(os.getloadavg())
    per_case = {case: worst_of([r for r in rows if r['case'] == case]) for case in args.cases}
    print()
    print(format_header())
    for row in rows:
        print(format_row(row) if 'error' not in row else '%-10s %3d  not made: %s'
              % (row['case'], row['run'], row['error']))
    print()
    for case, worst in per_case.items():
        print('\n'.join(worst_lines(case, worst)))
    with open(args.out, 'w') as f:
        json.dump({'conditions': cond, 'runs': rows, 'worst': per_case}, f, indent=2)
    say('written to %s; load %.2f at the end'
        % (os.path.relpath(args.out, ROOT), os.getloadavg()[0]))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
