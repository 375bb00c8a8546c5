"""
The law's step in the controller's loop, and the checks of what it gives.

:class:`LawStep` steps the loop's law (``freejoint_core.laws``: built by ``make_law``)
on a state and a reference: on the measured state, or with ``delay_compensation:
predict`` on the state predicted to when the command takes effect
(``freejoint_core.delay.StatePredictor``); with the failure monitor's reconfiguration
around it (``freejoint_control.failures``). A step that raises, or whose command or
state is non-finite or out of range (``freejoint_core.guards.law_output_fault``), is a
law fault: the law's state put back to the last good one, the previous command repeated.
It reads only what a law declares (``ControlLaw``: ``step`` and its ``LawOutput``,
``conditioning``, ``state_values``, ``state_bounds``, ``save_state`` /
``restore_state``, ``model``). No ROS, no clock.
"""

import math

from freejoint_control.loop_status import ERROR
from freejoint_core.delay import extrapolate_setpoint, StatePredictor
from freejoint_core.errors import FreejointValueError
from freejoint_core.guards import law_output_fault
from freejoint_core.law_base import LawOutput
import numpy as np


class LawStep:
    """
    Step a law and check its output (module notes).

    Parameters
    ----------
    law : freejoint_core.laws.ControlLaw
        The loop's law.
    log : callable
        ``log(level, kind, text)``.

    Attributes
    ----------
    faults : int
        Law faults so far.
    last_det : float
        The conditioning of the last step: its internal value the law's ``conditioning``
        names (0: a law without one); a tick without a law step reports it again.
    predictor : freejoint_core.delay.StatePredictor or None
        The state predictor (``delay_compensation: predict``), else None.

    """

    def __init__(self, law, log):
        self.law = law
        self.log = log
        self.faults = 0
        self.last_det = 0.0
        self.predictor = None
        self._m = law.model.task_dim
        self._good_state = law.save_state()

    def configure(self, cfg):
        """Take the command layout, the period and ``delay_compensation`` of a configuration."""
        self._dt = cfg.dt
        self._cmd_index = cfg.cmd_index
        self._identity = cfg.cmd_index == tuple(range(len(cfg.cmd_index)))
        self._limits = cfg.effort_limits
        self._r = len(cfg.cmd_index)
        if cfg.delay_compensation == 'predict':
            if self.predictor is None or self.predictor.params != cfg.nominal:
                self.predictor = StatePredictor(cfg.nominal, cfg.dt)
        else:
            self.predictor = None

    def keep_state(self):
        """Take the law's state now as the last good one (a fault puts it back)."""
        self._good_state = self.law.save_state()

    def restart_prediction(self):
        """Forget the commands the predictor has (a stop, a reset)."""
        if self.predictor is not None:
            self.predictor.reset()

    def step(self, ns, q, qd, ref, dt, now_ns, monitor, prev_cmd, effort_in):
        """
        Return ``(out, effort, values, fault)`` of one step.

        Parameters
        ----------
        ns : int
            The state's stamp [ns].
        q, qd : tuple of float, (n,)
            The state (the core's angles [rad], rates [rad/s]).
        ref : sequence of float, (3 m,)
            The reference's position, velocity and acceleration.
        dt : float
            The step [s].
        now_ns : int
            System time [ns] (the prediction's horizon).
        monitor : freejoint_control.failures.FailureMonitor or None
            The failure monitor.
        prev_cmd : list of float or None
            The last command sent (command order; None: none).
        effort_in : list of float or None
            The state's efforts in model order (the monitor's), or None.

        Returns
        -------
        out : LawOutput
            The law's output (a fault's: zero terms, the measured position).
        effort : list of float, (r,)
            The command in command order (a fault's: ``prev_cmd`` or zero).
        values : list of float
            The law's state after the step (``state_values``).
        fault : bool
            A law fault.

        """
        law = self.law
        m = self._m
        p_ref = ref[0:m]
        pred = self.predictor
        fault = None
        if monitor is not None:
            monitor.before_law(ns, q, qd, prev_cmd, effort_in)
        try:
            if monitor is not None and monitor.cannot_track:
                out = monitor.least_harm(q, qd, p_ref, self._last_internal())
            elif pred is None:
                out = law.step(q, qd, p_ref, ref[m:2 * m], ref[2 * m:3 * m], dt)
            else:
                out = self._predicted_step(pred, ns, q, qd, ref, dt, now_ns)
        except (FreejointValueError, ArithmeticError) as exc:
            out = None
            fault = 'result (%s: %s)' % (type(exc).__name__, exc)
        if out is not None:
            if monitor is not None:
                out = monitor.after_law(out)
            tau = out.tau.tolist()
            effort = tau if self._identity else [tau[i] for i in self._cmd_index]
            values = law.state_values()
            fault = law_output_fault(effort, self._limits, values, law.state_bounds)
        if fault is not None:
            self.faults += 1
            law.restore_state(self._good_state)
            effort = list(prev_cmd) if prev_cmd is not None else [0.0] * self._r
            self.log(ERROR, 'fault', 'the law gave a non-finite or out-of-range %s: not '
                     'published, law state restored, previous command repeated' % fault)
            out = self._fault_output(q, m)
            values = law.state_values()
        else:
            self._good_state = law.save_state()
        cond = law.conditioning
        self.last_det = out.internal[cond] if cond else 0.0
        return out, effort, values, fault is not None

    def _last_internal(self):
        """Return the internal values of a tick without a law step: the last conditioning."""
        cond = self.law.conditioning
        return {cond: self.last_det} if cond else {}

    def _fault_output(self, q, m):
        """Return the published terms of a tick whose law result was refused."""
        zero = np.zeros(m)
        return LawOutput(np.zeros(self._r), zero, zero, zero, self.law.model.fk(q), 0,
                         self._last_internal())

    def _predicted_step(self, pred, ns, q, qd, ref, dt, now_ns):
        """Run the law on the state predicted to when the command takes effect."""
        age = (now_ns - ns) * 1e-9
        ticks = min(pred.max_ticks, max(1, math.ceil(age / self._dt - 1e-9)))
        m = self._m
        p_d, v_d, a_d = ref[0:m], ref[m:2 * m], ref[2 * m:3 * m]
        try:
            q_pred, qd_pred = pred.predict(q, qd, ticks)
            h = ticks * self._dt
            p, v, a = extrapolate_setpoint(p_d, v_d, a_d, h)
        except FreejointValueError as exc:
            self.log(ERROR, 'predict', 'state prediction failed (%s): the law uses the '
                     'measured state' % exc)
            return self.law.step(q, qd, p_d, v_d, a_d, dt)
        return self.law.step(q_pred, qd_pred, p, v, a, dt)

    def push(self, effort):
        """Record the command sent (command order) in the predictor (model order), if any."""
        if self.predictor is None:
            return
        tau = [0.0] * len(effort)
        for j, i in enumerate(self._cmd_index):
            tau[i] = effort[j]
        self.predictor.push(tau)
