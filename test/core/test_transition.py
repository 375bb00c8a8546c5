"""The transition into a new circle: a quintic in task space, its duration and its checks."""

import math

from freejoint_core.arm import table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.singularity import check_path, det_map, semi_singular
from freejoint_core.trajectory import circle_max_tick_step, circle_peaks, CircleQuintic
from freejoint_core.trajectory import plan_transition, QuinticTransition, transition_limits
import numpy as np
import pytest

DT = 0.001
PAPER = CircleQuintic()


@pytest.fixture(scope='module')
def region():
    return semi_singular(det_map(table1('horizontal').scaled(0.7), 1.0), 1e-7)


def _path_check(region):
    def check(points):
        c = check_path(region, points)
        return c.ok, c.margin, c.reason
    return check


def test_a_rest_to_rest_transition_is_the_textbook_quintic_along_the_line():
    # p0 = (0, 0) at rest to p1 = (1, 2) in T = 2 s: p = p1 (10 u^3 - 15 u^4 + 6 u^5), u = t / T
    seg = QuinticTransition((0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (1.0, 2.0), 2.0)
    for t in (0.0, 0.3, 1.0, 1.7):
        u = t / 2.0
        s = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
        ds = (30 * u ** 2 - 60 * u ** 3 + 30 * u ** 4) / 2.0
        dds = (60 * u - 180 * u ** 2 + 120 * u ** 3) / 4.0
        np.testing.assert_allclose(seg.sample_tuple(t), (s, 2 * s, ds, 2 * ds, dds, 2 * dds),
                                   rtol=0, atol=1e-14)
    assert seg.sample_tuple(1.0)[2:4] == pytest.approx((1.875 / 2.0, 3.75 / 2.0), abs=1e-15)


def test_the_start_velocity_and_acceleration_terms_are_the_hermite_bases():
    # v0 only, back to the start: p = v0 T h1(u), h1 = u - 6 u^3 + 8 u^4 - 3 u^5;
    # a0 only: p = a0 T^2 u^2 (1 - u)^3 / 2. At u = 1/2, T = 1: 0.15625 and 0.03125.
    seg = QuinticTransition((0.0, 0.0), (1.0, 0.0), (0.0, 0.0), (0.0, 0.0), 1.0)
    assert seg.sample_tuple(0.5)[0] == pytest.approx(0.15625, abs=1e-15)
    seg = QuinticTransition((0.0, 0.0), (0.0, 0.0), (0.0, 2.0), (0.0, 0.0), 1.0)
    assert seg.sample_tuple(0.5)[1] == pytest.approx(0.03125, abs=1e-15)


def test_position_velocity_and_acceleration_are_continuous_at_both_joints():
    p0, v0, a0, p1 = (0.1, -0.2), (0.3, 0.4), (-1.0, 0.5), (0.25, 0.05)
    seg = QuinticTransition(p0, v0, a0, p1, 0.8)
    # start: exactly the state it starts from (what the stream published before goes on)
    assert seg.sample_tuple(0.0) == p0 + v0 + a0
    # end: the polynomial itself reaches p1 at rest (not only the held value past T)
    px, vx, ax = seg._eval(seg._cx, 0.8)
    py, vy, ay = seg._eval(seg._cy, 0.8)
    np.testing.assert_allclose((px, py, vx, vy, ax, ay), p1 + (0.0, 0.0, 0.0, 0.0),
                               rtol=0, atol=1e-12)
    assert seg.sample_tuple(0.8) == p1 + (0.0, 0.0, 0.0, 0.0)
    assert seg.sample_tuple(5.0) == p1 + (0.0, 0.0, 0.0, 0.0)      # held after T
    # and the derivatives are those of the position (central differences inside)
    for t in (0.1, 0.4, 0.75):
        h = 1e-5
        d = (np.array(seg.sample_tuple(t + h)) - np.array(seg.sample_tuple(t - h))) / (2 * h)
        np.testing.assert_allclose(d[:2], seg.sample_tuple(t)[2:4], rtol=0, atol=1e-8)
        np.testing.assert_allclose(d[2:4], seg.sample_tuple(t)[4:6], rtol=0, atol=1e-6)


def test_tick_samples_are_bit_identical_to_sample_tuple():
    seg = QuinticTransition((0.1, -0.2), (0.3, 0.4), (-1.0, 0.5), (0.25, 0.05), 0.8)
    ticks = seg.sample_ticks(DT, 900)
    for j in (0, 1, 17, 400, 799, 800, 899):
        assert tuple(ticks[j]) == seg.sample_tuple(j * DT), j


@pytest.mark.parametrize('name,args', [
    ('p0', ((0.0,), (0, 0), (0, 0), (1, 1), 1.0)),
    ('v0', ((0, 0), (math.nan, 0), (0, 0), (1, 1), 1.0)),
    ('duration', ((0, 0), (0, 0), (0, 0), (1, 1), 0.0)),
])
def test_a_malformed_transition_is_refused_naming_the_argument(name, args):
    with pytest.raises(FreejointValueError, match=name):
        QuinticTransition(*args)


def test_the_circle_peaks_and_tick_step_are_those_of_the_quintic_sampled_on_its_ticks():
    speed, acc = circle_peaks(PAPER)
    assert speed == pytest.approx(1.875 * 2 * math.pi * 0.2 / 5.0, rel=1e-15)   # 0.4712
    ticks = np.array([PAPER.sample_tuple(j * DT) for j in range(5002)])
    assert np.hypot(ticks[:, 2], ticks[:, 3]).max() <= speed
    assert np.hypot(ticks[:, 4], ticks[:, 5]).max() == pytest.approx(acc, rel=1e-6)
    step = np.hypot(np.diff(ticks[:, 0]), np.diff(ticks[:, 1])).max()
    assert circle_max_tick_step(PAPER, DT) == step
    slow = CircleQuintic(radius=0.1, duration=30.0)         # the window about the middle
    ticks = np.array([slow.sample_tuple(j * DT) for j in range(30002)])
    assert circle_max_tick_step(slow, DT) == np.hypot(np.diff(ticks[:, 0]),
                                                      np.diff(ticks[:, 1])).max()


@pytest.mark.parametrize('t_old', [0.8, 1.9, 2.5, 3.3, 4.4, 6.0])
def test_the_transition_from_a_running_circle_stays_within_the_new_circles_peaks(t_old):
    old = CircleQuintic(centre=(0.05, -0.03), start_angle=1.0)
    state = old.sample_tuple(t_old)
    choice = plan_transition(state[:2], state[2:4], state[4:], PAPER, DT)
    assert choice.ok, choice.reason
    v_lim, a_lim, s_lim = choice.limits
    assert (v_lim, a_lim, s_lim) == (*circle_peaks(PAPER), circle_max_tick_step(PAPER, DT))
    n = choice.ticks
    assert choice.segment.duration == n * DT
    ticks = choice.segment.sample_ticks(DT, n)
    ticks = np.vstack((ticks, PAPER.sample_tuple(0.0)))           # its last step: the circle
    assert np.hypot(ticks[:, 2], ticks[:, 3]).max() <= v_lim
    assert np.hypot(ticks[:, 4], ticks[:, 5]).max() <= a_lim
    assert np.hypot(np.diff(ticks[:, 0]), np.diff(ticks[:, 1])).max() <= s_lim
    assert tuple(ticks[0]) == state                               # starts where it was
    # the shortest: a tick shorter breaks a limit
    shorter = QuinticTransition(state[:2], state[2:4], state[4:], ticks[-1, :2], (n - 1) * DT)
    s = np.vstack((shorter.sample_ticks(DT, n - 1), PAPER.sample_tuple(0.0)))
    assert (np.hypot(s[:, 2], s[:, 3]).max() > v_lim or np.hypot(s[:, 4], s[:, 5]).max() > a_lim
            or np.hypot(np.diff(s[:, 0]), np.diff(s[:, 1])).max() > s_lim) or n > 32


def test_a_rest_to_rest_transition_takes_the_quintic_time_of_its_tightest_bound():
    # 0.3 m at rest: acceleration bound 5.7735 d / T^2 <= A gives T >= 0.7 s (speed: 0.6 s)
    p0 = np.array(PAPER.sample_tuple(0.0)[:2]) + (0.0, 0.3)
    choice = plan_transition(p0, (0, 0), (0, 0), PAPER, DT)
    _, a_lim, _ = choice.limits
    t_min = math.sqrt(10.0 / math.sqrt(3.0) * 0.3 / a_lim)
    assert choice.ok and t_min <= choice.segment.duration <= 1.011 * t_min + DT
    pts = choice.segment.sample_ticks(DT, choice.ticks)
    assert np.allclose(pts[:, 0], 0.2, rtol=0, atol=1e-15)        # a straight line


def test_no_transition_when_the_state_is_the_circle_start_at_rest_within_a_nanometre():
    choice = plan_transition((0.2, 0.0), (0.0, 0.0), (0.0, 0.0), PAPER, DT)
    assert choice.ok and choice.segment is None and choice.ticks == 0
    end = PAPER.sample_tuple(5.0)                       # (0.2, -4.9e-17): the same point
    assert end[1] != 0.0
    assert plan_transition(end[:2], end[2:4], end[4:], PAPER, DT).segment is None
    choice = plan_transition((0.2, 2e-9), (0.0, 0.0), (0.0, 0.0), PAPER, DT)
    assert choice.ok and choice.ticks > 0
    choice = plan_transition((0.2, 0.0), (1e-12, 0.0), (0.0, 0.0), PAPER, DT)
    assert choice.ok and choice.ticks > 0               # moving: always a transition


def test_a_faster_start_state_raises_the_limits_to_its_own_speed():
    slow = CircleQuintic(duration=20.0)
    v_lim, a_lim, s_lim = transition_limits(slow, DT, (0.4, 0.0), (0.0, 0.0))
    speed, acc = circle_peaks(slow)
    assert (v_lim, a_lim) == (0.4, acc)
    assert s_lim == pytest.approx(circle_max_tick_step(slow, DT) * 0.4 / speed, rel=1e-15)


def test_a_transition_that_would_cross_the_semi_singular_region_is_refused(region):
    # at 0.43 m moving outward at 0.47 m/s: stopping within 1.11 m/s^2 takes 0.1 m, into
    # the annulus from 0.478 m (1 deg map), whatever the duration
    inner = region.intervals[0, 0]
    assert 0.47 < inner < 0.5
    choice = plan_transition((0.43, 0.0), (0.47, 0.0), (0.0, 0.0), PAPER, DT,
                             path_check=_path_check(region))
    assert not choice.ok and choice.segment is None
    assert 'semi-singular annulus' in choice.reason, choice.reason
    # the same state moving inward is fine, with a positive margin
    choice = plan_transition((0.43, 0.0), (-0.47, 0.0), (0.0, 0.0), PAPER, DT,
                             path_check=_path_check(region))
    assert choice.ok and 0.0 < choice.margin < inner - 0.2


def test_no_transition_within_the_limits_is_refused_with_the_closest_miss():
    choice = plan_transition((0.0, 0.0), (0.0, 0.0), (0.0, 0.0), PAPER, DT, max_duration=0.05)
    assert not choice.ok
    assert 'no transition of at most 0.05 s' in choice.reason, choice.reason
