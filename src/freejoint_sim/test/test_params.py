"""The simulator's parameter validation (no ROS): /clock rate, publish rate, physical bounds."""
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


@pytest.mark.parametrize('changes,match', [
    ({'dist_bound': 10.5}, r'dist_bound: must be in \[0, 10\] N m \(the paper: 0.5; the '
                           r'horizontal case peaks near 11 N m of actuator torque\), got 10.5'),
    ({'dist_bound': -0.1}, r'dist_bound: must be in \[0, 10\] N m'),
    ({'initial_passive_deg': 400.0}, r'initial_passive_deg: must be within one turn, '
                                     r'\[-360, 360\] deg, got 400.0'),
    ({'initial_passive_deg': float('nan')}, 'initial_passive_deg: must be within one turn'),
    ({'initial_position': [5.0, 0.0]}, 'initial_position: unreachable'),
    ({'divergence_speed': 0.5}, r'divergence_speed: must be in \[1, 100000\] rad/s, got 0.5'),
    ({'divergence_speed': 1e6}, r'divergence_speed: must be in \[1, 100000\] rad/s'),
    ({'start_braked': 'yes'}, "start_braked: expected true or false, got 'yes'")])
def test_values_beyond_the_physical_bounds_are_refused_with_the_reason(changes, match):
    with pytest.raises(FreejointValueError, match=match):
        build_config(_values(**changes))


def test_publish_rate_above_the_step_rate_is_refused_naming_the_step_rate():
    values = _values()
    values['publish_rate'] = 2000.0
    with pytest.raises(FreejointValueError, match=r'publish_rate: 2000 Hz is above the step '
                                                  r'rate 1000 Hz \(1 / control_period\)'):
        build_config(values)


def test_publish_rate_500_hz_at_1_khz_publishes_every_other_step():
    values = _values()
    values['publish_rate'] = 500.0      # the states of a 500 Hz driver
    assert build_config(values).publish_every == 2


def test_the_declared_ranges_are_the_validated_bounds():
    bounds = {spec.name: spec.bounds for spec in SPECS}
    assert bounds['dist_bound'] == (0.0, 10.0)
    assert bounds['initial_passive_deg'] == (-360.0, 360.0)
    assert bounds['divergence_speed'] == (1.0, 1e5)
    cfg = build_config(_values(dist_bound=10.0, initial_passive_deg=-240.0,
                               divergence_speed=1e5))
    assert (cfg.dist_bound, cfg.divergence_speed) == (10.0, 1e5)


def _turned_paper_arm(**changes):
    """Return the values of the shipped paper_arm.urdf with gravity along +x (frame turned)."""
    from freejoint_core.urdf import shipped_urdf_path
    return _values(description_file=shipped_urdf_path('paper_arm'),
                   gravity=[9.81, 0.0, 0.0], **changes)


def test_initial_joint_positions_are_the_urdfs_angles_the_model_adds_the_offset():
    import math
    cfg = build_config(_turned_paper_arm(initial_joint_positions='0.1 0.2 0.3'))
    # gravity +x: the straight arm (+x) lies at -90 deg in the turned task frame
    assert cfg.arm.joint_offsets == (-math.pi / 2, 0.0, 0.0)
    assert cfg.q0 == (0.1 - math.pi / 2, 0.2, 0.3)
    assert cfg.arm.to_joints(cfg.q0) == pytest.approx((0.1, 0.2, 0.3), abs=1e-15)


def test_initial_position_of_a_turned_arm_is_reached_in_its_task_frame():
    import math
    from freejoint_core.arm import ArmModel
    cfg = build_config(_turned_paper_arm(initial_position=[0.2, 0.1], initial_passive_deg=100.0))
    assert ArmModel(cfg.params).fk(cfg.q0) == pytest.approx((0.2, 0.1), abs=1e-12)
    assert cfg.q0[2] == pytest.approx(math.radians(100.0), abs=1e-12)  # relative: no offset
