"""bench/soak.py: the parameter overlays a run is given, the setpoints read from a bag."""
import os

from freejoint_core.failure_offline import FAILURE_FREE_LINK_DAMPING
from freejoint_tools.harness import load_source

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
soak = load_source(os.path.join(ROOT, 'bench', 'soak.py'), 'soak')


def _given(items):
    return dict(item.split(':=', 1) for item in items)


def test_fully_actuated_with_stabilise_adds_the_freed_links_damping_to_the_controller_only():
    sim, ctl, planner = soak.fully_actuated_overrides()
    assert _given(ctl)['joint_failures'] == 'detect' and 'free_link_damping' not in _given(ctl)
    d_sim, d_ctl, d_planner = soak.fully_actuated_overrides(damped=True)
    assert (d_sim, d_planner) == (sim, planner)
    added = _given(d_ctl[len(ctl):])
    assert d_ctl[:len(ctl)] == ctl
    assert added['free_link_damping'] == 'true' and added['free_link_mode'] == 'rest'
    assert (float(added['free_link_delta_max']), float(added['free_link_drive_max'])) == (
        FAILURE_FREE_LINK_DAMPING['delta_max'], FAILURE_FREE_LINK_DAMPING['sat'])
    assert (float(added['free_link_rest_damping']), float(added['free_link_rest_after'])) == (
        0.2, 0.0)       # the offline option's k2 (0.2) from the start of each rest


def test_the_soak_pairs_each_state_with_the_setpoint_of_its_stamp_from_the_batches_of_a_bag(
        make_bag, publisher_module, tmp_path):
    from freejoint_common.contract import setpoint_samples
    from freejoint_tools.bagfile import open_bag
    path = str(tmp_path / 'run')
    make_bag(path, 30)
    dt_ns = publisher_module.DT_NS
    setpoints, index = soak.paired_setpoints(open_bag(path), [0, dt_ns, 5 * dt_ns + dt_ns // 3,
                                                              -dt_ns])
    assert len(setpoints) == 30
    assert index.tolist() == [0, 1, 5, -1]      # half a period after: the next; before: none
    for k in (0, 17, 29):
        sent = setpoint_samples(publisher_module.tick_messages(k)[1])[0]
        assert tuple(setpoints[k].position) == tuple(sent.position)
        assert setpoints[k].stamp_ns == k * dt_ns


class _Answer:
    def __init__(self, accepted, plan_id=0, reason=''):
        self.accepted, self.plan_id, self.reason = accepted, plan_id, reason


class _Outcome:
    def __init__(self, plan_id, code_name='SUCCEEDED'):
        self.plan_id = plan_id
        self.code_name = code_name


class _Client:
    """The bench client as CircleLoop uses it: plan requests, a node to subscribe with."""

    def __init__(self, answers):
        self.answers = list(answers)
        self.requests = 0
        self.node = self
        self.deliver = None

    def create_subscription(self, msg_type, name, callback, qos):
        assert name == 'plan_outcome'
        self.deliver = callback
        return object()

    def plan_circle(self, plan):
        self.requests += 1
        return self.answers.pop(0)


def test_a_followed_circle_is_not_cut_off_by_the_next_until_its_outcome_came(monkeypatch):
    graph = load_source(os.path.join(ROOT, 'bench', 'graph.py'), 'bench_graph_follow')
    now = [100.0]
    monkeypatch.setattr(graph.time, 'monotonic', lambda: now[0])
    rested = []
    client = _Client([_Answer(True, 7), _Answer(False, reason='not ready'), _Answer(True, 8)])
    loop = graph.CircleLoop(client, {'duration': 5.0}, period=5.5, strict=False, retry=0.5,
                            before=lambda: rested.append(now[0]), follow=True, rest=0.5)
    assert loop.poll() and client.requests == 1
    now[0] += 12.0                       # paused: 7 s late, no outcome yet
    assert not loop.poll() and client.requests == 1 and not rested
    client.deliver(_Outcome(7))
    assert not loop.poll()               # the outcome: the next after the rest
    now[0] += 0.4
    assert not loop.poll() and client.requests == 1
    now[0] += 0.1
    assert not loop.poll() and client.requests == 2 and rested == [112.5]
    now[0] += 0.5                        # refused: asked again, the arm not put back again
    assert loop.poll() and client.requests == 3 and rested == [112.5]
    assert loop.followed == [7, 8] and loop.waiting[0] == 8
    now[0] += 5.0 + graph.CircleLoop.OUTCOME_WAIT + 0.1
    assert not loop.poll() and loop.unanswered == [8]    # given up: recorded, next asked


def test_finishing_asks_for_no_more_circles_and_waits_for_the_running_ones_outcome(monkeypatch):
    graph = load_source(os.path.join(ROOT, 'bench', 'graph.py'), 'bench_graph_finish')
    now = [100.0]
    monkeypatch.setattr(graph.time, 'monotonic', lambda: now[0])
    client = _Client([_Answer(True, 3), _Answer(True, 4)])
    loop = graph.CircleLoop(client, {'duration': 5.0}, period=5.5, follow=True, rest=0.5)
    assert loop.poll() and loop.waiting[0] == 3
    now[0] += 6.0                        # the run's time is up while plan 3 is paused
    assert not loop.finish()             # still running: wait for it
    client.deliver(_Outcome(3))
    assert loop.finish() and loop.waiting is None
    now[0] += 10.0
    assert not loop.poll() and client.requests == 1      # no plan asked for after it
    # A plan that never gets its outcome is given up at its deadline, as in poll.
    other = graph.CircleLoop(_Client([_Answer(True, 9)]), {'duration': 5.0}, follow=True)
    assert other.poll()
    assert not other.finish()
    now[0] += 5.0 + graph.CircleLoop.OUTCOME_WAIT + 0.1
    assert other.finish() and other.unanswered == [9]


def test_the_arm_is_put_back_at_q0_only_after_a_circle_that_ended_at_its_start(monkeypatch):
    # An aborted plan leaves its setpoint standing along the path where the arm stopped: a
    # reset to q(0) there would move the arm away from it at once (the vertical arm 220 mm
    # off, the next plan aborted for its path tolerance), so the next circle joins from
    # where the arm is, by the planner's transition.
    reset = []
    monkeypatch.setattr(soak, 'rest_at_q0', reset.append)

    class Loop:
        followed, outcomes = [], {}
    loop = Loop()
    assert soak.rest_at_q0_after('client', loop) and reset == ['client']     # the first
    loop.followed, loop.outcomes = [4], {4: _Outcome(4, 'SUCCEEDED')}
    assert soak.rest_at_q0_after('client', loop) and len(reset) == 2
    for code in ('PAUSED_TOO_LONG', 'PATH_TOLERANCE_VIOLATED', 'CONTROLLER_NOT_READY'):
        loop.outcomes = {4: _Outcome(4, code)}
        assert not soak.rest_at_q0_after('client', loop) and len(reset) == 2, code
    loop.outcomes = {}                   # followed, its outcome never came: put back
    assert soak.rest_at_q0_after('client', loop) and len(reset) == 3


def test_stalls_and_controller_items_are_parsed_and_bad_ones_refused(capsys):
    args = soak.parse(['--stalls', '20', '50', '--ctl', 'realtime_epsilon:=0.1'])
    assert args.stalls == [20.0, 50.0] and args.ctl == ['realtime_epsilon:=0.1']
    for bad in (['--stalls', '50', '20'], ['--stalls', '0', '20'], ['--ctl', 'epsilon=0.1']):
        try:
            soak.parse(bad)
        except SystemExit as exc:
            assert exc.code == 2
        else:
            raise AssertionError('accepted %s' % bad)
    assert '--stalls LO HI' in capsys.readouterr().err
