"""
The simulator node in its own process, driven by this test as its controller.

Every published state is compared with ``freejoint_core.plant.Plant`` stepped here with the
efforts the simulator should have applied: the commanded ones, or zero for a refused or
missing command.
"""
import math
import os
import re
import time

from freejoint_core.arm import table1
from freejoint_core.models import make_model
from freejoint_core.offline import initial_state
from freejoint_core.plant import Plant
import pytest

pytestmark = pytest.mark.ros

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PARAMS = os.path.join(ROOT, 'config', 'sim.yaml')
DT = 0.001
DT_NS = 1_000_000
WARN = 1     # diagnostic_msgs/DiagnosticStatus levels
ERROR = 2


def _qos():
    from freejoint_common.contract import profile
    return profile(100)


class Controller:
    """
    This test as the simulator's controller.

    ``state_depth``: the keep-last depth of its ``joint_states`` reader (a test that reads
    every state gives more than a burst can fill while this process is busy).
    """

    def __init__(self, node, wait, state_depth=100):
        import rclpy
        from freejoint_common import contract
        from std_msgs.msg import MultiArrayDimension
        self.rclpy = rclpy
        self.node = node
        self.wait = wait
        self.states = {}
        self.ee = {}
        self.clock = []
        self.diagnostics = []      # (level int, message, {key: value}) of the sim's status
        self.arrivals = []         # every joint_states message, in order of arrival
        self.contract = contract
        commands, states, ee = contract.COMMANDS, contract.JOINT_STATES, contract.EE_POSITION
        self.pub = node.create_publisher(commands.msg_type, commands.name, _qos())
        node.create_subscription(states.msg_type, states.name, self._on_state,
                                 contract.profile(state_depth))
        node.create_subscription(ee.msg_type, ee.name, self._on_ee, _qos())
        diagnostics, clock = contract.DIAGNOSTICS, contract.CLOCK
        node.create_subscription(diagnostics.msg_type, diagnostics.name, self._on_diagnostics,
                                 diagnostics.qos)
        node.create_subscription(
            clock.msg_type, clock.name,
            lambda m: self.clock.append(contract.to_ns(m.clock)), _qos())   # none lost
        self.Float64MultiArray = commands.msg_type
        self.MultiArrayDimension = MultiArrayDimension

    @staticmethod
    def _ns(msg):
        from freejoint_common.contract import to_ns
        return to_ns(msg.header.stamp)

    def _on_state(self, msg):
        self.states.setdefault(self._ns(msg), msg)
        self.arrivals.append(msg)

    def _on_diagnostics(self, msg):
        for status in msg.status:
            if status.name == 'sim_node: simulator':
                self.diagnostics.append((ord(status.level), status.message,
                                         {v.key: v.value for v in status.values}))

    def _on_ee(self, msg):
        self.ee.setdefault(self._ns(msg), msg)

    def spin(self):
        self.rclpy.spin_once(self.node, timeout_sec=0.05)

    def command(self, data, k=None, stamp_ns=None):
        """Publish efforts; labelled with the stamp of step k (or ``stamp_ns``) if given."""
        msg = self.Float64MultiArray()
        if k is not None:
            stamp_ns = k * DT_NS
        if stamp_ns is not None:
            msg.layout.dim = [self.MultiArrayDimension(label=self.contract.stamp_label(stamp_ns),
                                                       size=len(data), stride=len(data))]
        msg.data = [float(v) for v in data]
        self.pub.publish(msg)

    def step(self, data, k, what='the state', timeout=15.0, resend=1.0):
        """
        Command step k (labelled) and return the state of step k + 1.

        The command goes out again every ``resend`` s until that state arrives: the
        simulator drops a command labelled with another step, so a repeat is harmless, and
        a first command published before the simulator's reader matched this writer (the
        writer's side matches first) is not lost.
        """
        ns = (k + 1) * DT_NS
        last = [float('-inf')]

        def arrived():
            if ns in self.states and ns in self.ee:
                return True
            if time.monotonic() - last[0] >= resend:
                last[0] = time.monotonic()
                self.command(data, k)
            return False
        self.wait(arrived, timeout, '%s of step %d' % (what, k + 1), spin=self.spin)
        return self.states[ns]

    def state(self, k, what='the state', timeout=15.0):
        ns = k * DT_NS
        self.wait(lambda: ns in self.states and ns in self.ee, timeout,
                  '%s of step %d' % (what, k), spin=self.spin)
        return self.states[ns]

    def release(self, held, what='the arm released'):
        """Command zero effort until the arm leaves ``held`` (released, it falls)."""
        def commanding():
            self.command([0.0, 0.0])
            self.spin()
        self.wait(lambda: self.arrivals[-1].position.tolist() != held, 15.0, what,
                  spin=commanding)

    def held_still(self, n=10):
        """Return whether the last ``n`` states stand at one position, at rest (braked)."""
        last = self.arrivals[-n:]
        return len(last) >= n and all(
            list(m.velocity) == [0.0] * 3 and m.position.tolist() == last[0].position.tolist()
            for m in last)

    def connect(self, proc, procs):
        self.wait(lambda: self.pub.get_subscription_count() > 0 and self.states,
                  30.0, 'the simulator (log: %s)' % proc.log_path, spin=self.spin)


def _plant(case='horizontal', seed=0, dist=0.5):
    params = table1(case)
    return Plant(params, 0.0005, dist_bound=dist, seed=seed, q0=initial_state(params))


def _stepped(plant, tau):
    plant.step(tau, DT)
    return plant


def _same(msg, plant, effort):
    assert list(msg.name) == ['joint1', 'joint2', 'joint3']
    assert list(msg.position) == plant.q.tolist()
    assert list(msg.velocity) == plant.qd.tolist()
    assert list(msg.effort) == [effort[0], effort[1], 0.0]


# Lockstep waits this long [s] for each step's command before it steps with zero effort: a
# test that compares every state with the plant commands each step in time on any host, so a
# host that stalls this test for more than the default 0.5 s does not change what it applies.
# A test of the timeout sets its own.
PATIENT = 60.0


def _start(procs, *extra):
    if not any(a.startswith(('command_timeout:=', 'mode:=realtime')) for a in extra):
        extra = ('-p', 'command_timeout:=%.1f' % PATIENT, *extra)
    return procs.start_node('freejoint_sim', 'sim_node', 'sim',
                            ['--ros-args', '--params-file', PARAMS, *extra])


def test_params_file_loads_and_lockstep_steps_are_the_plant(procs, ros_node, wait):
    proc = _start(procs)
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    plant = _plant()
    model = make_model(table1('horizontal'))
    msg = ctl.state(0)
    _same(msg, plant, (0.0, 0.0))
    # Step 0 (state and /clock) goes out again every republish period until the first
    # command: wait for its /clock too, or a late-matched /clock subscription misses it.
    wait(lambda: 0 in ctl.clock, 10.0, '/clock at step 0', spin=ctl.spin)
    for k in range(30):
        tau = (3.0 * math.sin(0.3 * k), -2.0 * math.cos(0.2 * k))
        msg = ctl.step(tau, k)
        plant.step(tau, DT)
        _same(msg, plant, tau)
        ee = ctl.ee[(k + 1) * DT_NS]
        assert [ee.point.x, ee.point.y] == model.fk(plant.q).tolist()
        assert ee.header.frame_id == 'base_link'
    wait(lambda: 30 * DT_NS in ctl.clock, 10.0, '/clock at step 30', spin=ctl.spin)
    # config/sim.yaml: clock_rate 100 Hz, /clock every 10th step (step 0 maybe repeated)
    assert ctl.clock == sorted(ctl.clock)
    assert sorted(set(ctl.clock)) == [0, 10 * DT_NS, 20 * DT_NS, 30 * DT_NS]
    assert procs.stop(proc) == 0
    with open(proc.log_path) as f:
        assert 'simulator stopped at step 30 (t = 0.030 s): 0 command timeouts' in f.read()


def test_clock_goes_out_on_the_multiples_of_the_clock_period_and_at_max_steps(
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'clock_rate:=250.0', '-p', 'max_steps:=30')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    wait(lambda: len(ctl.clock) >= 2, 10.0, 'step 0 republished while waiting',
         spin=ctl.spin)
    assert set(ctl.clock) == {0}
    plant = _plant()
    for k in range(30):
        msg = ctl.step([1.0, -0.5], k)         # the state every step, stamped t_k
        plant.step((1.0, -0.5), DT)
        _same(msg, plant, (1.0, -0.5))
    wait(lambda: 30 * DT_NS in ctl.clock, 10.0, '/clock at max_steps', spin=ctl.spin)
    for _ in range(5):
        ctl.spin()
    # 250 Hz at 1 kHz: every 4th step, and max_steps = 30 (the end of the run)
    assert ctl.clock == sorted(ctl.clock)
    assert sorted(set(ctl.clock)) == [k * DT_NS for k in (0, 4, 8, 12, 16, 20, 24, 28, 30)]
    assert len(ctl.states) == 31
    assert procs.stop(proc) == 0


def test_wrong_length_and_nan_commands_are_refused_and_zero_effort_applied(
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'case:=vertical', '-p', 'seed:=3')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    plant = _plant('vertical', seed=3)
    ctl.command([1.0, 2.0, 3.0], 0)
    _same(ctl.state(1, 'the state after a 3-effort command'), _stepped(plant, (0.0, 0.0)),
          (0.0, 0.0))
    ctl.command([1.0, math.nan], 1)
    _same(ctl.state(2, 'the state after a NaN command'), _stepped(plant, (0.0, 0.0)),
          (0.0, 0.0))
    # A command for another stamp is dropped; one without a stamp label answers this step.
    ctl.command([5.0, 5.0], 7)
    ctl.command([0.5, -0.5])
    _same(ctl.state(3), _stepped(plant, (0.5, -0.5)), (0.5, -0.5))
    log = procs.log(proc)
    assert "command refused: expected 2 efforts for ['joint1', 'joint2'], got 3; zero " \
        'effort applied' in log
    assert 'command refused: non-finite effort in [1.0, nan]; zero effort applied' in log
    wait(lambda: any(d[2]['refused commands'] == '2' for d in ctl.diagnostics), 5.0,
         'the refusals in the status', spin=ctl.spin)
    # WARN: 'N commands refused in the last 1.0 s' (with the timeouts once this test is
    # silent, '; '-joined)
    first = next(d for d in ctl.diagnostics if d[2]['refused commands'] != '0')
    assert first[0] == WARN and ' commands refused in the last ' in first[1]
    assert procs.stop(proc) == 0


def test_lockstep_without_command_times_out_to_zero_effort_and_warns(procs, ros_node, wait):
    proc = _start(procs, '-p', 'command_timeout:=0.2')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    plant = _plant()
    ctl.step([2.0, -1.0], 0)
    plant.step((2.0, -1.0), DT)
    # No command for steps 1 and 2: each is integrated with zero effort after the timeout.
    msg = ctl.state(3, 'the state after two timeouts')
    plant.step((0.0, 0.0), DT)
    plant.step((0.0, 0.0), DT)
    _same(msg, plant, (0.0, 0.0))
    log = procs.log(proc)
    assert 'no command for step 1 (t = 0.001 s) within 0.2 s: zero effort (1 timeouts' in log
    assert 'no command for step 2 (t = 0.002 s)' in log
    assert procs.stop(proc) == 0


def test_lockstep_holds_at_max_steps_ignoring_commands_and_timeouts(
        procs, ros_node, wait, tmp_path):
    timing = str(tmp_path / 'timing.npz')
    proc = _start(procs, '-p', 'max_steps:=3', '-p', 'command_timeout:=0.1',
                  '-p', 'timing_file:=' + timing, '-p', 'timing_steps:=10')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    for k in range(3):
        ctl.step([1.0, -1.0], k)
    # Step 3 is the last: a command for it is ignored and no timeout steps on.
    ctl.command([1.0, -1.0], 3)
    wait(lambda: 'reached max_steps = 3 (t = 0.003 s): holding' in procs.log(proc), 10.0,
         'the hold message', spin=ctl.spin)
    deadline_spins = 10   # 0.5 s of spinning, five command timeouts' worth
    for _ in range(deadline_spins):
        ctl.spin()
    assert max(ctl.states) == 3 * DT_NS
    # The run is over at max_steps: the timing file is written then, not at the stop.
    wait(lambda: os.path.exists(timing), 10.0, 'the timing file while holding')
    # One last status says so, then nothing more (a recorder of the run drains).
    wait(lambda: any(d[1] == 'holding at max_steps' for d in ctl.diagnostics), 5.0,
         'the last status', spin=ctl.spin)
    count = len(ctl.diagnostics)
    quiet_until = time.monotonic() + 2.5    # two status periods and more
    while time.monotonic() < quiet_until:
        ctl.spin()
    assert len(ctl.diagnostics) == count and ctl.diagnostics[-1][0] == 0
    assert proc.poll() is None
    assert procs.stop(proc) == 0
    assert 'simulator stopped at step 3 (t = 0.003 s): 0 command timeouts' in \
        procs.log(proc)


def _call_reset(ros_node):
    import rclpy
    from std_srvs.srv import Trigger
    client = ros_node.create_client(Trigger, '/sim_node/reset')
    assert client.wait_for_service(timeout_sec=15.0), 'no ~/reset service'
    future = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(ros_node, future, timeout_sec=15.0)
    assert future.done() and future.result().success
    return future.result().message


def test_a_diverged_plant_publishes_its_last_sane_state_reports_error_until_reset(
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'dist_bound:=0.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    before = ctl.step([1.0, -1.0], 0)
    ctl.command([1e306, -1e306], 1)     # finite, so accepted; RK4 cannot resolve it
    held = ctl.state(2, 'the state after the diverging step')
    # ERROR at once (not only at the next 1 Hz status), with the reason
    wait(lambda: any(d[0] == ERROR for d in ctl.diagnostics), 5.0, 'an ERROR status',
         spin=ctl.spin)
    level, message, values = next(d for d in ctl.diagnostics if d[0] == ERROR)
    assert message.startswith('plant diverged at step 1: tau_active: the integration over '
                              'step 1 diverged')
    assert values['diverged'] == 'true' and values['divergences'] == '1'
    # Commands go on being answered, the plant is not integrated further.
    for k in (2, 3):
        msg = ctl.step([1.0, 1.0], k, 'a state after the divergence')
        assert list(msg.position) == list(before.position) == list(held.position)
        assert list(msg.velocity) == list(before.velocity)
        assert all(math.isfinite(v) for v in (*msg.position, *msg.velocity))
        assert list(msg.effort) == [0.0, 0.0, 0.0]
    log = procs.log(proc)
    assert 'publishing the last sane state, no further integration (call ~/reset)' in log
    assert 'divergence cleared' in _call_reset(ros_node)
    ctl.command([0.0, 0.0], 4)
    _same(ctl.state(5, 'the state after the reset'), _plant(dist=0.0), (0.0, 0.0))
    ctl.command([1.0, 1.0], 5)
    _same(ctl.state(6), _stepped(_plant(dist=0.0), (1.0, 1.0)), (1.0, 1.0))
    # (OK, or WARN for the command timeouts once this test stops commanding)
    wait(lambda: ctl.diagnostics[-1][2]['diverged'] == 'false', 5.0, 'a status without the '
         'divergence after the reset', spin=ctl.spin)
    assert ctl.diagnostics[-1][0] != ERROR
    assert ctl.diagnostics[-1][2]['divergences'] == '1'
    assert procs.stop(proc) == 0
    assert ' 0 refused commands, 1 divergences' in procs.log(proc)


def test_a_joint_faster_than_divergence_speed_counts_as_a_diverged_plant(
        procs, ros_node, wait):
    proc = _start(procs, '-p', 'dist_bound:=0.0', '-p', 'divergence_speed:=2.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    plant = _plant(dist=0.0)
    k = 0
    last_sane = ctl.state(0)
    while True:     # a strong constant torque: some joint passes 2 rad/s within 0.1 s
        assert k < 100, 'no joint passed 2 rad/s'
        msg = ctl.step([20.0, -20.0], k)
        plant.step((20.0, -20.0), DT)
        k += 1
        if max(abs(v) for v in plant.qd) > 2.0:
            break
        _same(msg, plant, (20.0, -20.0))
        last_sane = msg
    # The step that went past the bound is not published: the last sane state is.
    assert list(msg.position) == list(last_sane.position)
    assert list(msg.velocity) == list(last_sane.velocity)
    assert 'beyond divergence_speed 2 rad/s' in procs.log(proc)
    assert procs.stop(proc) == 0
    assert '1 divergences' in procs.log(proc)


def test_reset_service_puts_the_arm_back_at_rest_and_time_runs_on(procs, ros_node, wait):
    proc = _start(procs)
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    for k in range(3):
        ctl.step([4.0, 4.0], k)
    assert 'from step 4 on' in _call_reset(ros_node)
    ctl.command([4.0, 4.0], 3)
    plant = _plant()
    _same(ctl.state(4, 'the state after the reset'), plant, (0.0, 0.0))
    ctl.command([1.0, 1.0], 4)
    plant.step((1.0, 1.0), DT)
    _same(ctl.state(5), plant, (1.0, 1.0))
    assert procs.stop(proc) == 0


def test_bad_parameter_values_are_refused_with_a_reason_and_it_keeps_running(
        procs, ros_node, wait):
    from freejoint_tools.harness import ParameterCalls
    from rclpy.parameter import Parameter
    proc = _start(procs)
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    res = ParameterCalls(ros_node, 'sim_node').set_parameters([
        Parameter('dt_sub', value=0.0003), Parameter('seed', value=-2),
        Parameter('initial_position', value=[2.0, 0.0]), Parameter('case', value='sideways'),
        Parameter('clock_rate', value=300.0), Parameter('command_timeout', value=PATIENT)])
    assert res[0].reason == ('dt_sub: control_period 0.001 s is not an integer multiple of '
                             'dt_sub 0.0003 s')
    assert res[1].reason == 'seed: expected an integer >= 0, got -2'
    assert res[2].reason.startswith('initial_position: unreachable')
    assert res[3].reason.startswith("case: expected one of ('horizontal', 'vertical')")
    assert res[4].reason == ('clock_rate: 300 Hz does not divide the step rate 1000 Hz '
                             '(1 / (clock_rate * control_period) must be an integer)')
    assert [r.successful for r in res] == [False, False, False, False, False, True]
    ctl.command([1.0, 1.0], 0)
    plant = _plant()
    plant.step((1.0, 1.0), DT)
    _same(ctl.state(1), plant, (1.0, 1.0))
    assert procs.stop(proc) == 0


def _latest_effort(ctl):
    """Return the effort (all joints) of the newest state the test's controller got."""
    return list(ctl.states[max(ctl.states)].effort)


def _command_until_applied(ctl, wait, effort):
    """Command the active joints' ``effort`` until the newest state shows it applied."""
    def commanding():
        ctl.command(effort)
        ctl.spin()

    wait(lambda: _latest_effort(ctl) == list(effort) + [0.0], 15.0,
         'the commanded effort applied', spin=commanding)


def test_realtime_applies_the_latest_command_and_zero_after_the_timeout(
        procs, ros_node, wait):
    proc = _realtime(procs, '-p', 'command_timeout:=0.3', '-p', 'publish_rate:=100.0',
                     '-p', 'brake_timeout:=0.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    _command_until_applied(ctl, wait, [1.5, -0.5])
    # The controller goes silent: zero effort after command_timeout, not the last command.
    wait(lambda: _latest_effort(ctl) == [0.0, 0.0, 0.0], 15.0, 'zero effort after the timeout',
         spin=ctl.spin)
    assert 'no command on /effort_controller/commands for 0.3 s: zero effort' in \
        procs.log(proc)
    # ... and says so in its status: WARN with the reason, the timeout counted.
    wait(lambda: ctl.diagnostics and ctl.diagnostics[-1][1].startswith(
         'no command for 0.3 s: zero effort'), 5.0, 'the timeout in the status', spin=ctl.spin)
    level, _, values = ctl.diagnostics[-1]
    # (>= 1: a stall of this test over 0.3 s while it was commanding is a timeout too.)
    assert level == WARN and int(values['command timeouts']) >= 1
    assert values['brakes'] == 'released' and values['diverged'] == 'false'
    assert procs.stop(proc) == 0


def _realtime(procs, *extra):
    return _start(procs, '-p', 'mode:=realtime', *extra)


def test_realtime_states_are_stamped_on_the_step_grid_at_publish_rate(procs, ros_node, wait):
    from freejoint_common.contract import JOINT_STATES, publisher_depth_override
    from freejoint_sim.sim_node import MAX_CATCH_UP
    # 1 kHz steps, joint_states at 500 Hz: the states a 500 Hz driver gives its controller.
    # Every state reaches this process: its reader and the simulator's writer hold `every`
    # (a busy test process overflows a reader of 100).
    every = 20000
    proc = _realtime(procs, '-p', 'publish_rate:=500.0',
                     '-p', publisher_depth_override(JOINT_STATES, every))
    ctl = Controller(ros_node, wait, state_depth=every)
    ctl.connect(proc, procs)

    def commanding():
        ctl.command([0.5, -0.5])
        ctl.spin()

    count = len(ctl.arrivals)
    wait(lambda: len(ctl.arrivals) >= count + 200, 30.0, '200 states', spin=commanding)
    stamps = [Controller._ns(m) for m in ctl.arrivals[count:]]
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    # Every stamp is a step time on the 1-ms grid (a late state keeps its step's time: late
    # publications show as age), every other step at 500 Hz: 2 ms apart, or further when
    # the simulator fell more than MAX_CATCH_UP steps behind the wall clock and dropped
    # them (its grid then moves on by the steps dropped). How often that happens is the
    # machine's load; the test counts no gaps.
    assert all(g > 0 and g % DT_NS == 0 for g in gaps), gaps
    dropped = (MAX_CATCH_UP + 1) * DT_NS
    assert all(g == 2 * DT_NS or g >= dropped for g in gaps), gaps
    assert all(s % DT_NS == stamps[0] % DT_NS for s in stamps)
    # The grid is system time (a simulation-time grid would be some 1.7e9 s behind): the
    # newest stamp within a minute of the clock, however long a loaded machine kept this
    # test from reading it (8.8 s once).
    assert abs(stamps[-1] - time.time_ns()) < 60_000_000_000

    def answering():            # labelled with the stamp of the newest state
        ctl.command([0.5, -0.5], stamp_ns=Controller._ns(ctl.arrivals[-1]))
        ctl.spin()

    wait(lambda: ctl.diagnostics and ctl.diagnostics[-1][2]['command latency max [ms]'] != '-',
         10.0, 'a status with the command latency', spin=answering)
    values = ctl.diagnostics[-1][2]
    assert 0.0 <= float(values['command latency mean [ms]']) <= \
        float(values['command latency max [ms]'])
    assert values['publish rate [Hz]'] == '500'
    assert procs.stop(proc) == 0


def test_realtime_holds_the_arm_at_q0_until_the_first_command_then_releases_it(
        procs, ros_node, wait):
    proc = _realtime(procs, '-p', 'case:=vertical', '-p', 'publish_rate:=100.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    q0 = initial_state(table1('vertical')).tolist()
    # 0.3 s without a command: a vertical arm without brakes would have fallen.
    wait(lambda: len(ctl.arrivals) >= 30, 30.0, '30 states before any command',
         spin=ctl.spin)
    for msg in ctl.arrivals:
        assert list(msg.position) == q0
        assert list(msg.velocity) == [0.0, 0.0, 0.0]
        assert list(msg.effort) == [0.0, 0.0, 0.0]
    wait(lambda: ctl.diagnostics, 5.0, 'a status', spin=ctl.spin)
    # (OK 'brakes engaged: holding q0 until the first command', or WARN for steps dropped
    # behind the wall clock on a loaded machine)
    assert ctl.diagnostics[-1][0] != ERROR
    assert ctl.diagnostics[-1][2]['brakes'] == 'engaged'
    assert 'brakes engaged: the arm is held at q0 until the first command' in \
        procs.log(proc)
    ctl.release(q0)             # zero effort: released, the arm falls under gravity
    assert 'brakes released at step' in procs.log(proc)
    assert procs.stop(proc) == 0


def test_realtime_no_command_for_brake_timeout_stops_the_arm_where_it_is_until_the_next(
        procs, ros_node, wait):
    proc = _realtime(procs, '-p', 'case:=vertical', '-p', 'publish_rate:=100.0',
                     '-p', 'brake_timeout:=0.05')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    q0 = initial_state(table1('vertical')).tolist()
    ctl.release(q0)             # zero effort: released, the arm falls under gravity
    # The controller goes silent: within brake_timeout the watchdog stops the arm where it
    # is (velocity zero, no integration) and holds it there.
    wait(lambda: 'brakes engaged at step' in procs.log(proc), 15.0, 'the watchdog',
         spin=ctl.spin)
    wait(lambda: len(ctl.arrivals) >= 2 and list(ctl.arrivals[-1].velocity) == [0.0] * 3,
         5.0, 'a braked state', spin=ctl.spin)
    n = len(ctl.arrivals)
    # A zero command still in flight when the watchdog fired (taken late on a loaded
    # machine) is a next command: it releases the brakes, and the watchdog engages them
    # again 0.05 s later. Every release after the start is such a command, and the arm is
    # held after the last engagement: wait for 0.2 s of states with the log's engagements
    # and releases paired.

    def settled():
        log = procs.log(proc)
        paired = log.count('brakes released at step') == log.count('brakes engaged at step')
        return paired and ctl.held_still() and len(ctl.arrivals) >= n + 20

    wait(settled, 10.0, '0.2 s more states, every release re-braked', spin=ctl.spin)
    log = procs.log(proc)
    engagements = log.count('brakes engaged at step')
    assert log.count('brakes released at step') - 1 == engagements - 1, log
    held = ctl.arrivals[-1].position.tolist()
    assert held != q0
    braked = ctl.arrivals[n:] if engagements == 1 else ctl.arrivals[-10:]
    for msg in braked:
        assert msg.position.tolist() == held
        assert list(msg.velocity) == [0.0, 0.0, 0.0]
    # The watchdog's wait after the last command: brake_timeout_at_rest (0.01 s) if it
    # found the arm at rest (braked: the first release), brake_timeout if it came late,
    # while the released arm fell (test_watchdog.py has which is which).
    wait(lambda: ctl.diagnostics and re.search(
        r'brakes engaged \(no command for (0\.01 s, the arm at rest|0\.05 s)\)',
        ctl.diagnostics[-1][1]), 5.0, 'the brakes in the status', spin=ctl.spin)
    level, _, values = ctl.diagnostics[-1]
    assert level == WARN and values['brakes'] == 'engaged'
    assert int(values['brake engagements (no command)']) >= 1
    # The next command releases them: the arm moves on from where it was held.
    ctl.release(held, 'released again')
    log = procs.log(proc)
    assert log.count('brakes released at step') >= 2
    assert procs.stop(proc) == 0
    assert 'brake engagements' in procs.log(proc)


def test_realtime_a_brake_request_stops_the_arm_at_once_without_the_watchdog_until_the_next(
        procs, ros_node, wait):
    from freejoint_common.contract import BRAKE_REQUEST
    # brake_timeout 0: no watchdog, so every engagement is the request's.
    proc = _realtime(procs, '-p', 'case:=vertical', '-p', 'publish_rate:=100.0',
                     '-p', 'brake_timeout:=0.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    brake = ros_node.create_publisher(BRAKE_REQUEST.msg_type, BRAKE_REQUEST.name,
                                      BRAKE_REQUEST.qos)
    wait(lambda: brake.get_subscription_count() >= 1, 15.0, 'the brake request matched',
         spin=ctl.spin)
    ctl.release(initial_state(table1('vertical')).tolist())

    def asking():               # no more commands (the arm falls on): only the request brakes
        if 'brakes engaged at step' not in procs.log(proc):
            brake.publish(BRAKE_REQUEST.msg_type(data='test: stop here'))
        ctl.spin()

    wait(lambda: 'the controller asked (brake_request): test: stop here: brakes engaged at '
         'step' in procs.log(proc), 15.0, 'the requested brakes', spin=asking)
    # Held where it is: no command since the request, the arm does not move.
    wait(ctl.held_still, 10.0, '0.1 s of braked states', spin=ctl.spin)
    held = ctl.arrivals[-1].position.tolist()
    wait(lambda: ctl.diagnostics and 'brakes engaged (asked on brake_request)' in
         ctl.diagnostics[-1][1], 5.0, 'the brakes in the status', spin=ctl.spin)
    values = ctl.diagnostics[-1][2]
    assert values['brakes'] == 'engaged'
    assert int(values['brake engagements (asked)']) >= 1
    assert values['brake engagements (no command)'] == '0'
    # The next command releases them, as after the watchdog.
    ctl.release(held, 'released again')
    assert procs.stop(proc) == 0
    assert re.search(r'[1-9]\d* brake engagements \([1-9]\d* asked\)', procs.log(proc))


def test_realtime_the_controllers_shorter_watchdog_request_brakes_sooner_and_a_bad_one_is_named(
        procs, ros_node, wait):
    from freejoint_common.contract import BRAKE_TIMEOUT_REQUEST
    # The drive's own waits 5 s: an engagement within them is the request's.
    proc = _realtime(procs, '-p', 'case:=vertical', '-p', 'publish_rate:=100.0',
                     '-p', 'brake_timeout:=5.0', '-p', 'brake_timeout_at_rest:=5.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    ask = ros_node.create_publisher(BRAKE_TIMEOUT_REQUEST.msg_type, BRAKE_TIMEOUT_REQUEST.name,
                                    BRAKE_TIMEOUT_REQUEST.qos)
    ask.publish(BRAKE_TIMEOUT_REQUEST.msg_type(data=0.02))     # latched: no matching wait
    wait(lambda: 'the controller asks for the brakes after 0.02 s without a command' in
         procs.log(proc), 15.0, 'the request taken', spin=ctl.spin)
    ask.publish(BRAKE_TIMEOUT_REQUEST.msg_type(data=float('nan')))
    wait(lambda: 'brake_timeout_request: expected a finite wait >= 0 s (0: none), got nan: '
         'ignored, the last good request (0.02 s) kept' in procs.log(proc), 15.0,
         'the bad request named', spin=ctl.spin)
    wait(lambda: ctl.diagnostics and ctl.diagnostics[-1][2]['brake wait asked [s]'] == '0.02',
         5.0, 'the request in the status', spin=ctl.spin)
    ctl.release(initial_state(table1('vertical')).tolist())    # then silence: it falls
    wait(lambda: 'no command on effort_controller/commands for 0.02 s, as the controller '
         'asked while its setpoint rests (brake_timeout_request): brakes engaged at step'
         in procs.log(proc).replace('/effort_controller', 'effort_controller'), 15.0,
         'the brakes after the requested wait', spin=ctl.spin)
    wait(ctl.held_still, 10.0, '0.1 s of braked states', spin=ctl.spin)
    assert procs.stop(proc) == 0


def test_realtime_without_start_braked_the_vertical_arm_falls_from_the_first_step(
        procs, ros_node, wait):
    proc = _realtime(procs, '-p', 'case:=vertical', '-p', 'publish_rate:=100.0',
                     '-p', 'start_braked:=false')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    q0 = initial_state(table1('vertical')).tolist()
    wait(lambda: ctl.arrivals[-1].position.tolist() != q0, 15.0, 'the arm falling',
         spin=ctl.spin)
    assert 'brakes' not in procs.log(proc)
    assert procs.stop(proc) == 0


def test_realtime_diverged_plant_freezes_reports_error_at_1hz_and_reset_brings_q0_braked(
        procs, ros_node, wait):
    proc = _realtime(procs, '-p', 'case:=vertical', '-p', 'publish_rate:=100.0',
                     '-p', 'divergence_speed:=1.0', '-p', 'command_timeout:=0.2',
                     '-p', 'brake_timeout:=0.0')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    q0 = initial_state(table1('vertical')).tolist()

    def commanding():           # zero effort: the released arm falls past 1 rad/s
        ctl.command([0.0, 0.0])
        ctl.spin()

    wait(lambda: 'plant diverged at step' in procs.log(proc), 15.0, 'the divergence',
         spin=commanding)
    wait(lambda: sum(d[0] == ERROR for d in ctl.diagnostics) >= 3, 10.0,
         'ERROR at once and then at 1 Hz', spin=ctl.spin)
    error = [d for d in ctl.diagnostics if d[0] == ERROR][-1]
    assert 'beyond divergence_speed 1 rad/s' in error[1]
    assert error[2]['divergences'] == '1'
    count = len(ctl.arrivals)
    wait(lambda: len(ctl.arrivals) >= count + 10, 10.0, 'states after the divergence',
         spin=ctl.spin)
    frozen = ctl.arrivals[count:]
    assert all(m.position.tolist() == frozen[0].position.tolist() for m in frozen)
    assert all(max(abs(v) for v in m.velocity) <= 1.0 for m in frozen)
    assert all(m.header.stamp != frozen[0].header.stamp for m in frozen[1:])   # time runs
    # No command after the reset: back at q0 at rest, brakes engaged, divergence cleared.
    assert 'divergence cleared' in _call_reset(ros_node)
    wait(lambda: ctl.arrivals[-1].position.tolist() == q0, 10.0, 'q0 after the reset',
         spin=ctl.spin)
    wait(lambda: ctl.diagnostics[-1][2]['diverged'] == 'false', 5.0, 'no ERROR after the '
         'reset', spin=ctl.spin)
    assert ctl.diagnostics[-1][0] != ERROR
    assert ctl.diagnostics[-1][2]['brakes'] == 'engaged'
    assert ctl.diagnostics[-1][2]['diverged'] == 'false'
    assert ctl.arrivals[-1].velocity.tolist() == [0.0, 0.0, 0.0]
    assert procs.stop(proc) == 0
    assert ', 1 divergences' in procs.log(proc)


def test_a_command_that_cannot_be_read_is_refused_counted_and_not_applied(ros_node):
    """
    In-process, no DDS delivery: the simulator's command callback called with bytes.

    A command is taken serialized (``freejoint_common.cdr``, else rclpy's deserialization):
    bytes neither reads are refused (counted, logged), the step does not advance; the
    controller's serialized command for the current step then advances it.
    """
    from rclpy.parameter import Parameter
    from freejoint_common.cdr import CommandWriter
    from freejoint_common.contract import stamp_label
    from freejoint_sim.sim_node import SimNode
    node = SimNode(parameter_overrides=[Parameter('case', value='vertical')])
    try:
        node._pub_js.publish = node._pub_ee.publish = lambda data: None
        k0 = node._k
        node._on_command(b'\x00\x01\x00\x00\x07')
        assert (node._refused, node._k) == (1, k0)
        node._on_command(CommandWriter(2)(stamp_label(node._t_ns), (0.5, -0.5)))
        assert (node._refused, node._k) == (1, k0 + 1)
    finally:
        node.destroy_node()


def test_realtime_the_stepping_thread_takes_the_commands_no_executor_dispatches_them(
        ros_node, wait):
    """
    In-process, real DDS delivery, the simulator's node never spun by an executor.

    In real time the command subscription sits on a hidden node the stepping thread takes at
    each step: a command published by another node is there to take without any spin, is
    judged at its receipt (the middleware's reception time, not the take's), and an
    unreadable one is refused and counted. The QoS override parameter is declared on the
    simulator's node, and the subscription has the overridden depth and the remapped topic.
    """
    import time
    from rclpy.parameter import Parameter
    from freejoint_common.cdr import CommandWriter
    from freejoint_common.contract import COMMANDS, stamp_label
    from freejoint_sim.sim_node import SimNode
    depth = 'qos_overrides./arm/effort_controller/commands.subscription.depth'
    node = SimNode(parameter_overrides=[Parameter('mode', value='realtime'),
                                        Parameter(depth, value=7)],
                   cli_args=['--ros-args', '-r',
                             'effort_controller/commands:=/arm/effort_controller/commands'])
    try:
        node.stop_stepping()
        assert node.get_parameter(depth).value == 7
        sub = node._cmd_sub
        assert (sub.topic_name, sub.qos_profile.depth) == ('/arm/effort_controller/commands', 7)
        pub = ros_node.create_publisher(COMMANDS.msg_type, '/arm/effort_controller/commands',
                                        COMMANDS.qos)
        wait(lambda: pub.get_subscription_count() == 1, 10.0, 'the command subscription')
        sent = time.monotonic()
        pub.publish(CommandWriter(2)(stamp_label(node._rt_origin_ns), (0.5, -0.5)))
        pub.publish(b'\x00\x01\x00\x00\x07')      # a command no reader can read
        wait(lambda: node._take_commands() or node._refused == 1, 10.0, 'both commands taken')
        tau, received = node._latest[0], node._latest[1]
        assert tau == [0.5, -0.5]
        # the reception time, mapped to the monotonic clock: after the publication, and not
        # later than the take that found it
        assert sent - 1e-3 <= received <= time.monotonic()
        assert node._refused == 1
    finally:
        node.destroy_node()


def test_realtime_without_the_command_watchdog_the_last_command_is_held_and_brakes_ignored(
        procs, ros_node, wait):
    from freejoint_common.contract import BRAKE_REQUEST
    # A driver that holds its last command (ros2_control's forward command controller): no
    # watchdog (brake_timeout would be 0.05 s), no command timeout (0.3 s), brake requests
    # ignored; only the start-up brakes, until the first command.
    proc = _realtime(procs, '-p', 'publish_rate:=100.0', '-p', 'command_watchdog:=false',
                     '-p', 'command_timeout:=0.3', '-p', 'brake_timeout:=0.05')
    ctl = Controller(ros_node, wait)
    ctl.connect(proc, procs)
    assert 'command_watchdog: false: every command is applied until the next one' in \
        procs.log(proc)
    brake = ros_node.create_publisher(BRAKE_REQUEST.msg_type, BRAKE_REQUEST.name,
                                      BRAKE_REQUEST.qos)
    wait(lambda: brake.get_subscription_count() >= 1, 15.0, 'the brake request matched',
         spin=ctl.spin)
    _command_until_applied(ctl, wait, [1.5, -0.5])
    silent_from = time.monotonic()
    brake.publish(BRAKE_REQUEST.msg_type(data='test: stop here'))
    # Silent for 1 s (past the timeouts a watchdog drive would have): still applied.
    wait(lambda: time.monotonic() - silent_from > 1.0, 5.0, '1 s of silence', spin=ctl.spin)
    n = len(ctl.arrivals)
    wait(lambda: len(ctl.arrivals) >= n + 10, 5.0, '10 more states', spin=ctl.spin)
    for msg in ctl.arrivals[n:]:
        assert list(msg.effort) == [1.5, -0.5, 0.0]
        assert list(msg.velocity) != [0.0, 0.0, 0.0]        # moving: not braked
    log = procs.log(proc)
    assert 'brake_request ignored (test: stop here)' in log
    assert 'brakes engaged at step' not in log and 'zero effort' not in log
    assert procs.stop(proc) == 0
