"""The MuJoCo plant (URDF imported by MuJoCo) equals the core's RK4 plant."""

from freejoint_core import offline
from freejoint_core.errors import FreejointValueError, PlantDivergedError
from freejoint_core.mujoco_plant import MujocoPlant
from freejoint_core.plant import Plant
from freejoint_core.urdf import (four_link_arm, GRAVITY_VERTICAL_VECTOR, paper_arm, parse_urdf,
                                 shipped_urdf_path)
import numpy as np
import pytest

DT = 1e-3


def _mujoco_plant_factory(case, built):
    """Return a stand-in for ``Plant(params, dt_sub, dist_bound=, seed=, q0=)`` on MuJoCo."""
    arm = paper_arm(case)

    def factory(params, dt_sub, dist_bound=0.5, seed=0, q0=None):
        assert params == arm.params
        plant = MujocoPlant(arm, dt_sub, dist_bound=dist_bound, seed=seed, q0=q0)
        built.append(plant)
        return plant
    return factory


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_closed_loop_on_mujoco_equals_closed_loop_on_rk4_over_the_paper_circle(
        case, monkeypatch):
    _, rk4 = offline.run_case(case, 'robust', 0, record_trace=True)
    built = []
    monkeypatch.setattr(offline, 'Plant', _mujoco_plant_factory(case, built))
    _, mj = offline.run_case(case, 'robust', 0, record_trace=True)
    assert len(built) == 1 and built[0].k == 5000   # the loop really ran on MuJoCo
    assert rk4['p'].shape == mj['p'].shape == (5000, 2)
    err_mm = 1e3 * np.max(np.hypot(*(mj['p'] - rk4['p']).T))
    assert err_mm <= 1e-6, f'{case}: MuJoCo vs RK4 closed loop differ by {err_mm:.3g} mm'
    assert np.max(np.abs(mj['tau'] - rk4['tau'])) <= 1e-6
    # and the loop tracked (not two equal divergences)
    assert 1e3 * np.max(np.hypot(*mj['e'].T)) < 10.0


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_four_link_mujoco_plant_follows_the_rk4_plant_open_loop(case, step_alongside):
    arm = four_link_arm(case)
    q0 = np.radians([20.0, 40.0, -30.0, 50.0])
    rk4 = Plant(arm.params, seed=5, q0=q0, use_fast=False)
    mj = MujocoPlant(arm, seed=5, q0=q0)
    step_alongside(mj, rk4, 500)
    assert np.max(np.abs(mj.q - rk4.q)) <= 1e-10
    assert np.max(np.abs(mj.qd - rk4.qd)) <= 1e-9


def test_mujoco_plant_reset_restarts_state_time_and_disturbance():
    arm = paper_arm('vertical')
    plant = MujocoPlant(arm, seed=2, q0=[0.1, 0.2, 0.3])
    plant.step([0.5, -0.5], DT)
    first = (plant.q, plant.last_disturbance)
    for _ in range(10):
        plant.step([0.5, -0.5], DT)
    plant.reset()
    assert plant.k == 0 and plant.t == 0.0
    np.testing.assert_array_equal(plant.q, [0.1, 0.2, 0.3])
    plant.step([0.5, -0.5], DT)
    np.testing.assert_array_equal(plant.q, first[0])
    assert plant.last_disturbance == first[1]


def test_mujoco_plant_refuses_bad_torque_and_period():
    plant = MujocoPlant(paper_arm('horizontal'))
    with pytest.raises(FreejointValueError, match='tau_active: expected 2 finite values'):
        plant.step([1.0, float('nan')], DT)
    with pytest.raises(FreejointValueError, match='tau_active: expected 2 finite values'):
        plant.step([1.0, 2.0, 3.0], DT)
    with pytest.raises(FreejointValueError, match='dt: 0.00075 s is not an integer multiple'):
        plant.step([1.0, 2.0], 0.00075)
    with pytest.raises(FreejointValueError, match='seed: expected a non-negative int'):
        MujocoPlant(paper_arm('horizontal'), seed=-1)
    assert plant.k == 0


def test_mujoco_plant_keeps_its_last_finite_state_when_the_integration_diverges(
        diverges_keeping_state):
    plant = MujocoPlant(paper_arm('vertical'), dist_bound=0.0, q0=[0.1, 0.2, 0.3])
    diverges_keeping_state(plant, 1e300)
    plant.step([1.0, 1.0], DT)      # and goes on from there
    assert plant.k == 2 and np.all(np.isfinite(plant.q))


def test_mujoco_plant_refuses_a_speed_beyond_what_mujoco_accepts_without_resetting():
    plant = MujocoPlant(paper_arm('horizontal'), dist_bound=0.0, q0=[0.1, 0.2, 0.3],
                        qd0=[2e10, 0.0, 0.0])
    with pytest.raises(PlantDivergedError, match='MuJoCo: Nan, Inf or huge value in QVEL'):
        plant.step([0.0, 0.0], DT)
    np.testing.assert_array_equal(plant.q, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(plant.qd, [2e10, 0.0, 0.0])
    # MuJoCo prints a warning only the first time; its counter still tells
    with pytest.raises(PlantDivergedError, match='tau_active: the integration over step 0'):
        plant.step([0.0, 0.0], DT)
    plant.reset(qd0=[0.0, 0.0, 0.0])
    plant.step([0.0, 0.0], DT)
    assert plant.k == 1


def test_urdf_mounted_on_a_world_link_gives_the_same_pinocchio_model_and_mujoco_plant():
    from freejoint_core.fast3 import Arm3Model
    from freejoint_core.pin_model import PinArmModel
    from freejoint_core.arm import table1
    with open(shipped_urdf_path('paper_arm'), encoding='utf-8') as f:
        text = f.read().replace(
            '<link name="base_link"/>', '<link name="world"/><joint name="mount" type="fixed">'
            '<parent link="world"/><child link="base_link"/><origin xyz="0 0 0.8"/></joint>'
            '<link name="base_link"/>')
    arm = parse_urdf(text, ['joint3'], GRAVITY_VERTICAL_VECTOR)
    q, qd = np.array([0.3, 0.5, -0.2]), np.array([1.0, 2.0, -1.0])
    pin_model, ref = PinArmModel(arm), Arm3Model(table1('vertical'))
    assert np.max(np.abs(pin_model.fk(q) - ref.fk(q))) <= 1e-12
    assert np.max(np.abs(pin_model.gravity_torque(q) - ref.gravity_torque(q))) <= 1e-12
    assert np.max(np.abs(pin_model.coriolis(q, qd) - ref.coriolis(q, qd))) <= 1e-12
    mj, rk4 = MujocoPlant(arm, q0=q, qd0=qd), Plant(arm.params, q0=q, qd0=qd)
    for _ in range(200):
        mj.step([0.1, 0.2], DT)
        rk4.step([0.1, 0.2], DT)
    assert np.max(np.abs(mj.q - rk4.q)) <= 1e-12
