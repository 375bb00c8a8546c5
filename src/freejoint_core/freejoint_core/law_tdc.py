"""
Time-delay control (TDC) in task space, after Youcef-Toumi & Ito and Hsia.

References: K. Youcef-Toumi and O. Ito, "A time delay controller for systems with
unknown dynamics", ASME J. Dyn. Sys. Meas. Control 112(1), 1990; T. C. Hsia and
L. S. Gao, "Robot manipulator control using decentralized linear time-invariant
time-delayed joint controllers", IEEE ICRA 1990.  Registered as ``tdc`` (one module, one
registration; the controller's parameter ``law: tdc``).

Idea: write the task dynamics with the free joints eliminated (paper eqs. 4, 5) as
``pdd = Dbar tau + N``, ``Dbar = Da^ / mbar`` the nominal decoupling matrix (``mbar``
scales the assumed inertia, 1: the nominal model's) and ``N`` everything else (the
drift, the model's error, the disturbance).  ``N`` varies slowly against the control
rate, so it is estimated from the previous tick, where the acceleration is measured as
the change of the task velocity ``J qd`` over the period the previous torque acted::

    N^_k = (J qd)_k - (J qd)_{k-1}) / dt - Dbar(q_k) tau_{k-1}     (time-delay estimate)
    tau_k = Dbar# (u0 - N^f_k) = mbar Da^# (u0 - N^f_k)

with ``u0 = pdd_d - Lam edot - K s`` (the paper's eq. 16, the same ``K``, ``Lambda`` as
every law here) and ``N^f`` the estimate through a first-order low-pass of time constant
``tdc.filter`` [s] (0: none; the measured acceleration differentiates the rate noise).
The first tick after a start or a stop has no previous tick: ``N^ = b^`` (the nominal
drift; the tick is the nominal computed torque).  With the real ``Da``, the error
dynamics are ``sdot = -K s + (I - Da Dbar^#)(...)``: the estimate converges when
``||I - Da Dbar^#|| < 1`` (70 % nominal: about 0.3).  The law is exact for a model error
of any size in the limit of a fast loop, and sensitive to what its one-tick-old estimate
does not see: delay, actuator lag, rate noise.

State: ``n_hat[0..1]`` (the filtered estimate [m/s^2]); the previous task velocity and
torque are kept with it (saved, restored; :meth:`TimeDelayLaw.restart_motion` forgets
them).  Gains (:data:`GAINS`): ``tdc.mbar``, ``tdc.filter``.
"""

import math

from freejoint_core.control import DET
from freejoint_core.law_base import INF, LawGain, LawValue, register_law
from freejoint_core.task_law import dot, TaskLaw
import numpy as np

GAINS = (
    LawGain('tdc.mbar', 1.0, 'scale of the assumed inertia: Dbar = Da^ / mbar (1: the '
            'nominal model)', (0.1, 10.0)),
    LawGain('tdc.filter', 0.002, 'time constant of the low-pass on the time-delay '
            'estimate [s] (0: none)', (0.0, 1.0)),
)
"""The law's own gains (``tdc.*``)."""

INTERNALS = (
    LawValue('n_hat', ('m',), 'm/s^2', 'filtered time-delay estimate N^f used this tick'),
    DET,
)
"""The internal values of the law's output."""


class TimeDelayLaw(TaskLaw):
    """
    Task-space time-delay control (module notes).

    Parameters
    ----------
    nominal, gains, model, params
        As :class:`freejoint_core.task_law.TaskLaw` (``params``: the ``tdc.*`` gains).

    """

    name = 'tdc'
    accelerator = 'tdc'
    gain_schema = GAINS
    internals = INTERNALS
    state_names = ('n_hat[0]', 'n_hat[1]')
    state_bounds = ((-INF, INF), (-INF, INF))

    def reset(self):
        """Start without an estimate and without a previous tick."""
        self._n_hat = None
        self._prev = None
        self._v = None

    def restart_motion(self):
        """Start the next tick from the nominal drift again (the arm was braked)."""
        self.reset()

    def command(self, q, qd, v, da, b, e, edot, s, u0, pdd_d, dt):
        """Return ``mbar (u0 - N^f)`` (module notes) and ``N^f``."""
        mbar = self.params['tdc.mbar']
        if self._prev is None:
            n_hat = b
        else:
            v_prev, tau_prev = self._prev
            tau = tau_prev.tolist()
            n_raw = (v - v_prev) / dt - np.array([dot(row, tau) for row in da.tolist()]) / mbar
            tc = self.params['tdc.filter']
            a = 1.0 - math.exp(-dt / tc) if tc > 0.0 else 1.0
            n_hat = self._n_hat + a * (n_raw - self._n_hat)
        self._n_hat = n_hat
        self._v = v
        return mbar * (u0 - n_hat), {'n_hat': n_hat.copy()}

    def applied(self, tau, da):
        """Keep the torque and the task velocity of this tick for the next estimate."""
        self._prev = (self._v, tau.copy())

    def state_values(self):
        """Return the filtered estimate ``N^f`` [m/s^2] (0 before the first step)."""
        return [0.0, 0.0] if self._n_hat is None else self._n_hat.tolist()

    def save_state(self):
        """Return the estimate and the previous tick."""
        return (self._n_hat, self._prev, self._v)

    def restore_state(self, saved):
        """Put back a :meth:`save_state` snapshot."""
        self._n_hat, self._prev, self._v = saved


register_law(TimeDelayLaw.name, TimeDelayLaw)
