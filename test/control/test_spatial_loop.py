"""The controller's loop runs a spatial arm: lockstep ticks equal the offline twin."""
import math
import os

from freejoint_control.loop import config_law, ControlLoop
from freejoint_control.params import SCHEMA
from freejoint_core.arm_gains import (delay_capped_damping, delay_step_bound, joint_inertia,
                                      mode_steps)
from freejoint_core.control import STATUS_TORQUE_LIMITED
from freejoint_core.spatial_law import SpatialControlLaw, SpatialGains
from freejoint_core.spatial_offline import CASES, circle, run_twin, start_posture
from freejoint_core.spatial_plant import SpatialPlant
from freejoint_sim.params import SCHEMA as SIM_SCHEMA
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DT_NS = 1_000_000
TICKS = 300


def _values(arm, **given):
    values = dict(SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml')))
    values.update(SCHEMA.yaml_values(os.path.join(ROOT, 'config', arm, 'controller.yaml')))
    values.update(given)
    return values


@pytest.mark.parametrize('arm, case', [('ur5', 'ur5_wrist2'), ('panda', 'panda_j7')])
def test_the_shipped_spatial_config_gives_the_offline_runners_law(arm, case):
    cfg = SCHEMA.config(_values(arm))
    law = config_law(cfg)
    assert isinstance(law, SpatialControlLaw) and cfg.gains.task_dim == 3
    assert law.law.nullspace.kd == 20.0
    assert law.law.nullspace.inverse == 'weighted'
    # the offline runner's (spatial_offline.run_case): SpatialGains(task_dim=3), kd 20
    offline = SpatialControlLaw(cfg.nominal, SpatialGains(task_dim=3))
    offline.set_nullspace_gains(20.0, 10.0)
    q = np.array(CASES[case][2]) + 0.05
    qd = np.linspace(-0.3, 0.3, cfg.nominal.n)
    p_d = cfg.nominal.fk(q) + 0.01
    a = law.step(q, qd, p_d, [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], 1e-3)
    b = offline.step(q, qd, p_d, [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], 1e-3)
    assert a.tau.tolist() == b.tau.tolist()
    assert law.state_values() == offline.state_values()


def test_lockstep_ticks_of_the_loop_on_a_ur5_equal_the_offline_twin_exactly():
    cfg = SCHEMA.config(_values('ur5'))
    arm = cfg.nominal
    real = arm.nominal(1.0)
    q0, why = start_posture(arm, CASES['ur5_wrist2'][2])
    assert q0 is not None, why
    twin = run_twin(real, q0, config_law(cfg), 3, t_stop=TICKS * 1e-3)
    loop = ControlLoop(cfg, lambda *line: None)
    plant = SpatialPlant(real, 5e-4, 0.5, 3, q0)
    p0 = real.fk(q0)
    names = list(reversed(cfg.joint_names))        # any order: the loop maps by name
    for k in range(TICKS):
        ns = k * DT_NS
        q, qd = plant.q.tolist(), plant.qd.tolist()
        assert loop.on_state(ns, names, q[::-1], qd[::-1], ns, 0.0) is None   # waits
        p, v, a = circle(p0, 0.1, k * 1e-3, 5.0)
        res = loop.on_setpoint(ns, p.tolist() + v.tolist() + a.tolist(), ns, 0.0)
        assert res is not None and res.status == 0, (k, res and res.message)
        assert res.effort == [float(t) for t in twin['trace']['tau'][k][list(
            cfg.cmd_index)]]
        assert list(res.position) == twin['trace']['p'][k].tolist()
        effort = [0.0] * cfg.nominal.r
        for name, value in zip(cfg.joints, res.effort):
            effort[cfg.nominal.active.index(cfg.joint_names.index(name))] = value
        plant.step(effort, 1e-3)
    assert len(res.law_state_values) == len(res.law_state_names) == 7
    assert res.law_state_names[-1] == 'kappa' and 0.0 < res.law_state_values[-1] <= 1.0
    assert 1e3 * max(np.linalg.norm(twin['trace']['p'] - twin['trace']['p_d'], axis=1)) < 3.0


def test_a_spatial_arm_refuses_the_planar_law_and_planar_only_options():
    assert SCHEMA.reason(_values('ur5', law='robust')).startswith(
        "law: a spatial arm (task_dim 3) runs law 'spatial'")
    assert SCHEMA.reason(_values('ur5', joint_failures='detect')).startswith(
        'joint_failures: planar arms only for now')
    assert SCHEMA.reason(_values('ur5', K=[100.0, 100.0])) == (
        "K: expected 3 values (the task dimension of the arm's model), got [100.0, 100.0]")
    planar = dict(SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml')))
    assert SCHEMA.reason(dict(planar, law='spatial')).startswith(
        "law: a spatial arm (task_dim 3) runs law 'spatial', a planar one another law")


def test_the_posture_is_where_the_task_began_and_is_taken_again_after_a_reset():
    cfg = SCHEMA.config(_values('ur5'))
    law = config_law(cfg)
    act = list(cfg.nominal.active)
    q0 = np.array(CASES['ur5_wrist2'][2])
    q1 = q0 + 0.02
    assert law.posture is None                          # nullspace_kp 10: taken at a step
    p_d = cfg.nominal.fk(q0)
    law.step(q0, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    assert law.posture == tuple(q0[act].tolist())
    assert law.law.nullspace.kp == 10.0 and law.law.nullspace.posture == law.posture
    law.step(q1, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    assert law.posture == tuple(q0[act].tolist())       # kept while the task runs
    saved = law.save_state()
    law.step(q1, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    law.restore_state(saved)
    assert law.save_state() == saved and law.state_values()[5:] == [0.0, 0.0]
    law.reset()
    assert law.posture is None and law.law.nullspace.kp == 0.0
    out = law.step(q1, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    assert law.posture == tuple(q1[act].tolist())
    # at its own posture and at rest the posture term is 0: the tick of a law without it
    free = config_law(SCHEMA.config(_values('ur5', nullspace_kp=0.0)))
    ref = free.step(q1, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    assert free.posture is None and out.tau.tolist() == ref.tau.tolist()


def test_a_planar_arm_takes_no_posture_stiffness():
    planar = dict(SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml')))
    assert SCHEMA.reason(dict(planar, nullspace_kp=1.0)).startswith(
        "nullspace_kp: the posture term is the spatial law's (task_dim 3)")


def test_effort_limits_below_the_urdfs_clip_the_spatial_laws_torque():
    # the UR5's shoulder at 10 N m (URDF: 150): a 2-cm step of the setpoint asks more
    cfg = SCHEMA.config(_values('ur5', effort_limits=[150.0, 10.0, 150.0, 28.0, 28.0]))
    law = config_law(cfg)
    q0 = np.array(CASES['ur5_wrist2'][2])
    out = law.step(q0, np.zeros(6), cfg.nominal.fk(q0) + 0.02, [0.0] * 3, [0.0] * 3, 1e-3)
    assert abs(out.tau[1]) == 10.0 and out.status & STATUS_TORQUE_LIMITED
    urdf = config_law(SCHEMA.config(_values('ur5')))
    ref = urdf.step(q0, np.zeros(6), cfg.nominal.fk(q0) + 0.02, [0.0] * 3, [0.0] * 3, 1e-3)
    assert abs(ref.tau[1]) > 10.0


def _sim_config():
    """Return the UR5 simulator's configuration (config/sim.yaml, config/ur5/sim.yaml)."""
    return SIM_SCHEMA.config(SIM_SCHEMA.yaml_values(
        os.path.join(ROOT, 'config', 'sim.yaml'), os.path.join(ROOT, 'config', 'ur5', 'sim.yaml')))


def _realtime_ur5(late_ns, ticks):
    """
    Run the UR5's real-time loop from rest on its twin arm; return the joint speeds (ticks, n).

    The controller answers each state ``late_ns`` after its stamp (no readiness guard: it
    answers from the first state), the planner holds the start point, and each command acts
    from the first simulator step after it arrives (before it: the start-up brakes).
    """
    sim = _sim_config()
    cfg = SCHEMA.config(_values('ur5', lockstep=False, readiness_guard=False))
    real = sim.arm.spatial
    plant = SpatialPlant(real, sim.dt_sub, sim.dist_bound, 0, sim.q0)
    loop = ControlLoop(cfg, lambda *line: None)
    hold = real.fk(np.array(sim.q0)).tolist() + [0.0] * 6
    sent = []                   # (arrival [ns], effort in the model's active order)
    effort = None
    speeds = []
    for k in range(ticks):
        ns = k * DT_NS
        while sent and sent[0][0] <= ns:
            effort = sent.pop(0)[1]
        if effort is not None:
            plant.step(effort, 1e-3)
            speeds.append(np.abs(plant.qd))
        loop.on_setpoint(ns + DT_NS, hold, ns, 0.0)
        res = loop.on_state(ns + DT_NS, list(cfg.joint_names), plant.q.tolist(),
                            plant.qd.tolist(), ns + DT_NS + late_ns, 0.0)
        if res is not None:
            cmd = [0.0] * real.r
            for name, value in zip(cfg.joints, res.effort):
                cmd[real.active.index(cfg.joint_names.index(name))] = value
            sent.append((ns + DT_NS + late_ns, cmd))
    return np.array(speeds), real


@pytest.mark.parametrize('late_ms', [0.5, 1.5, 2.5])
def test_a_real_time_ur5_keeps_its_light_wrist_within_its_speed_limit_at_the_loops_delay(
        late_ms):
    # The null-space damping of the lockstep config (20 N m s/rad: 1.2 of wrist_3's rate per
    # period) reverses and grows once a command acts a period late: wrist_3 passed its
    # 3.2 rad/s within 40 ms of the first command, and the state reader refused it.
    speeds, real = _realtime_ur5(round(late_ms * 1e6), 200)
    assert np.all(speeds < real.velocity), speeds.max(axis=0) / real.velocity
    wrist_3 = real.joint_names.index('wrist_3_joint')
    assert speeds[-50:, wrist_3].max() < 0.1 * real.velocity[wrist_3]


def test_the_real_time_null_space_damping_is_capped_by_the_delay_and_lockstep_is_not():
    q0 = np.array(_sim_config().q0)
    lockstep = config_law(SCHEMA.config(_values('ur5')))
    realtime = config_law(SCHEMA.config(_values('ur5', lockstep=False)))
    p_d = lockstep.model.fk(q0)
    for law in (lockstep, realtime):
        law.step(q0, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    assert lockstep.nullspace_kd == 20.0
    kd = realtime.nullspace_kd
    # the guard's trip delay (not measured for the UR5: the strictest, 1.5 ms) is 2 periods:
    # wrist_3 (0.012 kg m^2 on the 70 % model) at half of 2 sin(pi / 10) = 0.618 per period
    inertia = joint_inertia(realtime.model, q0)
    assert kd[:4] == pytest.approx((20.0,) * 4, rel=1e-9)
    assert kd[4] == pytest.approx(0.5 * 2 * math.sin(math.pi / 10) * inertia[4] / 1e-3,
                                  rel=1e-9)
    assert mode_steps(realtime.model, q0, kd, 1e-3)[0][0] <= 0.309017 + 1e-6
    assert delay_step_bound(0) == 2.0 and delay_step_bound(1) == pytest.approx(1.0)


def test_a_longer_trip_delay_given_live_caps_the_damping_anew_and_keeps_the_posture():
    q0 = np.array(_sim_config().q0)
    old = SCHEMA.config(_values('ur5', lockstep=False, readiness_guard=False))
    loop = ControlLoop(old, lambda *line: None)
    law = loop.law
    p_d = law.model.fk(q0)
    law.step(q0, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    posture, one = law.posture, law.nullspace_kd        # no guard: one period
    new = SCHEMA.config(_values('ur5', lockstep=False, readiness_guard=True,
                                readiness_max_delay=0.005))
    loop.apply(old, new)
    law.step(q0 + 0.01, np.zeros(6), p_d, [0.0] * 3, [0.0] * 3, 1e-3)
    assert law.posture == posture
    five = delay_capped_damping(law.model, q0 + 0.01, 20.0, 5, 1e-3)
    assert law.nullspace_kd == five and five[4] < one[4] / 2
