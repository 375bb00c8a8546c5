"""
Message conversions of the controller node (ROS message types only, no node, no spinning).

The node keeps one command and one ``ControllerState`` message and refills them per answer
(:func:`command_message`, :func:`controller_state_message`, :func:`fill_state`): no new
message object on the tick.
"""

from array import array

from freejoint_common.contract import COMMANDS, CONTROLLER_STATE, stamp_from_ns, stamp_label
from std_msgs.msg import MultiArrayDimension


def command_message(joints):
    """
    Return the command message (``std_msgs/Float64MultiArray``) the node refills.

    Its one dimension is labelled with the stamp answered (``stamp_label``, lockstep) and
    sized by the ``joints`` commanded.
    """
    msg = COMMANDS.msg_type()
    msg.layout.dim = [MultiArrayDimension(label=stamp_label(0), size=len(joints),
                                          stride=len(joints))]
    return msg


def controller_state_message(joints, law_state_names):
    """Return the ``ControllerState`` the node refills (joint and law-state names set)."""
    msg = CONTROLLER_STATE.msg_type()
    msg.joint_names = list(joints)
    msg.law_state_names = list(law_state_names)
    return msg


def fill_state(st, res):
    """
    Fill the ``ControllerState`` ``st`` from a loop ``Result`` (stamp when ``stamp_ns >= 0``).

    Parameters
    ----------
    st : freejoint_msgs.msg.ControllerState
        The node's message, refilled.
    res : freejoint_control.loop.Result
        The answer (plain values: sequences of float, numbers, a string).

    """
    if res.stamp_ns >= 0:
        stamp_from_ns(res.stamp_ns, st.header.stamp)
    st.error = array('d', res.error)
    st.error_rate = array('d', res.error_rate)
    st.sliding = array('d', res.sliding)
    st.law_state = array('d', res.law_state_values)
    st.effort = res.effort
    st.det_dd = res.det_dd
    st.position = array('d', res.position)
    st.position_desired = array('d', res.position_desired)
    st.status = res.status
    st.message = res.message
    if res.setpoint_ns is None:
        st.setpoint_stamp.sec = 0
        st.setpoint_stamp.nanosec = 0
    else:
        stamp_from_ns(res.setpoint_ns, st.setpoint_stamp)
    st.setpoint_age = res.setpoint_age
    st.dt = res.dt
    st.state_age = res.state_age
