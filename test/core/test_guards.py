"""The guards: when the simulated plant counts as diverged, when a law result is refused."""
import math

from freejoint_core.guards import divergence_reason, law_output_fault, MAX_ANGLE


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


def test_a_law_result_with_a_torque_beyond_its_limit_or_nan_is_a_fault():
    assert law_output_fault([1.0, -2.0], [1.0, 2.0], [0.5], [(0.0, 1.0)]) is None
    assert law_output_fault([1.5, 0.0], [1.0, 2.0], [], []) == 'torque [1.5, 0.0]'
    assert law_output_fault([math.nan, 0.0], [1.0, 2.0], [], []) == 'torque [nan, 0.0]'


def test_a_law_state_outside_its_bounds_or_non_finite_is_a_fault():
    bounds = [(0.0, 100.0), (-math.inf, math.inf)]
    assert law_output_fault([0.0], [1.0], [100.0, -1e300], bounds) is None
    assert law_output_fault([0.0], [1.0], [-1e-9, 0.0], bounds) == 'law state [-1e-09, 0.0]'
    assert law_output_fault([0.0], [1.0], [1.0, math.inf], bounds) == 'law state [1.0, inf]'
