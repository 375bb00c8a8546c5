"""The recorder reads sim time straight from the serialized /clock messages it records."""
from freejoint_tools.recorder import clock_ns
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock


def test_clock_time_is_read_from_the_serialized_message():
    msg = Clock()
    msg.clock.sec = 12
    msg.clock.nanosec = 345_000_000
    assert clock_ns(serialize_message(msg)) == 12_345_000_000


def test_big_endian_clock_and_short_data():
    big = b'\x00\x00\x00\x00' + (3).to_bytes(4, 'big') + (7).to_bytes(4, 'big')
    assert clock_ns(big) == 3_000_000_007
    assert clock_ns(b'\x00\x01\x00\x00\x01') is None
