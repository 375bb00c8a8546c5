"""
The controller's loop without ROS: what the controller node decides, as plain Python.

:class:`ControlLoop` takes the samples the node converts from its messages - a joint state
(stamp [ns], names, positions, velocities), a setpoint (stamp [ns], its ``3 m`` values:
position, velocity, acceleration, m the task dimension of the law's model) - and the
clock values the node reads (system time ``now_ns`` [ns], monotonic time ``mono`` [s]);
it reads no clock itself, so a test drives it deterministically.  Per input it returns
the :class:`Result` to publish (the command and the ControllerState's fields as plain
values) or None when nothing is to be published yet.  It owns:

- the joint-name mapping (any order, extra joints ignored) and the state guards (missing
  joint, short arrays, non-finite or implausible values: zero effort, STATUS_BAD_INPUT);
- the pairing of states with setpoints: lockstep by equal stamps (a state waits for its
  setpoint; :meth:`ControlLoop.watchdog` holds it after ``stale_timeout``), real time the
  newest fresh setpoint, carried forward along its velocity and acceleration while late;
- hold / resume (``ReferenceShaper``), the law (``freejoint_core.laws``, parameter ``law``)
  and its faults (law state restored, previous command repeated), the torque and rate
  limits, dt from the stamps, old states skipped, repeated stamps answered alike, time
  going back, ``delay_compensation: predict``, :meth:`ControlLoop.reset`;
- the hot spare's readiness (:meth:`ControlLoop.standby_waits_for`, from the numbers of
  matched and listed endpoints the node passes in), the status message, the counters and
  the content of the ``/diagnostics`` status (:meth:`ControlLoop.diagnostics`);
- real time, the readiness guard (``freejoint_control.readiness``, parameters
  ``readiness_*``): while the loop cannot keep within the delay its law tolerates or
  misses states, a stop (one stop command, the brakes asked for, then no command) or a
  hold, saying why; its judgement for the ``controller_readiness`` topic
  (:meth:`ControlLoop.take_readiness`);
- the stop command (:meth:`ControlLoop.stop_effort`): what a driver is left with whenever
  the controller stops answering or cannot compute (a guard trip, stale or bad state in
  real time): the active joints' static gravity load at the measured angles
  (``freejoint_core.guards.hold_effort``), never a stale tracking command.

Each job is a part it composes: ``loop_inputs.StateReader`` (the state's mapping and
checks), ``loop_setpoints.SetpointStream`` (the setpoints' checks and pairing),
``loop_reference.Reference`` (hold, blend, carrying forward), ``loop_law.LawStep`` (the
law's step and its faults), ``loop_stop`` (the readiness guard, the driver's requests, the
stop command) and ``loop_status`` (the Result, its message, the status period's report);
the loop decides between them which answer a state gets.

Logging goes through the ``log(level, kind, text)`` callable given (``kind`` names a
throttled kind of line, None: always); status bits are ControllerState's.

"""

import math

from freejoint_common.arm_description import resolve_arm
from freejoint_common.schema import nullspace_options
from freejoint_control import failures, loop_status
from freejoint_control.loop_inputs import StateReader
from freejoint_control.loop_law import LawStep
from freejoint_control.loop_reference import Reference
from freejoint_control.loop_setpoints import SetpointStream
# The published state's names, imported from here by the node and the tests too.
from freejoint_control.loop_status import (  # noqa: F401
    DEBUG, ERROR, INFO, PeriodFigures, RECEIPT, Result, STATUS_DT_CLAMPED, STATUS_HOLDING,
    STATUS_LAW_FAULT, status_message, STATUS_RATE_LIMITED, STATUS_RESUMING,
    STATUS_SETPOINT_LATE, STATUS_STOPPED, WARN)
from freejoint_control.loop_stop import (DAMP_SAID, DriverRequests, HOLD_ERROR_SAID,
                                         HOLD_GAP_SAID, QUIET_SAID, Readiness, REJOIN_SAID,
                                         stop_effort, STOP_SAID)
from freejoint_control.readiness import guard_margins
from freejoint_core.control import STATUS_BAD_INPUT, STATUS_STALE_SETPOINT, STATUS_STALE_STATE
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import clamp_dt, limit_effort
from freejoint_core.laws import make_law
from freejoint_core.reference import MODE_BLEND, MODE_HOLD
import numpy as np

STANDBY_SETTLE = 0.5
"""[s] A spare is ready once nothing was lacking for this long (its discovery of the graph,
which can list the simulator before the planner, settled)."""
_SAY_PERIOD_NS = round(1e9)
"""[ns of stamps] At most one 'not ready' line per this period (a transition at once)."""


def _no_log(level, kind, text):
    """Drop a log line (the default of ``log``)."""


def _part(part, name, doc):
    """Return a read-only property: the attribute ``name`` of the loop's part ``part``."""
    return property(lambda loop: getattr(getattr(loop, part), name), doc=doc)


def config_law(cfg):
    """
    Return the law a controller configuration names, with its null-space terms.

    ``make_law`` of ``cfg.law`` on the nominal model, the gains, the laws' own gains, the
    null-space options (``nullspace_kd``, ``nullspace_kd_joints``, ``nullspace_kp``) and,
    with ``free_link_damping``, the free link's damping around it: the law the loop steps
    and the one an offline twin of the graph must run.

    Parameters
    ----------
    cfg : freejoint_control.params.Config
        The controller's configuration (``law``, ``nominal``, ``gains``, the null space).

    Returns
    -------
    freejoint_core.laws.ControlLaw

    """
    values = cfg.values
    free_link = None
    if values['free_link_damping']:     # the reference damps the free link
        free_link = {'delta_max': values['free_link_delta_max'],
                     'k2_rest': values['free_link_rest_damping'],
                     'rest_after': values['free_link_rest_after'],
                     'mode': values['free_link_mode'],
                     'settle_window': values['free_link_settle_window'],
                     'sat': values['free_link_drive_max']}
    law = make_law(cfg.law, cfg.nominal, cfg.gains, model=cfg.nominal_model,
                   params=cfg.law_params, free_link=free_link, **nullspace_options(values))
    if not cfg.lockstep and hasattr(law, 'set_nullspace_delay'):
        law.set_nullspace_delay(nullspace_delay_periods(cfg), cfg.dt)
    return law


def nullspace_delay_periods(cfg):
    """
    Return the control periods of delay a real-time loop's null-space damping must stand.

    The readiness guard's trip delay (``readiness_max_delay``, else the arm's measured or
    the strictest one: ``freejoint_control.readiness.guard_margins``) in whole periods, at
    least 1 (a command acts from the period after its state's); 1 without the guard.
    """
    if not cfg.readiness_guard:
        return 1
    max_delay = guard_margins(resolve_arm(cfg.values).params, cfg.delay_compensation,
                              cfg.readiness_max_delay, epsilon=cfg.gains.epsilon)[0]
    return max(1, math.ceil(max_delay / cfg.dt - 1e-9))


class ControlLoop:
    """
    The controller's decisions between samples and commands (module docstring).

    Parameters
    ----------
    config : freejoint_control.params.Config
        The validated configuration (its fields and ``config.<parameter>``).
    log : callable, optional
        ``log(level, kind, text)``; default: drop.

    """

    def __init__(self, config, log=None):
        cfg = config
        self.log = log or _no_log
        self.law = config_law(cfg)
        # Joint failures (freejoint_control/failures.py): None when off.
        self.failures = None if cfg.values['joint_failures'] == 'off' else \
            failures.FailureMonitor(cfg, self.law, self.log)
        self.inputs = StateReader()
        self.setpoints = SetpointStream()
        m = self.task_dim = self.law.model.task_dim
        self.reference = Reference(cfg.resume_time, cfg.lockstep, m)
        self.shaper = self.reference.shaper
        self.stepper = LawStep(self.law, self.log)
        self._zero_task = (0.0,) * m
        self.watch = Readiness(self.log)
        self.requests = DriverRequests()
        self._guard_ns = None           # stamp of the last state the guard took
        self._withholding = False       # not ready, 'brake': no command sent
        self._said_ns = None            # stamp of the last 'not ready' line
        self.withheld = 0               # states not answered by the readiness guard
        self._kept_hold = None          # the hold's position when the guard stopped it
        self._commanded = False         # the last answer sent was a computed command
        self._ever_commanded = False    # a computed command was sent (or taken over)
        self._q_stop = None             # 'damp': the active joints' angles the stop found
        # 'hold': the gap [states] after which this not-ready spell gave way to the damped
        # joint hold (None: it did not)
        self._hold_gap = None
        self._gap_tripped = False       # that gap tripped the guard: its line said so
        # 'hold': the law's error [m] past its bound (readiness_max_error) after which this
        # not-ready spell gave way to the damped joint hold (None: it did not)
        self._hold_error = None
        # 'hold': this not-ready spell began with a following-error trip (the loop on time):
        # its hold at hold_stiffness, else at readiness_hold_stiffness
        self._error_spell = False
        self._damped = False            # this stop answered with the damped joint hold
        self._rejoin_ns = 0             # the state at which the loop, ready again, re-joins
        self.stops = 0                  # stop commands sent
        self._install(cfg)
        self.result = Result(m)
        self.result.law_state_names = tuple(self.law.state_names)
        self._zero = [0.0] * len(cfg.joints)
        self.last_ns = -1               # stamp of the last answered state
        self.pending = None             # lockstep: (ns, q, qd, since) waiting for a setpoint
        self._last_sp = self._zero_task
        self.last_state_wall = None     # monotonic time of the last state received
        self.stale_reported = False
        self._last_q = None
        self.ticks = 0
        self.zero_answers = 0
        self.holds = 0
        self.refused_setpoints = 0
        self.refused_states = 0
        self.old_states = 0
        self.stale_periods = 0          # onsets of a stale (or late) setpoint stream
        self._stale_now = False
        self.figures = PeriodFigures()  # what the status period reports beyond the counters
        # Last command sent, in command order (None: none yet in lockstep, whose start is
        # the paper's; real time starts from the zero effort the arm had).
        self._prev_cmd = None if cfg.lockstep else list(self._zero)
        self._rate_armed = not cfg.lockstep
        # Hot spare (real time): not answering until activate().
        self.standby = cfg.standby
        self._start_from_motion = False
        self.waiting_for = 'start-up'   # standby: what it waits for before it is ready
        self._settled_since = None      # standby: since when nothing was lacking

    # -- configuration -----------------------------------------------------------------
    def _install(self, cfg):
        """Cache what the tick needs from a validated configuration."""
        self.config = cfg
        self._dt = cfg.dt
        self._carry_ns = round(cfg.carry_forward_time * 1e9)
        self._max_age_ns = 0 if cfg.lockstep else round(cfg.max_state_age * 1e9)
        self.stale_timeout = cfg.stale_timeout
        self.lockstep = cfg.lockstep
        self._limits = cfg.effort_limits
        self._rate = cfg.effort_rate_limit
        self.hold_on_stale = cfg.on_stale_setpoint == 'hold'
        self.reference.configure(cfg)
        self.setpoints.configure(self.task_dim, (cfg.reach, cfg.setpoint_max_velocity,
                                                 cfg.setpoint_max_acceleration),
                                 cfg.dt_ns // 2, cfg.stale_timeout, self._carry_ns)
        self.inputs.configure(cfg.joint_names, cfg.position_lower, cfg.position_upper,
                              cfg.velocity_limit, cfg.joint_offsets)
        self.stepper.configure(cfg)
        self._stop_hold_time = cfg.stop_hold_time
        self.requests.configure(cfg.readiness_brake_request and not cfg.lockstep,
                                cfg.hold_brake_timeout)
        if self.watch.install(cfg):
            self._withholding = False
            self._hold_gap = self._hold_error = None

    def apply(self, old, cfg):
        """Take a validated parameter change (effective on the next state)."""
        law = self.law
        fm = self.failures
        renew = fm is not None and (cfg.nominal != old.nominal or cfg.gains != old.gains)
        if renew:
            fm.release()        # the law back on the configured arm, then the change
        if cfg.nominal != old.nominal:
            law.set_nominal(cfg.nominal, cfg.nominal_model)
        if cfg.gains != old.gains:
            law.set_gains(cfg.gains)
            if cfg.gains.theta0 != old.gains.theta0:
                law.reset()
            self.stepper.keep_state()
        if renew:
            self.failures = fm.renewed(cfg)
        if not cfg.lockstep and hasattr(law, 'set_nullspace_delay'):
            # the guard's trip delay changed: the null-space damping capped anew (next step)
            law.set_nullspace_delay(nullspace_delay_periods(cfg), cfg.dt)
        self._install(cfg)

    def reset(self):
        """Restart the law's state (theta_hat = theta0) and forget the hold / blend."""
        self.law.reset()
        self.stepper.keep_state()
        self.shaper.reset()
        self._kept_hold = None
        self._rate_armed = self._prev_cmd is not None
        self.stepper.restart_prediction()

    # -- standby -----------------------------------------------------------------------
    def activate(self):
        """Leave standby: answer from now on, the reference starting from the motion."""
        self.standby = False
        self._start_from_motion = True
        self._commanded = self._ever_commanded = True   # the dead controller's command

    def standby_waits_for(self, cmd_matched, cmd_listed, sp_matched, sp_listed, mono, now_ns,
                          names=('commands', 'setpoints')):
        """
        Return what a spare still lacks to take over at once ('' : nothing).

        Its commands matched by every subscriber the graph lists (at least one: the
        simulator or driver); every setpoint publisher the graph lists matched and, with
        one, the stream caught up: the newest setpoint received within the carry-forward
        time of now, or none for STANDBY_IDLE_STREAM s (a planner not streaming).

        Parameters
        ----------
        cmd_matched, cmd_listed : int
            Subscribers of the commands matched by its publisher / listed by the graph.
        sp_matched, sp_listed : int
            Setpoint publishers matched by its subscription / listed by the graph.
        mono : float
            Monotonic time [s].
        now_ns : int
            System time [ns].
        names : (str, str)
            The topics' names for the text.

        """
        if cmd_matched == 0 or cmd_matched < cmd_listed:
            return '%s matched by %d of its %d subscribers' % (
                names[0], cmd_matched, cmd_listed)
        return self.setpoints.spare_waits_for(sp_matched, sp_listed, mono, now_ns, names[1])

    def standby_settled(self, waits_for, mono):
        """
        Note what a spare lacks now; return True once nothing was lacking STANDBY_SETTLE s.

        ``waiting_for`` then is '' (the node tells the supervisor it is ready, once).
        """
        if waits_for:
            self.waiting_for = waits_for
            self._settled_since = None
            return False
        if self._settled_since is None:
            self._settled_since = mono
        if mono - self._settled_since < STANDBY_SETTLE:
            self.waiting_for = 'the graph settling'
            return False
        self.waiting_for = ''
        return True

    # -- inputs ------------------------------------------------------------------------
    def on_state(self, ns, names, pos, vel, now_ns, mono, effort=None):
        """
        Take a joint state; return the Result to publish, or None (none yet).

        Parameters
        ----------
        ns : int
            Its stamp [ns].
        names : sequence of str
            Joint names (any order, extra joints ignored).
        pos, vel : sequence of float
            Positions [rad] and velocities [rad/s] in the order of ``names``.
        now_ns : int
            System time [ns] (only read in real time: state ages).
        mono : float
            Monotonic time [s] (its receipt).
        effort : sequence of float, optional
            Efforts in the order of ``names`` (read only by the failure monitor).

        """
        self.last_state_wall = mono
        self.inputs.note_effort(effort)
        self.stale_reported = False
        watch = self.watch
        guard = watch.guard
        if guard is not None:
            change = 0
            if ns != self._guard_ns:
                self._guard_ns = ns
                change = guard.observe(ns, now_ns)
                if change:
                    watch.changed(change, ns)
                    self._said_ns = ns
                    self._error_spell = False
                if (not guard.ready and guard.started and self._hold_gap is None
                        and self._hold_error is None and watch.gives_way(guard)):
                    # 'hold': a gap longer than readiness_hold_max_gap, the law's last
                    # command kept by the driver all along (even if this state is skipped
                    # as old).
                    self._hold_gap = guard.last_missed
                    self._gap_tripped = change == 1
        if watch.stale_reason:
            watch.stale_reason = ''
            if guard is None or guard.ready:
                watch.note = (ns, True, '')
        if guard is not None:
            if not guard.ready and watch.brakes:
                return self._withhold(ns, now_ns)
            if self._withholding and guard.ready:
                self._resume_after_brake(ns)
            elif guard.ready:
                # (ready again before a state was answered)
                self._hold_gap = self._hold_error = None
        if self._max_age_ns:
            age_ns = now_ns - ns
            if age_ns > self._max_age_ns:
                self.old_states += 1
                self.log(WARN, 'old_state',
                         'state stamped %d ns is %.3f s old (> max_state_age %g s): '
                         'skipped, no command from it' % (
                             ns, age_ns * 1e-9, self.config.max_state_age))
                return None
        if ns == self.last_ns:
            # A repeated state (the sim's start-up republication): same answer, no new update.
            res = self.result
            res.repeated = True
            return res
        if ns < self.last_ns:
            self.log(WARN, None,
                     'state time went back from %d to %d ns (simulator restarted?): theta_hat '
                     'reset to theta0' % (self.last_ns, ns))
            self.reset()
            self.setpoints.clear()
        q, qd, kind, reason = self.inputs.read(names, pos, vel)
        if q is None:
            self.refused_states += 1
            if not self.lockstep and not self._ever_commanded:
                # Nothing computed was ever sent (the start): nothing to replace, and any
                # command would release the driver's start-up brakes.
                self.log(ERROR, kind, 'state refused: %s; no command, theta_hat kept' % reason)
                return None
            if self.lockstep:
                self.log(ERROR, kind, 'state refused: %s; zero effort, theta_hat kept' % reason)
                return self._answer_zero(ns, STATUS_BAD_INPUT, 'bad input: ' + reason, now_ns)
            self.log(ERROR, kind, 'state refused: %s; the stop command (gravity hold at the '
                     'last good state), theta_hat kept' % reason)
            return self._answer_stop(ns, STATUS_BAD_INPUT, 'bad input: %s: the stop command '
                                     '(gravity hold at the last good state)' % reason, now_ns)
        self._last_q = q
        if self._start_from_motion:
            self._start_from_motion = False
            self._start_from(q, qd)
        if self.lockstep:
            sp = self.setpoints.take(ns)
            if sp is None:
                if self.shaper.mode == MODE_HOLD and self.setpoints.seen:
                    # Already holding on a stale stream: answer at once, not a timeout per tick.
                    self.pending = None
                    return self._no_setpoint(ns, q, qd, now_ns)
                self.pending = (ns, q, qd, mono)
                return None
            self.pending = None
            return self._tick(ns, q, qd, ns, sp, now_ns)
        if guard is not None and not guard.ready:
            self.requests.ask_drive_wait(True)
            if watch.damps:
                if not guard.started:
                    return self._withhold(ns, now_ns)   # never started: the brakes stay on
                return self._damped_stop(ns, q, qd, now_ns)
            if self._hold_gap is not None or self._hold_error is not None:
                # A gap past readiness_hold_max_gap (the law's last command was kept all
                # along), or the law's hold off by more than its bound: from here the
                # damped joint hold, whose command is safe to keep.
                return self._gap_stop(ns, q, qd, now_ns, guard)
            return self._readiness_hold(ns, q, qd, now_ns, guard)
        found = self.setpoints.newest(ns)
        if found is None:
            self.requests.ask_drive_wait(True)
            return self._no_setpoint(ns, q, qd, now_ns)
        if ns - found[0] > self._carry_ns:
            self.requests.ask_drive_wait(True)
            if self.hold_on_stale:
                return self._no_setpoint(ns, q, qd, now_ns, (ns - found[0]) * 1e-9)
        else:
            self.requests.ask_drive_wait(not any(found[1][self.task_dim:]))
        return self._tick(ns, q, qd, found[0], found[1], now_ns)

    # -- readiness guard (real time) ---------------------------------------------------
    def readiness(self):
        """
        Return the loop's readiness now: ``(ready, reason)``.

        Lockstep, or real time without the guard: ready (never judged). A stop for want of
        states (the watchdog's stale state) is not ready until the next state.
        """
        return self.watch.verdict()

    def take_readiness(self):
        """Return the readiness change to publish, ``(stamp_ns, ready, reason)``, once, or None."""
        return self.watch.take_note()

    def take_drive_wait(self):
        """Return the driver's wait to send now [s] (brake_timeout_request), once, or None."""
        return self.requests.take_drive_wait()

    def take_brake_request(self):
        """Return the brake request to send (why), once, or None."""
        return self.requests.take_brake_request()

    # What the node and the tests read of the parts, as the loop's own attributes.
    _readiness = _part('watch', 'guard', 'The readiness guard (None: lockstep or off).')
    readiness_note = _part('watch', 'note', 'The readiness change to publish, or None.')
    brake_request = _part('requests', 'brake_request', 'Why the driver is to brake now, or None.')
    brake_requests = _part('requests', 'brake_requests', 'The brake requests so far.')
    drive_wait = _part('requests', 'drive_wait', "The driver's wait sent last [s], or None.")
    drive_wait_request = _part('requests', 'drive_wait_request',
                               "The driver's wait to send now [s], or None.")

    def _withhold(self, ns, now_ns):
        """
        Not ready, 'brake': stop - the stop command once, the brakes asked for - then quiet.

        The first state of a not-ready spell is answered with the stop command
        (:meth:`stop_effort`: what a driver that keeps its last command then holds, instead
        of the last tracking command) and the brakes are asked for (``brake_request``);
        the states after it are not answered (a driver with a command watchdog brakes).
        """
        reason = self.watch.guard.reason
        if not self._withholding:
            self._kept_hold = self.shaper.hold_position     # None unless holding
            self._withholding = True
            self.pending = None
            self.requests.ask_brake(reason)
            if self._commanded:
                # The driver holds a computed command: replace it before going quiet.
                return self._answer_stop(ns, STATUS_STOPPED, '%s: %s' % (reason, STOP_SAID),
                                         now_ns)
        self.withheld += 1
        self.pending = None
        said = self._said_ns
        if said is None or not 0 <= ns - said < _SAY_PERIOD_NS:
            # At most once per second of stamps (a transition is said at once).
            self._said_ns = ns
            self.log(ERROR, 'readiness', '%s: %s' % (reason, QUIET_SAID))
        return None

    def _gap_stop(self, ns, q, qd, now_ns, guard):
        """
        Not ready, 'hold', after a gap or a failed hold: the damped joint hold until ready.

        The law's hold answers every state, but a driver keeps the law's last command for
        the whole of a gap in the states; past ``readiness_hold_max_gap`` that command is
        no longer one the law rides through (its stiffness acts on an error it no longer
        sees). Nor is a hold whose error passed the law's bound (``readiness_max_error``
        while holding): the loop late and lossy enough to destabilise the law, which a
        driver holding each command turns into a runaway within tenths of a second. The
        damped joint hold's command stays stable when kept up to 1.33 ``stop_hold_time``;
        so from the first such gap or error of a not-ready spell on, the spell is answered
        as ``readiness_action: damp`` answers it, and tracking resumes from where the arm
        is.
        """
        if not self._withholding:
            self._said_ns = None
            if self._gap_tripped:
                pass    # the trip (by the gap or the error itself) said it in its line
            elif self._hold_error is not None:
                self.log(ERROR, None, '%s; then the hold %.3g mm off (> %.3g mm): %s' % (
                    guard.reason, self._hold_error * 1e3,
                    self.watch.law_hold_limit() * 1e3, HOLD_ERROR_SAID))
            else:
                self.log(ERROR, None, '%s; then %d states missed in a row (%.3g s > '
                         'readiness_hold_max_gap %g s): %s' % (
                             guard.reason, self._hold_gap,
                             (self._hold_gap + 1) * guard.dt_ns * 1e-9,
                             self.config.readiness_hold_max_gap, HOLD_GAP_SAID))
        return self._damped_stop(ns, q, qd, now_ns, HOLD_GAP_SAID
                                 if self._hold_error is None else HOLD_ERROR_SAID)

    def _damped_stop(self, ns, q, qd, now_ns, said=DAMP_SAID):
        """
        Not ready, 'damp': answer with the damped joint hold (a driver holding its last command).

        The active joints held where the stop found them (gains from their effective
        inertia and ``stop_hold_time``, on the gravity load of the nominal model), every
        state until the loop is ready again; nothing is asked of the brakes.
        """
        reason = self.watch.guard.reason
        if not self._withholding:
            self._kept_hold = self.shaper.hold_position     # None unless holding
            self._withholding = True
            self._damped = True
            self._q_stop = [q[i] for i in self.law.model.active]
            if self._said_ns is None:
                self._said_ns = ns      # (a transition was said at once)
        last_said = self._said_ns
        if not 0 <= ns - last_said < _SAY_PERIOD_NS:
            self._said_ns = ns
            self.log(ERROR, 'readiness', '%s: %s' % (reason, said))
        return self._answer_stop(ns, STATUS_STOPPED, '%s: %s' % (reason, said), now_ns,
                                 q, qd)

    def stop_effort(self, q=None, qd=None):
        """
        Return the stop command [N m] in command order (``freejoint_core.guards.hold_effort``).

        The active joints' gravity load of the law's (nominal) model at ``q`` (the core's
        angles; default the last good measured state), within the torque limits: zero in a
        horizontal plane, and zero before any state was measured. With ``qd`` (the damped
        stop, ``readiness_action: damp``): the damped joint hold towards the angles the
        stop found (``freejoint_core.guards.damped_hold_effort``, ``stop_hold_time``).
        """
        return stop_effort(self.law.model, self._last_q if q is None else q, qd,
                           self._q_stop, self._stop_hold_time, self.config.cmd_index,
                           self._limits)

    def _answer_stop(self, ns, status, message, now_ns, q=None, qd=None):
        """Return the stop command's answer to the state stamped ns, saying why."""
        res = self._answer_zero(ns, status, message, now_ns)
        effort = self.stop_effort(q, qd)
        res.effort = effort
        self.zero_answers -= 1
        self.stops += 1
        self._prev_cmd = list(effort)   # a resume ramps from it, not from zero
        self.stepper.restart_prediction()
        return res

    def _resume_after_brake(self, ns):
        """
        Ready again after withholding (at the state stamped ``ns``): start over from the arm.

        After the damped joint hold (the free link swung, the active joints sagged) the
        loop starts from where the arm is and tracks at once, but says it is not ready for
        a plan until its reference has re-joined the setpoints (``Readiness.rejoining``;
        :meth:`_tick` ends it).
        """
        self._withholding = False
        self.requests.stop_over()
        kept, self._kept_hold = self._kept_hold, None
        if self.watch.damps or self._hold_gap is not None or self._hold_error is not None:
            self._hold_gap = self._hold_error = None
            # The damped hold let the free joints swing (and the active joints sag): start
            # from where the arm is and how it moves, not back to the hold's old place
            # (the free link would be dragged along; a plan rewinds to the arm itself).
            kept = None
        if self._damped:
            self._damped = False
            self._rejoin_ns = ns
            self.watch.rejoining(ns, REJOIN_SAID)
        if kept is None:
            # Hold at fk(q), or blend to the setpoint from the measured motion: a braked arm
            # is at rest, but one a driver kept moving (the stop command held, the damped
            # joint hold) is not, and a reference from rest would be a step in velocity.
            self.shaper.reset()
            self._start_from_motion = True
        else:
            # A hold stopped (e.g. a drift past readiness_max_hold_error): back to its own
            # position from where the arm was braked, so that stops do not add up.
            self.shaper.return_to(kept)
        self.last_ns = -1               # dt of the first tick: one control period
        self._rate_armed = True         # ramp from the stop command the driver got
        self.law.restart_motion()       # e.g. the free link's shift: its swing was stopped
        self.stepper.keep_state()
        self.stepper.restart_prediction()

    def _rejoined(self, ns, ref_error, holding):
        """Say ready for a plan once the blend after a stop is over, within the error bound."""
        limit = self.watch.error_limit(holding)
        if limit and ref_error > limit:
            return
        self.watch.rejoined(ns)
        self.log(INFO, None, 're-joined the %s %.3g s after the loop was ready again (%.3g mm '
                 'off the reference): ready for a plan' % (
                     'hold' if holding else 'setpoints', (ns - self._rejoin_ns) * 1e-9,
                     ref_error * 1e3))

    def _readiness_hold(self, ns, q, qd, now_ns, guard):
        """
        Not ready, 'hold': hold the end effector, the message saying why.

        After a trip by the loop's timing the hold's gains are scaled by
        ``readiness_hold_stiffness`` (a late, lossy loop tolerates less gain) and a moving
        reference first stops along its path (``readiness_stop_acceleration``: no step to
        zero velocity for a driver to keep); after a following-error trip (the arm thrown
        off) it holds where the arm is, at ``hold_stiffness``, as any hold.
        """
        if self.shaper.mode != MODE_HOLD:
            self.holds += 1
        self.log(ERROR, 'readiness', guard.reason + ': holding position')
        timing = not self._error_spell
        return self._tick(ns, q, qd, None, None, now_ns, guard.reason,
                          hold_scale=self.config.readiness_hold_stiffness if timing else None,
                          stop=timing)

    def _start_from(self, q, qd):
        """Start the reference from the measured end-effector motion (fk, J qd)."""
        model = self.law.model
        try:
            p = model.fk(q)
            v = model.jacobian(q) @ np.asarray(qd, dtype=float)
            self.shaper.start_from(p.tolist(), v.tolist())
        except (FreejointValueError, ArithmeticError) as exc:
            self.shaper.reset()
            self.log(ERROR, None, 'cannot start from the measured motion (%s): blending '
                     'from the position at rest' % exc)

    def _no_setpoint(self, ns, q, qd, now_ns, late=None):
        """Answer a state without a fresh (or timely) setpoint: hold or zero effort."""
        if late is not None:
            why = ('setpoint stream late: the newest is %.3g s old, carried forward %g s at '
                   'most' % (late, self.config.carry_forward_time))
        elif self.reference.used:
            why = ('stale setpoint: none stamped within %g s before the state%s'
                   % (self.stale_timeout, self.setpoints.refusal_note()))
        else:
            why = 'no setpoint yet' + self.setpoints.refusal_note()
        if not self._stale_now and (late is not None or self.reference.used):
            self._stale_now = True
            self.stale_periods += 1
        if not self.hold_on_stale:
            self.log(WARN, 'stale_setpoint', why + ': zero effort')
            return self._answer_zero(ns, STATUS_STALE_SETPOINT, why + ': zero effort', now_ns)
        if self.shaper.mode != MODE_HOLD:
            self.holds += 1
            self.log(WARN, 'hold', why + ': holding position')
        return self._tick(ns, q, qd, None, None, now_ns, why, late is not None)

    def on_setpoint(self, ns, values, now_ns, mono):
        """
        Take a setpoint stamped ``ns``; return a Result or None.

        ``values``: its position, velocity and acceleration, m values each, in one flat
        sequence (``3 m``; planar: ``(px, py, vx, vy, ax, ay)``).

        Lockstep: the state waiting for it is answered now. A setpoint the guards refuse is
        dropped (counted, the reason logged and noted for the next hold's message).
        """
        stream = self.setpoints
        reason = stream.refusal_of(values)
        if reason is not None:
            self.refuse_setpoint(ns, reason)
            return None
        stream.taken(mono, self.standby)
        if not self.lockstep:
            stream.add(ns, values)
            return None
        pending = self.pending
        if pending is not None and pending[0] == ns:
            self.pending = None
            return self._tick(ns, pending[1], pending[2], ns, values, now_ns)
        if ns > self.last_ns:
            stream.keep(ns, values)
        return None

    def on_setpoints(self, samples, mono, publish):
        """
        Take a batch's setpoints in order; call ``publish`` with each Result computed.

        Parameters
        ----------
        samples : sequence of SetpointSample
            ``contract.setpoint_samples`` of a batch: ``stamp_ns`` [ns] and ``position``,
            ``velocity``, ``acceleration`` (m values each); one of another length than the
            task dimension is refused (counted, logged).
        mono : float
            Monotonic time [s] of their receipt.
        publish : callable
            ``publish(result)``, called as each Result is computed (lockstep: a waiting
            state answered); the next reuses the Result object, so publish it at once.

        """
        m = self.task_dim
        for sp in samples:
            if len(sp.position) != m:
                self.refuse_setpoint(sp.stamp_ns, '%d values per vector, the task dimension '
                                     'is %d' % (len(sp.position), m))
                continue
            res = self.on_setpoint(sp.stamp_ns, sp.position + sp.velocity + sp.acceleration,
                                   0, mono)
            if res is not None:
                publish(res)

    def refuse_setpoint(self, ns, reason, count=1):
        """
        Drop the setpoint stamped ``ns`` for ``reason``: counted, logged, noted.

        ``count`` > 1: a batch of that many from ``ns`` on, dropped for one reason.
        """
        self.refused_setpoints += count
        self.setpoints.refused(reason)
        what = ('setpoint stamped %d ns' % ns if count == 1 else
                '%d setpoints from the one stamped %d ns' % (count, ns))
        self.log(ERROR, 'setpoint', '%s refused: %s; dropped' % (what, reason))

    def refuse_state_message(self, reason):
        """
        Drop a joint state message that cannot be read (no stamp to answer): counted, logged.

        Nothing is answered: lockstep, the simulator waits for its command timeout; real
        time, the next state is answered (the watchdog holds if none comes).
        """
        self.refused_states += 1
        self.log(ERROR, 'unreadable', 'joint_states message refused: %s; nothing answered, '
                 'theta_hat kept' % reason)

    def watchdog(self, now_ns, mono):
        """
        Wall-clock staleness (the node calls it a few times per stale_timeout).

        A lockstep state waiting longer than stale_timeout for its setpoint is answered
        (hold, or zero effort); no state for stale_timeout: zero effort, once. Returns the
        Result to publish or None.
        """
        pending = self.pending
        if pending is not None:
            if self.setpoints.seen and mono - pending[3] > self.stale_timeout:
                self.pending = None
                return self._no_setpoint(pending[0], pending[1], pending[2], now_ns)
            return None
        last = self.last_state_wall
        if last is not None and not self.stale_reported and mono - last > self.stale_timeout:
            self.stale_reported = True
            if self.lockstep:
                self.log(WARN, None, 'no joint_states for %g s: zero effort' % self.stale_timeout)
                return self._answer_zero(self.last_ns, STATUS_STALE_STATE,
                                         'stale state: no joint_states within %g s'
                                         % self.stale_timeout, now_ns)
            if not self._commanded:
                return None     # nothing to replace (the driver got no computed command)
            why = ('stale state: no joint_states within %g s: %s'
                   % (self.stale_timeout, STOP_SAID))
            self.log(ERROR, None, why)
            self.watch.stale_reason = why
            self.watch.note = (self.last_ns, False, why)
            self.requests.ask_brake('stale state: no joint_states within %g s'
                                    % self.stale_timeout)
            self.requests.stop_over()       # a later stop asks again
            res = self._answer_stop(self.last_ns, STATUS_STALE_STATE, why, now_ns)
            # The arm may move meanwhile: the next state starts a hold / blend from it.
            self.shaper.reset()
            self.law.restart_motion()
            return res
        return None

    # -- outputs -----------------------------------------------------------------------
    def _tick(self, ns, q, qd, sp_ns, sp, now_ns, hold_reason='', late=False, hold_scale=None,
              stop=False):
        """Compute the answer to the state stamped ns (sp None: hold)."""
        status = 0
        planned = self.setpoints.planned(ns, sp, self.lockstep)
        shaper = self.shaper
        law = self.law
        if self.lockstep or self.last_ns < 0:
            dt = self._dt
        else:
            dt, clamped = clamp_dt((ns - self.last_ns) * 1e-9, self._dt)
            if clamped:
                status |= STATUS_DT_CLAMPED
                self.log(WARN, 'dt', 'state stamps %g s apart, outside [0.25, 4] x '
                         'control_period: the law uses dt = %g s'
                         % ((ns - self.last_ns) * 1e-9, dt))
        ref, bits, held = self.reference.step(law.model, q, ns, sp_ns, sp, late, hold_scale,
                                              stop)
        status |= bits
        if held:
            self._rate_armed = self._prev_cmd is not None
        if sp is not None:
            self._stale_now = False
        stiffness = self.reference.stiffness()
        if stiffness != law.stiffness:
            law.set_stiffness(stiffness)
        p_ref = ref[0:self.task_dim]
        limits = self._limits
        fm = self.failures
        out, effort, values, fault = self.stepper.step(
            ns, q, qd, ref, dt, now_ns, fm, self._prev_cmd,
            self.inputs.effort_of(len(q)) if fm is not None else None)
        if fault:
            status |= STATUS_LAW_FAULT
        status |= out.status
        if self._rate_armed:
            effort, clipped, rated = limit_effort(effort, limits, self._prev_cmd,
                                                  self._rate * dt)
            if rated:
                status |= STATUS_RATE_LIMITED
            else:
                self._rate_armed = False
        self._prev_cmd = effort
        self.stepper.push(effort)
        res = self.result
        res.repeated = False
        res.stamp_ns = ns
        res.effort = effort
        res.error = out.e
        res.error_rate = out.edot
        res.sliding = out.s
        res.law_state_values = values
        res.det_dd = self.stepper.last_det
        res.position = out.p if self.stepper.predictor is None else law.model.fk(q)
        res.position_desired = p_ref
        res.position_planned = planned
        ref_error = self.figures.track(res.position, planned, out.e)
        if self.watch.rejoin and shaper.mode != MODE_BLEND:
            self._rejoined(ns, ref_error, sp is None)
        res.status = status
        res.message = status_message(status, res.det_dd, self.config, hold_reason,
                                     shaper) if status else ''
        if fm is not None and fm.message:
            res.message = fm.message + ('; ' + res.message if res.message else '')
        if sp_ns is None:
            res.setpoint_ns = None
            res.setpoint_age = 0.0
        else:
            res.setpoint_ns = sp_ns
            res.setpoint_age = (ns - sp_ns) * 1e-9
        res.dt = dt
        if self.lockstep:
            # Sim time stands still until the command; the latency is the wall time from
            # the state's receipt to its command (the node's to measure).
            res.state_age = 0.0
            res.latency_ns = RECEIPT
        else:
            age_ns = now_ns - ns
            res.state_age = age_ns * 1e-9
            res.latency_ns = age_ns
        self.figures.bits |= status
        self.last_ns = ns
        self._last_sp = p_ref
        self.ticks += 1
        self._commanded = self._ever_commanded = True
        guard = self.watch.guard
        if guard is not None:
            holding = sp is None
            if guard.ready:
                limit = self.watch.error_limit(holding)
                if limit and ref_error > limit:
                    return self._following_error(res, ns, ref_error, guard, limit,
                                                 holding, now_ns, q, qd)
            elif self.watch.holds and self._hold_gap is None and self._hold_error is None:
                limit = self.watch.law_hold_limit()
                if limit and ref_error > limit:
                    # Not ready, the law's hold off by more than its bound: it gives way.
                    self._hold_error = ref_error
                    self._gap_tripped = False
                    return self._gap_stop(ns, q, qd, now_ns, guard)
        return res

    def _following_error(self, res, ns, error, guard, limit, holding, now_ns, q, qd):
        """
        Real time: the arm does not follow; stop tracking as a bad window would.

        'brake' and 'damp' stop at once. 'hold' answers this state with the command just
        computed and holds the end effector from the next state on, as after any other
        trip: the error may come from a push or a transient rather than from the loop (a
        state that jumped, a stall ridden through), and the damped joint hold lets a free
        link fall (a vertical arm's swings through its whole range). The law's hold still
        gives way to the damped joint hold past ``readiness_hold_max_error``.
        """
        if guard.trip('real-time loop not ready: tracking error %.3g mm > the %.3g mm of '
                      '%s (the arm does not follow its reference)'
                      % (error * 1e3, limit * 1e3, 'readiness_max_hold_error while holding'
                         if holding and self.config.readiness_max_hold_error
                         else 'readiness_max_error')):
            self.watch.changed(1, ns)
            self._said_ns = ns
        if self.watch.brakes:
            return self._withhold(ns, now_ns)
        if self.watch.damps:
            return self._damped_stop(ns, q, qd, now_ns)
        self._error_spell = True
        return res

    def on_failure_notice(self, name):
        """
        Take a driver's or operator's notice that the joint ``name`` failed (next tick).

        Returns '' if taken, else why not (failure handling off, unknown joint, ...).
        """
        if self.failures is None:
            why = ('joint failure notice for %r ignored: joint_failures is off' % name)
            self.log(WARN, None, why)
            return why
        return self.failures.notice(name)

    def _answer_zero(self, ns, status, message, now_ns):
        """Return the zero-effort answer to the state stamped ns, saying why."""
        law = self.law
        res = self.result
        res.repeated = False
        res.stamp_ns = ns
        res.effort = self._zero
        res.error = res.error_rate = res.sliding = self._zero_task
        res.law_state_values = law.state_values()
        res.det_dd = self.stepper.last_det
        q = self._last_q
        res.position = law.model.fk(q) if q is not None else self._last_sp
        res.position_desired = self._last_sp
        res.position_planned = ()
        res.status = status
        res.message = message
        res.setpoint_ns = None
        res.setpoint_age = 0.0
        res.dt = 0.0
        res.state_age = 0.0 if self.lockstep or ns < 0 else (now_ns - ns) * 1e-9
        res.latency_ns = None
        self.figures.bits |= status
        if ns >= 0:
            self.last_ns = ns
        self.zero_answers += 1
        self._commanded = False
        # The arm got zero: the next computed command ramps up from it.
        self._prev_cmd = list(self._zero)
        self._rate_armed = True
        self.stepper.push(self._zero)
        return res

    # -- status ------------------------------------------------------------------------
    faults = _part('stepper', 'faults', 'The law faults so far.')

    def counters(self):
        """Return the counters a status period starts from (answers, faults, refusals)."""
        return (self.ticks + self.zero_answers + self.stops, self.faults, self.refused_states,
                self.refused_setpoints, self.old_states)

    def diagnostics(self, elapsed, start, silent, latency, states_topic, activated_at):
        """Return (errors, warnings, ok message, key/values) of the status period ending."""
        return loop_status.diagnostics(self, elapsed, start, silent, latency, states_topic,
                                       activated_at)

    def report(self):
        """Return the end of the run's line (``loop_status.report`` of this loop)."""
        return loop_status.report(self)
