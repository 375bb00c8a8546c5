"""The settle gate's judgement: the free link's swing of a joint state, no ROS."""
import math

from freejoint_core.arm import table1
from freejoint_core.internal import hanging_pose
from freejoint_planner.params import validate
from freejoint_planner.planning import compute_model, settle_gate_refusal, swing_deg
import pytest

NAMES = ['joint1', 'joint2', 'joint3']


def _vertical_model():
    return compute_model('vertical', 0.7, 1.0, 1e-7)


def test_a_hanging_link_at_rest_does_not_swing_and_a_spinning_one_swings_by_its_energy():
    model = _vertical_model()
    real = table1('vertical')
    q = hanging_pose(real, (0.2, 0.0)).tolist()
    assert swing_deg(model, NAMES, NAMES, q, [0.0] * 3) == pytest.approx(0.0, abs=1e-6)
    # The link alone turning at w about its joint, at the bottom: cos(swing) =
    # 1 - J_eff w^2 / (2 m3 c3 g), J_eff = I3 + m3 c3 (c3 - L3), of the nominal arm (what the
    # planner knows: the 70 % model, its com scaled too).
    nominal = table1('vertical').scaled(0.7)
    m3, c3, l3, i3, g = (nominal.masses[2], nominal.com[2], nominal.lengths[2],
                         nominal.inertias[2], nominal.gravity)
    w = 2.0
    j_eff = i3 + m3 * c3 * (c3 - l3)
    expected = math.degrees(math.acos(1.0 - j_eff * w * w / (2.0 * m3 * c3 * g)))
    assert swing_deg(model, NAMES, NAMES, q, [0.0, 0.0, w]) == pytest.approx(expected, rel=1e-9)
    # any order of the joint state's names, extra joints ignored
    names = ['gripper', 'joint3', 'joint1', 'joint2']
    assert swing_deg(model, NAMES, names, [9.0, q[2], q[0], q[1]], [9.0, w, 0.0, 0.0]) == \
        pytest.approx(expected, rel=1e-9)


def test_an_incomplete_or_non_finite_joint_state_tells_nothing():
    model = _vertical_model()
    assert swing_deg(model, NAMES, NAMES[:2], [0.0, 0.0], [0.0, 0.0]) is None
    assert swing_deg(model, NAMES, NAMES, [0.0] * 3, [0.0] * 2) is None      # no velocities
    assert swing_deg(model, NAMES, NAMES, [0.0, math.nan, 0.0], [0.0] * 3) is None
    assert swing_deg(model, NAMES, NAMES, [0.0] * 3, [0.0, 0.0, math.inf]) is None


def test_the_gate_judges_a_free_last_link_under_gravity_only():
    assert settle_gate_refusal(table1('vertical').scaled(0.7)) == ''
    assert 'needs gravity' in settle_gate_refusal(table1('horizontal'))
    from freejoint_core.urdf import four_link_arm
    reason = settle_gate_refusal(four_link_arm('vertical').params)
    assert reason.startswith('settle_swing_deg: ') and 'passive joints [0]' in reason


def test_the_threshold_is_degrees_from_0_off_to_180():
    assert validate({'settle_swing_deg': 0.0}) == ''
    assert validate({'settle_swing_deg': 2.0}) == ''
    assert 'settle_swing_deg' in validate({'settle_swing_deg': -1.0})
    assert 'settle_swing_deg' in validate({'settle_swing_deg': 181.0})


def test_the_planners_state_is_cannot_plan_then_settling_then_ready():
    from freejoint_planner.planning import FAILED, planner_status, READY, SETTLING
    why = 'joint2 failed: 1 active joint(s) left for the 2-D task'
    assert planner_status(why, [], 'settling: the free link swings 9 deg') == (FAILED, why)
    swinging = 'settling: the free link swings 9.00 deg (> settle_swing_deg 3); ask again'
    assert planner_status('', [], swinging) == (SETTLING, swinging)
    assert planner_status('', [], '') == (READY, 'ready for a plan: the free link settled')
    assert planner_status('', [], None) == (READY, 'ready for a plan')
    assert planner_status('', ['joint3'], None) == (
        READY, 'ready for a plan; joint3 reported failed: assessed at the next plan request')
