"""
Per-step wall times of the simulator, for measurement (no ROS types).

With the parameters ``timing_file`` and ``timing_steps`` set, the simulator notes for each
step k < timing_steps, in arrays allocated once at start (a few array stores per step, no
logging): the monotonic wall time at which it published the state of step k, the time at
which it received the command answering that state, and (real time) which step's command
it applied over the period that follows state k.  The arrays go to ``timing_file``
(numpy ``.npz``, written to a temporary name and renamed, so a reader never sees half a
file) once the window is complete, or at shutdown.  ``bench/graph.py`` reads them:
state-to-command latency, real-time factor, control periods without a fresh command.

"""

import os

import numpy as np

WRITE_DELAY = 100
"""Steps after the window at which the file is written (late commands still counted)."""


class StepTiming:
    """
    Per-step publish and command-receipt times of steps 0 .. steps-1.

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

    """

    def __init__(self, path, steps):
        self.path = path
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
