"""
The free link's damping in the controller's loop, one process (r = m).

The loop (``free_link_damping: true``) is driven in lockstep by the core's plant stepped
here from the hanging start, vertical case, seed 0, over one circle and a rest; the
reference is the offline runner of circles back to back
(``freejoint_core.circles.run_circles`` with the stabilised options of the vertical case):
the same plant, the same modulation, so the same commands, element by element.
"""
import math
import os

from freejoint_control.loop import ControlLoop
from freejoint_control.params import SCHEMA
from freejoint_core.arm import ArmModel, table1
from freejoint_core.circles import MODULATION, run_circles, stabilised_options
from freejoint_core.control import Gains
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import hanging_pose
from freejoint_core.laws import FreeLinkDampedLaw, RobustLaw
from freejoint_core.plant import DEFAULT_DIST_BOUND, DEFAULT_DT_SUB, Plant
from freejoint_core.trajectory import CircleQuintic
from freejoint_sim.params import SCHEMA as SIM
from freejoint_tools.harness import load_source
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FILE = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'))
STAB = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'),
                          os.path.join(ROOT, 'config', 'stabilised', 'controller.yaml'))
SIM_STAB = (os.path.join(ROOT, 'config', 'sim.yaml'),
            os.path.join(ROOT, 'config', 'stabilised', 'sim.yaml'))
FOUR_SIM = (os.path.join(ROOT, 'config', 'sim.yaml'),
            os.path.join(ROOT, 'config', 'four_link', 'sim.yaml'))
FOUR = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'),
                          os.path.join(ROOT, 'config', 'four_link', 'controller.yaml'))
DT = 0.001
DT_NS = 1_000_000
NAMES = ['joint1', 'joint2', 'joint3']
TRAJ = CircleQuintic()
REST = 0.5


def sim_q0(files, **given):
    """Return the simulator's q(0) of parameter files with ``given`` on top."""
    values = SIM.yaml_values(*files)
    values.update(given)
    return SIM.config(values).q0


def make(base=FILE, **given):
    """Return the loop of a parameter file's values (config/controller.yaml) with ``given``."""
    values = dict(base)
    values.update(given)
    return ControlLoop(SCHEMA.config(values))


def drive(loop, case, seed, seconds, q0=None):
    """
    Drive ``loop`` in lockstep with the core plant from the hanging start.

    The setpoints are the circle, then its start point at rest.  Returns the commands
    (ticks, 3) and the law's state values (ticks, k).
    """
    real = table1(case)
    p0 = TRAJ.sample(0.0)[0]
    plant = Plant(real, DEFAULT_DT_SUB, dist_bound=DEFAULT_DIST_BOUND, seed=seed,
                  q0=hanging_pose(real, p0) if q0 is None else q0)
    rest = (float(p0[0]), float(p0[1]), 0.0, 0.0, 0.0, 0.0)
    cmds, states = [], []
    for k in range(int(round(seconds / DT))):
        t = k * DT
        ns = k * DT_NS
        assert loop.on_state(ns, NAMES, plant.q.tolist(), plant.qd.tolist(), 0,
                             100.0 + t) is None
        sp = TRAJ.sample_tuple(t) if t < TRAJ.duration - 0.5 * DT else rest
        res = loop.on_setpoint(ns, sp, 0, 100.0 + t)
        cmds.append(list(res.effort))
        states.append(list(res.law_state_values))
        plant.step(res.effort, DT)
    return np.array(cmds), np.array(states)


def test_the_damping_parameters_default_to_off_and_the_offline_bound():
    cfg = SCHEMA.config(dict(FILE))
    assert cfg.values['free_link_damping'] is False
    assert cfg.values['free_link_delta_max'] == MODULATION['delta_max'] == 0.01
    assert cfg.values['free_link_rest_damping'] == MODULATION['k2_rest'] == 1.0
    assert cfg.values['free_link_rest_after'] == MODULATION['rest_after'] == 1.5
    loop = make()
    assert isinstance(loop.law, RobustLaw)


def test_damping_on_wraps_the_law_and_reports_the_shift_in_its_state():
    loop = make(case='vertical', free_link_damping=True, free_link_delta_max=0.004)
    assert isinstance(loop.law, FreeLinkDampedLaw)
    assert loop.law.modulation.delta_max == 0.004
    assert loop.result.law_state_names[-2:] == ('free_link_delta[0]', 'free_link_delta[1]')
    assert loop.law.state_bounds[-1] == pytest.approx((-0.00404, 0.00404))


def test_damping_is_refused_for_an_arm_with_another_free_joint_or_none_without_failures():
    with pytest.raises(FreejointValueError, match='free_link_damping: needs the arm'):
        SCHEMA.config(dict(FOUR, free_link_damping=True))
    # Every joint driven: only with joint_failures (it waits for the last joint to fail).
    full = dict(FILE, passive_joints=[], joints=['joint1', 'joint2', 'joint3'],
                effort_limits=[300.0, 200.0, 200.0])
    with pytest.raises(FreejointValueError, match='free_link_damping: needs the arm whose '
                       r'last joint alone is free \(r = m = 2\), or with joint_failures a '
                       r'fully actuated arm of 3 joints; got passive joints \[\] of 3'):
        SCHEMA.config(dict(full, free_link_damping=True))
    SCHEMA.config(dict(full, free_link_damping=True, joint_failures='notice'))
    with pytest.raises(FreejointValueError, match='free_link_delta_max'):
        SCHEMA.config(dict(FILE, free_link_damping=True, free_link_delta_max=0.0))


@pytest.mark.parametrize('rest', [REST, 2.0])
def test_the_loop_with_damping_commands_what_the_offline_circles_run_does_bit_for_bit(rest):
    # Vertical, seed 0, hanging start, one circle and a rest (0.5 s; 2 s: past the settle
    # step's 1.5 s): the offline runner with the stabilised options and the loop's gains
    # (its torque limits, theta_max) on the same plant; every command equal, and the shift
    # equal to the offline one.
    opts = stabilised_options('vertical')
    assert opts == {'start': 'hanging', 'stabilise': MODULATION}
    gains = Gains(tau_limit=tuple(FILE['effort_limits']), theta_max=tuple(FILE['theta_max']))
    (rec,), trace = run_circles('vertical', 'robust', 0, circles=1, hold=rest, gains=gains,
                                record_trace=True, **opts)
    assert rec['diverged_at_s'] is None
    # the overlays config/stabilised/{controller,sim}.yaml: the loop's law and the sim's q(0)
    loop = make(STAB, case='vertical')
    q0 = sim_q0(SIM_STAB, case='vertical')
    cmds, states = drive(loop, 'vertical', 0, TRAJ.duration + rest, q0=q0)
    assert cmds.shape == trace['tau'].shape
    assert np.array_equal(cmds, trace['tau'])
    # the state after tick k is the shift the offline trace records at tick k
    assert np.array_equal(states[:, -2:], trace['delta'])
    assert np.max(np.hypot(states[:, -2], states[:, -1])) <= 0.01 * (1 + 1e-12)
    assert np.max(np.abs(states[:, -2:])) > 1e-3           # the damping did act


def test_a_restored_snapshot_repeats_the_step_modulation_included():
    # The loop restores the law's snapshot after a law fault: the wrapper's holds the shift.
    law = make(case='vertical', free_link_damping=True).law
    real = table1('vertical')
    q = hanging_pose(real, TRAJ.sample(0.0)[0])
    qd = np.array([0.1, -0.2, 3.0])
    sp = TRAJ.sample_tuple(0.3)
    law.step(q, qd, sp[0:2], sp[2:4], sp[4:6], DT)
    saved = law.save_state()
    first = law.step(q, qd, sp[0:2], sp[2:4], sp[4:6], DT).tau
    after = law.state_values()
    law.step(q, qd, sp[0:2], sp[2:4], sp[4:6], DT)
    law.restore_state(saved)
    assert np.array_equal(law.step(q, qd, sp[0:2], sp[2:4], sp[4:6], DT).tau, first)
    assert law.state_values() == after
    law.step(q, qd, sp[0:2], sp[2:4], sp[4:6], DT)
    before = law.state_values()
    law.restart_motion()                # the arm was braked: the shift, not theta_hat
    assert before[-2:] != [0.0, 0.0] and law.state_values() == before[:-2] + [0.0, 0.0]
    law.reset()
    assert law.state_values()[-2:] == [0.0, 0.0]


def test_the_simulator_starts_hanging_with_start_pose_hanging():
    # The overlay's start: the end effector at initial_position (0.2, 0) m, the free link's
    # absolute angle -90 deg (straight down), so gravity exerts no torque on joint 3.
    real = table1('vertical')
    q0 = np.array(sim_q0(SIM_STAB, case='vertical'))
    assert q0.tolist() == hanging_pose(real, (0.2, 0.0)).tolist()
    model = ArmModel(real)
    assert np.allclose(model.fk(q0), (0.2, 0.0), rtol=0.0, atol=1e-12)
    assert math.isclose(math.remainder(float(np.sum(q0)), 2.0 * math.pi), -0.5 * math.pi,
                        abs_tol=1e-12)
    assert abs(model.gravity_torque(q0)[2]) < 1e-12
    # paper: the default, q3 = 120 deg as before
    assert math.isclose(sim_q0(SIM_STAB[:1], case='vertical')[2], math.radians(120.0),
                        rel_tol=1e-12)


def test_start_pose_hanging_of_the_four_link_arm_is_its_free_base_at_rest():
    # Another arm: the equilibrium of its free base nearest initial_joint_positions.
    values = SIM.yaml_values(*FOUR_SIM)
    params = SIM.config(dict(values, case='vertical')).params
    guess = [float(v) for v in values['initial_joint_positions'].split()]
    q0 = np.array(sim_q0(FOUR_SIM, case='vertical', start_pose='hanging'))
    model = ArmModel(params)
    assert np.allclose(model.fk(q0), model.fk(guess), rtol=0.0, atol=1e-9)
    assert abs(model.gravity_torque(q0)[0]) < 1e-9


def test_start_pose_hanging_is_refused_without_gravity_or_a_reachable_point():
    with pytest.raises(FreejointValueError, match="start_pose: 'hanging' needs"):
        sim_q0(SIM_STAB, case='horizontal')
    with pytest.raises(FreejointValueError, match="start_pose: 'hanging' at initial_position"):
        sim_q0(SIM_STAB, case='vertical', initial_position=[2.0, 0.0])
    with pytest.raises(FreejointValueError, match='start_pose'):
        sim_q0(SIM_STAB, case='vertical', start_pose='upright')


STAB_H = SCHEMA.yaml_values(os.path.join(ROOT, 'config', 'controller.yaml'),
                            os.path.join(ROOT, 'config', 'stabilised_horizontal',
                                         'controller.yaml'))


def test_the_horizontal_overlay_is_the_offline_runners_settle_options():
    from freejoint_core.circles import HORIZONTAL_SETTLE
    cfg = SCHEMA.config(dict(STAB_H))
    assert cfg.values['free_link_damping'] is True
    assert {'mode': cfg.values['free_link_mode'], 'delta_max': cfg.values['free_link_delta_max'],
            'settle_window': cfg.values['free_link_settle_window']} == HORIZONTAL_SETTLE
    with pytest.raises(FreejointValueError, match='free_link_mode'):
        SCHEMA.config(dict(STAB_H, free_link_mode='sometimes'))


def test_the_loop_settling_the_horizontal_free_link_commands_what_the_offline_run_does():
    # Horizontal, seed 0, the paper's start, one circle and a 1-s rest: the offline circles
    # runner with the horizontal stabilised options (HORIZONTAL_SETTLE) and the loop with
    # config/stabilised_horizontal/controller.yaml: every command equal, the shift too.
    opts = stabilised_options('horizontal')
    gains = Gains(tau_limit=tuple(FILE['effort_limits']), theta_max=tuple(FILE['theta_max']))
    (rec,), trace = run_circles('horizontal', 'robust', 0, circles=1, hold=1.0, gains=gains,
                                record_trace=True, **opts)
    assert rec['diverged_at_s'] is None
    loop = make(STAB_H, case='horizontal')
    q0 = sim_q0((os.path.join(ROOT, 'config', 'sim.yaml'),), case='horizontal')
    cmds, states = drive(loop, 'horizontal', 0, TRAJ.duration + 1.0, q0=q0)
    assert np.array_equal(cmds, trace['tau'])
    assert np.array_equal(states[:, -2:], trace['delta'])
    n = int(round(TRAJ.duration / DT))
    shift = np.hypot(states[:, -2], states[:, -1])
    assert np.all(shift[:n] == 0.0)                    # tracking: the paper's law
    assert 5e-3 < shift[n:].max() <= 0.03 * (1 + 1e-12)   # the rest: centimetres
    assert shift[-1] < 1e-4                            # back before the next task


def _demo():
    """Return tools/demo.py as a module."""
    return load_source(os.path.join(ROOT, 'tools', 'demo.py'), 'freejoint_demo')


def test_demo_stabilise_starts_the_nodes_with_the_overlay_files_there_are():
    demo = _demo()
    stab = os.path.join(ROOT, 'config', 'stabilised')
    assert demo._overlay((demo.STABILISED,), 'controller') == [
        '--params-file', os.path.join(stab, 'controller.yaml')]
    assert demo._overlay((demo.STABILISED,), 'sim') == ['--params-file',
                                                        os.path.join(stab, 'sim.yaml')]
    assert demo._overlay((demo.STABILISED,), 'planner') == []       # the paper's circle
    assert demo._overlay((), 'sim') == []
    # --arm four_link --stabilise: the example's files, then its stabilised ones, in order
    four = os.path.join(ROOT, 'config', 'four_link')
    both = ('four_link', os.path.join('four_link', demo.STABILISED))
    assert demo._overlay(both, 'sim') == [
        '--params-file', os.path.join(four, 'sim.yaml'),
        '--params-file', os.path.join(four, 'stabilised', 'sim.yaml')]
    assert demo._overlay(both, 'planner') == ['--params-file',
                                              os.path.join(four, 'planner.yaml')]


def test_the_four_link_stabilised_overlay_is_the_offline_runner_s_stabilised_options():
    # config/four_link/stabilised/: the simulator starts where run_circles' 'equilibrium'
    # start does, the controller has its null-space damping and task gains.
    from freejoint_core.arm import ArmModel
    from freejoint_core.circles import arm_circle, FOUR_LINK_HANGING_GUESS
    from freejoint_core.circles import FOUR_LINK_TASK_GAINS, NULLSPACE_KD
    from freejoint_core.internal import equilibrium_pose
    from freejoint_core.urdf import four_link_arm
    four = os.path.join(ROOT, 'config', 'four_link')
    sim_files = (os.path.join(ROOT, 'config', 'sim.yaml'), os.path.join(four, 'sim.yaml'),
                 os.path.join(four, 'stabilised', 'sim.yaml'))
    model = ArmModel(four_link_arm('vertical').params)
    start = arm_circle('four_link').sample(0.0)[0]
    expected = equilibrium_pose(model, start, FOUR_LINK_HANGING_GUESS)
    q0 = sim_q0(sim_files, case='vertical')
    assert np.allclose(q0, expected, rtol=0, atol=1e-12)
    assert np.allclose(model.fk(q0), start, rtol=0, atol=1e-12)
    ctl = SCHEMA.config(SCHEMA.yaml_values(
        os.path.join(ROOT, 'config', 'controller.yaml'), os.path.join(four, 'controller.yaml'),
        os.path.join(four, 'stabilised', 'controller.yaml')))
    assert ctl.values['nullspace_kd'] == NULLSPACE_KD
    assert ctl.gains.K == (FOUR_LINK_TASK_GAINS['K'],) * 2
    assert ctl.gains.Lambda == (FOUR_LINK_TASK_GAINS['Lambda'],) * 2


def test_tracking_resumed_after_a_readiness_brake_starts_the_free_links_shift_from_zero():
    # Real time, vertical, damping on: the loop tracks the circle on the plant, a window of
    # late states trips the guard, the driver brakes the arm (frozen, at rest) until the
    # recovery windows pass. The shift from before the stop described a motion the brake
    # ended: kept, it put the reference up to free_link_delta_max (10 mm) off the braked
    # arm at the first resumed tick, and that tracking error tripped the guard again
    # (readiness_max_error 10 mm; seen in the back-to-back soak). Resumed, the shift starts
    # from 0 and the arm follows the blend from where it stopped; theta_hat is kept.
    window = 100
    loop = make(STAB, case='vertical', lockstep=False, max_state_age=0.0,
                stale_timeout=2.0, readiness_window=window * DT)
    plant = Plant(table1('vertical'), DEFAULT_DT_SUB, dist_bound=DEFAULT_DIST_BOUND, seed=0,
                  q0=sim_q0(SIM_STAB, case='vertical'))
    k = 0

    def tick(age_ns):
        """Answer state k (``age_ns`` old when taken); no answer: the arm braked."""
        nonlocal k
        ns = (k + 1) * DT_NS
        t = k * DT
        loop.on_setpoint(ns, TRAJ.sample_tuple(max(0.0, t - 0.5)), 0, 100.0 + t)
        res = loop.on_state(ns, NAMES, plant.q.tolist(), plant.qd.tolist(), ns + age_ns,
                            100.0 + t)
        k += 1
        if res is None:
            plant.qd[:] = 0.0               # the brakes hold every joint where it is
        else:
            plant.step(res.effort, DT)
        return res

    assert [tick(0) for _ in range(5 * window)] == [None] * (5 * window)   # not ready yet
    errors = [math.hypot(*tick(300_000).error) for _ in range(2000)]      # the circle
    assert max(errors) < 5e-3
    shift = loop.law.state_values()[-2:]
    assert math.hypot(*shift) > 5e-4        # the damping acts: a shift to forget
    while loop._readiness.ready:            # a window of states 3 ms old (> 2 ms)
        tick(3_000_000)
    theta = loop.law.state_values()[:5]
    braked = 0
    while tick(0) is None:                  # braked through the recovery windows
        braked += 1
    assert loop._readiness.ready and window * 4 < braked < window * 6
    first = loop.result
    assert math.hypot(*first.error) < 1e-5, first.error     # kept: 0.19 mm here
    # theta_hat kept: one step's adaptation from where the stop left it, not theta0's 0
    # (3.1e-4 here, six times the tolerance)
    assert max(theta) > 2.5e-4 and np.allclose(loop.law.state_values()[:5], theta, rtol=0.0,
                                               atol=5e-5)
    errors = [math.hypot(*tick(300_000).error) for _ in range(1000)]
    assert loop._readiness.trips == 1 and max(errors) < 5e-3, max(errors)


def test_real_time_the_horizontal_settle_leaves_the_held_start_alone_despite_the_resume_blend():
    # Real time, the rotor turning 1 rad/s under an end effector held 0.3 mm off the start
    # point: the loop's start blend moves the reference there (a fraction of a millimetre,
    # no task), so the settle must not drive; before SETTLE_AFTER_TRAVEL it did (the
    # soak's first circles 1.2-1.8 mm off their path). After a task's 2 cm, a rest is settled.
    horizontal = SCHEMA.yaml_values(
        os.path.join(ROOT, 'config', 'controller.yaml'),
        os.path.join(ROOT, 'config', 'stabilised_horizontal', 'controller.yaml'))
    loop = make(horizontal, case='horizontal', lockstep=False, readiness_guard=False,
                max_state_age=0.0)
    q = [-1.369438, 1.691679, 2.094395 + 0.0006]      # the start, joint 3 turned 0.3 mm
    held = ArmModel(table1('horizontal')).fk(q)
    assert 2e-4 < math.hypot(held[0] - 0.2, held[1]) < 4e-4
    start = (0.2, 0.0, 0.0, 0.0, 0.0, 0.0)
    for k in range(1500):
        ns = k * DT_NS
        loop.on_setpoint(ns, start, 0, k * DT)
        res = loop.on_state(ns, NAMES, q, [0.0, 0.0, 1.0], ns, 100.0 + k * DT)
        assert res.law_state_values[-2:] == [0.0, 0.0], k
    for k in range(1500, 1600):     # a task: 2 cm along x in 0.1 s, then a rest
        ns = k * DT_NS
        loop.on_setpoint(ns, (0.2 + 2e-4 * (k - 1499), 0.0, 0.2, 0.0, 0.0, 0.0), 0, k * DT)
        loop.on_state(ns, NAMES, q, [0.0, 0.0, 1.0], ns, 100.0 + k * DT)
    for k in range(1600, 1650):
        ns = k * DT_NS
        loop.on_setpoint(ns, (0.22, 0.0, 0.0, 0.0, 0.0, 0.0), 0, k * DT)
        res = loop.on_state(ns, NAMES, q, [0.0, 0.0, 1.0], ns, 100.0 + k * DT)
    assert np.linalg.norm(res.law_state_values[-2:]) > 0.0
