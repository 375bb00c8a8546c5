"""
A plan from rest starts where the arm is, never with a step.

With nothing streamed yet (the first plan, a reset simulator) the plan starts at the arm's
end effector (the nominal model's kinematics of a joint state), not at the circle's start
point whatever the arm's position (a 0.45 m jump in one tick), and reaches the circle's
start by a transition from rest, held to the circle's own largest step per tick, or is
refused with the reason. In-process: synthetic joint states, no DDS.
"""
import math

from freejoint_core.trajectory import circle_max_tick_step, CircleQuintic
from freejoint_planner.planning import compute_model, end_effector, join_from_arm
from freejoint_planner.planning import JOIN_REFUSED, JOIN_START, JOIN_WAIT
from freejoint_planner.planning import prepare_transition, transition_from_rest
from freejoint_planner.stream import Plan, SetpointStream
import numpy as np
import pytest

MS = 1_000_000  # ns
DT = 0.001
JOINTS = ('joint1', 'joint2', 'joint3')
BOUNDS = (1.0, 5.0)          # the planner's default max_speed, max_acceleration
# The case of a far start: the arm at the simulator's default start (0.2, 0), a circle whose start
# is 0.45 m away: centre (-0.05, 0), radius 0.2, start angle pi -> start (-0.25, 0).
AWAY = CircleQuintic(centre=(-0.05, 0.0), radius=0.2, start_angle=math.pi)


@pytest.fixture(scope='module')
def model():
    # Table I (links 0.5 m) at 0.7: semi-singular beyond 0.4782 m from the base (1 deg)
    return compute_model('horizontal', 0.7, 1.0, 1e-7)


def _run(stream, start_ns, end_ns, step_ns=10 * MS, hold=False):
    return [sp for t in range(start_ns, end_ns, step_ns)
            for sp in stream.advance(t, hold=hold)]


def _steps(setpoints):
    p = np.array([(sp.px, sp.py) for sp in setpoints])
    return np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))


def test_the_end_effector_of_a_joint_state_is_the_nominal_models_kinematics(model):
    # links 0.5 m: q = (pi/2, -pi/2, 0) -> phi = (pi/2, 0, 0): x = 0 + 0.5 + 0.5, y = 0.5
    names = ['gripper', 'joint3', 'joint1', 'joint2']          # any order, extra joints
    xy = end_effector(model, JOINTS, names, [7.0, 0.0, math.pi / 2, -math.pi / 2])
    assert xy == pytest.approx((1.0, 0.5), abs=1e-15)
    assert end_effector(model, JOINTS, ['joint1', 'joint2'], [0.0, 0.0]) is None
    assert end_effector(model, JOINTS, list(JOINTS), [0.0, math.nan, 0.0]) is None


def test_a_plan_from_rest_045_m_away_steps_no_more_than_the_circle_and_ends_on_its_start(
        model):
    arm = (0.2, 0.0)
    start = AWAY.sample_tuple(0.0)[:2]
    assert math.dist(arm, start) == pytest.approx(0.45, abs=1e-12)
    s = SetpointStream(DT, 20)
    s.advance(0)                                           # the clock runs, no plan yet
    reason, choice, tick = prepare_transition(s, AWAY, model, 60.0, BOUNDS, arm=arm)
    assert reason == '' and choice.ok and choice.ticks > 0 and tick is None
    s.start(Plan(1, AWAY, transition=choice.segment, ticks=choice.ticks))
    n = choice.ticks
    out = _run(s, 10 * MS, (n + 5200) * MS)
    assert [sp.stamp_ns // MS for sp in out] == list(range(0, len(out)))
    # the first setpoint is where the arm is, at rest
    assert (out[0].px, out[0].py, out[0].vx, out[0].vy, out[0].ax, out[0].ay) == (
        0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    # the transition ends on the circle's start, at rest, where the circle begins
    assert (out[n].px, out[n].py) == start and out[n].plan_time == 0.0
    assert out[n - 1].plan_time < 0.0 and not out[n - 1].final
    assert max(abs(v) for v in (out[n].vx, out[n].vy, out[n].ax, out[n].ay)) < 1e-12
    # no step, ever: not larger than the circle's own largest step per tick
    largest = circle_max_tick_step(AWAY, DT)
    assert _steps(out).max() <= largest
    assert choice.max_step <= largest and choice.peak_speed <= 1.875 * 2 * math.pi * 0.2 / 5.0


def test_an_arm_on_the_circles_start_starts_it_at_once_as_before(model):
    circle = CircleQuintic()                               # start (0.2, 0)
    s = SetpointStream(DT, 20)
    s.advance(0)
    # the simulator's IK round-off of its start on the circle
    reason, choice, tick = prepare_transition(s, circle, model, 60.0, BOUNDS,
                                              arm=(0.2 + 4e-17, -5e-17))
    assert reason == '' and choice.segment is None and choice.ticks == 0 and tick is None
    s.start(Plan(1, circle))
    before = SetpointStream(DT, 20)
    before.advance(0)
    before.start(Plan(1, circle))
    assert _run(s, 0, 300 * MS) == _run(before, 0, 300 * MS)


def test_without_the_arms_position_the_plan_waits_for_it_while_a_state_is_expected(model):
    s = SetpointStream(DT, 20)
    plan = Plan(1, AWAY, joined=False)
    s.start(plan)
    action, text = join_from_arm(plan, s, model, None, 'waiting for the arm', 60.0, BOUNDS)
    assert (action, text) == (JOIN_WAIT, 'waiting for the arm') and not plan.joined
    assert s.advance(0, hold=True) == [] and s.advance(5 * MS, hold=True) == []
    # the state arrives: the transition starts from it, on the first unpublished tick (sim
    # time: tick 5, the one the lockstep controller waits for since the clock said 5 ms)
    action, text = join_from_arm(plan, s, model, (0.2, 0.0), None, 60.0, BOUNDS)
    assert action == JOIN_START and plan.joined
    assert text.startswith('transition of %d ticks from the arm at (0.2000, 0.0000) m' %
                           plan.transition_ticks)
    out = s.advance(10 * MS)
    assert out[0].stamp_ns == 5 * MS and (out[0].px, out[0].py) == (0.2, 0.0)
    assert plan.transition_tick == 5 and plan.start_tick == 5 + plan.transition_ticks


def test_with_no_joint_states_at_all_the_plan_starts_at_its_start_and_says_so(model):
    s = SetpointStream(DT, 20)
    plan = Plan(1, AWAY, joined=False)
    s.start(plan)
    action, text = join_from_arm(plan, s, model, None, None, 60.0, BOUNDS)
    assert action == JOIN_START and plan.transition is None
    assert "the arm's position is not known" in text and 'a step if the arm' in text
    assert (s.advance(0)[0].px, s.advance(0) == []) == (-0.25, True)


def test_a_transition_into_the_semi_singular_region_is_refused_naming_the_arms_position(
        model):
    # the arm 0.9 m out (semi-singular beyond 0.4782 m): no path back is clear
    reason, choice = transition_from_rest((0.9, 0.0), AWAY, model, DT, 60.0, BOUNDS)
    assert not choice.ok
    assert reason.startswith('no safe transition from the arm at (0.9000, 0.0000) m into '
                             "the circle's start (-0.2500, 0.0000) m: "), reason
    s = SetpointStream(DT, 20)
    plan = Plan(1, AWAY, joined=False)
    s.start(plan)
    assert join_from_arm(plan, s, model, (0.9, 0.0), None, 60.0, BOUNDS) == (
        JOIN_REFUSED, reason)


def test_after_time_went_back_the_running_plan_joins_from_rest_again(model):
    s = SetpointStream(DT, 20)
    s.advance(0)
    _, choice, _ = prepare_transition(s, AWAY, model, 60.0, BOUNDS, arm=(0.2, 0.0))
    s.start(Plan(1, AWAY, transition=choice.segment, ticks=choice.ticks))
    _run(s, 0, 3000 * MS)
    assert not s.fresh()
    assert s.advance(1 * MS, hold=True) == []              # a reset simulator
    plan = s.plan
    assert s.fresh() and not plan.joined and plan.transition is None
    # the reset arm is back at (0.1, 0.1): the plan starts from there, not with a step
    action, _ = join_from_arm(plan, s, model, (0.1, 0.1), None, 60.0, BOUNDS)
    assert action == JOIN_START
    out = _run(s, 1 * MS, 4000 * MS)
    assert (out[0].px, out[0].py) == (0.1, 0.1)
    assert _steps(out).max() <= circle_max_tick_step(AWAY, DT)


def test_the_usable_region_is_the_reach_without_the_semi_singular_annuli(model):
    assert model.usable() == 'usable: 0.0000 <= |p| <= 0.4782 m from the base'


def test_the_usable_region_of_several_annuli_names_each_of_them():
    from types import SimpleNamespace

    from freejoint_planner.planning import SingularityModel
    bands = np.array([[0.1, 0.2], [0.3, 0.4], [0.85, 0.9]])
    region = SimpleNamespace(reach=(0.05, 0.9), intervals=bands)
    m = SingularityModel('horizontal', 0.7, 1.0, 1e-7, None, region, 0.0)
    assert m.usable() == ('usable: 0.0500 <= |p| <= 0.1000 m or 0.2000 <= |p| <= 0.3000 m or '
                          '0.4000 <= |p| <= 0.8500 m from the base (a path must stay within '
                          'one of these annuli)')
    region.intervals = np.array([[0.0, 0.9]])
    assert m.usable() == 'usable: none (the semi-singular annuli cover the reach)'
