"""When the simulated plant counts as diverged (no ROS)."""
import math

from freejoint_sim.divergence import divergence_reason, MAX_ANGLE


def test_a_finite_state_within_the_bounds_is_sane():
    assert divergence_reason([0.1, -3.0, 1e5], [999.0, -999.0, 0.0], 1000.0) is None


def test_a_non_finite_state_is_diverged_naming_the_joint():
    assert divergence_reason([0.0, math.nan, 0.0], [0.0, 0.0, 0.0], 1000.0) == \
        'joint 1: non-finite state (q = nan rad, qd = 0.0 rad/s)'
    assert divergence_reason([0.0, 0.0], [0.0, -math.inf], 1000.0).startswith('joint 1: non')


def test_a_joint_faster_than_the_bound_is_diverged_naming_speed_and_bound():
    assert divergence_reason([0.0, 0.0, 0.0], [0.0, 0.0, -1000.5], 1000.0) == \
        'joint 2: speed -1000.5 rad/s beyond divergence_speed 1000 rad/s'


def test_an_angle_beyond_the_plausible_is_diverged():
    assert divergence_reason([2 * MAX_ANGLE, 0.0], [0.0, 0.0], 1000.0) == \
        'joint 0: angle 2e+06 rad beyond 1e+06 rad'
