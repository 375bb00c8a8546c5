"""The guards: when the simulated plant counts as diverged, when a law result is refused."""
import math

from freejoint_core.arm import ArmModel, table1
from freejoint_core.arm_gains import active_inertia
from freejoint_core.errors import PlantDivergedError
from freejoint_core.guards import (damped_hold_effort, divergence_reason, hold_effort,
                                   law_output_fault, MAX_ANGLE)
from freejoint_core.internal import hanging_pose
from freejoint_core.plant import Plant
import numpy as np
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


# -- the damped joint hold (readiness_action damp: a driver that keeps its last command) --
def test_the_damped_hold_is_the_gravity_load_plus_the_effective_inertia_times_the_pd_by_hand():
    # T = 0.1 s: stiffness 1 / T^2 = 100 1/s^2, damping 1.5 / T = 15 1/s.
    # acc = 100 (q_hold - q_a) - 15 qd_a = (100 x 0.01 - 15 x 0.3, 100 x -0.02 + 15 x 0.2)
    #     = (-3.5, 1.0); M~aa acc = (2 x -3.5 + 0.5 x 1, 0.5 x -3.5 + 1 x 1) = (-6.5, -0.75).
    inertia = [[2.0, 0.5], [0.5, 1.0]]
    q, qd = [0.99, 2.02, 7.0], [0.3, -0.2, 9.0]
    tau = damped_hold_effort([4.0, -1.0, 0.0], (0, 1), inertia, q, qd, [1.0, 2.0], 0.1)
    assert tau == pytest.approx([4.0 - 6.5, -1.0 - 0.75], abs=1e-12)
    # Limited, and a non-finite term gives 0 for its joint.
    assert damped_hold_effort([4.0, -1.0, 0.0], (0, 1), inertia, q, qd, [1.0, 2.0], 0.1,
                              (1.0, 0.5)) == [-1.0, -0.5]
    assert damped_hold_effort([math.nan, -1.0, 0.0], (0, 1), inertia, q, qd, [1.0, 2.0],
                              0.1)[0] == 0.0


def test_a_damped_hold_command_kept_for_its_hold_time_twice_stops_a_joint_where_it_is_held():
    # Deadbeat: a unit inertia, no gravity, the command computed from the state and kept
    # for T, twice: x = v T + a T^2 / 2 per hold, exactly at rest on q_hold (round-off).
    for hold in (0.02, 0.1, 0.3):
        x, v = 0.4, -2.0
        for _ in range(2):
            a = damped_hold_effort([0.0], (0,), [[1.0]], [x], [v], [0.0], hold)[0]
            x, v = x + v * hold + 0.5 * a * hold * hold, v + a * hold
        assert abs(x) < 1e-12 and abs(v) < 1e-12


def test_the_active_inertia_is_the_paper_arms_effective_inertia():
    # Cross-check of M~aa = ((M^-1)_aa)^-1 with eq. (3)'s M_aa - M_ap M_pp^-1 M_pa.
    model = ArmModel(table1('vertical').scaled(0.7))
    q = [-1.369438, 1.691679, 2.094395]
    assert active_inertia(model, q) == pytest.approx(model.effective(q)[1], rel=1e-12)


def test_a_spatial_arms_active_inertia_is_its_mass_matrix_reduced_by_hand():
    # The UR5 with wrist_2 free: the law's decoupling against ((M^-1)_aa)^-1 of the mass
    # matrix, and M_aa - M_ap M_pp^-1 M_pa.
    import os
    from freejoint_core.spatial_model import KNOWN_ARMS, robot_data_dir, SpatialArm
    path, base, tip = KNOWN_ARMS['ur5']
    arm = SpatialArm(os.path.join(robot_data_dir(), path), base, tip, ['wrist_2_joint'])
    q = np.array([0.1, -1.2, 1.5, -0.4, 0.8, 0.3])
    mass = arm.terms(q, np.zeros(6)).M
    act, free = [0, 1, 2, 3, 5], [4]
    schur = (mass[np.ix_(act, act)] - mass[np.ix_(act, free)]
             @ np.linalg.solve(mass[np.ix_(free, free)], mass[np.ix_(free, act)]))
    assert active_inertia(arm, q) == pytest.approx(schur, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_kept_by_a_driver_through_bursts_of_missed_states_the_damped_hold_keeps_the_arm(case):
    # A driver that keeps each command until the next: from an active motion of 0.5 rad/s
    # (the free link hanging, vertical), every state of 0.1 s missed out of every 0.3 s and
    # each command applied 1-19 ms after its state, for 3 s, on the real Table I arm with
    # the disturbance, the nominal model's load and inertia: with stop_hold_time 0.1 s
    # the active joints stay within 0.2 rad of where they stopped (the vertical arm sags
    # some 0.13 rad on the 30 % gravity load the model misses) and no joint turns faster
    # than 2 rad/s; gains of a 0.02-s hold time (as stiff as 200 N m/rad, 20 N m s/rad
    # on the paper's arm) run away.
    fastest, off = _kept_through_bursts(case, 0.1)
    assert fastest < 2.0 and off < 0.2, (fastest, off)
    fastest, off = _kept_through_bursts(case, 0.02)
    assert fastest > 100.0, (fastest, off)


def _kept_through_bursts(case, hold, dt=1e-3, run_s=3.0):
    """Return (fastest joint [rad/s], largest active-joint offset [rad]) (test above)."""
    real = table1(case)
    nominal = ArmModel(real.scaled(0.7))
    q0 = (hanging_pose(real, (0.2, 0.0)).tolist() if case == 'vertical'
          else [-1.369438, 1.691679, 2.094395])
    plant = Plant(real, dist_bound=0.5, seed=0, q0=q0, qd0=[0.5, -0.5, 0.0])
    rng = np.random.default_rng(0)
    q_stop = q0[:2]

    def command():
        q, qd = plant.q, plant.qd
        return damped_hold_effort(nominal.gravity_torque(q).tolist(), (0, 1),
                                  active_inertia(nominal, q), q, qd, q_stop, hold)
    kept, pending = command(), []
    fastest = off = 0.0
    for k in range(round(run_s / dt)):
        if (k * dt) % 0.3 >= 0.1:
            pending.append((k + int(rng.integers(1, 20)), command()))
        while pending and pending[0][0] <= k:
            kept = pending.pop(0)[1]
        try:
            plant.step(kept, dt)
        except PlantDivergedError:
            return math.inf, math.inf
        fastest = max(fastest, float(np.max(np.abs(plant.qd))))
        off = max(off, float(np.max(np.abs(plant.q[:2] - np.array(q_stop)))))
    return fastest, off
