"""Feed hold: the time scaling that stops a plan along its path, by hand-derived figures."""
import math

from freejoint_core.errors import FreejointValueError
from freejoint_core.feed_hold import FeedRate, lateness, PEAK_RATE, ramp_time, scale_sample
from freejoint_core.feed_hold import smoothstep, smoothstep_integral, smoothstep_rate
from freejoint_core.trajectory import circle_peaks, CircleQuintic, RepeatedCircle
import numpy as np
import pytest

DT = 0.001


def test_smoothstep_goes_from_0_to_1_with_flat_ends_and_half_its_area():
    assert smoothstep(0.0) == 0.0 and smoothstep(1.0) == 1.0 and smoothstep(0.5) == 0.5
    assert smoothstep_rate(0.0) == 0.0 and smoothstep_rate(1.0) == 0.0
    assert smoothstep_rate(0.5) == PEAK_RATE == 30.0 / 16.0
    assert smoothstep_integral(1.0) == 0.5
    # independent cross-check: the integral and the derivative by quadrature / differences
    u = np.linspace(0.0, 1.0, 20001)
    s = np.array([smoothstep(x) for x in u])
    area = np.concatenate(([0.0], np.cumsum(0.5 * (s[1:] + s[:-1]) * np.diff(u))))
    assert np.max(np.abs(area - [smoothstep_integral(x) for x in u])) < 1e-9
    rate = np.gradient(s, u)
    assert np.max(np.abs(rate[1:-1] - [smoothstep_rate(x) for x in u[1:-1]])) < 1e-6


def test_a_feed_never_ramped_is_rate_1_and_the_integer_lag_0():
    feed = FeedRate(DT)
    assert feed.steady and feed.at(12345) == (0, 1.0, 0.0)
    assert feed.ramp(10, 1.0, 0.2) is False and feed.steady     # already at full feed


def test_stop_pause_and_resume_lag_by_half_each_ramp_plus_the_pause():
    # stop from tick 100 over 0.2 s, stand still until tick 1300, resume over 0.4 s:
    # late by 0.1 + 1.0 + 0.2 = 1.3 s = 1300 ticks
    feed = FeedRate(DT)
    assert feed.ramp(100, 0.0, 0.2)
    assert feed.start == 100 and feed.ramp_end() == 300
    assert feed.at(100) == (0.0, 1.0, 0.0)
    lag, rate, rate_dot = feed.at(200)                       # the middle of the stop
    assert rate == pytest.approx(0.5, abs=1e-15)
    assert rate_dot == pytest.approx(-PEAK_RATE / 0.2, rel=1e-12)
    # 0.1 s went by, the plan gained T (u - S-area(u)) = 0.2 (0.5 - 0.078125) s of it
    assert lag == pytest.approx((0.1 - 0.2 * (0.5 - 0.078125)) / DT, abs=1e-9) == 15.625
    assert feed.at(300) == (pytest.approx(100.0, abs=1e-9), 0.0, 0.0)
    assert feed.at(1300)[0] == pytest.approx(1100.0, abs=1e-9)
    assert feed.ramp(1300, 1.0, 0.4)
    assert feed.ramp_end() == 1700
    lag, rate, rate_dot = feed.at(1700)
    assert (rate, rate_dot) == (1.0, 0.0)
    assert lag * DT == pytest.approx(lateness(0.2, 1.0, 0.4), abs=1e-12) == 1.3
    assert feed.at(5000)[0] == pytest.approx(1300.0, abs=1e-9)   # stays late by as much


def test_a_resume_during_a_stop_ramps_from_the_rate_reached_and_its_slope_stays_bounded():
    feed = FeedRate(DT)
    feed.ramp(0, 0.0, 0.2)
    lag_mid, rate_mid, _ = feed.at(100)                      # r = 0.5 half way
    feed.ramp(100, 1.0, 0.2)                                 # back up: 0.5 of a full ramp
    assert feed.ramp_end() == 200
    rates = [feed.at(k) for k in range(100, 260)]
    assert rates[0][:2] == (lag_mid, rate_mid)               # continuous in lag and rate
    assert all(abs(rd) <= PEAK_RATE / 0.2 + 1e-12 for _, _, rd in rates)
    assert rates[-1][1:] == (1.0, 0.0)
    # lost: 0.1 s of the stop gained 0.2 (1/2 - S-area(1/2)) = 0.2 (0.5 - 0.078125) s of
    # plan time; the half resume, 0.1 s long, gained 0.1 (0.5 + 0.5 / 2) = 0.075 s
    assert rates[-1][0] * DT == pytest.approx((0.1 - 0.2 * (0.5 - 0.078125)) + (0.1 - 0.075),
                                              abs=1e-12)


def test_a_ramp_refuses_a_rate_outside_0_1_a_zero_time_and_a_tick_before_the_running_one():
    feed = FeedRate(DT)
    with pytest.raises(FreejointValueError, match='target'):
        feed.ramp(0, 1.5, 0.2)
    with pytest.raises(FreejointValueError, match='full_time'):
        feed.ramp(0, 0.0, 0.0)
    feed.ramp(50, 0.0, 0.2)
    with pytest.raises(FreejointValueError, match='before the running ramp'):
        feed.ramp(49, 1.0, 0.2)
    with pytest.raises(FreejointValueError, match='dt'):
        FeedRate(float('nan'))


def test_the_ramp_time_keeps_the_tangential_deceleration_within_the_bound():
    # the paper's circle peaks at 0.471 m/s: at 5 m/s^2 a stop needs 1.875 * 0.471 / 5 s
    speed = circle_peaks(CircleQuintic())[0]
    assert ramp_time(0.1, speed, 5.0) == pytest.approx(PEAK_RATE * speed / 5.0)
    assert ramp_time(0.5, speed, 5.0) == 0.5


def test_scaled_sample_is_the_chain_rule_of_the_plan_at_its_own_time():
    sample = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)          # p, v, a (m = 2)
    assert scale_sample(sample, 1.0, 0.0) == sample
    assert scale_sample(sample, 0.0, 0.0) == (1.0, 2.0, 0.0, 0.0, 0.0, 0.0)
    assert scale_sample(sample, 0.5, -2.0) == (1.0, 2.0, 1.5, 2.0, 0.25 * 5 - 2 * 3,
                                               0.25 * 6 - 2 * 4)
    assert len(scale_sample(tuple(range(9)), 0.5, 0.0)) == 9     # spatial: m = 3


def _held_circle(stop_at, stop_time, resume_at, start_time, ticks):
    """Return the paper's circle per tick through a feed stopped and resumed."""
    circle = CircleQuintic()
    feed = FeedRate(DT)
    out = []
    for k in range(ticks):
        if k == stop_at:
            feed.ramp(k, 0.0, stop_time)
        if k == resume_at:
            feed.ramp(k, 1.0, start_time)
        lag, rate, rate_dot = feed.at(k)
        out.append(scale_sample(circle.sample_tuple((k - lag) * DT), rate, rate_dot)
                   + ((k - lag) * DT,))
    return circle, np.array(out)


def test_a_circle_held_at_1_5_s_stops_along_the_path_waits_resumes_and_ends_late():
    stop_time, start_time = 0.2, 0.5
    circle, s = _held_circle(1500, stop_time, 2700, start_time, 7500)
    p, v, a, tau = s[:, 0:2], s[:, 2:4], s[:, 4:6], s[:, 6]
    speed, acc = circle_peaks(circle)
    # on the circle, always: radius 0.2 about the base
    assert np.max(np.abs(np.hypot(p[:, 0], p[:, 1]) - 0.2)) < 1e-12
    # no step: a tick's move is never more than the circle's own at full feed
    steps = np.hypot(*np.diff(p, axis=0).T)
    assert np.max(steps) <= speed * DT * (1 + 1e-6)
    # the velocity is the derivative of the position (central differences, O(dt^2))
    fd = (p[2:] - p[:-2]) / (2 * DT)
    assert np.max(np.abs(fd - v[1:-1])) < 2e-5
    # bounded deceleration: |dv/dt| <= the circle's peak + the ramp's 1.875 v / T
    dv = np.hypot(*np.diff(v, axis=0).T) / DT
    assert np.max(dv) <= acc + PEAK_RATE * speed / stop_time + 1e-6
    # stopped from the end of the ramp (tick 1700) to the resume (2700): still, at rest
    still = slice(1700, 2701)
    assert np.all(p[still] == p[1700]) and np.all(v[still] == 0.0) and np.all(a[still] == 0)
    # the plan's time stood at 1.5 + T_stop / 2 meanwhile
    assert tau[2000] == pytest.approx(1.5 + stop_time / 2, abs=1e-12)
    # resumed on the path, then ends late by T_stop / 2 + pause + T_start / 2
    late = lateness(stop_time, 1.0, start_time)
    assert late == pytest.approx(1.35)
    end = int(np.argmax(tau > circle.duration))
    assert end * DT == pytest.approx(circle.duration + late, abs=1.5 * DT)
    assert np.allclose(p[end], circle.sample(5.0)[0], atol=1e-12)


def test_a_repeated_circle_between_ticks_is_the_circle_at_that_time():
    circle = CircleQuintic(duration=2.0)
    series = RepeatedCircle(circle, 2, 0.5, DT)
    assert series.sample_tuple(0.7) == circle.sample_tuple(700 * DT)         # on the grid
    assert series.sample_tuple(0.7004) == circle.sample_tuple(0.7004)        # between ticks
    assert series.sample_tuple(2.5004) == pytest.approx(circle.sample_tuple(0.0004),
                                                        abs=1e-12)
    assert series.sample_tuple(2.2004) == series.sample_tuple(2.2)            # at rest
    assert series.sample_tuple(4.6004)[2:] == (0.0, 0.0, 0.0, 0.0)            # held at the end
    assert math.isclose(series.sample_tuple(4.6004)[0], 0.2)


def test_a_standing_plan_moved_back_lags_by_those_ticks_more_and_still_stands():
    dt = 0.001
    feed = FeedRate(dt)
    feed.ramp(100, 0.0, 0.2)                     # stands from tick 300: lag 100 there
    assert feed.at(300)[0] == pytest.approx(100.0, abs=1e-9)
    feed.rewind(310, 42)
    lag, rate, rate_dot = feed.at(310)
    assert lag == pytest.approx(110.0 + 42.0, abs=1e-9) and (rate, rate_dot) == (0.0, 0.0)
    assert feed.at(400)[0] == pytest.approx(200.0 + 42.0, abs=1e-9)
    feed.ramp(400, 1.0, 0.5)                     # resumes from there: half its ramp more
    assert feed.at(900 + 100)[0] == pytest.approx(242.0 + 250.0, abs=1e-9)


def test_a_plan_is_moved_back_only_while_it_stands():
    feed = FeedRate(0.001)
    with pytest.raises(FreejointValueError, match='^k: the plan does not stand'):
        feed.rewind(10, 5)                       # steady: rate 1
    feed.ramp(100, 0.0, 0.2)
    with pytest.raises(FreejointValueError, match='^k: the plan does not stand'):
        feed.rewind(200, 5)                      # still ramping down
    with pytest.raises(FreejointValueError, match='^ticks'):
        feed.rewind(300, -1)
    with pytest.raises(FreejointValueError, match='^k: tick 50 is before'):
        feed.rewind(50, 1)
