"""
A hot spare's takeover in one process: the control side of controller_supervisor.

Two loops (the active controller and a spare, ``standby: true``) take the same setpoints in
real time (the planner's circle 1 s after the start, seed 0); the core plant is stepped here,
1 ms per tick, as the simulator steps it. The active loop stops answering mid-circle (its
process killed); the simulator applies its last command until its drive watchdog
(``brake_timeout``, config/sim.yaml) engages the brakes (``Plant.stop`` held each step);
the spare is activated (the supervisor's SIGUSR1, then its next state) after a gap and must
track again within 2 s.  The process test (test/nodes/test_controller_supervisor.py) shows
what only processes show: death seen, activation, commands back; this one shows the arm
is caught, without the wall clock of a loaded machine deciding it.
"""
import math
import os

from freejoint_control.loop import ControlLoop
from freejoint_control.params import SCHEMA
from freejoint_core.arm import table1
from freejoint_core.plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant
from freejoint_core.trajectory import CircleQuintic
from freejoint_sim.params import SCHEMA as SIM
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONTROLLER = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'))
SIMULATOR = SIM.yaml_values(os.path.join(ROOT, 'config', 'sim.yaml'))
BRAKE_TICKS = int(round(SIMULATOR['brake_timeout'] * 1000))
DT = 0.001
DT_NS = 1_000_000
T0_NS = 10 ** 12        # stamps of a run that has been going for a while
NAMES = ['joint1', 'joint2', 'joint3']
TRAJ = CircleQuintic()
LEAD = 1.0              # the planner's start_delay: the start point held before the circle


def takeover(case, kill_at, gap, brakes=True, seed=0):
    """
    Run a takeover; return (tracking errors from 2 s after the kill to 2.5 s [m], efforts).

    ``kill_at``: time into the circle of the active loop's last answer [s]; ``gap``: from
    then to the spare's first state [s].  Efforts: every command sent, (ticks, 3) [N m].
    """
    values = dict(CONTROLLER, case=case, lockstep=False, readiness_guard=False)
    active = ControlLoop(SCHEMA.config(values))
    spare = ControlLoop(SCHEMA.config(dict(values, standby=True)))
    plant = Plant(table1(case), DEFAULT_DT_SUB, dist_bound=DEFAULT_DIST_BOUND, seed=seed,
                  q0=SIM.config(dict(SIMULATOR, case=case)).q0)
    p0 = TRAJ.sample(0.0)[0]
    rest = (float(p0[0]), float(p0[1]), 0.0, 0.0, 0.0, 0.0)
    kill = int(round((LEAD + kill_at) / DT))
    first = kill + int(round(gap / DT))
    errors, efforts, tau = [], [], [0.0, 0.0, 0.0]
    for k in range(kill + 2500):
        ns, mono = T0_NS + k * DT_NS, 100.0 + k * DT
        t = k * DT - LEAD
        sp = TRAJ.sample_tuple(t) if 0.0 <= t < TRAJ.duration else rest
        for loop in (active, spare):
            assert loop.on_setpoint(ns, sp, ns, mono) is None
        loop = active if k < kill else spare if k >= first else None
        if loop is not None:
            if k == first:
                spare.activate()
            res = loop.on_state(ns, NAMES, plant.q.tolist(), plant.qd.tolist(), ns, mono)
            tau = list(res.effort)
            efforts.append(tau)
            if k >= kill + 2000:
                errors.append(math.hypot(res.position[0] - res.position_desired[0],
                                         res.position[1] - res.position_desired[1]))
        if brakes and kill + BRAKE_TICKS <= k < first:
            plant.stop()        # braked: held where it is, no integration
        else:
            plant.step(np.array(tau), DT)
    return errors, np.array(efforts)


@pytest.mark.parametrize('case', ['vertical', 'horizontal'])
@pytest.mark.parametrize('gap', [0.03, 0.25, 1.0])
def test_a_spare_activated_after_a_kill_mid_circle_tracks_within_2_s(case, gap):
    # 0.03 s: a takeover as measured (docs/performance.md, "Real time under stress");
    # 0.25 s and 1 s: a slow one on a loaded machine, the brakes engaged meanwhile.
    errors, efforts = takeover(case, kill_at=1.0, gap=gap)
    assert errors and max(errors) < 0.005, max(errors)
    limits = CONTROLLER['effort_limits']
    assert np.isfinite(efforts).all()
    assert (np.abs(efforts) <= np.array(limits) + 1e-9).all()


def test_without_the_drive_watchdog_a_slow_takeover_loses_the_vertical_arm():
    # Why brake_timeout matters: the dead controller's last torque held for 0.5 s spins the
    # free link beyond what the spare can catch within the effort limits (held 0.35 s, the
    # real-time law still catches it: 2.0 mm 2 s later).
    errors, _ = takeover('vertical', kill_at=1.0, gap=0.5, brakes=False)
    assert max(errors) > 0.5
    caught, _ = takeover('vertical', kill_at=1.0, gap=0.5, brakes=True)
    assert max(caught) < 0.005
