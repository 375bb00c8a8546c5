"""The control-grid arithmetic and the setpoint stream, by hand-derived ticks and stamps."""
from freejoint_core.trajectory import CircleQuintic
from freejoint_planner.stream import ceil_div, first_tick_at_or_after, last_tick_due
from freejoint_planner.stream import period_ns, Plan, SetpointStream
import pytest

MS = 1_000_000  # ns


def test_period_is_rounded_to_whole_nanoseconds():
    assert period_ns(0.001) == MS
    assert period_ns(0.0025) == 2_500_000
    assert period_ns(2e-9) == 2


@pytest.mark.parametrize('dt,match', [(0.0, 'expected > 0'), (-0.001, 'expected > 0'),
                                      (1.5e-9, 'whole number of nanoseconds'),
                                      (1e-10, 'whole number of nanoseconds')])
def test_period_that_is_not_whole_nanoseconds_is_refused(dt, match):
    with pytest.raises(ValueError, match=match):
        period_ns(dt)


def test_integer_ceil_division_rounds_up_for_both_signs():
    assert ceil_div(7, 2) == 4
    assert ceil_div(6, 2) == 3
    assert ceil_div(-7, 2) == -3
    assert ceil_div(10**30 + 1, 10**9) == 10**21 + 1


def test_first_tick_at_or_after_and_last_tick_due_on_and_off_the_grid():
    assert first_tick_at_or_after(0, MS) == 0
    assert first_tick_at_or_after(3 * MS, MS) == 3
    assert first_tick_at_or_after(2_500_000, MS) == 3
    assert last_tick_due(3 * MS, MS, 20) == 23
    assert last_tick_due(2_500_000, MS, 20) == 22
    assert last_tick_due(2_500_000, MS, 0) == 2


def _ticks(setpoints):
    return [sp.stamp_ns // MS for sp in setpoints]


def _stream(lookahead=20, skip_late=False):
    return SetpointStream(0.001, lookahead, skip_late=skip_late)


def test_nothing_streams_without_a_plan():
    s = _stream()
    assert s.advance(0) == []
    assert s.advance(5 * MS) == []


def test_each_tick_up_to_now_plus_lookahead_is_published_once_in_order():
    s = _stream()
    s.start(Plan(1, CircleQuintic()))
    assert _ticks(s.advance(0)) == list(range(0, 21))
    assert s.advance(0) == []                               # same time again: nothing new
    assert _ticks(s.advance(1 * MS)) == [21]
    assert _ticks(s.advance(5_500_000)) == [22, 23, 24, 25]   # 25.5 ms -> tick 25
    assert _ticks(s.advance(5_999_999)) == []
    assert _ticks(s.advance(6 * MS)) == [26]


def test_lookahead_zero_publishes_the_ticks_at_or_before_now():
    s = _stream(lookahead=0)
    s.start(Plan(1, CircleQuintic()))
    assert _ticks(s.advance(0)) == [0]
    assert _ticks(s.advance(2_500_000)) == [1, 2]


def test_setpoint_k_is_the_circle_sampled_at_k_dt_since_the_plan_start():
    circle = CircleQuintic(duration=0.0105)
    s = _stream(lookahead=0)
    s.start(Plan(3, circle))
    out = s.advance(0) + s.advance(7 * MS) + s.advance(12 * MS)
    assert _ticks(out) == list(range(13))
    for k, sp in enumerate(out):
        assert (sp.px, sp.py, sp.vx, sp.vy, sp.ax, sp.ay) == circle.sample_tuple(k * 0.001)
        assert sp.stamp_ns == k * MS
        assert sp.plan_id == 3
        assert sp.plan_time == (k * MS) * 1e-9
    # 10 ms <= 10.5 ms: still moving; 11 ms: the first tick past the duration
    assert [sp.final for sp in out] == [False] * 11 + [True, True]
    assert (out[12].vx, out[12].vy) == (0.0, 0.0)


def test_a_plan_accepted_later_starts_at_the_first_tick_at_or_after_now():
    circle = CircleQuintic()
    s = _stream()
    assert s.advance(7_300_000) == []
    s.start(Plan(1, circle))
    out = s.advance(7_300_000)
    assert _ticks(out) == list(range(8, 28))                # ceil(7.3) .. floor(27.3)
    assert out[0].plan_time == 0.0
    assert (out[0].px, out[0].py) == (0.2, 0.0)
    assert (out[1].px, out[1].py) == circle.sample_tuple(0.001)[:2]


def test_start_delay_holds_the_start_point_before_the_plan_time_zero():
    circle = CircleQuintic()
    s = _stream(lookahead=0)
    s.start(Plan(1, circle, start_delay_ns=10_500_000))      # -> tick ceil(10.5) = 11
    out = s.advance(0) + s.advance(12 * MS)
    assert out[0].plan_time == (-11 * MS) * 1e-9
    assert out[0].plan_time == pytest.approx(-0.011, rel=1e-15)
    assert (out[0].px, out[0].py, out[0].vx, out[0].vy) == (0.2, 0.0, -0.0, 0.0)
    assert out[11].plan_time == 0.0
    assert (out[12].px, out[12].py) == circle.sample_tuple(0.001)[:2]


def test_a_new_plan_starts_at_the_first_unpublished_tick():
    s = _stream()
    s.start(Plan(1, CircleQuintic()))
    first = s.advance(0)                                    # ticks 0 .. 20 of plan 1
    s.start(Plan(2, CircleQuintic(radius=0.1)))
    assert s.advance(0) == []
    nxt = s.advance(1 * MS)
    assert _ticks(first) == list(range(21)) and {sp.plan_id for sp in first} == {1}
    assert _ticks(nxt) == [21]
    assert (nxt[0].plan_id, nxt[0].plan_time, nxt[0].px) == (2, 0.0, 0.1)


def test_time_going_backwards_restarts_the_stream_and_the_plan():
    s = _stream(lookahead=2)
    s.start(Plan(1, CircleQuintic()))
    s.advance(0)
    s.advance(5 * MS)
    out = s.advance(1 * MS)
    assert s.restarts == 1
    assert _ticks(out) == [1, 2, 3]
    assert [sp.plan_time for sp in out] == [0.0, 0.001, 0.002]


def test_sim_time_never_skips_a_tick_but_real_time_skips_the_late_ones():
    sim = _stream()
    sim.start(Plan(1, CircleQuintic()))
    sim.advance(0)
    assert _ticks(sim.advance(100 * MS)) == list(range(21, 121))
    wall = _stream(skip_late=True)
    wall.start(Plan(1, CircleQuintic()))
    wall.advance(0)
    assert _ticks(wall.advance(100 * MS)) == list(range(100, 121))
    assert wall.skipped == 79


def test_negative_lookahead_is_refused():
    with pytest.raises(ValueError, match='lookahead'):
        SetpointStream(0.001, -1)


def _lockstep(stream, steps, every, lost=()):
    """
    Play the lockstep simulator and controller against ``stream``; return what they saw.

    The simulator publishes /clock on the steps that are multiples of ``every`` (minus the
    ``lost`` ones) and needs the setpoint of each step before it can go on (the controller
    answers a state only with its setpoint). Returns the setpoints in publication order and
    the step it stalled at (None if it got through ``steps``).
    """
    out = []
    have = set()
    for k in range(steps + 1):
        if k % every == 0 and k not in lost:
            for sp in stream.advance(k * MS):
                out.append(sp)
                have.add(sp.stamp_ns)
        if k * MS not in have:
            return out, k
    return out, None


@pytest.mark.parametrize('every,lookahead', [(1, 0), (10, 9), (10, 20), (20, 19), (7, 50)])
def test_a_sparse_clock_streams_every_tick_once_in_order_when_lookahead_covers_it(
        every, lookahead):
    s = _stream(lookahead)
    s.start(Plan(1, CircleQuintic()))
    out, stalled = _lockstep(s, 5000, every)
    assert stalled is None
    assert _ticks(out)[:5001] == list(range(5001))
    assert len(out) == len(set(_ticks(out)))
    # the same setpoints as a stream that sees /clock at every step
    dense = _stream(lookahead)
    dense.start(Plan(1, CircleQuintic()))
    ref = [sp for k in range(0, 5001 + lookahead, every) for sp in dense.advance(k * MS)]
    assert out == ref[:len(out)]
    assert (s.spacing, s.late) == (every, 0)


def test_lookahead_below_the_clock_spacing_minus_one_stalls_the_loop_and_counts_late_ticks():
    s = _stream(lookahead=8)
    s.start(Plan(1, CircleQuintic()))
    out, stalled = _lockstep(s, 100, 10)
    assert stalled == 9                          # ticks 0 .. 8 out at /clock 0, 9 missing
    assert s.late == 0                           # nothing late yet: the next /clock is due
    assert _ticks(s.advance(10 * MS)) == list(range(9, 19))   # tick 9 only now
    assert (s.spacing, s.late) == (10, 1)


def test_one_lost_clock_is_ridden_out_with_lookahead_twice_the_spacing_minus_one():
    for lookahead, stall in ((19, None), (18, 19)):
        s = _stream(lookahead)
        s.start(Plan(1, CircleQuintic()))
        out, stalled = _lockstep(s, 1000, 10, lost={10})
        assert stalled == stall, lookahead
        if stall is None:
            assert _ticks(out)[:1001] == list(range(1001)) and s.late == 0
            assert s.spacing == 20


def test_the_clock_spacing_is_learnt_from_the_triggers_and_forgotten_on_a_new_time_base():
    s = _stream()
    assert s.spacing == 0
    s.advance(0)
    s.advance(0)                                 # the sim republishing step 0
    assert s.spacing == 0
    s.advance(10 * MS)
    s.advance(15 * MS)
    assert s.spacing == 10
    s.advance(2 * MS)                            # backwards: a new time base
    assert (s.restarts, s.spacing) == (1, 0)


# ---- transitions: a new plan joins the stream without a step ----------------------------

def _planned(stream, circle, plan_id, model=None, max_duration=60.0):
    """Accept ``circle`` as the node does: prepare its transition, start the plan."""
    from freejoint_planner.planning import prepare_transition
    reason, choice, tick = prepare_transition(stream, circle, model or _NoRegion(),
                                              max_duration)
    if reason:
        return reason
    seg = None if choice is None else choice.segment
    stream.start(Plan(plan_id, circle, 0, transition=seg,
                      ticks=0 if seg is None else choice.ticks, transition_tick=tick))
    return choice


class _NoRegion:
    """A model whose region is empty: every path is clear."""

    @staticmethod
    def check_points(points):
        return True, 1.0, ''


def _steps(setpoints):
    import numpy as np
    p = np.array([(sp.px, sp.py) for sp in setpoints])
    return np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))


def test_the_first_plan_with_nothing_streamed_starts_as_always_without_a_transition():
    s = _stream()
    s.advance(0)                                 # the clock runs, nothing published yet
    assert s.pending() is None
    choice = _planned(s, CircleQuintic(radius=0.1), 1)
    assert choice is None
    out = s.advance(0)
    assert (out[0].plan_time, out[0].px, out[0].vx) == (0.0, 0.1, -0.0)


def test_a_plan_accepted_while_a_circle_runs_starts_from_the_first_unpublished_tick_state():
    from freejoint_core.trajectory import circle_max_tick_step
    old, new = CircleQuintic(), CircleQuintic(centre=(0.05, 0.05))
    s = _stream()
    s.start(Plan(1, old))
    out = [sp for k in range(0, 2501, 10) for sp in s.advance(k * MS)]   # ticks 0 .. 2520
    k, state = s.pending()
    assert k == 2521 and state == old.sample_tuple(2521 * 0.001)
    choice = _planned(s, new, 2)
    n = choice.ticks
    assert choice.ok and n > 0
    out2 = [sp for t in range(2510, 2530 + n + 200, 10) for sp in s.advance(t * MS)]
    assert _ticks(out2) == list(range(2521, 2521 + len(out2)))
    # tick 2521: exactly what plan 1 would have published (p, v, a), under plan 2's id
    first = out2[0]
    assert (first.px, first.py, first.vx, first.vy, first.ax, first.ay) == state
    assert (first.plan_id, first.final) == (2, False)
    # transition ticks: plan_time < 0 counting up to the circle's start at tick 2521 + n
    k0 = 2521 + n
    trans = out2[:n]
    assert [sp.plan_time for sp in trans] == [((k - k0) * MS) * 1e-9 for k in range(2521, k0)]
    circ = out2[n:]
    assert circ[0].plan_time == 0.0
    assert (circ[0].px, circ[0].py, circ[0].vx, circ[0].vy) == new.sample_tuple(0.0)[:4]
    assert (circ[1].px, circ[1].py) == new.sample_tuple(0.001)[:2]
    # no step: across both joints no two setpoints are farther apart than the circle's own
    assert _steps(out[-1:] + out2).max() <= circle_max_tick_step(new, 0.001)


def test_a_plan_during_a_transition_is_refused_and_after_it_accepted():
    s = _stream()
    s.start(Plan(1, CircleQuintic()))
    for k in range(0, 1001, 10):
        s.advance(k * MS)
    choice = _planned(s, CircleQuintic(centre=(0.0, 0.1)), 2)
    reason = _planned(s, CircleQuintic(centre=(0.1, 0.0)), 3)
    assert isinstance(reason, str)
    end = s.plan.transition_end()
    assert reason.startswith('the transition into plan 2 runs until t = %.3f s (ROS time, '
                             '%.3f s from the first unpublished setpoint)'
                             % (end * 1e-3, (end - 1021) * 1e-3)), reason
    for k in range(1010, end + 1, 10):
        s.advance(k * MS)
    assert s.in_transition(s.next_tick) is None
    assert _planned(s, CircleQuintic(centre=(0.1, 0.0)), 3).ok
    assert choice.ok


def test_a_held_end_point_away_from_the_new_start_gets_a_rest_to_rest_transition():
    import numpy as np
    s = _stream()
    short = CircleQuintic(duration=0.5)
    s.start(Plan(1, short))
    for k in range(0, 601, 10):
        s.advance(k * MS)                       # plan 1 ended: (0.2, 0) held, final
    _, state = s.pending()
    assert state == short.sample_tuple(0.5) and state[2:] == (-0.0, 0.0, -0.0, -0.0)
    choice = _planned(s, CircleQuintic(centre=(-0.1, 0.0), radius=0.1), 2)   # start (0, 0)
    assert choice.ok and choice.ticks > 0
    out = [sp for t in range(610, 610 + choice.ticks + 40, 10) for sp in s.advance(t * MS)]
    p = np.array([(sp.px, sp.py) for sp in out[:choice.ticks]])
    assert np.all(abs(p[:, 1]) <= 1e-16) and np.all(np.diff(p[:, 0]) <= 0.0)   # straight
    assert out[choice.ticks].plan_time == 0.0 and out[choice.ticks].px == 0.0


def test_a_held_start_point_away_from_the_new_start_gets_a_transition_too():
    s = _stream()
    s.start(Plan(1, CircleQuintic(), start_delay_ns=1_000 * MS))    # holds (0.2, 0) for 1 s
    s.advance(0)
    choice = _planned(s, CircleQuintic(radius=0.25), 2)
    assert choice.ok and choice.ticks > 0
    out = s.advance(30 * MS)
    assert (out[0].px, out[0].py, out[0].plan_id) == (0.2, 0.0, 2)


def test_a_new_time_base_drops_the_transition_and_restarts_the_circle():
    s = _stream()
    s.start(Plan(1, CircleQuintic()))
    s.advance(0)
    s.advance(500 * MS)
    _planned(s, CircleQuintic(radius=0.1), 2)
    s.advance(520 * MS)
    out = s.advance(1 * MS)                      # backwards: a reset simulator
    assert s.plan.transition is None and s.pending() is not None
    assert (out[0].plan_time, out[0].px, out[0].plan_id) == (0.0, 0.1, 2)


def test_a_transition_starting_faster_than_max_speed_is_refused_with_the_bound():
    from freejoint_planner.planning import prepare_transition
    s = _stream()
    s.start(Plan(1, CircleQuintic()))
    for k in range(0, 2501, 10):
        s.advance(k * MS)                            # 0.47 m/s at mid-circle
    reason, choice, _ = prepare_transition(s, CircleQuintic(centre=(0.05, 0.0)), _NoRegion(),
                                           60.0, bounds=(0.3, 5.0))
    assert reason.startswith('no safe transition from the current setpoint: the current '
                             'state (0.471172 m/s, 1.11004 m/s^2)'), reason
    assert 'is already above the limits (speed 0.3 m/s, acceleration 1.11033 m/s^2)' in reason
    assert choice.limits[:2] == (0.3, choice.limits[1])
    reason, choice, _ = prepare_transition(s, CircleQuintic(centre=(0.05, 0.0)), _NoRegion(),
                                           60.0, bounds=(1.0, 5.0))
    assert reason == '' and choice.peak_speed <= choice.limits[0] < 1.0


def test_a_plan_of_revolutions_with_rests_streams_the_series_and_is_final_after_the_last():
    from freejoint_core.trajectory import RepeatedCircle
    circle = CircleQuintic(duration=0.05)            # 50 ticks
    series = RepeatedCircle(circle, 2, 0.01, 0.001)  # 50 + 10 rest + 50: final after 110 ms
    s = _stream(lookahead=0)
    s.start(Plan(1, series))
    got = s.advance(0) + s.advance(120 * MS)
    assert _ticks(got) == list(range(0, 121))
    start = circle.sample_tuple(0.0)[:2]
    for sp in got:
        k = sp.stamp_ns // MS
        assert (sp.px, sp.py, sp.vx, sp.vy, sp.ax, sp.ay) == series.sample_tuple(k * 0.001)
        assert sp.final == (k * 0.001 > 0.11)
    assert (got[55].px, got[55].py) == start and got[55].vx == 0.0          # the rest
    assert (got[70].px, got[70].py) == circle.sample_tuple(0.01)[:2]        # revolution 2
    assert (got[115].px, got[115].py) == start                              # after the last
