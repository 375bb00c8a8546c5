"""The controller node's message conversions: a loop Result into its messages, in place."""
from freejoint_common.contract import label_stamp
from freejoint_control.conversions import command_message, controller_state_message
from freejoint_control.conversions import fill_state
from freejoint_control.loop import Result


def test_a_result_fills_the_controller_state_in_place_with_its_stamps():
    st = controller_state_message(['joint1', 'joint2'], ('theta_hat_1', 'rho_hat'))
    assert list(st.joint_names) == ['joint1', 'joint2']
    assert list(st.law_state_names) == ['theta_hat_1', 'rho_hat']
    res = Result(m=3)
    res.stamp_ns = 2_500_000_001
    res.error, res.error_rate, res.sliding = (1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (7.0, 8.0, 9.0)
    res.position, res.position_desired = (0.1, 0.2, 0.3), (0.4, 0.5, 0.6)
    res.law_state_values = [0.5, 0.25]
    res.effort = [10.0, -20.0]
    res.det_dd, res.status, res.message = 0.125, 32 | 64, 'holding'
    res.setpoint_ns = 2_499_000_000
    res.setpoint_age, res.dt, res.state_age = 0.001, 0.002, 0.003
    fill_state(st, res)
    assert (st.header.stamp.sec, st.header.stamp.nanosec) == (2, 500_000_001)
    assert (st.setpoint_stamp.sec, st.setpoint_stamp.nanosec) == (2, 499_000_000)
    assert list(st.error) == [1.0, 2.0, 3.0] and list(st.sliding) == [7.0, 8.0, 9.0]
    assert list(st.error_rate) == [4.0, 5.0, 6.0]
    assert list(st.position) == [0.1, 0.2, 0.3] and list(st.position_desired) == [0.4, 0.5, 0.6]
    assert list(st.law_state) == [0.5, 0.25] and list(st.effort) == [10.0, -20.0]
    assert (st.det_dd, st.status, st.message) == (0.125, 96, 'holding')
    assert (st.setpoint_age, st.dt, st.state_age) == (0.001, 0.002, 0.003)
    # No stamp answered (-1): the header keeps the last; no setpoint: a zero stamp.
    res.stamp_ns, res.setpoint_ns = -1, None
    fill_state(st, res)
    assert (st.header.stamp.sec, st.header.stamp.nanosec) == (2, 500_000_001)
    assert (st.setpoint_stamp.sec, st.setpoint_stamp.nanosec) == (0, 0)


def test_the_command_message_has_one_dimension_sized_by_the_joints():
    msg = command_message(['joint1', 'joint2'])
    (dim,) = msg.layout.dim
    assert label_stamp(msg.layout.dim) == 0 and (dim.size, dim.stride) == (2, 2)
