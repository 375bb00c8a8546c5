"""
How late the machine wakes a real-time thread: a cyclictest-like probe beside a run.

One process per CPU, pinned to it, at SCHED_FIFO ``--priority`` (99 by default: above
every thread of the graph, so nothing of the project can delay it; the default scheduler
when the process may not), sleeps ``--period`` (1 ms) in a loop and notes how much later
than the period each wake-up came. A late wake-up here is the machine's: a hypervisor
that took the virtual CPU (steal time), a kernel section that does not preempt
(``PREEMPT_NONE``), an interrupt storm. A node's thread on that CPU stalls at least as
long, whatever its priority. ``bench/soak.py`` runs it beside each run (columns ``wake``
and ``>10``), so that a miss can be told from the machine's stall.

Cost: about 2 % of a CPU per probe process (1000 Python wake-ups per second).

Usage (until SIGINT / SIGTERM, or ``--seconds``)::

    . tools/env.sh && python bench/wakeup_probe.py --seconds 60 --out probe.json

prints (and writes) per CPU: wake-ups, the latest one [ms late], the count and times
(Unix time) of those later than ``--threshold`` (10 ms).
"""

import argparse
import json
import os
import shutil
import signal
import sys
import tempfile
import time

PERIOD = 1e-3
"""Sleep of each cycle [s] (cyclictest's default interval, 1000 us)."""
THRESHOLD = 10e-3
"""A wake-up later than this [s] is listed with its time (a stall a 1-kHz loop feels)."""
KEPT = 200
"""At most this many late wake-ups are listed per CPU (the count covers all)."""


class LateWakeups:
    """
    How late each wake-up came: after the previous one plus ``period``, in order.

    ``note(before, now, unix)`` per wake-up (monotonic times [s] of the previous and this
    one, Unix time [s] of this one); :meth:`summary` the figures.

    Parameters
    ----------
    period, threshold : float
        The sleep of a cycle [s] and the lateness [s] above which a wake-up is listed
        with its Unix time, > 0.
    kept : int
        Most late wake-ups listed (the latest first; the count covers all), >= 0.

    Raises
    ------
    ValueError
        If ``period`` or ``threshold`` is not > 0, or ``kept`` < 0.

    """

    def __init__(self, period=PERIOD, threshold=THRESHOLD, kept=KEPT):
        if not period > 0.0:
            raise ValueError('period: expected a time > 0 s, got %r' % (period,))
        if not threshold > 0.0:
            raise ValueError('threshold: expected a time > 0 s, got %r' % (threshold,))
        if kept < 0:
            raise ValueError('kept: expected a count >= 0, got %r' % (kept,))
        self.period, self.kept = period, kept
        self.limit = period + threshold     # a gap beyond it is a listed late wake-up
        self.count = 0
        self.worst_gap = 0.0
        self.late = []

    def note(self, before, now, unix):
        """Take the wake-up at monotonic ``now`` [s] after the one at ``before``."""
        gap = now - before
        self.count += 1
        if gap > self.worst_gap:
            self.worst_gap = gap
        if gap > self.limit:
            self.late.append((gap - self.period, unix))

    def summary(self):
        """
        Return the figures (dict).

        ``wakeups`` (int), ``worst_ms`` (the latest wake-up [ms late], 0.0 without any),
        ``late`` (the count over the threshold) and ``listed``: ``[unix_s, ms_late]``
        of the latest ones, the latest first.
        """
        listed = sorted(self.late, reverse=True)[:self.kept]
        return {'wakeups': self.count,
                'worst_ms': max(self.worst_gap - self.period, 0.0) * 1e3,
                'late': len(self.late),
                'listed': [[unix, late * 1e3] for late, unix in listed]}


def _probe(cpu, priority, seconds, out):
    """Run one probe on ``cpu`` until SIGINT / SIGTERM or ``seconds``; write its summary."""
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(True))
    os.sched_setaffinity(0, {cpu})
    applied = 0
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            applied = priority
        except PermissionError:
            applied = 0
    mono, wall, sleep = time.monotonic, time.time, time.sleep
    end = mono() + seconds if seconds else float('inf')
    wakes = LateWakeups()
    note = wakes.note
    before = mono()
    while not stop and before < end:
        sleep(PERIOD)
        now = mono()
        note(before, now, wall())
        before = now
    summary = wakes.summary()
    summary.update(cpu=cpu, priority=applied)
    with open(out, 'w') as fh:
        json.dump(summary, fh)


class Probes:
    """
    A probe process per CPU (``python wakeup_probe.py --cpu K ...``) for a run.

    ``with Probes() as p: ...; result = p.stop()``: each is stopped (the harness's
    SIGINT, bounded wait, SIGKILL) on leaving whatever happened; :meth:`stop` returns the
    merged summary, or None when a probe wrote nothing (``failure`` then says which and
    the last line it printed).
    """

    def __init__(self, priority=99, cpus=None, seconds=0.0):
        # Imported here: the probe processes themselves need none of it.
        from freejoint_tools.harness import Processes
        self.dir = tempfile.mkdtemp(prefix='wakeup_probe_')
        self.procs = Processes(self.dir, stop_timeout=5.0)
        self.outs = {}
        self.failure = ''
        for cpu in sorted(os.sched_getaffinity(0) if cpus is None else cpus):
            name = 'cpu%d' % cpu
            self.outs[name] = os.path.join(self.dir, name + '.json')
            self.procs.start_script(os.path.abspath(__file__), name, [
                '--cpu', str(cpu), '--priority', str(priority), '--seconds', str(seconds),
                '--out', self.outs[name]])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    def stop(self):
        """Stop every probe; return the merged summary (None if one is missing)."""
        if not self.outs:
            return None
        codes = self.procs.stop_all()
        results = []
        for name, out in self.outs.items():
            try:
                with open(out) as fh:
                    results.append(json.load(fh))
            except (OSError, ValueError):
                results.append(None)
                self.failure = '%s: exit %s, %s' % (
                    os.path.basename(out), codes.get(name),
                    self.procs.tail(name, 1).strip() or 'no output')
        self.outs = {}
        shutil.rmtree(self.dir, ignore_errors=True)
        return None if None in results else merge(results)


def merge(results):
    """Return the summary of several CPUs' (worst, counts summed, listed by lateness)."""
    listed = sorted(((ms, unix, r['cpu']) for r in results for unix, ms in r['listed']),
                    reverse=True)
    return {'cpus': [r['cpu'] for r in results],
            'priority': min(r['priority'] for r in results),
            'wakeups': sum(r['wakeups'] for r in results),
            'worst_ms': max(r['worst_ms'] for r in results),
            'late': sum(r['late'] for r in results),
            'listed': [[unix, ms, cpu] for ms, unix, cpu in listed[:KEPT]]}


def main(argv=None):
    """Run one probe (``--cpu``) or one per CPU; print the summary as JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=0.0, help='0: until SIGINT / SIGTERM')
    ap.add_argument('--priority', type=int, default=99)
    ap.add_argument('--cpu', type=int, default=None, help='(one probe, on this CPU)')
    ap.add_argument('--out', default=None)
    args = ap.parse_args(argv)
    if not 0 <= args.priority <= 99 or args.seconds < 0:
        ap.error('0 <= --priority <= 99, --seconds >= 0')
    if args.cpu is not None:
        _probe(args.cpu, args.priority, args.seconds, args.out or os.devnull)
        return 0
    signal.signal(signal.SIGTERM, signal.default_int_handler)     # as SIGINT: stop, print
    probes = Probes(args.priority, seconds=args.seconds)
    try:
        for proc in probes.procs.started:
            proc.wait()
    except KeyboardInterrupt:
        pass
    result = probes.stop()
    text = json.dumps(result)
    print(text)
    if args.out:
        with open(args.out, 'w') as fh:
            fh.write(text + '\n')
    return 0 if result is not None else 1


if __name__ == '__main__':
    sys.exit(main())
