"""A plan as a goal: feed hold on a not-ready controller, tolerances and outcome codes."""
import math

from freejoint_core.feed_hold import lateness
from freejoint_core.trajectory import circle_peaks, CircleQuintic
from freejoint_planner.plan_goal import CANCELLED, circle_peak_speed, GOAL_TOLERANCE_VIOLATED
from freejoint_planner.plan_goal import Limits, PATH_TOLERANCE_VIOLATED, PAUSED_TOO_LONG
from freejoint_planner.plan_goal import PlanMonitor, position_of, PREEMPTED, SUCCEEDED
from freejoint_planner.stream import Plan, SetpointStream
import pytest

MS = 1_000_000
STOP, START = 0.2, 0.5          # above 1.875 * 0.471 / 5 = 0.177 s: the times are these
LIMITS = Limits(path=0.05, goal=None, goal_time=1.0, max_pause=5.0)


class Run:
    """The stream triggered every 10 ms as the real-time planner does, and its monitor."""

    def __init__(self, limits=LIMITS):
        self.stream = SetpointStream(0.001, 20)
        self.circle = CircleQuintic()
        self.stream.start(Plan(1, self.circle))
        self.limits = limits
        self.monitor = None
        self.out = {}           # stamp -> setpoint
        self.now = 0

    def step(self, ready=True, reason='', ee=None):
        """Advance 10 ms; ``ee``: the end effector at now (None: on the setpoint)."""
        if self.monitor is None:
            speed = circle_peaks(self.circle)[0]
            self.monitor = PlanMonitor(self.stream, self.limits, STOP, START, speed, 5.0)
        outcome = self.monitor.update(self.now, ready, reason)
        due = self.stream.advance(self.now)
        self.monitor.published(due)
        self.out.update((sp.stamp_ns, sp) for sp in due)
        at = self.out[self.now]
        self.monitor.measure(self.now, position_of(at) if ee is None else ee)
        outcome = self.monitor.outcome
        self.now += 10 * MS
        return outcome

    def until(self, t, **kw):
        """Step until ``t`` [s] or an outcome; return it (None: none yet)."""
        outcome = None
        while self.now < t * 1e9 and outcome is None:
            outcome = self.step(**kw)
        return outcome

    def run_to(self, t, **kw):
        """Step until ``t`` [s] whatever the outcome."""
        while self.now < t * 1e9:
            self.step(**kw)

    def positions(self):
        return [position_of(self.out[k]) for k in sorted(self.out)]


def test_a_plan_always_ready_succeeds_at_its_end_on_time_never_paused():
    run = Run()
    outcome = run.until(6.0)
    assert outcome is not None and outcome.code == SUCCEEDED and outcome.code_name == 'SUCCEEDED'
    assert outcome.pauses == 0 and outcome.time_paused == 0.0
    assert outcome.lateness == 0.0 and run.stream.plan.feed.steady
    # ended at the trigger whose setpoint is the end point: t = 5.00 s
    assert outcome.stamp_ns == 5000 * MS and outcome.elapsed == pytest.approx(5.0)
    assert outcome.max_path_error == 0.0


def test_not_ready_at_1_s_pauses_along_the_path_resumes_and_ends_late_by_the_pause():
    run = Run()
    assert run.until(1.0) is None
    assert run.until(2.0, ready=False, reason='tripped: 74 % answered') is None
    mon = run.monitor
    assert mon.paused and mon.pauses == 1
    status = mon.status(run.now - 10 * MS)
    assert status['paused'] and status['state'] == 'paused: tripped: 74 % answered'
    assert status['feed_rate'] == 0.0
    outcome = run.until(9.0)
    assert outcome.code == SUCCEEDED
    # not ready from the trigger at 1.00 s to the one at 2.00 s; the ramps start on the
    # first unpublished tick (20 ticks ahead): late by T_stop / 2 + 1 s + T_start / 2
    assert outcome.time_paused == pytest.approx(1.0, abs=1e-9)
    assert outcome.lateness == pytest.approx(lateness(STOP, 1.0 - STOP, START), abs=1e-9)
    assert outcome.stamp_ns * 1e-9 == pytest.approx(5.0 + outcome.lateness, abs=0.011)
    # on the circle, no step beyond the circle's own at full feed
    p = run.positions()
    steps = [math.dist(a, b) for a, b in zip(p, p[1:])]
    assert max(steps) <= circle_peaks(run.circle)[0] * 0.001 * (1 + 1e-6)
    assert all(abs(math.hypot(*q) - 0.2) < 1e-12 for q in p)


def test_a_plan_paused_for_an_arm_braked_at_once_resumes_from_where_the_arm_stopped():
    # The arm stops on its last state before the trip (the trigger of 0.99 s: plan time
    # 0.990 s), braked; the stop ramp starts on the first unpublished tick (1.011 s: the
    # trigger of 0.99 s published 20 ahead), so the feed stands at plan time 1.011 +
    # STOP / 2 = 1.111 s. Once it stands it goes back 0.121 s to the arm and resumes
    # from there: late by the pause, its ramps and the 0.121 s.
    run = Run()
    assert run.until(1.0) is None
    arm = position_of(run.out[run.now - 10 * MS])
    assert run.until(2.0, ready=False, reason='tripped', ee=arm) is None
    mon = run.monitor
    assert mon.rewound[0] == pytest.approx(0.121, abs=1e-9)
    stood = position_of(run.out[run.now - 10 * MS])
    assert math.dist(stood, arm) < 1e-12
    assert mon.rewound[1] == pytest.approx(math.dist(
        arm, run.circle.sample_tuple(1.111)[:2]), abs=1e-12)
    run.step(ee=arm)
    assert 'nearest the arm' in mon.resume_note and mon.rewound is None
    outcome = run.until(9.0)
    assert outcome.code == SUCCEEDED and outcome.pauses == 1
    assert outcome.lateness == pytest.approx(lateness(STOP, 1.0 - STOP, START) + 0.121,
                                             abs=1e-9)
    # one step back along the circle, while the plan stood (velocity 0 both sides);
    # every other step within the circle's own at full feed
    keys = sorted(run.out)
    p = run.positions()
    fast = [i for i, (a, b) in enumerate(zip(p, p[1:]))
            if math.dist(a, b) > circle_peaks(run.circle)[0] * 0.001 * (1 + 1e-6)]
    assert len(fast) == 1
    before, after = run.out[keys[fast[0]]], run.out[keys[fast[0] + 1]]
    assert (before.vx, before.vy, after.vx, after.vy) == (0.0, 0.0, 0.0, 0.0)
    assert all(abs(math.hypot(*q) - 0.2) < 1e-12 for q in p)


def test_a_plan_paused_with_the_arm_on_its_setpoint_is_not_moved_back():
    run = Run()
    run.until(1.0)
    run.until(2.0, ready=False)
    assert run.monitor.rewound == (0.0, 0.0)


def test_a_plan_replaced_before_its_delayed_start_reports_no_time_elapsed():
    stream = SetpointStream(0.001, 20)
    stream.start(Plan(1, CircleQuintic(), start_delay_ns=3600 * 10 ** 9))
    mon = PlanMonitor(stream, LIMITS, STOP, START, 0.5, 5.0)
    mon.update(0, True)
    stream.advance(0)
    outcome = mon.preempt(2 * 10 ** 9, 2)
    assert outcome.code == PREEMPTED and outcome.elapsed == 0.0


def test_a_pause_longer_than_max_pause_aborts_and_the_plan_stays_stopped():
    run = Run(LIMITS._replace(max_pause=0.5))
    run.until(1.0)
    outcome = run.until(3.0, ready=False, reason='no controller_readiness')
    assert outcome.code == PAUSED_TOO_LONG and 'max_pause' in outcome.message
    assert 'no controller_readiness' in outcome.message
    assert outcome.time_paused == pytest.approx(0.51, abs=1e-9)   # first trigger beyond 0.5 s
    stopped = run.positions()[-1]
    run.run_to(5.0, ready=True)                # ready again: an aborted plan stays stopped
    assert run.positions()[-1] == stopped
    assert run.monitor.outcome is outcome


def test_the_end_effector_off_the_path_at_full_feed_aborts_and_stops_along_the_path():
    run = Run()
    run.until(1.0)
    outcome = run.step(ee=(0.0, 0.0))          # 0.2 m from the circle's setpoint
    assert outcome.code == PATH_TOLERANCE_VIOLATED and '200.00 mm' in outcome.message
    assert run.stream.plan.feed.target == 0.0  # stopping along the path
    run.run_to(2.0)
    p = run.positions()
    assert p[-1] == p[-100]


def test_no_path_check_while_paused_nor_until_the_resume_settled():
    # braked: the arm stands while the plan decelerates; back, the controller blends
    run = Run()
    run.until(1.0)
    braked = position_of(run.out[run.now])
    run.until(1.5, ready=False, ee=braked)
    # ready at the trigger of 1.50 s: the resume ramp starts on the first unpublished
    # tick, 1.49 + 0.02 + 0.001 = 1.511 s, ends 0.5 s later, and the check waits as long
    # again: from 2.511 s, the trigger of 2.52 s
    outcome = run.until(2.51, ee=braked)
    assert outcome is None, outcome and outcome.line()
    assert run.step(ee=braked) is None         # 2.51 s: not checked yet ...
    assert run.step(ee=braked).code == PATH_TOLERANCE_VIOLATED   # ... 2.52 s is


def test_an_arm_that_leaves_the_path_while_the_plan_is_paused_aborts_it():
    # Paused with the arm braked 30 mm outside the circle (radially, where it stopped):
    # within path_tolerance of the path, the plan waits. The arm then falls to the base,
    # 0.2 m from every point of the circle: PATH_TOLERANCE_VIOLATED while paused, and the
    # plan stays stopped (not SUCCEEDED after a resume, the fall unseen).
    run = Run()
    run.until(1.0)
    x, y = position_of(run.out[run.now - 10 * MS])
    out = (x * 0.23 / 0.2, y * 0.23 / 0.2)
    assert run.until(1.5, ready=False, reason='tripped', ee=out) is None
    assert run.monitor.paused
    outcome = run.step(ready=False, reason='tripped', ee=(0.0, 0.0))
    assert outcome.code == PATH_TOLERANCE_VIOLATED
    assert 'paused (tripped)' in outcome.message and '200.00 mm' in outcome.message
    assert outcome.max_path_error == pytest.approx(0.2, abs=1e-9)
    stood = run.positions()[-1]
    run.run_to(3.0, ready=True)                 # ready again: an aborted plan stays stopped
    assert run.positions()[-1] == stood
    assert run.monitor.outcome is outcome


def test_a_paused_arm_behind_the_stop_ramp_is_measured_against_the_path_behind_it():
    # The feed stands 0.1 s of plan time ahead of where the arm was braked (its ramp),
    # up to about 47 mm ahead along the circle; before the rewind the arm is that far from
    # the standing setpoint but on the path: nothing trips, and without a rewind (the arm's
    # position not yet measured after the ramp) the same holds.
    run = Run(LIMITS._replace(path=0.02))
    run.until(1.0)
    braked = position_of(run.out[run.now - 10 * MS])
    for _ in range(15):
        assert run.step(ready=False, ee=braked) is None
        assert run.monitor._off_path(braked, 0.02) is None
    ahead = position_of(run.out[max(run.out)])
    assert math.dist(ahead, braked) > 0.02      # the standing setpoint is beyond 20 mm


def test_a_cancelled_plan_stops_along_the_path_then_ends_cancelled():
    run = Run()
    run.until(1.0)
    run.monitor.cancel(run.now)
    outcome = run.until(2.0)
    assert outcome.code == CANCELLED
    # decided once its feed stood still: the stop ramp (0.2 s) from the first unpublished
    # tick, at most 20 ticks ahead of the cancel
    assert 1.2 <= outcome.stamp_ns * 1e-9 <= 1.23
    assert run.stream.plan.feed.at(run.stream.next_tick)[1] == 0.0


def test_goal_tolerance_waits_for_the_arm_then_aborts_if_it_never_arrives():
    run = Run(LIMITS._replace(path=None, goal=0.001, goal_time=0.3))
    run.until(5.0)
    end = run.circle.sample_tuple(5.0)[:2]
    off = (end[0] + 0.002, end[1])
    outcome = run.until(6.0, ee=off)
    assert outcome.code == GOAL_TOLERANCE_VIOLATED and '2.00 mm' in outcome.message
    assert outcome.stamp_ns * 1e-9 == pytest.approx(5.0 + 0.31, abs=1e-9)
    good = Run(LIMITS._replace(path=None, goal=0.001, goal_time=0.3))
    good.until(5.0)
    assert good.until(6.0, ee=(end[0] + 0.0005, end[1])).code == SUCCEEDED


def test_a_configured_plan_the_controller_was_never_ready_for_waits_without_limit():
    run = Run(LIMITS._replace(max_pause=0.5))
    assert run.until(3.0, ready=False, reason='starting') is None
    assert run.monitor.pauses == 0 and run.monitor.time_paused == 0.0
    assert run.monitor.status(run.now - 10 * MS)['state'].startswith(
        'waiting for the controller: starting')
    p = run.positions()
    assert all(q == p[0] for q in p)           # at its start: the feed stood from its start
    assert run.until(10.0).code == SUCCEEDED


def test_a_newer_plan_preempts_the_running_one():
    run = Run()
    run.until(1.0)
    outcome = run.monitor.preempt(run.now, 2)
    assert outcome.code == PREEMPTED and outcome.message == 'replaced by plan 2'
    assert run.monitor.update(run.now + MS, True) is outcome


def test_the_peak_speed_of_a_quintic_revolution_is_2_pi_r_1_875_over_t():
    assert circle_peak_speed(0.2, 5.0) == pytest.approx(circle_peaks(CircleQuintic())[0],
                                                        rel=1e-6)
