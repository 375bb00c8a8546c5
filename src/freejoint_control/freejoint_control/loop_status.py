"""
The published state of the controller's loop, and what its status period reports.

Its fields, status bits and message, and the status period's ``/diagnostics`` and the
end-of-run line.

:class:`Result` is what :class:`freejoint_control.loop.ControlLoop` answers a state with
(ControllerState's fields as plain values); :func:`status_message` words its status bits;
:class:`PeriodFigures` keeps what a status period reports beyond the counters (the bits
seen, the error against the plan and against the controller's reference);
:func:`diagnostics` and :func:`report` put them into words.  No ROS, no clock.
"""

import math

from freejoint_core.control import STATUS_NEAR_SINGULAR, STATUS_STALE_SETPOINT, \
    STATUS_TORQUE_LIMITED

# ControllerState's status bits beyond the core's (test_loop checks them against the message).
STATUS_HOLDING = 32
STATUS_RATE_LIMITED = 64
STATUS_LAW_FAULT = 128
STATUS_RESUMING = 256
STATUS_DT_CLAMPED = 512
STATUS_SETPOINT_LATE = 1024
STATUS_STOPPED = 2048

DEBUG, INFO, WARN, ERROR = 'debug', 'info', 'warn', 'error'
"""Levels of the ``log`` callable."""
RECEIPT = 'receipt'
"""``Result.latency_ns`` of a lockstep answer: the node measures it from the state's receipt
(``ControlLoop.last_state_wall``) to the command, on its own clock."""


class Result:
    """
    What to publish for one answered state (one object per loop, refilled per answer).

    Attributes
    ----------
    stamp_ns : int
        Stamp [ns] of the state answered (-1: none answered yet).
    effort : list of float, (r,)
        The command [N m] in the order of parameter ``joints``.
    error, error_rate, sliding, position, position_desired : sequence of float, (m,)
        ControllerState's task-space terms [m, m/s] (m: the task dimension); ``error``
        against the controller's reference ``position_desired``.
    position_planned : sequence of float, (m,) or (0,)
        The plan's setpoint for the state, as streamed (before hold, blend or carrying
        forward) [m]; empty without one (ControllerState's ``position_planned``).
    det_dd, state_age, setpoint_age, dt : float
        As ControllerState's fields.
    status : int
        Status bits; ``message`` says why when not 0.
    setpoint_ns : int or None
        Stamp of the setpoint used (None: none).
    law_state_names : tuple of str
        Names of the law's internal state (``ControlLaw.state_names``).
    law_state_values : list of float
        Its values after this answer (ControllerState's ``law_state``).
    repeated : bool
        The state's stamp was answered before: the same answer again.
    latency_ns : int, RECEIPT or None
        The latency of the answer [ns] for the diagnostics: real time from the state's
        stamp; lockstep :data:`RECEIPT` (from its receipt, measured by the node); None for
        a zero-effort answer (not counted).

    """

    __slots__ = ('stamp_ns', 'effort', 'error', 'error_rate', 'sliding', 'det_dd',
                 'position', 'position_desired', 'position_planned', 'status',
                 'message', 'setpoint_ns', 'setpoint_age', 'dt', 'state_age',
                 'law_state_names', 'law_state_values', 'repeated', 'latency_ns')

    def __init__(self, m=2):
        zero = (0.0,) * m
        self.stamp_ns = -1
        self.effort = []
        self.error = self.error_rate = self.sliding = zero
        self.position = self.position_desired = zero
        self.position_planned = ()
        self.det_dd = self.state_age = self.setpoint_age = self.dt = 0.0
        self.status = 0
        self.message = ''
        self.setpoint_ns = None
        self.law_state_names = ()
        self.law_state_values = []
        self.repeated = False
        self.latency_ns = 0


class PeriodFigures:
    """
    What a status period reports beyond the counters: bits, errors against plan and reference.

    Attributes
    ----------
    bits : int
        Status bits of the answers of the period.
    plan_error_max : float
        Largest ``|position - position_planned|`` of the period [m].
    plan_error_last : float or None
        That of the last answer [m] (None: it had no plan).
    ref_error_max : float
        Largest ``|error|`` (against the controller's reference) of the period [m].

    """

    __slots__ = ('bits', 'plan_error_max', 'plan_error_last', 'ref_error_max')

    def __init__(self):
        self.bits = 0
        self.plan_error_max = 0.0
        self.plan_error_last = None
        self.ref_error_max = 0.0

    def track(self, position, planned, error):
        """
        Note a computed answer's errors; return ``|error|`` [m].

        ``position``, ``planned`` (empty: no plan) and ``error`` (against the controller's
        reference) as the Result's ``position``, ``position_planned`` and ``error``.
        """
        if planned:
            plan_error = math.dist(position, planned)
            self.plan_error_last = plan_error
            if plan_error > self.plan_error_max:
                self.plan_error_max = plan_error
        else:
            self.plan_error_last = None
        ref_error = math.hypot(*error)
        if ref_error > self.ref_error_max:
            self.ref_error_max = ref_error
        return ref_error

    def take(self):
        """Return ``(bits, plan_error_max, ref_error_max)`` of the period ending; start anew."""
        out = self.bits, self.plan_error_max, self.ref_error_max
        self.bits = 0
        self.plan_error_max = self.ref_error_max = 0.0
        return out


def diagnostics(loop, elapsed, start, silent, latency, states_topic, activated_at):
    """
    Return (errors, warnings, ok message, key/values) of the status period now ending.

    Parameters
    ----------
    loop : freejoint_control.loop.ControlLoop
        The loop (its counters, readiness guard, failures and last Result).
    elapsed : float
        Length of the period [s].
    start : tuple
        ``loop.counters()`` at its start.
    silent : bool
        No state came in the period.
    latency : (str, str)
        Mean and maximum latency [ms] of the period, as text.
    states_topic : str
        The joint-states topic's resolved name (for the text).
    activated_at : float or None
        System time [s] of the activation from standby.

    """
    answers0, faults0, refused_states0, refused_sp0, old0 = start
    answers = loop.ticks + loop.zero_answers + loop.stops - answers0
    faults = loop.faults - faults0
    refused_states = loop.refused_states - refused_states0
    refused_sp = loop.refused_setpoints - refused_sp0
    old = loop.old_states - old0
    figures = loop.figures
    bits, plan_max, ref_max = figures.take()
    res = loop.result
    current = res.status
    period = 'in the last %.1f s' % elapsed
    errors = []
    warnings = []
    no_state = None
    if loop.last_state_wall is None:
        no_state = 'no joint_states yet on %s' % states_topic
    elif loop.stale_reported:
        no_state = 'no joint_states for %g s: %s' % (
            loop.stale_timeout, 'zero effort commanded' if loop.lockstep else
            'the stop command sent (gravity hold), the brakes asked for')
    elif silent:
        no_state = 'no joint_states %s' % period
    if no_state is not None:
        if loop.lockstep:
            warnings.append(no_state + ' (lockstep: simulation time stands still)')
        else:
            errors.append(no_state)
    guard = loop.watch.guard
    if guard is not None and not guard.ready:
        errors.append('%s: %s' % (guard.reason, 'stopped (stop command, brakes asked '
                                  'for); %d states not answered' % loop.withheld
                                  if loop.watch.brakes else 'holding position'))
    if faults:
        errors.append('%d law faults %s: the previous command repeated, theta_hat '
                      'restored' % (faults, period))
    if current & STATUS_HOLDING or (current & STATUS_STALE_SETPOINT
                                    and not loop.hold_on_stale):
        warnings.append(res.message)
    elif bits & STATUS_HOLDING:
        warnings.append('held %s' % period)
    for bit, text in ((STATUS_RATE_LIMITED, 'torque change rate limited'),
                      (STATUS_TORQUE_LIMITED, 'torque limited'),
                      (STATUS_SETPOINT_LATE, 'setpoint stream late (carried forward)'),
                      (STATUS_DT_CLAMPED, 'state stamps irregular: dt clamped')):
        if bits & bit:
            warnings.append('%s %s' % (text, period))
    for count, what in ((refused_states, 'states refused'),
                        (refused_sp, 'setpoints refused'),
                        (old, 'states skipped as too old')):
        if count:
            warnings.append('%d %s %s' % (count, what, period))
    if loop.pending is not None:
        ok = ('waiting for the setpoint of the state stamped %d ns (lockstep)'
              % loop.pending[0])
    else:
        ok = res.message or 'tracking'
    if loop.failures is not None:
        extra = loop.failures.diagnostics(errors, warnings)
    else:
        extra = ()
    values = (
        ('mode', 'lockstep' if loop.lockstep else 'realtime'),
        ('activated from standby', 'no' if activated_at is None
         else 'at %.3f (system time)' % activated_at),
        ('answer rate [Hz]', '%.1f' % (answers / elapsed if elapsed > 0.0 else 0.0)),
        ('latency mean [ms]', latency[0]),
        ('latency max [ms]', latency[1]),
        ('status', current),
        ('status message', res.message),
        ('error vs plan [mm]', '-' if figures.plan_error_last is None
         else '%.4g' % (figures.plan_error_last * 1e3)),
        ('error vs plan max [mm]', '%.4g' % (plan_max * 1e3)),
        ('error vs controller reference max [mm]', '%.4g' % (ref_max * 1e3)),
        ('ticks', loop.ticks),
        ('zero-effort answers', loop.zero_answers),
        ('holds', loop.holds),
        ('stale setpoint periods', loop.stale_periods),
        ('refused states', loop.refused_states),
        ('refused setpoints', loop.refused_setpoints),
        ('law faults', loop.faults),
        ('old states skipped', loop.old_states)) + extra
    if guard is not None:
        values += (
            ('readiness', 'ready' if guard.ready else 'not ready'),
            ('readiness trips', guard.trips),
            ('tolerated delay [ms]', '%.3g' % (guard.max_delay * 1e3)),
            ('window mean delay [ms]', '-' if guard.last_delay is None
             else '%.3g' % (guard.last_delay * 1e3)),
            ('window answered [%]', '-' if guard.last_rate is None
             else '%.0f' % (guard.last_rate * 100.0)),
            ('states not answered (stopped)', loop.withheld),
            ('stop commands', loop.stops),
            ('brake requests', loop.brake_requests))
    return errors, warnings, ok, values


def report(loop):
    """One line for the end of the run: ticks, zero-effort answers, holds, refusals."""
    return ('controller stopped: %d ticks computed, %d zero-effort answers (stale or bad '
            'input), %d holds, %d states and %d setpoints refused, %d law faults, %d '
            'states skipped as too old%s'
            % (loop.ticks, loop.zero_answers, loop.holds, loop.refused_states,
               loop.refused_setpoints, loop.faults, loop.old_states,
               '' if loop.watch.guard is None else
               ', readiness guard: %d trips, %d stop commands, %d states not answered, %d '
               'brake requests' % (loop.watch.guard.trips, loop.stops, loop.withheld,
                                   loop.brake_requests)))


def status_message(status, det, cfg, hold_reason, shaper):
    """Return the ControllerState message of a computed answer's status bits."""
    parts = []
    if status & STATUS_HOLDING:
        hold = shaper.hold_position
        parts.append('%s (%s) m: %s' % ('stopping along the path to' if shaper.stopping
                                        else 'holding at',
                                        ', '.join('%.4f' % x for x in hold), hold_reason))
    if status & STATUS_RESUMING:
        parts.append('resuming: blending from the hold to the setpoint over %.3g s'
                     % shaper.blend_duration)
    if status & STATUS_NEAR_SINGULAR:
        parts.append('near singular: |det(Da Da^T)| = %.3g < %.3g, damped pseudo-inverse'
                     % (det, cfg.gains.det_threshold))
    if status & STATUS_TORQUE_LIMITED:
        parts.append('torque limited to %s N m' % list(cfg.effort_limits))
    if status & STATUS_RATE_LIMITED:
        parts.append('torque change limited to %g N m/s' % cfg.effort_rate_limit)
    if status & STATUS_LAW_FAULT:
        parts.append('law fault: non-finite or out-of-range output, previous command repeated')
    if status & STATUS_SETPOINT_LATE and not status & STATUS_HOLDING:
        parts.append('setpoint late: the newest is older than %d control periods, carried '
                     'forward along its velocity and acceleration' % cfg.late_periods)
    if status & STATUS_DT_CLAMPED:
        parts.append('state stamps outside [0.25, 4] x control_period: dt clamped')
    return '; '.join(parts)
