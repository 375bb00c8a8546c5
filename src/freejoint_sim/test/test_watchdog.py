"""The simulated drive's command watchdog (freejoint_sim.watchdog)."""
from freejoint_core.errors import FreejointValueError
from freejoint_sim.params import SCHEMA
from freejoint_sim.watchdog import DriveWatchdog
import pytest


def test_a_command_that_finds_the_arm_at_rest_brakes_after_the_shorter_wait():
    dog = DriveWatchdog(0.05, 0.01, 0.05)
    rest = dog.judge([0.0, -0.049, 0.049])[0]
    assert rest == 0.01
    assert not dog.expired(1.0099, 1.0, rest) and dog.expired(1.0101, 1.0, rest)


def test_one_joint_moving_passive_or_not_keeps_the_moving_wait():
    dog = DriveWatchdog(0.05, 0.01, 0.05)
    for qd in ([0.05, 0.0, 0.0], [0.0, 0.0, -0.3], [2.0, 1.0, 0.0]):
        wait = dog.judge(qd)[0]
        assert wait == 0.05, qd
        assert not dog.expired(1.04, 1.0, wait) and dog.expired(1.051, 1.0, wait)


def test_no_watchdog_never_brakes_and_the_rest_wait_is_at_most_the_moving_one():
    never = DriveWatchdog(0.0, 0.01, 0.05)
    assert never.judge([0.0, 0.0])[0] == 0.0 and not never.expired(1e6, 0.0, 0.0)
    assert DriveWatchdog(0.05, 0.0).judge([0.0])[0] == 0.05      # 0: brake_timeout
    assert DriveWatchdog(0.02, 0.5).judge([0.0])[0] == 0.02      # never above it


def test_the_defaults_are_the_schemas_and_bad_values_are_refused_naming_them():
    d = SCHEMA.defaults()
    dog = DriveWatchdog(d['brake_timeout'], d['brake_timeout_at_rest'], d['rest_speed'])
    assert (dog.brake_timeout, dog.rest_timeout, dog.rest_speed) == (0.05, 0.01, 0.05)
    with pytest.raises(FreejointValueError, match='^rest_timeout: expected a finite wait'):
        DriveWatchdog(0.05, -1.0)
    with pytest.raises(FreejointValueError, match='^brake_timeout: expected a finite wait'):
        DriveWatchdog(float('nan'))
    with pytest.raises(FreejointValueError, match='^rest_speed: expected > 0 rad/s'):
        DriveWatchdog(0.05, 0.01, 0.0)


def test_the_controllers_request_shortens_the_wait_and_says_so_but_never_lengthens_it():
    dog = DriveWatchdog(0.05, 0.01, 0.05)
    moving, rest = [0.0, 0.0, 2.0], [0.0, 0.0, 0.0]
    assert dog.judge(moving) == (0.05, 'moving')
    assert dog.judge(rest) == (0.01, 'at rest')
    assert dog.judge(moving, 0.02) == (0.02, 'asked')          # the free link swinging
    assert dog.judge(rest, 0.02) == (0.01, 'at rest')          # its own is shorter
    assert dog.judge(moving, 0.5) == (0.05, 'moving')          # never longer
    assert dog.judge(moving, 0.0) == (0.05, 'moving')          # 0: no request
    # A watchdog turned off stays off: a request does not make the drive brake.
    assert DriveWatchdog(0.0, 0.01).judge(moving, 0.01) == (0.0, 'moving')


def test_a_request_that_is_not_a_finite_wait_is_refused_naming_the_topic():
    assert DriveWatchdog.check_request(0.01) == 0.01
    assert DriveWatchdog.check_request(0) == 0.0
    for bad in (float('nan'), float('inf'), -0.01, 'soon', None):
        with pytest.raises(FreejointValueError, match='^brake_timeout_request: expected'):
            DriveWatchdog.check_request(bad)
