"""The graph contract: topics, QoS profiles, stamps and the lockstep label (docs/GRAPH.md)."""

from types import SimpleNamespace

from builtin_interfaces.msg import Time
from freejoint_common import contract
from freejoint_common.node_tools import overridable
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import MultiArrayDimension


def test_stamps_round_trip_between_time_and_integer_nanoseconds():
    stamp = contract.stamp_from_ns(1_500_000_001)
    assert (stamp.sec, stamp.nanosec) == (1, 500_000_001)
    assert contract.to_ns(stamp) == 1_500_000_001
    kept = Time()
    assert contract.stamp_from_ns(999_999_999, kept) is kept
    assert (kept.sec, kept.nanosec) == (0, 999_999_999)
    assert contract.to_ns(SimpleNamespace(sec=2, nanosec=3)) == 2_000_000_003


def test_clock_ns_reads_a_serialized_clock_and_refuses_a_short_one():
    msg = Clock(clock=contract.stamp_from_ns(12_345_000_000))
    assert contract.clock_ns(serialize_message(msg)) == 12_345_000_000
    assert contract.clock_ns(b'\x00\x01\x00\x00\x01') is None


def test_label_names_the_stamp_and_anything_else_is_no_label():
    dims = [MultiArrayDimension(label=contract.stamp_label(7_000_000), size=2, stride=2)]
    assert dims[0].label == 'stamp_ns=7000000'
    assert contract.label_stamp(dims) == 7_000_000
    for label in ('', 'joints', 'stamp_ns=', 'stamp_ns=1.5'):
        assert contract.label_stamp([MultiArrayDimension(label=label)]) is None
    assert contract.label_stamp([]) is None


def test_profiles_are_the_documented_ones():
    def policies(qos):
        return (qos.history, qos.depth, qos.reliability, qos.durability)
    keep, rel, best = HistoryPolicy.KEEP_LAST, ReliabilityPolicy.RELIABLE, \
        ReliabilityPolicy.BEST_EFFORT
    vol, latched = DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL
    assert policies(contract.STREAM_QOS) == (keep, 1000, rel, vol)
    assert policies(contract.REALTIME_STATE_QOS) == (keep, 1, rel, vol)
    assert policies(contract.SETPOINT_QOS) == (keep, 1000, rel, latched)
    assert policies(contract.LATCHED_QOS) == (keep, 1, rel, latched)
    assert policies(contract.CLOCK_PUBLISHER_QOS) == (keep, 1000, rel, vol)
    assert policies(contract.CLOCK_SUBSCRIPTION_QOS) == (keep, 1000, best, vol)
    assert policies(contract.DIAGNOSTICS_QOS) == (keep, 10, rel, vol)


def test_an_override_of_one_topic_leaves_the_contract_profile_alone():
    own = overridable(contract.JOINT_STATES.qos)
    own.reliability = ReliabilityPolicy.BEST_EFFORT    # what a qos_overrides value writes
    assert contract.JOINT_STATES.qos.reliability == ReliabilityPolicy.RELIABLE
    assert contract.COMMANDS.qos.reliability == ReliabilityPolicy.RELIABLE


def test_graph_topics_are_the_recorded_names_types_and_durabilities():
    assert [(t.name, t.type_name, t.latched) for t in contract.GRAPH_TOPICS] == [
        ('/clock', 'rosgraph_msgs/msg/Clock', False),
        ('joint_states', 'sensor_msgs/msg/JointState', False),
        ('ee_position', 'geometry_msgs/msg/PointStamped', False),
        ('effort_controller/commands', 'std_msgs/msg/Float64MultiArray', False),
        ('controller_state', 'freejoint_msgs/msg/ControllerState', False),
        ('setpoints', 'freejoint_msgs/msg/CartesianSetpoints', True),
        ('semi_singular_map', 'nav_msgs/msg/OccupancyGrid', True),
        ('planned_path', 'visualization_msgs/msg/Marker', True),
        ('controller_readiness', 'freejoint_msgs/msg/ControllerReadiness', True),
        ('plan_outcome', 'freejoint_msgs/msg/PlanOutcome', True),
    ]
    assert contract.type_name(contract.PLAN_CIRCLE.srv_type) == 'freejoint_msgs/srv/PlanCircle'
    assert (contract.JOINT_STATES.absolute, contract.CLOCK.absolute) == \
        ('/joint_states', '/clock')
    assert contract.PLAN_CIRCLE.of('freejoint_planner') == '/freejoint_planner/plan_circle'
    assert contract.RECORDER_STATUS.of('/recorder') == '/recorder/status'
    assert contract.FOLLOW_CIRCLE.of('freejoint_planner') == '/freejoint_planner/follow_circle'
