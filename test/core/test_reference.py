"""Hold / resume reference (freejoint_core.reference) and the input guards (guards)."""
import math

from freejoint_core.arm import table1
from freejoint_core.control import Gains, RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import clamp_dt, limit_effort, setpoint_refusal, state_refusal
from freejoint_core.reference import (ArcStop, MODE_BLEND, MODE_HOLD, MODE_STREAM,
                                      quintic_offset, ReferenceShaper, STOP_MIN_SPEED)
from freejoint_core.trajectory import CircleQuintic
import numpy as np
import pytest


def test_quintic_offset_meets_its_six_boundary_conditions():
    d0, v0, a0, T = 0.03, -0.2, 1.5, 0.5
    assert quintic_offset(d0, v0, a0, T, 0.0) == (d0, v0, a0)
    d, v, a = quintic_offset(d0, v0, a0, T, T - 1e-9)
    assert abs(d) < 1e-12 and abs(v) < 1e-7 and abs(a) < 1e-4
    assert quintic_offset(d0, v0, a0, T, T) == (0.0, 0.0, 0.0)
    # Its derivatives are the returned rate and acceleration (finite differences).
    h = 1e-6
    for t in (0.05, 0.2, 0.41):
        dm, vm, _ = quintic_offset(d0, v0, a0, T, t - h)
        dp, vp, _ = quintic_offset(d0, v0, a0, T, t + h)
        _, v, a = quintic_offset(d0, v0, a0, T, t)
        assert abs((dp - dm) / (2 * h) - v) < 1e-6
        assert abs((vp - vm) / (2 * h) - a) < 1e-4


def test_hold_freezes_the_position_at_its_onset_with_zero_velocity():
    sh = ReferenceShaper(0.5)
    assert sh.hold((0.1, 0.2)) == (0.1, 0.2, 0.0, 0.0, 0.0, 0.0)
    assert sh.hold((0.5, 0.5)) == (0.1, 0.2, 0.0, 0.0, 0.0, 0.0)
    assert sh.mode == MODE_HOLD and sh.hold_position == (0.1, 0.2)


def test_a_hold_returned_to_blends_from_the_braked_arm_back_to_its_own_position():
    sh = ReferenceShaper(0.5)
    sh.hold((0.1, 0.2))
    sh.return_to(sh.hold_position)                    # stopped; the arm braked 3 mm off
    first = sh.hold((0.103, 0.2), 4.0)
    assert first == (0.103, 0.2, 0.0, 0.0, 0.0, 0.0)   # from where the arm is, at rest
    assert sh.hold_position == (0.1, 0.2)
    mid = sh.hold(None, 4.25)                          # half way: the quintic's midpoint
    assert mid[0] == pytest.approx(0.1015, abs=1e-12) and mid[1] == 0.2
    assert mid[2] == pytest.approx(-1.875 * 0.003 / 0.5, abs=1e-12)   # its peak speed
    assert sh.hold(None, 4.5) == (0.1, 0.2, 0.0, 0.0, 0.0, 0.0)
    assert sh.hold((0.5, 0.5), 9.0) == (0.1, 0.2, 0.0, 0.0, 0.0, 0.0)
    # Without return_to a hold starts where the arm is; a track forgets the target.
    sh.reset()
    assert sh.hold((0.103, 0.2), 4.0)[0] == 0.103
    sh.return_to((0.1, 0.2))
    sh.track(5.0, (0.3, 0.0, 0.0, 0.0, 0.0, 0.0), (0.103, 0.2))
    sh.hold((0.2, 0.2), 6.0)
    assert sh.hold(None, 7.0)[0] == 0.2 and sh.hold_position == (0.2, 0.2)
    with pytest.raises(FreejointValueError, match=r'^target: expected 2 finite values'):
        sh.return_to((0.1, math.nan))


def test_resume_blends_from_the_hold_to_the_stream_without_a_step():
    traj = CircleQuintic()
    dt = 1e-3
    sh = ReferenceShaper(0.5)
    hold = (0.23, -0.04)
    refs = [sh.hold(hold)]
    t0 = 1.7
    for k in range(800):
        sp = traj.sample_tuple(t0 + k * dt)
        ref, blending = sh.track(t0 + k * dt, sp, None)
        assert blending == (k * dt < 0.5 - 1e-12)
        refs.append(ref)
    refs = np.array(refs)
    # Continuous position, velocity and acceleration: the largest change per tick is
    # what a bounded jerk gives, at the switch into the blend and out of it.
    steps = np.abs(np.diff(refs, axis=0)).max(axis=0)
    assert steps[0:2].max() < 2e-3 * 1.0        # < 2 mm per ms: no jump of 0.03 m
    assert steps[2:4].max() < 0.01              # m/s per tick
    assert steps[4:6].max() < 0.2               # m/s^2 per tick
    assert tuple(refs[1]) == pytest.approx(hold + (0, 0, 0, 0), abs=1e-12)
    assert sh.mode == MODE_STREAM
    assert tuple(refs[-1]) == traj.sample_tuple(t0 + 799 * dt)


def test_first_setpoint_blends_in_from_the_arm_in_real_time_and_not_in_lockstep():
    sp = (0.2, 0.0, 0.1, 0.0, 0.0, 0.0)
    rt = ReferenceShaper(0.5, blend_on_start=True)
    ref, blending = rt.track(10.0, sp, (0.25, 0.01))
    assert blending and ref == (0.25, 0.01, 0.0, 0.0, 0.0, 0.0)
    assert rt.mode == MODE_BLEND
    ls = ReferenceShaper(0.5, blend_on_start=False)
    assert ls.track(0.0, sp, (0.25, 0.01)) == (sp, False)
    ls.reset()
    assert ls.mode == 'none'


def test_resume_time_zero_switches_at_once_and_bad_values_are_refused():
    sh = ReferenceShaper(0.0)
    sh.hold((0.0, 0.3))
    sp = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert sh.track(0.0, sp, None) == (sp, False)
    with pytest.raises(FreejointValueError, match='^resume_time'):
        ReferenceShaper(-1.0)
    with pytest.raises(FreejointValueError, match='^resume_time'):
        sh.set_resume_time(math.nan)


def test_clamp_dt_bounds_the_step_to_a_quarter_and_four_periods():
    assert clamp_dt(0.002, 0.002) == (0.002, False)
    assert clamp_dt(0.0001, 0.002) == (0.0005, True)
    assert clamp_dt(1.0, 0.002) == (0.008, True)
    assert clamp_dt(math.inf, 0.001) == (0.001, True)


def test_limit_effort_clips_per_joint_and_limits_the_step():
    assert limit_effort([500.0, -10.0], (300.0, 200.0)) == ([300.0, -10.0], True, False)
    tau, clipped, rated = limit_effort([100.0, -50.0], (300.0, 200.0), [0.0, 0.0], 20.0)
    assert tau == [20.0, -20.0] and not clipped and rated
    assert limit_effort([5.0, 1.0], (300.0, 200.0), [0.0, 0.0], 20.0) == ([5.0, 1.0], False,
                                                                          False)


def test_state_refusal_names_the_joint_and_the_limit():
    lo, hi, vmax = (-6.0,) * 3, (6.0,) * 3, (100.0,) * 3
    assert state_refusal((0.1, 0.2, 0.3), (1.0, 2.0, 3.0), lo, hi, vmax) is None
    assert 'joint 1 position 1000000.0' in state_refusal((0.0, 1e6, 0.0), (0.0,) * 3, lo, hi,
                                                         vmax)
    assert 'joint 2 velocity 1e+160' in state_refusal((0.0,) * 3, (0.0, 0.0, 1e160), lo, hi,
                                                      vmax)
    assert 'velocity nan' in state_refusal((0.0,) * 3, (math.nan, 0.0, 0.0), lo, hi, vmax)


def test_setpoint_refusal_checks_reach_speed_and_acceleration():
    ok = (0.2, 0.0, 0.3, 0.0, 1.0, 0.0)
    assert setpoint_refusal(ok, 0.9, 5.0, 50.0) is None
    assert 'beyond the reach' in setpoint_refusal((1e300, 0.0, 0, 0, 0, 0), 0.9, 5.0, 50.0)
    assert 'velocity' in setpoint_refusal((0.2, 0.0, 10.0, 0, 0, 0), 0.9, 5.0, 50.0)
    assert 'acceleration' in setpoint_refusal((0.2, 0.0, 0, 0, 0, 1e3), 0.9, 5.0, 50.0)
    assert 'non-finite' in setpoint_refusal((0.2, math.nan, 0, 0, 0, 0), 0.9, 5.0, 50.0)


def test_theta_max_clamps_the_update_and_set_theta_restores_an_estimate():
    ctl = RobustController(table1('horizontal').scaled(0.7),
                           Gains(Gamma=(1e3,) * 5, theta_max=(1e-3,) * 5))
    q = (-1.369438, 1.691679, 2.094395)
    ctl.step(q, (1.0, -2.0, 3.0), (0.3, 0.1), (0.0, 0.0), (0.0, 0.0), 1e-3)
    assert max(ctl.theta) <= 1e-3 and max(ctl.theta) == 1e-3
    ctl.set_theta((0.0, 1e-4, 0.0, 0.0, 0.0))
    assert ctl.theta.tolist() == [0.0, 1e-4, 0.0, 0.0, 0.0]
    with pytest.raises(FreejointValueError, match='^theta'):
        ctl.set_theta((math.nan,) * 5)
    with pytest.raises(FreejointValueError, match='^theta_max'):
        Gains(theta_max=(0.0,) * 5)
    general = RobustController(table1('horizontal').scaled(0.7),
                               Gains(Gamma=(1e3,) * 5, theta_max=(1e-3,) * 5), use_fast=False)
    general.step(q, (1.0, -2.0, 3.0), (0.3, 0.1), (0.0, 0.0), (0.0, 0.0), 1e-3)
    assert max(general.theta) == 1e-3


def test_a_large_offset_blends_for_longer_within_the_speed_and_acceleration_bounds():
    sh = ReferenceShaper(0.5, True, max_velocity=0.5, max_acceleration=2.0)
    sh.hold((0.2, -0.7))                       # the arm fell 0.7 m below the stream
    sp = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    dt = 1e-3
    refs = [sh.track(k * dt, sp, None)[0] for k in range(4000)]
    assert sh.blend_duration == pytest.approx(1.875 * 0.7 / 0.5)       # 2.625 s > 0.5 s
    speed = max(math.hypot(r[2], r[3]) for r in refs)
    acc = max(math.hypot(r[4], r[5]) for r in refs)
    assert speed <= 0.5 + 1e-9 and acc <= 2.0 + 1e-9
    assert refs[-1] == sp
    # A small offset keeps resume_time.
    sh.reset()
    sh.hold((0.2, -0.01))
    sh.track(0.0, sp, None)
    assert sh.blend_duration == 0.5
    with pytest.raises(FreejointValueError, match='^max_velocity'):
        sh.set_bounds(0.0, None)


def test_a_stiffer_step_equals_a_controller_built_with_the_scaled_gains_exactly():
    nominal = table1('vertical').scaled(0.7)
    scaled = RobustController(nominal, Gains(K=(200.0, 200.0), Lambda=(100.0, 100.0)))
    stiff = RobustController(nominal, Gains())
    stiff.set_stiffness(2.0)
    q, qd = (0.3, 1.2, 2.0), (0.1, -0.2, 0.3)
    a = scaled.step(q, qd, (0.21, 0.01), (0.0, 0.0), (0.0, 0.0), 1e-3)
    b = stiff.step(q, qd, (0.21, 0.01), (0.0, 0.0), (0.0, 0.0), 1e-3)
    assert a.tau.tolist() == b.tau.tolist()
    assert a.internal['theta_hat'].tolist() == b.internal['theta_hat'].tolist()
    # ... and back to 1 it equals the paper's gains again, bit for bit.
    plain = RobustController(nominal, Gains())
    stiff.set_stiffness(1.0)
    stiff.reset()
    c = plain.step(q, qd, (0.21, 0.01), (0.0, 0.0), (0.0, 0.0), 1e-3)
    d = stiff.step(q, qd, (0.21, 0.01), (0.0, 0.0), (0.0, 0.0), 1e-3)
    assert c.tau.tolist() == d.tau.tolist()


def test_new_gains_keep_the_stiffness_and_a_bad_scale_is_refused_naming_it():
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    ctl.set_stiffness(3.0)
    ctl.set_gains(Gains(K=(40.0, 60.0)))
    ref = RobustController(table1('horizontal').scaled(0.7),
                           Gains(K=(120.0, 180.0), Lambda=(150.0, 150.0)))
    args = ((0.3, 1.2, 2.0), (0.1, -0.2, 0.3), (0.2, 0.0), (0.1, 0.0), (0.0, 0.0), 1e-3)
    assert ctl.step(*args).tau.tolist() == ref.step(*args).tau.tolist()
    for bad in (0.0, -1.0, float('nan'), float('inf')):
        with pytest.raises(FreejointValueError, match=r'^scale: '):
            ctl.set_stiffness(bad)


def test_the_hold_is_stiffer_and_the_blend_hands_back_smoothly_to_the_law_gains():
    shaper = ReferenceShaper(0.5, blend_on_start=True)
    assert shaper.stiffness(2.0) == 1.0            # nothing yet: the law's own gains
    shaper.hold((0.2, 0.0))
    assert shaper.stiffness(2.0) == 2.0
    sp = (0.25, 0.0, 0.0, 0.0, 0.0, 0.0)
    seen = []
    for k in range(600):
        shaper.track(k * 1e-3, sp, None)
        seen.append(shaper.stiffness(2.0))
    assert seen[0] == 2.0                          # the blend starts where the hold was
    assert seen[-1] == 1.0 and shaper.mode == 'stream'
    assert all(a >= b for a, b in zip(seen, seen[1:]))    # monotone, no step:
    assert max(abs(a - b) for a, b in zip(seen, seen[1:])) < 2 * 1.875 / 500
    # at the middle of the blend the smoothstep is exactly 1/2
    assert seen[250] == pytest.approx(1.5, abs=1e-12)


def test_start_from_the_measured_motion_keeps_position_and_velocity_continuous():
    # A standby activated while the arm moves at (0.3, -0.1) m/s, 2 cm from the stream.
    sp = (0.50, 0.20, 0.40, 0.10, 1.0, -2.0)
    sh = ReferenceShaper(1.0, max_velocity=1.0, max_acceleration=5.0)
    sh.hold((0.0, 0.0))
    sh.start_from((0.52, 0.21), (0.30, -0.10))
    ref, blending = sh.track(10.0, sp, None)
    # At activation the reference is the measured motion, acceleration 0.
    assert blending and sh.mode == MODE_BLEND
    assert ref == pytest.approx((0.52, 0.21, 0.30, -0.10, 0.0, 0.0), abs=1e-15)
    # Offset (0.02, 0.01) m, (-0.1, -0.2) m/s, (-1, 2) m/s^2 decaying over T = 1 s (the
    # 2.2 cm offset is within the bounds): half-way, by hand, d(t) = d0 + v0 t + a0 t^2 / 2
    # + c3 t^3 + c4 t^4 + c5 t^5 with c3 = -(20 d0 + 12 v0 + 3 a0) / 2,
    # c4 = (30 d0 + 16 v0 + 3 a0) / 2, c5 = -(12 d0 + 6 v0 + a0) / 2 (T = 1).

    def by_hand(d0, v0, a0, t):
        c3 = -(20 * d0 + 12 * v0 + 3 * a0) / 2
        c4 = (30 * d0 + 16 * v0 + 3 * a0) / 2
        c5 = -(12 * d0 + 6 * v0 + a0) / 2
        return d0 + v0 * t + a0 * t * t / 2 + c3 * t ** 3 + c4 * t ** 4 + c5 * t ** 5
    # x: d0 = 0.02, v0 = -0.1, a0 = -1 -> c3 = 1.9, c4 = -2.0, c5 = 0.68:
    # 0.02 - 0.05 - 0.125 + 0.2375 - 0.125 + 0.02125 = -0.02125
    assert by_hand(0.02, -0.1, -1.0, 0.5) == pytest.approx(-0.02125, abs=1e-15)
    ref, blending = sh.track(10.5, sp, None)
    assert blending
    assert ref[0] == pytest.approx(0.50 - 0.02125, abs=1e-12)
    assert ref[1] == pytest.approx(0.20 + by_hand(0.01, -0.2, 2.0, 0.5), abs=1e-12)
    # Then the stream itself.
    assert sh.track(11.0, sp, None) == (sp, False)


def test_start_from_is_refused_for_non_finite_motion_and_a_hold_forgets_it():
    sh = ReferenceShaper(0.5)
    with pytest.raises(FreejointValueError, match='p, v'):
        sh.start_from((0.1, math.nan), (0.0, 0.0))
    with pytest.raises(FreejointValueError, match='p, v'):
        sh.start_from((0.1, 0.2), (0.0,))
    sh.start_from((0.1, 0.2), (1.0, 0.0))
    # No setpoint at activation: a hold at zero velocity where the arm is now.
    assert sh.hold((0.3, 0.4)) == (0.3, 0.4, 0.0, 0.0, 0.0, 0.0)
    ref, _ = sh.track(0.0, (0.5, 0.5, 0.0, 0.0, 0.0, 0.0), None)
    assert ref[:4] == pytest.approx((0.3, 0.4, 0.0, 0.0))


def _circling(phi, r=0.2, speed=0.4):
    """Return uniform motion on the circle of radius r about the origin at angle phi (ccw)."""
    c, s = math.cos(phi), math.sin(phi)
    w = speed * speed / r
    return (r * c, r * s, -speed * s, speed * c, -w * c, -w * s)


def test_a_stop_along_a_circle_stays_on_it_and_stands_half_its_ramp_along():
    # 0.4 m/s on a 0.2-m circle, stopped over T = 0.15 s: the feed hold's ramp, which
    # travels s0 T / 2 = 30 mm (0.15 rad) and decelerates at most 1.875 s0 / T = 5 m/s^2.
    start = _circling(0.3)
    stop = ArcStop(start, 2.0, 0.15)
    assert stop.end == pytest.approx((0.2 * math.cos(0.45), 0.2 * math.sin(0.45)), abs=1e-15)
    assert stop.sample(2.0) == pytest.approx(start, abs=1e-15)     # no step
    for t in np.linspace(2.0, 2.2, 41):
        p = stop.sample(t)
        assert math.hypot(p[0], p[1]) == pytest.approx(0.2, abs=1e-15)
    assert stop.sample(2.15) == pytest.approx(stop.end + (0.0,) * 4, abs=1e-15)
    assert stop.sample(9.0) == pytest.approx(stop.end + (0.0,) * 4, abs=0.0)
    # Half way: half the speed, along the tangent, and the ramp's peak deceleration
    # 1.875 s0 / T = 5 m/s^2 on top of the centripetal (s0 / 2)^2 / r = 0.2 m/s^2; the
    # angle travelled is s0 T (1/2 - int_0^1/2 S) / r = 0.06 (1/2 - 5/64) / 0.2.
    phi = 0.3 + 0.06 * (0.5 - 5.0 / 64.0) / 0.2
    tangent, inward = (-math.sin(phi), math.cos(phi)), (-math.cos(phi), -math.sin(phi))
    mid = stop.sample(2.075)
    assert mid[0:2] == pytest.approx((0.2 * math.cos(phi), 0.2 * math.sin(phi)), abs=1e-15)
    assert mid[2:4] == pytest.approx((0.2 * tangent[0], 0.2 * tangent[1]), abs=1e-15)
    assert mid[4:6] == pytest.approx((-5.0 * tangent[0] + 0.2 * inward[0],
                                      -5.0 * tangent[1] + 0.2 * inward[1]), abs=1e-12)
    # Its velocity and acceleration are the derivatives of its position and velocity.
    h = 1e-6
    for t in (2.01, 2.07, 2.13):
        a, b, now = stop.sample(t - h), stop.sample(t + h), stop.sample(t)
        for i in range(2):
            assert (b[i] - a[i]) / (2 * h) == pytest.approx(now[2 + i], abs=1e-8)
            assert (b[2 + i] - a[2 + i]) / (2 * h) == pytest.approx(now[4 + i], abs=1e-5)


def test_a_stop_without_normal_acceleration_is_straight_and_one_in_space_keeps_its_plane():
    # Along x at 0.5 m/s, the acceleration along the motion: a straight line, 25 mm in
    # T = 0.1 s, the reference's own tangential acceleration replaced by the ramp's.
    stop = ArcStop((0.1, 0.2, 0.5, 0.0, 3.0, 0.0), 0.0, 0.1)
    assert stop.end == pytest.approx((0.125, 0.2), abs=1e-15)
    assert stop.sample(0.0) == pytest.approx((0.1, 0.2, 0.5, 0.0, 0.0, 0.0), abs=1e-15)
    # A circle of radius 0.1 about (0, 0, 0.3) in the x-z plane (task dimension 3).
    ref = (0.1, 0.0, 0.3, 0.0, 0.0, 0.2, -0.4, 0.0, 0.0)
    stop = ArcStop(ref, 0.0, 0.2)                  # 20 mm along: 0.2 rad
    assert stop.end == pytest.approx((0.1 * math.cos(0.2), 0.0, 0.3 + 0.1 * math.sin(0.2)),
                                     abs=1e-15)
    for t in (0.05, 0.1, 0.15):
        p = stop.sample(t)
        assert p[1] == 0.0 and math.hypot(p[0], p[2] - 0.3) == pytest.approx(0.1, abs=1e-15)


def test_a_stop_is_refused_without_motion_or_with_bad_values_naming_them():
    with pytest.raises(FreejointValueError, match='^ref: the velocity'):
        ArcStop((0.1, 0.2, 0.0, 0.0, 1.0, 0.0), 0.0, 0.1)
    with pytest.raises(FreejointValueError, match='^ref: expected 3 m finite'):
        ArcStop((0.1, 0.2, math.nan, 0.0, 1.0, 0.0), 0.0, 0.1)
    with pytest.raises(FreejointValueError, match='^duration: expected'):
        ArcStop(_circling(0.0), 0.0, 0.0)
    with pytest.raises(FreejointValueError, match='^max_acceleration: expected'):
        ReferenceShaper(0.5).stop(0.0, 0.0, -1.0)


def test_a_moving_reference_stops_along_its_arc_into_the_hold():
    sh = ReferenceShaper(0.5, blend_on_start=False)
    # Nothing to stop: no reference yet, a hold, a reference slower than STOP_MIN_SPEED.
    assert sh.stop(0.0, 0.001, 5.0) is None and sh.mode == 'none'
    sh.hold((0.2, 0.0))
    assert sh.stop(0.0, 0.001, 5.0) is None and sh.hold_position == (0.2, 0.0)
    sh = ReferenceShaper(0.5, blend_on_start=False)
    sh.track(1.0, (0.2, 0.0, 0.5 * STOP_MIN_SPEED, 0.0, 0.0, 0.0), None)
    assert sh.stop(1.0, 1.001, 5.0) is None and sh.mode == MODE_STREAM
    # Streaming at 0.4 m/s on the circle, the last reference at 3.0 s; the hold starts
    # 12 ms later (a gap): 1.875 * 0.4 / 5 = 0.15 s of stop from 3.0 s, as ArcStop's.
    sh.track(3.0, _circling(0.3), None)
    expected = ArcStop(_circling(0.3), 3.0, 0.15)
    assert sh.stop(3.0, 3.012, 5.0) == expected.sample(3.012)
    assert sh.mode == MODE_HOLD and sh.stopping and sh.hold_position == expected.end
    assert sh.hold(None, 3.1) == expected.sample(3.1)
    assert sh.hold(None, 3.16) == expected.end + (0.0,) * 4 and not sh.stopping
    assert sh.hold((0.0, 0.0), 4.0) == expected.end + (0.0,) * 4
    # A setpoint mid-stop: the blend starts from the moving reference, no step.
    sh.reset()
    sh.track(3.0, _circling(0.3), None)
    sh.stop(3.0, 3.012, 5.0)
    here = sh.hold(None, 3.05)
    ref, blending = sh.track(3.05, _circling(0.2), None)
    assert blending and ref == pytest.approx(here, abs=1e-15) and not sh.stopping
