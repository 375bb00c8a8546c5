"""
``/diagnostics`` of the freejoint nodes, as ros2_control's controller_manager publishes it.

One ``diagnostic_msgs/DiagnosticStatus`` per node, named ``<node name>: <kind>``, in a
``DiagnosticArray`` on ``/diagnostics`` at 1 Hz from a steady-clock timer (what
diagnostic_updater does), with the values of the last status period.  The per-tick part
stays a few counters: :class:`LatencyWindow` notes one latency per answer, the message is
built once a period by :meth:`Diagnostics.publish`.  :func:`level_and_message` is the
common rule of the level: ERROR when any error, else WARN when any warning, else OK.
"""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from freejoint_common.contract import DIAGNOSTICS
from rclpy.clock import Clock, ClockType

DIAGNOSTICS_PERIOD = 1.0
"""Wall period [s] of the status (ros2_control's diagnostic_updater: 1 Hz)."""
OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR


class LatencyWindow:
    """
    Count, sum and maximum of the latencies [ns] noted in one status period.

    :meth:`note` is the per-tick part (three integer updates); :meth:`take` reads the
    period's mean and maximum [ms] as text ('-' without any) and starts a new period.
    """

    __slots__ = ('count', 'total', 'peak')

    def __init__(self):
        self.count = 0
        self.total = 0
        self.peak = 0

    def note(self, ns):
        """Note one latency [ns]."""
        self.count += 1
        self.total += ns
        if ns > self.peak:
            self.peak = ns

    def take(self, restart=True):
        """
        Return ('<mean>', '<max>') in ms with 3 decimals ('-' if none).

        With ``restart`` (the periodic status) a new period starts; without it (a status
        sent at once between two, on an event) the period goes on.
        """
        n = self.count
        found = (('%.3f' % (self.total / n * 1e-6), '%.3f' % (self.peak * 1e-6)) if n
                 else ('-', '-'))
        if restart:
            self.count = self.total = self.peak = 0
        return found


def level_and_message(errors, warnings, ok_message):
    """
    Return (level, message): ERROR with the errors, else WARN with the warnings, else OK.

    Parameters
    ----------
    errors, warnings : list of str
        Reasons, joined by '; ' into the message.
    ok_message : str
        The message when there is neither.

    """
    if errors:
        return ERROR, '; '.join(errors)
    if warnings:
        return WARN, '; '.join(warnings)
    return OK, ok_message


class Diagnostics:
    """
    A node's ``/diagnostics`` publisher and its 1 Hz steady-clock timer.

    Parameters
    ----------
    node : rclpy.node.Node
        The node; the status is named ``<node name>: <kind>``.
    kind : str
        What the node is ('simulator', 'controller').
    hardware_id : str
        The status's ``hardware_id``.
    on_timer : callable
        Called every ``period`` wall s (on the node's executor); it calls :meth:`publish`.
    period : float, optional
        Wall period [s].

    """

    def __init__(self, node, kind, hardware_id, on_timer, period=DIAGNOSTICS_PERIOD):
        self.name = '%s: %s' % (node.get_name(), kind)
        self.hardware_id = hardware_id
        self.period = period
        self._clock = node.get_clock()
        self._pub = node.create_publisher(DIAGNOSTICS.msg_type, DIAGNOSTICS.name,
                                          DIAGNOSTICS.qos)
        self.timer = node.create_timer(period, on_timer,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish(self, level, message, values):
        """
        Publish one status.

        Parameters
        ----------
        level : int
            OK, WARN or ERROR.
        message : str
            The status message.
        values : iterable of (str, object)
            Key and value pairs (values as ``str(value)``).

        """
        status = DiagnosticStatus(level=level, name=self.name, message=message,
                                  hardware_id=self.hardware_id)
        status.values = [KeyValue(key=key, value=str(value)) for key, value in values]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self._clock.now().to_msg()
        self._pub.publish(msg)
