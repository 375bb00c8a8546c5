"""Behaviour of the quintic circle trajectory."""

import math

from freejoint_core.errors import FreejointValueError
from freejoint_core.trajectory import CircleQuintic, workspace_annulus
import numpy as np
import pytest


PAPER_LENGTHS = (0.5, 0.5, 0.5)


def _central_diff(fun, t, h=1e-5):
    return (np.asarray(fun(t + h)) - np.asarray(fun(t - h))) / (2.0 * h)


@pytest.mark.parametrize('direction', [1, -1])
@pytest.mark.parametrize('t', [0.3, 1.1, 2.5, 3.7, 4.6])
def test_velocity_and_acceleration_match_finite_differences(direction, t):
    traj = CircleQuintic(centre=(0.1, -0.05), radius=0.2, duration=5.0,
                         start_angle=0.4, direction=direction)
    p, pd, pdd = traj.sample(t)
    fd_pd = _central_diff(lambda x: traj.sample(x)[0], t)
    fd_pdd = _central_diff(lambda x: traj.sample(x)[1], t)
    np.testing.assert_allclose(pd, fd_pd, rtol=0, atol=1e-8)
    np.testing.assert_allclose(pdd, fd_pdd, rtol=0, atol=1e-7)
    # And the point really lies on the circle.
    assert math.hypot(p[0] - 0.1, p[1] + 0.05) == pytest.approx(0.2, abs=1e-15)


def test_paper_circle_starts_and_ends_at_rest_at_0_2_0():
    traj = CircleQuintic()
    for t in (0.0, 5.0):
        p, pd, pdd = traj.sample(t)
        np.testing.assert_allclose(p, [0.2, 0.0], atol=1e-15)
        np.testing.assert_array_equal(pd, [0.0, 0.0])
        np.testing.assert_allclose(pdd, [0.0, 0.0], atol=1e-15)


def test_point_is_held_outside_the_duration():
    traj = CircleQuintic(start_angle=0.5)
    start = traj.sample(0.0)
    end = traj.sample(5.0)
    for t, ref in ((-1.0, start), (-1e-9, start), (5.0 + 1e-9, end), (100.0, end)):
        for got, want in zip(traj.sample(t), ref):
            np.testing.assert_array_equal(got, want)


def test_peak_speed_is_at_half_time_with_the_quintic_value():
    # s'(1/2) = 30/4 - 60/8 + 30/16 = 15/8, so |v| = r 2 pi (15/8) / T.
    traj = CircleQuintic(radius=0.2, duration=5.0)
    _, pd, pdd = traj.sample(2.5)
    assert np.linalg.norm(pd) == pytest.approx(0.2 * 2 * math.pi * 15 / 8 / 5.0, rel=1e-14)
    # s''(1/2) = 0: the acceleration is purely centripetal, pointing to the centre.
    p, _, _ = traj.sample(2.5)
    w = 2 * math.pi * 15 / 8 / 5.0
    np.testing.assert_allclose(pdd, -w * w * p, atol=1e-14)


def test_half_time_is_half_a_revolution():
    traj = CircleQuintic()
    p, _, _ = traj.sample(2.5)
    np.testing.assert_allclose(p, [-0.2, 0.0], atol=1e-15)


@pytest.mark.parametrize('direction, sign', [(1, 1.0), (-1, -1.0)])
def test_one_full_revolution_in_the_given_direction(direction, sign):
    traj = CircleQuintic(direction=direction)
    t = np.linspace(0.0, 5.0, 2001)
    angles = np.array([math.atan2(*traj.sample(x)[0][::-1]) for x in t])
    total = np.sum(np.diff(np.unwrap(angles)))
    assert total == pytest.approx(sign * 2 * math.pi, abs=1e-12)


def test_sample_tuple_equals_sample():
    traj = CircleQuintic(centre=(0.05, 0.02), radius=0.15, start_angle=-1.0, direction=-1)
    for t in (-0.5, 0.0, 0.77, 2.0, 4.999, 5.0, 7.0):
        p, pd, pdd = traj.sample(t)
        assert traj.sample_tuple(t) == (p[0], p[1], pd[0], pd[1], pdd[0], pdd[1])
        assert all(type(v) is float for v in traj.sample_tuple(t))


def test_points_trace_the_circle_and_close():
    traj = CircleQuintic(centre=(0.1, 0.0), radius=0.2)
    pts = traj.points(9)
    assert pts.shape == (9, 2)
    np.testing.assert_allclose(np.hypot(pts[:, 0] - 0.1, pts[:, 1]), 0.2, atol=1e-15)
    np.testing.assert_allclose(pts[0], pts[-1], atol=1e-15)
    np.testing.assert_allclose(pts[2], [0.1, 0.2], atol=1e-15)


@pytest.mark.parametrize('kwargs, match', [
    ({'radius': 0.0}, 'radius'),
    ({'radius': -0.1}, 'radius'),
    ({'radius': float('nan')}, 'radius'),
    ({'radius': 'big'}, 'radius'),
    ({'duration': 0.0}, 'duration'),
    ({'duration': float('inf')}, 'duration'),
    ({'centre': (0.0, 0.0, 0.0)}, 'centre'),
    ({'centre': (0.0, float('nan'))}, 'centre'),
    ({'start_angle': None}, 'start_angle'),
    ({'direction': 0}, 'direction'),
    ({'direction': 2}, 'direction'),
    ({'direction': True}, 'direction'),
])
def test_bad_arguments_raise_naming_the_argument(kwargs, match):
    with pytest.raises(FreejointValueError, match=match):
        CircleQuintic(**kwargs)


def test_sample_rejects_non_finite_time():
    with pytest.raises(FreejointValueError, match='^t:'):
        CircleQuintic().sample(float('nan'))


def test_workspace_annulus_of_equal_links_reaches_the_base():
    assert workspace_annulus(PAPER_LENGTHS) == (0.0, 1.5)
    assert workspace_annulus((1.0, 0.3, 0.2)) == pytest.approx((0.5, 1.5))
    with pytest.raises(FreejointValueError, match='lengths'):
        workspace_annulus((0.5, -0.5))


def test_repeated_circle_ticks_are_the_circles_then_its_start_at_rest():
    from freejoint_core.trajectory import RepeatedCircle
    circle = CircleQuintic()                      # 5 s: 5000 ticks of 1 ms
    series = RepeatedCircle(circle, 3, 0.5, 0.001)  # 5500 ticks per revolution and rest
    assert series.duration == 3 * 5.0 + 2 * 0.5
    start = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    # revolution 2 (c = 1) starts at tick 5500: its tick i is the circle's i
    for j, i in ((0, 0), (1234, 1234), (4999, 4999), (5500, 0), (5501, 1), (12345, 1345),
                 (15999, 4999)):
        assert series.sample_tuple(j * 0.001) == circle.sample_tuple(i * 0.001), j
    # the rests and after the last revolution: the start point, at rest (not the circle's
    # end point, whose y is sin(2 pi) * 0.2 = -4.9e-17)
    for j in (5000, 5499, 10999, 16000, 20000):
        assert series.sample_tuple(j * 0.001) == start, j
    assert series.sample_tuple(-0.01) == circle.sample_tuple(-0.01)


def test_repeated_circle_refuses_a_rest_off_the_tick_grid_naming_it():
    from freejoint_core.trajectory import RepeatedCircle
    with pytest.raises(FreejointValueError, match='rest: 0.0005 s'):
        RepeatedCircle(CircleQuintic(), 2, 0.0005, 0.001)
    with pytest.raises(FreejointValueError, match='count: expected an int >= 1'):
        RepeatedCircle(CircleQuintic(), 0, 0.0, 0.001)


def test_repeated_circle_is_the_offline_circles_runners_setpoint_tick_by_tick():
    from freejoint_core.arm import ArmModel, table1
    from freejoint_core.circles import run_circles
    from freejoint_core.trajectory import RepeatedCircle
    records, trace = run_circles('vertical', 'robust', 0, circles=2, rest=0.5,
                                 record_trace=True)
    assert len(records) == 2 and records[-1]['diverged_at_s'] is None
    series = RepeatedCircle(CircleQuintic(), 2, 0.5, 0.001)
    model = ArmModel(table1('vertical'))
    # the runner's setpoint of tick k: the true end effector less the error it recorded
    for k in range(0, len(trace['t']), 50):
        des = model.fk(trace['q'][k]) - trace['e'][k]
        assert des == pytest.approx(series.sample_tuple(k * 0.001)[:2], abs=1e-12), k
