"""
Behaviour of the arm parameters and models (general ArmModel and 3-link kernel).

Expected values come from hand derivations or from an independent numeric
Lagrange derivation written here (kinetic and potential energy from the link
centre-of-mass positions), never from the models' own code paths.
"""

import cmath
import math

from freejoint_core.arm import ArmModel, ArmParams, CASES, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.fast3 import Arm3Model
from freejoint_core.models import make_model
import numpy as np
import pytest

G = 9.81


def _params(n, passive, gravity=G):
    """Non-uniform n-link parameters (so symmetric mistakes cannot cancel)."""
    return ArmParams(
        lengths=tuple(0.3 + 0.1 * i for i in range(n)),
        masses=tuple(1.0 + 0.4 * i for i in range(n)),
        inertias=tuple(0.05 + 0.03 * i for i in range(n)),
        com=tuple(0.12 + 0.04 * i for i in range(n)),
        passive=passive, gravity=gravity)


CONFIGS = [
    (2, ()),
    (3, (2,)),
    (3, (0,)),
    (3, (1,)),
    (4, (1,)),
    (4, (0, 3)),
]


# -- independent derivation -------------------------------------------------
def _com_positions(params, q):
    """COM positions (n, 2) by walking the chain; works on complex q."""
    out, x, y, phi = [], 0.0, 0.0, 0.0
    for length, c, qi in zip(params.lengths, params.com, q):
        phi = phi + qi
        out.append((x + c * cmath.cos(phi), y + c * cmath.sin(phi)))
        x, y = x + length * cmath.cos(phi), y + length * cmath.sin(phi)
    return out


def _kinetic(params, q, qd):
    """Kinetic energy, COM velocities by complex-step differentiation (exact)."""
    h = 1e-30
    qc = [complex(a, h * b) for a, b in zip(q, qd)]
    kin, omega = 0.0, 0.0
    coms = _com_positions(params, qc)
    for (xc, yc), m, inertia, w in zip(coms, params.masses, params.inertias, qd):
        omega += w
        vx, vy = xc.imag / h, yc.imag / h
        kin += 0.5 * m * (vx * vx + vy * vy) + 0.5 * inertia * omega * omega
    return kin


def _potential(params, q):
    return params.gravity * sum(
        m * yc.real for (_, yc), m in zip(_com_positions(params, q), params.masses))


def _mass_lagrange(params, q):
    """M by polarisation of the quadratic form T(q, .)."""
    n = params.n
    eye = np.eye(n)
    mass = np.empty((n, n))
    for j in range(n):
        for k in range(n):
            mass[j, k] = (_kinetic(params, q, eye[j] + eye[k]) - _kinetic(params, q, eye[j])
                          - _kinetic(params, q, eye[k]))
    return mass


def _bias_lagrange(params, q, qd, h=1e-6):
    """C qd + G = Mdot qd - dT/dq + dV/dq (central differences)."""
    n = params.n
    mdot = (_mass_lagrange(params, q + h * qd) - _mass_lagrange(params, q - h * qd)) / (2 * h)
    eye = np.eye(n)
    dtdq = np.array([(_kinetic(params, q + h * e, qd) - _kinetic(params, q - h * e, qd))
                     / (2 * h) for e in eye])
    dvdq = np.array([(_potential(params, q + h * e) - _potential(params, q - h * e)) / (2 * h)
                     for e in eye])
    return mdot @ qd - dtdq + dvdq


def _random_state(rng, n):
    return rng.uniform(-math.pi, math.pi, n), rng.uniform(-3.0, 3.0, n)


# -- parameters ---------------------------------------------------------------
def test_table1_real_and_nominal_values_match_the_paper():
    for case in CASES:
        real = table1(case)
        assert real.lengths == (0.5, 0.5, 0.5)
        assert real.masses == (1.0, 1.0, 1.0)
        assert real.inertias == (0.1, 0.1, 0.1)
        assert real.com == (0.25, 0.25, 0.25)
        assert real.passive == (2,)
        nominal = real.scaled(0.7)
        assert nominal.lengths == (0.5, 0.5, 0.5)
        assert nominal.masses == pytest.approx((0.7,) * 3, abs=1e-15)
        assert nominal.inertias == pytest.approx((0.07,) * 3, abs=1e-15)
        assert nominal.com == pytest.approx((0.175,) * 3, abs=1e-15)
    assert table1('horizontal').gravity == 0.0
    assert table1('vertical').gravity == 9.81


def test_params_expose_counts_and_sorted_active_passive_indices():
    p = _params(4, [3, 0])
    assert (p.n, p.r, p.p) == (4, 2, 2)
    assert p.passive == (0, 3)
    assert p.active == (1, 2)


@pytest.mark.parametrize('field, value, match', [
    ('masses', (1.0, 0.0, 1.0), 'masses'),
    ('masses', (1.0, -1.0, 1.0), 'masses'),
    ('inertias', (0.1, 0.1, -0.1), 'inertias'),
    ('lengths', (0.5, 0.0, 0.5), 'lengths'),
    ('com', (0.25, 0.6, 0.25), 'com'),
    ('com', (0.25, 0.0, 0.25), 'com'),
    ('masses', (1.0, 1.0), 'masses'),
    ('masses', (1.0, float('nan'), 1.0), 'masses'),
    ('passive', (1, 2), 'passive'),
    ('passive', (3,), 'passive'),
    ('passive', (-1,), 'passive'),
    ('passive', (2, 2), 'passive'),
    ('gravity', -9.81, 'gravity'),
])
def test_params_reject_invalid_fields_naming_them(field, value, match):
    kwargs = {'lengths': (0.5,) * 3, 'masses': (1.0,) * 3, 'inertias': (0.1,) * 3,
              'com': (0.25,) * 3, 'passive': (2,), 'gravity': 0.0}
    kwargs[field] = value
    with pytest.raises(FreejointValueError, match=f'^{match}'):
        ArmParams(**kwargs)


def test_params_reject_a_single_link():
    with pytest.raises(FreejointValueError, match='^lengths'):
        ArmParams(lengths=(0.5,), masses=(1.0,), inertias=(0.1,), com=(0.25,), passive=())


def test_table1_and_scaled_reject_bad_arguments():
    with pytest.raises(FreejointValueError, match='^case'):
        table1('sideways')
    with pytest.raises(FreejointValueError, match='^scale'):
        table1().scaled(0.0)
    with pytest.raises(FreejointValueError, match='^com'):
        table1().scaled(3.0)   # com 0.75 > L = 0.5


# -- hand-derived values --------------------------------------------------------
def test_fk_of_hand_configurations():
    model = ArmModel(table1())
    np.testing.assert_allclose(model.fk([0.0, 0.0, 0.0]), [1.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(model.fk([math.pi / 2, 0.0, 0.0]), [0.0, 1.5], atol=1e-15)
    np.testing.assert_allclose(model.fk([0.0, math.pi / 2, -math.pi / 2]), [1.0, 0.5],
                               atol=1e-15)


def test_mass_matrix_and_gravity_of_the_stretched_table1_arm():
    # Arm along +x: M_jk = sum_i m_i (x_ci - x_j)(x_ci - x_k) + sum_{i >= j, k} I_i.
    # COMs at x = 0.25, 0.75, 1.25; joints at x = 0, 0.5, 1.0.
    expected = np.array([
        [0.3 + 0.0625 + 0.5625 + 1.5625, 0.2 + 0.25 * 0.75 + 0.75 * 1.25, 0.1 + 0.25 * 1.25],
        [0.0, 0.2 + 0.0625 + 0.5625, 0.1 + 0.25 * 0.75],
        [0.0, 0.0, 0.1 + 0.0625]])
    expected = np.triu(expected) + np.triu(expected, 1).T
    for model in (ArmModel(table1('vertical')), Arm3Model(table1('vertical'))):
        np.testing.assert_allclose(model.mass_matrix([0.0, 0.0, 0.0]), expected, atol=1e-14)
        # G_j = g * sum_{i >= j} m_i (x_ci - x_j)
        np.testing.assert_allclose(model.gravity_torque([0.0, 0.0, 0.0]),
                                   [9.81 * 2.25, 9.81 * 1.0, 9.81 * 0.25], atol=1e-13)
    np.testing.assert_array_equal(ArmModel(table1('horizontal')).gravity_torque([0.3, 1, 2]),
                                  [0.0, 0.0, 0.0])


# -- structural properties ------------------------------------------------------
@pytest.mark.parametrize('n, passive', CONFIGS)
def test_mass_matrix_is_symmetric_positive_definite(n, passive):
    rng = np.random.default_rng(10 + n)
    model = ArmModel(_params(n, passive))
    for _ in range(20):
        mass = model.mass_matrix(_random_state(rng, n)[0])
        np.testing.assert_allclose(mass, mass.T, atol=1e-15)
        assert np.linalg.eigvalsh(mass).min() > 1e-3


@pytest.mark.parametrize('n, passive', CONFIGS)
def test_mdot_minus_two_c_is_skew_symmetric(n, passive):
    rng = np.random.default_rng(20 + n)
    model = ArmModel(_params(n, passive))
    h = 1e-6
    for _ in range(10):
        q, qd = _random_state(rng, n)
        mdot = (model.mass_matrix(q + h * qd) - model.mass_matrix(q - h * qd)) / (2 * h)
        skew = mdot - 2.0 * model.coriolis_matrix(q, qd)
        np.testing.assert_allclose(skew + skew.T, 0.0, atol=1e-8)
        # and the matrix really is C: C qd equals the Coriolis vector.
        np.testing.assert_allclose(model.coriolis_matrix(q, qd) @ qd, model.coriolis(q, qd),
                                   atol=1e-12)


@pytest.mark.parametrize('n, passive', CONFIGS)
def test_mass_matrix_and_bias_match_numeric_lagrange_equations(n, passive):
    params = _params(n, passive)
    rng = np.random.default_rng(30 + n)
    for model in (ArmModel(params), make_model(params)):
        for _ in range(5):
            q, qd = _random_state(rng, n)
            np.testing.assert_allclose(model.mass_matrix(q), _mass_lagrange(params, q),
                                       rtol=0, atol=1e-12)
            bias = model.coriolis(q, qd) + model.gravity_torque(q)
            np.testing.assert_allclose(bias, _bias_lagrange(params, q, qd), rtol=0, atol=1e-7)


@pytest.mark.parametrize('n, passive', CONFIGS)
def test_jacobian_matches_finite_differences_of_fk(n, passive):
    rng = np.random.default_rng(40 + n)
    h = 1e-6
    for model in (ArmModel(_params(n, passive)), make_model(_params(n, passive))):
        for _ in range(10):
            q = _random_state(rng, n)[0]
            fd = np.array([(model.fk(q + h * e) - model.fk(q - h * e)) / (2 * h)
                           for e in np.eye(n)]).T
            np.testing.assert_allclose(model.jacobian(q), fd, atol=1e-9)


@pytest.mark.parametrize('n, passive', CONFIGS)
def test_jdot_qdot_matches_finite_differences_of_the_jacobian(n, passive):
    rng = np.random.default_rng(50 + n)
    h = 1e-6
    for model in (ArmModel(_params(n, passive)), make_model(_params(n, passive))):
        for _ in range(10):
            q, qd = _random_state(rng, n)
            jdot = (model.jacobian(q + h * qd) - model.jacobian(q - h * qd)) / (2 * h)
            np.testing.assert_allclose(model.jdot_qdot(q, qd), jdot @ qd, atol=1e-8)


@pytest.mark.parametrize('n, passive', CONFIGS)
def test_forward_dynamics_solves_the_lagrange_equations(n, passive):
    params = _params(n, passive)
    rng = np.random.default_rng(60 + n)
    for model in (ArmModel(params), make_model(params)):
        for _ in range(5):
            q, qd = _random_state(rng, n)
            tau = rng.uniform(-2.0, 2.0, n)
            qdd = model.forward_dynamics(q, qd, tau)
            lhs = _mass_lagrange(params, q) @ qdd + _bias_lagrange(params, q, qd)
            np.testing.assert_allclose(lhs, tau, atol=1e-6)


@pytest.mark.parametrize('n, passive', [c for c in CONFIGS if c[1]])
def test_decoupling_matrix_equals_effective_jacobian_over_effective_inertia(n, passive):
    params = _params(n, passive)
    act, pas = list(params.active), list(params.passive)
    rng = np.random.default_rng(70 + n)
    for model in (ArmModel(params), make_model(params)):
        for _ in range(10):
            q, qd = _random_state(rng, n)
            mass = _mass_lagrange(params, q)
            jac = model.jacobian(q)
            mpp_inv_mpa = np.linalg.inv(mass[np.ix_(pas, pas)]) @ mass[np.ix_(pas, act)]
            ja_eff = jac[:, act] - jac[:, pas] @ mpp_inv_mpa
            maa_eff = mass[np.ix_(act, act)] - mass[np.ix_(act, pas)] @ mpp_inv_mpa
            da, b = model.decoupling(q, qd)
            assert da.shape == (2, params.r)
            np.testing.assert_allclose(da, ja_eff @ np.linalg.inv(maa_eff), atol=1e-10)
            np.testing.assert_allclose(da, (jac @ np.linalg.inv(mass))[:, act], atol=1e-10)
            ja_m, maa_m = ArmModel(params).effective(q)
            np.testing.assert_allclose(ja_m, ja_eff, atol=1e-10)
            np.testing.assert_allclose(maa_m, maa_eff, atol=1e-10)
            # eq. (5): b = Jdot qd - J M^-1 (C qd + G), all terms independent here.
            h = 1e-6
            jdot_qd = (model.jacobian(q + h * qd) - model.jacobian(q - h * qd)) / (2 * h) @ qd
            b_ref = jdot_qd - jac @ np.linalg.solve(mass, _bias_lagrange(params, q, qd))
            np.testing.assert_allclose(b, b_ref, atol=1e-6)


def test_energy_is_kinetic_plus_potential():
    params = _params(3, (2,))
    rng = np.random.default_rng(80)
    for model in (ArmModel(params), Arm3Model(params)):
        q, qd = _random_state(rng, 3)
        expected = _kinetic(params, q, qd) + _potential(params, q)
        assert model.energy(q, qd) == pytest.approx(expected, abs=1e-12)


# -- the 3-link kernel ------------------------------------------------------------
@pytest.mark.parametrize('passive', [(2,), (0,), (1,), ()])
@pytest.mark.parametrize('gravity', [0.0, G])
def test_fast_kernel_agrees_with_general_model(passive, gravity):
    params = _params(3, passive, gravity)
    ref, fast = ArmModel(params), Arm3Model(params)
    rng = np.random.default_rng(90)
    for _ in range(50):
        q = rng.uniform(-6.0, 6.0, 3)
        qd = rng.uniform(-8.0, 8.0, 3)
        tau = rng.uniform(-5.0, 5.0, 3)
        for name, args in (('fk', (q,)), ('jacobian', (q,)), ('jdot_qdot', (q, qd)),
                           ('mass_matrix', (q,)), ('coriolis', (q, qd)),
                           ('gravity_torque', (q,)), ('forward_dynamics', (q, qd, tau)),
                           ('energy', (q, qd))):
            want = np.asarray(getattr(ref, name)(*args))
            got = np.asarray(getattr(fast, name)(*args))
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max(),
                                       err_msg=name)
        for got, want in zip(fast.decoupling(q, qd), ref.decoupling(q, qd)):
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
        if len(passive) == 1:
            px, py, vx, vy, d00, d01, d10, d11, bx, by = fast.task(*q.tolist(), *qd.tolist())
            da, b = ref.decoupling(q, qd)
            np.testing.assert_allclose([px, py], ref.fk(q), rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose([vx, vy], ref.jacobian(q) @ qd, rtol=1e-12, atol=1e-13)
            np.testing.assert_allclose([[d00, d01], [d10, d11]], da, rtol=1e-12, atol=1e-13)
            np.testing.assert_allclose([bx, by], b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_make_model_returns_the_fast_kernel_only_for_three_links():
    assert type(make_model(table1())) is Arm3Model
    assert type(make_model(_params(3, (0,)))) is Arm3Model
    assert type(make_model(_params(4, (1,)))) is ArmModel
    assert type(make_model(_params(2, ()))) is ArmModel
    with pytest.raises(FreejointValueError, match='^params'):
        make_model('table1')
    with pytest.raises(FreejointValueError, match='^params'):
        Arm3Model(_params(4, (1,)))


# -- inverse kinematics -------------------------------------------------------------
@pytest.mark.parametrize('n, passive', [(3, (2,)), (3, (0,)), (3, (1,)), (4, (0, 3)),
                                        (2, ())])
@pytest.mark.parametrize('branch', [1, -1])
def test_ik_reproduces_the_target_and_keeps_passive_angles(n, passive, branch):
    params = _params(n, passive)
    model = ArmModel(params)
    rng = np.random.default_rng(100 + n)
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, n)
        qp = q[list(passive)]
        sol = model.ik(model.fk(q), qp, branch)
        np.testing.assert_allclose(model.fk(sol), model.fk(q), atol=1e-12)
        np.testing.assert_array_equal(sol[list(passive)], qp)


def test_ik_branch_plus_one_gives_positive_q2_when_q3_is_zero():
    model = ArmModel(table1())
    up = model.ik([1.0, 0.3], [0.0], branch=1)
    down = model.ik([1.0, 0.3], [0.0], branch=-1)
    assert up[1] > 0.0 > down[1]
    # hand value: target (1, 0) with q3 = 0 is a 0.5 / 1.0 two-link arm:
    # cos(q2) = (1 - 0.25 - 1) / (2 * 0.5 * 1) = -0.25.
    sol = model.ik([1.0, 0.0], [0.0], branch=1)
    assert sol[1] == pytest.approx(math.acos(-0.25), abs=1e-12)


def test_ik_rejects_unreachable_targets_and_redundant_arms():
    model = ArmModel(table1())
    with pytest.raises(FreejointValueError, match='^p'):
        model.ik([0.2, 0.0], [0.0])   # reach with q3 = 0 is [0.5, 1.5]
    with pytest.raises(FreejointValueError, match='^q_passive'):
        model.ik([1.0, 0.0], [0.0, 1.0])
    with pytest.raises(FreejointValueError, match='^branch'):
        model.ik([1.0, 0.0], [0.0], branch=0)
    with pytest.raises(FreejointValueError, match='^params'):
        ArmModel(_params(4, (1,))).ik([1.0, 0.0], [0.0])


# -- argument validation ---------------------------------------------------------------
@pytest.mark.parametrize('model', [ArmModel(table1()), Arm3Model(table1())],
                         ids=['general', 'fast3'])
def test_model_methods_reject_bad_arguments_naming_them(model):
    with pytest.raises(FreejointValueError, match=r'^q: expected shape \(3,\), got \(2,\)'):
        model.fk([0.0, 0.0])
    with pytest.raises(FreejointValueError, match='^q:'):
        model.mass_matrix([0.0, float('inf'), 0.0])
    with pytest.raises(FreejointValueError, match='^qd:'):
        model.decoupling([0.0, 0.0, 0.0], [[0.0, 0.0, 0.0]])
    with pytest.raises(FreejointValueError, match='^tau:'):
        model.forward_dynamics([0.0] * 3, [0.0] * 3, [0.0, 0.0])
    with pytest.raises(FreejointValueError, match='^qd:'):
        model.energy([0.0] * 3, [0.0, float('nan'), 0.0])
