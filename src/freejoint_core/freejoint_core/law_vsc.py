"""
Variable-structure (sliding-mode) Cartesian law, in the manner of Bergerman & Xu.

Reference: M. Bergerman and Y. Xu, "Robust joint and Cartesian control of underactuated
manipulators", ASME J. Dyn. Sys. Meas. Control 118(3), 1996: a sliding surface on the
task error, the end effector driven by the active joints through the dynamics with the
free joints eliminated, the switching gain from a bound of the nominal model's
uncertainty, a boundary layer against chattering.  Registered as ``vsc`` (one module,
one registration; the controller's parameter ``law: vsc``).

Derivation (planar task, m = 2).  The real arm's task dynamics, free joints eliminated
(paper eqs. 4, 5), are ``pdd = Da tau + b + d`` (``d``: the disturbance's effect); the
law knows the nominal ``Da^``, ``b^`` and applies ``tau = Da^# (u - b^)``
(``Da^ Da^# = I``), so that::

    pdd = u + E (u - b^) + (b - b^) + d,        E = Da Da^# - I.

On the surface ``s = edot + Lam e`` (the paper's), with the command
``u = u0 - k sat(s / phi)`` and ``u0 = pdd_d - Lam edot - K s`` (the paper's eq. 16, the
same ``K``, ``Lambda`` as every law here)::

    sdot = -K s - k sat(s / phi) + Delta,      Delta = E (u - b^) + (b - b^) + d.

The uncertainty bound of the same nominal model: the decoupling matrix is known to a
relative error ``||E|| <= delta`` (< 1), the drift and the disturbance to
``||b - b^ + d|| <= beta0 + beta1 ||qd||^2`` (gravity and disturbance; Coriolis and
centrifugal terms, quadratic in the joint rates).  With ``||u - b^|| <= ||u0 - b^|| + k``
the sliding condition ``s^T sdot <= -K ||s||^2 - eta ||s||`` outside the layer holds for
the switching gain::

    k = (delta ||u0 - b^|| + beta0 + beta1 ||qd||^2 + eta) / (1 - delta).

``sat(s / phi) = s / max(||s||, phi)`` (:func:`freejoint_core.task_law.sat`): outside
the boundary layer ``||s|| <= phi`` the unit vector of ``s`` (the ideal switching law,
reaching the layer in finite time), inside it linear (no chattering); in the layer the
tracking error is bounded by about ``phi / Lambda`` (``phi`` 0.1 m/s, ``Lambda`` 50 /s:
2 mm).  The law has no internal state; it reports the switching gain ``k`` [m/s^2] and
``||s|| / phi`` (above 1 outside the layer); its output's internal values
(:data:`INTERNALS`) are ``k``, the switching term ``-k sat(s / phi)`` and ``det``.

Gains (namespaced, :data:`GAINS`): ``vsc.phi`` [m/s], ``vsc.eta`` [m/s^2],
``vsc.delta`` [-], ``vsc.beta0`` [m/s^2], ``vsc.beta1`` [m/rad^2]; the defaults cover the
paper's point (70 % nominal: ``||E||`` about 0.3; 0.5 N m disturbance) with margin.
"""

from freejoint_core.control import DET
from freejoint_core.law_base import INF, LawGain, LawValue, register_law
from freejoint_core.task_law import norm, norm2, sat, TaskLaw

GAINS = (
    LawGain('vsc.phi', 0.1, 'boundary layer of the sliding surface [m/s] (tracking error '
            'within about phi / Lambda)', (1e-6, 100.0)),
    LawGain('vsc.eta', 0.5, 'reaching margin of the switching gain [m/s^2]', (0.0, 1e4)),
    LawGain('vsc.delta', 0.4, 'relative error bound of the nominal decoupling matrix '
            '||Da Da^# - I|| (< 1)', (0.0, 0.95)),
    LawGain('vsc.beta0', 3.0, 'bound of the drift and disturbance error [m/s^2]',
            (0.0, 1e4)),
    LawGain('vsc.beta1', 0.1, 'bound of the velocity-dependent drift error '
            '[m/s^2 per (rad/s)^2]', (0.0, 1e4)),
)
"""The law's own gains (``vsc.*``)."""

INTERNALS = (
    LawValue('switching_gain', (), 'm/s^2', 'switching gain k of this tick'),
    LawValue('switching_term', ('m',), 'm/s^2', 'switching term -k sat(s / phi)'),
    DET,
)
"""The internal values of the law's output."""


class SlidingModeLaw(TaskLaw):
    """
    Bergerman & Xu style sliding-mode Cartesian law (module notes).

    Parameters
    ----------
    nominal, gains, model, params
        As :class:`freejoint_core.task_law.TaskLaw` (``params``: the ``vsc.*`` gains).

    """

    name = 'vsc'
    accelerator = 'vsc'
    gain_schema = GAINS
    internals = INTERNALS
    state_names = ('switching_gain', 'surface_over_layer')
    state_bounds = ((0.0, INF), (0.0, INF))

    def reset(self):
        """No state: the reported values read 0 until a step."""
        self._report = [0.0, 0.0]

    def command(self, q, qd, v, da, b, e, edot, s, u0, pdd_d, dt):
        """Return ``u0 - k sat(s / phi) - b^`` (module notes), ``k`` and the switching term."""
        g = self.params
        delta = g['vsc.delta']
        phi = g['vsc.phi']
        k = (delta * norm(u0 - b) + g['vsc.beta0'] + g['vsc.beta1'] * norm2(qd)
             + g['vsc.eta']) / (1.0 - delta)
        dv = -k * sat(s, phi)
        self._report = [k, norm(s) / phi]
        return u0 + dv - b, {'switching_gain': k, 'switching_term': dv}

    def state_values(self):
        """Return the switching gain [m/s^2] and ``||s|| / phi`` of the last step."""
        return list(self._report)


register_law(SlidingModeLaw.name, SlidingModeLaw)
