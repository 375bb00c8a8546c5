"""
The controller loop's readiness and what it asks of the driver when it stops.

:class:`Readiness` builds the real-time readiness guard from the ``readiness_*``
parameters (``freejoint_control.readiness``: kept across a parameter change that does not
touch it, its verdict kept when it is rebuilt), words a change of its verdict (the log
and the ``controller_readiness`` note to publish) and tells the loop's readiness
(a stop for want of states included). :class:`DriverRequests` holds what the loop asks
of a driver: its brakes (once per stop) and how long it may wait for the next command.
:func:`stop_effort` is the stop command itself. No ROS, no clock.
"""

from freejoint_common.arm_description import resolve_arm
from freejoint_control.loop_status import ERROR, INFO, WARN
from freejoint_control.readiness import guard_margins, ReadinessGuard
from freejoint_core.arm_gains import active_inertia
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import damped_hold_effort, hold_effort
import numpy as np

STOP_SAID = ('stop command sent (the gravity hold of the active joints), the brakes asked '
             'for; no command until the loop is ready again')
QUIET_SAID = 'no command until the loop is ready (the brakes asked for)'
DAMP_SAID = ('the damped joint hold answered to every state (readiness_action damp) until '
             'the loop is ready again')
HOLD_GAP_SAID = ('the damped joint hold answered to every state (the law held until a gap '
                 'longer than it rides through) until the loop is ready again')
REJOIN_SAID = ('real-time loop ready again, re-joining: the reference blends from where the '
               'stop left the arm back to the setpoints (a plan waits until it has)')
HOLD_ERROR_SAID = ('the damped joint hold answered to every state (a command safe to keep, '
                   "the law's hold given up) until the loop is ready again")


class Readiness:
    """
    The readiness guard of a real-time loop, and the loop's readiness (module notes).

    Attributes
    ----------
    guard : freejoint_control.readiness.ReadinessGuard or None
        The guard (None: lockstep, or ``readiness_guard`` off).
    brakes, damps, holds : bool
        ``readiness_action`` is 'brake' / 'damp' / 'hold'.
    note : tuple or None
        ``(stamp_ns, ready, reason)`` to publish, or None.
    stale_reason : str
        Why the loop stopped for want of states ('' : it did not, or a state came since).
    rejoin : str
        Why a loop ready again is not yet ready for a plan: its reference blends from where
        a stop left the arm back to the setpoints ('' : it is not re-joining).

    """

    def __init__(self, log):
        self.log = log
        self.guard = None
        self._key = None
        self.brakes = self.damps = self.holds = False
        self._hold_max_gap_ns = 0
        self.note = None
        self.stale_reason = ''
        self.rejoin = ''
        self._max_error = self._max_hold_error = self._max_law_hold_error = 0.0

    def install(self, cfg):
        """(Re)build the guard when its parameters change (keeps its verdict); True: none."""
        self.brakes = cfg.readiness_action == 'brake'
        self.damps = cfg.readiness_action == 'damp'
        self.holds = cfg.readiness_action == 'hold'
        self._hold_max_gap_ns = round(cfg.readiness_hold_max_gap * 1e9)
        if cfg.lockstep or not cfg.readiness_guard:
            self.guard = None
            self._key = None
            self.rejoin = ''
            return True
        margins = guard_margins(resolve_arm(cfg.values).params, cfg.delay_compensation,
                                cfg.readiness_max_delay, cfg.readiness_min_answer_rate,
                                cfg.readiness_resume_delay, cfg.readiness_resume_answer_rate,
                                cfg.readiness_max_gap, cfg.gains.epsilon)
        max_delay = margins[0]
        key = (cfg.dt_ns, max_delay, margins[1], cfg.readiness_window,
               cfg.readiness_recover_windows, margins[2], margins[3], margins[4])
        self._max_error = cfg.readiness_max_error
        self._max_hold_error = cfg.readiness_max_hold_error or cfg.readiness_max_error
        self._max_law_hold_error = cfg.readiness_hold_max_error or self._max_hold_error
        if key == self._key:
            return False
        old = self.guard
        guard = ReadinessGuard(*key[:5], start_ready=cfg.standby, resume_delay=key[5],
                               resume_rate=key[6], max_gap=key[7])
        if 'not measured' in margins[5]:
            self.log(WARN, None, 'readiness guard: ' + margins[5])
        if old is not None:
            guard.ready, guard.reason, guard.started = old.ready, old.reason, old.started
            guard.trips, guard.recoveries = old.trips, old.recoveries
        self.guard = guard
        self._key = key
        self.log(INFO, None, 'readiness guard: trips past a mean state->command delay of '
                 '%.3g ms, under %.0f %% of the states answered per %.3g s window or past %d '
                 'states missed in a row, resumes within %.3g ms and %.0f %% (%s); not ready: '
                 '%s' % (
                     max_delay * 1e3, margins[1] * 100.0, cfg.readiness_window, margins[4],
                     guard.good_delay * 1e3, guard.good_rate * 100.0, margins[5],
                     'a stop command, the brakes asked for, then no command'
                     if self.brakes else 'the damped joint hold answered'
                     if self.damps else 'the end effector held by the law, every state '
                     'answered'))
        return False

    def gives_way(self, guard):
        """
        Tell whether the law's hold gives way to the damped joint hold now.

        True: ``readiness_action`` 'hold', and the state ``guard`` just observed came after
        a gap longer than ``readiness_hold_max_gap``.
        """
        limit = self._hold_max_gap_ns
        return (self.holds and limit > 0
                and (guard.last_missed + 1) * guard.dt_ns > limit)

    def error_limit(self, holding):
        """Return the tracking error [m] past which the loop is not ready (0: none)."""
        return self._max_hold_error if holding else self._max_error

    def law_hold_limit(self):
        """Return the error [m] past which a not-ready law's hold gives way (0: never)."""
        return self._max_law_hold_error

    def verdict(self):
        """Return ``(ready, reason)`` now (a stop for want of states: not ready)."""
        if self.stale_reason:
            return False, self.stale_reason
        guard = self.guard
        if guard is None:
            return True, ''
        if guard.ready and self.rejoin:
            return False, self.rejoin
        return guard.ready, guard.reason

    def rejoining(self, ns, reason):
        """
        Say (note) that the loop, ready again at the state stamped ``ns``, re-joins first.

        The stop may have left the arm off the setpoints (the damped joint hold lets the
        free link swing and the active joints sag): until the reference has blended back
        to them, the loop tracks but is not ready for a plan, so that a plan paused for it
        stays paused and a new one is refused, with ``reason``.
        """
        self.rejoin = reason
        self.note = (ns, False, reason)

    def rejoined(self, ns):
        """Say (note) that the reference is back on the setpoints at the state ``ns``."""
        self.rejoin = ''
        self.note = (ns, True, self.guard.reason if self.guard is not None else '')

    def take_note(self):
        """Return the readiness change to publish, ``(stamp_ns, ready, reason)``, once, or None."""
        note = self.note
        self.note = None
        return note

    def changed(self, change, ns, action=None):
        """
        Log a change of the guard's verdict (once per transition); note it to publish.

        ``action``: what a trip (``change`` 1) does, when not what ``readiness_action``
        does (the loop's words).
        """
        guard = self.guard
        self.note = (ns, guard.ready, guard.reason)
        self.rejoin = ''
        if change == 1:
            action = action or (STOP_SAID if self.brakes else DAMP_SAID if self.damps
                                else HOLD_GAP_SAID if self.gives_way(guard)
                                else 'holding position')
            self.log(ERROR, None, '%s: %s' % (guard.reason, action))
        else:
            self.log(WARN if guard.recoveries else INFO, None,
                     'real-time loop ready%s (%d good windows: mean delay %.3g ms, %.0f %% of '
                     'the states answered): tracking %s from a hold where the arm is' % (
                         ' again' if guard.recoveries else '', guard.recover_windows,
                         guard.last_delay * 1e3, guard.last_rate * 100.0,
                         'resumes' if guard.recoveries else 'starts'))


class DriverRequests:
    """
    What the loop asks of the driver (the node sends each once).

    Attributes
    ----------
    brake_request : str or None
        Why the driver is asked to brake now, or None.
    brake_requests : int
        Brake requests so far.
    drive_wait : float or None
        The wait for a command sent last [s] (``brake_timeout_request``; None: none).
    drive_wait_request : float or None
        The one to send now, or None.

    """

    def __init__(self):
        self.brake_request = None
        self.brake_requests = 0
        self._asked = False             # asked during this stop
        self.drive_wait = None
        self.drive_wait_request = None
        self._ask_brakes = False
        self._hold_wait = 0.0

    def configure(self, ask_brakes, hold_wait):
        """Take ``readiness_brake_request`` (real time) and ``hold_brake_timeout`` [s]."""
        self._ask_brakes = ask_brakes
        self._hold_wait = hold_wait

    def ask_brake(self, reason):
        """Ask the driver for its brakes now (once per stop; ``readiness_brake_request``)."""
        if self._ask_brakes and not self._asked:
            self._asked = True
            self.brake_requests += 1
            self.brake_request = '%s: brake now' % reason

    def stop_over(self):
        """End the stop: the next one asks for the brakes again."""
        self._asked = False

    def take_brake_request(self):
        """Return the brake request to send (why), once, or None."""
        why = self.brake_request
        self.brake_request = None
        return why

    def ask_drive_wait(self, rests):
        """
        Note the driver's wait to ask for (real time): ``hold_brake_timeout`` at rest, else 0.

        ``rests``: this tick's setpoint rests (none, stale, or zero velocity and
        acceleration). Sets ``drive_wait_request`` when it differs from the one sent.
        """
        wait = self._hold_wait if rests else 0.0
        if wait != self.drive_wait:
            self.drive_wait = self.drive_wait_request = wait

    def take_drive_wait(self):
        """Return the driver's wait to send now [s] (brake_timeout_request), once, or None."""
        wait = self.drive_wait_request
        self.drive_wait_request = None
        return wait


def stop_effort(model, q, qd, q_stop, hold_time, cmd_index, limits):
    """
    Return the stop command [N m] in command order (``freejoint_core.guards``).

    Parameters
    ----------
    model : ArmModel or SpatialArm
        The law's (nominal) model: ``gravity_torque``, ``active`` and its inertia.
    q : sequence of float, (n,) or None
        The core's angles [rad] (None: no state measured yet: zero).
    qd : sequence of float, (n,) or None
        Rates [rad/s] for the damped hold, or None (the gravity hold alone).
    q_stop : sequence of float, (r,) or None
        The damped hold's angles of the active joints [rad].
    hold_time : float
        ``stop_hold_time`` [s] (the damped hold's gains).
    cmd_index : tuple of int
        The command's joints as indices of the active ones.
    limits : sequence of float or None
        The torque limits in command order.

    Returns
    -------
    list of float
        The active joints' gravity load at ``q`` (``hold_effort``; with ``qd`` the damped
        joint hold, ``damped_hold_effort``), within ``limits``; zero when it cannot be
        computed.

    """
    zero = [0.0] * len(cmd_index)
    if q is None:
        return zero
    try:
        gravity = model.gravity_torque(q).tolist()
        if qd is None:
            tau = hold_effort(gravity, model.active)
        else:
            tau = damped_hold_effort(gravity, model.active, active_inertia(model, q), q, qd,
                                     q_stop, hold_time)
    except (FreejointValueError, ArithmeticError, np.linalg.LinAlgError):
        return zero
    identity = cmd_index == tuple(range(len(cmd_index)))
    effort = tau if identity else [tau[i] for i in cmd_index]
    if limits is not None:
        effort = hold_effort(effort, range(len(effort)), limits)
    return effort
