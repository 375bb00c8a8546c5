"""runner.run: one lifecycle for every node process (configure, spin, shut down)."""
from freejoint_common.runner import Lifecycle, run, StopFlag
from freejoint_core.errors import FreejointValueError
from rclpy.node import Node


class Probe(Node, Lifecycle):
    """A node that notes what the runner called."""

    calls = []

    def __init__(self, name='probe', problem=None):
        super().__init__(name)
        self.problem = problem

    def on_shutdown(self):
        Probe.calls.append(('on_shutdown', self.get_name()))

    def report(self):
        Probe.calls.append(('report', self.get_name()))
        return '%s stopped' % self.get_name()

    def failure(self):
        return self.problem


def once(nodes, executor, stop):
    """Spin once instead of until a signal."""
    executor.spin_once(timeout_sec=0.01)


def test_several_nodes_share_one_executor_and_shut_down_in_order(capsys):
    Probe.calls = []
    seen = []

    def loop(nodes, executor, stop):
        seen.extend(node.executor is executor for node in nodes)

    code = run(lambda: [Probe('a'), Probe('b')], 'probe', [], loop=loop,
               executor_kind='single_threaded')
    assert code == 0 and seen == [True, True]
    assert Probe.calls == [('on_shutdown', 'a'), ('report', 'a'),
                           ('on_shutdown', 'b'), ('report', 'b')]


def test_a_bad_start_up_parameter_is_exit_2_and_the_nodes_made_before_are_shut_down():
    Probe.calls = []

    def make():
        yield Probe('first')
        raise FreejointValueError('radius: must be > 0, got -1.0')

    assert run(make, 'probe', [], loop=once, executor_kind='single_threaded') == 2
    assert Probe.calls == [('on_shutdown', 'first'), ('report', 'first')]


def test_a_failure_after_the_run_is_one_error_line_and_exit_1(capsys):
    code = run(lambda: Probe(problem='disk full: 12 messages lost'), 'recorder', [],
               loop=once, executor_kind='single_threaded')
    assert code == 1
    assert capsys.readouterr().err == 'recorder: error: disk full: 12 messages lost\n'


def test_an_error_of_the_given_kinds_is_one_line_and_exit_1(capsys):
    def make():
        raise OSError('cannot create /nonexistent/bag')

    assert run(make, 'player', [], errors=(OSError,), loop=once) == 1
    assert capsys.readouterr().err == 'player: error: cannot create /nonexistent/bag\n'


def test_the_stop_flag_notes_the_signal_and_gives_the_handlers_back():
    import signal
    before = signal.getsignal(signal.SIGTERM)
    stop = StopFlag().install()
    try:
        assert signal.getsignal(signal.SIGTERM) is stop and not stop
        stop(signal.SIGTERM, None)
        assert stop and stop.signum == signal.SIGTERM
    finally:
        stop.restore()
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_signal_inside_the_wake_futures_own_lock_returns_and_the_future_completes_after():
    # A signal interrupts the loop's thread anywhere, also inside the wake future's methods
    # that hold its (non-reentrant) lock, as the executor's remove_done_callback does on
    # every spin. Here the signal is delivered from there by a done callback's comparison.
    import signal
    import threading
    import time

    from rclpy.task import Future
    stop = StopFlag()
    woken = Future()
    stop.wake_on_signal(woken)

    class SignalOnCompare:
        def __call__(self, future):
            pass

        def __eq__(self, other):            # list.remove compares under the future's lock
            stop(signal.SIGTERM, None)
            return self is other

        __hash__ = object.__hash__

    woken.add_done_callback(SignalOnCompare())
    returned = threading.Event()

    def spin_end():
        woken.remove_done_callback(lambda future: None)
        returned.set()

    threading.Thread(target=spin_end, daemon=True).start()
    try:
        assert returned.wait(10.0), 'the handler waited for the lock its own thread held'
        assert stop.signum == signal.SIGTERM
        deadline = time.monotonic() + 10.0
        while not woken.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert woken.done() and woken.result() == signal.SIGTERM
    finally:
        stop.restore()
