"""
A joint fails during the task: the controller's loop in one process.

The loop is driven in lockstep by the core's plant stepped here (``Plant.fail_joint``), no
DDS, no clock; the setpoints are the paper's circle.  The reference for the detection and
the switch is the offline runner (``freejoint_core.failure_offline``) on the same seed.
"""
from dataclasses import replace
import math
import os

from freejoint_control.failures import FailureMonitor, precompute_verdicts
from freejoint_control.loop import ControlLoop
from freejoint_control.params import SCHEMA
from freejoint_core.arm import NOMINAL_SCALE, table1
from freejoint_core.control import Gains, RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.failure import CANNOT_TRACK, TRACKING
from freejoint_core.failure_offline import FAILURE_FREE_LINK_DAMPING, run_failure_case
from freejoint_core.laws import FreeLinkDampedLaw
from freejoint_core.offline import initial_state
from freejoint_core.plant import DEFAULT_DT_SUB, Plant
from freejoint_core.trajectory import CircleQuintic
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FILE = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'))
FULL = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'),
                          os.path.join(ROOT, 'config', 'fully_actuated', 'controller.yaml'))
DT = 0.001
DT_NS = 1_000_000
NAMES = ['joint1', 'joint2', 'joint3']
TRAJ = CircleQuintic()


def make(base, **given):
    """Return (loop, log lines) of a parameter file's values with ``given`` on top."""
    values = dict(base)
    values.update(given)
    logs = []
    loop = ControlLoop(SCHEMA.config(values), lambda level, kind, text: logs.append(
        (level, kind, text)))
    return loop, logs


def run(loop, case, seconds, fail=(), seed=0, notices=None, effort=True, passive=()):
    """
    Drive ``loop`` in lockstep with the core plant (its joints failing as ``fail`` says).

    Returns
    -------
    dict
        ``cmd`` (ticks, r) commands, ``err`` (ticks,) tracking error [m], ``msg`` the
        status messages, ``q``, ``qd`` (ticks, n) the states answered.

    """
    real = table1(case)
    q0 = initial_state(real, 120.0, TRAJ.sample(0.0)[0])
    plant = Plant(replace(real, passive=tuple(passive)), DEFAULT_DT_SUB, seed=seed, q0=q0)
    for j, at in fail:
        plant.fail_joint(j, at)
    notices = dict(notices or {})
    out = {'cmd': [], 'err': [], 'msg': [], 'q': [], 'qd': []}
    for k in range(int(round(seconds / DT))):
        t = k * DT
        for name in notices.pop(k, ()):
            assert loop.on_failure_notice(name) == ''
        ns = k * DT_NS
        q, qd = plant.q.tolist(), plant.qd.tolist()
        assert loop.on_state(ns, NAMES, q, qd, 0, 100.0 + t,
                             list(plant.last_effort) if effort else None) is None
        sp = TRAJ.sample_tuple(t)
        res = loop.on_setpoint(ns, sp, 0, 100.0 + t)
        cmd = list(res.effort)
        out['cmd'].append(cmd)
        out['err'].append(math.hypot(res.position[0] - sp[0], res.position[1] - sp[1]))
        out['msg'].append(res.message)
        out['q'].append(q)
        out['qd'].append(qd)
        plant.step(cmd, DT)
    for key in ('cmd', 'err', 'q', 'qd'):
        out[key] = np.array(out[key])
    return out


def test_the_fully_actuated_config_drives_all_three_joints_with_nullspace_damping():
    cfg = SCHEMA.config(dict(FULL))
    assert cfg.nominal.passive == () and cfg.nominal.r == 3
    assert tuple(cfg.joints) == tuple(NAMES)
    loop, _ = make(FULL)
    assert loop.law.nullspace is not None and loop.law.nullspace.kd == 3.0
    assert loop.failures is not None and loop.failures.detect


def test_joint_failures_off_builds_no_monitor_and_takes_no_notice():
    loop, logs = make(FILE)
    assert loop.failures is None
    assert 'joint_failures is off' in loop.on_failure_notice('joint2')
    assert logs and 'ignored' in logs[-1][2]


def test_a_bad_failure_parameter_is_refused_naming_it():
    with pytest.raises(FreejointValueError, match='joint_failures'):
        SCHEMA.config(dict(FILE, joint_failures='sometimes'))
    with pytest.raises(FreejointValueError, match='failure_observer_gain'):
        SCHEMA.config(dict(FILE, joint_failures='detect', failure_observer_gain=2500.0))


def test_detection_off_a_failing_joint_changes_nothing_the_bare_law_bit_for_bit():
    # Joint 2 of the paper's arm goes limp at 0.1 s; with joint_failures off every command
    # is RobustController's on the same states, element by element.
    loop, logs = make(FILE, case='vertical')
    out = run(loop, 'vertical', 0.3, fail=[(1, 0.1)], passive=(2,))
    ctl = RobustController(table1('vertical').scaled(NOMINAL_SCALE),
                           Gains(tau_limit=tuple(FILE['effort_limits']),
                                 theta_max=(100.0,) * 5))
    for k in range(len(out['cmd'])):
        px, py, vx, vy, ax, ay = TRAJ.sample_tuple(k * DT)
        tau = ctl.step(out['q'][k], out['qd'][k], (px, py), (vx, vy), (ax, ay), DT).tau
        assert tau.tolist() == out['cmd'][k].tolist()
    assert not any('failed' in m for m in out['msg'])
    assert not any('fail' in text for _, _, text in logs)


@pytest.mark.parametrize('case', ['vertical', 'horizontal'])
def test_joint3_failure_is_found_by_the_residual_the_law_switches_as_offline_bit_for_bit(case):
    # Fully actuated, seed 0, joint 3 limp from 2.5 s, residual only (no effort, no notice).
    loop, logs = make(FULL, case=case, failure_use_effort=False)
    out = run(loop, case, 2.7, fail=[(2, 2.5)])
    (event,) = loop.failures.events
    assert event['joint'] == 'joint3' and event['by'] == 'residual'
    assert event['verdict'] == TRACKING and event['passive'] == ['joint3']
    delay = event['t'] - 2.5
    assert 0.0 < delay <= (0.020 if case == 'vertical' else 0.100)
    k_switch = int(round(event['t'] / DT))
    assert np.all(out['cmd'][k_switch:, 2] == 0.0)          # joint 3 no longer commanded
    assert np.any(out['cmd'][2400:k_switch, 2] != 0.0)
    assert loop.law.nominal.passive == (2,) and loop.law.nullspace is None
    assert 'joint3 failed at t = %.3f s (detected by residual)' % event['t'] in \
        out['msg'][k_switch]
    assert any(level == 'warn' and 'joint3 failed' in text for level, _, text in logs)
    assert out['err'].max() < (5.5e-3 if case == 'vertical' else 1.7e-3)
    # The detection is announced once (the node publishes it on joint_failures); that
    # announcement coming back as a notice is taken silently.
    assert loop.failures.announcements() == ['joint3']
    assert loop.failures.announcements() == []
    lines = len(logs)
    assert loop.on_failure_notice('joint3') == 'joint3 failed already'
    assert len(logs) == lines and loop.failures.events == [event]
    # The offline runner on the same seed: same detection tick, same commands, same states.
    rec, trace = run_failure_case(case, 0, [(2, 2.5)], duration=2.7, record_trace=True)
    assert rec['detected_at_s'] == [round(event['t'], 9)]
    assert np.array_equal(out['cmd'], trace['tau'])
    assert np.array_equal(out['q'], trace['q'])


DAMPED = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'),
                            os.path.join(ROOT, 'config', 'fully_actuated', 'controller.yaml'),
                            os.path.join(ROOT, 'config', 'fully_actuated',
                                         'free_link_damping.yaml'))


def test_the_freed_link_is_damped_in_the_rest_after_the_failure_as_offline_bit_for_bit():
    # The overlay is the offline option: mode, bound and drive (k2 as tracking, at once).
    assert (DAMPED['free_link_mode'], DAMPED['free_link_delta_max'],
            DAMPED['free_link_drive_max']) == tuple(FAILURE_FREE_LINK_DAMPING[k] for k in (
                'mode', 'delta_max', 'sat'))
    assert DAMPED['free_link_rest_damping'] == 0.2 and DAMPED['free_link_rest_after'] == 0.0
    loop, _ = make(DAMPED, case='vertical', failure_use_effort=False)
    assert isinstance(loop.law, FreeLinkDampedLaw) and loop.law.modulation is None
    # Joint 3 fails at 2.5 s; the circle ends at 5 s, then 1 s of rest.
    out = run(loop, 'vertical', 6.0, fail=[(2, 2.5)])
    (event,) = loop.failures.events
    assert event['passive'] == ['joint3'] and loop.law.modulation is not None
    assert np.any(loop.law.modulation.delta != 0.0)           # it acted in the rest
    rec, trace = run_failure_case('vertical', 0, [(2, 2.5)], duration=6.0, record_trace=True,
                                  free_link_damping=FAILURE_FREE_LINK_DAMPING)
    assert rec['detected_at_s'] == [round(event['t'], 9)]
    assert np.array_equal(out['cmd'], trace['tau'])
    assert np.array_equal(out['q'], trace['q'])
    # ... and not the undamped arm's rest (the same circle up to its end).
    plain, plain_trace = run_failure_case('vertical', 0, [(2, 2.5)], duration=6.0,
                                          record_trace=True)
    k_end = int(round(TRAJ.duration / DT))
    assert np.array_equal(out['cmd'][:k_end], plain_trace['tau'][:k_end])
    assert not np.array_equal(out['cmd'][k_end + 1:], plain_trace['tau'][k_end + 1:])


def test_a_notice_switches_the_law_at_the_next_tick():
    # The notice comes in between tick 2499 and 2500 (the failure at 2.5 s): the answer to
    # state 2500 already runs the law with joint 3 free; detection off (notices only).
    loop, logs = make(FULL, case='vertical', joint_failures='notice')
    out = run(loop, 'vertical', 2.52, fail=[(2, 2.5)], notices={2500: ['joint3']})
    (event,) = loop.failures.events
    assert event['by'] == 'notice' and abs(event['t'] - 2.5) < 1e-12
    assert out['cmd'][2499, 2] != 0.0 and np.all(out['cmd'][2500:, 2] == 0.0)
    assert 'detected by notice' in out['msg'][2500]
    assert out['err'].max() < 5.5e-3
    assert loop.failures.announcements() == []      # a notice is not announced again


def test_a_notice_for_an_unknown_or_undriven_joint_is_ignored_saying_why():
    loop, logs = make(FILE, joint_failures='notice')
    assert 'not a joint' in loop.on_failure_notice('elbow')
    assert 'not driven' in loop.on_failure_notice('joint3')     # the paper's free joint
    assert loop.on_failure_notice('joint2') == ''


def test_joints_2_and_3_failing_give_cannot_track_and_a_finite_least_harm_command():
    # r = 1 < m: the controller says it cannot track within 50 ms and damps / holds what is
    # left (joint 1: gravity compensation and a soft hold), never a non-finite command.
    loop, logs = make(FULL, case='vertical')
    out = run(loop, 'vertical', 2.7, fail=[(1, 2.5), (2, 2.5)])
    verdicts = [e for e in loop.failures.events if e['verdict'] == CANNOT_TRACK]
    assert verdicts and verdicts[0]['t'] - 2.5 <= 0.050
    k = int(round(verdicts[0]['t'] / DT))
    assert np.all(np.isfinite(out['cmd']))
    limits = np.array(FULL['effort_limits'])
    assert np.all(np.abs(out['cmd']) <= limits)
    assert np.all(out['cmd'][k:, 1:] == 0.0) and np.any(out['cmd'][k:, 0] != 0.0)
    assert 'cannot_track' in out['msg'][-1] and 'least-harm' in out['msg'][-1]
    assert any(level == 'error' and 'cannot_track' in text for level, _, text in logs)
    errors, warnings = [], []
    values = dict(loop.failures.diagnostics(errors, warnings))
    assert errors and 'cannot_track' in errors[0]
    assert values['failure verdict'] == CANNOT_TRACK


def test_joint2_free_vertical_is_refused_by_the_check_precomputed_at_start_up():
    # docs/failures.md: joint 2 free in the vertical plane passes det(Da Da^T) and diverges.
    cfg = SCHEMA.config(dict(FULL, case='vertical'))
    verdicts = precompute_verdicts(cfg.nominal, 'vertical', cfg.gains)
    assert set(verdicts) == {(0,), (1,), (2,)}
    assert verdicts[(1,)].verdict == CANNOT_TRACK and verdicts[(2,)].verdict == TRACKING
    monitor = FailureMonitor(cfg, make(FULL, case='vertical')[0].law, lambda *a: None)
    assert monitor.precomputed.keys() == verdicts.keys()


def test_detection_on_without_a_failure_commands_what_detection_off_commands():
    on, _ = make(FULL, case='vertical')
    off, _ = make(FULL, case='vertical', joint_failures='off')
    a = run(on, 'vertical', 1.0)
    b = run(off, 'vertical', 1.0)
    assert on.failures.events == []
    assert np.array_equal(a['cmd'], b['cmd'])


def test_joint2_failing_vertically_gives_cannot_track_within_50_ms_and_no_runaway():
    # Joint 2 free in the vertical plane passes det(Da Da^T) but its internal motion runs
    # away: the start-up check refuses it; the remaining joints get the least-harm command.
    loop, logs = make(FULL, case='vertical', failure_use_effort=False)
    out = run(loop, 'vertical', 3.0, fail=[(1, 2.5)])
    (event,) = loop.failures.events
    assert event['joint'] == 'joint2' and event['by'] == 'residual'
    assert event['verdict'] == CANNOT_TRACK and 'runs away' in event['reason']
    assert event['t'] - 2.5 <= 0.050
    k = int(round(event['t'] / DT))
    assert np.all(out['cmd'][k:, 1] == 0.0)
    assert np.all(np.isfinite(out['cmd'])) and np.all(np.isfinite(out['qd']))
    assert np.all(np.abs(out['cmd']) <= np.array(FULL['effort_limits']))
    assert np.max(np.abs(out['qd'][k:])) < 20.0       # the arm sags, it does not run away


def test_a_parameter_change_after_a_switch_keeps_the_failed_joint_out():
    loop, logs = make(FULL, case='vertical', joint_failures='notice')
    out = run(loop, 'vertical', 0.05, fail=[(2, 0.02)], notices={20: ['joint3']})
    assert loop.law.nominal.passive == (2,)
    old = loop.config
    values = dict(FULL, case='vertical', joint_failures='notice', R=[3.0, 3.0])
    loop.apply(old, SCHEMA.config(values))
    assert loop.law.gains.R == (3.0, 3.0)
    k = len(out['cmd'])
    ns = k * DT_NS
    sp = TRAJ.sample_tuple(k * DT)
    loop.on_state(ns, NAMES, out['q'][-1].tolist(), out['qd'][-1].tolist(), 0, 200.0)
    res = loop.on_setpoint(ns, sp, 0, 200.0)
    assert loop.law.nominal.passive == (2,) and res.effort[2] == 0.0
    assert all(math.isfinite(v) for v in res.effort)
    assert [e['joint'] for e in loop.failures.events] == ['joint3', 'joint3']


def test_real_time_effort_is_compared_with_the_recent_command_the_driver_applied():
    # A driver applies the newest command it has, answering a state up to its latency old:
    # the reference is the command sent within EFFORT_HISTORY_S nearest to the effort over
    # the driven joints; a joint reading 0 against it is a gap.
    cfg = SCHEMA.config(dict(FULL, lockstep=False))
    loop = ControlLoop(cfg)
    monitor = loop.failures
    assert monitor._effort_reference([1.0, 2.0, 3.0], [0.5, 2.0, 0.0]) == [1.0, 2.0, 3.0]
    # joints 1, 2 match the older command (the one applied); joint 3 reads 0: still a gap
    # of 3 N m against it
    assert monitor._effort_reference([1.2, 2.5, 3.2], [1.0, 2.0, 0.0]) == [1.0, 2.0, 3.0]
    # 12 ticks of latency (a loaded machine): the command of 12 ticks ago is found
    for k in range(12):
        monitor._effort_reference([10.0 + k, -5.0 - k, 1.0 + k], [0.0] * 3)
    assert monitor._effort_reference([30.0, -30.0, 30.0], [10.0, -5.0, 1.0]) == \
        [10.0, -5.0, 1.0]
    assert monitor._effort_reference([30.0, -30.0, 30.0], [13.0, -8.0, 0.0]) == \
        [13.0, -8.0, 4.0]
    # a small command of the failed joint does not choose: joints 1, 2 match the command
    # of the tick before exactly, joint 3 (commanded -0.058, then -0.021) reads 0
    monitor._effort_reference([0.097, -0.715, -0.058], [0.0] * 3)
    assert monitor._effort_reference([0.076, -0.700, -0.021], [0.097, -0.715, 0.0]) == \
        [0.097, -0.715, -0.058]
    # two driven joints (after a switch): the command matching both is the one applied
    monitor.rec.effort.set_watch([0, 1])
    monitor._effort_reference([5.0, 7.0, 0.0], [0.0] * 3)
    assert monitor._effort_reference([5.2, 6.0, 0.0], [5.0, 7.0, 0.0]) == [5.0, 7.0, 0.0]
    monitor.rec.effort.set_watch([0, 1, 2])
    # the history is EFFORT_HISTORY_S long: older commands are forgotten
    for _ in range(200):
        monitor._effort_reference([50.0, 50.0, 50.0], [0.0] * 3)
    assert monitor._effort_reference([50.0, 50.0, 50.0], [10.0, -5.0, 1.0]) == [50.0] * 3
    locked = make(FULL)[0].failures
    locked._effort_reference([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    assert locked._effort_reference([1.2, 2.5, 3.2], [1.0, 2.0, 0.0]) == [1.2, 2.5, 3.2]


def test_real_time_no_torque_on_every_joint_is_a_stopped_drive_and_one_joint_reading_0_a_failure():
    # Real time, efforts reported: the brakes (or the drive's watchdog) zero every joint's
    # effort while the controller commands: no failure, the effort judged again 20 ms after
    # torque is back; then joint 3 alone reading 0 is flagged by effort after the
    # detector's ticks.  The residual does not judge (the effort is the applied torque).
    from freejoint_control.failures import HOLDOFF_S
    from freejoint_core.failure import DEFAULT_EFFORT_TICKS
    loop, logs = make(FULL, case='vertical', lockstep=False)
    monitor = loop.failures
    q = initial_state(table1('vertical'), 120.0, TRAJ.sample(0.0)[0]).tolist()
    cmd = [40.0, 20.0, 5.0]
    k = 0

    def tick(effort):
        nonlocal k
        monitor.before_law(k * DT_NS, q, [0.0] * 3, cmd, effort)
        k += 1
    for _ in range(50):
        tick(list(cmd))
    for _ in range(300):                # braked for 0.3 s
        tick([0.0, 0.0, 0.0])
    assert monitor.events == [] and monitor.drive_stops == 1
    holdoff = round(HOLDOFF_S / DT)
    for _ in range(holdoff):            # joint 3 reads 0 at once: not judged yet
        tick([40.0, 20.0, 0.0])
    assert monitor.events == []
    for _ in range(DEFAULT_EFFORT_TICKS):
        tick([40.0, 20.0, 0.0])
    (event,) = monitor.events
    assert event['joint'] == 'joint3' and event['by'] == 'effort'
    assert event['t'] == pytest.approx((350 + holdoff + DEFAULT_EFFORT_TICKS - 1) * DT)
    assert monitor.announcements() == ['joint3']
    # A joint that reads torque other than any command sent (a stall longer than the
    # history) has not failed: no joint flagged.
    for _ in range(100):
        tick([25.0, 20.0, 0.0])
    assert len(monitor.events) == 1
