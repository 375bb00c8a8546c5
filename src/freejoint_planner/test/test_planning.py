"""The planner's parameter validation, circle sampling, path check and grid extent."""
import re

from freejoint_core.arm import table1
from freejoint_core.singularity import det_map, semi_singular
from freejoint_core.trajectory import CircleQuintic
from freejoint_planner.params import validate
from freejoint_planner.planning import circle_bounds, circle_check_points, compute_model
from freejoint_planner.planning import grid_bound, grid_extent, make_circle, SingularityModel
import numpy as np
import pytest

DEFAULTS = {
    'case': 'horizontal', 'nominal_scale': 0.7, 'resolution_deg': 0.25, 'eps_d': 1e-7,
    'grid_resolution': 0.01, 'frame_id': 'base_link', 'control_period': 0.001,
    'lookahead': 20, 'centre': [0.0, 0.0], 'radius': 0.2, 'duration': 5.0,
    'start_angle': 0.0, 'direction': 1, 'start_delay': 0.0, 'autostart': True,
    'max_speed': 1.0, 'max_acceleration': 5.0, 'transition_max_duration': 60.0,
}


@pytest.fixture(scope='module')
def model():
    return compute_model('horizontal', 0.7, 1.0, 1e-7)


def test_the_paper_configuration_is_valid():
    assert validate(DEFAULTS) == ''


@pytest.mark.parametrize('name,value,match', [
    ('radius', -0.1, r'radius: expected a value in \(0, 10\], got -0.1'),
    ('radius', 0.0, 'radius: expected a value in'),
    ('eps_d', 0.0, r'eps_d: expected a value in \(0, 1\], got 0'),
    ('eps_d', -1e-7, 'eps_d'),
    ('resolution_deg', 0.05, r'resolution_deg: expected a value in \[0.1, 10\]'),
    ('resolution_deg', 1.6, r'360 / 1.6 must be an even integer'),      # 225 steps
    ('resolution_deg', 0.7, r'360 / 0.7 must be an even integer'),      # 514.3 steps
    ('centre', [0.1], r'centre: expected 2 values \(x, y\) in m, got 1'),
    ('centre', [0.1, 0.2, 0.3], 'centre: expected 2 values'),
    ('centre', [0.1, float('nan')], 'centre: expected finite numbers'),
    ('direction', 0, r'direction: expected \+1 or -1, got 0'),
    ('case', 'diagonal', "case: expected one of .*, got 'diagonal'"),
    ('duration', 0.0, 'duration'),
    ('start_delay', -1.0, 'start_delay'),
    ('lookahead', -1, 'lookahead'),
    ('lookahead', 0, r'lookahead: expected a value in \[1, 1000\], got 0'),
    ('lookahead', 1001, 'lookahead'),
    ('start_angle', 7.0, r'start_angle: expected a value in \[-6.28319, 6.28319\]'),
    ('start_angle', 1e17, 'start_angle'),
    ('max_speed', 0.0, r'max_speed: expected a value in \(0, 10\]'),
    ('max_acceleration', 101.0, 'max_acceleration'),
    ('transition_max_duration', 0.0, 'transition_max_duration'),
    ('control_period', 0.0010000005, 'control_period: .* not a whole number'),
    ('grid_resolution', 1.0, 'grid_resolution'),
    ('frame_id', ' ', 'frame_id'),
    ('start_angle', float('inf'), 'start_angle: expected a finite number'),
    ('nominal_scale', True, 'nominal_scale: expected a number'),
])
def test_a_bad_value_is_refused_with_a_reason_naming_it(name, value, match):
    reason = validate({**DEFAULTS, name: value})
    assert reason.startswith(name + ':')
    assert re.search(match, reason), reason


def test_make_circle_builds_the_configured_circle():
    c = make_circle({**DEFAULTS, 'centre': [0.1, -0.2], 'direction': -1, 'start_angle': 1.0})
    assert c.centre.tolist() == [0.1, -0.2]
    assert (c.radius, c.duration, c.start_angle, c.direction) == (0.2, 5.0, 1.0, -1)


def test_check_points_are_dense_and_include_the_nearest_and_farthest_points():
    pts = circle_check_points(CircleQuintic(centre=(0.5, 0.0), radius=0.2))
    # 2 pi 0.2 / 5e-4 = 2513.3 -> 2514 steps, 2515 points, plus the two extremes
    assert pts.shape == (2517, 2)
    assert pts[-2].tolist() == pytest.approx([0.3, 0.0], abs=1e-15)
    assert pts[-1].tolist() == pytest.approx([0.7, 0.0], abs=1e-15)
    steps = np.hypot(*np.diff(pts[:-2], axis=0).T)
    assert steps.max() <= 5e-4


def test_check_points_of_a_circle_about_the_base_are_the_circle_only():
    pts = circle_check_points(CircleQuintic(radius=0.01))
    assert pts.shape == (721, 2)
    assert np.allclose(np.hypot(pts[:, 0], pts[:, 1]), 0.01, rtol=0, atol=1e-15)


def test_model_is_the_core_region_of_the_nominal_arm(model):
    ref = semi_singular(det_map(table1('horizontal').scaled(0.7), 1.0), 1e-7)
    assert np.array_equal(model.region.intervals, ref.intervals)
    assert model.region.reach == (0.0, 1.5)
    assert model.seconds > 0.0


def test_a_four_link_arm_model_takes_the_general_map_and_checks_circles_by_it():
    # the planner's check on another arm: SingularityModel over the core's arm_region
    from freejoint_core.singularity_nlink import arm_region
    from freejoint_core.urdf import four_link_arm
    nominal = four_link_arm('horizontal').nominal(0.7)
    four = SingularityModel(case='horizontal', nominal_scale=0.7, resolution_deg=4.0,
                            eps_d=1e-7, nominal=nominal, region=arm_region(nominal, 4.0),
                            seconds=0.0)
    assert four.region.singular_mask.ndim == 3           # over (q2, q3, q4)
    assert four.region.reach == pytest.approx((0.0, 1.3))
    check = four.check(CircleQuintic(centre=(0.0, 0.5), radius=0.02))
    assert not check.ok and 'semi-singular annulus' in check.reason


def test_the_paper_circle_passes_with_the_exact_radial_margin(model):
    check = model.check(CircleQuintic())
    lo = model.region.intervals[0, 0]
    assert check.ok and check.reason == ''
    assert check.margin == pytest.approx(lo - 0.2, abs=1e-12)
    assert check.margin > 0.25


def test_an_off_centre_circle_reaches_its_margin_at_the_nearest_point(model):
    check = model.check(CircleQuintic(centre=(0.1, 0.05), radius=0.2))
    lo = model.region.intervals[0, 0]
    assert check.ok
    assert check.margin == pytest.approx(lo - (np.hypot(0.1, 0.05) + 0.2), abs=1e-12)


@pytest.mark.parametrize('centre,radius', [((0.5, 0.0), 0.2), ((1.5, 0.0), 0.2),
                                           ((0.0, 0.0), 0.6)])
def test_a_circle_into_the_semi_singular_region_or_out_of_reach_is_refused(
        model, centre, radius):
    check = model.check(CircleQuintic(centre=centre, radius=radius))
    assert not check.ok
    assert check.margin < 0.0
    assert 'semi-singular annulus' in check.reason or 'reach' in check.reason


def test_grid_extent_is_a_square_of_whole_cells_covering_the_reach():
    assert grid_extent((0.0, 1.5), 0.01) == pytest.approx((-1.5, 1.5, -1.5, 1.5))
    assert grid_extent((0.0, 1.5), 0.4) == pytest.approx((-1.6, 1.6, -1.6, 1.6))
    assert grid_extent((0.2, 1.0), 0.25) == pytest.approx((-1.0, 1.0, -1.0, 1.0))


@pytest.mark.parametrize('circle,match', [
    (CircleQuintic(radius=0.76), r'radius: 0.76 m exceeds the largest circle the reach '
                                 r'annulus \[0, 1.5\] m of the arm holds, 0.75 m'),
    (CircleQuintic(centre=(1.2, 1.0), radius=0.1), r'centre: \(1.2, 1\) m is 1.56205 m from '
                                                   r'the base, beyond the reach 1.5 m'),
    (CircleQuintic(duration=2.0), r'duration: 2 s for radius 0.2 m peaks at 1.1781 m/s, above '
                                  r'max_speed 1 m/s \(duration >= 2.35619 s\)'),
    (CircleQuintic(radius=0.02, duration=0.5), r'duration: 0.5 s .* peaks at 11.1033 m/s\^2, '
                                               r'above max_acceleration 5 m/s\^2'),
])
def test_a_circle_beyond_the_arm_or_the_speed_bounds_is_refused_naming_the_parameter(
        model, circle, match):
    reason = circle_bounds(circle, model, 1.0, 5.0)
    assert re.search(match, reason), reason


def test_the_paper_circle_is_within_the_default_bounds(model):
    assert circle_bounds(CircleQuintic(), model, 1.0, 5.0) == ''


def test_a_grid_resolution_giving_more_than_2000_cells_a_side_is_refused_naming_the_smallest():
    assert grid_bound((0.0, 1.5), 0.0015) == ''                  # 2000 cells a side
    reason = grid_bound((0.0, 1.5), 0.001)
    assert reason == ('grid_resolution: 0.001 m gives a semi_singular_map of 3000 x 3000 cells '
                      'for the reach 1.5 m, above 2000 a side (grid_resolution >= 0.0015 m)')


def test_a_joint_state_in_the_urdfs_angles_is_read_with_the_arms_offsets():
    from freejoint_planner.planning import end_effector, joint_state
    model = compute_model('horizontal', 0.7, 1.0, 1e-7)    # Table I: links 0.5 m
    names = ('joint1', 'joint2', 'joint3')
    offsets = (np.pi / 2, 0.0, 0.0)    # a task frame turned: the straight arm points along y
    assert end_effector(model, names, names, [0.0, 0.0, 0.0], offsets) == pytest.approx(
        (0.0, 1.5), abs=1e-12)
    assert end_effector(model, names, names, [0.0, 0.0, 0.0]) == pytest.approx(
        (1.5, 0.0), abs=1e-12)
    q, qd = joint_state(names, names, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], offsets)
    assert q == [0.1 + np.pi / 2, 0.2, 0.3] and qd == [1.0, 2.0, 3.0]
