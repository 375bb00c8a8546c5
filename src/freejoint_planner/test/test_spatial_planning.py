"""
Spatial plans without ROS: the offline runner's circle, streamed; the plan checks.

The arms are those of the planner's overlays (config/ur5/planner.yaml and
config/panda/planner.yaml on config/planner.yaml, resolved as the node resolves them); the
start postures the offline runner's (``gravity_carrying_free_joint`` from its planned
postures, as config/*/sim.yaml), computed here on ``known_arm``.
"""
import math
import os

from freejoint_common.arm_description import resolve_arm
from freejoint_core.spatial_law import arm_reach, gravity_carrying_free_joint, SpatialGains
from freejoint_core.spatial_law import SpatialControlLaw, task_conditioning
from freejoint_core.spatial_model import known_arm
from freejoint_core.spatial_offline import CASES, circle, run_twin
from freejoint_planner.params import SCHEMA
from freejoint_planner.spatial_planning import check_spatial_plan, first_joint_origin
from freejoint_planner.spatial_planning import nominal_loop, spatial_bounds, SpatialCircle
from freejoint_planner.spatial_planning import SpatialRequest, start_point
from freejoint_planner.stream import Plan, SetpointStream, SpatialSetpoint
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))))
CONFIG = os.path.join(ROOT, 'config')
MS = 1_000_000
DT = 0.001
BOUNDS = (1.0, 5.0)         # the planner's default max_speed, max_acceleration
ARMS = {'ur5': 'ur5_wrist2', 'panda': 'panda_j7'}


def _values(arm, **changes):
    """Return the planner's values of config/planner.yaml with the arm's overlay."""
    values = SCHEMA.yaml_values(os.path.join(CONFIG, 'planner.yaml'),
                                os.path.join(CONFIG, arm, 'planner.yaml'))
    values.update(changes)
    return values


@pytest.fixture(scope='module')
def arms():
    """``{arm: (NodeArm of the overlay, its nominal model, start posture)}``."""
    out = {}
    for arm, case in ARMS.items():
        values = _values(arm)
        node_arm = resolve_arm(values)
        name, free, q_plan = CASES[case]
        q0, why = gravity_carrying_free_joint(known_arm(name, [free]).nominal(0.7),
                                              np.array(q_plan))
        assert q0 is not None, why
        out[arm] = (node_arm, node_arm.nominal(values['nominal_scale']), q0)
    return out


def _advance(stream, until_ns, step_ns=7 * MS):
    return [sp for t in range(0, until_ns, step_ns) for sp in stream.advance(t)]


def test_the_overlays_are_spatial_arms_with_the_simulators_chains(arms):
    ur5, nominal, _ = arms['ur5']
    assert ur5.task_dim == 3 and ur5.spatial is not None
    assert ur5.joint_names[4] == 'wrist_2_joint' and ur5.spatial.passive == (4,)
    assert nominal.scale == 0.7
    panda = arms['panda'][0]
    assert panda.spatial.passive == (6,) and panda.spatial.tip_link == 'panda_hand_tcp'
    assert _values('panda')['frame_id'] == 'panda_link0'
    values = _values('ur5')
    assert (values['radius'], values['duration'], values['autostart']) == (0.1, 5.0, True)


def test_the_streamed_spatial_setpoints_are_the_offline_runners_circle_exactly(arms):
    # Tick k of a plan started at tick 0 carries circle(p0, 0.1, k dt, 5) of
    # freejoint_core.spatial_offline, bit for bit, in the 3 values of each vector.
    node_arm, _, q0 = arms['ur5']
    p0 = node_arm.spatial.fk(q0)
    stream = SetpointStream(DT, 20)
    stream.start(Plan(1, SpatialCircle(p0, 0.1, 5.0)))
    out = _advance(stream, 7100 * MS)
    assert [sp.stamp_ns for sp in out] == [k * MS for k in range(len(out))]
    assert all(type(sp) is SpatialSetpoint for sp in out)
    for k in (0, 1, 2, 3, 999, 1234, 2500, 4999, 5000, 5001, 7000):
        pos, vel, acc = circle(p0, 0.1, k * DT, 5.0)
        sp = out[k]
        assert (sp.position, sp.velocity, sp.acceleration) == (
            tuple(pos.tolist()), tuple(vel.tolist()), tuple(acc.tolist())), k
        assert (sp.plan_id, sp.plan_time, sp.final) == (1, (k * MS) * 1e-9, k * DT > 5.0)
    # the start point is the tip, at rest; the end holds the point the circle ends on
    assert out[0].velocity == (0.0, 0.0, 0.0) and out[0].acceleration == (0.0, 0.0, 0.0)
    assert np.allclose(out[0].position, p0, rtol=0, atol=1e-15)
    assert out[5001].position == out[7000].position
    assert np.allclose(out[7000].position, p0, rtol=0, atol=1e-15)


def test_the_first_setpoints_equal_the_offline_twins_desired_path(arms):
    # Independent of this module: spatial_offline.run_twin (the lockstep graph's offline
    # runner) records the setpoint it feeds the law at each tick.
    node_arm, nominal, q0 = arms['ur5']
    law = SpatialControlLaw(node_arm.nominal(0.7), SpatialGains(task_dim=3))
    law.set_nullspace_gains(20.0, 10.0)
    twin = run_twin(node_arm.spatial, q0, law, 0, t_stop=0.03)['trace']['p_d']
    stream = SetpointStream(DT, 20)
    stream.start(Plan(1, SpatialCircle(node_arm.spatial.fk(q0), 0.1, 5.0)))
    out = _advance(stream, 30 * MS)
    assert len(twin) == 30
    assert [list(sp.position) for sp in out[:30]] == twin.tolist()


def test_before_a_start_delay_the_start_point_is_held_at_rest():
    path = SpatialCircle((0.5, 0.1, 0.3), 0.1, 5.0)
    stream = SetpointStream(DT, 20)
    stream.start(Plan(3, path, start_delay_ns=100 * MS))
    out = _advance(stream, 300 * MS)
    first = out[0]
    assert first.plan_time == -0.1 and not first.final
    assert path.sample_tuple(-0.1) == path.sample_tuple(0.0)
    assert first.position + first.velocity + first.acceleration == path.sample_tuple(0.0)
    assert out[100].plan_time == 0.0
    assert out[150].position == tuple(circle(path.p0, 0.1, 0.05, 5.0)[0].tolist())


def test_a_spatial_circle_refuses_bad_values_naming_them():
    with pytest.raises(ValueError, match=r'p0: the start point \[0.0, 0.0, 0.5\] m is on the '
                       "base's vertical axis"):
        SpatialCircle((0.0, 0.0, 0.5), 0.1, 5.0)
    with pytest.raises(ValueError, match='p0: expected 3 finite numbers'):
        SpatialCircle((0.5, 0.1), 0.1, 5.0)
    with pytest.raises(ValueError, match='radius: expected a finite number > 0'):
        SpatialCircle((0.5, 0.1, 0.3), 0.0, 5.0)
    with pytest.raises(ValueError, match='duration: expected a finite number > 0'):
        SpatialCircle((0.5, 0.1, 0.3), 0.1, math.inf)


@pytest.mark.parametrize('arm, free, case', [
    ('ur5', 'elbow_joint', 'ur5_wrist2'), ('panda', 'panda_joint4', 'panda_j7')])
def test_a_free_joint_that_must_carry_gravity_is_refused_in_one_line_naming_it(
        arm, free, case):
    nominal = known_arm(arm, [free]).nominal(0.7)
    q = np.array(CASES[case][2])
    verdict = check_spatial_plan(nominal, q, np.zeros(nominal.n), 0.1, 5.0, *BOUNDS)
    assert verdict.reason.startswith(f'free joint {free} must carry gravity: no rest posture '
                                     'within the joint limits holds the tip at ')
    assert '\n' not in verdict.reason and verdict.loop is None
    # at that posture the joint carries gravity indeed (docs/spatial.md: 14.6 / 22.9 N m)
    assert abs(nominal.gravity_torque(q)[nominal.passive[0]]) > 5.0


@pytest.mark.parametrize('arm', ['ur5', 'panda'])
def test_the_example_arms_circles_are_accepted_from_their_start_postures(arms, arm):
    node_arm, nominal, q0 = arms[arm]
    verdict = check_spatial_plan(nominal, q0, np.zeros(nominal.n), 0.1, 5.0, *BOUNDS,
                                 p0=node_arm.spatial.fk(q0))
    assert verdict.reason == ''
    loop = verdict.loop
    assert loop.reason == '' and loop.steps == 3001          # 6 s at 2 ms, and t = 0
    assert loop.kappa_min > 0.2 and loop.max_error < 3e-3
    assert np.array_equal(verdict.rest, q0)                  # at rest where it starts
    assert verdict.circle.p0.tolist() == node_arm.spatial.fk(q0).tolist()
    assert 0.5 < verdict.margin < 0.6                        # reach margin [m]
    # the free joint's range is reported, not refused: the Panda's joint 7 turns past its
    # URDF limits (+-2.8973 rad) in the nominal loop
    assert loop.free_outside == (() if arm == 'ur5' else ('panda_joint7',))
    active = list(nominal.active)
    assert np.all(np.array(loop.q_min)[active] >= nominal.lower[active])
    assert np.all(np.array(loop.q_max)[active] <= nominal.upper[active])
    assert 'nominal closed loop: 3001 steps of 2 ms' in verdict.describe()


def test_a_path_from_a_singular_posture_is_refused_at_its_start():
    # UR5 elbow straight (q3 = 0) with wrist_1 at -pi/2 and wrist_2 at 0: upper arm,
    # forearm and wrist in one line, so the three parallel joints 2-4 move the tip along
    # one direction only and the position Jacobian of the active joints has rank 2
    nominal = known_arm('ur5', ['wrist_2_joint']).nominal(0.7)
    q = np.array([0.0, -1.2, 0.0, -math.pi / 2, 0.0, 0.0])
    sv = np.linalg.svd(nominal.jacobian(q)[:, list(nominal.active)], compute_uv=False)
    assert sv[2] < 1e-9 * sv[0]
    da, _, maa = nominal.decoupling(nominal.terms(q, np.zeros(6)))
    assert task_conditioning(da, maa, arm_reach(nominal))[0] < 1e-6
    verdict = check_spatial_plan(nominal, q, np.zeros(6), 0.1, 5.0, *BOUNDS)
    assert verdict.reason.startswith('the nominal closed loop passes a singular posture: '
                                     'kappa ')
    assert '< kappa_min 0.001 at t = 0.000 s' in verdict.reason


def test_a_path_through_a_singular_posture_is_refused_where_it_passes():
    # From q3 = -0.1 (elbow nearly straight) the circle leads the loop without the posture
    # term (kp 0) through the stretched posture of the previous test: kappa falls below
    # 1e-3 after 0.3 s. The shipped law's posture term (kp 10) holds the elbow bent: the
    # tip then cannot follow, and the plan is refused for that (before the singularity)
    nominal = known_arm('ur5', ['wrist_2_joint']).nominal(0.7)
    q = np.array([0.0, -2.0, -0.1, -math.pi / 2, 0.0, 0.0])
    loop = nominal_loop(nominal, q, np.zeros(6), SpatialCircle(nominal.fk(q), 0.1, 5.0),
                        kp=0.0)
    assert loop.reason.startswith('the nominal closed loop passes a singular posture')
    assert loop.kappa_min < 1e-3 and loop.t_kappa_min > 0.1
    verdict = check_spatial_plan(nominal, q, np.zeros(6), 0.1, 5.0, *BOUNDS)
    assert verdict.reason.startswith('the nominal closed loop cannot follow the path')


def test_a_circle_beyond_the_reach_is_refused_before_the_loop(arms):
    # radius 0.6 m from the UR5's start point: its far side is 1.37 m from the shoulder pan
    # axis' origin, beyond L = 1.2396 m, the sum of the joint-to-joint distances to the tip
    node_arm, nominal, q0 = arms['ur5']
    p0 = node_arm.spatial.fk(q0)
    origin = first_joint_origin(nominal)
    far = max(np.linalg.norm(circle(p0, 0.6, t, 20.0)[0] - origin)
              for t in np.linspace(0.0, 20.0, 4001))
    assert far > arm_reach(nominal) == pytest.approx(1.2396, abs=1e-4)
    verdict = check_spatial_plan(nominal, q0, np.zeros(6), 0.6, 20.0, *BOUNDS, p0=p0)
    assert verdict.reason.startswith('radius: the circle leaves the reach of the arm: its '
                                     'point ')
    assert 'from the first joint shoulder_pan_joint' in verdict.reason
    assert verdict.loop is None and verdict.margin < 0.0
    # 0.5 m stays inside the bound (the loop decides then)
    assert check_spatial_plan(nominal, q0, np.zeros(6), 0.5, 20.0, *BOUNDS,
                              p0=p0).margin > 0.0


def test_a_circle_the_stretched_arm_cannot_follow_is_refused_by_the_loop():
    # Elbow nearly straight, pointing up: the circle rises above what the arm reaches
    nominal = known_arm('ur5', ['wrist_2_joint']).nominal(0.7)
    q = np.array([0.0, -1.2, 0.1, -math.pi / 2, 0.0, 0.0])
    verdict = check_spatial_plan(nominal, q, np.zeros(6), 0.1, 5.0, *BOUNDS)
    assert verdict.reason.startswith('the nominal closed loop cannot follow the path: tip '
                                     'error ')
    assert '(> 10 mm;' in verdict.reason and verdict.margin > 0.0


def test_a_path_that_takes_an_active_joint_past_its_urdf_limit_is_refused_naming_it():
    # The Panda's elbow (joint 4, upper limit -0.0698 rad) at -0.47 rad: without the
    # posture term (kp 0) the circle straightens it (to +0.43 rad with the limits lifted);
    # the shipped law's posture term (kp 10) keeps it bent and the tip falls behind instead
    nominal = known_arm('panda', ['panda_joint7']).nominal(0.7)
    q, why = gravity_carrying_free_joint(nominal, np.array([0.0, 0.3, 0.0, -0.12, 0.0, 0.5,
                                                            0.785]))
    assert q is not None, why
    loop = nominal_loop(nominal, q, np.zeros(7), SpatialCircle(nominal.fk(q), 0.1, 5.0),
                        kp=0.0)
    assert loop.reason.startswith('the nominal closed loop takes the active joint '
                                  'panda_joint4 to ')
    assert 'outside its URDF limits [-3.0718, -0.0698] rad' in loop.reason
    verdict = check_spatial_plan(nominal, q, np.zeros(7), 0.1, 5.0, *BOUNDS)
    assert verdict.reason.startswith('the nominal closed loop cannot follow the path')


def test_the_speed_and_acceleration_bounds_are_the_planar_circles_naming_duration():
    # peak speed 1.875 * 2 pi r / T: r = 0.1 m in 0.5 s peaks at 2.356 m/s
    reason = spatial_bounds(0.1, 0.5, 1.0, 100.0)
    assert reason.startswith('duration: 0.5 s for radius 0.1 m peaks at 2.35619 m/s, above '
                             'max_speed 1 m/s (duration >= 1.1781 s)')
    assert spatial_bounds(0.1, 5.0, *BOUNDS) == ''
    assert spatial_bounds(0.1, 5.0, 1.0, 0.1).startswith('duration: 5 s for radius 0.1 m '
                                                         'peaks at ')
    verdict = check_spatial_plan(None, None, None, 0.1, 0.5, *BOUNDS)
    assert verdict.reason.startswith('duration: ') and verdict.circle is None


def test_a_new_spatial_plan_starts_where_the_running_one_rests_and_never_mid_circle():
    path = SpatialCircle((0.5, 0.1, 0.3), 0.1, 1.0)
    stream = SetpointStream(DT, 20)
    assert start_point(stream) == (None, '')              # nothing streamed: the arm's tip
    stream.start(Plan(1, path))
    assert start_point(stream) == (None, '')
    stream.advance(0)                                      # ticks 0..20 out
    p0, reason = start_point(stream)
    assert p0 is None
    assert reason == ('the running plan 1 moves until t = 1.000 s (ROS time): a spatial plan '
                      'starts from rest (no 3-D transition); ask again once it holds its end '
                      'point')
    stream.advance(990 * MS)                               # ticks up to 1010 out
    p0, reason = start_point(stream)
    assert reason == '' and p0.tolist() == circle(path.p0, 0.1, 1.011, 1.0)[0].tolist()
    # a request waiting for the arm starts from the arm's tip
    stream.start(Plan(2, SpatialRequest(0.1, 1.0), joined=False))
    assert start_point(stream) == (None, '')


def test_a_plan_in_its_start_delay_rests_at_its_start_point():
    path = SpatialCircle((0.5, 0.1, 0.3), 0.1, 1.0)
    stream = SetpointStream(DT, 20)
    stream.start(Plan(1, path, start_delay_ns=500 * MS))
    stream.advance(0)
    p0, reason = start_point(stream)
    assert reason == '' and p0.tolist() == circle(path.p0, 0.1, 0.0, 1.0)[0].tolist()


def test_the_nominal_loop_at_the_control_period_agrees_with_the_check_period(arms):
    # The check runs at 2 ms; at the control period (1 ms) the same loop meets the same
    # smallest kappa to 1 % along the UR5's circle (module notes: 0.5 %) and the joints
    # that move the tip the same ranges to 0.05 rad (wrist_3, on the axis of the tip,
    # drifts by 1.5 rad at 2 ms only: it moves neither the tip nor kappa)
    node_arm, nominal, q0 = arms['ur5']
    path = SpatialCircle(node_arm.spatial.fk(q0), 0.1, 5.0)
    fine = nominal_loop(nominal, q0, np.zeros(6), path, hold=0.0, period=0.001)
    coarse = nominal_loop(nominal, q0, np.zeros(6), path, hold=0.0)
    assert fine.reason == coarse.reason == ''
    assert (fine.steps, coarse.steps) == (5001, 2501)
    assert coarse.kappa_min == pytest.approx(fine.kappa_min, rel=0.01)
    moving = [0, 1, 2, 3]
    assert np.allclose(np.array(coarse.q_min)[moving], np.array(fine.q_min)[moving],
                       rtol=0, atol=0.05)
    assert np.allclose(np.array(coarse.q_max)[moving], np.array(fine.q_max)[moving],
                       rtol=0, atol=0.05)
    assert fine.q_max[5] < 1e-3 and coarse.q_max[5] > 1.0


def test_planar_only_circle_parameters_are_refused_for_a_spatial_arm_naming_them():
    reason = SCHEMA.reason(_values('ur5', centre=[0.1, 0.0]))
    assert reason.startswith('centre: does not apply to a spatial arm (task_dim 3')
    assert SCHEMA.reason(_values('ur5', circles=2)).startswith('circles: does not apply')
    assert SCHEMA.reason(_values('ur5', direction=-1)).startswith('direction: does not apply')
    assert SCHEMA.reason(_values('ur5', radius=0.05, duration=4.0, start_delay=0.5)) is None
    # a planar arm takes them as before
    planar = SCHEMA.yaml_values(os.path.join(CONFIG, 'planner.yaml'))
    planar.update(centre=[0.1, 0.0], circles=2)
    assert SCHEMA.reason(planar) is None


def test_a_plane_normal_turns_the_circle_and_belongs_to_spatial_arms():
    # the circle of a plane_normal is spatial_offline.circle with that normal, from rest
    assert SCHEMA.reason(_values('ur5', plane_normal=[0.0, 0.0, 1.0])) is None
    assert SCHEMA.reason(_values('ur5', plane_normal=[0.0, 1.0])).startswith(
        'plane_normal: expected 3 finite numbers')
    planar = SCHEMA.yaml_values(os.path.join(CONFIG, 'planner.yaml'))
    assert SCHEMA.reason(dict(planar, plane_normal=[0.0, 0.0, 1.0])).startswith(
        "plane_normal: a spatial arm's (task_dim 3)")
    p0 = (0.5, 0.1, 0.3)
    path = SpatialRequest(0.1, 5.0, [0.0, 0.0, 1.0]).at(p0)
    for t in (0.0, 1.0, 2.5, 5.0, 7.0):
        assert path.sample_tuple(t) == tuple(np.concatenate(circle(
            np.array(p0), 0.1, t, 5.0, (0.0, 0.0, 1.0))).tolist())
        assert path.sample(t)[0][2] == pytest.approx(0.3, abs=1e-15)    # horizontal plane
    assert SpatialRequest(0.1, 5.0, [0.0, 0.0, 0.0]).normal is None       # the default plane
    with pytest.raises(ValueError, match='^normal: expected 3 finite numbers, not all 0'):
        SpatialCircle(p0, 0.1, 5.0, (0.0, 0.0, 1e-12))


def test_the_spatial_plan_and_the_stream_import_in_a_python_without_ros():
    from freejoint_tools.harness import load_source
    check = load_source(os.path.join(ROOT, 'test', 'test_ros_free_imports.py'),
                        'ros_free_imports_helpers')
    assert check.imports_without_ros(['freejoint_planner.spatial_planning',
                                      'freejoint_planner.stream']) == ''
