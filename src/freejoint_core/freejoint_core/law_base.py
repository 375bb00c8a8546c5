"""
The interface every control law implements (``freejoint_core.laws`` keeps the registry).

A module defining a law imports :class:`ControlLaw` from here (or from ``laws``, which
re-exports it); ``laws`` imports a law module only when a controller asks for that law.
"""

import math

INF = math.inf
"""Unbounded end of a state value's plausible range."""


class ControlLaw:
    """
    The interface of a control law (a base class; a law overrides what it has).

    Attributes
    ----------
    name : str
        The name the law is registered under (parameter ``law``).
    state_names : tuple of str
        Names of the values of :meth:`state_values`, in order.
    state_bounds : tuple of (float, float)
        Plausible range of each state value; outside it (or non-finite): a law fault.
    model : ArmModel
        The nominal model of the law (``fk``, ``jacobian``).
    stiffness : float
        The factor of the gains while holding (1: the gains as given).

    """

    name = ''
    state_names = ()
    state_bounds = ()

    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """
        Return the torques of one tick and advance the law's state by ``dt``.

        Parameters
        ----------
        q, qd : sequence of float, (n,)
            Measured joint angles [rad] and velocities [rad/s] (model order).
        p_d, pd_d, pdd_d : sequence of float, (2,)
            Setpoint position [m], velocity [m/s], acceleration [m/s^2].
        dt : float
            Time step [s], > 0.

        Returns
        -------
        ControlOutput
            ``tau`` (r,) [N m] and the law's instrumentation.

        """
        raise NotImplementedError

    def reset(self):
        """Start the law's internal state afresh."""

    def restart_motion(self):
        """
        Forget what describes the motion before a stop (the arm braked, now released).

        The adaptation is kept (what :meth:`reset` would start afresh); a law without
        such state (this base, the paper's) does nothing.
        """

    def state_values(self):
        """Return the law's internal state after the last step, list of float."""
        return []

    def save_state(self):
        """Return a snapshot of the internal state for :meth:`restore_state`."""
        return None

    def restore_state(self, saved):
        """Put back a snapshot of :meth:`save_state`."""

    def set_stiffness(self, scale):
        """Scale the law's gains for a hold (1: as given)."""
        self.stiffness = float(scale)

    def set_nominal(self, params, model=None):
        """Take a new nominal model (next step)."""
        raise NotImplementedError

    def set_gains(self, gains):
        """Take new gains (next step); the state is kept."""
        raise NotImplementedError
