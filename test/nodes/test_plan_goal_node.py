"""
The planner's plan as a goal, in its own process: readiness, feed hold, the action.

The test plays the lockstep simulator's ``/clock`` (every 10 ms, lookahead 20) and the
controller's ``controller_readiness`` (latched), and is the ``follow_circle`` client.
The planner runs in sim time with ``readiness: required`` (not heard = not ready, as in
real time), ``feed_hold_time`` 0.2 s and ``feed_resume_time`` 0.5 s (above the 0.177 s the
paper's circle needs at 5 m/s^2: the ramps last exactly these).
"""
import math
import os

from freejoint_core.feed_hold import lateness
from freejoint_tools.harness import load_source
import pytest

pytestmark = pytest.mark.ros

MS = 1_000_000
STOP, START = 0.2, 0.5
ARGS = ('-p', 'use_sim_time:=true', '-p', 'autostart:=false', '-p', 'readiness:=required',
        '-p', 'feed_hold_time:=%g' % STOP, '-p', 'feed_resume_time:=%g' % START)


def _helpers():
    """Return test_planner_node.py (its ClockDriver and service helpers)."""
    return load_source(os.path.join(os.path.dirname(__file__), 'test_planner_node.py'),
                       'planner_node_test_helpers')


class Rig:
    """The planner, /clock, readiness, plan_outcome and the follow_circle client."""

    def __init__(self, procs, ros_node, wait, *args):
        from freejoint_common.contract import CONTROLLER_READINESS, FOLLOW_CIRCLE, PLAN_OUTCOME
        from rclpy.action import ActionClient
        self.h = _helpers()
        self.procs, self.node, self.wait = procs, ros_node, wait
        self.proc = self.h._start_planner(procs, ARGS + args)
        self.client = self.h._wait_ready(ros_node, procs, self.proc, wait)
        self.clock = self.h.ClockDriver(ros_node)
        self.readiness = ros_node.create_publisher(
            CONTROLLER_READINESS.msg_type, CONTROLLER_READINESS.name, CONTROLLER_READINESS.qos)
        self.outcomes = []
        ros_node.create_subscription(PLAN_OUTCOME.msg_type, PLAN_OUTCOME.name,
                                     self.outcomes.append, PLAN_OUTCOME.qos)
        self.action = ActionClient(ros_node, FOLLOW_CIRCLE.action_type,
                                   FOLLOW_CIRCLE.of('freejoint_planner'))
        self.feedback = []
        self.now = 0
        wait(lambda: self.clock.matched() and self.action.server_is_ready(), 30.0,
             'the planner matching /clock, setpoints and its action server',
             spin=self.spin)

    def spin(self, seconds=0.02):
        self.h._spin(self.node, seconds)

    def log(self):
        return self.procs.log(self.proc)

    def say(self, ready, reason=''):
        """Publish controller_readiness; wait until the planner logged taking it."""
        from freejoint_common.contract import CONTROLLER_READINESS
        line = 'controller ready' if ready else 'controller not ready: %s' % reason
        before = self.log().count(line)
        self.readiness.publish(CONTROLLER_READINESS.msg_type(ready=ready, reason=reason))
        self.wait(lambda: self.log().count(line) > before, 30.0,
                  'the planner taking readiness %s (log: %s)' % (ready, self.log()),
                  spin=self.spin)

    def run_to(self, t):
        """Step /clock every 10 ms up to ``t`` s, each time waiting for its setpoints."""
        while self.now <= round(t * 1e9):
            self.clock.step(self.now, self.wait, '(log: %s)' % self.log(), beyond=False)
            self.now += 10 * MS

    def plan_circle(self, execute=True):
        from freejoint_msgs.srv import PlanCircle
        request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.2, duration=5.0,
                                     start_angle=0.0, direction=1, execute=execute)
        return self.h._call(self.node, self.client, request, 'plan_circle', timeout=30.0)

    def send(self, **fields):
        """Send a follow_circle goal (the paper's circle); return its goal handle."""
        from freejoint_common.contract import FOLLOW_CIRCLE
        goal = FOLLOW_CIRCLE.action_type.Goal(centre=[0.0, 0.0], radius=0.2, duration=5.0,
                                              start_angle=0.0, direction=1, **fields)
        future = self.action.send_goal_async(goal, feedback_callback=self._on_feedback)
        self.wait(future.done, 30.0, 'the goal answered', spin=self.spin)
        handle = future.result()
        assert handle.accepted
        return handle

    def _on_feedback(self, msg):
        self.feedback.append(msg.feedback)

    def result(self, handle, until=None):
        """Return (status, outcome) of a goal, stepping /clock up to ``until`` s meanwhile."""
        future = handle.get_result_async()
        while not future.done() and until is not None and self.now <= until * 1e9:
            self.run_to(self.now * 1e-9 + 0.05)
            self.spin(0.0)
        self.wait(future.done, 30.0, 'the result (log: %s)' % self.log(), spin=self.spin)
        return future.result().status, future.result().result.outcome

    def positions(self):
        return [tuple(sp.position) for sp in self.clock.got]


def test_plans_are_refused_while_the_controller_is_not_ready_with_the_reason(
        procs, ros_node, wait):
    from action_msgs.msg import GoalStatus
    from freejoint_msgs.msg import PlanOutcome
    rig = Rig(procs, ros_node, wait)
    # nothing heard: no controller_readiness publisher yet ... (a check alone is answered)
    answer = rig.plan_circle()
    assert not answer.accepted and answer.plan_id == 0
    assert answer.reason.startswith('controller not ready: no controller_readiness'), \
        answer.reason
    assert rig.plan_circle(execute=False).accepted
    # ... or it says not ready
    rig.say(False, 'tripped: 118 of 160 states answered')
    answer = rig.plan_circle()
    assert not answer.accepted
    assert answer.reason == 'controller not ready: tripped: 118 of 160 states answered'
    status, outcome = rig.result(rig.send())
    assert status == GoalStatus.STATUS_ABORTED
    assert (outcome.code, outcome.code_name, outcome.plan_id) == (
        PlanOutcome.CONTROLLER_NOT_READY, 'CONTROLLER_NOT_READY', 0)
    assert outcome.message == answer.reason
    for now in range(0, 100 * MS, 10 * MS):
        rig.clock.publish(now)
        rig.spin(0.02)
    assert rig.clock.got == [], 'a refused plan streamed'
    # every refused request to execute one is on plan_outcome, latched
    wait(lambda: len(rig.outcomes) >= 3, 30.0, 'the outcomes', spin=rig.spin)
    assert [o.code for o in rig.outcomes] == [PlanOutcome.CONTROLLER_NOT_READY] * 3
    # a bad goal: INVALID_GOAL with the reason
    rig.say(True)
    status, outcome = rig.result(rig.send(max_pause=math.nan))
    assert (status, outcome.code) == (GoalStatus.STATUS_ABORTED, PlanOutcome.INVALID_GOAL)
    assert 'max_pause: expected a finite number' in outcome.message
    answer = rig.plan_circle()
    assert answer.accepted and answer.plan_id == 1, answer.reason
    assert procs.stop(rig.proc) == 0


def test_a_goal_pauses_along_the_path_while_not_ready_resumes_and_succeeds_late(
        procs, ros_node, wait):
    from action_msgs.msg import GoalStatus
    from freejoint_msgs.msg import PlanOutcome
    rig = Rig(procs, ros_node, wait)
    rig.say(True)
    handle = rig.send()
    rig.run_to(1.5)
    rig.say(False, 'tripped')
    rig.run_to(3.0)                     # not ready from the trigger at 1.51 s
    held = rig.positions()
    rig.say(True)
    status, outcome = rig.result(handle, until=10.0)     # ready from the trigger at 3.01 s
    assert status == GoalStatus.STATUS_SUCCEEDED, outcome.message
    assert (outcome.code, outcome.code_name, outcome.pauses) == (
        PlanOutcome.SUCCEEDED, 'SUCCEEDED', 1)
    # the ramps start 11 ticks after their triggers (the first unpublished tick), 1.5 s
    # apart: stopped for 1.5 - 0.2 s between them
    assert outcome.lateness == pytest.approx(lateness(STOP, 1.5 - STOP, START), abs=1e-9)
    assert outcome.time_paused == pytest.approx(1.5, abs=1e-9)
    # the plan stood still (ticks 1.72 .. 3.02 s) on the circle, and never stepped
    stamps = [sp.stamp_ns for sp in rig.clock.got]
    still = held[stamps.index(1_721 * MS):stamps.index(3_020 * MS) + 1]
    assert len(set(still)) == 1 and abs(math.hypot(*still[0]) - 0.2) < 1e-12
    steps = [math.dist(a, b) for a, b in zip(rig.positions(), rig.positions()[1:])]
    assert max(steps) <= 2 * math.pi * 0.2 * 1.875 / 5.0 * 0.001 * (1 + 1e-6)
    # feedback said so meanwhile
    paused = [f for f in rig.feedback if f.paused]
    assert paused and all(f.state == 'paused: tripped' for f in paused)
    assert {f.plan_id for f in rig.feedback} == {1}
    # the last feedback, sent as the goal ends, says where the plan ended
    rig.wait(lambda: rig.feedback[-1].progress == pytest.approx(1.0, abs=0.05), 30.0,
             'the last feedback (log: %s)' % rig.log(), spin=rig.spin)
    assert procs.stop(rig.proc) == 0


def test_goals_end_preempted_cancelled_and_paused_too_long(procs, ros_node, wait):
    from action_msgs.msg import GoalStatus
    from freejoint_msgs.msg import PlanOutcome
    rig = Rig(procs, ros_node, wait)
    rig.say(True)
    first = rig.send()
    rig.run_to(1.0)
    second = rig.send()                 # replaces the first, by a transition
    status, outcome = rig.result(first)
    assert (status, outcome.code, outcome.message) == (
        GoalStatus.STATUS_ABORTED, PlanOutcome.PREEMPTED, 'replaced by plan 2')
    rig.run_to(2.0)
    cancel = second.cancel_goal_async()
    wait(cancel.done, 30.0, 'the cancel answered', spin=rig.spin)
    assert len(cancel.result().goals_canceling) == 1
    status, outcome = rig.result(second, until=4.0)
    assert (status, outcome.code) == (GoalStatus.STATUS_CANCELED, PlanOutcome.CANCELLED)
    rig.run_to(rig.now * 1e-9 + 0.3)
    tail = rig.positions()[-100:]
    assert len(set(tail)) == 1          # stopped along the path, held there
    third = rig.send(max_pause=0.3)
    rig.run_to(rig.now * 1e-9 + 0.5)
    rig.say(False, 'stopped')
    status, outcome = rig.result(third, until=rig.now * 1e-9 + 2.0)
    assert (status, outcome.code) == (GoalStatus.STATUS_ABORTED, PlanOutcome.PAUSED_TOO_LONG)
    assert outcome.message.startswith('paused 0.3 s (max_pause) for a controller not ready: '
                                      'stopped'), outcome.message
    assert outcome.time_paused == pytest.approx(0.31, abs=1e-9)   # the trigger after 0.3 s
    wait(lambda: len(rig.outcomes) >= 3, 30.0, 'the outcomes', spin=rig.spin)
    assert [(o.plan_id, o.code_name) for o in rig.outcomes] == [
        (1, 'PREEMPTED'), (2, 'CANCELLED'), (3, 'PAUSED_TOO_LONG')]
    assert procs.stop(rig.proc) == 0


def test_in_real_time_a_goal_paused_for_a_second_ends_late_by_the_pause_and_its_ramps(
        procs, ros_node, wait):
    # the planner on the system clock (readiness auto: a controller not heard is not ready)
    import time
    from action_msgs.msg import GoalStatus
    from freejoint_common.contract import CONTROLLER_READINESS, FOLLOW_CIRCLE
    from freejoint_msgs.msg import PlanOutcome
    from rclpy.action import ActionClient
    h = _helpers()
    proc = h._start_planner(procs, ('-p', 'use_sim_time:=false', '-p', 'autostart:=false',
                                    '-p', 'feed_hold_time:=%g' % STOP,
                                    '-p', 'feed_resume_time:=%g' % START))
    h._wait_ready(ros_node, procs, proc, wait)
    readiness = ros_node.create_publisher(CONTROLLER_READINESS.msg_type,
                                          CONTROLLER_READINESS.name, CONTROLLER_READINESS.qos)
    action = ActionClient(ros_node, FOLLOW_CIRCLE.action_type,
                          FOLLOW_CIRCLE.of('freejoint_planner'))

    def spin():
        h._spin(ros_node, 0.02)
    wait(action.server_is_ready, 30.0, 'the action server', spin=spin)
    readiness.publish(CONTROLLER_READINESS.msg_type(ready=True))
    wait(lambda: 'controller ready' in procs.log(proc), 30.0, 'readiness taken', spin=spin)
    # a 1.5-s circle of radius 0.05 m (peak 0.39 m/s: its stop ramp is the 0.2 s set)
    goal = FOLLOW_CIRCLE.action_type.Goal(centre=[0.0, 0.0], radius=0.05, duration=1.5,
                                          start_angle=0.0, direction=1)
    sent = action.send_goal_async(goal)
    wait(sent.done, 30.0, 'the goal answered', spin=spin)
    result = sent.result().get_result_async()
    # no joint_states: it starts at its start point (after waiting for a publisher)
    wait(lambda: 'plan 1 starts at its start point' in procs.log(proc), 30.0,
         'the plan started', spin=spin)
    start = time.monotonic()
    wait(lambda: time.monotonic() - start > 0.3, 5.0, '0.3 s', spin=spin)
    readiness.publish(CONTROLLER_READINESS.msg_type(ready=False, reason='tripped'))
    wait(lambda: 'plan 1 paused' in procs.log(proc), 30.0, 'the pause', spin=spin)
    paused = time.monotonic()
    wait(lambda: time.monotonic() - paused > 1.0, 5.0, '1 s paused', spin=spin)
    assert not result.done(), 'the plan ran on while the controller was not ready'
    readiness.publish(CONTROLLER_READINESS.msg_type(ready=True))
    wait(result.done, 30.0, 'the result (log: %s)' % procs.log(proc), spin=spin)
    status, outcome = result.result().status, result.result().result.outcome
    assert (status, outcome.code, outcome.pauses) == (
        GoalStatus.STATUS_SUCCEEDED, PlanOutcome.SUCCEEDED, 1), outcome.message
    assert outcome.time_paused >= 1.0
    # late by the time paused, less half the stop ramp, plus half the resume ramp: each
    # ramp starts on the first unpublished tick after the trigger that saw the change, so
    # the two triggers' delays (a stall of the loaded machine) shift it; 0.25 s allowed
    expected = outcome.time_paused - STOP / 2 + START / 2
    assert abs(outcome.lateness - expected) < 0.25, (outcome.lateness, expected)
    assert outcome.elapsed == pytest.approx(1.5 + outcome.lateness, abs=0.1)
    assert procs.stop(proc) == 0
