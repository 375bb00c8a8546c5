"""The batched simulator runs the offline runner's loop: per run equal to the scalar runs."""
import math

from freejoint_core import batch
from freejoint_core.arm import ArmParams, table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.offline import run_case
from freejoint_core.plant import Plant
import numpy as np
import pytest

DURATION = 1.5


def _sample():
    """Six runs: both cases, every axis on in some run (two of them diverge)."""
    runs = batch.run_defaults(6)
    runs['vertical'][:] = [False, True, True, False, True, False]
    runs['noise_q'][:] = [0.0, 1e-3, 0.0, 0.0, 2e-4, 0.0]
    runs['noise_qd'][:] = [0.0, 1e-2, 0.0, 0.0, 0.0, 5e-3]
    runs['noise_tau'][:] = [0.0, 0.0, 0.1, 0.0, 0.0, 0.05]
    runs['delay'][:] = [0, 2, 25, 1, 0, 3]
    runs['lag'][:] = [0.0, 0.005, 0.0, 0.002, 0.01, 0.0]
    runs['dist_type'][:] = [0, 1, 0, 1, 0, 0]
    runs['dist_bound'][:] = [0.5, 0.5, 1.0, 0.0, 2.0, 0.5]
    runs['scale_mass'][:] = [0.7, 0.5, 1.2, 0.7, 0.3, 0.9]
    runs['scale_inertia'][:] = [0.7, 0.9, 1.2, 0.4, 0.7, 0.9]
    runs['scale_lc'][:] = [0.7, 0.6, 1.0, 1.3, 0.7, 1.1]
    runs['q3_0_deg'][:] = [120.0, 100.0, 120.0, 140.0, 120.0, 110.0]
    runs['seed'][:] = [0, 3, 5, 7, 11, 13]
    return runs


@pytest.fixture(scope='module')
def references():
    runs = _sample()
    return runs, [batch.run_scalar({k: v[i] for k, v in runs.items()}, duration=DURATION)
                  for i in range(6)]


@pytest.mark.parametrize('engine', batch.ENGINES)
def test_each_batched_run_follows_its_scalar_run_to_1e9_m_with_every_axis_on(
        references, engine):
    runs, refs = references
    out = batch.simulate(runs, duration=DURATION, record_trace=True, engine=engine)
    assert {bool(v) for v in runs['vertical']} == {False, True}
    stopped = sum(_follows(out, i, metrics, p) for i, (metrics, p) in enumerate(refs))
    assert stopped >= 1   # the divergence rule is exercised


def _follows(out, i, metrics, p):
    """Assert batched run ``i`` of ``out`` is the scalar run (metrics, p); return if it stopped."""
    ticks = len(p)
    assert out['ticks'][i] == ticks == metrics['ticks']
    assert np.max(np.abs(out['p'][i, :ticks] - p)) <= 1e-9
    assert np.all(np.isnan(out['p'][i, ticks:]))
    div = metrics['diverged_at_s']
    assert (math.isnan(div) and math.isnan(out['diverged_at_s'][i])) \
        or out['diverged_at_s'][i] == div
    for name in batch.METRICS:
        if name not in ('diverged_at_s', 'ticks'):
            assert out[name][i] == pytest.approx(metrics[name], rel=1e-9, abs=1e-9), name
    return not math.isnan(div)


@pytest.mark.parametrize('law', ['vsc', 'tdc'])
def test_each_task_law_kernel_run_follows_its_scalar_step_to_1e9_m_with_every_axis_on(law):
    # The kernel does the task law's operations in the scalar step's order (task_law,
    # law_vsc, law_tdc: plain float arithmetic, no BLAS), so a run equals its scalar run up
    # to what the compiled closed forms round otherwise (1e-9 m over 1500 ticks, as the
    # paper's law); a diverging run diverges at the same tick.
    runs = _sample()
    out = batch.simulate_law(runs, law=law, duration=DURATION, record_trace=True)
    robust = batch.simulate(runs, duration=DURATION)
    stopped = 0
    for i in range(6):
        metrics, p = batch.run_scalar({k: v[i] for k, v in runs.items()}, duration=DURATION,
                                      law=law)
        stopped += _follows(out, i, metrics, p)
        assert out['theta_final_norm'][i] == 0.0     # no adaptive estimate
    # it is that law that ran: the paper's law's runs differ
    assert not np.allclose(out['max_mm'], robust['max_mm'])
    assert stopped < 6


@pytest.mark.parametrize('law,gain,value', [('vsc', 'vsc.phi', 0.02),
                                            ('tdc', 'tdc.filter', 0.0)])
def test_a_task_law_kernel_takes_the_laws_own_gains(law, gain, value):
    runs = _sample()
    own = batch.simulate_law(runs, law=law, law_params={gain: value}, duration=0.5)
    default = batch.simulate_law(runs, law=law, duration=0.5)
    assert not np.array_equal(own['rms_mm'], default['rms_mm'], equal_nan=True)
    for i in (0, 1):
        metrics, _ = batch.run_scalar({k: v[i] for k, v in runs.items()}, duration=0.5,
                                      law=law, law_params={gain: value})
        assert own['rms_mm'][i] == pytest.approx(metrics['rms_mm'], rel=1e-9, abs=1e-9)


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_with_the_axes_off_the_scalar_reference_is_the_offline_runner(case):
    rec, trace = run_case(case, 'robust', 4, duration=1.0, record_trace=True)
    runs = batch.run_defaults(1)
    runs['vertical'][:] = case == 'vertical'
    runs['seed'][:] = 4
    metrics, p = batch.run_scalar({k: v[0] for k, v in runs.items()}, duration=1.0)
    assert np.array_equal(p, trace['p'])
    assert metrics['rms_mm'] == rec['rms_mm'] and metrics['max_mm'] == rec['max_mm']
    assert [metrics['tau_peak_1_nm'], metrics['tau_peak_2_nm']] == rec['tau_peak_nm']
    assert [metrics['q3_min_deg'], metrics['q3_max_deg']] == rec['q3_range_deg']
    assert metrics['min_det'] == rec['min_det']


def test_a_delayed_batched_run_is_the_offline_runners_delay_ticks():
    rec, trace = run_case('vertical', 'robust', 2, duration=1.0, delay_ticks=4,
                          record_trace=True)
    runs = batch.run_defaults(1)
    runs['vertical'][:] = True
    runs['seed'][:] = 2
    runs['delay'][:] = 4
    out = batch.simulate(runs, duration=1.0, record_trace=True)
    assert np.max(np.abs(out['p'][0] - trace['p'])) <= 1e-12
    assert out['max_mm'][0] == pytest.approx(rec['max_mm'], rel=1e-12)


def test_the_disturbance_draws_are_the_plants_stream_of_the_same_seed():
    runs = batch.check_runs(batch.run_defaults(3))
    runs['dist_bound'][:] = [0.5, 0.0, 1.5]
    dist, _, _, _, flags = batch.draws(runs, 20)
    assert not flags.any()
    for i in range(3):
        plant = Plant(table1('horizontal'), dist_bound=runs['dist_bound'][i],
                      seed=int(runs['seed'][i]))
        for k in range(20):
            plant.step([0.0, 0.0], 1e-3)
            assert list(plant.last_disturbance) == (dist[i, k].tolist() if i != 1
                                                    else [0.0, 0.0, 0.0])


def test_a_constant_disturbance_is_one_draw_held_and_noise_is_seeded_per_run():
    runs = batch.check_runs(batch.run_defaults(2))
    runs['dist_type'][:] = 1
    runs['noise_q'][:] = [0.0, 0.01]
    dist, nq, _, _, flags = batch.draws(runs, 5)
    first = np.random.default_rng(0).uniform(-0.5, 0.5, 3)
    assert np.array_equal(dist[0], np.tile(first, (5, 1)))
    assert flags[:, 0].tolist() == [False, True]
    expected = 0.01 * np.random.default_rng([24, 1, 1]).standard_normal((5, 3))
    assert np.array_equal(nq[1], expected)


@pytest.mark.parametrize('change,field', [
    ({'scale_mass': [0.0]}, 'scale_mass'), ({'delay': [-1]}, 'delay'),
    ({'noise_q': [math.nan]}, 'noise_q'), ({'dist_type': [2]}, 'dist_type'),
    ({'lag': [1.0, 2.0]}, 'lag'), ({'wind': [1.0]}, 'wind')])
def test_bad_per_run_inputs_are_refused_naming_the_field(change, field):
    runs = batch.run_defaults(1)
    runs.update(change)
    with pytest.raises(FreejointValueError, match=field):
        batch.check_runs(runs)


OTHER_ARM = {v: ArmParams(lengths=(0.6, 0.45, 0.35), masses=(1.5, 1.0, 0.4),
                          inertias=(0.05, 0.03, 0.01), com=(0.3, 0.2, 0.15), passive=(2,),
                          gravity=9.81 if v else 0.0) for v in (False, True)}
"""A 3-link arm that is not Table I's (another URDF's), joint 3 passive, per case."""


@pytest.mark.parametrize('engine', batch.ENGINES)
def test_another_three_link_arm_runs_batched_equal_to_its_scalar_runs(engine):
    runs = _sample()
    runs['q3_0_deg'][:] = [100.0, 115.0, 110.0, 105.0, 100.0, 120.0]   # reached by both arms
    refs = [batch.run_scalar({k: v[i] for k, v in runs.items()}, duration=DURATION,
                             arms=OTHER_ARM) for i in range(6)]
    out = batch.simulate(runs, duration=DURATION, record_trace=True, engine=engine,
                         arms=OTHER_ARM)
    table_one = batch.simulate(runs, duration=DURATION, engine=engine)
    for i, (metrics, p) in enumerate(refs):
        ticks = len(p)
        assert out['ticks'][i] == ticks
        assert np.max(np.abs(out['p'][i, :ticks] - p)) <= 1e-9
        assert out['max_mm'][i] == pytest.approx(metrics['max_mm'], rel=1e-9, abs=1e-9)
    # it is that arm that ran: Table I's runs differ
    assert not np.allclose(out['max_mm'], table_one['max_mm'])


def test_the_scalar_reference_of_another_arm_starts_where_its_own_inverse_kinematics_put_it():
    from freejoint_core.arm import ArmModel
    runs = batch.run_defaults(1)
    runs['vertical'][:] = True
    runs['q3_0_deg'][:] = 100.0
    _, p = batch.run_scalar({k: v[0] for k, v in runs.items()}, duration=0.01,
                            arms=OTHER_ARM)
    # the paper's circle starts at (0.2, 0): the arm's own kinematics reach it at tick 0
    assert p[0] == pytest.approx((0.2, 0.0), abs=1e-12)
    q0 = ArmModel(OTHER_ARM[True]).ik((0.2, 0.0), [math.radians(100.0)], branch=1)
    assert ArmModel(OTHER_ARM[True]).fk(q0) == pytest.approx(p[0], abs=1e-12)


@pytest.mark.parametrize('arms,match', [
    ({False: table1('horizontal')}, r'arms: expected a mapping of False and True'),
    ({False: ArmParams(lengths=(0.5,) * 4, masses=(1.0,) * 4, inertias=(0.1,) * 4,
                       com=(0.25,) * 4, passive=(3,)), True: table1('vertical')},
     r'arms\[False\]: the batch kernel runs 3-link arms whose joint 3 alone is passive, got 4'),
    ({False: table1('horizontal'), True: OTHER_ARM[True]}, r'arms: both arms need the same '
     r'lengths'),
])
def test_an_arm_the_batch_kernel_cannot_run_is_refused_naming_it(arms, match):
    with pytest.raises(FreejointValueError, match=match):
        batch.simulate(batch.run_defaults(1), duration=0.01, arms=arms)
