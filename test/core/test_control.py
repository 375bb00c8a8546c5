"""Behaviour of the robust control law (paper eqs. 15-19) and its safeguards."""

import math

from freejoint_core.arm import ArmModel, ArmParams, table1
from freejoint_core.control import (
    Gains, ROBUST_INTERNALS, RobustController, STATUS_NEAR_SINGULAR, STATUS_OK,
    STATUS_TORQUE_LIMITED)
from freejoint_core.errors import FreejointValueError
import numpy as np
import pytest

DT = 1e-3
NOMINAL = table1('vertical').scaled(0.7)
FOUR_LINK = ArmParams(lengths=(0.3, 0.4, 0.5, 0.2), masses=(1.0, 2.0, 1.0, 1.0),
                      inertias=(0.1, 0.2, 0.1, 0.1), com=(0.1, 0.2, 0.3, 0.1), passive=(1,),
                      gravity=9.81)
# q = (0, pi/2, -pi/2): links along +x, +y, +x, so p = (1.0, 0.5).
Q_HAND = (0.0, math.pi / 2, -math.pi / 2)


def _random_tick(rng, n):
    q = rng.uniform(-math.pi, math.pi, n)
    q[1] = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 2.8)   # away from q2 = 0 (singular)
    return (q, rng.uniform(-2.0, 2.0, n), rng.uniform(-0.5, 0.5, 2), rng.uniform(-1, 1, 2),
            rng.uniform(-3.0, 3.0, 2))


def test_default_gains_are_the_papers():
    g = Gains()
    assert g.K == (100.0, 100.0) and g.Lambda == (50.0, 50.0) and g.R == (2.0, 2.0)
    assert g.Gamma == (0.01,) * 5 and g.sigma == (0.1,) * 5 and g.theta0 == (0.0,) * 5
    assert (g.epsilon, g.h_form, g.robust, g.det_threshold, g.tau_limit) == (
        0.1, 'sum', True, 1e-7, None)


def test_scalar_gains_are_broadcast():
    g = Gains(K=10, Lambda=5.0, R=1.0, Gamma=0.5, sigma=0.2, theta0=1, tau_limit=3)
    assert (g.K, g.Lambda, g.R) == ((10.0, 10.0), (5.0, 5.0), (1.0, 1.0))
    assert (g.Gamma, g.sigma, g.theta0) == ((0.5,) * 5, (0.2,) * 5, (1.0,) * 5)
    assert g.tau_limit == 3.0


# -- the closed loop with an exact model --------------------------------------------
@pytest.mark.parametrize('params, use_fast', [
    (table1('vertical'), True), (table1('vertical'), False), (table1('horizontal'), True),
    (FOUR_LINK, True)], ids=['fast', 'general', 'horizontal', 'four-link'])
def test_exact_model_without_robust_term_gives_the_linear_error_dynamics(params, use_fast):
    # nominal == real, no disturbance, robust off: pdd = b + Da tau = v, so
    # edd + (K + Lam) edot + K Lam e = 0 exactly (checked with the continuous dynamics).
    gains = Gains(K=(80.0, 120.0), Lambda=(40.0, 60.0), robust=False)
    ctl = RobustController(params, gains, use_fast=use_fast)
    assert ctl.uses_fast_path == (use_fast and params.n == 3)
    model = ArmModel(params)
    rng = np.random.default_rng(1)
    k, lam = np.array(gains.K), np.array(gains.Lambda)
    for _ in range(20):
        q, qd, p_d, pd_d, pdd_d = _random_tick(rng, params.n)
        out = ctl.step(q, qd, p_d, pd_d, pdd_d, DT)
        tau = np.zeros(params.n)
        tau[list(params.active)] = out.tau
        qdd = model.forward_dynamics(q, qd, tau)
        pdd = model.jacobian(q) @ qdd + model.jdot_qdot(q, qd)
        e = model.fk(q) - p_d
        edot = model.jacobian(q) @ qd - pd_d
        residual = (pdd - pdd_d) + (k + lam) * edot + k * lam * e
        assert np.abs(residual).max() < 1e-8 * (1.0 + np.abs(k * lam * e).max())
        np.testing.assert_allclose(out.e, e, atol=1e-14)
        np.testing.assert_allclose(out.edot, edot, atol=1e-13)
        assert out.status == STATUS_OK


def test_torque_is_the_minimum_norm_solution_for_a_redundant_arm():
    ctl = RobustController(FOUR_LINK, Gains())
    model = ArmModel(FOUR_LINK)
    rng = np.random.default_rng(2)
    for _ in range(10):
        q, qd, p_d, pd_d, pdd_d = _random_tick(rng, 4)
        out = ctl.step(q, qd, p_d, pd_d, pdd_d, DT)
        da, _ = model.decoupling(q, qd)
        null = np.linalg.svd(da)[2][-1]       # Da null direction (r = 3 > m = 2)
        assert abs(null @ out.tau) < 1e-9 * (1.0 + np.abs(out.tau).max())


@pytest.mark.parametrize('use_fast', [True, False])
def test_pseudoinverse_is_a_right_inverse_da_tau_equals_v_plus_dv_minus_b(use_fast):
    gains = Gains(theta0=(0.5, 0.1, 0.2, 0.3, 0.4))
    ctl = RobustController(NOMINAL, gains, use_fast=use_fast)
    model = ArmModel(NOMINAL)
    rng = np.random.default_rng(3)
    k, lam = np.array(gains.K), np.array(gains.Lambda)
    for _ in range(20):
        q, qd, p_d, pd_d, pdd_d = _random_tick(rng, 3)
        out = ctl.step(q, qd, p_d, pd_d, pdd_d, DT)
        da, b = model.decoupling(q, qd)
        v = pdd_d - (k + lam) * out.edot - k * lam * out.e
        np.testing.assert_allclose(da @ out.tau, v + out.internal['delta_v'] - b, rtol=1e-10,
                                   atol=1e-9)
        assert out.internal['det'] == pytest.approx(abs(np.linalg.det(da @ da.T)), rel=1e-10)


# -- the robust term and the adaptation, hand values ------------------------------------
def _hand_tick(ctl, e=(0.01, 0.0), edot=(0.0, 0.02), dt=DT):
    """State with qd = 0 at Q_HAND: p = (1, 0.5), J qd = 0."""
    p_d = (1.0 - e[0], 0.5 - e[1])
    pd_d = (-edot[0], -edot[1])
    return ctl.step(Q_HAND, (0.0, 0.0, 0.0), p_d, pd_d, (0.0, 0.0), dt)


@pytest.mark.parametrize('use_fast', [True, False])
def test_robust_term_and_adaptation_match_hand_values(use_fast):
    ctl = RobustController(NOMINAL, Gains(theta0=(1.0,) * 5), use_fast=use_fast)
    out = _hand_tick(ctl)
    # s = edot + 50 e = (0.5, 0.02); alpha = 2 s = (1, 0.04); h = |alpha| + 0.1
    # psi = (1, |qd|^2 = 0, |pdd_d| = 0, |edot| = 0.02, |e| = 0.01), rho = 1.03
    na = math.sqrt(1.0016)
    h = na + 0.1
    np.testing.assert_allclose(out.s, [0.5, 0.02], atol=1e-13)
    assert out.internal['rho_hat'] == pytest.approx(1.03, abs=1e-13)
    np.testing.assert_allclose(out.internal['delta_v'], [-1.03 / h, -1.03 * 0.04 / h], atol=1e-12)
    np.testing.assert_allclose(out.p, [1.0, 0.5], atol=1e-15)
    psi = np.array([1.0, 0.0, 0.0, 0.02, 0.01])
    a = math.exp(-0.01 * 0.1 * DT)
    expected = a * 1.0 + (1.0 - a) * (1.0016 / h) * psi / 0.1
    np.testing.assert_allclose(out.internal['theta_hat'], expected, rtol=1e-12)
    np.testing.assert_allclose(ctl.theta, expected, rtol=1e-12)


@pytest.mark.parametrize('use_fast', [True, False])
@pytest.mark.parametrize('h_form, e, dv_x', [
    ('sum', 0.0005, -0.05 / 0.15),   # |alpha| = 0.05 < eps: h = 0.15
    ('sat', 0.0005, -0.05 / 0.1),    # h = eps
    ('sum', 0.01, -1.0 / 1.1),       # |alpha| = 1: h = 1.1
    ('sat', 0.01, -1.0),             # h = |alpha|: |dv| = rho exactly
])
def test_chattering_function_forms(use_fast, h_form, e, dv_x):
    gains = Gains(theta0=(1.0, 0.0, 0.0, 0.0, 0.0), h_form=h_form)
    out = _hand_tick(RobustController(NOMINAL, gains, use_fast=use_fast), e=(e, 0.0),
                     edot=(0.0, 0.0))
    assert out.internal['rho_hat'] == 1.0
    np.testing.assert_allclose(out.internal['delta_v'], [dv_x, 0.0], atol=1e-14)


@pytest.mark.parametrize('use_fast', [True, False])
def test_torque_uses_the_estimate_before_the_update(use_fast):
    ctl = RobustController(NOMINAL, Gains(), use_fast=use_fast)   # theta0 = 0
    out = _hand_tick(ctl)
    assert out.internal['rho_hat'] == 0.0
    np.testing.assert_array_equal(out.internal['delta_v'], [0.0, 0.0])
    theta = out.internal['theta_hat']
    assert theta[0] > 0.0 and theta[3] > 0.0
    assert theta[1] == 0.0 and theta[2] == 0.0      # psi_2 = psi_3 = 0 here
    assert _hand_tick(ctl).internal['rho_hat'] == pytest.approx(
        theta[0] + 0.02 * theta[3] + 0.01 * theta[4], rel=1e-12)


@pytest.mark.parametrize('use_fast', [True, False])
def test_sigma_modification_keeps_theta_nonnegative_with_a_large_step(use_fast):
    # Gamma sigma dt = 5: explicit Euler would multiply theta by 1 - 5 = -4.
    dt = 0.05
    gains = Gains(Gamma=(100.0,) * 5, sigma=(1.0,) * 5)
    ctl = RobustController(NOMINAL, gains, use_fast=use_fast)
    rng = np.random.default_rng(4)
    lowest = np.inf
    for k in range(2000):
        if k % 2:
            before = ctl.theta
            out = _hand_tick(ctl, e=(0.0, 0.0), edot=(0.0, 0.0), dt=dt)   # no error: decay
            np.testing.assert_allclose(out.internal['theta_hat'], math.exp(-5.0) * before,
                                       rtol=1e-12)
        else:
            big = rng.uniform(-1.0, 1.0, 2)
            out = _hand_tick(ctl, e=big, edot=10.0 * rng.uniform(-1.0, 1.0, 2), dt=dt)
        lowest = min(lowest, out.internal['theta_hat'].min())
    assert lowest >= 0.0


@pytest.mark.parametrize('use_fast', [True, False])
def test_adaptation_settles_at_the_low_pass_fixed_point(use_fast):
    # Constant input u psi: theta -> u psi / sigma (the low-pass of Remark 2).
    ctl = RobustController(NOMINAL, Gains(Gamma=(10.0,) * 5, sigma=(2.0,) * 5),
                           use_fast=use_fast)
    for _ in range(200):
        out = _hand_tick(ctl, dt=0.01)
    na2 = 1.0016
    u = na2 / (math.sqrt(na2) + 0.1)
    np.testing.assert_allclose(out.internal['theta_hat'],
                               u * np.array([1.0, 0.0, 0.0, 0.02, 0.01]) / 2.0,
                               rtol=1e-12)


@pytest.mark.parametrize('use_fast', [True, False])
def test_adaptation_without_sigma_integrates_exactly(use_fast):
    ctl = RobustController(NOMINAL, Gains(sigma=(0.0,) * 5, Gamma=(3.0,) * 5),
                           use_fast=use_fast)
    out = _hand_tick(ctl, dt=0.002)
    u = 1.0016 / (math.sqrt(1.0016) + 0.1)
    np.testing.assert_allclose(out.internal['theta_hat'],
                               3.0 * u * np.array([1.0, 0, 0, 0.02, 0.01]) * 0.002,
                               rtol=1e-12)


@pytest.mark.parametrize('use_fast', [True, False])
def test_robust_off_means_no_robust_term_and_no_adaptation(use_fast):
    ctl = RobustController(NOMINAL, Gains(robust=False, theta0=(1.0,) * 5), use_fast=use_fast)
    out = _hand_tick(ctl)
    assert out.internal['rho_hat'] == 0.0
    np.testing.assert_array_equal(out.internal['delta_v'], [0.0, 0.0])
    np.testing.assert_array_equal(out.internal['theta_hat'], [1.0] * 5)


# -- safeguards beyond the paper -----------------------------------------------------
def _det_at(q2):
    da, _ = ArmModel(NOMINAL).decoupling([0.3, q2, 1.0], [0.0, 0.0, 0.0])
    return abs(np.linalg.det(da @ da.T)), da


@pytest.mark.parametrize('use_fast', [True, False])
def test_fallback_is_used_and_bounded_at_a_singular_configuration(use_fast):
    # q2 = 0 (links 1 and 2 aligned) makes the nominal Da singular.
    thr = 1e-7
    det, da = _det_at(0.0)
    assert det < 1e-12        # round-off only; threshold 1e-7
    ctl = RobustController(NOMINAL, Gains(det_threshold=thr), use_fast=use_fast)
    out = ctl.step([0.3, 0.0, 1.0], [0.5, -0.2, 0.1], (0.9, 0.4), (0.1, 0.0), (0.0, 1.0), DT)
    assert out.status & STATUS_NEAR_SINGULAR
    assert np.all(np.isfinite(out.tau))
    _, b = ArmModel(NOMINAL).decoupling([0.3, 0.0, 1.0], [0.5, -0.2, 0.1])
    k, lam = np.array(ctl.gains.K), np.array(ctl.gains.Lambda)
    w = np.array([0.0, 1.0]) - (k + lam) * out.edot - k * lam * out.e + out.internal['delta_v'] - b
    bound = math.sqrt((np.sum(da ** 2) + math.sqrt(thr)) / thr)   # documented bound
    assert np.linalg.norm(out.tau) <= bound * np.linalg.norm(w)


@pytest.mark.parametrize('use_fast', [True, False])
def test_fallback_switches_on_continuously_at_the_threshold(use_fast):
    thr = 1e-7
    lo, hi = 1e-6, 0.5            # det < thr at lo, > thr at hi; det grows with |q2|
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _det_at(mid)[0] < thr else (lo, mid)
    ctl = RobustController(NOMINAL, Gains(det_threshold=thr), use_fast=use_fast)
    args = ([0.0, 0.0, 0.0], (0.9, 0.4), (0.1, 0.0), (0.0, 1.0), DT)
    below = ctl.step([0.3, lo * (1 - 1e-9), 1.0], *args)
    above = ctl.step([0.3, hi * (1 + 1e-9), 1.0], *args)
    assert below.status == STATUS_NEAR_SINGULAR and above.status == STATUS_OK
    assert np.abs(below.tau - above.tau).max() < 1e-4 * np.abs(above.tau).max()


@pytest.mark.parametrize('use_fast', [True, False])
def test_torque_limit_clips_each_joint_and_flags_it(use_fast):
    flat = table1('horizontal').scaled(0.7)    # no gravity: zero torque at rest on target
    free = RobustController(flat, Gains(), use_fast=use_fast)
    limited = RobustController(flat, Gains(tau_limit=(0.5, 2.0)), use_fast=use_fast)
    args = (Q_HAND, (0.0, 0.0, 0.0), (0.95, 0.45), (0.0, 0.0), (0.0, 0.0), DT)
    raw = free.step(*args).tau
    assert abs(raw[0]) > 0.5 and abs(raw[1]) > 2.0
    out = limited.step(*args)
    np.testing.assert_array_equal(out.tau, np.sign(raw) * [0.5, 2.0])
    assert out.status == STATUS_TORQUE_LIMITED
    calm = limited.step(Q_HAND, (0.0, 0.0, 0.0), (1.0, 0.5), (0.0, 0.0), (0.0, 0.0), DT)
    assert calm.status == STATUS_OK


# -- the two implementations ---------------------------------------------------------
@pytest.mark.parametrize('gains', [
    Gains(), Gains(h_form='sat', theta0=(1.0, 2.0, 0.5, 0.1, 3.0)),
    Gains(robust=False, tau_limit=5.0), Gains(Gamma=(50.0,) * 5, tau_limit=(20.0, 30.0))],
    ids=['paper', 'sat', 'nominal-id', 'fast-adapt'])
def test_scalar_tick_agrees_with_general_numpy_path(gains):
    fast = RobustController(NOMINAL, gains)
    ref = RobustController(NOMINAL, gains, use_fast=False)
    assert fast.uses_fast_path and not ref.uses_fast_path
    rng = np.random.default_rng(5)
    for k in range(100):
        q, qd, p_d, pd_d, pdd_d = _random_tick(rng, 3)
        singular = k == 50
        if singular:
            q[1] = 0.0          # one singular tick: DLS amplifies round-off, looser check
        a = fast.step(q, qd, p_d, pd_d, pdd_d, DT)
        b = ref.step(q, qd, p_d, pd_d, pdd_d, DT)
        assert a.status == b.status
        assert list(a.internal) == list(b.internal) == [v.name for v in ROBUST_INTERNALS]
        for name in ('tau', 'e', 'edot', 's', 'p') + tuple(a.internal):
            x, y = (np.asarray(out.internal[name] if name in out.internal
                               else getattr(out, name), float) for out in (a, b))
            assert x.shape == y.shape, name
            tol = 1e-6 if singular else 1e-9
            np.testing.assert_allclose(x, y, rtol=tol, atol=tol * (1 + np.abs(y).max()),
                                       err_msg=name)


def test_output_shapes_and_types():
    out = RobustController(NOMINAL).step(Q_HAND, [0.0] * 3, (1.0, 0.5), (0, 0), (0, 0), DT)
    for name, shape in (('tau', (2,)), ('e', (2,)), ('edot', (2,)), ('s', (2,)), ('p', (2,))):
        assert getattr(out, name).shape == shape, name
    # the internal values as the law declares them, in order ('m': the task dimension 2)
    assert [v.name for v in ROBUST_INTERNALS] == list(out.internal)
    for value in ROBUST_INTERNALS:
        got = out.internal[value.name]
        if value.shape:
            assert got.shape == tuple(2 if d == 'm' else d for d in value.shape), value.name
        else:
            assert isinstance(got, float), value.name
    assert isinstance(out.status, int)


# -- configuration ---------------------------------------------------------------------
def test_set_gains_keeps_theta_and_reset_restores_theta0():
    ctl = RobustController(NOMINAL, Gains())
    _hand_tick(ctl)
    theta = ctl.theta
    assert theta[0] > 0.0
    ctl.set_gains(Gains(K=(10.0, 10.0), theta0=(2.0,) * 5))
    np.testing.assert_array_equal(ctl.theta, theta)
    ctl.reset()
    np.testing.assert_array_equal(ctl.theta, [2.0] * 5)


def test_set_nominal_switches_the_model():
    ctl = RobustController(NOMINAL, Gains(robust=False))
    args = (Q_HAND, (0.1, 0.2, 0.3), (0.95, 0.45), (0.0, 0.0), (0.0, 0.0), DT)
    before = ctl.step(*args).tau
    ctl.set_nominal(table1('vertical'))
    after = ctl.step(*args).tau
    exact = RobustController(table1('vertical'), Gains(robust=False)).step(*args).tau
    np.testing.assert_array_equal(after, exact)
    assert np.abs(after - before).max() > 1e-3


# -- argument validation -----------------------------------------------------------------
@pytest.mark.parametrize('field, value', [
    ('K', (0.0, 100.0)), ('K', -1.0), ('K', (100.0, 100.0, 100.0)), ('Lambda', (50.0, 0.0)),
    ('R', (2.0, -2.0)), ('epsilon', 0.0), ('epsilon', float('nan')), ('Gamma', (-0.01,) * 5),
    ('Gamma', (0.01,) * 4), ('sigma', (0.1, 0.1, 0.1, 0.1, -0.1)), ('theta0', (-1.0,) * 5),
    ('h_form', 'max'), ('robust', 'yes'), ('det_threshold', 0.0), ('tau_limit', 0.0),
    ('tau_limit', (1.0, -1.0)), ('K', 'abc'),
])
def test_gains_reject_bad_fields_naming_them(field, value):
    with pytest.raises(FreejointValueError, match=f'^{field}'):
        Gains(**{field: value})


def test_controller_rejects_torque_limit_of_wrong_length_and_bad_types():
    with pytest.raises(FreejointValueError, match=r'^tau_limit: expected shape \(2,\)'):
        RobustController(NOMINAL, Gains(tau_limit=(1.0, 1.0, 1.0)))
    with pytest.raises(FreejointValueError, match='^nominal_params'):
        RobustController(NOMINAL.lengths)
    with pytest.raises(FreejointValueError, match='^gains'):
        RobustController(NOMINAL, {'K': 1.0})


@pytest.mark.parametrize('use_fast', [True, False])
@pytest.mark.parametrize('index, value, match', [
    (0, [0.0, 0.0], '^q:'),
    (0, np.zeros((3, 1)), '^q:'),
    (0, [0.0, float('nan'), 0.0], '^q:'),
    (1, [0.0, 0.0, float('inf')], '^qd:'),
    (1, 'abc', '^qd:'),
    (2, [1.0], '^p_d:'),
    (3, [0.0, float('nan')], '^pd_d:'),
    (4, None, '^pdd_d:'),
    (5, 0.0, '^dt:'),
    (5, -1e-3, '^dt:'),
    (5, float('nan'), '^dt:'),
    (5, 'fast', '^dt:'),
])
def test_step_rejects_bad_inputs_naming_them(use_fast, index, value, match):
    ctl = RobustController(NOMINAL, Gains(theta0=(1.0,) * 5), use_fast=use_fast)
    args = [Q_HAND, (0.0, 0.0, 0.0), (1.0, 0.5), (0.0, 0.0), (0.0, 0.0), DT]
    args[index] = value
    with pytest.raises(FreejointValueError, match=match):
        ctl.step(*args)
    np.testing.assert_array_equal(ctl.theta, [1.0] * 5)   # no state change on error


@pytest.mark.parametrize('nullspace', [None, 'kd', 'posture'])
@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_every_joint_driven_the_scalar_path_gives_the_general_paths_torques(case, nullspace):
    from dataclasses import replace
    from freejoint_core.internal import NullSpace
    ns = {None: None, 'kd': NullSpace(kd=3.0),
          'posture': NullSpace(kd=(1.0, 2.0, 3.0), kp=(4.0, 5.0, 6.0),
                               posture=(0.1, 1.0, -0.5))}[nullspace]
    nominal = replace(table1(case), passive=()).scaled(0.7)
    gains = Gains(tau_limit=(300.0, 200.0, 200.0))
    fast = RobustController(nominal, gains, nullspace=ns)
    ref = RobustController(nominal, gains, use_fast=False, nullspace=ns)
    assert fast.uses_fast_path and not ref.uses_fast_path
    rng = np.random.default_rng(7)
    statuses = set()
    for _ in range(300):     # adaptation carried over the ticks; some near-singular states
        q, qd = rng.uniform(-3.0, 3.0, 3), rng.uniform(-2.0, 2.0, 3)
        if _ % 50 == 0:
            q[1] = 0.0       # links 1 and 2 in line: Da Da^T near singular
        args = (q, qd, rng.uniform(-0.5, 0.5, 2), rng.uniform(-1.0, 1.0, 2),
                rng.uniform(-2.0, 2.0, 2), 1e-3)
        a, b = fast.step(*args), ref.step(*args)
        assert np.allclose(a.tau, b.tau, rtol=1e-12, atol=1e-12)
        ia, ib = a.internal, b.internal
        assert np.allclose(ia['theta_hat'], ib['theta_hat'], rtol=1e-12, atol=1e-15)
        assert a.status == b.status and ia['det'] == pytest.approx(ib['det'], rel=1e-12)
        statuses.add(a.status)
    assert len(statuses) > 1
