"""QoS profiles between rclpy and the rosbag2 version 9 metadata format (plain dicts)."""

from freejoint_common.contract import NS_PER_S, profile
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, ReliabilityPolicy

from .bagfile import INFINITE

_INF_NS = 2 ** 63 - 1


def _duration_dict(value):
    ns = value.nanoseconds if hasattr(value, 'nanoseconds') else int(value)
    if ns >= _INF_NS or ns < 0:
        return {'sec': INFINITE[0], 'nsec': INFINITE[1]}
    return {'sec': ns // NS_PER_S, 'nsec': ns % NS_PER_S}


def _duration(value):
    try:
        sec, nsec = int(value['sec']), int(value['nsec'])
    except (KeyError, TypeError, ValueError):
        return None
    if (sec, nsec) == INFINITE or sec < 0:
        return None
    return Duration(seconds=sec, nanoseconds=nsec)


def _policy(enum, value, default):
    try:
        return enum(int(value))
    except (TypeError, ValueError):
        pass
    try:
        return enum[str(value).upper()]
    except KeyError:
        return default


def profile_to_dict(qos):
    """Return an rclpy QoSProfile (as offered, e.g. from endpoint info) as a v9 dict."""
    return {
        'history': _policy(HistoryPolicy, qos.history, HistoryPolicy.UNKNOWN).name.lower(),
        'depth': int(qos.depth),
        'reliability': _policy(ReliabilityPolicy, qos.reliability,
                               ReliabilityPolicy.UNKNOWN).name.lower(),
        'durability': _policy(DurabilityPolicy, qos.durability,
                              DurabilityPolicy.UNKNOWN).name.lower(),
        'deadline': _duration_dict(qos.deadline),
        'lifespan': _duration_dict(qos.lifespan),
        'liveliness': _policy(LivelinessPolicy, qos.liveliness,
                              LivelinessPolicy.UNKNOWN).name.lower(),
        'liveliness_lease_duration': _duration_dict(qos.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    }


def subscription_qos(offered, depth):
    """
    Return the QoS a recorder subscribes with to receive everything the publishers offer.

    As ``ros2 bag record`` adapts to the offers: reliable if every publisher is reliable
    (else best effort), transient local if every publisher is (so latched data already
    published is received), keep-last with ``depth`` (a deep queue: nothing is dropped
    while the recorder catches up).
    """
    offered = list(offered)
    reliable = bool(offered) and all(
        _policy(ReliabilityPolicy, q.reliability, None) == ReliabilityPolicy.RELIABLE
        for q in offered)
    latched = bool(offered) and all(
        _policy(DurabilityPolicy, q.durability, None) == DurabilityPolicy.TRANSIENT_LOCAL
        for q in offered)
    return profile(max(int(depth), len(offered), 1), reliable, latched)


def publisher_qos(profiles, depth):
    """
    Return the QoS to republish a recorded topic with (its first recorded offer).

    Reliability and durability as recorded; keep-last with the recorded depth if known,
    else ``depth`` (discovery does not carry the depth). Transient local streams (the
    setpoints) need the deep queue as much as volatile ones: a depth of 1 would let a fast
    playback overwrite samples a reliable subscriber has not acknowledged yet.
    """
    first = profiles[0] if profiles else {}
    reliability = _policy(ReliabilityPolicy, first.get('reliability'),
                          ReliabilityPolicy.RELIABLE)
    if reliability not in (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT):
        reliability = ReliabilityPolicy.RELIABLE
    durability = _policy(DurabilityPolicy, first.get('durability'), DurabilityPolicy.VOLATILE)
    if durability not in (DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL):
        durability = DurabilityPolicy.VOLATILE
    recorded_depth = int(first.get('depth') or 0)
    keep = recorded_depth if recorded_depth > 0 else int(depth)
    kwargs = {}
    for key in ('deadline', 'lifespan'):
        value = _duration(first.get(key, {}))
        if value is not None:
            kwargs[key] = value
    return profile(max(keep, 1), reliability == ReliabilityPolicy.RELIABLE,
                   durability == DurabilityPolicy.TRANSIENT_LOCAL, **kwargs)
