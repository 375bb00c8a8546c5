"""The shared parts of the nodes' /diagnostics and QoS overrides (no node needed)."""

from freejoint_common.contract import profile
from freejoint_common.diagnostics import ERROR, LatencyWindow, level_and_message, OK, WARN
from freejoint_common.node_tools import overridable, QOS_OVERRIDES
from rclpy.qos import QoSPolicyKind, ReliabilityPolicy


def test_latency_window_gives_mean_and_max_in_ms_and_restarts_only_when_asked():
    window = LatencyWindow()
    assert window.take() == ('-', '-')
    for ns in (1_000_000, 3_000_000, 2_000_000):
        window.note(ns)
    assert window.take(restart=False) == ('2.000', '3.000')   # an event's status
    assert window.take() == ('2.000', '3.000')                  # the periodic one
    assert window.take() == ('-', '-')


def test_level_is_error_before_warn_before_ok_with_the_reasons_joined():
    assert level_and_message(['a', 'b'], ['c'], 'fine') == (ERROR, 'a; b')
    assert level_and_message([], ['c', 'd'], 'fine') == (WARN, 'c; d')
    assert level_and_message([], [], 'fine') == (OK, 'fine')


def test_overridable_profiles_are_copies_and_the_options_are_rclpys_defaults():
    shared = profile(1000)
    own = overridable(shared)
    own.reliability = ReliabilityPolicy.BEST_EFFORT   # what an override writes
    assert shared.reliability == ReliabilityPolicy.RELIABLE and own.depth == 1000
    assert tuple(QOS_OVERRIDES.policy_kinds) == (
        QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY)
