"""The controller node's message conversions: serialized state in, command and state out."""
from freejoint_common.contract import label_stamp
from freejoint_control.conversions import Messages, StateThinning
from freejoint_control.loop import Result
import pytest


def _deserialize(data, msg_type):
    from rclpy.serialization import deserialize_message
    return deserialize_message(data, msg_type)


def _result():
    res = Result(m=3)
    res.stamp_ns = 2_500_000_001
    res.error, res.error_rate, res.sliding = (1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0, 8.0, 9.0)
    res.position, res.position_desired = (0.1, 0.2, 0.3), (0.4, 0.5, 0.6)
    res.law_state_values = [0.5, 0.25]
    res.effort = [10.0, -20.0]
    res.det_dd, res.status, res.message = 0.125, 32 | 64, 'holding'
    res.setpoint_ns = 2_499_000_000
    res.setpoint_age, res.dt, res.state_age = 0.001, 0.002, 0.003
    return res


def test_a_result_is_written_as_the_controller_state_rclpy_reads_with_its_stamps():
    from freejoint_msgs.msg import ControllerState
    messages = Messages(['joint1', 'joint2'], ('theta_hat_1', 'rho_hat'))
    res = _result()
    st = _deserialize(messages.write_controller_state(res), ControllerState)
    assert list(st.joint_names) == ['joint1', 'joint2']
    assert list(st.law_state_names) == ['theta_hat_1', 'rho_hat']
    assert (st.header.stamp.sec, st.header.stamp.nanosec) == (2, 500_000_001)
    assert (st.setpoint_stamp.sec, st.setpoint_stamp.nanosec) == (2, 499_000_000)
    assert list(st.error) == [1.0, 2.0, 3.0] and list(st.sliding) == [7.0, 8.0, 9.0]
    assert list(st.error_rate) == [4.0, 5.0, 6.0]
    assert list(st.position) == [0.1, 0.2, 0.3] and list(st.position_desired) == [0.4, 0.5, 0.6]
    assert list(st.law_state) == [0.5, 0.25] and list(st.effort) == [10.0, -20.0]
    assert (st.det_dd, st.status, st.message) == (0.125, 96, 'holding')
    assert (st.setpoint_age, st.dt, st.state_age) == (0.001, 0.002, 0.003)
    assert messages.controller_state is not None
    # No stamp answered (-1): the header keeps the last; no setpoint: a zero stamp.
    res.stamp_ns, res.setpoint_ns, res.message = -1, None, ''
    st = _deserialize(messages.write_controller_state(res), ControllerState)
    assert (st.header.stamp.sec, st.header.stamp.nanosec) == (2, 500_000_001)
    assert (st.setpoint_stamp.sec, st.setpoint_stamp.nanosec) == (0, 0)
    assert st.message == ''


def test_the_command_has_one_dimension_sized_by_the_joints_labelled_with_the_stamp():
    from std_msgs.msg import Float64MultiArray
    messages = Messages(['joint1', 'joint2'], ())
    first = _deserialize(messages.command, Float64MultiArray)
    (dim,) = first.layout.dim
    assert label_stamp(first.layout.dim) == 0 and (dim.size, dim.stride) == (2, 2)
    data = messages.write_command(7_000_000, [1.5, -2.5])
    assert messages.command is data
    cmd = _deserialize(data, Float64MultiArray)
    assert label_stamp(cmd.layout.dim) == 7_000_000 and list(cmd.data) == [1.5, -2.5]


def test_a_joint_state_is_read_from_its_bytes_and_an_unreadable_one_raises_naming_why():
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    msg = JointState(name=['joint1', 'joint2'], position=[0.5, 1.5], velocity=[-1.0, 2.0])
    msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 4
    messages = Messages(['joint1'], ())
    ns, names, pos, vel, eff = messages.read_state(serialize_message(msg))
    assert (ns, names, list(pos), list(vel), list(eff)) == (
        3_000_000_004, ['joint1', 'joint2'], [0.5, 1.5], [-1.0, 2.0], [])
    with pytest.raises(ValueError, match='joint_states: .*malformed.*rclpy cannot deserialize'):
        messages.read_state(serialize_message(msg)[:30])


def test_state_thinning_gives_one_per_period_of_stamps_and_one_at_each_status_change():
    ms = 1_000_000
    thin = StateThinning(200.0)                     # a 5-ms period of stamps
    due = [k for k in range(12) if thin.due(k * ms, 0)]
    assert due == [0, 5, 10]
    assert thin.due(11 * ms, 64)                    # a status change: at once
    assert not thin.due(12 * ms, 64)
    assert thin.due(3 * ms, 64)                     # the stamps went back
    assert not thin.due(4 * ms, 64)
    assert thin.due(-1, 64) and thin.due(-1, 64)    # no stamp: the last one's is kept
    thin.set_rate(0.0)                              # every answer
    assert all(thin.due(k * ms, 64) for k in range(5, 9))
    every = StateThinning(0.0)
    assert all(every.due(k * ms, 0) for k in range(4))
