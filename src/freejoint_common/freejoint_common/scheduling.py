"""
Real-time scheduling of a node process: SCHED_FIFO priority and CPU affinity.

What ros2_control's controller_manager does with its ``thread_priority`` and
``cpu_affinity`` parameters (``realtime_tools::configure_sched_fifo`` /
``set_current_thread_affinity``), for every thread of a Python node process: the
executor's thread and the middleware's receive and event threads alike, since a
message's path through the process crosses all of them (but the threads named in
``BEST_EFFORT_THREADS``, the middleware's asynchronous writer, which can busy-wait: they
keep the default scheduler, on the same CPUs).  Threads are found in
``/proc/self/task``; :meth:`ProcessScheduling.refresh` also covers threads started
later (the middleware starts some on discovery).

No ROS here: plain ``os`` calls, usable by any node.  Linux only (``os.sched_*``).

Requires permission: root, ``CAP_SYS_NICE`` or an ``rtprio`` limit of at least the
priority (``ulimit -r``; ``/etc/security/limits.conf``: ``@realtime - rtprio 98``).
Without it :meth:`ProcessScheduling.apply` reports why and changes nothing, and the node
runs on under the default scheduler, as the controller_manager does.
"""

import os

from freejoint_core.errors import FreejointValueError

MAX_PRIORITY = 98
"""Highest priority accepted: 99 stays with the kernel's own watchdog threads."""


BEST_EFFORT_THREADS = ('dds.asyn',)
"""Prefixes of thread names kept at the default scheduler (their CPUs are still set): Fast
DDS's asynchronous writer thread busy-waits at times (measured: 0.95 s of CPU a second while
the node started), and at the node's SCHED_FIFO priority on the node's one CPU it starved
every other thread of the process (FIFO threads of one priority do not share a CPU)."""

RT_RUNTIME_FILE = '/proc/sys/kernel/sched_rt_runtime_us'
RT_PERIOD_FILE = '/proc/sys/kernel/sched_rt_period_us'


def rt_budget():
    """
    Return the kernel's real-time budget ``(runtime_us, period_us)``; None if unreadable.

    The kernel lets SCHED_FIFO threads use a CPU for ``runtime_us`` of every
    ``period_us`` (950000 of 1000000 by default) and throttles all of them on a CPU that
    used it up, for the rest of the period: a real-time loop that needs more stalls for up
    to ``period_us - runtime_us``. ``runtime_us`` -1: no budget (no throttling).
    """
    try:
        with open(RT_RUNTIME_FILE) as f:
            runtime = int(f.read())
        with open(RT_PERIOD_FILE) as f:
            period = int(f.read())
    except (OSError, ValueError):
        return None
    return runtime, period


def rt_budget_note(budget):
    """Return the one-line note on a limited real-time ``budget`` (None: unlimited)."""
    if budget is None or budget[0] < 0 or budget[0] >= budget[1]:
        return None
    runtime, period = budget
    return ('the kernel throttles SCHED_FIFO threads after %d of every %d us on a CPU '
            '(kernel.sched_rt_runtime_us): a graph whose real-time threads need more stalls '
            'up to %.0f ms; a real-time machine runs with kernel.sched_rt_runtime_us=-1 or '
            'cores to spare (docs/GRAPH.md, real-time scheduling)'
            % (runtime, period, (period - runtime) * 1e-3))


def available_cpus():
    """Return the sorted CPUs this process may use at all (its start-up affinity)."""
    return sorted(os.sched_getaffinity(0))


def validate_priority(value):
    """
    Return ``thread_priority`` as an int in [0, MAX_PRIORITY] or raise naming it.

    0 means the default scheduler (SCHED_OTHER), 1..98 SCHED_FIFO at that priority.
    """
    if isinstance(value, bool) or not isinstance(value, int):
        raise FreejointValueError(
            f'thread_priority: expected an integer 0..{MAX_PRIORITY}, got {value!r}')
    if not 0 <= value <= MAX_PRIORITY:
        raise FreejointValueError(
            f'thread_priority: expected 0 (default scheduler) or 1..{MAX_PRIORITY} '
            f'(SCHED_FIFO), got {value}')
    return value


def validate_affinity(value, cpus=None):
    """
    Return ``cpu_affinity`` as a sorted tuple of CPU numbers, () for all; or raise.

    Parameters
    ----------
    value : sequence of int or None
        CPU numbers; None or empty means every CPU of ``cpus``.
    cpus : sequence of int, optional
        CPUs that may be named (default: those the process started with, not the ones a
        previous ``cpu_affinity`` left it).

    Raises
    ------
    FreejointValueError
        If an entry is not an integer, is repeated, or is not one of ``cpus``.

    """
    if value is None:
        return ()
    allowed = list(process_scheduling().cpus if cpus is None else sorted(cpus))
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int):
            raise FreejointValueError(f'cpu_affinity: expected CPU numbers, got {list(value)}')
        if v not in allowed:
            raise FreejointValueError(
                f'cpu_affinity: CPU {v} is not available to this process (CPUs {allowed})')
        if v in out:
            raise FreejointValueError(f'cpu_affinity: CPU {v} named twice in {list(value)}')
        out.append(v)
    return tuple(sorted(out))


def best_effort_thread(name):
    """Return whether a thread of this name stays at the default scheduler."""
    return name.startswith(BEST_EFFORT_THREADS)


def _thread_name(tid):
    try:
        with open('/proc/self/task/%d/comm' % tid) as f:
            return f.read().strip()
    except OSError:
        return ''


def _thread_ids():
    try:
        return [int(tid) for tid in os.listdir('/proc/self/task')]
    except OSError:
        return [0]


class ProcessScheduling:
    """
    The scheduling of every thread of this process: requests, apply, refresh, describe.

    Several nodes can share a process (``freejoint_bringup graph``): each makes its own
    request and the process runs at the highest priority asked for, on the union of the
    CPUs asked for (every CPU if any node asks for all).

    Parameters
    ----------
    cpus : sequence of int, optional
        CPUs the process may use (default: :func:`available_cpus` at construction); the
        affinity ``()`` stands for exactly these.

    """

    def __init__(self, cpus=None):
        self.cpus = tuple(available_cpus() if cpus is None else sorted(cpus))
        self.requests = {}
        self.priority = 0
        self.affinity = ()
        self._done = set()
        self._touched = False      # a thread's scheduling was ever changed

    def request(self, owner, priority, affinity):
        """
        Set ``owner``'s request and apply the result to every thread.

        Parameters
        ----------
        owner : str
            Who asks (a node name); a later request of the same owner replaces it.
        priority : int
            0 (SCHED_OTHER) or 1..MAX_PRIORITY (SCHED_FIFO); validated.
        affinity : sequence of int or None
            CPUs; validated; empty or None for every CPU the process started with.

        Returns
        -------
        str or None
            None on success; otherwise a sentence saying what was refused and how to
            allow it (the request is then dropped and the threads keep their previous
            scheduling).

        Raises
        ------
        FreejointValueError
            If ``priority`` or ``affinity`` is not valid (naming it).

        """
        entry = (validate_priority(priority), validate_affinity(affinity, self.cpus))
        old = self.requests.get(owner)
        self.requests[owner] = entry
        reason = self._apply()
        if reason is not None:
            if old is None:
                del self.requests[owner]
            else:
                self.requests[owner] = old
            self._apply()
        return reason

    def _apply(self):
        values = list(self.requests.values())
        priority = max((p for p, _ in values), default=0)
        if not values or any(not a for _, a in values):
            affinity = ()
        else:
            affinity = tuple(sorted(set().union(*(a for _, a in values))))
        if affinity == self.cpus:
            affinity = ()
        if (priority, affinity) != (self.priority, self.affinity):
            self.priority, self.affinity = priority, affinity
            self._done = set()
        return self.refresh()

    def refresh(self):
        """Apply the current settings to threads not yet done; return None or the reason."""
        if not self.requests and not self._touched:
            return None             # nothing asked for: leave the process as it started
        other = os.SCHED_OTHER, os.sched_param(0)
        fifo = (os.SCHED_FIFO, os.sched_param(self.priority)) if self.priority else other
        cpus = self.affinity or self.cpus
        for tid in _thread_ids():
            if tid in self._done:
                continue
            self._touched = True
            policy, param = other if best_effort_thread(_thread_name(tid)) else fifo
            try:
                os.sched_setaffinity(tid, cpus)
                os.sched_setscheduler(tid, policy, param)
            except PermissionError:
                self._done = set()
                return (f'SCHED_FIFO priority {self.priority} not permitted for this process '
                        f'(needs root, CAP_SYS_NICE or an rtprio limit >= {self.priority}: '
                        f'ulimit -r is {_rtprio_limit()})')
            except ProcessLookupError:
                continue            # the thread ended meanwhile
            except OSError as exc:
                self._done = set()
                return f'cannot set the scheduling of thread {tid}: {exc}'
            self._done.add(tid)
        return None

    def describe(self):
        """Return a short description: 'SCHED_FIFO 80 on CPUs [1]' or 'default ...'."""
        what = 'SCHED_FIFO %d' % self.priority if self.priority else 'default scheduler'
        return '%s on CPUs %s' % (what, list(self.affinity or self.cpus))


_PROCESS = []


def process_scheduling():
    """Return this process's :class:`ProcessScheduling` (made on first use)."""
    if not _PROCESS:
        _PROCESS.append(ProcessScheduling())
    return _PROCESS[0]


def _rtprio_limit():
    try:
        import resource
        soft, _hard = resource.getrlimit(resource.RLIMIT_RTPRIO)
    except (ImportError, AttributeError, OSError):
        return 'unknown'
    return 'unlimited' if soft == resource.RLIM_INFINITY else str(soft)
