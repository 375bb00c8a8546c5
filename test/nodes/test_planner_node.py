"""
The planner node in its own process: map, path, setpoint stream in sim time, refusals.

Its bad start-up parameters run in the test process, through the ``main`` the
executable runs.

The test process plays the simulator's part of the lockstep protocol: it owns `/clock`.
"""
import os

import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
YAML = os.path.join(ROOT, 'config', 'planner.yaml')
NODE = '/freejoint_planner'
MS = 1_000_000  # ns
DT = 0.001
LOOKAHEAD = 20


def _start_planner(procs, args=('-p', 'use_sim_time:=true')):
    return procs.start_node('freejoint_planner', 'planner_node', 'planner',
                            ['--ros-args', *args])


def _spin(node, timeout=0.02):
    import rclpy
    rclpy.spin_once(node, timeout_sec=timeout)


def _wait_ready(ros_node, procs, proc, wait):
    """Wait for ~/plan_circle: the planner creates it last, after the map and marker."""
    from freejoint_msgs.srv import PlanCircle
    client = ros_node.create_client(PlanCircle, NODE + '/plan_circle')
    wait(client.service_is_ready, 30.0,
         'the planner service (log: %s)' % procs.log(proc), spin=lambda: _spin(ros_node, 0.1))
    return client


def _call(ros_node, client, request, what, timeout=10.0):
    import rclpy
    future = client.call_async(request)
    rclpy.spin_until_future_complete(ros_node, future, timeout_sec=timeout)
    assert future.done(), 'no answer to %s within %.0f s' % (what, timeout)
    return future.result()


def _param_client(ros_node):
    from freejoint_tools.harness import ParameterCalls
    return ParameterCalls(ros_node, NODE, timeout=30.0)


def _set(params, name, value):
    """Set one parameter as `ros2 param set` does; return its SetParametersResult."""
    from rclpy.parameter import Parameter
    return params.set_parameters([Parameter(name, value=value)])[0]


def _stamps(messages):
    """Return the stamps [ns] of ``messages`` (SetpointSample)."""
    return [m.stamp_ns for m in messages]


class ClockDriver:
    """Publish `/clock` like the lockstep sim and collect the planner's setpoints."""

    def __init__(self, ros_node, lookahead=LOOKAHEAD):
        from freejoint_common.contract import CLOCK, profile, SETPOINTS
        self.node = ros_node
        self.lookahead = lookahead
        self.got = []           # the setpoints (SetpointSample), in the order received
        self.batches = []       # the CartesianSetpoints messages
        self.clock_pub = ros_node.create_publisher(CLOCK.msg_type, CLOCK.name, profile(10))
        # GRAPH.md: reliable, keep-last 1000, transient local (what the controller uses: a
        # match completed on the planner's side only after its first ticks loses nothing)
        self.sub = ros_node.create_subscription(SETPOINTS.msg_type, SETPOINTS.name,
                                                self._on_batch, SETPOINTS.qos)
        self._clock = CLOCK.msg_type

    def _on_batch(self, msg):
        from freejoint_common.contract import setpoint_samples
        self.batches.append(msg)
        self.got.extend(setpoint_samples(msg))

    def matched(self):
        _spin(self.node)
        return (self.sub.get_publisher_count() >= 1
                and self.clock_pub.get_subscription_count() >= 1)

    def publish(self, now_ns):
        from freejoint_common.contract import stamp_from_ns
        self.clock_pub.publish(self._clock(clock=stamp_from_ns(now_ns)))

    def last_stamp(self):
        if not self.got:
            return None
        return self.got[-1].stamp_ns

    def step(self, now_ns, wait, what='', beyond=True):
        """
        Publish /clock = now and wait for the setpoints due (up to now + lookahead).

        ``beyond``: then spin 10 ms more and assert that nothing beyond them came (the
        lookahead); False for a test about the stream's values, not its lead.
        """
        due = (now_ns + self.lookahead * MS) // MS * MS

        def spin():
            before = len(self.got)
            _spin(self.node, 0.02)
            if len(self.got) == before:
                self.publish(now_ns)       # best effort: say it again until answered

        self.publish(now_ns)
        wait(lambda: self.last_stamp() is not None and self.last_stamp() >= due, 10.0,
             'setpoint %d ns after /clock %d ns %s' % (due, now_ns, what), spin=spin)
        if not beyond:
            return
        for _ in range(2):                 # anything published beyond `due` shows up now
            _spin(self.node, 0.005)
        assert self.last_stamp() == due, 'published beyond now + lookahead: %d > %d' % (
            self.last_stamp(), due)


def test_planner_yaml_loads_and_a_late_subscriber_gets_the_map_and_the_path(
        procs, ros_node, wait):
    import numpy as np
    from freejoint_core.arm import table1
    from freejoint_core.singularity import det_map, semi_singular
    from freejoint_common.contract import LATCHED_QOS
    from nav_msgs.msg import OccupancyGrid
    from visualization_msgs.msg import Marker
    from freejoint_planner.params import SCHEMA
    # the file over the schema's defaults (cpu_affinity: not set), and its use_sim_time
    expected = {k: v for k, v in SCHEMA.yaml_values(YAML).items() if v is not None}
    expected['use_sim_time'] = True
    proc = _start_planner(procs, ('--params-file', YAML))
    _wait_ready(ros_node, procs, proc, wait)
    # late: subscribed only now, after the planner published both at start
    latched = LATCHED_QOS
    grids, markers = [], []
    ros_node.create_subscription(OccupancyGrid, 'semi_singular_map', grids.append, latched)
    ros_node.create_subscription(Marker, 'planned_path', markers.append, latched)
    wait(lambda: grids and markers, 15.0, 'the latched map and marker',
         spin=lambda: _spin(ros_node, 0.1))

    params = _param_client(ros_node).get_values(sorted(expected))
    assert params == expected
    assert params['use_sim_time'] is True          # not the default: the file was applied

    grid = grids[0]
    cell = expected['grid_resolution']
    info = grid.info
    assert (info.width, info.height) == (300, 300)  # 2 * 1.5 m reach / 0.01 m
    assert (info.origin.position.x, info.origin.position.y) == (-1.5, -1.5)
    assert grid.header.frame_id == 'base_link'
    region = semi_singular(det_map(table1(expected['case']).scaled(expected['nominal_scale']),
                                   expected['resolution_deg']), expected['eps_d'])
    extent = (info.origin.position.x, info.origin.position.x + info.width * cell,
              info.origin.position.y, info.origin.position.y + info.height * cell)
    ref = region.to_grid(extent, cell)
    data = np.array(grid.data, dtype=np.int8).reshape(info.height, info.width)
    assert np.array_equal(data == 100, ref == 100)   # the semi-singular cells agree
    assert np.array_equal(data, ref)
    assert data[150, 150] == 0 and data[150, 250] == 100 and data[0, 0] == -1

    marker = markers[0]
    assert marker.type == Marker.LINE_STRIP and marker.header.frame_id == 'base_link'
    pts = np.array([(p.x, p.y) for p in marker.points])
    assert len(pts) > 100
    assert np.allclose(np.hypot(pts[:, 0], pts[:, 1]), 0.2, rtol=0, atol=1e-12)
    assert pts[0] == pytest.approx([0.2, 0.0], abs=1e-15)


def test_setpoints_in_sim_time_are_the_circle_on_the_grid_each_stamp_once_in_order_ahead(
        procs, ros_node, wait):
    from freejoint_core.trajectory import CircleQuintic
    # lookahead 100 >= N - 1 for the jumps of 73 ticks below (the clock spacing rule)
    proc = _start_planner(procs, ('-p', 'use_sim_time:=true', '-p', 'lookahead:=100'))
    _wait_ready(ros_node, procs, proc, wait)
    clock = ClockDriver(ros_node, lookahead=100)
    wait(clock.matched, 30.0, 'the planner matching /clock and setpoint',
         spin=lambda: _spin(ros_node, 0.05))
    for _ in range(10):
        _spin(ros_node, 0.02)
    assert clock.got == [], 'setpoints before any /clock'
    # The sim's start: /clock 0 (said again until answered), then single steps, times off
    # the grid, and jumps of many ticks, through the end of the 5 s circle.
    times = [0, 1 * MS, 2 * MS, 2_500_000, 2_999_999, 3 * MS, 3_000_001, 7 * MS]
    times += list(range(80 * MS, 5_100 * MS, 73 * MS)) + [5_100 * MS]
    for now in times:
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    last = (5_100 + 100)
    stamps = _stamps(clock.got)
    assert stamps == [k * MS for k in range(last + 1)]       # each once, in order, on the grid
    circle = CircleQuintic()                                  # the paper's, the default
    for k, m in enumerate(clock.got):
        assert tuple(m.position) + tuple(m.velocity) + tuple(m.acceleration) == \
            circle.sample_tuple(k * DT), 'tick %d' % k
        assert (m.plan_id, m.plan_time, m.final) == (1, (k * MS) * 1e-9, k * DT > 5.0)
    assert [m.final for m in clock.got].index(True) == 5001
    assert {b.header.frame_id for b in clock.batches} == {'base_link'}


def test_sim_time_takes_clock_once_and_a_sparse_clock_streams_each_tick_once_in_order_and_a_too_small_lookahead_is_refused_or_raised(  # noqa: E501
        procs, ros_node, wait):
    from freejoint_common.contract import LATCHED_QOS
    from freejoint_msgs.srv import PlanCircle
    from visualization_msgs.msg import Marker
    proc = _start_planner(procs)
    client = _wait_ready(ros_node, procs, proc, wait)
    params = _param_client(ros_node)
    clock = ClockDriver(ros_node)
    wait(clock.matched, 30.0, 'the planner matching /clock and setpoint',
         spin=lambda: _spin(ros_node, 0.05))
    for _ in range(25):                       # 0.5 s: a second /clock reader would show
        _spin(ros_node, 0.02)
    # one /clock reader: the trigger, no rclpy TimeSource subscription besides it
    assert clock.clock_pub.get_subscription_count() == 1
    for now in range(0, 201 * MS, 10 * MS):  # /clock every 10th tick, as clock_rate 100 Hz
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    stamps = _stamps(clock.got)
    assert stamps == [k * MS for k in range(201 + LOOKAHEAD)]
    # one message per /clock: the first the lookahead's ticks and its own, then 10 each,
    # stamped with its first setpoint's stamp
    assert [len(b.stamps) for b in clock.batches] == [LOOKAHEAD + 1] + [10] * 20
    from freejoint_common.contract import to_ns
    assert all(to_ns(b.header.stamp) == b.stamps[0] and b.header.frame_id == 'base_link'
               for b in clock.batches)
    assert '/clock every 10 ticks (or more): lookahead 20 covers it and one lost /clock' in \
        procs.log(proc)
    assert 'went out only at' not in procs.log(proc)
    # the node's ROS clock follows its own /clock subscription: the marker of a plan
    # accepted now is stamped with the last /clock
    markers = []
    ros_node.create_subscription(Marker, 'planned_path', markers.append, LATCHED_QOS)
    wait(lambda: markers, 15.0, 'the latched marker', spin=lambda: _spin(ros_node, 0.1))
    request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.1, duration=5.0,
                                 start_angle=0.0, direction=1, execute=True)
    assert _call(ros_node, client, request, 'plan_circle').accepted
    wait(lambda: len(markers) == 2, 15.0, 'the new marker', spin=lambda: _spin(ros_node, 0.1))
    stamp = markers[1].header.stamp
    assert (stamp.sec, stamp.nanosec) == (0, 200 * MS)
    # the spacing N = 10 is known: a lookahead below N - 1 = 9 is refused, 0 always
    result = _set(params, 'lookahead', 5)
    assert not result.successful
    assert result.reason.startswith('lookahead: 5 ticks is below N - 1 = 9 for /clock every '
                                    'N = 10 ticks'), result.reason
    result = _set(params, 'lookahead', 0)
    assert not result.successful and 'lookahead' in result.reason and 'Min: 1' in \
        result.reason, result.reason
    assert _set(params, 'lookahead', 9).successful
    # /clock then jumps 30 ticks: 221 .. 239 due, 221 .. 229 late; N = 30 > lookahead + 1:
    # a loud error and lookahead raised to 2 N - 1 = 59, the ticks up to 289 out at once
    clock.got.clear()
    clock.publish(230 * MS)
    wait(lambda: clock.last_stamp() == 289 * MS, 10.0, 'the setpoints after /clock 230 ms',
         spin=lambda: _spin(ros_node, 0.02))
    assert [m.stamp_ns // MS for m in clock.got] == list(range(221, 290))
    wait(lambda: 'lookahead raised to' in procs.log(proc), 10.0, 'the raised lookahead',
         spin=lambda: _spin(ros_node, 0.02))
    log = procs.log(proc)
    assert '9 setpoint(s) went out only at /clock 0.230000 s, after ROS time had passed ' \
        'them' in log
    assert 'lookahead must be >= N - 1 = 29 ticks for /clock every N = 30 ticks, >= 2 N - 1 ' \
        '= 59 to ride out a lost /clock; lookahead is 9' in log
    assert '[ERROR]' in log and '/clock every N = 30 ticks but lookahead is 9 < N - 1 = 29' \
        in log and 'lookahead raised to 59' in log
    assert params.get_values(['lookahead']) == {'lookahead': 59}


def test_a_path_into_the_semi_singular_region_is_refused_and_the_good_plan_keeps_streaming(
        procs, ros_node, wait):
    from freejoint_core.trajectory import CircleQuintic
    from freejoint_msgs.srv import PlanCircle
    proc = _start_planner(procs, ('-p', 'use_sim_time:=true', '-p', 'lookahead:=100'))
    client = _wait_ready(ros_node, procs, proc, wait)
    params = _param_client(ros_node)
    clock = ClockDriver(ros_node, lookahead=100)
    wait(clock.matched, 30.0, 'the planner matching /clock and setpoint',
         spin=lambda: _spin(ros_node, 0.05))
    clock.step(0, wait)

    bad = PlanCircle.Request(centre=[0.5, 0.0], radius=0.2, duration=5.0, start_angle=0.0,
                             direction=1, execute=True)
    answer = _call(ros_node, client, bad, 'plan_circle (semi-singular)')
    assert not answer.accepted
    assert 'refused' in answer.reason and 'semi-singular annulus' in answer.reason
    assert answer.margin < 0.0 and answer.plan_id == 0

    paper = PlanCircle.Request(centre=[0.0, 0.0], radius=0.2, duration=5.0, start_angle=0.0,
                               direction=1, execute=False)
    answer = _call(ros_node, client, paper, 'plan_circle (paper circle)')
    assert answer.accepted and answer.reason == ''
    assert answer.margin > 0.2 and answer.plan_id == 0        # about 0.29 m; not executed

    result = _set(params, 'centre', [0.5, 0.0])
    assert not result.successful
    assert 'circle refused' in result.reason and 'semi-singular annulus' in result.reason
    for name, value in [('radius', -0.1), ('eps_d', 0.0), ('resolution_deg', 0.05),
                        ('centre', [0.1])]:
        result = _set(params, name, value)
        assert not result.successful and name in result.reason, (name, result.reason)
    assert params.get_values(['centre', 'radius', 'eps_d', 'resolution_deg']) == {
        'centre': [0.0, 0.0], 'radius': 0.2, 'eps_d': 1e-7, 'resolution_deg': 0.25}

    for now in (1 * MS, 30 * MS, 100 * MS):
        clock.step(now, wait, '(log: %s)' % procs.log(proc))
    circle = CircleQuintic()
    assert len(clock.got) == 201
    for k, m in enumerate(clock.got):
        assert m.plan_id == 1
        assert tuple(m.position) == circle.sample_tuple(k * DT)[:2], 'tick %d' % k
    assert 'refused' in procs.log(proc)


def test_a_circle_change_starts_at_the_next_tick_by_a_transition_and_a_map_change_recomputes_the_map(  # noqa: E501
        procs, ros_node, wait):
    import numpy as np
    from freejoint_core.arm import table1
    from freejoint_core.singularity import det_map, semi_singular
    from freejoint_core.trajectory import CircleQuintic
    from freejoint_common.contract import LATCHED_QOS
    from nav_msgs.msg import OccupancyGrid
    proc = _start_planner(procs)
    _wait_ready(ros_node, procs, proc, wait)
    params = _param_client(ros_node)
    clock = ClockDriver(ros_node)
    wait(clock.matched, 30.0, 'the planner matching /clock and setpoint',
         spin=lambda: _spin(ros_node, 0.05))
    clock.step(0, wait)
    clock.step(10 * MS, wait)                                 # ticks 0 .. 30 of plan 1
    result = _set(params, 'radius', 0.3)
    assert result.successful, result.reason
    clock.step(12 * MS, wait)                                 # ticks 31, 32 of plan 2
    assert [m.plan_id for m in clock.got] == [1] * 31 + [2, 2]
    # plan 1 was moving: plan 2 starts from its state at tick 31 by a transition (plan
    # time < 0 until the new circle starts), no step
    m = clock.got[31]
    assert tuple(m.position) + tuple(m.velocity) + tuple(m.acceleration) == \
        CircleQuintic().sample_tuple(31 * DT)
    assert m.plan_time < 0.0 and clock.got[32].plan_time == m.plan_time + MS * 1e-9
    assert not m.final
    assert 'plan 2 (configured) accepted' in procs.log(proc)
    assert 'transition of' in procs.log(proc)

    grids = []
    ros_node.create_subscription(OccupancyGrid, 'semi_singular_map', grids.append, LATCHED_QOS)
    wait(lambda: grids, 15.0, 'the latched map', spin=lambda: _spin(ros_node, 0.1))
    result = _set(params, 'eps_d', 0.1)             # wider band, plan 2 still clear
    assert result.successful, result.reason
    wait(lambda: len(grids) == 2, 15.0, 'the recomputed map', spin=lambda: _spin(ros_node, 0.1))
    region = semi_singular(det_map(table1('horizontal').scaled(0.7), 0.25), 0.1)
    ref = region.to_grid((-1.5, 1.5, -1.5, 1.5), 0.01)
    assert np.array_equal(np.array(grids[1].data, dtype=np.int8).reshape(300, 300), ref)
    assert not np.array_equal(grids[0].data, grids[1].data)
    result = _set(params, 'eps_d', 1.0)             # everything semi-singular
    assert not result.successful
    assert 'running plan 2 would enter the semi-singular region' in result.reason
    assert params.get_values(['eps_d']) == {'eps_d': 0.1}


BAD_START = [
    # parameter, bad value, what the one line says after 'bad parameter: <name>: '
    ('radius', '-1.0', 'out of range'),      # a descriptor's range (every parameter's
    #   range is declared on the node: test_node_parameters.py's schema test)
    ('centre', '[0.1]', 'expected 2 values (x, y) in m, got 1'),
    ('resolution_deg', '0.7', '360 / 0.7 must be an even integer'),
    ('case', 'diagonal', "expected one of ('horizontal', 'vertical'), got 'diagonal'"),
    ('radius', '0.8', 'exceeds the largest circle the reach annulus [0, 1.5] m of the arm '
                      'holds, 0.75 m'),
    ('duration', '1.0', 'peaks at 2.35619 m/s, above max_speed 1 m/s (duration >= 2.35619 s)'),
    ('grid_resolution', '0.001', '3000 x 3000 cells for the reach 1.5 m, above 2000 a side'),
    ('settle_swing_deg', '3.0', 'the settle gate needs gravity'),     # horizontal by default
]


@pytest.mark.parametrize('param, value, reason', BAD_START,
                         ids=['%s=%s' % row[:2] for row in BAD_START])
def test_a_bad_start_up_parameter_makes_the_planners_main_log_one_line_naming_it_and_return_2(
        param, value, reason, run_main, bad_parameter_line):
    # In this process, through the main planner_node runs (its exit status as a process:
    # test_node_parameters.py's planner_node row started as one).
    code, out = run_main('freejoint_planner', 'planner_node',
                         ['--ros-args', '-p', '%s:=%s' % (param, value)])
    line = bad_parameter_line(code, out, param)
    assert reason in line, line


def test_plan_circle_every_1_3_s_while_circles_run_never_steps_the_setpoint_and_every_accepted_circle_is_reached(  # noqa: E501
        procs, ros_node, wait):
    """In sim time: plan requests while moving make no step."""
    import math
    import numpy as np
    from freejoint_core.trajectory import CircleQuintic
    from freejoint_msgs.srv import PlanCircle
    proc = _start_planner(procs)                      # the paper circle starts at t = 0
    client = _wait_ready(ros_node, procs, proc, wait)
    clock = ClockDriver(ros_node)
    wait(clock.matched, 30.0, 'the planner matching /clock and setpoint',
         spin=lambda: _spin(ros_node, 0.05))

    def own_step(circle):
        """Return the circle's largest change between consecutive ticks, from its ticks."""
        ref = np.array([circle.sample_tuple(j * DT)[:2] for j in range(5002)])
        return np.hypot(np.diff(ref[:, 0]), np.diff(ref[:, 1])).max()

    requests = [((0.05, 0.05), math.pi / 2, 1), ((-0.05, 0.02), math.pi, -1),
                ((0.02, -0.06), -math.pi / 2, 1), ((0.0, 0.0), 0.0, -1),
                ((0.06, -0.02), 2.0, 1), ((-0.03, -0.04), -2.5, -1)]
    circles = {1: CircleQuintic()}
    answers = []
    period = 1300                                     # ticks between requests: 1.3 s
    end = period * (len(requests) + 1) + 5200         # room for the last circle to start
    # /clock every LOOKAHEAD ticks: each step lets the planner publish its next LOOKAHEAD
    # setpoints (the simulator's /clock comes every 10); its lead over /clock: the tests above
    for now in range(0, end, LOOKAHEAD):
        clock.step(now * MS, wait, '(log: %s)' % procs.log(proc), beyond=False)
        i = now // period - 1
        if now % period == 0 and 0 <= i < len(requests):
            centre, angle, direction = requests[i]
            answer = _call(ros_node, client, PlanCircle.Request(
                centre=list(centre), radius=0.2, duration=5.0, start_angle=angle,
                direction=direction, execute=True), 'plan_circle at %d ms' % now)
            answers.append((now, answer.accepted, answer.plan_id, answer.reason))
            if answer.accepted:
                circles[answer.plan_id] = CircleQuintic(centre=centre, radius=0.2,
                                                        duration=5.0, start_angle=angle,
                                                        direction=direction)
            else:
                assert answer.reason.startswith(
                    'circle centre') and ('the transition into plan' in answer.reason
                                          or 'no safe transition' in answer.reason), answer
    stamps = _stamps(clock.got)
    assert stamps == [k * MS for k in range(len(stamps))]      # each tick once, in order
    p = np.array([tuple(m.position) for m in clock.got])
    steps = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    # all of one radius and duration: the same largest step but for the rounding of centre
    # + r (cos, sin), ~3e-17 m
    circle_step = max(own_step(c) for c in circles.values())
    assert circle_step - own_step(CircleQuintic()) < 1e-15
    assert steps.max() <= circle_step, (
        "setpoint step %.6g m at tick %d > the circle's own %.6g m" % (
            steps.max(), int(steps.argmax()) + 1, circle_step))
    accepted = [a for a in answers if a[1]]
    assert len(accepted) >= 3, answers                # most requests get through
    assert sorted(circles) == [1] + [a[2] for a in accepted]
    ids = [m.plan_id for m in clock.got]
    for plan_id, circle in circles.items():           # every accepted circle is reached
        ticks = [k for k, m in enumerate(clock.got)
                 if m.plan_id == plan_id and m.plan_time >= 0.0]
        assert ticks, 'plan %d never reached its circle (answers %s)' % (plan_id, answers)
        k0 = ticks[0]
        assert clock.got[k0].plan_time == 0.0
        for k in ticks[:2000]:
            m = clock.got[k]
            assert tuple(m.position) + tuple(m.velocity) + tuple(m.acceleration) == \
                circle.sample_tuple((k - k0) * DT), (plan_id, k)
        # before its circle: the transition, under its id with plan_time < 0
        before = [k for k in range(len(ids)) if ids[k] == plan_id and k < k0]
        assert all(clock.got[k].plan_time < 0.0 for k in before)
        assert plan_id == 1 or before, 'plan %d started without a transition' % plan_id
    log = procs.log(proc)
    assert log.count('transition of') == len(accepted)


def test_circles_beyond_the_reach_or_the_bounds_are_refused_at_run_time_naming_the_parameter(
        procs, ros_node, wait):
    from freejoint_msgs.srv import PlanCircle
    proc = _start_planner(procs)
    client = _wait_ready(ros_node, procs, proc, wait)
    params = _param_client(ros_node)
    for name, value, words in [
            ('radius', 0.8, 'radius: 0.8 m exceeds the largest circle the reach annulus'),
            ('centre', [1.6, 0.0], 'centre: (1.6, 0) m is 1.6 m from the base, beyond the '
                                   'reach 1.5 m'),
            ('duration', 1.0, 'duration: 1 s for radius 0.2 m peaks at 2.35619 m/s, above '
                              'max_speed 1 m/s'),
            ('grid_resolution', 0.001, 'grid_resolution: 0.001 m gives a semi_singular_map '
                                       'of 3000 x 3000 cells'),
            ('start_angle', 7.0, 'start_angle'),
            ('max_speed', 0.0, 'max_speed')]:
        result = _set(params, name, value)
        assert not result.successful and words in result.reason, (name, result.reason)
    # the configured circle (the paper's, 0.471 m/s) must stay within the bounds
    result = _set(params, 'max_speed', 0.3)
    assert not result.successful and result.reason.startswith(
        'max_speed: the configured circle would exceed the bounds: duration: 5 s for radius '
        '0.2 m peaks at 0.471239 m/s, above max_speed 0.3 m/s'), result.reason
    assert _set(params, 'duration', 8.0).successful      # 0.295 m/s
    assert _set(params, 'max_speed', 0.3).successful
    for request, words in [
            ({'radius': 0.2, 'duration': 5.0, 'start_angle': 0.0},
             'above max_speed 0.3 m/s (duration >= 7.85398 s)'),
            ({'radius': 0.2, 'duration': 8.0, 'start_angle': 7.0},
             'bad request: start_angle: expected a value in'),
            ({'radius': 0.76, 'duration': 60.0, 'start_angle': 0.0}, 'radius: 0.76 m exceeds')]:
        answer = _call(ros_node, client, PlanCircle.Request(centre=[0.0, 0.0], direction=1,
                                                            execute=True, **request),
                       'plan_circle %s' % request)
        assert not answer.accepted and words in answer.reason, answer.reason
    answer = _call(ros_node, client, PlanCircle.Request(
        centre=[0.0, 0.0], radius=0.2, duration=8.0, start_angle=0.0, direction=1,
        execute=False), 'plan_circle (slow enough)')
    assert answer.accepted, answer.reason


def test_the_planner_takes_thread_priority_and_cpu_affinity_for_every_thread_like_the_sim(
        procs, ros_node, wait):
    """In real time the stream must not be starved by SCHED_FIFO sim and controller."""
    import subprocess
    import sys
    permitted = subprocess.run(
        [sys.executable, '-c', 'import os; os.sched_setscheduler(0, os.SCHED_FIFO, '
         'os.sched_param(1))'], capture_output=True, timeout=30).returncode == 0
    cpu = sorted(os.sched_getaffinity(0))[-1]
    proc = _start_planner(procs, ('-p', 'use_sim_time:=false', '-p', 'thread_priority:=10',
                                  '-p', 'cpu_affinity:=[%d]' % cpu))
    _wait_ready(ros_node, procs, proc, wait)
    params = _param_client(ros_node)

    def threads():
        # The threads thread_priority applies to (not the middleware's asynchronous writer,
        # kept at the default scheduler: freejoint_common.scheduling.BEST_EFFORT_THREADS).
        from freejoint_tools.harness import thread_scheduling
        return {(p, prio, tuple(cpus)) for p, prio, cpus in thread_scheduling(proc.pid)[0]}
    if permitted:
        assert threads() == {(os.SCHED_FIFO, 10, (cpu,))}, procs.log(proc)
        assert params.get_values(['thread_priority']) == {'thread_priority': 10}
    else:
        assert 'thread_priority 10 not applied' in procs.log(proc)
        assert params.get_values(['thread_priority']) == {'thread_priority': 0}
    result = _set(params, 'cpu_affinity', [4096])
    assert not result.successful and 'cpu_affinity: CPU 4096' in result.reason, result.reason
    assert _set(params, 'thread_priority', 0).successful
    wait(lambda: {t[:2] for t in threads()} == {(os.SCHED_OTHER, 0)}, 10.0,
         'every thread back on the default scheduler', spin=lambda: _spin(ros_node, 0.1))


def test_with_the_settle_gate_a_plan_waits_for_the_free_link_to_settle(procs, ros_node, wait):
    # Vertical, settle_swing_deg 3: a hanging link turning at 2 rad/s (14 deg real, 18 deg
    # by the nominal model) is refused 'settling'; at rest it is accepted.
    from freejoint_common.contract import JOINT_STATES, stamp_from_ns
    from freejoint_core.arm import table1
    from freejoint_core.internal import hanging_pose
    from freejoint_msgs.srv import PlanCircle
    proc = _start_planner(procs, ('-p', 'use_sim_time:=true', '-p', 'case:=vertical',
                                  '-p', 'autostart:=false', '-p', 'settle_swing_deg:=3.0'))
    client = _wait_ready(ros_node, procs, proc, wait)
    clock = ClockDriver(ros_node)
    pub = ros_node.create_publisher(JOINT_STATES.msg_type, JOINT_STATES.name, JOINT_STATES.qos)
    wait(lambda: clock.matched() and pub.get_subscription_count() >= 1, 30.0,
         'the planner matching /clock, setpoint and joint_states',
         spin=lambda: _spin(ros_node, 0.05))
    q = hanging_pose(table1('vertical'), (0.2, 0.0)).tolist()
    request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.2, duration=5.0,
                                 start_angle=0.0, direction=1, execute=True)

    def answer_with(qd):
        msg = JOINT_STATES.msg_type(name=['joint1', 'joint2', 'joint3'], position=q,
                                    velocity=qd)
        stamp_from_ns(0, msg.header.stamp)
        pub.publish(msg)
        _spin(ros_node, 0.05)
        return _call(ros_node, client, request, 'plan_circle')

    refusals = []

    def refused_swinging():
        answer = answer_with([0.0, 0.0, 2.0])
        assert not answer.accepted and answer.reason.split(' refused: ')[1].startswith(
            'settling: '), answer.reason
        refusals.append(answer.reason)
        return 'the free link swings 18.' in answer.reason

    wait(refused_swinging, 15.0, 'a settling refusal naming the swing',
         spin=lambda: _spin(ros_node, 0.05))
    # and its state on /diagnostics says so (WARN, 'settling'), once a second
    from freejoint_common.contract import DIAGNOSTICS
    statuses = []
    ros_node.create_subscription(
        DIAGNOSTICS.msg_type, DIAGNOSTICS.name,
        lambda msg: statuses.extend(s for s in msg.status if 'planner' in s.name),
        DIAGNOSTICS.qos)
    wait(lambda: any(s.message.startswith('settling: the free link swings 18.')
                     for s in statuses), 15.0, 'the planner settling on /diagnostics',
         spin=lambda: _spin(ros_node, 0.05))
    settling = [s for s in statuses if s.message.startswith('settling')][0]
    from diagnostic_msgs.msg import DiagnosticStatus
    assert settling.level == DiagnosticStatus.WARN
    assert settling.name == 'freejoint_planner: planner'
    assert {kv.key: kv.value for kv in settling.values}['state'] == 'settling'
    assert 'settle_swing_deg 3' in refusals[-1] and refusals[-1].startswith(
        'circle centre (0, 0) m radius 0.2 m duration 5 s refused: ')
    accepted = []

    def accepted_at_rest():
        answer = answer_with([0.0, 0.0, 0.0])
        if answer.accepted:
            accepted.append(answer)
            return True
        assert 'settling: the free link swings 18.' in answer.reason, answer.reason
        return False

    wait(accepted_at_rest, 15.0, 'the plan accepted with the link at rest',
         spin=lambda: _spin(ros_node, 0.05))
    assert accepted[0].plan_id == 1 and accepted[0].reason == ''
    statuses.clear()
    wait(lambda: any(s.message == 'ready for a plan: the free link settled'
                     for s in statuses), 15.0, 'the planner ready on /diagnostics',
         spin=lambda: _spin(ros_node, 0.05))


def test_in_sim_time_a_standing_clock_gets_one_status_until_the_clock_moves(
        procs, ros_node, wait):
    # A lockstep run over (the simulator holds at max_steps, /clock stands still): the
    # planner's unchanged status is not repeated each second, so a recorder's count stays
    # steady and its drain ends; a tick of the clock brings the next status.
    import time
    from freejoint_common.contract import DIAGNOSTICS, to_ns
    proc = _start_planner(procs, ('-p', 'use_sim_time:=true', '-p', 'autostart:=false'))
    _wait_ready(ros_node, procs, proc, wait)
    clock = ClockDriver(ros_node)
    arrivals = []

    def on_status(msg):
        # Only the statuses of the moved clock (stamped in sim time): one the planner sent
        # before it took the clock's first message, stamped 0, may arrive too.
        arrivals.extend(time.monotonic() for s in msg.status
                        if s.name == 'freejoint_planner: planner'
                        and to_ns(msg.header.stamp) > 0)
    ros_node.create_subscription(DIAGNOSTICS.msg_type, DIAGNOSTICS.name, on_status,
                                 DIAGNOSTICS.qos)
    wait(clock.matched, 30.0, 'the planner matching /clock',
         spin=lambda: _spin(ros_node, 0.05))
    # The same time again until the planner has it: its /clock reader is best effort, and
    # the publisher's side matched first (a message sent before the reader's side had
    # matched is lost); the same stamp again keeps the clock standing.

    def move_clock_to(ns):
        clock.publish(ns)
        _spin(ros_node, 0.05)
    wait(lambda: arrivals, 15.0, 'a planner status after the clock moved',
         spin=lambda: move_clock_to(5_000_000))
    first = arrivals[0]
    # three status periods (1 s each) with the clock standing still: nothing more
    end = time.monotonic() + 3.5
    while time.monotonic() < end:
        _spin(ros_node, 0.05)
    assert [round(t - first, 2) for t in arrivals[1:]] == []
    wait(lambda: len(arrivals) >= 2, 15.0, 'the next status once the clock moved again',
         spin=lambda: move_clock_to(6_000_000))


def test_a_joint_reported_failed_joins_the_passive_set_and_an_arm_that_cannot_track_refuses_plans(  # noqa: E501
        procs, ros_node, wait):
    # The paper's arm (joint 3 free): joint 3 reported failed changes nothing; joint 2
    # leaves one active joint for the 2-D task, so every plan is refused naming it.
    from freejoint_common.contract import JOINT_FAILURES
    from freejoint_msgs.srv import PlanCircle
    proc = _start_planner(procs, ('-p', 'use_sim_time:=true', '-p', 'autostart:=false'))
    client = _wait_ready(ros_node, procs, proc, wait)
    pub = ros_node.create_publisher(JOINT_FAILURES.msg_type, JOINT_FAILURES.name,
                                    JOINT_FAILURES.qos)
    wait(lambda: pub.get_subscription_count() >= 1, 30.0, 'the planner matching joint_failures',
         spin=lambda: _spin(ros_node, 0.05))
    request = PlanCircle.Request(centre=[0.0, 0.0], radius=0.2, duration=5.0,
                                 start_angle=0.0, direction=1, execute=False)
    answers = []

    def taken(line):
        # A failure is assessed at the next plan: ask until the planner has received it.
        answers.append(_call(ros_node, client, request, 'plan_circle'))
        return line in procs.log(proc)

    pub.publish(JOINT_FAILURES.msg_type(data='joint3'))
    wait(lambda: taken('joint3 failed: it is free in the arm the map is of already'), 30.0,
         "the planner's line on joint3", spin=lambda: _spin(ros_node, 0.05))
    assert answers[-1].accepted, answers[-1].reason
    pub.publish(JOINT_FAILURES.msg_type(data='joint2'))
    wait(lambda: taken('no plan is accepted from now on'), 30.0,
         "the planner's line on joint2", spin=lambda: _spin(ros_node, 0.05))
    answer = answers[-1]
    assert not answer.accepted
    assert answer.reason.endswith('refused: joint2 failed: 1 active joint(s) left for the 2-D '
                                  "task (passive ['joint2', 'joint3']): no plan can be "
                                  'tracked'), answer.reason
