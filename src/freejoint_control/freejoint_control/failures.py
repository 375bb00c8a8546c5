"""
A joint fails during the task: the controller's detection and reconfiguration, no ROS.

:class:`FailureMonitor` is what :class:`freejoint_control.loop.ControlLoop` calls per tick
when the parameter ``joint_failures`` is not ``'off'`` (``'off'``, the default: no monitor,
the loop computes exactly what it computed before).  Per answered state, before the law:

1. :meth:`FailureMonitor.before_law` takes the measured ``q``, ``qd``, the command sent at
   the last tick (all configured active joints, command order) and the effort the
   JointState reports (if it has one): with ``joint_failures: detect`` the generalised
   momentum residual (``freejoint_core.failure.Reconfigurer.observe``; the effort
   detector too when the JointState has efforts and ``failure_use_effort``) looks for a
   joint that lost its torque; a notice (:meth:`FailureMonitor.notice`, the
   ``joint_failures`` topic) queued since the last tick is taken first, so a notice
   switches the law at the first tick after its receipt.
2. On a detected or notified failure the joint joins the passive set
   (``Reconfigurer.switch``) and the verdict is given at once, on the tick:

   - ``r < m`` and ``det(Da Da^T)`` at the current pose: computed on the tick (cheap);
   - the internal motion (``freejoint_core.failure.assess_passive_set``'s simulation of
     the zero dynamics, about 0.2 s of CPU per set): **precomputed at construction**
     (node start-up) for every passive set a single failure of the configured arm gives,
     along the paper's circle (``CircleQuintic``, the planner's default plan) from its
     start state (``freejoint_core.offline.initial_state``, joint 3 at 120 deg); arms of
     other than 3 links: the pose checks only.  The tick looks the set up
     (:attr:`FailureMonitor.precomputed`).  This is the path's start, not the failure's
     time: a set whose internal motion depends on when it fails (joint 2 free,
     horizontal: docs/failures.md) is judged as at the start.

   Tracking: the law gets the nominal arm with the new passive set (``law.set_nominal``:
   its adaptive estimate kept; the null-space term dropped when ``r = m``; the torque
   limits of the remaining joints) and the command keeps its length, 0 on the failed
   joint (:meth:`FailureMonitor.after_law`).  Cannot track: from then the remaining
   joints get ``freejoint_core.failure.least_harm_torque`` (a light damper horizontally,
   a soft hold with gravity compensation vertically, clipped to the effort limits)
   instead of the law (:meth:`FailureMonitor.least_harm`).

The status message (ControllerState ``message``, no new status bit), ``/diagnostics`` and
the log name the joint, the time (state stamp) and how it was found (``residual``,
``effort`` or ``notice``).  docs/failures.md, "In the controller".
"""

from dataclasses import replace
import math

from freejoint_core.arm import table1
from freejoint_core.errors import FreejointValueError
from freejoint_core.failure import (assess_passive_set, Assessment, CANNOT_TRACK,
                                    least_harm_torque, M_TASK, Reconfigurer, TRACKING)
from freejoint_core.law_base import LawOutput
from freejoint_core.offline import initial_state
from freejoint_core.trajectory import CircleQuintic
import numpy as np

MODES = ('off', 'notice', 'detect')
"""Values of the parameter ``joint_failures``."""
NO_TORQUE = 1e-9
"""[N m] A measured effort this small is no torque (a failed joint, a braked or stopped
drive reads 0)."""
EFFORT_HISTORY_S = 0.05
"""[s] Real time: the commands the driver may have applied over the last period are those
sent this recently (its latency: 3-13 ms measured here, loaded)."""
HOLDOFF_S = 0.02
"""[s] Real time: after the drive applied no torque on every driven joint (brakes, its
watchdog, a stop), how long the effort detector waits before it judges again."""

_ZERO2 = np.zeros(2)


def precompute_verdicts(nominal, case, gains):
    """
    Return the internal-motion verdict of every single-failure passive set of an arm.

    Computed once per distinct (arm, case, K, Lambda) and kept (``_VERDICTS``).

    Parameters
    ----------
    nominal : ArmParams
        The configured nominal arm (its passive set: the joints free from the start).
    case : str
        ``'horizontal'`` or ``'vertical'`` (the start state's arm).
    gains : freejoint_core.control.Gains
        The law's gains (K, Lambda of the simulated error dynamics).

    Returns
    -------
    dict
        ``{passive set (tuple): Assessment}``; for arms of other than 3 links the pose
        checks only (at the start state: none, the dict is empty).

    """
    key = (nominal, case, float(gains.K[0]), float(gains.Lambda[0]))
    if key not in _VERDICTS:
        _VERDICTS[key] = _verdicts(nominal, case, gains)
        while len(_VERDICTS) > 8:
            del _VERDICTS[next(iter(_VERDICTS))]
    return dict(_VERDICTS[key])


_VERDICTS = {}
"""``precompute_verdicts``' results by (nominal arm, case, K, Lambda): about 1 s of CPU
each, which a parameter change of the controller (a new monitor, on the executor) or
another loop of the same arm would otherwise spend again; the last 8 kept."""


def _verdicts(nominal, case, gains):
    """Return :func:`precompute_verdicts`' result, computed."""
    out = {}
    if nominal.n != 3:
        return out
    traj = CircleQuintic()
    q0 = initial_state(table1(case), 120.0, traj.sample(0.0)[0])
    qd0 = np.zeros(nominal.n)
    for j in nominal.active:
        passive = tuple(sorted(set(nominal.passive) | {j}))
        if nominal.n - len(passive) < M_TASK:
            continue
        out[passive] = assess_passive_set(nominal, passive, q0, qd0, traj, 0.0,
                                          gains=(gains.K[0], gains.Lambda[0]))
    return out


class FailureMonitor:
    """
    Joint-failure detection and the law's reconfiguration for the control loop.

    Parameters
    ----------
    cfg : freejoint_control.params.Config
        The validated controller configuration (``joint_failures``,
        ``failure_observer_gain``, ``failure_margin``, ``failure_ticks``,
        ``failure_use_effort``, the arm, the gains, the limits).
    law : freejoint_core.laws.ControlLaw
        The loop's law (reconfigured in place).
    log : callable
        ``log(level, kind, text)`` of the loop.

    Attributes
    ----------
    events : list of dict
        One per failure taken: ``joint`` (name), ``t`` [s], ``by``, ``verdict``,
        ``reason``, ``passive`` (names).
    precomputed : dict
        ``{passive set: Assessment}`` of :func:`precompute_verdicts`.

    """

    def __init__(self, cfg, law, log):
        mode = cfg.values['joint_failures']
        if mode not in MODES[1:]:
            raise FreejointValueError(f'joint_failures: expected one of {MODES[1:]}, got '
                                      f'{mode!r}')
        self.detect = mode == 'detect'
        self.use_effort = self.detect and bool(cfg.values['failure_use_effort'])
        self.law = law
        self.log = log
        self.names = tuple(cfg.joint_names)
        self.configured = cfg.nominal                 # the arm the command is laid out for
        self._cfg_active = tuple(cfg.nominal.active)
        self._cmd_index = cfg.cmd_index
        self._gains = cfg.gains
        self._limit = cfg.gains.tau_limit             # active (model) order
        self.rec = Reconfigurer(cfg.nominal, cfg.dt, k_o=cfg.values['failure_observer_gain'],
                                margin=cfg.values['failure_margin'],
                                ticks=cfg.values['failure_ticks'], effort=self.use_effort)
        self.precomputed = precompute_verdicts(cfg.nominal, cfg.values['case'], cfg.gains)
        self._dt_ns = cfg.dt_ns
        self._last_ns = None
        # Real time: the commands sent within EFFORT_HISTORY_S (model order; NaN: none).
        self._sent = np.full((max(2, round(EFFORT_HISTORY_S / cfg.dt)), self.rec.n), np.nan)
        self._sent_count = 0
        self._lockstep = cfg.lockstep
        self._holdoff_ticks = max(1, round(HOLDOFF_S / cfg.dt))
        self._holdoff = 0               # real time: ticks left before the effort is judged
        self.drive_stops = 0            # real time: onsets of no torque on every joint
        self._notices = []
        self._hold_q = None
        self.events = []
        self._announced = 0
        self.message = ''
        self.cannot_track = False

    # -- inputs ------------------------------------------------------------------------
    def notice(self, name):
        """
        Queue a failure notice for the joint named ``name`` (taken at the next tick).

        Returns
        -------
        str
            '' if queued, else why it was ignored (logged, but for a joint known failed:
            the announcement of a detection, :meth:`announcements`, comes back).

        """
        if name not in self.names:
            why = 'joint failure notice for %r ignored: not a joint of %s' % (
                name, list(self.names))
        else:
            j = self.names.index(name)
            if j in self.rec.failed or (j in self.rec.nominal.passive
                                        and j not in self.configured.passive):
                return '%s failed already' % name   # e.g. this controller's announcement
            if j not in self.rec.active:
                why = 'joint failure notice for %s ignored: it is not driven (passive or ' \
                    'failed already)' % name
            elif j in self._notices:
                why = ''
            else:
                self._notices.append(j)
                return ''
        if why:
            self.log('warn', None, why)
        return why

    def announcements(self):
        """
        Return the joints detected failed since the last call (not those notified).

        The node publishes them on ``joint_failures``: the planner, a hot spare and the
        bag learn of a failure only this controller saw.
        """
        new = self.events[self._announced:]
        self._announced = len(self.events)
        return [e['joint'] for e in new if e['by'] != 'notice']

    def before_law(self, ns, q, qd, prev_cmd, effort):
        """
        One tick of detection; switch the law on a failure found or notified.

        Parameters
        ----------
        ns : int
            The state's stamp [ns].
        q, qd : sequence of float, (n,)
            Measured state (model order).
        prev_cmd : sequence of float, (r,) or None
            The command sent at the last tick (command order), None: none yet.
        effort : sequence of float, (n,) or None
            Measured effort over the last period (model order), None: not reported.

        """
        rec = self.rec
        tau_last = [0.0] * rec.n
        if prev_cmd is not None:
            for j, i in enumerate(self._cmd_index):
                tau_last[self._cfg_active[i]] = prev_cmd[j]
        if self._last_ns is not None and ns - self._last_ns != self._dt_ns:
            rec.observer.rebase()                     # a tick missed or time jumped
            rec.detector.reset()
        self._last_ns = ns
        found = [(j, 'notice') for j in self._notices]
        self._notices = []
        if self.detect:
            if self.use_effort and effort is not None:
                hit = self._observe_with_effort(q, qd, tau_last, effort)
            else:
                hit = rec.observe(q, qd, tau_last, None)
            if hit is not None and all(h[0] != hit[0] for h in found):
                found.append(hit)
        for j, how in found:
            if j in rec.active:
                self._switch(j, ns * 1e-9, how, q, qd)

    def _effort_reference(self, tau_last, effort):
        """
        Return the command the measured effort is to be compared with.

        Lockstep the measured effort is the last command exactly (a healthy joint: gap 0):
        the last command is the reference, as offline.  In real time the driver applied
        whichever command it had last received, answering a state up to its latency old:
        the reference is the command sent within ``EFFORT_HISTORY_S`` that matches the
        effort on every driven joint (within the detector's tolerance), else the one
        nearest to it on all but the farthest joint (the healthy ones match the one
        applied exactly; a failed joint, which reads 0 against every one, must not
        choose: its commands can be as small as the differences between them).
        """
        if self._lockstep:
            return tau_last
        ring = self._sent
        ring[self._sent_count % len(ring)] = tau_last
        self._sent_count += 1
        watch = list(self.rec.effort.watch)
        gaps = np.abs(ring[:, watch] - np.asarray(effort)[watch])
        total = gaps.sum(axis=1)
        best = int(np.nanargmin(total))
        if total[best] > self.rec.effort.tol and len(watch) > 1:
            best = int(np.nanargmin(total - gaps.max(axis=1)))
        return ring[best].tolist()

    def _observe_with_effort(self, q, qd, tau_last, effort):
        """Return ``Reconfigurer.observe``'s finding with the effort detector's reference."""
        rec = self.rec
        if not self._lockstep:
            return self._observe_real_time(q, qd, tau_last, effort)
        res = rec.observer.step(q, qd, tau_last, rec.dt)
        j = rec.effort.update(self._effort_reference(tau_last, effort), effort)
        if j is not None:
            return j, 'effort'
        if rec.verdict != TRACKING:
            return None
        j = rec.detector.update(res)
        return None if j is None else (j, 'residual')

    def _observe_real_time(self, q, qd, tau_last, effort):
        """
        Return a joint the effort detector finds failed in real time, or None.

        The measured effort is the torque the drive applied: the residual cannot tell a
        late answer (the driver applied the previous command) from a lost torque, so in
        real time, with efforts, the effort detector alone judges and the observer runs
        on the applied torque (kept current, flags nothing); only a joint that reads no
        torque (within the detector's tolerance) against its command can be flagged.
        Every driven joint reading no torque is the drive stopped (brakes, its watchdog,
        a stop), not one actuator lost: no judgement then, and for ``HOLDOFF_S`` after.
        """
        rec = self.rec
        rec.observer.step(q, qd, effort, rec.dt)
        detector = rec.effort
        reference = self._effort_reference(tau_last, effort)
        if all(abs(effort[j]) <= NO_TORQUE for j in detector.watch):
            if self._holdoff == 0:
                self.drive_stops += 1
            detector.set_watch(detector.watch)          # the counts restart
            self._holdoff = self._holdoff_ticks
            return None
        if self._holdoff > 0:
            self._holdoff -= 1
            return None
        # A failed actuator applies no torque: a joint that reads torque has not failed
        # (its gap is a command applied that the history does not hold: a stall).
        reference = [m if abs(m) > detector.tol else c for c, m in zip(reference, effort)]
        j = detector.update(reference, effort)
        return None if j is None else (j, 'effort')

    def _switch(self, j, t, how, q, qd):
        rec = self.rec
        was_tracking = rec.verdict == TRACKING
        sw = rec.switch(j, t, how, q, qd)
        assessment = sw.assessment
        if sw.verdict == TRACKING and sw.passive in self.precomputed:
            pre = self.precomputed[sw.passive]
            if pre.verdict != TRACKING:
                assessment = Assessment(CANNOT_TRACK, pre.reason + ' (checked along the '
                                        'path from its start at start-up)', assessment.det,
                                        pre.min_det, pre.growth, pre.max_qd)
                rec.verdict = CANNOT_TRACK
                rec.switches[-1] = replace(sw, assessment=assessment)
        if rec.verdict == TRACKING:
            self._install(rec.nominal)
        elif was_tracking:
            self.cannot_track = True
            self._hold_q = list(q)
        name = self.names[j]
        passive = [self.names[p] for p in sw.passive]
        self.events.append({'joint': name, 't': t, 'by': how, 'verdict': rec.verdict,
                            'reason': assessment.reason, 'passive': passive})
        if rec.verdict == TRACKING:
            self.message = ('%s failed at t = %.3f s (detected by %s): law switched to '
                            'passive %s' % (name, t, how, passive))
            self.log('warn', None, 'joint failure: ' + self.message + ', det(Da Da^T) = '
                     '%.3g, theta_hat kept' % assessment.det)
        else:
            self.message = ('%s failed at t = %.3f s (detected by %s): cannot_track (%s): '
                            'least-harm command on %s' % (
                                name, t, how, assessment.reason,
                                [self.names[a] for a in rec.active]))
            self.log('error', None, 'joint failure: ' + self.message)

    def _install(self, nominal):
        """Give the law the nominal arm with the new passive set (theta kept)."""
        law = self.law
        gains = self._gains
        limit = None if self._limit is None else tuple(
            self._limit[self._cfg_active.index(a)] for a in nominal.active)
        law.set_gains(replace(gains, tau_limit=None))
        law.set_nominal(nominal)        # (a law drops its null space with no joint to spare)
        law.set_gains(replace(gains, tau_limit=limit))

    def release(self):
        """Put the law back on the configured arm (before a change of its model or gains)."""
        law = self.law
        law.set_gains(replace(law.gains, tau_limit=None))
        law.set_nominal(self.configured)
        law.set_gains(self._gains)

    def renewed(self, cfg):
        """
        Return the monitor of a changed configuration, the failures known so far kept.

        The joints failed so far are taken again at the next tick (as notices: the new
        model's verdict), the events so far kept.
        """
        new = FailureMonitor(cfg, self.law, self.log)
        new.events = list(self.events)
        new._announced = self._announced
        failed = set(self.rec.nominal.passive) - set(self.configured.passive)
        new._notices.extend(sorted(failed | set(self.rec.failed)))
        return new

    # -- outputs -----------------------------------------------------------------------
    def after_law(self, out):
        """Return ``out`` with its torque laid out on the configured active joints."""
        active = self.rec.nominal.active
        if len(active) == len(self._cfg_active):
            return out
        tau = out.tau.tolist()
        full = [0.0] * len(self._cfg_active)
        for a, v in zip(active, tau):
            full[self._cfg_active.index(a)] = v
        return out._replace(tau=np.array(full))

    def least_harm(self, q, qd, p_d, internal):
        """
        Return the ``LawOutput`` of a tick after ``cannot_track``: the least-harm torque.

        Parameters
        ----------
        q, qd : sequence of float, (n,)
            Measured state.
        p_d : sequence of float, (2,)
            The reference position [m] (for the error reported).
        internal : dict
            The internal values to report (the law's last conditioning).

        """
        rec = self.rec
        act = rec.active
        lim = None if self._limit is None else [
            self._limit[self._cfg_active.index(a)] for a in act]
        tau = least_harm_torque(rec.nominal, act, q, qd, self._hold_q, limit=lim)
        full = [0.0] * len(self._cfg_active)
        for a, v in zip(act, tau.tolist()):
            full[self._cfg_active.index(a)] = v
        p = self.law.model.fk(q)
        return LawOutput(np.array(full), p - np.asarray(p_d, dtype=float), _ZERO2.copy(),
                         _ZERO2.copy(), p, 0, internal)

    def diagnostics(self, errors, warnings):
        """Add the failures to a status period's errors / warnings; return key / values."""
        if self.events:
            (errors if self.cannot_track else warnings).append(self.message)
        last = self.events[-1] if self.events else None
        return (('joint failures', ', '.join(
            '%s at %.3f s by %s (%s)' % (e['joint'], e['t'], e['by'], e['verdict'])
            for e in self.events) or 'none'),
                ('passive joints', str([self.names[p] for p in self.rec.nominal.passive]
                                       + [self.names[f] for f in self.rec.failed])),
                ('failure verdict', last['verdict'] if last else TRACKING),
                ('drive stops (no torque on any joint)', str(self.drive_stops)))


def finite_or_none(values, n):
    """Return ``values`` as a list of n floats if it has n finite ones, else None."""
    if values is None or len(values) != n:
        return None
    vals = [float(v) for v in values]
    return vals if all(map(math.isfinite, vals)) else None
