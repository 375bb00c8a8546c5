"""
Send a request until it is answered: the one resend helper of the tests, the viewer and fj.

rmw_fastrtps drops a service response sent before the server matched the client's
response reader (ros2/rmw_fastrtps#390, #467): a request to a server discovered a moment
ago can go unanswered for good, and waiting longer never brings its answer. An
idempotent request (a parameter query, a ``~/reset``, a ``~/status``) is therefore sent
again while unanswered; the first answer of any of the requests sent is taken, the
others are cancelled (a late answer goes nowhere).

:func:`first_answer` does not spin or sleep itself: the caller hands it how to wait, so
one loop serves a process that spins its own executor (the test harness, ``fj``:
``wait`` spins it) and a thread waiting on an executor that runs elsewhere (the viewer's
server threads: :class:`Wakeup`). It works on any futures with ``done()``,
``cancelled()``, ``cancel()`` (rclpy's, ``concurrent.futures``').
"""

import threading
import time


def first_answer(send, wait, timeout, resend=None, clock=time.monotonic):
    """
    Send a request and wait until one is answered; return ``(future or None, sent)``.

    Parameters
    ----------
    send : callable
        ``send() -> future``: sends one request.
    wait : callable
        ``wait(predicate, seconds)``: returns once ``predicate()`` is true or ``seconds``
        have passed (spinning the executor, or blocking the calling thread).
    timeout : float
        Seconds in all.
    resend : float, optional
        Seconds an unanswered request waits before the next is sent (idempotent requests
        only); None sends one request.
    clock : callable
        Seconds (``time.monotonic``).

    Returns
    -------
    tuple of (future or None, int)
        The first future done (its ``result()`` is the answer, or raises the request's
        exception), None if none was within ``timeout``; and how many requests were sent.

    """
    deadline = clock() + timeout
    futures = []

    def answered():
        return next((f for f in futures if f.done() and not f.cancelled()), None)

    try:
        while True:
            futures.append(send())
            left = deadline - clock()
            wait(lambda: answered() is not None,
                 max(0.0, left if resend is None else min(resend, left)))
            if answered() is not None or clock() >= deadline:
                break
        first = answered()
    finally:
        for future in futures:
            future.cancel()         # a done future stays done
    return first, len(futures)


class Wakeup:
    """
    A ``wait`` for :func:`first_answer` in a thread other than the executor's.

    :meth:`watch` (on the executor's thread, where the future is made) wakes the waiting
    thread when the future is done; calling the object waits for the predicate.
    """

    def __init__(self, clock=time.monotonic):
        self._event = threading.Event()
        self._clock = clock

    def watch(self, future):
        """Wake the waiting thread when ``future`` is done; return ``future``."""
        future.add_done_callback(lambda _future: self._event.set())
        return future

    def __call__(self, predicate, seconds):
        """Block until ``predicate()`` is true or ``seconds`` passed; return ``predicate()``."""
        deadline = self._clock() + seconds
        while not predicate():
            left = deadline - self._clock()
            if left <= 0.0:
                return False
            self._event.wait(left)
            self._event.clear()
        return True
