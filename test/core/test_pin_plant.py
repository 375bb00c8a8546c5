"""The RK4 plant on Pinocchio's ABA equals the core's RK4 plant."""

from freejoint_core import offline
from freejoint_core.errors import FreejointValueError
from freejoint_core.pin_plant import PinPlant
from freejoint_core.plant import Plant
from freejoint_core.urdf import four_link_arm, FOUR_LINK_Q0, paper_arm
import numpy as np
import pytest

DT = 1e-3


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_four_link_pinocchio_plant_equals_the_general_rk4_plant(case, step_alongside):
    arm = four_link_arm(case)
    ref = Plant(arm.params, seed=4, q0=FOUR_LINK_Q0, use_fast=False)
    plant = PinPlant(arm, seed=4, q0=FOUR_LINK_Q0)
    step_alongside(plant, ref, 300)
    assert plant.k == ref.k == 300 and plant.t == ref.t
    assert np.max(np.abs(plant.q - ref.q)) <= 1e-11
    assert np.max(np.abs(plant.qd - ref.qd)) <= 1e-10


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_closed_loop_on_the_pinocchio_plant_equals_the_rk4_plant_over_the_paper_circle(
        case, monkeypatch):
    _, rk4 = offline.run_case(case, 'robust', 0, record_trace=True)
    arm = paper_arm(case)
    built = []

    def factory(params, dt_sub, dist_bound=0.5, seed=0, q0=None):
        assert params == arm.params
        built.append(PinPlant(arm, dt_sub, dist_bound=dist_bound, seed=seed, q0=q0))
        return built[-1]
    monkeypatch.setattr(offline, 'Plant', factory)
    _, pin_run = offline.run_case(case, 'robust', 0, record_trace=True)
    assert len(built) == 1 and built[0].k == 5000
    err_mm = 1e3 * np.max(np.hypot(*(pin_run['p'] - rk4['p']).T))
    assert err_mm <= 1e-6, f'{case}: Pinocchio vs RK4 plant closed loop differ by {err_mm:.3g} mm'


def test_pinocchio_plant_refuses_bad_input_and_keeps_its_state_on_divergence(
        diverges_keeping_state):
    plant = PinPlant(paper_arm('vertical'), dist_bound=0.0, q0=[0.1, 0.2, 0.3])
    with pytest.raises(FreejointValueError, match='tau_active: expected 2 finite values'):
        plant.step([1.0, float('inf')], DT)
    with pytest.raises(FreejointValueError, match='dt: 0.00075 s is not an integer multiple'):
        plant.step([1.0, 2.0], 0.00075)
    diverges_keeping_state(plant, 1e308)
    plant.reset()
    np.testing.assert_array_equal(plant.q, [0.1, 0.2, 0.3])
    assert plant.k == 0 and plant.t == 0.0
