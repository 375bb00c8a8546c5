"""The guards: when the simulated plant counts as diverged, when a law result is refused."""
import math

from freejoint_core.arm import ArmModel, table1
from freejoint_core.guards import divergence_reason, hold_effort, law_output_fault, MAX_ANGLE
from freejoint_core.plant import Plant
import pytest


def test_a_finite_state_within_the_bounds_is_sane():
    assert divergence_reason([0.1, -3.0, 1e5], [999.0, -999.0, 0.0], 1000.0) is None


def test_a_non_finite_state_is_diverged_naming_the_joint():
    assert divergence_reason([0.0, math.nan, 0.0], [0.0, 0.0, 0.0], 1000.0) == \
        'joint 1: non-finite state (q = nan rad, qd = 0.0 rad/s)'
    assert divergence_reason([0.0, 0.0], [0.0, -math.inf], 1000.0).startswith('joint 1: non')


def test_a_joint_faster_than_the_bound_is_diverged_naming_speed_and_bound():
    assert divergence_reason([0.0, 0.0, 0.0], [0.0, 0.0, -1000.5], 1000.0) == \
        'joint 2: speed -1000.5 rad/s beyond divergence_speed 1000 rad/s'


def test_an_angle_beyond_the_plausible_is_diverged():
    assert divergence_reason([2 * MAX_ANGLE, 0.0], [0.0, 0.0], 1000.0) == \
        'joint 0: angle 2e+06 rad beyond 1e+06 rad'


def test_a_law_result_with_a_torque_beyond_its_limit_or_nan_is_a_fault():
    assert law_output_fault([1.0, -2.0], [1.0, 2.0], [0.5], [(0.0, 1.0)]) is None
    assert law_output_fault([1.5, 0.0], [1.0, 2.0], [], []) == 'torque [1.5, 0.0]'
    assert law_output_fault([math.nan, 0.0], [1.0, 2.0], [], []) == 'torque [nan, 0.0]'


def test_a_law_state_outside_its_bounds_or_non_finite_is_a_fault():
    bounds = [(0.0, 100.0), (-math.inf, math.inf)]
    assert law_output_fault([0.0], [1.0], [100.0, -1e300], bounds) is None
    assert law_output_fault([0.0], [1.0], [-1e-9, 0.0], bounds) == 'law state [-1e-09, 0.0]'
    assert law_output_fault([0.0], [1.0], [1.0, math.inf], bounds) == 'law state [1.0, inf]'


# -- the stop command (docs/real-time.md, "Stopping") ------------------------------------
def test_the_stop_command_is_the_active_joints_gravity_load_by_hand():
    # Table I vertical, every link along +x (q = 0): the weights' lever arms about joint 1
    # are 0.25, 0.75 and 1.25 m (1 kg each), about joint 2 0.25 and 0.75 m:
    # G_1 = 9.81 x 2.25 = 22.0725 N m, G_2 = 9.81 x 1.0 = 9.81 N m (joint 3 free: not sent).
    gravity = ArmModel(table1('vertical')).gravity_torque([0.0, 0.0, 0.0]).tolist()
    assert hold_effort(gravity, (0, 1)) == pytest.approx([22.0725, 9.81], abs=1e-12)
    # Straight up (q1 = 90 deg) no lever arm: nothing to hold; horizontal plane: zero.
    up = ArmModel(table1('vertical')).gravity_torque([math.pi / 2, 0.0, 0.0]).tolist()
    assert hold_effort(up, (0, 1)) == pytest.approx([0.0, 0.0], abs=1e-12)
    flat = ArmModel(table1('horizontal')).gravity_torque([0.3, -1.0, 2.0]).tolist()
    assert hold_effort(flat, (0, 1)) == [0.0, 0.0]


def test_the_stop_command_is_limited_and_never_non_finite():
    assert hold_effort([22.0725, -9.81, 2.0], (0, 1), (20.0, 5.0)) == [20.0, -5.0]
    assert hold_effort([math.nan, 3.0, math.inf], (2, 1)) == [0.0, 3.0]


def test_held_by_a_driver_the_stop_command_keeps_a_resting_arm_where_zero_lets_it_fall():
    # The vertical arm at rest with its free link hanging (no torque on joint 3): the
    # exact gravity load holds it where it is; zero effort lets it fall.
    q0 = [-0.3, 0.9, -0.6 - math.pi / 2]        # phi_3 = -90 deg: the free link hangs
    model = ArmModel(table1('vertical'))
    assert model.gravity_torque(q0)[2] == pytest.approx(0.0, abs=1e-12)
    hold = hold_effort(model.gravity_torque(q0).tolist(), model.active)
    drift = {}
    for name, tau in (('hold', hold), ('zero', [0.0, 0.0])):
        plant = Plant(table1('vertical'), dist_bound=0.0, q0=q0)
        for _ in range(500):                    # 0.5 s held
            plant.step(tau, 1e-3)
        drift[name] = float(max(abs(a - b) for a, b in zip(plant.q, q0)))
    assert drift['hold'] < 1e-9 and drift['zero'] > 0.3
