"""The arm the planner plans for after a joint failure, no ROS."""
from dataclasses import replace

from freejoint_core.arm import table1
from freejoint_core.failure import assess_passive_set, CANNOT_TRACK, TRACKING
from freejoint_core.offline import initial_state
from freejoint_core.trajectory import CircleQuintic
from freejoint_planner.planning import after_failure, ASSESS_HORIZON, compute_model
from freejoint_planner.planning import joint_state
import numpy as np
import pytest

NAMES = ['joint1', 'joint2', 'joint3']
CIRCLE = CircleQuintic()


def _start(case):
    """Return the paper's start state (end effector on the circle's start, joint 3 120 deg)."""
    return initial_state(table1(case), 120.0, CIRCLE.sample(0.0)[0]).tolist(), [0.0] * 3


def _fully_actuated(case):
    return replace(table1(case), passive=())


def test_a_joint_free_in_the_map_already_or_not_of_the_arm_changes_nothing():
    out = after_failure(table1('vertical'), NAMES, 'joint3', _start('vertical'))
    assert out.arm is None and out.refusal == '' and 'free in the arm the map is of' in out.note
    out = after_failure(table1('vertical'), NAMES, 'elbow', _start('vertical'))
    assert out.arm is None and out.refusal == ''
    assert out.note == "joint failure notice for 'elbow' ignored: not a joint of " \
        "['joint1', 'joint2', 'joint3']"


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_fewer_active_joints_than_the_task_has_refuse_every_plan(case):
    # The paper's arm (joint 3 free): joint 2 failing leaves joint 1 alone for x, y.
    out = after_failure(table1(case), NAMES, 'joint2', _start(case))
    assert out.arm is None
    assert out.refusal == ('joint2 failed: 1 active joint(s) left for the 2-D task (passive '
                           "['joint2', 'joint3']): no plan can be tracked")


def test_joint2_free_runs_away_in_both_cases_and_joint3_free_is_held():
    # The fully actuated arm: joint 2 free has no stable internal motion on the paper's
    # circle (the controller's start-up check over the whole path says so too); joint 3
    # free is the paper's arm.  Cross-check: the core's assessment over the whole path.
    for case in ('horizontal', 'vertical'):
        state = _start(case)
        nominal = table1(case).scaled(0.7)
        out = after_failure(_fully_actuated(case), NAMES, 'joint2', state)
        assert out.arm.passive == (1,)
        assert out.refusal.startswith("joint2 failed: the arm with passive ['joint2'] cannot "
                                      'track: the internal motion runs away')
        whole = assess_passive_set(nominal, (1,), *state, CIRCLE, 0.0)
        assert whole.verdict == CANNOT_TRACK
        out = after_failure(_fully_actuated(case), NAMES, 'joint3', state)
        assert out.refusal == '' and out.arm == table1(case)
        assert 'assessed over %g s: held' % ASSESS_HORIZON in out.note
        assert assess_passive_set(nominal, (2,), *state, CIRCLE, 0.0).verdict == TRACKING


def test_without_a_joint_state_the_map_changes_and_the_note_says_the_motion_is_unassessed():
    out = after_failure(_fully_actuated('vertical'), NAMES, 'joint1')
    assert out.refusal == '' and out.arm.passive == (0,)
    assert out.note.endswith('(its internal motion not assessed: no joint state)')
    # the map of that arm is one the planner can compute
    model = compute_model('vertical', 0.7, 2.0, 1e-7, arm=out.arm)
    assert model.nominal.passive == (0,)


def test_joint_state_takes_the_arms_joints_by_name_and_refuses_a_missing_or_nan_value():
    names = ['gripper', 'joint3', 'joint1', 'joint2']
    assert joint_state(NAMES, names, [9.0, 3.0, 1.0, 2.0], [9.0, 0.3, 0.1, 0.2]) == \
        ([1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
    assert joint_state(NAMES, NAMES[:2], [1.0, 2.0], [0.0, 0.0]) is None
    assert joint_state(NAMES, NAMES, [1.0, 2.0, 3.0], [0.0, 0.0]) is None
    assert joint_state(NAMES, NAMES, [1.0, np.nan, 3.0], [0.0] * 3) is None


def test_the_assessment_gives_the_failed_arm_and_the_map_of_it_when_it_can_track():
    from freejoint_planner.planning import assess_failure
    out, model = assess_failure(_fully_actuated('vertical'), NAMES, 'joint3',
                                _start('vertical'), CIRCLE, 0.7, ('vertical', 0.7, 2.0, 1e-7))
    assert out.refusal == '' and out.arm.passive == (2,)
    assert model.nominal.passive == (2,) and model.resolution_deg == 2.0
    out, model = assess_failure(_fully_actuated('vertical'), NAMES, 'joint2',
                                _start('vertical'), CIRCLE, 0.7, ('vertical', 0.7, 2.0, 1e-7))
    assert out.refusal and model is None
