"""Behaviour of the simulated plant (held-torque RK4 with seeded disturbance)."""

import math

from freejoint_core.arm import ArmParams, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.plant import DEFAULT_DT_SUB, Plant
import numpy as np
import pytest

DT = 1e-3
FOUR_LINK = ArmParams(lengths=(0.3, 0.4, 0.5, 0.2), masses=(1.0, 2.0, 1.0, 1.0),
                      inertias=(0.1, 0.2, 0.1, 0.1), com=(0.1, 0.2, 0.3, 0.1), passive=(1,),
                      gravity=9.81)


def _energy(params, q, qd):
    """Kinetic + potential energy written out link by link (independent of the models)."""
    x = y = vx = vy = phi = omega = 0.0
    total = 0.0
    for length, c, m, inertia, qi, wi in zip(params.lengths, params.com, params.masses,
                                             params.inertias, q, qd):
        phi += qi
        omega += wi
        cy = y + c * math.sin(phi)
        cvx, cvy = vx - c * omega * math.sin(phi), vy + c * omega * math.cos(phi)
        total += 0.5 * m * (cvx ** 2 + cvy ** 2) + 0.5 * inertia * omega ** 2
        total += m * params.gravity * cy
        x, y = x + length * math.cos(phi), y + length * math.sin(phi)
        vx, vy = vx - length * omega * math.sin(phi), vy + length * omega * math.cos(phi)
    return total


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_energy_is_conserved_in_free_motion_over_ten_seconds(case):
    params = table1(case)
    plant = Plant(params, dist_bound=0.0, q0=[0.3, 1.2, -0.8], qd0=[1.0, -2.0, 3.0])
    e0 = _energy(params, plant.q, plant.qd)
    worst = 0.0
    for _ in range(10000):
        plant.step([0.0, 0.0], DT)
        worst = max(worst, abs(_energy(params, plant.q, plant.qd) - e0))
    assert plant.t == pytest.approx(10.0, abs=1e-9)
    assert np.abs(plant.qd).max() > 1.0    # it really moved
    assert worst < 1e-7                     # J, of ~13 J; measured ~7e-9 J


def test_energy_is_conserved_on_the_general_numpy_path():
    plant = Plant(FOUR_LINK, dist_bound=0.0, q0=[0.3, 1.2, -0.8, 0.5], qd0=[1.0, -2.0, 3.0, 0])
    e0 = _energy(FOUR_LINK, plant.q, plant.qd)
    for _ in range(500):
        plant.step([0.0, 0.0, 0.0], DT)
    assert abs(_energy(FOUR_LINK, plant.q, plant.qd) - e0) < 1e-7


@pytest.mark.parametrize('params, n', [(table1('horizontal'), 3),
                                       (ArmParams((0.3, 0.4, 0.5, 0.2), (1, 2, 1, 1),
                                                  (0.1, 0.2, 0.1, 0.1), (0.1, 0.2, 0.3, 0.1),
                                                  passive=(1,)), 4)])
def test_stretched_arm_spins_rigidly_without_torque(params, n):
    # A straight horizontal arm turning about joint 1 needs no torque at the other
    # joints (centrifugal forces point along the links): q(t) = (w t, 0, ...).
    qd0 = np.zeros(n)
    qd0[0] = 2.0
    plant = Plant(params, dist_bound=0.0, qd0=qd0)
    for _ in range(200 if n == 3 else 50):
        plant.step([0.0] * params.r, DT)
    expected = np.zeros(n)
    expected[0] = 2.0 * plant.t
    np.testing.assert_allclose(plant.q, expected, atol=1e-12)
    np.testing.assert_allclose(plant.qd, qd0, atol=1e-12)


def test_scalar_kernel_and_general_model_integrate_the_same_trajectory():
    runs = []
    for use_fast in (True, False):
        plant = Plant(table1('vertical'), seed=4, q0=[0.3, 1.2, -0.8], qd0=[1.0, -2.0, 3.0],
                      use_fast=use_fast)
        for k in range(100):
            plant.step([math.cos(0.05 * k), -0.3], DT)
        runs.append(np.concatenate([plant.q, plant.qd]))
    np.testing.assert_allclose(runs[0], runs[1], rtol=0, atol=1e-11)
    assert np.abs(runs[0][:3] - [0.3, 1.2, -0.8]).max() > 0.05


def test_hanging_arm_stays_at_rest():
    plant = Plant(table1('vertical'), dist_bound=0.0, q0=[-math.pi / 2, 0.0, 0.0])
    for _ in range(1000):
        plant.step([0.0, 0.0], DT)
    np.testing.assert_allclose(plant.q, [-math.pi / 2, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(plant.qd, 0.0, atol=1e-12)


def test_integrator_converges_with_fourth_order():
    def final_state(dt_sub):
        plant = Plant(table1('vertical'), dt_sub=dt_sub, dist_bound=0.0, q0=[0.3, 1.2, -0.8],
                      qd0=[1.0, -2.0, 3.0])
        for _ in range(50):
            plant.step([1.0, -0.5], 4e-3)
        return np.concatenate([plant.q, plant.qd])

    ref = final_state(1e-4)
    errors = [np.abs(final_state(h) - ref).max() for h in (4e-3, 2e-3, 1e-3)]
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    # RK4: halving the step divides the global error by ~2^4 = 16.
    assert all(12.0 < r < 20.0 for r in ratios), (errors, ratios)


def test_long_period_equals_consecutive_short_periods_with_the_same_torque():
    a = Plant(table1('vertical'), dt_sub=5e-4, dist_bound=0.0, q0=[0.3, 1.2, -0.8])
    b = Plant(table1('vertical'), dt_sub=5e-4, dist_bound=0.0, q0=[0.3, 1.2, -0.8])
    a.step([0.7, -0.2], 2e-3)
    b.step([0.7, -0.2], 1e-3)
    b.step([0.7, -0.2], 1e-3)
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.qd, b.qd)
    assert (a.k, b.k) == (1, 2)


def test_disturbance_is_one_seeded_uniform_draw_per_step_within_the_bound():
    plant = Plant(table1('vertical'), dist_bound=0.5, seed=7, q0=[0.3, 1.2, -0.8])
    rng = np.random.default_rng(7)
    for _ in range(200):
        plant.step([0.0, 0.0], 2e-3)
        expected = rng.uniform(-0.5, 0.5, 3)
        np.testing.assert_array_equal(plant.last_disturbance, expected)
        assert max(abs(d) for d in plant.last_disturbance) <= 0.5


def test_disturbance_acts_on_every_joint_including_the_passive_one():
    # Same arm, all joints active and no disturbance, driven by tau + d by hand:
    # the dynamics do not care which joints are called passive.
    real = table1('vertical')
    disturbed = Plant(real, dist_bound=0.5, seed=3, q0=[0.3, 1.2, -0.8])
    all_active = ArmParams(real.lengths, real.masses, real.inertias, real.com, passive=(),
                           gravity=real.gravity)
    manual = Plant(all_active, dist_bound=0.0, q0=[0.3, 1.2, -0.8])
    rng = np.random.default_rng(3)
    for k in range(300):
        tau = [math.sin(0.01 * k), 0.5]
        disturbed.step(tau, DT)
        d = rng.uniform(-0.5, 0.5, 3)
        manual.step([tau[0] + d[0], tau[1] + d[1], d[2]], DT)
    np.testing.assert_allclose(disturbed.q, manual.q, rtol=0, atol=1e-14)
    np.testing.assert_allclose(disturbed.qd, manual.qd, rtol=0, atol=1e-14)
    # and the disturbance is not negligible: without it the passive joint ends elsewhere.
    undisturbed = Plant(real, dist_bound=0.0, q0=[0.3, 1.2, -0.8])
    for k in range(300):
        undisturbed.step([math.sin(0.01 * k), 0.5], DT)
    assert abs(undisturbed.q[2] - disturbed.q[2]) > 1e-6


def test_same_seed_reproduces_and_other_seed_differs():
    runs = []
    for seed in (1, 1, 2):
        plant = Plant(table1('horizontal'), seed=seed, q0=[0.3, 1.2, -0.8])
        for _ in range(100):
            plant.step([0.1, 0.1], DT)
        runs.append(plant.q)
    np.testing.assert_array_equal(runs[0], runs[1])
    assert np.abs(runs[0] - runs[2]).max() > 1e-6


def test_zero_bound_disables_the_disturbance():
    plant = Plant(table1('horizontal'), dist_bound=0.0)
    plant.step([0.0, 0.0], DT)
    assert plant.last_disturbance == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(plant.q, [0.0, 0.0, 0.0])


def test_time_step_count_and_reset():
    plant = Plant(table1('vertical'), seed=5, q0=[0.3, 1.2, -0.8])
    for _ in range(10):
        plant.step([0.0, 0.0], DT)
    first = (plant.q, plant.qd)
    assert plant.k == 10
    assert plant.t == pytest.approx(0.01, abs=1e-15)
    plant.reset()
    assert (plant.k, plant.t) == (0, 0.0)
    np.testing.assert_array_equal(plant.q, [0.3, 1.2, -0.8])
    for _ in range(10):
        plant.step([0.0, 0.0], DT)
    np.testing.assert_array_equal(plant.q, first[0])
    np.testing.assert_array_equal(plant.qd, first[1])
    plant.reset(q0=[0.0, 0.5, 0.5], qd0=[0.0, 0.0, 1.0], seed=6)
    np.testing.assert_array_equal(plant.q, [0.0, 0.5, 0.5])
    np.testing.assert_array_equal(plant.qd, [0.0, 0.0, 1.0])


def test_state_attributes_are_copies():
    plant = Plant(table1('horizontal'), dist_bound=0.0)
    q = plant.q
    q[0] = 1.0
    assert plant.q[0] == 0.0
    assert DEFAULT_DT_SUB == plant.dt_sub


@pytest.mark.parametrize('tau, dt, match', [
    ([0.0, float('nan')], DT, '^tau_active'),
    ([0.0, float('inf')], DT, '^tau_active'),
    ([0.0, 0.0, 0.0], DT, r'^tau_active: expected 2 finite values'),
    (np.zeros((2, 1)), DT, '^tau_active'),
    ('ab', DT, '^tau_active'),
    (None, DT, '^tau_active'),
    ([0.0, 0.0], 1.2e-3, '^dt: .* not an integer multiple'),
    ([0.0, 0.0], 0.0, '^dt'),
    ([0.0, 0.0], -1e-3, '^dt'),
    ([0.0, 0.0], float('nan'), '^dt'),
])
def test_step_rejects_bad_arguments_naming_them(tau, dt, match):
    plant = Plant(table1('horizontal'))
    with pytest.raises(FreejointValueError, match=match):
        plant.step(tau, dt)
    assert plant.k == 0


@pytest.mark.parametrize('kwargs, match', [
    ({'dt_sub': 0.0}, '^dt_sub'),
    ({'dt_sub': float('nan')}, '^dt_sub'),
    ({'dist_bound': -0.1}, '^dist_bound'),
    ({'q0': [0.0, 0.0]}, r'^q0: expected shape \(3,\)'),
    ({'qd0': [0.0, 0.0, float('nan')]}, '^qd0'),
    ({'seed': -1}, '^seed'),
    ({'seed': 1.5}, '^seed'),
])
def test_constructor_rejects_bad_arguments_naming_them(kwargs, match):
    with pytest.raises(FreejointValueError, match=match):
        Plant(table1('horizontal'), **kwargs)


def test_constructor_rejects_non_params():
    with pytest.raises(FreejointValueError, match='^params'):
        Plant({'lengths': (0.5, 0.5, 0.5)})


def test_a_diverging_step_raises_and_keeps_the_last_finite_state():
    from freejoint_core.errors import PlantDivergedError
    plant = Plant(table1('vertical'), 0.0005, dist_bound=0.0, q0=[0.1, 0.2, 0.3])
    plant.step([1.0, -1.0], 0.001)
    q, qd, k = plant.q, plant.qd, plant.k
    with pytest.raises(PlantDivergedError, match='^tau_active: the integration over step 1'):
        plant.step([1e306, -1e306], 0.001)
    assert plant.q.tolist() == q.tolist() and plant.qd.tolist() == qd.tolist()
    assert plant.k == k
    plant.step([0.0, 0.0], 0.001)
    assert plant.k == k + 1


def test_a_step_from_an_infinite_angle_is_a_divergence_not_a_math_error():
    from freejoint_core.errors import PlantDivergedError
    plant = Plant(table1('vertical'), 0.0005, dist_bound=0.0, q0=[0.1, 0.2, 0.3])
    plant._q = [math.inf, 0.2, 0.3]   # what a blown-up earlier step would leave in fast3
    with pytest.raises(PlantDivergedError, match='diverged'):
        plant.step([0.0, 0.0], 0.001)


def test_stop_zeroes_every_velocity_and_keeps_the_position():
    plant = Plant(table1('vertical'), dist_bound=0.0)
    for _ in range(50):
        plant.step([0.0, 0.0], 0.001)
    q = plant.q.tolist()
    assert any(v != 0.0 for v in plant.qd.tolist())   # the released arm was falling
    plant.stop()
    assert plant.q.tolist() == q
    assert plant.qd.tolist() == [0.0, 0.0, 0.0]
