"""
The controller's loop in one process: synthetic sample streams, no DDS, no clock, no sleep.

Every answer is compared with the core stepped here on the same inputs (:class:`Replica`:
``RobustController``, ``ReferenceShaper``, the guards), as the node's answers were; the
clock values are the test's, so each run is the same.
"""
import math
import os

from freejoint_control.loop import (ControlLoop, STATUS_DT_CLAMPED, STATUS_HOLDING,
                                    STATUS_LAW_FAULT, STATUS_RATE_LIMITED, STATUS_RESUMING,
                                    STATUS_SETPOINT_LATE, STATUS_STOPPED)
from freejoint_control.params import SCHEMA
from freejoint_control.readiness import REALTIME_EPSILON
from freejoint_core.arm import ArmModel, table1
from freejoint_core.control import (Gains, RobustController, STATUS_BAD_INPUT,
                                    STATUS_STALE_SETPOINT, STATUS_STALE_STATE,
                                    STATUS_TORQUE_LIMITED)
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import clamp_dt, limit_effort
from freejoint_core.reference import extrapolate, MODE_HOLD, MODE_NONE, ReferenceShaper
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PARAMS = os.path.join(ROOT, 'config', 'controller.yaml')
FILE = SCHEMA.yaml_values(PARAMS)
LIMITS = tuple(FILE['effort_limits'])
RATE = FILE['effort_rate_limit']
STIFFNESS = FILE['hold_stiffness']
DT = 0.001
DT_NS = 1_000_000
NAMES = ['joint1', 'joint2', 'joint3']
Q0 = (-1.369438, 1.691679, 2.094395)
QD0 = (0.05, -0.1, 0.3)


def make(**given):
    """
    Return (loop, log lines) of config/controller.yaml with ``given`` on top.

    The readiness guard off unless given (its streams' gaps and ages are test_readiness's).
    """
    values = dict(FILE, readiness_guard=False)
    values.update(given)
    logs = []
    loop = ControlLoop(SCHEMA.config(values), lambda level, kind, text: logs.append(
        (level, kind, text)))
    return loop, logs


class Clock:
    """The test's clocks: system time at the state's stamp (age 0) and a monotonic one."""

    def __init__(self):
        self.mono = 100.0


def state(loop, k, q=Q0, qd=QD0, names=NAMES, mono=None, now_ns=None):
    """Feed the state of tick k (stamp k ms); return the Result or None."""
    ns = k * DT_NS
    return loop.on_state(ns, names, list(q), list(qd), ns if now_ns is None else now_ns,
                         100.0 + k * DT if mono is None else mono)


def setpoint(loop, k, values, mono=None):
    """Feed the setpoint stamped k ms."""
    return loop.on_setpoint(k * DT_NS, tuple(values), 0, 100.0 + k * DT if mono is None
                            else mono)


def _setpoint(k):
    return (0.2 - 1e-4 * k, 1e-4 * k, -0.01, 0.02, 0.5, -0.3)


def _state_q(k):
    return tuple(v + 1e-3 * k for v in Q0), tuple(v * (1 + 0.1 * k) for v in QD0)


def _moving_setpoint(k, base):
    return (base[0] + 0.03 + 1e-4 * k, base[1] - 0.02, 0.1, 0.0, 0.0, 0.0)


def _finite_within(cmd, limits=LIMITS):
    return all(math.isfinite(x) and abs(x) <= lim for x, lim in zip(cmd, limits))


class Replica:
    """What the loop must answer, from the core: law, hold / blend reference, limits."""

    def __init__(self, case, lockstep, resume=0.5, limits=LIMITS, rate=RATE, dt=DT,
                 resume_bounds=(1.0, 5.0), stiffness=STIFFNESS, gains=None):
        # In real time the law's chattering bound is the arm's measured real-time one.
        self.ctl = RobustController(table1(case).scaled(0.7), gains or Gains(
            tau_limit=limits, theta_max=(100.0,) * 5,
            epsilon=Gains().epsilon if lockstep else REALTIME_EPSILON[(table1(case), 'off')]))
        self.shaper = ReferenceShaper(resume, not lockstep, *resume_bounds)
        self.lockstep = lockstep
        self.stiffness = stiffness
        self.limits = limits
        self.rate = rate
        self.dt = dt
        self.prev = None if lockstep else [0.0, 0.0]
        self.armed = not lockstep
        self.last_ns = -1
        self.late = False

    def fk(self, q):
        return self.ctl.model.fk(q).tolist()

    def tick(self, ns, q, qd, sp, sp_ns=None):
        """Return (effort, reference, dt, LawOutput) for the state stamped ns."""
        if self.lockstep or self.last_ns < 0:
            dt = self.dt
        else:
            dt = clamp_dt((ns - self.last_ns) * 1e-9, self.dt)[0]
        if sp is not None and not self.lockstep:
            age = ns - (ns if sp_ns is None else sp_ns)
            if age > 0:
                sp = extrapolate(sp, age * 1e-9)
            late = age > 10 * DT_NS
            if not late and self.late:
                self.shaper.restart_blend()
            self.late = late
        if sp is None:
            self.late = False
            if self.shaper.mode != MODE_HOLD:
                ref = self.shaper.hold(self.fk(q))
                self.armed = self.prev is not None
            else:
                ref = self.shaper.hold(None)
        else:
            p_now = self.fk(q) if self.shaper.mode == MODE_NONE else None
            ref, _ = self.shaper.track(ns * 1e-9, sp, p_now)
        scale = self.shaper.stiffness(self.stiffness)
        if scale != self.ctl.stiffness:
            self.ctl.set_stiffness(scale)
        out = self.ctl.step(q, qd, ref[0:2], ref[2:4], ref[4:6], dt)
        effort = out.tau.tolist()
        if self.armed:
            effort, _, rated = limit_effort(effort, self.limits, self.prev, self.rate * dt)
            self.armed = rated
        self.prev = effort
        self.last_ns = ns
        return effort, ref, dt, out

    def zero(self, ns, effort=(0.0, 0.0)):
        self.prev = list(effort)
        self.armed = True
        self.last_ns = ns

    def reset(self):
        self.ctl.reset()
        self.shaper.reset()
        self.armed = self.prev is not None


# -- import and interface ------------------------------------------------------------------
# (That the loop imports without rclpy is test/test_ros_free_imports.py.)
def test_the_status_bits_are_the_controller_state_message_s():
    from freejoint_msgs.msg import ControllerState as CS
    assert (STATUS_HOLDING, STATUS_RATE_LIMITED, STATUS_LAW_FAULT, STATUS_RESUMING,
            STATUS_DT_CLAMPED, STATUS_SETPOINT_LATE, STATUS_STOPPED) == (
        CS.STATUS_HOLDING, CS.STATUS_RATE_LIMITED, CS.STATUS_LAW_FAULT, CS.STATUS_RESUMING,
        CS.STATUS_DT_CLAMPED, CS.STATUS_SETPOINT_LATE, CS.STATUS_STOPPED)


# -- lockstep ---------------------------------------------------------------------------
def test_each_lockstep_tick_is_the_core_law_and_a_repeated_stamp_gets_the_same_answer():
    loop, _ = make()
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    for k in range(5):
        q, qd = _state_q(k)
        assert setpoint(loop, k, _setpoint(k)) is None
        res = state(loop, k, q, qd)
        out = ctl.step(q, qd, _setpoint(k)[0:2], _setpoint(k)[2:4], _setpoint(k)[4:6], DT)
        assert res.effort == out.tau.tolist()
        assert res.law_state_values[:5] == out.internal['theta_hat'].tolist()
        assert list(res.position) == out.p.tolist() and res.det_dd == out.internal['det']
        assert res.position_desired == _setpoint(k)[0:2]
        assert res.status == 0 and res.message == '' and res.stamp_ns == k * DT_NS
        assert res.law_state_names[:5] == tuple('theta_hat[%d]' % i for i in range(5))
        internal = out.internal
        assert res.law_state_values == internal['theta_hat'].tolist() + [
            internal['rho_hat']] + internal['delta_v'].tolist()
    again = state(loop, 4, *_state_q(4))
    assert again.repeated and again.law_state_values[:5] == ctl.theta.tolist()


def test_a_state_comes_before_its_setpoint_and_is_answered_when_the_setpoint_comes():
    loop, _ = make()
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    assert state(loop, 0) is None and loop.pending[0] == 0
    res = setpoint(loop, 0, _setpoint(0))
    assert res.effort == ctl.step(Q0, QD0, _setpoint(0)[0:2], _setpoint(0)[2:4],
                                  _setpoint(0)[4:6], DT).tau.tolist()


def test_a_batch_of_setpoints_answers_each_waiting_state_in_order_and_refuses_a_wrong_size():
    from freejoint_common.contract import SetpointSample
    loop, logs = make()
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())

    def sample(k, m=2):
        v = _setpoint(k)
        pad = (0.0,) * (m - 2)
        return SetpointSample(k * DT_NS, v[0:2] + pad, v[2:4] + pad, v[4:6] + pad, 0, 0.0,
                              False)

    published = []
    assert state(loop, 0) is None
    # state 0 waits: the batch answers it with setpoint 0, refuses setpoint 1, keeps 2
    loop.on_setpoints([sample(0), sample(1, m=3), sample(2)], 100.0,
                      lambda res: published.append((res.stamp_ns, list(res.effort))))
    sp0 = _setpoint(0)
    tau0 = ctl.step(Q0, QD0, sp0[0:2], sp0[2:4], sp0[4:6], DT).tau.tolist()
    assert published == [(0, tau0)]
    assert loop.refused_setpoints == 1
    assert 'setpoint stamped 1000000 ns refused: 3 values per vector, the task dimension ' \
        'is 2' in logs[-1][2]
    res = state(loop, 2)        # setpoint 1 was refused, setpoint 2 taken
    assert res.setpoint_ns == 2 * DT_NS


def test_joint_state_in_another_order_with_extra_joints_drives_it_the_same():
    loop, _ = make()
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    names = ['gripper', 'joint3', 'wrist', 'joint1', 'joint2']
    for k in range(3):
        q, qd = _state_q(k)
        out = ctl.step(q, qd, _setpoint(k)[0:2], _setpoint(k)[2:4], _setpoint(k)[4:6], DT)
        setpoint(loop, k, _setpoint(k))
        if k == 1:
            res = state(loop, k, (0.7, q[2], -1.0, q[0], q[1]),
                        (0.0, qd[2], 5.0, qd[0], qd[1]), names)
        else:
            res = state(loop, k, q, qd)
        assert res.effort == out.tau.tolist()
        assert res.law_state_values[:5] == out.internal['theta_hat'].tolist()


def test_lockstep_holds_when_setpoints_go_stale_and_answers_at_once_while_holding():
    loop, logs = make(case='vertical', stale_timeout=1.0)
    rep = Replica('vertical', lockstep=True)
    setpoint(loop, 0, _setpoint(0))
    res = state(loop, 0)
    assert res.effort == rep.tick(0, Q0, QD0, _setpoint(0))[0] and res.status == 0
    q1 = (Q0[0] + 0.002, Q0[1], Q0[2])
    assert state(loop, 1, q1, mono=200.0) is None
    assert loop.watchdog(0, 200.9) is None           # within stale_timeout: still waiting
    res = loop.watchdog(0, 201.1)
    effort, _, _, out = rep.tick(DT_NS, q1, QD0, None)
    assert res.effort == effort and res.effort != [0.0, 0.0]
    assert res.status & STATUS_HOLDING and res.status & STATUS_STALE_SETPOINT, res.message
    assert res.position_desired == tuple(rep.fk(q1))
    assert res.law_state_values[:5] == out.internal['theta_hat'].tolist()
    assert any('holding position' in text for _, _, text in logs)
    res = state(loop, 2)                             # answered at once, same frozen reference
    assert res.effort == rep.tick(2 * DT_NS, Q0, QD0, None)[0]
    assert res.position_desired == tuple(rep.fk(q1))
    for k in (3, 4):
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k)
        effort, ref, _, _ = rep.tick(k * DT_NS, Q0, QD0, _setpoint(k))
        assert res.effort == effort and res.status & STATUS_RESUMING
        assert res.position_desired == tuple(ref[0:2])


def test_lockstep_waits_for_the_first_setpoint_without_a_timeout():
    loop, _ = make()
    assert state(loop, 0) is None
    assert loop.watchdog(0, 1e6) is None and loop.pending is not None


def test_with_on_stale_zero_stale_setpoint_and_stale_state_command_zero_effort_and_say_so():
    loop, logs = make(stale_timeout=0.3, on_stale_setpoint='zero')
    setpoint(loop, 0, _setpoint(0))
    res = state(loop, 0, mono=10.0)
    assert res.status == 0 and res.effort != [0.0, 0.0]
    assert state(loop, 1, mono=10.001) is None
    res = loop.watchdog(0, 10.302)
    assert res.effort == [0.0, 0.0] and res.stamp_ns == DT_NS
    assert res.status == STATUS_STALE_SETPOINT and 'stale setpoint' in res.message
    res = loop.watchdog(0, 10.31)                     # no state for 0.3 s
    assert res.status == STATUS_STALE_STATE and res.effort == [0.0, 0.0]
    assert res.stamp_ns == DT_NS
    assert loop.watchdog(0, 11.0) is None             # once
    assert ('warn', None, 'no joint_states for 0.3 s: zero effort') in logs


# -- guards -----------------------------------------------------------------------------
def test_missing_joint_short_arrays_and_non_finite_state_are_refused_with_zero_effort():
    loop, logs = make()
    setpoint(loop, 0, _setpoint(0))
    res = loop.on_state(0, ['joint1', 'joint2'], Q0[:2], QD0[:2], 0, 1.0)
    assert res.effort == [0.0, 0.0] and res.status == STATUS_BAD_INPUT
    assert "lacks joint(s) ['joint3']" in res.message
    setpoint(loop, 1, _setpoint(1))
    res = loop.on_state(DT_NS, NAMES, list(Q0), list(QD0[:2]), 0, 1.0)
    assert res.status == STATUS_BAD_INPUT and '3 names but 3 positions and 2 vel' in res.message
    setpoint(loop, 2, _setpoint(2))
    res = state(loop, 2, (Q0[0], math.nan, Q0[2]))
    assert res.effort == [0.0, 0.0] and 'non-finite' in res.message
    assert [kind for level, kind, _ in logs] == ['missing', 'short', 'nonfinite']
    assert loop.refused_states == 3 and loop.zero_answers == 3
    # A good state afterwards: the law, ramped up from the zero effort at the rate limit.
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    setpoint(loop, 3, _setpoint(3))
    res = state(loop, 3)
    tau = ctl.step(Q0, QD0, _setpoint(3)[0:2], _setpoint(3)[2:4], _setpoint(3)[4:6],
                   DT).tau.tolist()
    assert res.effort == [max(-20.0, min(20.0, x)) for x in tau]
    assert res.status == (STATUS_RATE_LIMITED if res.effort != tau else 0)
    assert res.law_state_values[:5] == ctl.theta.tolist()


FAULTS = {
    'qd_1e10': ('state', lambda q, qd: (q, (qd[0], 1e10, qd[2])),
                'joint 1 velocity 10000000000.0'),
    'qd_1e160': ('state', lambda q, qd: (q, (1e160, qd[1], qd[2])), 'joint 0 velocity 1e+160'),
    'q_1e6': ('state', lambda q, qd: ((q[0], q[1], 1e6), qd), 'joint 2 position 1000000.0'),
    'setpoint_1e300': ('setpoint', None, 'beyond the reach'),
    'K_1e300': ('param', None, 'K: values must be <= 10000'),
}


@pytest.mark.parametrize('fault', sorted(FAULTS))
def test_absurd_input_is_refused_with_a_reason_and_tracking_resumes_within_half_a_second(fault):
    kind, corrupt, reason = FAULTS[fault]
    loop, logs = make(case='vertical', lockstep=False, max_state_age=0.0, resume_time=0.01,
                      stale_timeout=2.0)
    rep = Replica('vertical', lockstep=False, resume=0.01)
    k_fault = 20
    for k in range(k_fault):
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k)
        assert res.effort == rep.tick(k * DT_NS, Q0, QD0, _setpoint(k))[0]
    theta_before = res.law_state_values[:5]
    k = k_fault
    if kind == 'state':
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k, *corrupt(Q0, QD0))
        # Real time: the stop command, the nominal model's gravity load at the last good
        # state (what a driver holding its last command keeps), not zero effort.
        hold = ArmModel(table1('vertical').scaled(0.7)).gravity_torque(Q0)[0:2].tolist()
        assert res.effort == pytest.approx(hold, abs=1e-12) and min(map(abs, hold)) > 1.0
        assert res.status == STATUS_BAD_INPUT, res.message
        assert reason in res.message and res.law_state_values[:5] == theta_before
        assert 'implausible state' in logs[-1][2]
        rep.zero(k * DT_NS, res.effort)
    elif kind == 'setpoint':
        setpoint(loop, k, (1e300, 0.0, 0.0, 0.0, 0.0, 0.0))
        res = state(loop, k)
        # Dropped: the previous setpoint (1 ms old, still fresh), carried forward.
        effort, ref, _, _ = rep.tick(k * DT_NS, Q0, QD0, _setpoint(k - 1), (k - 1) * DT_NS)
        assert res.effort == effort and res.position_desired == tuple(ref[0:2])
        assert 'setpoint stamped %d ns refused: position (1e+300' % (k * DT_NS) in logs[-1][2]
        assert reason in logs[-1][2] and loop.refused_setpoints == 1
    else:
        # A parameter change: refused by the configuration's validation, the loop unchanged.
        values = dict(loop.config.values, K=[1e300, 1e300])
        with pytest.raises(FreejointValueError, match='^' + reason):
            SCHEMA.config(values)
        assert SCHEMA.reason(values).startswith(reason)
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k)
        assert res.effort == rep.tick(k * DT_NS, Q0, QD0, _setpoint(k))[0]
    assert _finite_within(res.effort) and all(map(math.isfinite, res.law_state_values))
    resumed = None
    for k in range(k_fault + 1, k_fault + 501):
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k)
        effort = rep.tick(k * DT_NS, Q0, QD0, _setpoint(k))[0]
        assert res.effort == effort and _finite_within(res.effort), k
        if resumed is None and not res.status & ~0x1:
            resumed = k
    assert resumed is not None and resumed - k_fault <= 500


def test_a_live_gain_change_applies_on_the_next_tick():
    loop, _ = make()
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    setpoint(loop, 0, _setpoint(0))
    state(loop, 0)
    ctl.step(Q0, QD0, _setpoint(0)[0:2], _setpoint(0)[2:4], _setpoint(0)[4:6], DT)
    old = loop.config
    loop.apply(old, SCHEMA.config(dict(old.values, K=[40.0, 60.0], robust=False)))
    ctl.set_gains(Gains(K=(40.0, 60.0), robust=False))
    q, qd = _state_q(1)
    setpoint(loop, 1, _setpoint(1))
    res = state(loop, 1, q, qd)
    assert res.effort == ctl.step(q, qd, _setpoint(1)[0:2], _setpoint(1)[2:4],
                                  _setpoint(1)[4:6], DT).tau.tolist()
    assert res.law_state_values[6:8] == [0.0, 0.0]


def test_per_joint_effort_limits_clip_each_joint_and_say_so():
    loop, _ = make(effort_limits=[5.0, 3.0])
    ctl = RobustController(table1('horizontal').scaled(0.7), Gains())
    for k in range(3):
        q, qd = _state_q(k)
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k, q, qd)
        tau = ctl.step(q, qd, _setpoint(k)[0:2], _setpoint(k)[2:4], _setpoint(k)[4:6],
                       DT).tau.tolist()
        assert res.effort == [max(-5.0, min(5.0, tau[0])), max(-3.0, min(3.0, tau[1]))]
        assert res.status & STATUS_TORQUE_LIMITED
        assert 'torque limited to [5.0, 3.0] N m' in res.message


# -- real time --------------------------------------------------------------------------
def test_real_time_holds_against_gravity_before_the_first_setpoint_and_resumes_without_a_step():
    loop, _ = make(case='vertical', lockstep=False, max_state_age=0.0, resume_time=0.05,
                   stale_timeout=2.0, resume_max_velocity=100.0, resume_max_acceleration=1e4)
    rep = Replica('vertical', lockstep=False, resume=0.05, resume_bounds=(100.0, 1e4))
    q, qd = Q0, (0.0, 0.0, 0.0)
    hold = tuple(rep.fk(q))
    offset = 0
    prev = [0.0, 0.0]
    refs = []
    for k in range(160):
        sp = _moving_setpoint(k, hold) if 10 <= k < 80 or k >= 120 else None
        if k == 100:
            q = (Q0[0] + 0.01, Q0[1], Q0[2])       # the arm moved: a new hold starts here
            offset = 2_100_000_000                 # and 2.1 s of stamps passed meanwhile
        ns = k * DT_NS + offset
        if sp is not None:
            loop.on_setpoint(ns, sp, 0, 0.0)
        res = loop.on_state(ns, NAMES, q, qd, ns + 500_000, 0.0)
        used = _moving_setpoint(min(k, 79), hold) if 80 <= k < 100 else sp
        effort, ref, dt, out = rep.tick(ns, q, qd, used, 79 * DT_NS if 80 <= k < 100 else None)
        assert res.effort == effort, k
        assert res.law_state_values[:5] == out.internal['theta_hat'].tolist(), k
        assert res.position_desired == tuple(ref[0:2]) and res.dt == dt
        assert res.state_age == 5e-4
        if k in (0, 100):
            assert max(abs(a - b) for a, b in zip(res.effort, prev)) <= RATE * dt + 1e-9, k
        prev = res.effort
        refs.append(ref[0:2])
        holding = bool(res.status & STATUS_HOLDING)
        if k < 10:
            assert holding and not res.status & STATUS_STALE_SETPOINT, res.message
            assert res.position_desired == hold and 'no setpoint yet' in res.message
            assert res.setpoint_ns is None
        elif k < 60 or 120 <= k < 170:
            assert res.status & STATUS_RESUMING and not holding and res.setpoint_ns == ns
        elif 100 <= k < 120:
            assert holding and res.status & STATUS_STALE_SETPOINT, (k, res.message)
            assert res.position_desired == tuple(rep.fk(q)) and 'stale setpoint' in res.message
        else:
            assert not holding and not res.status & STATUS_RESUMING, (k, res.message)
        if 80 <= k < 100:
            assert res.setpoint_age == pytest.approx((k - 79) * DT, abs=1e-12)
    assert max(abs(x) for x in rep.tick(1, Q0, qd, None)[0]) > 5.0  # gravity is held
    steps = [math.dist(a, b) for a, b in zip(refs, refs[1:])]
    assert max(steps[:99]) < 2e-3 and max(steps[101:]) < 2e-3
    assert loop.holds == 2 and loop.stale_periods == 1


def test_real_time_dt_comes_from_the_state_stamps_bounded_to_four_periods():
    loop, logs = make(lockstep=False, max_state_age=0.0, resume_time=0.0, stale_timeout=2.0)
    rep = Replica('horizontal', lockstep=False, resume=0.0)
    for k, want in ((0, DT), (2, 0.002), (4, 0.002), (6, 0.002), (36, 0.004), (38, 0.002)):
        q, qd = _state_q(k)
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k, q, qd)
        effort, _, dt, out = rep.tick(k * DT_NS, q, qd, _setpoint(k))
        assert dt == want and res.dt == want and res.effort == effort
        assert bool(res.status & STATUS_DT_CLAMPED) == (k == 36), res.message
    assert any('outside [0.25, 4] x control_period' in text for _, _, text in logs)


def test_restarted_real_time_controller_ramps_its_torque_from_zero_without_a_spike():
    loop, _ = make(case='vertical', lockstep=False, max_state_age=0.0, stale_timeout=2.0)
    rep = Replica('vertical', lockstep=False)
    base = rep.fk(Q0)
    prev = [0.0, 0.0]
    limited = []
    for k in range(30):
        q = tuple(v + 1e-4 * k for v in Q0)
        qd = (0.1, -0.1, 0.5)
        setpoint(loop, k, _moving_setpoint(k, base))
        res = state(loop, k, q, qd)
        assert res.effort == rep.tick(k * DT_NS, q, qd, _moving_setpoint(k, base))[0]
        assert max(abs(a - b) for a, b in zip(res.effort, prev)) <= RATE * DT + 1e-9
        limited.append(bool(res.status & STATUS_RATE_LIMITED))
        prev = res.effort
    assert limited[0] and not limited[-1]


def test_reset_restarts_theta_hat_and_blends_in_again_from_the_arm():
    loop, _ = make(lockstep=False, max_state_age=0.0, resume_time=0.01, stale_timeout=2.0)
    rep = Replica('horizontal', lockstep=False, resume=0.01)
    qd = (1.0, -2.0, 3.0)
    for k in range(25):
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k, Q0, qd)
        assert res.effort == rep.tick(k * DT_NS, Q0, qd, _setpoint(k))[0]
    assert max(res.law_state_values[:5]) > 0.0 and not res.status & STATUS_RESUMING
    loop.reset()
    loop.reset()            # twice: as once
    rep.reset()
    setpoint(loop, 25, _setpoint(25))
    res = state(loop, 25, Q0, qd)
    effort, ref, _, out = rep.tick(25 * DT_NS, Q0, qd, _setpoint(25))
    assert res.effort == effort and res.law_state_values[:5] == out.internal['theta_hat'].tolist()
    assert res.status & STATUS_RESUMING and res.position_desired == tuple(rep.fk(Q0))


def test_time_going_back_restarts_the_law_and_forgets_the_setpoints():
    loop, logs = make(lockstep=False, max_state_age=0.0, stale_timeout=2.0)
    for k in range(10, 15):
        setpoint(loop, k, _setpoint(k))
        state(loop, k, Q0, (1.0, -2.0, 3.0))
    res = state(loop, 0)
    assert res.status & STATUS_HOLDING and 'no setpoint yet' not in res.message
    theta = res.law_state_values[:5]
    assert theta == list(Gains().theta0) or max(theta) < 1e-6
    assert any('state time went back from 14000000 to 0 ns' in t for _, _, t in logs), logs


def test_a_late_setpoint_stream_is_carried_forward_then_held_and_rejoined_without_a_step():
    loop, _ = make(lockstep=False, max_state_age=0.0, stale_timeout=2.0, resume_time=0.02,
                   carry_forward_time=0.05)
    rep = Replica('horizontal', lockstep=False, resume=0.02)
    q, qd = Q0, (0.0, 0.0, 0.0)
    base = rep.fk(q)

    def stream(j):
        t = j * DT
        return (base[0] + 0.1 * t + 0.5 * t * t + 5.0 * t ** 3, base[1],
                0.1 + t + 15.0 * t * t, 0.0, 1.0 + 30.0 * t, 0.0)
    refs = []
    blend_end = None
    for k in range(330):
        if not 30 <= k < 90:
            setpoint(loop, k, stream(k))
        res = state(loop, k, q, qd)
        if 80 <= k < 90:
            effort, ref, _, _ = rep.tick(k * DT_NS, q, qd, None)
        else:
            sp_k = min(k, 29) if 30 <= k < 90 else k
            effort, ref, _, _ = rep.tick(k * DT_NS, q, qd, stream(sp_k), sp_k * DT_NS)
        assert res.effort == effort and res.position_desired == tuple(ref[0:2]), k
        assert bool(res.status & STATUS_SETPOINT_LATE) == (40 <= k < 90), (k, res.message)
        assert bool(res.status & STATUS_HOLDING) == (80 <= k < 90), (k, res.message)
        if 40 <= k < 80:
            assert 'setpoint late' in res.message
        if 80 <= k < 90:
            assert 'setpoint stream late' in res.message
        if k == 90:
            blend_end = 90 + math.ceil(rep.shaper.blend_duration / DT - 1e-9)
        if k >= 90:
            assert bool(res.status & STATUS_RESUMING) == (k < blend_end), k
        refs.append(ref)
    assert refs[79][0] - refs[29][0] > 0.005
    for k in range(1, 330):
        if k != 80:
            assert abs(refs[k][0] - refs[k - 1][0] - refs[k - 1][2] * DT) < 2e-5, k


def test_position_planned_is_the_streamed_setpoint_while_the_reference_is_carried_or_held():
    # The late stream above: no setpoint from 30 to 89 ms. The reference is carried forward
    # (40-79), then held (80-89), then blends back; position_planned is the newest
    # setpoint as streamed throughout, and the error against it is |position - planned|.
    loop, _ = make(lockstep=False, max_state_age=0.0, stale_timeout=2.0, resume_time=0.02,
                   carry_forward_time=0.05)
    q, qd = Q0, (0.0, 0.0, 0.0)
    base = loop.law.model.fk(q).tolist()

    def stream(j):
        return (base[0] + 1e-4 * j, base[1], 0.1, 0.0, 0.0, 0.0)
    plan_errors = []
    for k in range(120):
        if not 30 <= k < 90:
            setpoint(loop, k, stream(k))
        res = state(loop, k, q, qd)
        newest = min(k, 29) if 30 <= k < 90 else k
        assert tuple(res.position_planned) == stream(newest)[0:2], k
        if 40 <= k < 90:
            assert tuple(res.position_desired) != tuple(res.position_planned), k
        plan_errors.append(math.dist(res.position, stream(newest)[0:2]))
    values = dict(loop.diagnostics(1.0, loop.counters(), False, ('1.0', '2.0'),
                                   '/joint_states', None)[3])
    assert values['error vs plan max [mm]'] == '%.4g' % (max(plan_errors) * 1e3)
    assert values['error vs plan [mm]'] == '%.4g' % (plan_errors[-1] * 1e3)


def test_position_planned_is_the_lockstep_setpoint_and_empty_without_a_plan():
    loop, _ = make(stale_timeout=0.5)
    for k in range(3):
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k)
        assert tuple(res.position_planned) == _setpoint(k)[0:2]
    state(loop, 3)
    res = loop.watchdog(0, 100.0 + 3 * DT + 1.0)        # stale: the lockstep hold
    assert res.status & STATUS_HOLDING and tuple(res.position_planned) == ()
    values = dict(loop.diagnostics(1.0, loop.counters(), False, ('1.0', '2.0'),
                                   '/joint_states', None)[3])
    assert values['error vs plan [mm]'] == '-'


def test_real_time_skips_a_state_older_than_max_state_age_without_a_command():
    loop, logs = make(lockstep=False, max_state_age=2.0)
    now = 10_000 * DT_NS + 20_000_000_000
    assert loop.on_state(10_000 * DT_NS, NAMES, Q0, QD0, now, 1.0) is None
    assert 'skipped, no command from it' in logs[-1][2] and loop.old_states == 1
    res = loop.on_state(now - 1_000_000, NAMES, Q0, QD0, now, 1.0)
    assert res.status & STATUS_HOLDING and res.state_age == pytest.approx(1e-3)
    assert '1 states skipped as too old' in loop.report()


@pytest.mark.parametrize('case', ['horizontal', 'vertical'])
def test_stale_state_in_real_time_sends_the_stop_command_then_holds_anew(case):
    loop, _ = make(case=case, lockstep=False, max_state_age=0.0, stale_timeout=0.5)
    setpoint(loop, 0, _setpoint(0))
    state(loop, 0, mono=1.0)
    res = loop.watchdog(2 * DT_NS, 1.6)
    # The gravity load of the active joints at the last state (0 in a horizontal plane).
    hold = ArmModel(table1(case).scaled(0.7)).gravity_torque(Q0)[0:2].tolist()
    assert res.status == STATUS_STALE_STATE and res.effort == pytest.approx(hold, abs=1e-12)
    assert loop.shaper.mode == MODE_NONE
    assert loop.watchdog(3 * DT_NS, 1.7) is None        # once


def test_delay_compensation_predict_runs_the_law_on_the_predicted_state():
    from freejoint_core.delay import extrapolate_setpoint, StatePredictor
    loop, _ = make(case='vertical', lockstep=False, max_state_age=0.0, stale_timeout=2.0,
                   resume_time=0.0, delay_compensation='predict')
    # With the predictor the law keeps the paper's chattering bound in real time.
    rep = Replica('vertical', lockstep=False, resume=0.0, gains=Gains(
        tau_limit=LIMITS, theta_max=(100.0,) * 5))
    pred = StatePredictor(table1('vertical').scaled(0.7), DT)
    for k in range(5):
        setpoint(loop, k, _setpoint(k))
        ns = k * DT_NS
        res = loop.on_state(ns, NAMES, Q0, QD0, ns + 2_500_000, 0.0)   # 2.5 ms old: 3 ticks
        q_p, qd_p = pred.predict(Q0, QD0, 3)
        ref = rep.shaper.track(ns * 1e-9, _setpoint(k), rep.fk(Q0) if k == 0 else None)[0]
        p, v, a = extrapolate_setpoint(ref[0:2], ref[2:4], ref[4:6], 3 * DT)
        out = rep.ctl.step(q_p, qd_p, p, v, a, DT)
        effort = out.tau.tolist()
        if rep.armed:
            effort, _, rep.armed = limit_effort(effort, LIMITS, rep.prev, RATE * DT)
        rep.prev = effort
        pred.push(effort)
        assert res.effort == effort, k
        assert list(res.position) == rep.fk(Q0)


# -- law faults and the law seam ----------------------------------------------------------
def test_a_non_finite_law_result_is_never_returned_and_the_law_state_is_restored():
    loop, logs = make(case='vertical', lockstep=False, max_state_age=0.0, resume_time=0.0,
                      stale_timeout=2.0)
    law = loop.law
    real_step = law.step
    k_bad = 5
    tick = {'k': 0}

    def step(q, qd, p_d, pd_d, pdd_d, dt):
        if tick['k'] == k_bad:
            qd = (1e160, qd[1], qd[2])      # the law's psi overflows: theta_hat inf
        return real_step(q, qd, p_d, pd_d, pdd_d, dt)
    law.step = step
    rep = Replica('vertical', lockstep=False, resume=0.0)
    results = []
    for k in range(8):
        tick['k'] = k
        setpoint(loop, k, _setpoint(k))
        res = state(loop, k)
        results.append((list(res.effort), res.law_state_values[:5], res.status))
        assert _finite_within(res.effort) and all(map(math.isfinite, res.law_state_values))
        if k == k_bad:
            assert res.status & STATUS_LAW_FAULT and 'law fault' in res.message
            assert res.effort == results[-2][0] and res.law_state_values[:5] == results[-2][1]
            assert loop.law.save_state() == tuple(results[-2][1])
            rep.shaper.track(k * DT_NS * 1e-9, _setpoint(k), None)
            rep.last_ns = k * DT_NS
            rep.armed = False
        else:
            expected, _, _, out = rep.tick(k * DT_NS, Q0, QD0, _setpoint(k))
            assert res.effort == expected, k
            assert res.law_state_values[:5] == out.internal['theta_hat'].tolist(), k
            assert not res.status & STATUS_LAW_FAULT
    assert loop.faults == 1 and '1 law faults' in loop.report()
    assert any(kind == 'fault' for _, kind, _ in logs)


def test_a_second_law_is_one_registration_and_one_parameter_value():
    """The nominal inverse dynamics (what ``robust: false`` computes) as a separate law."""
    import numpy as np
    from freejoint_core.laws import ControlLaw, LAWS, LawOutput, register_law
    from freejoint_core.models import make_model

    class NominalInverseDynamics(ControlLaw):
        name = 'nominal_id'
        state_names = ()

        def __init__(self, nominal, gains, model=None):
            self.model = model or make_model(nominal)
            self.gains = gains
            self.stiffness = 1.0

        def step(self, q, qd, p_d, pd_d, pdd_d, dt):
            m = self.model
            p = m.fk(q)
            e = p - np.asarray(p_d)
            edot = m.jacobian(q) @ np.asarray(qd) - np.asarray(pd_d)
            k = np.array(self.gains.K) * self.stiffness
            lam = np.array(self.gains.Lambda) * self.stiffness
            v = np.asarray(pdd_d) - (k + lam) * edot - k * lam * e
            da, b = m.decoupling(q, qd)
            tau = da.T @ np.linalg.solve(da @ da.T, v - b)
            tau = np.clip(tau, -np.array(self.gains.tau_limit), np.array(self.gains.tau_limit))
            return LawOutput(tau, e, edot, edot + lam * e, p, 0, {})   # no internal values

    register_law('nominal_id', NominalInverseDynamics)
    try:
        loop, _ = make(law='nominal_id')
        assert type(loop.law) is NominalInverseDynamics and loop.result.law_state_names == ()
        ctl = RobustController(table1('horizontal').scaled(0.7), Gains(robust=False))
        for k in range(4):
            q, qd = _state_q(k)
            setpoint(loop, k, _setpoint(k))
            res = state(loop, k, q, qd)
            out = ctl.step(q, qd, _setpoint(k)[0:2], _setpoint(k)[2:4], _setpoint(k)[4:6], DT)
            assert res.effort == pytest.approx(out.tau.tolist(), rel=1e-9, abs=1e-9)
            assert res.det_dd == 0.0 and res.law_state_values == []   # declares none
            assert res.law_state_values == []
    finally:
        del LAWS['nominal_id']
    with pytest.raises(FreejointValueError, match='^law: expected one of'):
        SCHEMA.config(dict(FILE, law='nominal_id'))


# -- standby ----------------------------------------------------------------------------
def test_standby_readiness_waits_for_matching_the_stream_and_settling():
    loop, _ = make(lockstep=False, standby=True)
    assert loop.standby and loop.waiting_for == 'start-up'
    names = ('/effort_controller/commands', '/setpoints')
    assert loop.standby_waits_for(0, 1, 1, 1, 0.0, 0, names) == (
        '/effort_controller/commands matched by 0 of its 1 subscribers')
    assert loop.standby_waits_for(1, 1, 0, 1, 0.0, 0, names) == (
        '/setpoints: 0 of its 1 publishers matched')
    assert loop.standby_waits_for(1, 1, 0, 0, 0.0, 0, names) == ''     # no planner
    assert loop.standby_waits_for(1, 1, 1, 1, 10.0, 0, names) == (
        'the setpoint stream matched, no setpoint received yet')
    assert loop.standby_waits_for(1, 1, 1, 1, 10.3, 0, names) == ''    # silent: not streaming
    now = 5_000_000_000
    loop.on_setpoint(now - 100_000_000, _setpoint(0), 0, 10.35)
    assert loop.standby_waits_for(1, 1, 1, 1, 10.4, now, names) == (
        'the setpoint stream catching up (newest 0.100 s old)')
    loop.on_setpoint(now - 10_000_000, _setpoint(0), 0, 10.41)
    waits = loop.standby_waits_for(1, 1, 1, 1, 10.42, now, names)
    assert waits == ''
    assert not loop.standby_settled('x', 10.0) and loop.waiting_for == 'x'
    assert not loop.standby_settled('', 10.0) and loop.waiting_for == 'the graph settling'
    assert not loop.standby_settled('', 10.4)
    assert loop.standby_settled('', 10.5) and loop.waiting_for == ''


def test_an_activated_spare_starts_from_the_measured_motion_and_ramps_from_zero():
    loop, _ = make(case='vertical', lockstep=False, standby=True, max_state_age=0.0)
    base = Replica('vertical', lockstep=False).fk(Q0)
    setpoint(loop, 0, _moving_setpoint(0, base))
    loop.activate()
    res = state(loop, 0, Q0, (0.1, -0.1, 0.5))
    assert not loop.standby and res.status & STATUS_RESUMING
    assert res.position_desired == pytest.approx(base, abs=1e-12)
    assert max(abs(x) for x in res.effort) <= RATE * DT + 1e-12


# -- diagnostics ------------------------------------------------------------------------
def test_diagnostics_say_holding_then_tracking_then_stale_then_no_state():
    loop, _ = make(lockstep=False, max_state_age=0.0, resume_time=0.0)
    errors, warnings, ok, values = loop.diagnostics(1.0, loop.counters(), True, ('-', '-'),
                                                    '/joint_states', None)
    assert errors == ['no joint_states yet on /joint_states']
    start = loop.counters()
    for k in range(5):
        state(loop, k)
    errors, warnings, ok, values = loop.diagnostics(1.0, start, False, ('1.0', '2.0'),
                                                    '/joint_states', None)
    values = dict(values)
    assert not errors and 'holding at' in warnings[0] and 'no setpoint yet' in warnings[0]
    assert values['holds'] == 1 and values['answer rate [Hz]'] == '5.0'
    start = loop.counters()
    for k in range(5, 10):
        setpoint(loop, k, _setpoint(k))
        state(loop, k)
    errors, warnings, ok, values = loop.diagnostics(1.0, start, False, ('1.0', '2.0'),
                                                    '/joint_states', None)
    assert ok.startswith('torque change limited') or ok == 'tracking' or warnings, ok
    assert dict(values)['mode'] == 'realtime' and dict(values)['law faults'] == 0
    loop.watchdog(0, 1e6)
    errors, _, _, _ = loop.diagnostics(1.0, loop.counters(), True, ('-', '-'),
                                       '/joint_states', None)
    assert errors == ['no joint_states for 0.5 s: the stop command sent (gravity hold), the '
                      'brakes asked for']
    assert loop.result.status == STATUS_STALE_STATE and loop.result.effort == [0.0, 0.0]
    assert loop.take_brake_request() == 'stale state: no joint_states within 0.5 s: brake now'
    assert loop.take_readiness()[1:] == (False, 'stale state: no joint_states within 0.5 s: '
                                         'stop command sent (the gravity hold of the active '
                                         'joints), the brakes asked for; no command until '
                                         'the loop is ready again')
    state(loop, 10)     # states again: ready (no guard here)
    assert loop.take_readiness() == (10 * DT_NS, True, '')
