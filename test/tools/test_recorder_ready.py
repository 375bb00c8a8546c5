"""
The recorder's readiness (``~/status``) in real time and in sim time (no DDS).

A real-time graph has no ``/clock``: a recorder waiting for it would never answer
success. ``/clock`` is waited for only in sim time, where the log times come from it.
"""
from freejoint_common import contract
from freejoint_tools.params import RECORDER
from freejoint_tools.recorder import ready_topic_names, status_answer

GRAPH = ['/joint_states', '/ee_position', '/effort_controller/commands', '/controller_state',
         '/setpoints', '/semi_singular_map', '/planned_path']


def test_the_default_ready_topics_are_the_graph_topics_without_clock_and_readiness():
    # controller_readiness is recorded but not waited for: latched, it arrives whenever
    # its publisher matches (and a graph without a controller has none).
    default = RECORDER['ready_topics'].default
    assert '/clock' not in default and contract.CONTROLLER_READINESS.name not in default
    assert sorted(default) == sorted(t.name for t in contract.GRAPH_TOPICS
                                     if t.name not in ('/clock', 'controller_readiness'))


def test_in_system_time_the_recorder_waits_only_for_the_topics_named():
    assert ready_topic_names(GRAPH, sim_time=False) == GRAPH


def test_in_sim_time_clock_is_waited_for_too_once():
    assert ready_topic_names(GRAPH, sim_time=True) == GRAPH + ['/clock']
    assert ready_topic_names(['/clock'] + GRAPH, sim_time=True) == ['/clock'] + GRAPH


def test_a_real_time_graph_without_clock_is_ready():
    matched = dict.fromkeys(GRAPH, 1)
    ok, message = status_answer(ready_topic_names(GRAPH, False), matched, False, None, 12, 0)
    assert ok
    assert message.startswith('recording; received 12; not written 0; matched publishers: ')


def test_in_sim_time_a_graph_without_clock_publisher_is_not_ready_and_says_so():
    matched = dict.fromkeys(GRAPH, 1)
    matched['/clock'] = 0
    ok, message = status_answer(ready_topic_names(GRAPH, True), matched, False, None, 0, 0)
    assert not ok
    assert message.startswith('waiting for /clock; received 0;')


def test_a_closed_bag_or_a_write_problem_is_never_ready():
    matched = dict.fromkeys(GRAPH, 1)
    assert status_answer(GRAPH, matched, True, None, 5, 0) == (
        False, 'closed; received 5; not written 0; matched publishers: %s'
        % ', '.join('%s 1' % n for n in sorted(GRAPH)))
    ok, message = status_answer(GRAPH, matched, False, 'disk full', 5, 2)
    assert not ok and message.startswith('cannot write the bag: disk full; received 5; '
                                         'not written 2;')
