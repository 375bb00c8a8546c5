"""Delay compensation: the state predictor and the offline runner's fixed command delay."""

import math

from freejoint_core import offline
from freejoint_core.arm import table1
from freejoint_core.delay import DEFAULT_BIAS_GAIN, extrapolate_setpoint, StatePredictor
from freejoint_core.errors import FreejointValueError
from freejoint_core.plant import Plant
from freejoint_core.trajectory import CircleQuintic
import numpy as np
import pytest

DT = 1e-3
Q0 = (-1.3, 1.7, 2.1)
QD0 = (0.3, -0.2, 1.0)


def _torques(count, seed=1):
    return np.random.default_rng(seed).uniform(-10.0, 10.0, (count, 2))


@pytest.mark.parametrize('use_fast', [True, False])
@pytest.mark.parametrize('ticks', [1, 2, 5])
def test_exact_model_predicts_the_plant_state_to_round_off(use_fast, ticks):
    real = table1('vertical')
    plant = Plant(real, dist_bound=0.0, q0=Q0, qd0=QD0)
    pred = StatePredictor(real, DT, max_ticks=5, use_fast=use_fast, bias_gain=0.0)
    q, qd = plant.q, plant.qd
    for tau in _torques(ticks):
        pred.push(tau)
        plant.step(tau, DT)
    q_pred, qd_pred = pred.predict(q, qd, ticks)
    np.testing.assert_allclose(q_pred, plant.q, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(qd_pred, plant.qd, rtol=0.0, atol=1e-12)


def test_only_the_last_ticks_commands_act_over_the_horizon():
    real = table1('horizontal')
    pred = StatePredictor(real, DT, max_ticks=5, bias_gain=0.0)
    taus = _torques(8)
    for tau in taus:
        pred.push(tau)
    plant = Plant(real, dist_bound=0.0, q0=Q0, qd0=QD0)
    for tau in taus[-3:]:
        plant.step(tau, DT)
    q_pred, qd_pred = pred.predict(Q0, QD0, 3)
    np.testing.assert_allclose(np.r_[q_pred, qd_pred], np.r_[plant.q, plant.qd], atol=1e-12)


def test_zero_ticks_returns_the_measured_state_as_fresh_arrays():
    pred = StatePredictor(table1('vertical').scaled(0.7), DT)
    pred.push((1.0, 2.0))
    q = np.array(Q0)
    q_pred, qd_pred = pred.predict(q, QD0, 0)
    assert q_pred.tolist() == list(Q0) and qd_pred.tolist() == list(QD0)
    assert q_pred is not q and q_pred.shape == (3,) and qd_pred.shape == (3,)


def test_missing_history_is_the_oldest_command_and_zero_torque_before_any_push():
    real = table1('vertical')
    pred = StatePredictor(real, DT, max_ticks=4, bias_gain=0.0)
    zero = (0.0, 0.0, 0.0)
    assert pred.commands(3) == [zero] * 3
    pred.push((1.0, 2.0))
    pred.push((3.0, 4.0))
    # joint 3 is passive: zero actuator torque there
    assert pred.commands(4) == [(1.0, 2.0, 0.0)] * 3 + [(3.0, 4.0, 0.0)]
    assert pred.commands(1) == [(3.0, 4.0, 0.0)]
    assert len(pred) == 2
    pred.reset()
    assert len(pred) == 0 and pred.commands(2) == [zero] * 2


def test_history_keeps_only_what_the_longest_horizon_needs():
    pred = StatePredictor(table1('horizontal'), DT, max_ticks=2)
    for k in range(10):
        pred.push((float(k), 0.0))
    assert pred.commands(2) == [(8.0, 0.0, 0.0), (9.0, 0.0, 0.0)]
    assert len(pred) <= 3


def test_fast_and_general_paths_agree_with_the_nominal_model_and_the_observer():
    nominal = table1('vertical').scaled(0.7)
    real = table1('vertical')
    fast = StatePredictor(nominal, DT, max_ticks=5)
    slow = StatePredictor(nominal, DT, max_ticks=5, use_fast=False)
    assert fast.bias_gain == slow.bias_gain == DEFAULT_BIAS_GAIN
    plant = Plant(real, dist_bound=0.5, seed=3, q0=Q0, qd0=QD0)
    for tau in _torques(30):
        a = fast.predict(plant.q, plant.qd, 5)
        b = slow.predict(plant.q, plant.qd, 5)
        np.testing.assert_allclose(np.r_[a], np.r_[b], rtol=0.0, atol=1e-9)
        fast.push(tau)
        slow.push(tau)
        plant.step(tau, DT)
    np.testing.assert_allclose(fast.bias, slow.bias, rtol=0.0, atol=1e-6)


def _prediction_errors(bias_gain, ticks=5, periods=300):
    """Hold a command on the vertical arm (it swings); 70 % model; |error| of each prediction."""
    real = table1('vertical')
    # no disturbance: its random draw (unpredictable) would set the floor of both errors
    plant = Plant(real, dist_bound=0.0, q0=Q0)
    pred = StatePredictor(real.scaled(0.7), DT, max_ticks=ticks, bias_gain=bias_gain)
    states, preds = [], []
    tau = np.array([20.0, 8.0])
    for _ in range(periods):
        q, qd = plant.q, plant.qd
        states.append(np.r_[q, qd])
        preds.append(np.r_[pred.predict(q, qd, ticks)])
        pred.push(tau)
        plant.step(tau, DT)
    states, preds = np.array(states), np.array(preds)
    return np.abs(preds[:-ticks] - states[ticks:])


def test_bias_observer_removes_most_of_the_nominal_model_error():
    plain = _prediction_errors(0.0)[100:]
    learned = _prediction_errors(DEFAULT_BIAS_GAIN)[100:]
    # joint velocities after 5 periods: the 30 % model error dominates the plain prediction
    assert plain[:, 3:].max() > 10.0 * learned[:, 3:].max()
    assert plain[:, :3].max() > 10.0 * learned[:, :3].max()


def test_bias_observer_learns_only_after_exactly_one_push():
    real = table1('vertical')
    pred = StatePredictor(real.scaled(0.7), DT, max_ticks=2)
    pred.predict(Q0, QD0, 2)
    pred.predict(Q0, QD0, 2)       # no push in between: nothing learned
    assert pred.bias.tolist() == [0.0, 0.0, 0.0]
    pred.push((0.0, 0.0))
    pred.push((0.0, 0.0))
    pred.predict(Q0, QD0, 2)       # two pushes: a skipped tick, nothing learned
    assert pred.bias.tolist() == [0.0, 0.0, 0.0]
    pred.push((0.0, 0.0))
    pred.predict(Q0, QD0, 2)       # one period, the state unchanged: the arm was held
    # the nominal arm under zero torque would have fallen: the residual is that fall
    plain = StatePredictor(real.scaled(0.7), DT, bias_gain=0.0)
    _, qd_fallen = plain.predict(Q0, QD0, 1)
    expected = DEFAULT_BIAS_GAIN / DT * (np.array(QD0) - qd_fallen)
    assert np.abs(expected).max() > 0.1
    np.testing.assert_allclose(pred.bias, expected, rtol=1e-12)
    pred.reset()
    assert pred.bias.tolist() == [0.0, 0.0, 0.0]


def test_extrapolated_setpoint_matches_the_quintic_to_third_order():
    traj = CircleQuintic()
    for t in (0.7, 2.5, 4.1):
        p, v, a = traj.sample(t)
        for h in (1e-3, 5e-3):
            p_h, v_h, a_h = extrapolate_setpoint(p, v, a, h)
            p_t, v_t, a_t = traj.sample(t + h)
            np.testing.assert_allclose(p_h, p_t, atol=2.0 * h ** 3)
            np.testing.assert_allclose(v_h, v_t, atol=5.0 * h ** 2)
            np.testing.assert_array_equal(a_h, a)
    p, v, a = traj.sample(1.0)
    assert [x.tolist() for x in extrapolate_setpoint(p, v, a, 0.0)] == \
        [p.tolist(), v.tolist(), a.tolist()]


def test_offline_delay_zero_is_the_undelayed_run():
    base, tb = offline.run_case('vertical', 'robust', 4, duration=0.3, record_trace=True)
    same, ts = offline.run_case('vertical', 'robust', 4, duration=0.3, record_trace=True,
                                delay_ticks=0, predict=True)
    assert same == base
    for key in tb:
        np.testing.assert_array_equal(ts[key], tb[key])


@pytest.mark.parametrize('m', [1, 3])
def test_offline_delay_applies_the_command_of_tick_k_minus_m_and_tau0_before(m):
    rec, tr = offline.run_case('vertical', 'robust', 2, duration=0.2, record_trace=True,
                               delay_ticks=m)
    assert rec['variant'] == f'robust d{m}' and rec['diverged_at_s'] is None
    # Replaying the plant with tau_{max(j - m, 0)} reproduces every recorded state exactly.
    q0 = offline.initial_state(table1('vertical'))
    plant = Plant(table1('vertical'), dist_bound=0.5, seed=2, q0=q0)
    for j in range(len(tr['t'])):
        assert plant.q.tolist() == tr['q'][j].tolist()
        assert plant.qd.tolist() == tr['qd'][j].tolist()
        plant.step(tr['tau'][max(j - m, 0)], 1e-3)
    # without the predictor the law sees the measured state: its error is the recorded one
    undelayed, _ = offline.run_case('vertical', 'robust', 2, duration=0.2)
    assert rec['max_mm'] != undelayed['max_mm']


@pytest.mark.parametrize('m', [2, 5])
def test_offline_predictor_on_the_exact_model_acts_on_the_state_the_plant_will_have(m):
    rec, tr = offline.run_case('vertical', 'exact', None, duration=0.5, record_trace=True,
                               delay_ticks=m, predict=True, bias_gain=0.0)
    assert rec['variant'] == f'exact d{m}+p' and rec['diverged_at_s'] is None
    # From tick 1 on the history is exact (tick 0 assumed zero torque): the state the law
    # used at tick k is the plant's state at tick k + m, to round-off.
    np.testing.assert_allclose(tr['q_law'][1:-m], tr['q'][1 + m:], rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(tr['qd_law'][1:-m], tr['qd'][1 + m:], rtol=0.0, atol=1e-11)
    # So once the start-up has died out the delayed loop tracks like the undelayed one,
    # while the same delay uncompensated leaves a several times larger error.

    def err_mm(trace):
        return 1000.0 * np.hypot(trace['e'][250:, 0], trace['e'][250:, 1]).max()

    _, undelayed = offline.run_case('vertical', 'exact', None, duration=0.5, record_trace=True)
    _, plain = offline.run_case('vertical', 'exact', None, duration=0.5, record_trace=True,
                                delay_ticks=m)
    assert err_mm(tr) == pytest.approx(err_mm(undelayed), rel=0.1)
    assert err_mm(plain) > 4.0 * err_mm(undelayed)


@pytest.mark.parametrize('kwargs, name', [
    ({'nominal_params': 'arm'}, 'nominal_params'),
    ({'dt': 0.0}, 'dt'),
    ({'dt': math.nan}, 'dt'),
    ({'dt_sub': 0.0003}, 'dt_sub'),
    ({'dt_sub': -1.0}, 'dt_sub'),
    ({'max_ticks': 0}, 'max_ticks'),
    ({'max_ticks': 2.5}, 'max_ticks'),
    ({'max_ticks': True}, 'max_ticks'),
    ({'bias_gain': 1.5}, 'bias_gain'),
    ({'bias_gain': 'x'}, 'bias_gain'),
])
def test_bad_constructor_arguments_raise_naming_the_argument(kwargs, name):
    args = {'nominal_params': table1('vertical'), 'dt': DT}
    args.update(kwargs)
    with pytest.raises(FreejointValueError, match=f'^{name}:'):
        StatePredictor(**args)


@pytest.mark.parametrize('use_fast', [True, False])
def test_bad_call_arguments_raise_naming_the_argument(use_fast):
    pred = StatePredictor(table1('vertical'), DT, max_ticks=3, use_fast=use_fast)
    for tau in ((1.0,), (1.0, math.nan), 'ab', None, (1.0, 2.0, 3.0)):
        with pytest.raises(FreejointValueError, match='^tau_active:'):
            pred.push(tau)
    for args, name in (((Q0[:2], QD0, 1), 'q'), (((0.0, math.inf, 0.0), QD0, 1), 'q'),
                       ((Q0, None, 1), 'qd'), ((Q0, QD0, 4), 'ticks'),
                       ((Q0, QD0, -1), 'ticks'), ((Q0, QD0, 1.0), 'ticks')):
        with pytest.raises(FreejointValueError, match=f'^{name}:'):
            pred.predict(*args)
    with pytest.raises(FreejointValueError, match='^ticks:'):
        pred.commands(4)
    assert len(pred) == 0


def test_bad_setpoint_shift_and_runner_arguments_raise_naming_the_argument():
    with pytest.raises(FreejointValueError, match='^h:'):
        extrapolate_setpoint((0, 0), (0, 0), (0, 0), -1e-3)
    with pytest.raises(FreejointValueError, match='^pd_d:'):
        extrapolate_setpoint((0, 0), (0, math.nan), (0, 0), 1e-3)
    for value in (-1, 1.5, True, '2'):
        with pytest.raises(FreejointValueError, match='^delay_ticks:'):
            offline.run_case('horizontal', 'robust', 0, duration=0.01, delay_ticks=value)
    with pytest.raises(FreejointValueError, match='^predict:'):
        offline.run_case('horizontal', 'robust', 0, duration=0.01, delay_ticks=1,
                         predict='yes')
    with pytest.raises(FreejointValueError, match='^bias_gain:'):
        offline.run_case('horizontal', 'robust', 0, duration=0.01, delay_ticks=1,
                         predict=True, bias_gain=-0.1)
    for value in (-1, 2.0, False):
        with pytest.raises(FreejointValueError, match='^predict_ticks:'):
            offline.run_case('horizontal', 'robust', 0, duration=0.01, delay_ticks=1,
                             predict=True, predict_ticks=value)


def test_offline_predictor_horizon_defaults_to_the_delay_and_can_be_mis_set():
    kw = {'duration': 0.1, 'delay_ticks': 3, 'predict': True}
    ref, _ = offline.run_case('vertical', 'robust', 1, **kw)
    same, _ = offline.run_case('vertical', 'robust', 1, predict_ticks=3, **kw)
    short, _ = offline.run_case('vertical', 'robust', 1, predict_ticks=2, **kw)
    assert same == ref and ref['variant'] == 'robust d3+p'
    assert short['variant'] == 'robust d3+p2' and short['rms_mm'] != ref['rms_mm']


def test_delay_study_rows_summarise_the_runs_and_zero_delay_is_the_paper_run():
    rows, records = offline.delay_study((0, 2), seeds=[0], cases=['horizontal'])
    assert [(r['delay_ms'], r['option']) for r in rows] == [(0, 'off'), (2, 'off'), (2, 'on')]
    assert [r['variant'] for r in records] == ['robust', 'robust d2', 'robust d2+p']
    paper, _ = offline.run_case('horizontal', 'robust', 0)
    assert records[0] == paper
    assert rows[0]['worst_rms_mm'] == paper['rms_mm'] and rows[0]['diverged'] == 0
    assert rows[2]['worst_max_mm'] == records[2]['max_mm']
    table = offline.format_delay_table(rows).splitlines()
    assert len(table) == 5 and table[4].startswith('| horizontal | 2 | on | 1 |')


@pytest.mark.parametrize('argv', [['--delay-ticks', '-1'], ['--bias-gain', '1.5'],
                                  ['--delay-jitter', '-2'], ['--predict-ticks', '-1']])
def test_offline_cli_refuses_a_negative_delay_and_an_observer_gain_out_of_range(argv):
    with pytest.raises(SystemExit, match='offline: --'):
        offline.main(argv + ['--out', ''])


def test_ticks_since_finds_the_applied_command_in_the_history():
    pred = StatePredictor(table1('vertical'), DT, max_ticks=3)
    assert pred.ticks_since((0.0, 0.0)) is None          # nothing pushed yet
    for k in range(6):
        pred.push((float(k), -float(k)))
    assert pred.ticks_since((5.0, -5.0)) == 0
    assert pred.ticks_since(np.array([3.0, -3.0])) == 2
    assert pred.ticks_since((2.0, -2.0)) == 3             # the oldest held: max_ticks
    assert pred.ticks_since((1.0, -1.0)) is None          # no longer held
    assert pred.ticks_since((3.0, -3.0000001)) is None    # exact match only
    pred.push((5.0, -5.0))
    assert pred.ticks_since((5.0, -5.0)) == 0             # the latest of equal pushes
    with pytest.raises(FreejointValueError, match='^applied:'):
        pred.ticks_since((1.0, math.nan))


def test_applied_command_replaces_the_assumed_one_in_the_bias_observer():
    nominal = table1('vertical').scaled(0.7)
    told = StatePredictor(nominal, DT, max_ticks=2)
    assumed = StatePredictor(nominal, DT, max_ticks=2)
    for pred in (told, assumed):
        pred.predict(Q0, QD0, 2)
        pred.push((5.0, 1.0))
    # the command pushed ticks + 1 = 3 ago does not exist: the oldest push (5, 1) pads the
    # history, so the observer would assume (5, 1); told that zero torque acted, it learns
    # the residual of a zero-torque period instead
    told.predict(Q0, QD0, 2, applied=(0.0, 0.0))
    assumed.predict(Q0, QD0, 2)
    assert told.bias.tolist() != assumed.bias.tolist()
    plain = StatePredictor(nominal, DT, bias_gain=0.0)
    _, qd_zero = plain.predict(Q0, QD0, 1)            # one period under zero torque
    np.testing.assert_allclose(told.bias, DEFAULT_BIAS_GAIN / DT * (np.array(QD0) - qd_zero),
                               rtol=1e-12)
    with pytest.raises(FreejointValueError, match='^applied:'):
        told.predict(Q0, QD0, 1, applied=(1.0,))


def test_offline_echo_recovers_the_delay_from_the_applied_command():
    kw = {'duration': 0.3, 'delay_ticks': 4, 'predict': True}
    matched, _ = offline.run_case('vertical', 'robust', 1, **kw)
    for guess in (1, 4, 6):
        rec, _ = offline.run_case('vertical', 'robust', 1, predict_ticks=guess, echo=True, **kw)
        assert rec['variant'].endswith('e')
        # after the start-up (where tau_0 repeats and the echo is ambiguous) it is the
        # matched loop: same tracking to a few percent
        assert rec['max_mm'] == pytest.approx(matched['max_mm'], rel=0.05)
    with pytest.raises(FreejointValueError, match='^echo:'):
        offline.run_case('vertical', 'robust', 1, echo='yes', **kw)


def test_offline_jitter_applies_the_newest_command_arrived_in_order():
    m, jit, seed = 1, 3, 5
    rec, tr = offline.run_case('vertical', 'robust', seed, duration=0.2, record_trace=True,
                               delay_ticks=m, delay_jitter=jit)
    assert rec['variant'] == 'robust d1~3'
    # Hand replay of the documented rule: command k arrives at k + m + j_k (j_k from
    # default_rng([7919, seed]) in 0..jit), never before the previous one; step j applies
    # the newest arrived (tau_0 before any).
    draws = np.random.default_rng([7919, seed]).integers(0, jit + 1, len(tr['t'])).tolist()
    assert set(draws) == set(range(jit + 1))
    arrive, last = [], 0
    for k, d in enumerate(draws):
        last = max(k + m + d, last)
        arrive.append(last)
    plant = Plant(table1('vertical'), dist_bound=0.5, seed=seed,
                  q0=offline.initial_state(table1('vertical')))
    held = skipped = prev = 0
    for j in range(len(tr['t'])):
        assert plant.q.tolist() == tr['q'][j].tolist()
        arrived = [k for k in range(j + 1) if arrive[k] <= j]
        newest = arrived[-1] if arrived else 0
        plant.step(tr['tau'][newest], 1e-3)
        if j and newest == prev:
            held += 1
        elif j and newest > prev + 1:
            skipped += 1
        prev = newest
    assert held > 0 and skipped > 0     # the jitter both holds and skips commands
    with pytest.raises(FreejointValueError, match='^delay_jitter:'):
        offline.run_case('vertical', 'robust', 0, duration=0.01, delay_jitter=-1)
