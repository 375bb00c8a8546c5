"""The simulator's parameter validation (no ROS): the /clock rate of lockstep."""
from freejoint_common.node_tools import SCHEDULING_SPECS
from freejoint_core.errors import FreejointValueError
from freejoint_sim.params import build_config, SPECS
import pytest


def _values(**changes):
    values = {spec.name: spec.default for spec in SPECS}
    values.update(changes)
    values['publish_rate'] = 1.0 / values['control_period']   # real time only; valid
    return values


def test_every_parameter_is_declared_once():
    names = [spec.name for spec in SPECS]
    assert len(names) == len(set(names))
    assert {spec.name for spec in SCHEDULING_SPECS} <= set(names)


@pytest.mark.parametrize('rate,period,every', [
    (0.0, 0.001, 1),          # the declared default: /clock every step
    (1000.0, 0.001, 1), (100.0, 0.001, 10), (50.0, 0.001, 20), (1.0, 0.001, 1000),
    (0.0, 0.002, 1), (100.0, 0.002, 5), (250.0, 0.002, 2)])
def test_clock_rate_gives_the_steps_from_one_clock_to_the_next(rate, period, every):
    cfg = build_config(_values(clock_rate=rate, control_period=period))
    assert cfg.clock_every == every


@pytest.mark.parametrize('rate,match', [
    (300.0, r'clock_rate: 300 Hz does not divide the step rate 1000 Hz \(1 / \(clock_rate '
            r'\* control_period\) must be an integer\)'),
    (0.3, 'clock_rate: 0.3 Hz does not divide the step rate 1000 Hz'),
    (2000.0, r'clock_rate: 2000 Hz is above the step rate 1000 Hz \(1 / control_period\)'),
    (-1.0, r'clock_rate: must be >= 0 Hz \(0 = every step\), got -1.0'),
    (float('nan'), 'clock_rate: must be >= 0 Hz'),
    (float('inf'), 'clock_rate: must be >= 0 Hz')])
def test_a_clock_rate_that_is_no_divisor_of_the_step_rate_is_refused_naming_it(rate, match):
    with pytest.raises(FreejointValueError, match=match):
        build_config(_values(clock_rate=rate))


def test_the_declared_default_publishes_clock_every_step_for_any_control_period():
    # 0 Hz is "every step": a file that sets only control_period still starts
    for period in (0.001, 0.0025, 0.01):
        assert build_config(_values(control_period=period)).clock_every == 1
