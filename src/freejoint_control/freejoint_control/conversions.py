"""
Message conversions of the controller node: serialized messages in and out, no node.

The node takes ``joint_states`` serialized and publishes its command and
``ControllerState`` serialized (``freejoint_common.cdr``): no message object on the tick,
which rclpy's conversion of a ``JointState`` in and two messages out would cost more than
the law (docs/performance.md). A state in an encoding ``cdr`` does not read is
deserialized by rclpy instead (:meth:`Messages.read_state`).
"""

from freejoint_common.cdr import CommandWriter, ControllerStateWriter, JointStateReader
from freejoint_common.contract import JOINT_STATES, NS_PER_S, read_serialized, stamp_label


def _joint_state_fields(msg):
    stamp = msg.header.stamp
    return stamp.sec, stamp.nanosec, list(msg.name), msg.position, msg.velocity, msg.effort


class Messages:
    """
    The controller's messages: a joint state read, a command and a ControllerState written.

    Parameters
    ----------
    joints : sequence of str
        The joints commanded (the command's order, ``ControllerState.joint_names``).
    law_state_names : sequence of str
        ``ControllerState.law_state_names``.

    """

    def __init__(self, joints, law_state_names):
        self._read = JointStateReader()
        self._command = CommandWriter(len(joints))
        self._state = ControllerStateWriter(joints, law_state_names)
        self._stamp = (0, 0)
        self._text = ''
        self._text_bytes = b''
        self.command = self._command(stamp_label(0), [0.0] * len(joints))
        """The last command written (bytes)."""
        self.controller_state = None
        """The last ControllerState written (bytes), None before the first."""

    def read_state(self, data):
        """
        Return ``(stamp_ns, names, position, velocity, effort)`` of a serialized JointState.

        Parameters
        ----------
        data : bytes
            The message as taken (``raw=True``).

        Raises
        ------
        ValueError
            The message cannot be read (the reason names what was wrong).

        """
        sec, nanosec, names, position, velocity, effort = read_serialized(
            data, self._read, JOINT_STATES.msg_type, _joint_state_fields)
        return sec * NS_PER_S + nanosec, names, position, velocity, effort

    def write_command(self, stamp_ns, effort):
        """Return (and keep as :attr:`command`) the command answering ``stamp_ns``."""
        self.command = data = self._command(stamp_label(stamp_ns), effort)
        return data

    def write_controller_state(self, res):
        """
        Return (and keep) the ControllerState of a loop ``Result``.

        Stamped with ``res.stamp_ns`` when >= 0, else with the last stamp written; a zero
        ``setpoint_stamp`` without a setpoint (``res.setpoint_ns`` None).
        """
        if res.stamp_ns >= 0:
            self._stamp = divmod(res.stamp_ns, NS_PER_S)
        if res.message is not self._text:
            self._text = res.message
            self._text_bytes = res.message.encode('utf-8')
        sp = res.setpoint_ns
        self.controller_state = data = self._state(
            self._stamp, (0, 0) if sp is None else divmod(sp, NS_PER_S), res, self._text_bytes)
        return data


class StateThinning:
    """
    Which answers get a ControllerState: at most ``rate`` per second of stamps, and any change.

    ros2_control's state publishers' rate: a ControllerState when ``1 / rate`` s of stamps
    passed since the last one, when the status changed, or when the stamps went back; every
    answer with ``rate`` 0.

    Parameters
    ----------
    rate : float
        ControllerStates per second of stamps [Hz], >= 0 (0: every answer).

    """

    def __init__(self, rate):
        self.set_rate(rate)
        self._ns = None                 # stamp of the last one published
        self._status = None             # and its status

    def set_rate(self, rate):
        """Take a new ``rate`` [Hz] (from the next answer on)."""
        self._period_ns = round(1e9 / rate) if rate > 0.0 else 0

    def due(self, ns, status):
        """Return whether the answer stamped ``ns`` [ns] with ``status`` gets one (noted)."""
        period = self._period_ns
        if period and self._ns is not None and status == self._status and (
                0 <= ns - self._ns < period):
            return False
        if ns >= 0:
            self._ns = ns
        self._status = status
        return True
