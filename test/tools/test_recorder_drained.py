"""received_count / wait_drained: the drain wait of make demo and bench/graph.py."""

import time

from freejoint_tools.recorder import received_count, wait_drained


def test_the_count_is_read_from_the_status_message_format():
    status = 'recording; received 5021; matched publishers: /clock 1, /setpoint 1'
    assert received_count(status) == 5021
    assert received_count('waiting for /setpoint; received 0; matched publishers: ') == 0
    assert received_count('') is None
    assert received_count(None) is None
    assert received_count('received twelve') is None


def test_it_returns_once_the_count_stops_changing_for_the_quiet_time():
    answers = iter([None, 'x; received 10; y', 'x; received 20; y'] +
                   ['x; received 30; y'] * 1000)
    reads = []

    def read():
        reads.append(1)
        return next(answers)

    count, settled = wait_drained(read, 0.05, 10.0, lambda: time.sleep(0.01))
    assert count == 30
    assert 0.0 <= settled < 1.0
    assert 5 <= len(reads) < 100      # stopped after ~0.05 s of the same count


def test_on_timeout_it_returns_the_last_count_read():
    counts = iter(range(10**6))
    count, settled = wait_drained(lambda: 'x; received %d; y' % next(counts), 0.5, 0.05,
                                  lambda: None)
    assert count is not None and count > 0
    assert settled >= 0.05
    assert wait_drained(lambda: None, 0.01, 0.05, lambda: None)[0] is None
