"""
Replay a real-time run's timing through the control loop and the plant, in one process.

A real-time run's simulator timing file (``timing_file``: ``make soak`` and ``make bench``
keep one per run, ``bags/soak/<case>_<n>/timing.npz``) says, for each state k, when it
was published, when the command answering it arrived and which state's command the driver
applied over period k. Around a moment of that run (a trip, a lost arm) this tool takes
that pattern (``Pattern``: the states the loop took, how late, which answer was applied at
each period) and puts it, at several points of the paper's vertical circle and for seeds
0-9, into ``freejoint_control.loop.ControlLoop`` (the real-time configuration of
``config/controller.yaml``, ``readiness_action: hold``) on the Table I plant (70 %
nominal model in the law, disturbance on), a driver keeping its last command (the
hold-last driver), every other period answered at once. While the loop is not ready the
plan pauses along its path as the planner's feed hold pauses it (``CircleRun``). A run is
**lost** when the end effector ends more than 0.1 m from the path (or the plan never
finishes).

    python bench/replay_timing.py bags/soak/vertical_1/timing.npz 1796421442.817
    python bench/replay_timing.py FILE STAMP --set effort_rate_limit=1e9 --at 0.5 2.5

``STAMP`` [s, system time]: the moment (a state's stamp; the controller's log line of a
trip gives it); the pattern runs from ``--before`` s before it to ``--after`` s after.
``--set name=value`` overrides a controller parameter (repeatable). ``--save FILE`` writes
the pattern as JSON, which replays in place of a timing file (no ``STAMP``):
``bench/patterns/hold_last_vertical_loss.json`` is the pattern of a SCHED_FIFO hold-last
soak run that lost the vertical arm (docs/real-time.md). ``--event EVENT SIZE`` runs a
made event instead (``run_event``: a push, a reset, a stall or a starved loop; ``--case``
the arm). Prints one line per run, the count of runs lost and how far the others strayed
from the path. Exit code 0 whatever the figures (a benchmark).

    python bench/replay_timing.py bench/patterns/hold_last_vertical_loss.json
    python bench/replay_timing.py --event stall 60 --set readiness_stop_acceleration=0
    python bench/replay_timing.py --event starve 100 --case horizontal
"""

import argparse
import json
import math
import os
import sys
from typing import NamedTuple

from freejoint_control.loop import ControlLoop
from freejoint_control.params import SCHEMA
from freejoint_core.arm import table1
from freejoint_core.feed_hold import FeedRate, ramp_time, scale_sample
from freejoint_core.plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant, PlantDivergedError
from freejoint_core.trajectory import CircleQuintic
from freejoint_planner.params import SCHEMA as PLANNER_SCHEMA
from freejoint_planner.plan_goal import circle_peak_speed, ticks_back_to
from freejoint_sim.params import SCHEMA as SIM
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONTROLLER = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'))
SIMULATOR = SIM.yaml_values(os.path.join(ROOT, 'config', 'sim.yaml'))
PLANNER = PLANNER_SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'planner.yaml'))
DT, DT_NS, T0_NS = 0.001, 1_000_000, 10 ** 12
NAMES = ['joint1', 'joint2', 'joint3']
LEAD = 1.5              # [s] the start point held first: the loop judged ready meanwhile
RADIUS = 0.2            # [m] the paper's circle, centred at the base
LOST = 0.1              # [m] farther from the path than this: the arm is lost
ANSWER_S = 0.0003       # [s] the answer's delay outside the pattern


class Pattern(NamedTuple):
    """
    The timing of a run's periods 0 .. n-1 from a chosen state on.

    Attributes
    ----------
    taken : dict of int -> float
        Period r whose state the loop took -> how late it took it [s] (its publication's
        lateness on the grid plus the answer's delay, less 0.2 ms for the answer itself).
    applied : list of int, (n,)
        The period whose state's answer the driver applied over period r (< 0: an answer
        from before the pattern: the last one kept).

    """

    taken: dict
    applied: list


def pattern(timing, stamp_s, before=0.1, after=0.6):
    """
    Return the :class:`Pattern` of a timing file around ``stamp_s``.

    Parameters
    ----------
    timing : mapping
        ``published`` [s], ``received`` [s] (NaN: no answer), ``stamp_ns`` and ``applied``
        arrays of a simulator timing file (``freejoint_sim.timing``), one entry per state.
    stamp_s : float
        System time [s] of the moment; the state stamped nearest it is the centre.
    before, after : float
        Seconds of states before and after it.

    """
    stamps = np.asarray(timing['stamp_ns'], dtype=float)
    pub = np.asarray(timing['published'], dtype=float)
    rec = np.asarray(timing['received'], dtype=float)
    app = np.asarray(timing['applied'])
    i = int(np.argmin(np.abs(stamps - stamp_s * 1e9)))
    lo, hi = max(0, i - int(before / DT)), min(len(stamps), i + int(after / DT))
    if not (np.isfinite(pub[lo]) and hi > lo):
        raise ValueError('stamp %.3f s: no published state there' % stamp_s)
    taken, applied = {}, []
    for j in range(lo, hi):
        late = pub[j] - pub[lo] - (stamps[j] - stamps[lo]) * 1e-9
        if np.isfinite(rec[j]) and np.isfinite(pub[j]):
            taken[j - lo] = max(rec[j] - pub[j] - 0.0002, 0.0) + max(late, 0.0)
        applied.append(int(app[j]) - lo)
    return Pattern(taken, applied)


class CircleRun:
    """
    The paper's circle in one process: ``ControlLoop`` on the Table I plant.

    The loop has ``config/controller.yaml``'s real-time configuration with
    ``readiness_action: hold`` (and ``overrides``); the plant is Table I's arm of ``case``
    (``'vertical'`` or ``'horizontal'``; the loop's law on its 70 % nominal model),
    disturbance on, from the simulator's q(0).
    The circle's start point is held for :data:`LEAD` s (the loop judged ready meanwhile),
    then the circle runs, paused as the planner pauses it (``config/planner.yaml``'s feed
    hold, reacting at once): from the tick the loop is not ready its feed ramps to a stop
    along the path (``feed_hold_time``); ready again, a plan that stands goes back along
    its path to the point nearest the arm (the planner's ``ticks_back_to``) and its feed
    ramps up (``feed_resume_time``). The caller answers the states and drives the plant:

        run = CircleRun(seed)
        for k, ns, mono in run.ticks():      # each tick's setpoint given to the loop
            ...                              # run.loop.on_state(...) as the test needs
            if not run.step(effort, k >= start):
                break                        # the plant diverged

    Attributes
    ----------
    loop : ControlLoop
    plant : Plant
    q0 : numpy.ndarray, (3,)
        The plant's initial angles [rad].
    worst : float
        The end effector's largest distance [m] from the path (from the circle's start
        point outside the circle's time) over the measured periods; inf: diverged.
    fastest : float
        The fastest joint [rad/s] over the measured periods.
    done : bool
        The plan finished (one second past its end).

    """

    def __init__(self, seed, overrides=None, case='vertical'):
        values = dict(CONTROLLER, case=case, lockstep=False, readiness_action='hold',
                      **(overrides or {}))
        self.loop = ControlLoop(SCHEMA.config(values), lambda level, kind, text: None)
        self.q0 = SIM.config(dict(SIMULATOR, case=case)).q0
        self.plant = Plant(table1(case), DEFAULT_DT_SUB, dist_bound=DEFAULT_DIST_BOUND,
                           seed=seed, q0=self.q0)
        self._traj = CircleQuintic()
        p0 = self._traj.sample(0.0)[0]
        self._rest = (float(p0[0]), float(p0[1]), 0.0, 0.0, 0.0, 0.0)
        self._t = -LEAD
        self._feed = FeedRate(DT)
        peak = circle_peak_speed(RADIUS, self._traj.duration)
        self._stop_time = ramp_time(PLANNER['feed_hold_time'], peak, PLANNER['max_acceleration'])
        self._start_time = ramp_time(PLANNER['feed_resume_time'], peak,
                                     PLANNER['max_acceleration'])
        self.worst = 0.0
        self.fastest = 0.0
        self.done = False

    @staticmethod
    def tick_at(at):
        """Return the tick ``at`` s into the circle (its start point held before it)."""
        return int(round((LEAD + at) / DT))

    def ticks(self):
        """Yield ``(k, ns, mono)`` per tick after giving the loop its setpoint; stop when done."""
        loop, traj, rest, feed = self.loop, self._traj, self._rest, self._feed
        end = traj.duration
        k0 = int(round(LEAD / DT)) - 1         # the circle's plan time 0
        for k in range(int((LEAD + end + 9.0) / DT)):
            ns, mono = T0_NS + k * DT_NS, 100.0 + k * DT
            if k >= k0:
                ready = loop.readiness()[0]
                if not ready and feed.target != 0.0:
                    feed.ramp(k, 0.0, self._stop_time)
                elif ready and feed.target == 0.0:
                    if k >= feed.ramp_end():
                        self._rewind(k, k0)
                    feed.ramp(k, 1.0, self._start_time)
            lag, rate, rate_dot = feed.at(k) if k >= k0 else (0, 1.0, 0.0)
            self._t = (k - k0 - lag) * DT
            if self._t > end + 1.0:
                self.done = True
                return
            sp = (scale_sample(traj.sample_tuple(self._t), rate, rate_dot)
                  if 0.0 <= self._t < end else rest)
            loop.on_setpoint(ns, sp, ns, mono)
            yield k, ns, mono

    def _rewind(self, k, k0):
        """Move the standing plan back along its path to the point nearest the arm."""
        traj = self._traj
        tau = (k - k0 - self._feed.at(k)[0]) * DT
        if not 0.0 < tau < traj.duration:
            return
        back = ticks_back_to(traj, tau, self.loop.law.model.fk(self.plant.q)[0:2], DT)
        if back:
            self._feed.rewind(k, back)

    def step(self, effort, measure):
        """
        Integrate one period with ``effort`` [N m] on the active joints; measure if asked.

        Returns False when the plant diverged (``worst`` is then inf).
        """
        plant = self.plant
        try:
            plant.step(np.asarray(effort, dtype=float), DT)
        except PlantDivergedError:
            self.worst = math.inf
            return False
        if measure:
            p = self.loop.law.model.fk(plant.q)
            off = (abs(math.hypot(p[0], p[1]) - RADIUS) if 0.0 <= self._t < self._traj.duration
                   else math.hypot(p[0] - self._rest[0], p[1] - self._rest[1]))
            self.worst = max(self.worst, off)
            self.fastest = max(self.fastest, float(np.max(np.abs(plant.qd))))
        return True

    def figures(self, **flags):
        """Return ``worst``, ``fastest`` and ``done`` in a dict with ``flags``."""
        return dict(flags, worst=self.worst, fastest=self.fastest, done=self.done)


def run(pat, at, seed, overrides=None):
    """
    Run the vertical circle with ``pat`` from ``at`` s into it; return what the arm did.

    Returns a dict: ``worst`` [m], the end effector's largest distance from the path from
    the pattern on (inf: the plant diverged); ``fastest`` [rad/s]; ``damped``, whether the
    damped joint hold answered; ``tripped``, whether the loop was not ready from the pattern
    on; ``done``, whether the plan finished.
    """
    circle = CircleRun(seed, overrides)
    loop, plant = circle.loop, circle.plant
    start = circle.tick_at(at)
    tau, answers = [0.0, 0.0], {}
    damped = tripped = False
    for k, ns, mono in circle.ticks():
        r = k - start
        q, qd = plant.q.tolist(), plant.qd.tolist()
        inside = 0 <= r < len(pat.applied)
        late = pat.taken.get(r) if inside else ANSWER_S
        if late is not None:
            res = loop.on_state(ns, NAMES, q, qd, ns + int(late * 1e9), mono + late)
            damped |= 'damped joint hold' in res.message
            if inside:
                answers[r] = list(res.effort)
            else:
                tau = list(res.effort)
        if inside and pat.applied[r] in answers:
            tau = answers[pat.applied[r]]
        if not circle.step(tau, k >= start):
            break
        if k >= start:
            tripped |= not loop.readiness()[0]
    return circle.figures(damped=damped, tripped=tripped)


EVENTS = ('push', 'reset', 'starve', 'stall')


def run_event(event, at, size, seed=0, overrides=None, case='vertical'):
    """
    Run one circle with ``event`` at ``at`` s into it; return what the arm did after it.

    ``event``: 'push' (``size`` N m on the active joints, +/-, for 30 ms), 'reset' (the
    plant back at q(0) at rest, the loop silent ``size`` ticks from then, the states
    answered once it is back: the soak's ``~/reset`` meeting a stall), 'stall' (the loop
    silent ``size`` ticks, then the states that queued answered at once) or 'starve' (11
    states lost, then for ``size`` ticks one state in 10 answered: a loop the machine
    starves, a gap trip first); the driver keeps its last command throughout. Returns a
    dict: ``worst`` [m], the end effector's largest distance from the circle (from its
    start point outside the circle's time) from the event on (inf: diverged);
    ``fastest`` [rad/s], the fastest joint then; ``tripped``, whether a following error
    tripped the guard; ``damped``, whether the damped joint hold answered; ``done``,
    whether the plan finished.
    """
    if event not in EVENTS:
        raise ValueError('event: expected one of %s, got %r' % (EVENTS, event))
    circle = CircleRun(seed, overrides, case)
    loop, plant = circle.loop, circle.plant
    start = circle.tick_at(at)
    tau, queued = [0.0, 0.0], []
    tripped = damped = False
    for k, ns, mono in circle.ticks():
        if event == 'reset' and k == start:
            plant.reset(q0=circle.q0, qd0=np.zeros(3))
        state = (ns, plant.q.tolist(), plant.qd.tolist(), mono)
        if event == 'starve' and start <= k < start + 11 + size and (
                k < start + 11 or (k - start) % 10):
            pass                                    # lost: the driver keeps the command
        elif event in ('reset', 'stall') and start <= k < start + size:
            queued.append(state)
        else:
            for st in queued + [state]:
                res = loop.on_state(st[0], NAMES, st[1], st[2], ns, st[3])
                if res is None:                     # too old to answer: refused
                    continue
                tau = list(res.effort)
                damped |= 'damped joint hold' in res.message
                tripped |= 'tracking error' in loop.readiness()[1]
            queued = []
        applied = np.array(tau)
        if event == 'push' and start <= k < start + 30:
            applied = applied + np.array([size, -size])
        if not circle.step(applied, k >= start):
            break
    return circle.figures(tripped=tripped, damped=damped)


def _value(text):
    try:
        return json.loads(text)
    except ValueError:
        return text


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[1])
    parser.add_argument('timing', nargs='?',
                        help='a simulator timing file (timing.npz) or a pattern (.json, --save)')
    parser.add_argument('stamp', type=float, nargs='?',
                        help='the moment [s, system time] (a timing file)')
    parser.add_argument('--event', nargs=2, metavar=('EVENT', 'SIZE'),
                        help='instead of a timing: %s and its size (N m for a push, else '
                        'ticks; run_event)' % ', '.join(EVENTS))
    parser.add_argument('--case', choices=('vertical', 'horizontal'), default='vertical',
                        help='the arm (an --event; a timing replays on the vertical arm)')
    parser.add_argument('--save', metavar='FILE', help='write the pattern as JSON')
    parser.add_argument('--before', type=float, default=0.1)
    parser.add_argument('--after', type=float, default=0.6)
    parser.add_argument('--at', type=float, nargs='+', default=[0.5, 1.5, 2.5, 3.5],
                        help='points of the circle [s] the pattern starts at')
    parser.add_argument('--seeds', type=int, default=10)
    parser.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                        help='a controller parameter (repeatable)')
    args = parser.parse_args(argv)
    overrides = {}
    for item in args.set:
        name, sep, text = item.partition('=')
        if not sep or name not in SCHEMA:
            parser.error('--set %s: expected NAME=VALUE with a controller parameter' % item)
        overrides[name] = _value(text)
    if args.event:
        event, size = args.event
        if event not in EVENTS:
            parser.error('--event: expected one of %s, got %r' % (', '.join(EVENTS), event))
        size = float(size) if event == 'push' else int(size)

        def one(at, seed):
            return run_event(event, at, size, seed, overrides, args.case)
    else:
        if args.timing is None:
            parser.error('a timing file, a pattern or --event is needed')
        if args.timing.endswith('.json'):
            with open(args.timing) as f:
                saved = json.load(f)
            pat = Pattern({int(r): float(v) for r, v in saved['taken'].items()},
                          [int(v) for v in saved['applied']])
        else:
            if args.stamp is None:
                parser.error('a timing file needs STAMP')
            with np.load(args.timing) as timing:
                pat = pattern(timing, args.stamp, args.before, args.after)
        if args.save:
            with open(args.save, 'w') as f:
                json.dump({'taken': {r: round(v, 6) for r, v in pat.taken.items()},   # 1 us
                           'applied': pat.applied}, f)
                f.write('\n')

        def one(at, seed):
            return run(pat, at, seed, overrides)
    lost, kept = 0, []
    for at in args.at:
        for seed in range(args.seeds):
            out = one(at, seed)
            bad = not out['worst'] <= LOST or not out['done']
            lost += bad
            if not bad:
                kept.append(out['worst'])
            print('at %.2f s seed %d: worst %.1f mm, fastest joint %.1f rad/s, damped hold %s%s'
                  % (at, seed, out['worst'] * 1e3, out['fastest'],
                     'yes' if out['damped'] else 'no', ', LOST' if bad else ''), flush=True)
    print('%s: %d of %d runs lost the arm%s' % (
        overrides or 'as configured', lost, len(args.at) * args.seeds,
        '; the others %.1f mm from the path at the median, %.1f at worst'
        % (float(np.median(kept)) * 1e3, max(kept) * 1e3) if kept else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
