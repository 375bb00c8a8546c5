"""
freejoint_common.cdr reads and writes what rclpy's own serialization writes and reads.

Every case is checked against ``rclpy.serialization`` (the rmw's type support, not this
module's code): a written message deserializes to the fields it was given, a message
rclpy serialized is read back field for field, whatever the lengths (empty arrays, names
of every length modulo 4, the alignments that move with them).
"""
import math
import random
import struct

from freejoint_common.cdr import CdrError, CommandReader, CommandWriter, ControllerStateWriter
from freejoint_common.cdr import ENCAPSULATION, JointStateReader, JointStateWriter
from freejoint_common.cdr import PointStampedWriter, string_sequence
from freejoint_common.contract import label_stamp, stamp_label
import pytest

pytestmark = pytest.mark.ros


def _serialize(msg):
    from rclpy.serialization import serialize_message
    return serialize_message(msg)


def _deserialize(data, msg_type):
    from rclpy.serialization import deserialize_message
    return deserialize_message(data, msg_type)


def _joint_state(sec, nanosec, names, position, velocity, effort, frame=''):
    from sensor_msgs.msg import JointState
    msg = JointState()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    msg.header.frame_id = frame
    msg.name = list(names)
    msg.position = list(position)
    msg.velocity = list(velocity)
    msg.effort = list(effort)
    return msg


@pytest.mark.parametrize('label', [stamp_label(0), stamp_label(5_000_000), 'x', ''])
@pytest.mark.parametrize('effort', [(1.5, -2.25), (0.0, 1e-300, -7.0), ()])
def test_command_written_here_is_the_float64_multi_array_rclpy_reads(label, effort):
    from std_msgs.msg import Float64MultiArray
    data = CommandWriter(len(effort))(label, effort)
    msg = _deserialize(data, Float64MultiArray)
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [
        (label, len(effort), len(effort))]
    assert msg.layout.data_offset == 0
    assert list(msg.data) == list(effort)
    assert len(data) % 4 == 0


def test_command_of_a_label_length_seen_before_reuses_its_format_and_stays_exact():
    from std_msgs.msg import Float64MultiArray
    write = CommandWriter(2)
    for ns in (1_000_000, 2_000_000, 10_000_000, 3_000_000):
        msg = _deserialize(write(stamp_label(ns), (ns * 1e-9, -1.0)), Float64MultiArray)
        assert label_stamp(msg.layout.dim) == ns
        assert list(msg.data) == [ns * 1e-9, -1.0]
    assert len(write._formats) == 2         # two label lengths


class _Result:
    """A control loop Result's published fields (plain values)."""

    def __init__(self, m, k, n, message=''):
        rnd = random.Random(m * 100 + k * 10 + n)
        self.error = [rnd.uniform(-1, 1) for _ in range(m)]
        self.error_rate = [rnd.uniform(-1, 1) for _ in range(m)]
        self.sliding = [rnd.uniform(-1, 1) for _ in range(m)]
        self.law_state_values = [rnd.uniform(-9, 9) for _ in range(k)]
        self.effort = [rnd.uniform(-50, 50) for _ in range(n)]
        self.det_dd = 1.5e-3
        self.position = [rnd.uniform(-1, 1) for _ in range(m)]
        self.position_desired = [rnd.uniform(-1, 1) for _ in range(m)]
        # the plan's setpoint: m values, or none (no plan) for an odd k
        self.position_planned = [rnd.uniform(-1, 1) for _ in range(m)] if k % 2 == 0 else []
        self.status = 0x0421
        self.message = message
        self.setpoint_age = 0.004
        self.dt = 0.001
        self.state_age = 2.5e-4


@pytest.mark.parametrize('m, k, n', [(2, 8, 2), (3, 5, 3), (6, 0, 7), (0, 1, 0)])
@pytest.mark.parametrize('message', ['', 'holding: setpoint stale', 'é'])
@pytest.mark.parametrize('joints', [['joint1', 'joint2'], ['a', 'bb', 'ccc', 'dddd'], []])
def test_controller_state_written_here_is_the_message_rclpy_reads(m, k, n, message, joints):
    from freejoint_msgs.msg import ControllerState
    law_names = ['theta_hat[%d]' % i for i in range(k)]
    res = _Result(m, k, n, message)
    data = ControllerStateWriter(joints, law_names)((7, 123), (3, 2_000_001), res,
                                                    message.encode('utf-8'))
    msg = _deserialize(data, ControllerState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (
        7, 123, '')
    assert list(msg.error) == res.error
    assert list(msg.error_rate) == res.error_rate
    assert list(msg.sliding) == res.sliding
    assert list(msg.law_state_names) == law_names
    assert list(msg.law_state) == res.law_state_values
    assert list(msg.effort) == res.effort
    assert list(msg.joint_names) == joints
    assert msg.det_dd == res.det_dd
    assert list(msg.position) == res.position
    assert list(msg.position_desired) == res.position_desired
    assert list(msg.position_planned) == res.position_planned
    assert msg.status == res.status
    assert msg.message == message
    assert msg.state_age == res.state_age
    assert (msg.setpoint_stamp.sec, msg.setpoint_stamp.nanosec) == (3, 2_000_001)
    assert (msg.setpoint_age, msg.dt) == (res.setpoint_age, res.dt)


def test_controller_state_of_numpy_arrays_is_the_same_message_as_of_lists():
    import numpy as np
    res = _Result(2, 8, 2, 'x')
    write = ControllerStateWriter(['j1', 'j2'], ['x'] * 8)
    of_lists = write((1, 2), (3, 4), res, b'x')
    for name in ('error', 'error_rate', 'sliding', 'law_state_values', 'effort', 'position',
                 'position_desired', 'position_planned'):
        setattr(res, name, np.array(getattr(res, name)))
    assert write((1, 2), (3, 4), res, b'x') == of_lists


def test_string_sequence_is_what_rclpy_writes_for_a_string_array():
    # A JointState's names, rclpy-serialized, start at 20 (after the stamp and frame_id '').
    for names in (['joint1', 'joint2', 'joint3'], ['a'], [], ['abc', '', 'defgh']):
        ref = _serialize(_joint_state(0, 0, names, (), (), ()))
        assert _pad_free_equal(ref[20:], string_sequence(names), names)


def _pad_free_equal(ref, ours, names):
    """Compare two serialized string sequences ignoring their pad bytes (unset in rclpy's)."""
    at = 4
    for name in names:
        size = 4 + len(name.encode()) + 1
        if ref[at:at + size] != ours[at:at + size]:
            return False
        at += size + (-(at + size) % 4)
    return ref[:4] == ours[:4]


NAMES_CASES = [
    ['joint1', 'joint2', 'joint3'],
    ['passive', 'joint1', 'joint2', 'extra_joint_with_a_long_name'],
    ['a', 'bb', 'ccc', 'dddd', 'eeeee'],
    [],
]


def joint_state_cases(test):
    """Run ``test`` on every name list, frame and array lengths (``names, frame, lengths``)."""
    for mark in (pytest.mark.parametrize('lengths', [(3, 3, 3), (3, 3, 0), (0, 2, 1), (0, 0, 0)]),
                 pytest.mark.parametrize('frame', ['', 'b', 'base_link']),
                 pytest.mark.parametrize('names', NAMES_CASES)):
        test = mark(test)
    return test


def _arrays(lengths, seed):
    """Return position, velocity and effort lists of ``lengths``, random from ``seed``."""
    rnd = random.Random(seed)
    return ([rnd.uniform(-3, 3) for _ in range(n)] for n in lengths)


@joint_state_cases
def test_joint_state_rclpy_wrote_is_read_here_field_for_field(names, frame, lengths):
    pos, vel, eff = _arrays(lengths, len(names) * 7 + len(frame))
    data = _serialize(_joint_state(12, 345_678_901, names, pos, vel, eff, frame))
    sec, nanosec, got_names, got_pos, got_vel, got_eff = JointStateReader()(data)
    assert (sec, nanosec) == (12, 345_678_901)
    assert got_names == names
    assert (list(got_pos), list(got_vel), list(got_eff)) == (pos, vel, eff)


def test_joint_state_names_are_decoded_once_and_a_new_name_list_is_read_anew():
    read = JointStateReader()
    names = ['joint1', 'joint2', 'joint3']
    first = read(_serialize(_joint_state(0, 1, names, (1, 2, 3), (4, 5, 6), ())))[2]
    again = read(_serialize(_joint_state(0, 2, names, (1, 2, 3), (4, 5, 6), ())))[2]
    assert first == names and again is first
    other = ['joint1', 'joint2', 'joint4']
    changed = read(_serialize(_joint_state(0, 3, other, (1, 2, 3), (4, 5, 6), ())))
    assert changed[2] == other
    shorter = read(_serialize(_joint_state(0, 4, other[:2], (1, 2), (4, 5), ())))
    assert shorter[2] == other[:2] and shorter[3] == (1.0, 2.0)


def test_joint_state_keeps_nan_and_infinity_for_the_loop_to_refuse():
    _, _, _, pos, vel, _ = JointStateReader()(_serialize(_joint_state(
        0, 0, ['joint1'], [math.nan], [math.inf], ())))
    assert math.isnan(pos[0]) and vel[0] == math.inf


def _good():
    return _serialize(_joint_state(1, 2, ['joint1', 'joint2', 'joint3'], (1, 2, 3),
                                   (4, 5, 6), (7, 8, 9)))


@pytest.mark.parametrize('cut', [0, 3, 4, 11, 20, 40, 60, -9, -1])
def test_a_truncated_joint_state_is_refused_with_a_cdr_error(cut):
    data = _good()[:cut]
    with pytest.raises(CdrError, match='joint_states'):
        JointStateReader()(data)


def test_a_joint_state_in_another_encapsulation_is_refused_naming_it():
    data = b'\x00\x00\x00\x00' + _good()[4:]       # big-endian CDR
    with pytest.raises(CdrError, match='encapsulation'):
        JointStateReader()(data)


@pytest.mark.parametrize('offset, value, match', [
    (16, 0xFFFFFFF0, 'names'),             # the name count
    (20, 0, 'name string'),                 # the first name's length (no NUL)
    (20, 0x7FFFFFFF, 'name string'),        # the first name's length (past the end)
])
def test_absurd_counts_in_a_joint_state_are_refused_not_allocated(offset, value, match):
    data = bytearray(_good())
    struct.pack_into('<I', data, 4 + offset, value)
    with pytest.raises(CdrError, match=match):
        JointStateReader()(bytes(data))


def test_an_absurd_array_count_is_refused_naming_the_array_limit():
    data = bytearray(_serialize(_joint_state(1, 2, ['j'], (1.0,), (), ())))
    # name 'j': count at 16, length at 20, 'j\0' at 24, pad; position count at 28
    struct.pack_into('<I', data, 4 + 28, 10 ** 9)
    with pytest.raises(CdrError, match='array of 1000000000'):
        JointStateReader()(bytes(data))


def test_a_name_that_is_not_utf8_is_refused():
    data = bytearray(_serialize(_joint_state(1, 2, ['jx'], (), (), ())))
    data[4 + 25] = 0xFF                     # the 'x' of 'jx'
    with pytest.raises(CdrError, match='UTF-8'):
        JointStateReader()(bytes(data))


@joint_state_cases
def test_joint_state_written_here_is_the_message_rclpy_reads(names, frame, lengths):
    from sensor_msgs.msg import JointState
    pos, vel, eff = _arrays(lengths, len(names) * 5 + len(frame))
    msg = _deserialize(JointStateWriter(names, frame)(12, 345_678_901, pos, vel, eff),
                       JointState)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (
        12, 345_678_901, frame)
    assert list(msg.name) == names
    assert (list(msg.position), list(msg.velocity), list(msg.effort)) == (pos, vel, eff)


def test_joint_state_written_here_is_read_back_here():
    write, read = JointStateWriter(['joint1', 'joint2', 'joint3']), JointStateReader()
    for k in range(3):
        got = read(write(k, 7, (0.1 * k, 2.0, 3.0), (4.0, 5.0, -6.0), (7.0, 8.0, 9.0)))
        assert got == (k, 7, ['joint1', 'joint2', 'joint3'], (0.1 * k, 2.0, 3.0),
                       (4.0, 5.0, -6.0), (7.0, 8.0, 9.0))


@pytest.mark.parametrize('frame', ['', 'w', 'world', 'base_link_0'])
def test_point_stamped_written_here_is_the_message_rclpy_reads(frame):
    from geometry_msgs.msg import PointStamped
    msg = _deserialize(PointStampedWriter(frame)(3, 4, 0.25, -1.5, 1e-9), PointStamped)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (
        3, 4, frame)
    assert (msg.point.x, msg.point.y, msg.point.z) == (0.25, -1.5, 1e-9)


def _multi_array(labels, data):
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=i + 1, stride=7)
                      for i, label in enumerate(labels)]
    msg.layout.data_offset = 5
    msg.data = list(data)
    return msg


@pytest.mark.parametrize('labels', [[], [stamp_label(12_000_000)], ['a', 'bb'], ['', 'xyz', 'é']])
@pytest.mark.parametrize('data', [(), (1.5,), (1.5, -2.0), (0.0, 1.0, 2.0, 3.0, 4.0)])
def test_a_command_rclpy_wrote_is_read_here_label_and_data(labels, data):
    label, values = CommandReader()(_serialize(_multi_array(labels, data)))
    assert label == (labels[0] if labels else None)
    assert values == tuple(data)


def test_the_controllers_command_is_read_back_with_its_stamp_label():
    label, values = CommandReader()(CommandWriter(3)(stamp_label(9_000_000), (1.0, 2.0, 3.0)))
    assert (label, values) == (stamp_label(9_000_000), (1.0, 2.0, 3.0))


@pytest.mark.parametrize('cut', [0, 3, 7, 12, 20, 30, -1])
def test_a_truncated_command_is_refused_with_a_cdr_error(cut):
    data = _serialize(_multi_array([stamp_label(5)], (1.0, 2.0)))[:cut]
    with pytest.raises(CdrError, match='command'):
        CommandReader()(data)


@pytest.mark.parametrize('offset, value, match', [
    (0, 10 ** 6, 'layout dimensions'),
    (4, 0, 'label is malformed'),
    (4, 10 ** 6, 'label is malformed'),
])
def test_absurd_counts_in_a_command_are_refused(offset, value, match):
    data = bytearray(_serialize(_multi_array([stamp_label(5)], (1.0, 2.0))))
    struct.pack_into('<I', data, 4 + offset, value)
    with pytest.raises(CdrError, match=match):
        CommandReader()(bytes(data))


def test_a_command_in_another_encapsulation_is_refused_naming_it():
    data = b'\x00\x00\x00\x00' + _serialize(_multi_array([], (1.0,)))[4:]
    with pytest.raises(CdrError, match='encapsulation'):
        CommandReader()(data)


def _big_endian_command(value):
    """Return a Float64MultiArray (no dimension, one value) in big-endian CDR, by hand."""
    return b'\x00\x00\x00\x00' + struct.pack('>III', 0, 0, 1) + bytes(4) + struct.pack(
        '>d', value)


def test_read_serialized_takes_what_cdr_cannot_read_from_rclpys_deserialization():
    from freejoint_common.contract import COMMANDS, read_serialized
    with pytest.raises(CdrError, match='encapsulation'):
        CommandReader()(_big_endian_command(1.5))
    got = read_serialized(_big_endian_command(1.5), CommandReader(), COMMANDS.msg_type,
                          lambda msg: (len(msg.layout.dim), list(msg.data)))
    assert got == (0, [1.5])
    # What both cannot read: one ValueError naming both reasons.
    with pytest.raises(ValueError, match='short or malformed.*rclpy cannot deserialize'):
        read_serialized(ENCAPSULATION + b'\x01', CommandReader(), COMMANDS.msg_type,
                        lambda msg: msg)


@pytest.mark.parametrize('label, stamp', [
    (None, None), ('', None), ('x', None), (stamp_label(0), 0),
    (stamp_label(12_000_000), 12_000_000), (stamp_label(5) + 'x', None)])
def test_a_commands_label_gives_its_stamp_or_none(label, stamp):
    from freejoint_common.contract import label_to_stamp
    assert label_to_stamp(label) == stamp
