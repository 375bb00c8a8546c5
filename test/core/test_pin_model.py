"""The Pinocchio model of the shipped URDFs equals the core's closed-form models."""

from freejoint_core.arm import ArmModel, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.fast3 import Arm3Model
from freejoint_core.pin_model import PinArmModel
from freejoint_core.urdf import (four_link_arm, GRAVITY_BY_CASE, paper_arm, parse_urdf,
                                 shipped_urdf_path)
import numpy as np
import pytest

TOL = 1e-12
N_STATES = 200


def _states(n, seed):
    rng = np.random.default_rng(seed)
    for _ in range(N_STATES):
        yield rng.uniform(-np.pi, np.pi, n), rng.uniform(-6.0, 6.0, n)


def _quantities(model, q, qd):
    return {
        'M': model.mass_matrix(q),
        'Cqd': model.coriolis(q, qd),
        'G': model.gravity_torque(q),
        'J': model.jacobian(q),
        'Jdot qd': model.jdot_qdot(q, qd),
        'fk': model.fk(q),
    }


def _max_errors(model, ref, n, seed):
    worst = {}
    for q, qd in _states(n, seed):
        got, want = _quantities(model, q, qd), _quantities(ref, q, qd)
        for key in want:
            assert got[key].shape == want[key].shape, key
            worst[key] = max(worst.get(key, 0.0), float(np.max(np.abs(got[key] - want[key]))))
    return worst


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
@pytest.mark.parametrize('reference', ['ArmModel', 'Arm3Model'])
def test_table1_urdf_through_pinocchio_equals_the_closed_form_model(case, reference):
    ref = (ArmModel if reference == 'ArmModel' else Arm3Model)(table1(case))
    worst = _max_errors(PinArmModel(paper_arm(case)), ref, 3, seed=13)
    assert all(v <= TOL for v in worst.values()), worst


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_nominal_pinocchio_model_equals_the_scaled_closed_form_model(case):
    ref = Arm3Model(table1(case).scaled(0.7))
    worst = _max_errors(PinArmModel(paper_arm(case), scale=0.7), ref, 3, seed=14)
    assert all(v <= TOL for v in worst.values()), worst


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_four_link_urdf_through_pinocchio_equals_the_general_model_of_its_parameters(case):
    arm = four_link_arm(case)
    assert arm.params.n == 4
    worst = _max_errors(PinArmModel(arm), ArmModel(arm.params), 4, seed=15)
    assert all(v <= TOL for v in worst.values()), worst


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_pinocchio_task_terms_equal_the_closed_form_decoupling(case):
    model, ref = PinArmModel(paper_arm(case)), Arm3Model(table1(case))
    for q, qd in _states(3, seed=16):
        mass, h, jac, jdqd, p = model.terms(q, qd)
        assert np.max(np.abs(mass - ref.mass_matrix(q))) <= TOL
        assert np.max(np.abs(h - ref.coriolis(q, qd) - ref.gravity_torque(q))) <= TOL
        assert np.max(np.abs(jac - ref.jacobian(q))) <= TOL
        assert np.max(np.abs(jdqd - ref.jdot_qdot(q, qd))) <= TOL
        assert np.max(np.abs(p - ref.fk(q))) <= TOL
        da, b = model.decoupling(q, qd)
        da_ref, b_ref = ref.decoupling(q, qd)
        assert np.max(np.abs(da - da_ref)) <= 1e-12 * max(1.0, np.max(np.abs(da_ref)))
        assert np.max(np.abs(b - b_ref)) <= 1e-12 * max(1.0, np.max(np.abs(b_ref)))


def test_pinocchio_forward_dynamics_and_coriolis_matrix_equal_the_reference():
    arm = four_link_arm('vertical')
    model, ref = PinArmModel(arm), ArmModel(arm.params)
    tau = np.array([1.0, -2.0, 0.5, 0.3])
    for q, qd in _states(4, seed=17):
        qdd = model.forward_dynamics(q, qd, tau)
        qdd_ref = ref.forward_dynamics(q, qd, tau)
        assert np.max(np.abs(qdd - qdd_ref)) <= 1e-9 * max(1.0, np.max(np.abs(qdd_ref)))
        assert np.max(np.abs(model.coriolis_matrix(q, qd) - ref.coriolis_matrix(q, qd))) <= TOL


def test_continuous_joints_map_to_the_same_dynamics():
    with open(shipped_urdf_path('paper_arm'), encoding='utf-8') as f:
        text = f.read()
    limit = ('<limit lower="-6.283185307179586" upper="6.283185307179586" effort="100" '
             'velocity="100"/>')
    text = text.replace('type="revolute"', 'type="continuous"').replace(limit, '')
    text = text.replace('<limit lower="-6.283185307179586" upper="6.283185307179586" '
                        'effort="0" velocity="100"/>', '')
    arm = parse_urdf(text, ['joint3'], GRAVITY_BY_CASE['vertical'])
    model = PinArmModel(arm)
    assert model.pin_model.nq == 6 and model.pin_model.nv == 3
    ref = Arm3Model(table1('vertical'))
    worst = _max_errors(model, ref, 3, seed=18)
    assert all(v <= TOL for v in worst.values()), worst
    for q, qd in _states(3, seed=19):
        for got, want in zip(model.decoupling(q, qd), ref.decoupling(q, qd)):
            assert np.max(np.abs(got - want)) <= 1e-12 * max(1.0, np.max(np.abs(want)))


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_four_link_pinocchio_decoupling_equals_the_general_model(case):
    arm = four_link_arm(case)
    model, ref = PinArmModel(arm, scale=0.7), ArmModel(arm.nominal(0.7))
    for q, qd in _states(4, seed=20):
        for got, want in zip(model.decoupling(q, qd), ref.decoupling(q, qd)):
            assert got.shape == want.shape
            assert np.max(np.abs(got - want)) <= 1e-12 * max(1.0, np.max(np.abs(want)))


def test_pinocchio_model_validates_its_arguments():
    model = PinArmModel(paper_arm('horizontal'))
    with pytest.raises(FreejointValueError, match='q: expected shape'):
        model.mass_matrix([0.0, 0.0])
    with pytest.raises(FreejointValueError, match='qd: values must be finite'):
        model.coriolis([0.0, 0.0, 0.0], [0.0, float('nan'), 0.0])
    with pytest.raises(FreejointValueError, match='arm: expected UrdfArm'):
        PinArmModel(table1('horizontal'))
