"""
Per-step wall times of the simulator, for measurement (no ROS types).

The simulator tells an optional :class:`StepObserver` of its step events (a state
published, a command received or applied, steps dropped, a step done, the run over) and
keeps nothing for measurement itself. With the parameters ``timing_file`` and
``timing_steps`` set, its observer is a :class:`StepTiming`, which notes for each step
k < timing_steps, in arrays allocated once at start (a few array stores per step, no
logging): the monotonic wall time at which the state of step k was published, the time at
which the command answering that state was received, and (real time) which step's command
was applied over the period that follows state k.  The arrays go to ``timing_file``
(numpy ``.npz``, written to a temporary name and renamed, so a reader never sees half a
file) once the window is complete, or at shutdown.  ``bench/graph.py`` reads them:
state-to-command latency, real-time factor, control periods without a fresh command.

"""

import os
import time

import numpy as np

WRITE_DELAY = 100
"""Steps after the window at which the file is written (late commands still counted)."""


class StepObserver:
    """
    The simulator's step events, for measurement; every method here does nothing.

    ``k`` is the simulator's step; times are ``time.monotonic()`` seconds.
    """

    def state_published(self, k, t_ns):
        """Hear that the state of step ``k`` (header stamp ``t_ns``) is being published."""

    def command_answered(self, k, now):
        """Hear that (lockstep) the command answering state ``k`` arrived at ``now``."""

    def command_received(self, label_ns, k, now):
        """
        Hear that (real time) a command labelled ``label_ns`` arrived at step ``k``.

        ``label_ns`` is None for a command without a label. Returns the step whose
        state it answers, or -1 (unknown).
        """
        return -1

    def command_applied(self, k, answered):
        """Hear that (real time) over period k -> k+1 the answer to ``answered`` applies."""

    def steps_dropped(self, n):
        """Hear that (real time) ``n`` periods were skipped (the timer fell behind)."""

    def step_done(self, k):
        """Hear that step ``k`` is done (integrated and, if due, published)."""

    def run_over(self):
        """Hear that no later event counts (lockstep max_steps reached, or shutdown)."""


class StepTiming(StepObserver):
    """
    Per-step publish and command-receipt times of steps 0 .. steps-1 (a step observer).

    Attributes
    ----------
    published : numpy.ndarray (steps,)
        Monotonic wall time [s] of the (last) publication of the state of step k.
    received : numpy.ndarray (steps,)
        Monotonic wall time [s] of the first receipt of the command answering state k
        (NaN: none arrived).
    stamp_ns : numpy.ndarray (steps,) int64
        Header stamp of the state of step k (real time: the wall clock; lockstep: t_k).
    applied : numpy.ndarray (steps,) int64
        Real time: the step whose state the command applied over period k -> k+1 answered
        (k: fresh; -1: none or timed out).  Lockstep: k (the command is always the answer).
    dropped : int
        Real time: periods skipped because the timer fell too far behind.

    As an observer (``mode`` 'lockstep' or 'realtime' and ``dt`` [s] given), the file is
    written :data:`WRITE_DELAY` steps after the window or when the run is over, whichever
    comes first, and ``log`` (a callable, optional) is told where.

    """

    def __init__(self, path, steps, mode=None, dt=None, log=None):
        self.path = path
        self.mode = mode
        self.dt = dt
        self.log = log
        self.write_at = int(steps) + WRITE_DELAY
        self.steps = int(steps)
        self.published = np.full(self.steps, np.nan)
        self.received = np.full(self.steps, np.nan)
        self.stamp_ns = np.zeros(self.steps, dtype=np.int64)
        self.applied = np.full(self.steps, -1, dtype=np.int64)
        self.dropped = 0
        self.written = False

    def step_of_stamp(self, ns, k):
        """Return the step <= k (at most 16 back) whose state had stamp ``ns``, or -1."""
        stamps = self.stamp_ns
        for j in range(min(k, self.steps - 1), max(-1, k - 16), -1):
            if stamps[j] == ns:
                return j
        return -1

    def state_published(self, k, t_ns):
        """Note the publication time and stamp of the state of step ``k``."""
        if k < self.steps:
            self.published[k] = time.monotonic()
            self.stamp_ns[k] = t_ns

    def command_answered(self, k, now):
        """Note the first answer to the state of step ``k`` (lockstep: applied at k)."""
        if k < self.steps and self.received[k] != self.received[k]:   # NaN: the first
            self.received[k] = now
            self.applied[k] = k

    def command_received(self, label_ns, k, now):
        """Note the first receipt of the answer to the state labelled ``label_ns``."""
        if label_ns is None:
            return -1
        j = self.step_of_stamp(label_ns, k)
        if j >= 0 and self.received[j] != self.received[j]:
            self.received[j] = now
        return j

    def command_applied(self, k, answered):
        """Note which step's command applied over period k -> k+1."""
        if k < self.steps:
            self.applied[k] = answered

    def steps_dropped(self, n):
        """Count skipped periods."""
        self.dropped += n

    def step_done(self, k):
        """Write the file :data:`WRITE_DELAY` steps after the window."""
        if k == self.write_at:
            self.run_over()

    def run_over(self):
        """Write the file once (late commands can no longer count); log where."""
        if not self.written:
            path = self.write(self.mode, self.dt)
            if self.log is not None:
                self.log('timing of steps 0..%d written to %s' % (self.steps - 1, path))

    def write(self, mode, dt):
        """Write the arrays to ``path`` (once); return the path."""
        tmp = self.path + '.tmp.npz'
        directory = os.path.dirname(os.path.abspath(self.path))
        os.makedirs(directory, exist_ok=True)
        np.savez(tmp, published=self.published, received=self.received,
                 stamp_ns=self.stamp_ns, applied=self.applied,
                 dropped=np.int64(self.dropped), mode=np.str_(mode), dt=np.float64(dt))
        os.replace(tmp, self.path)
        self.written = True
        return self.path
