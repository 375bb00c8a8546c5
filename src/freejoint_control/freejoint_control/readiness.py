"""
The real-time readiness guard: the loop within the delay its law tolerates, or not.

In real time the command computed from the state stamped ``t_k`` acts from the simulator's
(or driver's) first step after it is sent: over ``[t_{k+M}, t_{k+M+1}]`` with
``M = floor(age / control_period) + 1`` periods, ``age`` the state's age when the loop
takes it (system time minus stamp).  The paper's law tolerates a bounded ``M``
(docs/delay.md: the vertical case diverges at a fixed 3 ms, the horizontal at 15 ms), and
each state the loop does not answer holds the previous command one period longer.
:class:`ReadinessGuard` measures both over consecutive windows of state-stamp time:

- the mean effective delay ``mean(M) * control_period`` of the states taken in the window,
  against the tolerated delay (parameter ``readiness_max_delay``; 0 = the measured margin
  of the running case, :func:`tolerated_delay`);
- the answer rate: states taken / states expected (the window's stamp span over the
  control period), against ``readiness_min_answer_rate``.

A loop starts not ready (the driver's brakes, engaged at start, stay on) until
``readiness_recover_windows`` good windows; a hot spare starts ready (it must take over at
once).  One bad window makes the loop not ready: it stops tracking (the loop withholds its
commands, so the driver's watchdog brakes, or holds: parameter ``readiness_action``); a
window that has already missed more states than the answer rate allows (a stall of the
loop) does so at once, not at its end.  ``readiness_recover_windows`` consecutive good
windows make it ready again, good meaning within half the margins: a mean delay at most
halfway from one period to the tolerated one, at most a quarter of the states a window may
miss missed (hysteresis: a marginal loop does not release the brakes).  Lockstep
never trips (the simulator waits for each command: no delay).  It reads no clock: the
caller passes the stamps and the system time, so a test drives it deterministically.

"""

from freejoint_core.errors import FreejointValueError

MEASURED_MARGIN = {
    # (case, delay_compensation) -> largest fixed delay [s] at which all 10 seeds of the
    # delay study tracked (docs/delay.md, "Delay margin"; 70 % nominal, disturbance on).
    ('horizontal', 'off'): 0.010,
    ('horizontal', 'predict'): 0.020,
    ('vertical', 'off'): 0.002,
    ('vertical', 'predict'): 0.010,
}
"""The law's measured delay margin [s] per case and delay compensation (docs/delay.md)."""


def tolerated_delay(case, delay_compensation, given=0.0):
    """
    Return the delay [s] the loop may keep on average: ``given`` if > 0, else the margin.

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        The nominal model's case (controller parameter ``case``).
    delay_compensation : {'off', 'predict'}
        The controller's parameter of that name.
    given : float
        ``readiness_max_delay`` [s]; 0 = the measured margin (:data:`MEASURED_MARGIN`).

    Returns
    -------
    float
        Seconds (> 0).

    """
    if given > 0.0:
        return float(given)
    try:
        return MEASURED_MARGIN[(case, delay_compensation)]
    except KeyError:
        raise FreejointValueError(
            'case / delay_compensation: no measured delay margin for %r with %r (known: %s); '
            'set readiness_max_delay' % (case, delay_compensation,
                                         sorted(MEASURED_MARGIN))) from None


def effective_periods(age_ns, dt_ns):
    """
    Return the periods M after which a command from a state ``age_ns`` old acts (>= 1).

    ``floor(age / dt) + 1``: answered within its own period it acts from the next step
    (the delay study's M = 1); a negative age (clocks apart) counts as 1.
    """
    if age_ns <= 0:
        return 1
    return age_ns // dt_ns + 1


class ReadinessGuard:
    """
    Windows of state-stamp time judged against the tolerated delay and answer rate.

    Parameters
    ----------
    dt_ns : int
        Control period [ns] (> 0).
    max_delay : float
        Tolerated mean effective delay [s] (> 0, :func:`tolerated_delay`).
    min_rate : float
        Least fraction of the expected states taken per window, in (0, 1].
    window : float
        Window length [s of state stamps] (at least 2 periods).
    recover_windows : int
        Consecutive good windows that make a not-ready loop ready again (>= 1).
    start_ready : bool
        Ready before any window was judged (a hot spare); else not ready until
        ``recover_windows`` good windows.

    Attributes
    ----------
    ready : bool
        The loop keeps within the bounds.
    started : bool
        It was ready at least once.
    reason : str
        Why it is not ready ('' when ready): the bad window's figures and the bound.
    good_delay, good_rate : float
        What a window must keep to count towards readiness [s, fraction]: half the margins.
    trips, recoveries : int
        Transitions to not ready and back.
    last_rate, last_delay : float or None
        The last judged window's answer rate and mean effective delay [s].

    """

    def __init__(self, dt_ns, max_delay, min_rate, window, recover_windows,
                 start_ready=False):
        if not (isinstance(dt_ns, int) and dt_ns > 0):
            raise FreejointValueError('dt_ns: expected an int > 0, got %r' % (dt_ns,))
        if not max_delay > 0.0:
            raise FreejointValueError('max_delay: expected > 0 s, got %r' % (max_delay,))
        if not 0.0 < min_rate <= 1.0:
            raise FreejointValueError('min_rate: expected in (0, 1], got %r' % (min_rate,))
        if not window >= 2 * dt_ns * 1e-9:
            raise FreejointValueError('window: expected >= 2 control periods (%g s), got %r'
                                      % (2 * dt_ns * 1e-9, window))
        if not (isinstance(recover_windows, int) and recover_windows >= 1):
            raise FreejointValueError('recover_windows: expected an int >= 1, got %r'
                                      % (recover_windows,))
        self.dt_ns = dt_ns
        self.max_delay = float(max_delay)
        self.min_rate = float(min_rate)
        self.window_ns = round(window * 1e9)
        # A good window (one of those that make a not-ready loop ready): half the margins.
        self.good_delay = 0.5 * (dt_ns * 1e-9 + self.max_delay)
        self.good_rate = 1.0 - 0.25 * (1.0 - self.min_rate)
        # States a window may miss: more, and it is bad whatever follows.
        self._may_miss = int((1.0 - self.min_rate) * (self.window_ns // dt_ns) + 1e-9)
        self.recover_windows = recover_windows
        self.ready = self.started = bool(start_ready)
        self.reason = '' if start_ready else (
            'real-time loop not judged yet: waiting for %d good windows of %.3g s'
            % (recover_windows, window))
        self.trips = 0
        self.recoveries = 0
        self.last_rate = None
        self.last_delay = None
        self._start_ns = None       # stamp opening the current window
        self._count = 0             # states taken in it
        self._periods = 0           # sum of their effective periods
        self._good = 0              # consecutive good windows while not ready

    def restart(self):
        """Forget the current window (time went back); keep ready / not ready."""
        self._start_ns = None
        self._count = 0
        self._periods = 0

    def observe(self, ns, now_ns):
        """
        Take a state stamped ``ns`` received at system time ``now_ns``; judge ended windows.

        Returns
        -------
        int
            0: no change; 1: it just became not ready (``reason`` says why); 2: it just
            became ready (``recoveries`` counts the times after the first).

        """
        start = self._start_ns
        if start is None or ns < start:
            self._start_ns = ns
            self._count = 1
            self._periods = effective_periods(now_ns - ns, self.dt_ns)
            return 0
        change = 0
        span = ns - start
        if span >= self.window_ns:
            change = self._judge(span)
            self._start_ns = ns
            self._count = 0
            self._periods = 0
        self._count += 1
        self._periods += effective_periods(now_ns - ns, self.dt_ns)
        if change == 0 and self.ready:
            expected = (ns - self._start_ns) // self.dt_ns + 1
            if expected - self._count > self._may_miss:
                return self._not_ready(
                    'real-time loop not ready: %d of %d states answered so far, more than the '
                    '%d a %.3g s window may miss (answer rate %.0f %%)' % (
                        self._count, expected, self._may_miss, self.window_ns * 1e-9,
                        self.min_rate * 100.0))
        return change

    def trip(self, reason):
        """
        Make the loop not ready for ``reason`` (a check outside the windows failed).

        As a bad window: the recovery count restarts. Returns 1 if it just became not
        ready, else 0 (as :meth:`observe`).
        """
        return self._not_ready(reason)

    def _not_ready(self, reason):
        """Note a bad window; return 1 if the loop just became not ready, else 0."""
        self._good = 0
        self.reason = reason
        if self.ready:
            self.ready = False
            self.trips += 1
            return 1
        return 0

    def _judge(self, span):
        """Judge the window of ``span`` ns that just ended; return the change (observe)."""
        dt_ns = self.dt_ns
        expected = span // dt_ns
        rate = self._count / expected
        delay = self._periods * dt_ns * 1e-9 / self._count
        self.last_rate = rate
        self.last_delay = delay
        bad = []
        if delay > self.max_delay:
            bad.append('mean state->command delay %.3g ms > the %.3g ms the law tolerates'
                       % (delay * 1e3, self.max_delay * 1e3))
        if rate < self.min_rate:
            bad.append('%d of %d states answered (%.0f %% < %.0f %%)'
                       % (self._count, expected, rate * 100.0, self.min_rate * 100.0))
        if bad:
            return self._not_ready('real-time loop not ready: %s over %.3g s'
                                   % ('; '.join(bad), span * 1e-9))
        if self.ready:
            return 0
        if delay > self.good_delay or rate < self.good_rate:
            # Not bad, not good enough to start again (hysteresis): the count restarts.
            self._good = 0
            self.reason = ('real-time loop not ready: waiting for %d good windows (mean '
                           'delay <= %.3g ms, >= %.0f %% of the states answered), the last '
                           '%.3g ms, %.0f %%' % (self.recover_windows, self.good_delay * 1e3,
                                                 self.good_rate * 100.0, delay * 1e3,
                                                 rate * 100.0))
            return 0
        self._good += 1
        if self._good >= self.recover_windows:
            self.ready = True
            self.reason = ''
            if self.started:
                self.recoveries += 1
            self.started = True
            return 2
        return 0
