"""
The simulated drive's command watchdog (real time; no ROS types).

A drive brakes when its controller falls silent. How long it waits is a trade
(docs/real-time.md): while the arm moves, a short stall of the controller is best ridden
through on the last command (braking a moving arm stops it while the task moves on); at
rest the last command drives the arm open loop for nothing, and a vertical arm held by a
command computed before the stall (e.g. still ramping up from the brakes) sags for the
whole wait. So :class:`DriveWatchdog` waits ``brake_timeout`` after a command that found
the arm moving and ``rest_timeout`` after one that found it at rest: every joint
(the passive ones included) slower than ``rest_speed``, as a drive's standstill monitor
judges it.

The controller knows more than the drive: whether its setpoint rests (no task moving). It
may ask for a shorter wait (the contract's ``brake_timeout_request``): a held arm, the free
link swinging under it included, gains nothing from a stall ridden on its last command.
:meth:`DriveWatchdog.judge` takes that request; it can only shorten the wait, never turn
a disabled watchdog on or lengthen it.
"""

import math

from freejoint_core.errors import FreejointValueError


class DriveWatchdog:
    """
    When no command for too long engages the brakes.

    Parameters
    ----------
    brake_timeout : float
        Wait [s] after a command that found the arm moving; 0 = never brake.
    rest_timeout : float
        Wait [s] after a command that found the arm at rest; 0 = ``brake_timeout``.
    rest_speed : float
        At rest: every joint speed below this [rad/s], > 0.

    Raises
    ------
    FreejointValueError
        A negative or non-finite wait, a rest speed not > 0 (the argument named).

    """

    def __init__(self, brake_timeout, rest_timeout=0.0, rest_speed=0.05):
        for name, value in (('brake_timeout', brake_timeout), ('rest_timeout', rest_timeout)):
            if not (math.isfinite(value) and value >= 0.0):
                raise FreejointValueError(f'{name}: expected a finite wait >= 0 s, got {value!r}')
        if not (math.isfinite(rest_speed) and rest_speed > 0.0):
            raise FreejointValueError(f'rest_speed: expected > 0 rad/s, got {rest_speed!r}')
        self.brake_timeout = float(brake_timeout)
        self.rest_timeout = (min(float(rest_timeout), self.brake_timeout) if rest_timeout > 0.0
                             else self.brake_timeout)
        self.rest_speed = float(rest_speed)

    def judge(self, qd, requested=0.0):
        """
        Return ``(wait, why)`` for a command taken now: the wait [s] it starts, and why.

        Parameters
        ----------
        qd : sequence of float, (n,)
            Joint speeds [rad/s] of the arm when the command is taken (every joint).
        requested : float
            The wait [s] the controller asked for (``brake_timeout_request``), > 0, or 0:
            none. A request shorter than the judged wait replaces it.

        Returns
        -------
        tuple of (float, str)
            The wait [s] (0: never brake) and why: ``'moving'``, ``'at rest'`` or
            ``'asked'`` (the controller's request was the shortest).

        """
        if self.brake_timeout <= 0.0:
            return 0.0, 'moving'
        wait, why = self.rest_timeout, 'at rest'
        limit = self.rest_speed
        for v in qd:
            if not -limit < v < limit:
                wait, why = self.brake_timeout, 'moving'
                break
        if 0.0 < requested < wait:
            return requested, 'asked'
        return wait, why

    @staticmethod
    def check_request(value):
        """
        Return a requested wait [s] as a float, or raise naming what was wrong.

        Raises
        ------
        FreejointValueError
            Not a finite number >= 0.

        """
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise FreejointValueError(
                f'brake_timeout_request: expected a number of seconds, got {value!r}') from None
        if not (math.isfinite(value) and value >= 0.0):
            raise FreejointValueError(
                f'brake_timeout_request: expected a finite wait >= 0 s (0: none), got {value!r}')
        return value

    @staticmethod
    def expired(now, receipt, wait):
        """
        Return True when the wait after the command received at ``receipt`` is over.

        Parameters
        ----------
        now, receipt : float
            Monotonic times [s].
        wait : float
            The command's wait (:meth:`judge`); 0 never expires.

        """
        return wait > 0.0 and now - receipt > wait
