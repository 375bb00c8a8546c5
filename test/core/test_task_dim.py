"""The task dimension m is data: the model says it, references and guards take any m."""
import math

from freejoint_core.arm import ArmModel, table1
from freejoint_core.control import Gains
from freejoint_core.delay import extrapolate_setpoint
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import setpoint_refusal
from freejoint_core.laws import make_law
from freejoint_core.models import make_model
from freejoint_core.reference import extrapolate, quintic_offset, ReferenceShaper
import numpy as np
import pytest


def test_the_planar_models_have_task_dimension_two_as_their_fk_gives():
    params = table1('horizontal')
    for model in (ArmModel(params), make_model(params)):
        assert model.task_dim == 2 == model.fk((0.1, 0.2, 0.3)).shape[0]


def test_the_papers_law_names_its_state_by_the_task_dimension():
    law = make_law('robust', table1('horizontal').scaled(0.7), Gains())
    assert law.state_names == ('theta_hat[0]', 'theta_hat[1]', 'theta_hat[2]',
                               'theta_hat[3]', 'theta_hat[4]', 'rho_hat', 'delta_v[0]',
                               'delta_v[1]')
    assert len(law.state_values()) == len(law.state_names) == len(law.state_bounds)


def test_a_three_dimensional_hold_is_the_position_at_rest():
    shaper = ReferenceShaper(0.5, m=3)
    assert shaper.hold([0.1, 0.2, 0.3]) == (0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert shaper.hold_position == (0.1, 0.2, 0.3)


def test_a_three_dimensional_blend_decays_each_coordinate_along_its_own_quintic():
    shaper = ReferenceShaper(1.0, m=3)
    shaper.hold([0.0, 0.0, 0.0])
    sp = (0.03, 0.04, 0.12, 0.1, 0.2, 0.3, 1.0, 2.0, 3.0)
    ref, blending = shaper.track(10.0, sp, None)
    assert blending and ref == pytest.approx((0.0,) * 9, abs=1e-15)
    # |offset| = 0.13 m: the blend lasts resume_time (no bounds); at 0.25 s each coordinate
    # is the setpoint plus quintic_offset of its own offset.
    ref, _ = shaper.track(10.25, sp, None)
    for i in range(3):
        d, v, a = quintic_offset(-sp[i], -sp[3 + i], -sp[6 + i], 1.0, 0.25)
        assert ref[i] == pytest.approx(sp[i] + d, abs=1e-15)
        assert ref[3 + i] == pytest.approx(sp[3 + i] + v, abs=1e-15)
        assert ref[6 + i] == pytest.approx(sp[6 + i] + a, abs=1e-15)
    assert shaper.track(11.0, sp, None) == (sp, False)


def test_the_planar_blend_equals_the_general_one_on_the_same_coordinates():
    planar, general = ReferenceShaper(0.4), ReferenceShaper(0.4, m=3)
    planar.hold([0.1, -0.2])
    general.hold([0.1, -0.2, 0.0])
    sp2 = (0.2, 0.1, 0.5, -0.5, 2.0, 1.0)
    sp3 = (0.2, 0.1, 0.0, 0.5, -0.5, 0.0, 2.0, 1.0, 0.0)
    for t in (0.0, 0.1, 0.2, 0.3):
        r2, _ = planar.track(t, sp2, None)
        r3, _ = general.track(t, sp3, None)
        assert r3 == (r2[0], r2[1], 0.0, r2[2], r2[3], 0.0, r2[4], r2[5], 0.0)


def test_start_from_wants_m_values_each():
    shaper = ReferenceShaper(0.5, m=3)
    with pytest.raises(FreejointValueError, match='expected 3 finite values each'):
        shaper.start_from([0.1, 0.2], [0.0, 0.0])
    with pytest.raises(FreejointValueError, match='m: expected an int >= 1'):
        ReferenceShaper(0.5, m=0)


def test_extrapolate_carries_any_m_along_its_taylor_polynomial():
    sp = (1.0, 2.0, 3.0, 0.5, -0.5, 1.0, 2.0, 0.0, -4.0)
    assert extrapolate(sp, 0.5) == (1.0 + 0.25 + 0.25, 2.0 - 0.25, 3.0 + 0.5 - 0.5,
                                    1.5, -0.5, -1.0, 2.0, 0.0, -4.0)
    p, v, a = extrapolate_setpoint(sp[0:3], sp[3:6], sp[6:9], 0.5)
    assert p.tolist() == [1.5, 1.75, 3.0] and v.tolist() == [1.5, -0.5, -1.0]
    assert a.tolist() == [2.0, 0.0, -4.0]


def test_the_setpoint_guard_measures_norms_in_m_dimensions_and_wants_3_m_values():
    ok = (0.3, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert setpoint_refusal(ok, 0.6, 5.0, 50.0, 3) is None
    far = (0.3, 0.4, 1.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)          # |p| = 1.3 m
    assert setpoint_refusal(far, 0.9, 5.0, 50.0, 3) == (
        'position (0.3, 0.4, 1.2) is 1.3 m from the base, beyond the reach 0.9 m')
    fast = (0.0, 0.0, 0.0, 2.0, 3.0, 6.0, 0.0, 0.0, 0.0)         # |v| = 7 m/s
    assert setpoint_refusal(fast, 0.9, 5.0, 50.0, 3) == 'velocity 7 m/s beyond 5 m/s'
    assert setpoint_refusal((0.1, 0.2, 0.0, 0.0, 0.0), 0.9, 5.0, 50.0) == (
        '5 values, expected 6 (position, velocity, acceleration of 2 each)')
    assert 'non-finite' in setpoint_refusal(ok[:8] + (math.inf,), 0.9, 5.0, 50.0, 3)


def test_the_planar_setpoint_guard_reads_as_before():
    assert setpoint_refusal((1.2, 0.5, 0, 0, 0, 0), 0.9, 5.0, 50.0) == (
        'position (1.2, 0.5) is 1.3 m from the base, beyond the reach 0.9 m')
    assert np.hypot(1.2, 0.5) == 1.3


def test_the_task_space_gains_are_sized_by_the_task_dimension():
    assert Gains().K == (100.0, 100.0) and Gains().task_dim == 2
    three = Gains(task_dim=3)
    assert three.K == (100.0,) * 3 and three.Lambda == (50.0,) * 3 and three.R == (2.0,) * 3
    assert Gains(K=(1.0, 2.0, 3.0), Lambda=1.0, R=1.0, task_dim=3).K == (1.0, 2.0, 3.0)
    with pytest.raises(FreejointValueError, match=r'K: expected shape \(3,\), got \(2,\)'):
        Gains(K=(1.0, 2.0), task_dim=3)
    with pytest.raises(FreejointValueError, match='task_dim: expected an int >= 1'):
        Gains(task_dim=0)


def test_a_law_refuses_gains_of_another_task_dimension_than_its_models():
    with pytest.raises(FreejointValueError, match='gains: sized for task dimension 3, the '
                                                  'model has 2'):
        make_law('robust', table1('horizontal').scaled(0.7), Gains(task_dim=3))
