"""
Real-time scenarios: replans, restarts, drivers (not in ``make test``): figures and JSON.

Each scenario starts the real-time graph as ``bench/soak.py`` does (a process per node, the
recorder on, sim and controller at SCHED_FIFO ``--priority``, a ROS domain per run, every
process stopped whatever happens), prints its figures with the acceptance met / NOT met and
writes ``bags/soak/scenario_<name>.json`` (bags and logs in ``bags/soak/<name>_<case>/``).
The tracking bound is 1.5 x the offline runner's worst max error of seeds 0-9 of the case.

``replan``  (a) both cases: a ``plan_circle`` call every ``--replan-period`` s (1.3) while
    circles run, ``--seconds`` (20) s: the largest change between consecutive setpoints
    (the ``setpoint`` stream by stamp, and the ``position_desired`` the controller used) vs
    the quintic circle's own largest per-tick change; the largest |effort| per joint vs the
    limits of config/controller.yaml; tracking vs the bound.
``planner_kill``  (b) vertical: kill -9 the planner mid-circle: the end effector's drift
    over 5 s from the first HOLDING tick (<= 5 mm; also from the kill), HOLDING ticks; the
    planner restarted (autostart off), the circle asked for again: tracking while it runs.
``controller_restart``  (c) both cases, ``--cycles`` (5) times: kill -9 the controller
    mid-circle, restart it ``--down`` (1.0) s later: the largest |effort| after the restart
    vs the limit, divergence, time from the restart until the tracking error stays within
    the bound (<= 2 s). ``--supervised``: under ``controller_supervisor``, the active child
    killed and its hot spare taking over (times from the kill); ``--children-transport
    inherit`` for the supervisor's children on the environment's transports (shared
    memory), ``--recorder-priority P`` for the recorder under ``chrt -f P``.
``driver500``  (d) both cases: the simulator publishing joint_states at 500 Hz
    (``publish_rate: 500``; ``--control-period`` for the controller, default: as
    configured), circles for ``--seconds``: tracking vs the bound, stale periods.
``start_order``  (e) vertical: each of the 6 start orders of sim, controller and planner
    (recorder first, ``--gap`` (1.5) s between nodes, no ``~/reset``, no plan): the end
    effector's largest deviation from ``initial_position`` before the plan (<= 2 mm); then
    one circle: tracking vs the bound.

``joint_failure``  (f) both cases: the fully actuated arm (config/fully_actuated/),
    one circle, joint 3 made to fail ``--mid`` (2.5) s after its acceptance through the
    simulator's ``~/fail_joint`` (``soak.py --fully-actuated --fail-at``'s run): the
    detection and its delay from the failure taking effect, false alarms, tracking after it
    vs the bound.

Usage: ``. tools/env.sh && python bench/scenarios.py replan [planner_kill ...] | all
[--cases ...] [--seconds S] [--priority 50]``.
"""

import argparse
import itertools
import json
import os
import signal
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import graph as bench_graph  # noqa: E402 - bench/graph.py, the process harness
from freejoint_common.contract import EE_POSITION, NS_PER_S  # noqa: E402, I100
import soak  # noqa: E402 - bench/soak.py, the session and the bag analysis

RESUMING_BIT = 256
"""freejoint_msgs/ControllerState STATUS_RESUMING: the reference blends onto the stream."""
SCENARIOS = ('replan', 'planner_kill', 'controller_restart', 'driver500', 'start_order',
             'joint_failure')
NS = NS_PER_S


def say(text):
    """Print a progress line at once."""
    print('[scenario] ' + text, flush=True)


def verdict(ok):
    """Return 'met' / 'NOT met' (None: 'n/a')."""
    return 'n/a' if ok is None else ('met' if ok else 'NOT met')


def quintic_step_mm():
    """Return the configured circle's largest change between consecutive ticks [mm]."""
    import numpy as np
    from freejoint_core.trajectory import CircleQuintic
    plan = bench_graph.ros_params('planner.yaml')
    dt = float(plan['control_period'])
    circle = CircleQuintic(centre=plan['centre'], radius=plan['radius'],
                           duration=plan['duration'], start_angle=plan['start_angle'],
                           direction=plan['direction'])
    n = int(round(float(plan['duration']) / dt))
    p = np.array([circle.sample(k * dt)[0] for k in range(n + 1)])
    return 1000.0 * float(np.max(np.hypot(*np.diff(p, axis=0).T)))


def setpoint_steps_mm(bag_path, lo_ns, hi_ns, dt_ns):
    """
    Return the largest change between setpoints of consecutive ticks [mm] in the window.

    The ``setpoints`` stream by stamp (the newest setpoint of each stamp counts, as the
    controller takes the newest), consecutive = stamps one control period apart.
    """
    import numpy as np
    from freejoint_tools.bagfile import open_bag
    by_stamp = {}
    for log_ns, msg in soak.bag_setpoints(open_bag(bag_path)):
        if lo_ns <= log_ns <= hi_ns:
            by_stamp[msg.stamp_ns] = (msg.position[0], msg.position[1])
    stamps = np.array(sorted(by_stamp), dtype=np.int64)
    if len(stamps) < 2:
        return None, 0
    p = np.array([by_stamp[s] for s in stamps])
    step = np.hypot(*np.diff(p, axis=0).T)
    consecutive = np.diff(stamps) == dt_ns
    return (1000.0 * float(step[consecutive].max()) if consecutive.any() else None,
            int(len(stamps)))


def desired_steps_mm(ticks, mask, dt_ns=1_000_000):
    """
    Return the largest change of ``position_desired`` per control period [mm].

    Consecutive answered ticks ``n`` periods apart (a state skipped as too old, a stale
    period) may differ by ``n`` periods of motion: the change is divided by ``n``.
    """
    import numpy as np
    pd = ticks['pd'][mask]
    if len(pd) < 2:
        return None
    order = np.argsort(ticks['stamp_ns'][mask], kind='stable')
    periods = np.maximum(1, np.round(np.diff(ticks['stamp_ns'][mask][order]) / dt_ns))
    return 1000.0 * float(np.max(np.hypot(*np.diff(pd[order], axis=0).T) / periods))


def active_joints():
    """Return the simulator's commanded joints (config/sim.yaml ``joints``)."""
    return [str(j) for j in bench_graph.ros_params('sim.yaml')['joints']]


def effort_verdict(effort_max, limits):
    """Return whether every joint's largest |effort| is within its limit (None: no limit)."""
    if effort_max is None or not limits:
        return None
    return all(e <= lim * (1.0 + 1e-9) for e, lim in zip(effort_max, limits))


def log_window(ticks, lo_s, hi_s):
    """Return the mask of the ticks the recorder took between system times lo_s and hi_s."""
    return (ticks['log_ns'] >= int(lo_s * NS)) & (ticks['log_ns'] <= int(hi_s * NS))


# -- (a) replan -------------------------------------------------------------------------
def replan(args, index):
    """Ask for a circle every 1.3 s while circles run: no setpoint step."""
    results = []
    quintic = quintic_step_mm()
    limits = soak.effort_limits()
    dt_ns = int(round(float(bench_graph.ros_params('planner.yaml')['control_period']) * NS))
    for case in args.cases:
        bound, _factor, _worst = soak.bound_of(case, 0)
        with soak.Session('replan_' + case, index, case, args.seconds) as s:
            index += 1
            s.up()
            loop = bench_graph.CircleLoop(s.client, period=args.replan_period, strict=False)
            t0 = time.time()
            s.wait(args.seconds, loop)
            t1 = time.time()
        ticks = soak.controller_ticks(s.bag)
        lo = loop.accepted_wall[0] if loop.accepted_wall else t0
        mask = log_window(ticks, lo, t1)
        summary = soak.summarise(ticks, mask)
        sp_step, n_sp = setpoint_steps_mm(s.bag, int(lo * NS), int(t1 * NS), dt_ns)
        pd_step = desired_steps_mm(ticks, mask)
        row = {'case': case, 'seconds': args.seconds, 'requests': len(loop.accepted)
               + len(loop.refused), 'accepted': len(loop.accepted),
               'refused': len(loop.refused),
               'refusal_reasons': sorted({r for _, r in loop.refused}),
               'quintic_step_mm': quintic, 'setpoint_step_mm': sp_step,
               'setpoints': n_sp, 'desired_step_mm': pd_step, 'effort_limits': limits,
               'bound_mm': bound, 'diverged_log_lines': s.diverged_lines(),
               'exit_codes': s.codes, 'bag': os.path.relpath(s.bag, ROOT)}
        row.update(summary)
        row['no_step'] = (sp_step is not None and sp_step <= quintic * (1.0 + 1e-6)
                          and pd_step is not None and pd_step <= quintic * (1.0 + 1e-6))
        row['efforts_within'] = effort_verdict(row['effort_max'], limits)
        row['tracking_within'] = row['max_mm'] is not None and row['max_mm'] <= bound
        say('replan %s: %d requests (%d accepted, %d refused%s); largest step: setpoints '
            '%s mm, position_desired %s mm, quintic %.4f mm -> %s; |effort| max %s vs '
            'limits %s -> %s; tracking max %s mm rms %s mm vs %.3f -> %s; holds %d'
            % (case, row['requests'], row['accepted'], row['refused'],
               (': ' + '; '.join(row['refusal_reasons'])) if row['refused'] else '',
               _f(sp_step), _f(pd_step), quintic, verdict(row['no_step']),
               _fl(row['effort_max']), limits, verdict(row['efforts_within']),
               _f(row['max_mm']), _f(row['rms_mm']), bound, verdict(row['tracking_within']),
               row['holds']))
        results.append(row)
    return results, index


# -- (b) planner kill -------------------------------------------------------------------
def planner_kill(args, index):
    """Vertical: kill -9 the planner mid-circle; the arm holds; restart, plan, follow."""
    import numpy as np
    case = 'vertical'
    bound, _factor, _worst = soak.bound_of(case, 0)
    with soak.Session('planner_kill_' + case, index, case, 30.0) as s:
        index += 1
        s.up()
        loop = bench_graph.CircleLoop(s.client)
        loop.poll()
        s.wait(args.mid)
        t_kill = s.kill('planner_node')
        s.wait(args.hold_seconds + 1.0)
        t_restart = s.restart('planner_node', {'autostart:=true': 'autostart:=false'})
        again = bench_graph.CircleLoop(s.client, strict=False)
        deadline = time.monotonic() + 60.0
        while not again.accepted and time.monotonic() < deadline:
            again.next = 0.0
            again.poll()
            s.wait(0.5)
        t_plan = again.accepted_wall[0] if again.accepted_wall else None
        if t_plan is not None:
            s.wait(float(again.plan['duration']) + 0.5)
        t_end = time.time()
    ticks = soak.controller_ticks(s.bag)
    hold = ticks['status'] & soak.holding_bit() != 0
    after = log_window(ticks, t_kill, t_restart)
    first_hold = np.nonzero(after & hold)[0]
    row = {'case': case, 'kill_after_s': args.mid, 'holding_ticks': int(np.count_nonzero(
        after & hold)), 'ticks_after_kill': int(np.count_nonzero(after)),
        'exit_codes': s.codes, 'bag': os.path.relpath(s.bag, ROOT)}
    p = ticks['p']
    at_kill = np.nonzero(after)[0]
    if len(at_kill):
        w = log_window(ticks, t_kill, t_kill + args.hold_seconds)
        row['drift_from_kill_mm'] = 1000.0 * float(np.max(np.hypot(*(p[w] - p[at_kill[0]]).T)))
    if len(first_hold):
        i = first_hold[0]
        th = ticks['log_ns'][i] * 1e-9
        w = log_window(ticks, th, th + args.hold_seconds)
        row['hold_started_after_kill_s'] = th - t_kill
        row['drift_from_hold_mm'] = 1000.0 * float(np.max(np.hypot(*(p[w] - p[i]).T)))
        w = log_window(ticks, th, t_restart)
        row['drift_until_restart_mm'] = 1000.0 * float(np.max(np.hypot(*(p[w] - p[i]).T)))
        row['held_until_restart_s'] = t_restart - th
        row['holding_at_restart'] = bool(hold[np.nonzero(after)[0][-1]])
    row['drift_within'] = (row.get('drift_from_hold_mm') is not None
                           and row['drift_from_hold_mm'] <= 5.0)
    row['status_says_holding'] = bool(row['holding_ticks'])
    row['replan_accepted'] = t_plan is not None
    row['plan_accepted_after_restart_s'] = None if t_plan is None else t_plan - t_restart
    row['replan_refusals'] = sorted({r for _, r in again.refused})
    if t_plan is not None:
        follow = log_window(ticks, t_plan, t_end)
        row['after_replan'] = soak.summarise(ticks, follow)
        # The new circle starts at its start point, away from the held arm: the controller
        # blends the arm onto it (STATUS_RESUMING, offset decaying by design); the arm
        # follows the plan once the blend is over.
        blending = ticks['status'] & (soak.holding_bit() | RESUMING_BIT) != 0
        row['after_blend'] = soak.summarise(ticks, follow & ~blending)
        row['follows'] = (row['after_blend']['max_mm'] is not None
                          and row['after_blend']['max_mm'] <= bound)
    else:
        row['follows'] = False
    row['bound_mm'] = bound
    row['diverged_log_lines'] = s.diverged_lines()
    say('planner_kill vertical: killed %.1f s into the circle; HOLDING ticks %d of %d '
        '(first %s s after the kill) -> %s; drift over %g s from the first HOLDING tick %s mm '
        '(from the kill %s mm; until the restart %s s later %s mm) <= 5 -> %s; restarted '
        'planner: plan %s %s s after the restart%s; tracking after it max %s mm (with the '
        'blend onto the new circle), after the blend %s mm vs %.3f -> %s'
        % (args.mid, row['holding_ticks'], row['ticks_after_kill'],
           _f(row.get('hold_started_after_kill_s')), verdict(row['status_says_holding']),
           args.hold_seconds, _f(row.get('drift_from_hold_mm')),
           _f(row.get('drift_from_kill_mm')), _f(row.get('held_until_restart_s')),
           _f(row.get('drift_until_restart_mm')), verdict(row['drift_within']),
           'accepted' if t_plan else 'NOT accepted',
           _f(row['plan_accepted_after_restart_s']),
           (' (%s)' % '; '.join(row['replan_refusals'])) if row['replan_refusals'] else '',
           _f(row.get('after_replan', {}).get('max_mm')),
           _f(row.get('after_blend', {}).get('max_mm')), bound, verdict(row['follows'])))
    return [row], index


# -- (c) controller restart -------------------------------------------------------------
def log_times(path, text):
    """Return the system times [s] of a node log's lines containing ``text`` (rcutils stamps)."""
    times = []
    try:
        with open(path, errors='replace') as f:
            for line in f:
                if text in line:
                    head = line.split('] [', 2)
                    try:
                        times.append(float(head[1].split(']')[0]))
                    except (IndexError, ValueError):
                        pass
    except OSError:
        pass
    return times


def restart_timeline(log, released, t_restart, t_end):
    """
    Return when a restarted controller got where, in s after its start (``t_restart``).

    ``node_s``: its first log line (the node built, its participant created: process start,
    interpreter, imports, ``rclpy.init`` and the node's parameters before it); ``ready_s``:
    'controller ready' (publishers, subscriptions, timers made); ``first_command_s``: the
    simulator's 'brakes released' (its first command accepted: the participants discovered
    each other, a state reached the controller and its command the simulator).
    """
    def first(times):
        after = [t - t_restart for t in times if t_restart <= t <= t_end]
        return min(after) if after else None
    lines = log_times(log, '[controller_node]')
    row = {'node_s': first(lines), 'ready_s': first(log_times(log, 'controller ready')),
           'first_command_s': first(released)}
    for key, text in (('imports_s', 'imports done'), ('rclpy_init_s', 'rclpy initialised'),
                      ('matched_joint_states_s', 'matched subscription joint_states'),
                      ('matched_setpoint_s', 'matched subscription setpoint'),
                      ('matched_commands_s', 'matched publisher effort_controller/commands'),
                      ('first_joint_states_s', 'first message on joint_states'),
                      ('first_setpoint_s', 'first message on setpoint')):
        value = first(log_times(log, '[PROBE]') and log_times(log, text))
        if value is not None:
            row[key] = value
    return row


def blend_of(plant, t_first):
    """
    Return the resume blend of a restarted controller: the offset at its first command.

    ``blend_offset_mm``: |end effector - setpoint| at the first command; ``blend_s``: the
    blend's duration for that offset, ``max(resume_time, 1.875 d / resume_max_velocity,
    sqrt(5.7735 d / resume_max_acceleration))`` with config/controller.yaml's values (the
    controller's ReferenceShaper rule).
    """
    import math
    import numpy as np
    i = int(np.searchsorted(plant['log_ns'], int(t_first * NS)))
    if i >= len(plant['log_ns']) or not np.isfinite(plant['err_mm'][i]):
        return {}
    d = float(plant['err_mm'][i]) / 1000.0
    ctl = bench_graph.ros_params('controller.yaml')
    blend = float(ctl.get('resume_time', 0.0))
    if ctl.get('resume_max_velocity'):
        blend = max(blend, 1.875 * d / float(ctl['resume_max_velocity']))
    if ctl.get('resume_max_acceleration'):
        blend = max(blend, math.sqrt(5.7735 * d / float(ctl['resume_max_acceleration'])))
    return {'blend_offset_mm': 1000.0 * d, 'blend_s': blend}


def first_after(times, t0, t_end):
    """Return the first of ``times`` in [t0, t_end], in s after t0 (None: none)."""
    after = [t - t0 for t in times if t0 <= t <= t_end]
    return min(after) if after else None


def rewrite_start(s, rewrite):
    """Start the session's processes with ``rewrite(name, cmd)`` as their command line."""
    start = s.graph.start

    def start_rewritten(name, cmd, *rest, **kwargs):
        return start(name, rewrite(name, list(cmd)), *rest, **kwargs)
    s.graph.start = start_rewritten


def supervise(s, pid_file, args):
    """
    Run the session's controller under ``controller_supervisor`` (``--supervised``).

    The graph's ``controller_node`` process becomes the supervisor with the controller's
    own arguments: an active controller and a hot spare (parameter ``standby``), the spare
    activated by the supervisor when the active one dies. The supervisor runs under ``chrt
    -f`` (``--restart-priority``, else ``--priority``) so that it reacts at once; its
    children start at the default scheduler and take their ``thread_priority`` themselves.
    """
    node = bench_graph.executable('freejoint_control', 'controller_node')
    sup = bench_graph.executable('freejoint_control', 'controller_supervisor')
    priority = args.restart_priority or args.priority

    def supervised(name, cmd):
        if name != 'controller_node' or not cmd or cmd[0] != node:
            return cmd
        return (['chrt', '-f', str(priority)] if priority else []) + [
            sup, '--pid-file', pid_file, '--transport', args.children_transport,
            '--'] + cmd[1:]
    rewrite_start(s, supervised)


def recorder_at(s, priority):
    """
    Start the session's recorder under ``chrt -f priority`` (``--recorder-priority``).

    The recorder is the measuring instrument: at the default scheduler on 2 CPUs whose
    real-time threads are not throttled it falls behind and loses the tail of the bag
    (cycles without plant figures). Below the planner (``--priority`` - 10).
    """
    rewrite_start(s, lambda name, cmd: ['chrt', '-f', str(priority)] + cmd
                  if name == 'recorder' else cmd)


def supervised_pids(s, pid_file, timeout=60.0):
    """Wait until the supervisor's spare is ready; return (active pid, spare pid)."""
    from freejoint_control.supervisor import read_pid_file
    end = time.monotonic() + timeout
    while True:
        pids = read_pid_file(pid_file)
        if pids.get('ready'):
            return pids['active'], pids['spare']
        if time.monotonic() > end:
            raise RuntimeError('no ready spare within %g s (%s)' % (timeout, pid_file))
        s.wait(0.05)


def restart_command(args):
    """
    Return ``(replace, prefix)`` of the restarted controller's command line.

    ``--restart-priority P``: started under ``chrt -f P``: a supervisor can start a real-time
    process in its scheduling class (systemd's ``CPUSchedulingPolicy=fifo`` /
    ``CPUSchedulingPriority=``, ``chrt``), so that its start-up (interpreter, imports,
    participant) is not queued behind best-effort load; the node sets its
    ``thread_priority`` itself once built either way. ``--probe``: bench/controller_probe.py
    instead of the executable (the start-up timeline in the node's log).
    """
    prefix = ['chrt', '-f', str(args.restart_priority)] if args.restart_priority else []
    if not args.probe:
        return None, prefix
    exe = bench_graph.executable('freejoint_control', 'controller_node')
    return {exe: os.path.join(HERE, 'controller_probe.py')}, prefix + [sys.executable]


def fastdds_profile():
    """Return the Fast DDS XML profile file the nodes load (None: Fast DDS defaults)."""
    from freejoint_control.supervisor import profiles_file
    return profiles_file(os.environ)


def controller_restart(args, index):
    """Both cases: kill -9 and restart the controller mid-circle, ``--cycles`` times."""
    import numpy as np
    results = []
    limits = soak.effort_limits()
    for case in args.cases:
        bound, _factor, _worst = soak.bound_of(case, 0)
        cycles = []
        seconds = args.cycles * (args.down + args.recover + 6.0) + 10.0
        with soak.Session('controller_restart_' + case, index, case, seconds) as s:
            index += 1
            pid_file = os.path.join(s.dir, 'supervisor.json')
            if args.supervised:
                supervise(s, pid_file, args)
            if args.recorder_priority:
                recorder_at(s, args.recorder_priority)
            s.up()
            loop = bench_graph.CircleLoop(s.client, before=lambda: soak.rest_at_q0(s.client))
            for _ in range(args.cycles):
                # A circle from rest at q(0) each cycle (no new circle meanwhile), killed
                # args.mid s after it was accepted; supervised, a circle starts once the
                # spare is ready (the kill is then mid-circle, not after the circle).
                if args.supervised:
                    supervised_pids(s, pid_file)
                loop.next = 0.0
                loop.poll()
                while time.monotonic() < loop.accepted[-1] + args.mid:
                    s.wait(0.02)
                if args.supervised:
                    # kill -9 of the active child; the supervisor activates the spare and
                    # starts the next one (ready before the next cycle's kill).
                    active, _spare = supervised_pids(s, pid_file)
                    load = os.getloadavg()[0]
                    t_kill = time.time()
                    os.kill(active, signal.SIGKILL)
                    log = s.graph.procs['controller_node'].log_path
                    s.wait(args.recover)
                    cycles.append((t_kill, t_kill, time.time(), log, load))
                    continue
                t_kill = s.kill('controller_node')
                s.wait(args.down)
                load = os.getloadavg()[0]
                t_restart = s.restart('controller_node', *restart_command(args))
                log = s.graph.procs['controller_node'].log_path
                s.wait(args.recover)
                cycles.append((t_kill, t_restart, time.time(), log, load))
        ticks = soak.controller_ticks(s.bag)
        plant = soak.plant_ticks(s.bag, active_joints())
        released = log_times(s.graph.procs['sim_node'].log_path, 'brakes released')
        diverged_at = log_times(s.graph.procs['sim_node'].log_path, 'iverge')
        rows = []
        for t_kill, t_restart, t_end, log, load in cycles:
            w = log_window(plant, t_restart, t_end)
            idx = np.nonzero(w)[0]
            row = {'kill': t_kill, 'restart': t_restart, 'plant_ticks': int(len(idx)),
                   'load_average_1min': load, 'controller_log': os.path.relpath(log, ROOT)}
            row.update(restart_timeline(log, released, t_restart, t_end))
            row['diverged'] = any(t_restart <= t <= t_end for t in diverged_at)
            answers = np.nonzero(log_window(ticks, t_restart, t_end))[0]
            row['first_controller_state_s'] = (float(ticks['log_ns'][answers[0]] * 1e-9
                                                     - t_restart) if len(answers) else None)
            if args.supervised:
                # Times from the kill: the supervisor saw the death, the spare activated;
                # its first command is its first controller_state in the bag (a takeover
                # within the simulator's 0.05-s brake watchdog has no 'brakes released').
                row['node_s'] = row['ready_s'] = None   # built long before the kill
                row['detected_s'] = first_after(log_times(log, 'died (signal'), t_kill, t_end)
                row['takeover_s'] = first_after(log_times(log, 'activated (standby)'),
                                                t_kill, t_end)
                row['first_command_s'] = row['first_controller_state_s']
            down = log_window(plant, t_kill, t_restart)
            row['max_mm_while_down'] = (float(np.nanmax(plant['err_mm'][down]))
                                        if down.any() else None)
            if len(idx):
                err = plant['err_mm'][idx]
                t = plant['log_ns'][idx] * 1e-9
                out = np.nonzero(~(err <= bound))[0]
                if row.get('first_command_s') is None:
                    # Never commanded in the window: a braked arm the stream passes near
                    # is not 'back'.
                    row['back_within_s'] = None
                elif not len(out):
                    row['back_within_s'] = 0.0
                elif out[-1] + 1 < len(t):
                    row['back_within_s'] = float(t[out[-1] + 1] - t_restart)
                else:
                    row['back_within_s'] = None     # not back by the end of the window
                row['effort_max'] = [float(v) for v in np.nanmax(np.abs(
                    plant['effort'][idx]), axis=0)]
                row['max_mm_after'] = float(np.nanmax(err))
                row.update(blend_of(plant, t_restart + row['first_command_s'])
                           if row.get('first_command_s') is not None else {})
            if row.get('back_within_s') is not None and row.get('first_command_s') is not None:
                row['back_after_first_command_s'] = row['back_within_s'] - row['first_command_s']
            rows.append(row)
        diverged = s.diverged_lines()
        backs = [r.get('back_within_s') for r in rows]
        efforts = [r.get('effort_max') for r in rows if r.get('effort_max')]
        worst_effort = ([max(e[j] for e in efforts) for j in range(len(efforts[0]))]
                        if efforts else None)
        res = {'case': case, 'cycles': rows, 'down_s': args.down, 'bound_mm': bound,
               'effort_limits': limits, 'effort_max': worst_effort,
               'diverged_log_lines': diverged,
               'diverged_diagnostics': soak.diagnostics_diverged(s.bag),
               'worst_back_within_s': (None if any(b is None for b in backs) or not backs
                                       else max(backs)),
               'exit_codes': s.codes, 'bag': os.path.relpath(s.bag, ROOT)}
        res['efforts_within'] = effort_verdict(worst_effort, limits)
        res['no_divergence'] = not (diverged or res['diverged_diagnostics'])
        res['back_within_2s'] = (res['worst_back_within_s'] is not None
                                 and res['worst_back_within_s'] <= 2.0)
        res['fastdds_profile'] = fastdds_profile()
        if args.supervised:
            res['children_transport'] = args.children_transport
        say('controller_restart %s: Fast DDS profile %s%s; per cycle, s after the restart '
            '(load = 1-min load average at the restart):' % (
                case, res['fastdds_profile'], ', supervised, children transport %s'
                % args.children_transport if args.supervised else ''))
        say('  cycle  load  node  ready  1st cmd  blend (offset mm)  back  back-1st cmd  '
            'max |effort| N m  diverged')
        for k, r in enumerate(rows):
            say('  %5d %5.2f %5s %6s %8s %6s (%7s) %6s %13s  %16s  %s' % (
                k + 1, r['load_average_1min'], _f(r.get('node_s')), _f(r.get('ready_s')),
                _f(r.get('first_command_s')), _f(r.get('blend_s')),
                _f(r.get('blend_offset_mm')), _f(r.get('back_within_s')),
                _f(r.get('back_after_first_command_s')), _fl(r.get('effort_max')),
                r.get('diverged', 'n/a')))
            if args.supervised:
                say('        supervised: death seen %s s, spare activated %s s after the kill '
                    '(times above from the kill)' % (_f(r.get('detected_s')),
                                                     _f(r.get('takeover_s'))))
            if args.probe:
                say('        probe: imports %s, rclpy.init %s, matched joint_states %s, '
                    'commands %s, setpoint %s; first joint_states %s, setpoint %s' % tuple(
                        _f(r.get(k)) for k in (
                            'imports_s', 'rclpy_init_s', 'matched_joint_states_s',
                            'matched_commands_s', 'matched_setpoint_s',
                            'first_joint_states_s', 'first_setpoint_s')))
        say('controller_restart %s: %d kill -9 / restarts (%g s down): first answer after '
            '%s s; end effector back within %.3f mm of the setpoint after %s s (worst; <= 2 s '
            '-> %s); largest |effort| applied after a restart %s vs limits %s -> %s; '
            'diverged: %d log lines, %d diagnostics -> %s'
            % (case, len(rows), args.down,
               ', '.join(_f(r.get('first_controller_state_s')) for r in rows), bound,
               ', '.join(_f(b) for b in backs), verdict(res['back_within_2s']),
               _fl(worst_effort), limits, verdict(res['efforts_within']), diverged,
               res['diverged_diagnostics'], verdict(res['no_divergence'])))
        results.append(res)
    return results, index


# -- (d) a 500 Hz driver ----------------------------------------------------------------
def driver500(args, index):
    """Both cases: joint_states at 500 Hz; tracking within the bound."""
    results = []
    ctl = ['control_period:=%g' % args.control_period] if args.control_period else []
    for case in args.cases:
        bound, _factor, _worst = soak.bound_of(case, 0)
        with soak.Session('driver500_' + case, index, case, args.seconds,
                          sim=['publish_rate:=500.0'], ctl=ctl) as s:
            index += 1
            s.up()
            loop = bench_graph.CircleLoop(s.client, before=lambda: soak.rest_at_q0(s.client))
            start = time.monotonic()
            s.wait(args.seconds, loop)
            end = time.monotonic()
        row = {'case': case, 'publish_rate': 500.0, 'controller_overrides': ctl,
               'bound_mm': bound, 'plans': len(loop.accepted), 'exit_codes': s.codes,
               'bag': os.path.relpath(s.bag, ROOT)}
        timing = soak.stale_periods(s.timing_path, (start, end))
        lo, hi = timing.pop('stamp_window_ns')
        row.update(timing)
        ticks = soak.controller_ticks(s.bag)
        row.update(soak.summarise(ticks, (ticks['stamp_ns'] >= lo) & (ticks['stamp_ns'] <= hi)))
        row['diverged_log_lines'] = s.diverged_lines()
        row['tracking_within'] = row['max_mm'] is not None and row['max_mm'] <= bound
        say('driver500 %s: joint_states at 500 Hz%s, %d circles: tracking max %s mm rms %s '
            'mm vs %.3f -> %s; stale periods %d (longest %d); holds %d; diverged %d'
            % (case, ' (controller %s)' % ', '.join(ctl) if ctl else '', row['plans'],
               _f(row['max_mm']), _f(row['rms_mm']), bound, verdict(row['tracking_within']),
               row['stale'], row['longest_stale'], row['holds'], row['diverged_log_lines']))
        results.append(row)
    return results, index


# -- (e) start order --------------------------------------------------------------------
def start_order(args, index):
    """Vertical: every start order of the three nodes; deviation before the plan."""
    import numpy as np
    from freejoint_tools.bagfile import open_bag
    case = 'vertical'
    bound, _factor, _worst = soak.bound_of(case, 0)
    initial = [float(v) for v in bench_graph.ros_params('sim.yaml')['initial_position']]
    sched = bench_graph.scheduling_overrides()
    nodes = {
        'sim': ('sim_node', 'freejoint_sim', 'sim_node', 'sim.yaml',
                ['case:=' + case, 'seed:=%d' % bench_graph.SEED, 'mode:=realtime'] + sched),
        'controller': ('controller_node', 'freejoint_control', 'controller_node',
                       'controller.yaml', ['case:=' + case, 'lockstep:=false'] + sched),
        'planner': ('planner_node', 'freejoint_planner', 'planner_node', 'planner.yaml',
                    ['case:=' + case, 'use_sim_time:=false', 'autostart:=false'])}
    results = []
    for order in itertools.permutations(('sim', 'controller', 'planner')):
        name = 'start_order_' + '_'.join(order)
        with soak.Session(name, index, case, 30.0, timing=False) as s:
            index += 1
            s.graph.start('recorder', [
                bench_graph.executable('freejoint_tools', 'recorder'), '--ros-args',
                '-p', 'output:=' + s.bag, '-p', 'topics:=[]', '-p', 'overwrite:=true',
                '-p', 'use_sim_time:=false',
                '-p', 'custom_data:=[case=%s, start_order=%s]' % (case, '-'.join(order))])
            if not s.client.spin_until(lambda: s.graph.exited() or bool(
                    s.client.recorder_status(1.0)), 60.0) or s.graph.exited():
                raise RuntimeError('the recorder does not answer ~/status after 60 s (logs '
                                   'in %s)' % s.graph.log_dir)
            t_first = time.time()
            for node in order:
                proc, pkg, exe, config, overrides = nodes[node]
                s.graph.start(proc, bench_graph.node_cmd(pkg, exe, config, overrides))
                s.wait(args.gap)
            if not s.client.controller_answers(60.0):
                raise RuntimeError('the controller does not answer after 60 s')
            s.wait(args.settle)
            loop = bench_graph.CircleLoop(s.client, strict=False)
            t_plan = time.time()
            loop.poll()
            s.wait(float(loop.plan['duration']) + 0.5)
            t_end = time.time()
        bag = open_bag(s.bag)
        ee = [(lt, m.point.x, m.point.y) for lt, m in bag.decode(EE_POSITION.absolute)
              if lt <= int(t_plan * NS)]
        row = {'case': case, 'order': list(order), 'gap_s': args.gap,
               'ee_samples_before_plan': len(ee), 'exit_codes': s.codes,
               'bag': os.path.relpath(s.bag, ROOT)}
        if ee:
            xy = np.array([(x, y) for _, x, y in ee])
            dev = 1000.0 * np.hypot(*(xy - initial).T)
            row['deviation_max_mm'] = float(dev.max())
            row['first_ee_after_first_node_s'] = ee[0][0] * 1e-9 - t_first
        row['deviation_within'] = (row.get('deviation_max_mm') is not None
                                   and row['deviation_max_mm'] <= 2.0)
        ticks = soak.controller_ticks(s.bag)
        before = log_window(ticks, 0.0, t_plan)
        row['holds_before_plan'] = int(np.count_nonzero(
            ticks['status'][before] & soak.holding_bit()))
        row['plan_accepted'] = bool(loop.accepted)
        if loop.accepted:
            row['after_plan'] = soak.summarise(ticks, log_window(ticks, loop.accepted_wall[0],
                                                                 t_end))
            row['follows'] = (row['after_plan']['max_mm'] is not None
                              and row['after_plan']['max_mm'] <= bound)
        row['diverged_log_lines'] = s.diverged_lines()
        say('start_order %-28s deviation before the plan %s mm (<= 2 -> %s) over %d samples; '
            'HOLDING ticks %d; circle after: max %s mm vs %.3f -> %s'
            % (' '.join(order), _f(row.get('deviation_max_mm')),
               verdict(row['deviation_within']), len(ee), row['holds_before_plan'],
               _f(row.get('after_plan', {}).get('max_mm')), bound,
               verdict(row.get('follows'))))
        results.append(row)
    return results, index


def _f(value):
    return 'n/a' if value is None else '%.3f' % value


def _fl(values):
    return 'n/a' if values is None else '[%s]' % ', '.join('%.1f' % v for v in values)


# -- (f) a joint fails ---------------------------------------------------------------------
def joint_failure(args, index):
    """Both cases: the fully actuated arm's joint 3 fails ``--mid`` s into a circle."""
    results = []
    for case in args.cases:
        row = soak.soak_run(case, index, 0, max(args.seconds, args.mid + 5.5), 0,
                            fully_actuated=True, fail_at=args.mid)
        index += 1
        say('joint_failure %s: %s; false alarms %d; detected %s ms after it took effect; '
            'max %s mm after it (bound %.3f) -> %s' % (
                case, row.get('detected') or 'NOT DETECTED', row['false_alarms'],
                _f(row.get('delay_ms')), _f(row.get('max_after_mm')), row['bound_mm'],
                verdict(row['met'])))
        results.append(row)
    return results, index


RUNNERS = {'replan': replan, 'planner_kill': planner_kill,
           'controller_restart': controller_restart, 'driver500': driver500,
           'start_order': start_order, 'joint_failure': joint_failure}


def parse(argv):
    """Return the command-line options."""
    ap = argparse.ArgumentParser(prog='scenarios', description=__doc__.strip().splitlines()[0])
    ap.add_argument('scenarios', nargs='+', choices=SCENARIOS + ('all',))
    ap.add_argument('--cases', nargs='+', choices=soak.CASES, default=list(soak.CASES))
    ap.add_argument('--seconds', type=float, default=20.0,
                    help='replan / driver500: seconds of circles (default 20)')
    ap.add_argument('--replan-period', type=float, default=1.3)
    ap.add_argument('--mid', type=float, default=2.5,
                    help='kill (joint_failure: make joint 3 fail) this many s after a '
                    'circle was accepted (default 2.5)')
    ap.add_argument('--hold-seconds', type=float, default=5.0)
    ap.add_argument('--cycles', type=int, default=5, help='controller_restart cycles')
    ap.add_argument('--down', type=float, default=1.0,
                    help='controller_restart: seconds without a controller (default 1)')
    ap.add_argument('--recover', type=float, default=4.0,
                    help='controller_restart: seconds measured after a restart (default 4)')
    ap.add_argument('--restart-priority', type=int, default=0,
                    help='controller_restart: start the restarted controller under chrt -f '
                    'this priority (0: the default scheduler until the node sets its own)')
    ap.add_argument('--supervised', action='store_true',
                    help='controller_restart: the controller runs under controller_supervisor '
                    '(an active controller and a hot spare); the active child is killed, the '
                    'spare takes over, the supervisor starts the next spare')
    ap.add_argument('--children-transport', choices=('udp', 'inherit'), default='udp',
                    help="controller_restart --supervised: the supervisor's --transport (udp: "
                    'its children without shared memory, the default; inherit: as the '
                    'environment, for comparison)')
    ap.add_argument('--recorder-priority', type=int, default=0,
                    help='controller_restart: the recorder under chrt -f this priority '
                    '(0: the default scheduler)')
    ap.add_argument('--probe', action='store_true',
                    help='controller_restart: restart the controller through '
                    'bench/controller_probe.py (its start-up timeline in its log)')
    ap.add_argument('--control-period', type=float, default=None,
                    help='driver500: the controller control_period (default: configured)')
    ap.add_argument('--gap', type=float, default=1.5, help='start_order: s between nodes')
    ap.add_argument('--settle', type=float, default=3.0,
                    help='start_order: s after the controller answers, before the plan')
    ap.add_argument('--priority', type=int, default=50)
    return ap.parse_args(argv)


def main(argv=None):
    """Run the scenarios asked for; return 1 if one could not be made."""
    args = parse(sys.argv[1:] if argv is None else argv)
    soak.stop_on_sigterm()
    bench_graph.PRIORITY = args.priority
    names = SCENARIOS if 'all' in args.scenarios else args.scenarios
    os.makedirs(soak.OUT, exist_ok=True)
    failed = 0
    index = 40      # domains apart from a soak started by the same process id
    for name in names:
        cond = soak.conditions(args.priority, 0)
        cond['fastdds_profile'] = fastdds_profile()
        say('%s: priority %d, %d CPUs, load %.2f, sched_rt_runtime_us %s' % (
            name, args.priority, os.cpu_count(), os.getloadavg()[0], cond['sched_rt_runtime_us']))
        try:
            rows, index = RUNNERS[name](args, index)
            error = None
        except Exception as exc:  # noqa: B902 - one scenario must not cost the others
            say('%s could not be made: %s: %s' % (name, type(exc).__name__, exc))
            rows, error = [], str(exc)
            failed += 1
            index += 8
        cond['load_average_end'] = list(os.getloadavg())
        out = os.path.join(soak.OUT, 'scenario_%s.json' % name)
        with open(out, 'w') as f:
            json.dump({'scenario': name, 'conditions': cond, 'options': vars(args),
                       'results': rows, 'error': error}, f, indent=2, default=str)
        say('%s: written to %s' % (name, os.path.relpath(out, ROOT)))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
