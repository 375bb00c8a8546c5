"""
The one runner of the freejoint node processes: start-up, spinning, end of run.

Every node process (``sim_node``, ``controller_node``, ``freejoint_planner``, the viewer,
the recorder, the player) and bringup's one-process composition of sim, controller and
planner run through :func:`run`. Its lifecycle, for one node or several in one executor
(as ros2/examples' ``composed.py`` adds nodes to one executor):

1. configure: ``rclpy.init`` (no rclpy signal handlers), then ``make()`` builds the
   node(s): each declares and validates its parameters in its constructor. A bad
   start-up parameter (the node's ``FreejointValueError`` or rclpy's range and type
   checks, ``ParameterException``) is one fatal line ``bad parameter: <name>: <reason>``
   and exit status 2, no traceback. An exception of ``errors`` (a bag that cannot be
   created or read) is one line ``<name>: error: <reason>`` on stderr and exit 1.
2. spin: one executor (the first node's ``executor_kind``: ``'events'`` or
   ``'single_threaded'``) runs every node until SIGINT/SIGTERM: the signal only sets a
   flag, so the running callback finishes and the process stops between callbacks
   (rclpy's own handler invalidates the context under a running callback, whose next
   publish then fails). The default loop (:func:`spin_until`) freezes what start-up made
   for the garbage collector, times its pauses, and applies the process scheduling to
   threads started meanwhile once per :data:`REFRESH_PERIOD`; a node with a loop of its
   own (the recorder's batched takes, the player's single pass) passes ``loop``.
3. shut down, for each node in order: :meth:`Lifecycle.on_shutdown` (stop threads,
   write files, finalise the bag), then its :meth:`Lifecycle.report` line is logged; then
   the collector's pauses; the executor is shut down (the events executor then clears
   the middleware callbacks it set on the nodes' entities: ``remove_node`` only queues
   that for a spin that no longer comes), then the nodes are destroyed. A node's
   :meth:`Lifecycle.failure` (something recorded was lost) is one line
   ``<name>: error: <reason>`` and exit 1.

``EventsExecutor.spin()`` of the rclpy 7.1.6 wheels never runs a timer and busy-waits;
the default loop hands the executor :data:`SPIN_PERIOD` at a time through
``spin_until_future_complete`` on a future the stop flag completes (timers run, an idle
executor sleeps, a signal stops it after the callback it interrupted), not one
``spin_once`` per event: each ``spin_once`` costs a crossing into the executor and a
``rclpy.ok()``, about 25-30 us of CPU per event on this machine's 1-kHz nodes.
"""

import gc
import inspect
import os
import signal
import sys
import threading
import time

from freejoint_common.node_tools import GC_PAUSES, parameter_error
from freejoint_common.scheduling import process_scheduling
from freejoint_core.errors import FreejointValueError

REFRESH_PERIOD = 1.0
"""Wall period [s] of applying the process scheduling to threads started meanwhile."""
EXECUTOR_SHUTDOWN_WAIT = 5.0
"""Wall time [s] shutting the executor down waits for callbacks still running."""
SPIN_PERIOD = 0.2
"""Wall time [s] the default loop leaves the executor at most before it checks ``ok()``
and the refresh (a signal stops it sooner once a callback runs)."""


class Lifecycle:
    """
    What the runner calls on a node (mixed into every freejoint node class).

    ``configure`` is the node's constructor. The defaults do nothing: a node overrides
    what it has.
    """

    executor_kind = 'events'
    """The executor the runner spins the node with: 'events' or 'single_threaded'."""

    def on_shutdown(self):
        """Stop what runs besides the executor and write what the run leaves (files)."""

    def report(self):
        """Return the end-of-run line (logged at shutdown), or None for none."""
        return None

    def failure(self):
        """Return why the run failed after all (exit 1), or None."""
        return None


class StopFlag:
    """
    SIGINT/SIGTERM handler that notes the signal (:attr:`signum`) and returns.

    The handler only notes the signal and writes one byte to a pipe: a thread waiting on
    the pipe completes the future :meth:`wake_on_signal` gave it. Completing it in the
    handler could wait forever: the signal may interrupt this very thread inside the
    future's own methods, which hold its lock (rclpy's ``Future`` takes a non-reentrant
    lock in ``add_done_callback``, ``remove_done_callback`` and ``set_result``, and the
    executor calls the first two on every spin of the loop).
    """

    def __init__(self):
        self.signum = None
        self._previous = {}
        self._wake = None
        self._wake_lock = threading.Lock()
        self._pipe = None

    def __call__(self, signum, frame):
        self.signum = signum
        if self._pipe is not None:
            try:
                os.write(self._pipe[1], b'\0')
            except BlockingIOError:
                pass                # bytes not yet read: the waker is woken anyway

    def wake_on_signal(self, future):
        """
        Complete ``future`` (an ``rclpy.task.Future``) at the next signal (the loop's).

        None: complete nothing from now on; it returns once a completion under way (and
        the executor's done callback it runs) is over, so the executor is not touched
        from the waker after the loop has left it.
        """
        with self._wake_lock:
            self._wake = future
        if future is not None and self._pipe is None:
            self._pipe = os.pipe()
            os.set_blocking(self._pipe[1], False)
            threading.Thread(target=self._waker, args=(self._pipe[0],), daemon=True,
                             name='stop-flag-wake').start()

    def _waker(self, fd):
        while os.read(fd, 64):      # b'': the write end closed (restore)
            self._complete()
        os.close(fd)

    def _complete(self):
        with self._wake_lock:
            wake = self._wake
            if wake is not None and not wake.done():
                wake.set_result(self.signum)

    def __bool__(self):
        return self.signum is not None

    def install(self):
        """Handle SIGINT and SIGTERM with this flag."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self)
        return self

    def restore(self):
        """Give SIGINT and SIGTERM back to the handlers they had before :meth:`install`."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous = {}
        if self._pipe is not None:
            os.close(self._pipe[1])             # ends the waker
            self._pipe = None


def make_executor(kind='events'):
    """Return rclpy's EventsExecutor (``kind`` 'events') or SingleThreadedExecutor."""
    if kind == 'events':
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


def spin_until(executor, ok, stop):
    """
    Spin ``executor`` until ``stop`` or not ``ok()``; keep new threads' scheduling.

    ``stop``: a :class:`StopFlag` (its signal ends the executor's current
    :data:`SPIN_PERIOD`).
    """
    from rclpy.task import Future
    GC_PAUSES.start()
    refresh = process_scheduling().refresh
    monotonic = time.monotonic
    next_refresh = monotonic() + REFRESH_PERIOD
    try:
        while not stop and ok():
            woken = Future()
            stop.wake_on_signal(woken)
            if not stop:
                executor.spin_until_future_complete(woken, timeout_sec=SPIN_PERIOD)
            if monotonic() >= next_refresh:
                next_refresh = monotonic() + REFRESH_PERIOD
                refresh()
    finally:
        stop.wake_on_signal(None)


def spin_nodes(nodes, executor, stop):
    """Spin the executor until the stop flag or rclpy's shutdown (the default loop)."""
    import rclpy
    spin_until(executor, rclpy.ok, stop)


def run(make, name, args=None, *, loop=spin_nodes, errors=(), handle_signals=True,
        executor_kind=None):
    """
    Run node(s) through the lifecycle above; return the exit status (0, 1 or 2).

    Parameters
    ----------
    make : callable
        Builds the node, a list of nodes, or a generator of nodes (after ``rclpy.init``;
        a generator's nodes made before a failure are shut down too); each node is a
        :class:`Lifecycle`.
    name : str
        Name of the process in its start-up and failure lines.
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (None: ``sys.argv``).
    loop : callable, optional
        ``loop(nodes, executor, stop)`` runs the process until ``stop`` (default:
        :func:`spin_nodes`).
    errors : tuple of exception types, optional
        Failures of ``make`` or ``loop`` reported as ``<name>: error: <reason>``, exit 1.
    handle_signals : bool, optional
        False: rclpy's own signal handlers (SIGINT raises in a loop that blocks outside
        the executor, as the player's).
    executor_kind : str, optional
        'events' or 'single_threaded' (default: the first node's ``executor_kind``).

    """
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions
    rclpy.init(args=args, signal_handler_options=(
        SignalHandlerOptions.NO if handle_signals else SignalHandlerOptions.ALL))
    stop = StopFlag()
    if handle_signals:
        stop.install()
    nodes = []
    code = 0
    executor = None
    try:
        made = make()
        if inspect.isgenerator(made):
            for node in made:
                nodes.append(node)
        else:
            nodes = list(made) if isinstance(made, (list, tuple)) else [made]
        executor = make_executor(executor_kind or nodes[0].executor_kind)
        for node in nodes:
            executor.add_node(node)
        loop(nodes, executor, stop)
    except (FreejointValueError, ParameterException) as exc:
        rclpy.logging.get_logger(name).fatal('bad parameter: %s' % parameter_error(exc))
        code = 2
    except errors as exc:
        print('%s: error: %s' % (name, exc), file=sys.stderr)
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        failures = shut_down(nodes, executor)
        # A node whose constructor raised (a bad parameter) is reachable only through its
        # own reference cycles: collect it now, so that its middleware participant is
        # destroyed with this run, not by a later collection beside another participant of
        # the process (Fast DDS 2.14 can deadlock destroying a participant while another
        # one in the process delivers discovery data to it: a test process's in-process
        # main, run_main of test/conftest.py, hung so).
        gc.collect()
        rclpy.try_shutdown()
        stop.restore()
    for text in failures:
        print('%s: error: %s' % (name, text), file=sys.stderr)
    return code or (1 if failures else 0)


def shut_down(nodes, executor=None):
    """Shut ``nodes`` down in order (on_shutdown, report); destroy them; return failures."""
    failures = []
    for node in nodes:
        node.on_shutdown()
        line = node.report()
        if line:
            node.get_logger().info(line)
        reason = node.failure()
        if reason:
            failures.append(reason)
    if nodes and GC_PAUSES in gc.callbacks:
        nodes[0].get_logger().info(GC_PAUSES.report())
    if executor is not None and not executor.shutdown(timeout_sec=EXECUTOR_SHUTDOWN_WAIT):
        nodes[0].get_logger().warning(
            'the executor did not finish its callbacks within %.0f s of the stop'
            % EXECUTOR_SHUTDOWN_WAIT)
    for node in nodes:
        node.destroy_node()
    return failures
