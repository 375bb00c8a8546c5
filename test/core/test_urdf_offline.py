"""The offline runner of a URDF arm and the controller's Pinocchio nominal model."""

from freejoint_core.control import Gains, RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.pin_model import PinArmModel
from freejoint_core.trajectory import CircleQuintic
from freejoint_core.urdf import four_link_arm, FOUR_LINK_CIRCLE, FOUR_LINK_Q0, paper_arm
from freejoint_core.urdf_offline import make_plant, nominal_model, run_arm
import numpy as np
import pytest


def test_controller_on_pinocchios_nominal_model_equals_the_general_numpy_path():
    arm = four_link_arm('horizontal')
    traj = CircleQuintic(**FOUR_LINK_CIRCLE)
    numpy_ctl = RobustController(arm.nominal(0.7), Gains())
    pin_ctl = RobustController(arm.nominal(0.7), Gains(), model=nominal_model(arm, 0.7))
    assert isinstance(pin_ctl.model, PinArmModel)
    plant = make_plant(arm, q0=FOUR_LINK_Q0)
    for k in range(300):
        sp = traj.sample_tuple(k * 1e-3)
        a = numpy_ctl.step(plant.q, plant.qd, sp[0:2], sp[2:4], sp[4:6], 1e-3)
        b = pin_ctl.step(plant.q, plant.qd, sp[0:2], sp[2:4], sp[4:6], 1e-3)
        assert np.max(np.abs(a.tau - b.tau)) <= 1e-9
        assert np.max(np.abs(a.internal['theta_hat'] - b.internal['theta_hat'])) <= 1e-12
        plant.step(b.tau, 1e-3)


def test_the_paper_arm_keeps_the_closed_form_kernel_and_a_wrong_model_is_refused():
    arm = paper_arm('horizontal')
    assert nominal_model(arm, 0.7) is None
    with pytest.raises(FreejointValueError, match='^model: '):
        RobustController(arm.nominal(0.7), model=PinArmModel(arm, 0.5))


def test_four_link_offline_runner_tracks_within_the_stated_bound_on_both_engines():
    arm = four_link_arm('horizontal')
    records = [run_arm(arm, CircleQuintic(**FOUR_LINK_CIRCLE), FOUR_LINK_Q0, engine=engine,
                       n_ticks=5000)
               for engine in ('rk4', 'mujoco')]
    for record, trace in records:
        assert record['diverged_at_s'] is None and len(trace['t']) == 5000
        assert record['max_mm'] <= 2.0
    assert np.max(np.abs(records[0][1]['p'] - records[1][1]['p'])) <= 1e-9
