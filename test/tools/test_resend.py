"""
The resend helper (freejoint_tools.resend) of the harness, the viewer and ``fj``.

Driven by a simulated clock and futures answered by a scripted server (no DDS, no
sleeps): a request left unanswered ``resend`` s is sent again, the first answer of any
request is taken, every other request is cancelled, and nothing is sent past the timeout.
"""
import concurrent.futures
import threading

from freejoint_tools.resend import first_answer, Wakeup


class Clock:
    """A clock that advances only when the waiter waits."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def scripted(clock, answer_at):
    """
    Return ``(send, wait, futures)``: request i is answered at ``answer_at[i]`` s (None: never).

    ``wait(predicate, seconds)`` advances the clock to the first answer due within
    ``seconds`` (answering it), else by ``seconds``.
    """
    futures = []
    due = []

    def send():
        future = concurrent.futures.Future()
        at = answer_at[len(futures)] if len(futures) < len(answer_at) else None
        futures.append(future)
        if at is not None:
            due.append((at, len(futures) - 1))
        return future

    def wait(predicate, seconds):
        end = clock.now + seconds
        while not predicate():
            pending = sorted((at, i) for at, i in due
                             if at <= end and not futures[i].done())
            if not pending:
                clock.now = end
                return False
            at, i = pending[0]
            clock.now = max(clock.now, at)
            futures[i].set_result('answer %d' % i)
        return True

    return send, wait, futures


def test_an_answered_request_is_sent_once_and_its_answer_taken():
    clock = Clock()
    send, wait, futures = scripted(clock, [0.2])
    future, sent = first_answer(send, wait, 10.0, resend=1.0, clock=clock)
    assert (future.result(), sent) == ('answer 0', 1)
    assert clock.now == 0.2


def test_a_lost_response_is_sent_again_after_resend_seconds_and_the_second_answers():
    clock = Clock()
    send, wait, futures = scripted(clock, [None, 1.3])
    future, sent = first_answer(send, wait, 10.0, resend=1.0, clock=clock)
    assert (future.result(), sent) == ('answer 1', 2)
    assert futures[0].cancelled()           # the lost one goes nowhere


def test_a_late_answer_to_an_earlier_request_is_taken_when_it_comes_first():
    clock = Clock()
    send, wait, futures = scripted(clock, [1.5, 9.0])      # the first answers after a resend
    future, sent = first_answer(send, wait, 10.0, resend=1.0, clock=clock)
    assert (future.result(), sent) == ('answer 0', 2)
    assert clock.now == 1.5
    assert futures[1].cancelled()


def test_without_resend_one_request_waits_the_whole_timeout_and_none_is_returned():
    clock = Clock()
    send, wait, futures = scripted(clock, [None])
    future, sent = first_answer(send, wait, 2.0, resend=None, clock=clock)
    assert (future, sent) == (None, 1)
    assert clock.now == 2.0
    assert futures[0].cancelled()


def test_unanswered_requests_are_resent_every_resend_seconds_until_the_timeout():
    clock = Clock()
    send, wait, futures = scripted(clock, [])
    future, sent = first_answer(send, wait, 2.0, resend=0.5, clock=clock)
    assert future is None
    assert sent == 4                        # at 0, 0.5, 1.0, 1.5; none at the deadline
    assert clock.now == 2.0
    assert all(f.cancelled() for f in futures)


def test_a_request_that_failed_is_an_answer_whose_result_raises():
    clock = Clock()
    failing = concurrent.futures.Future()
    failing.set_exception(RuntimeError('service gone'))
    future, sent = first_answer(lambda: failing, lambda p, s: p(), 5.0, resend=1.0,
                                clock=clock)
    assert (future, sent) == (failing, 1)
    assert isinstance(future.exception(), RuntimeError)


def test_the_wakeup_returns_when_a_watched_future_is_done_on_another_thread():
    wakeup = Wakeup()
    future = wakeup.watch(concurrent.futures.Future())
    answering = threading.Thread(target=future.set_result, args=('answer',))
    answering.start()
    assert wakeup(future.done, 30.0)        # returns on the answer, long before 30 s
    answering.join(timeout=30.0)
    assert future.result() == 'answer'


def test_the_wakeup_gives_up_after_its_seconds_when_nothing_is_done():
    wakeup = Wakeup()
    wakeup.watch(concurrent.futures.Future())
    assert not wakeup(lambda: False, 0.0)
