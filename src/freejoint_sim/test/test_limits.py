"""The simulator's watch of the URDF's joint limits (freejoint_sim.limits)."""
import math

from freejoint_sim.limits import LimitWatch
import pytest


def test_each_first_passage_is_said_once_and_the_extremes_kept():
    watch = LimitWatch(['j1', 'j7'], [-1.0, -2.9], [1.0, 2.9], [2.0, 2.6])
    assert watch.observe(0.0, [0.0, 2.8], [0.5, 2.0]) == []
    assert watch.observe(0.1, [0.2, 2.95], [0.5, 2.0]) == [
        'j7 at 2.9500 rad passed its URDF position limits [-2.9, 2.9] rad at t = 0.100 s']
    assert watch.observe(0.2, [0.2, 3.2], [0.5, -3.0]) == [
        'j7 at 3.0000 rad/s passed its URDF speed limit 2.6 rad/s at t = 0.200 s']
    assert watch.observe(0.3, [0.2, 3.5], [0.5, 4.0]) == []          # said once each
    assert watch.passed == {('j7', 'position'): (0.1, 2.95), ('j7', 'speed'): (0.2, 3.0)}
    assert watch.extremes == {'j7': (2.8, 3.5, 4.0)}
    assert watch.summary() == 'j7 (position, speed: 2.800..3.500 rad, 4.000 rad/s)'


def test_joints_without_limits_are_not_watched_and_nothing_passed_says_nothing():
    inf = math.inf
    watch = LimitWatch(['c', 'd'], [-inf, 0.0], [inf, 0.0], [0.0, inf])   # continuous etc.
    assert watch.observe(0.0, [100.0, 5.0], [50.0, 50.0]) == []
    assert watch.summary() == '' and watch.extremes == {}


def test_a_list_of_the_wrong_length_is_refused_naming_it():
    with pytest.raises(ValueError, match=r'^lower, upper, velocity: expected 2 values each'):
        LimitWatch(['a', 'b'], [0.0], [1.0, 1.0], [1.0, 1.0])
