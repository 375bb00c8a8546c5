"""
The interface every control law implements (``freejoint_core.laws`` keeps the registry).

A module defining a law imports :class:`ControlLaw` from here (or from ``laws``, which
re-exports it); ``laws`` imports a law module only when a controller asks for that law.
"""

from dataclasses import dataclass
import math

from freejoint_core.errors import FreejointValueError
import numpy as np

INF = math.inf
"""Unbounded end of a state value's plausible range."""


@dataclass(frozen=True)
class LawGain:
    """
    One gain a law declares beyond the shared task gains (its namespaced schema).

    Attributes
    ----------
    name : str
        ``<law>.<gain>`` (e.g. ``vsc.phi``): the controller parameter and the key of a
        campaign's ``controller`` entry.
    default : float
        Its value unless given.
    description : str
        What it is, with its unit (the parameter's documentation).
    bounds : tuple of float
        Closed range ``(lower, upper)`` of accepted values.

    """

    name: str
    default: float
    description: str
    bounds: tuple = (0.0, INF)

    def reason(self, value):
        """Return why ``value`` is refused ('' when accepted)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f'{self.name}: expected a number, got {value!r}'
        lo, hi = self.bounds
        if not (math.isfinite(value) and lo <= value <= hi):
            return f'{self.name}: expected a finite number in [{lo}, {hi}], got {value!r}'
        return ''


def law_params(law_name, schema, given=None):
    """
    Return a law's own gains: the defaults of ``schema`` updated by ``given``, checked.

    Parameters
    ----------
    law_name : str
        The law's registered name (every key starts with it and a dot).
    schema : sequence of LawGain
        The law's declared gains.
    given : mapping of str to float, optional
        Values by namespaced name; names of other laws are ignored (a configuration
        carries every law's gains), unknown names of this law refused.

    Returns
    -------
    dict of str to float

    Raises
    ------
    FreejointValueError
        Naming the gain: unknown to the law, or out of its range.

    """
    out = {g.name: float(g.default) for g in schema}
    prefix = law_name + '.'
    for key, value in (given or {}).items():
        if not key.startswith(prefix):
            continue
        spec = next((g for g in schema if g.name == key), None)
        if spec is None:
            raise FreejointValueError(
                f'{key}: not a gain of law {law_name!r} (its gains: '
                f'{", ".join(g.name for g in schema) or "none"})')
        problem = spec.reason(value)
        if problem:
            raise FreejointValueError(problem)
        out[key] = float(value)
    return out


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
    gain_schema : tuple of LawGain
        The law's own gains (namespaced ``<name>.<gain>``) beyond the shared ``Gains``
        (``K``, ``Lambda``, the torque limit, the singularity threshold); the registry
        reads it, the node declares them as parameters, a campaign accepts them.
    accelerator : str or None
        The batched campaign kernel registered for the law (``freejoint_core.batch``);
        None: a campaign runs the law through its scalar step (same results, slower).

    """

    name = ''
    state_names = ()
    state_bounds = ()
    gain_schema = ()
    accelerator = None

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

    @property
    def theta(self):
        """Return the law's adaptive estimate (numpy copy; empty: a law without one)."""
        return np.zeros(0)

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


LAWS = {}
"""The registry: law name -> factory ``(nominal, gains, model, **options) -> ControlLaw``."""


def register_law(name, factory):
    """
    Register a control law under ``name`` (the value of the controller's parameter ``law``).

    Parameters
    ----------
    name : str
        Its name, non-empty.
    factory : callable
        ``factory(nominal, gains, model=None)`` returning a :class:`ControlLaw`; with
        ``params=`` its own gains (a factory whose ``gain_schema`` declares them, each
        named ``<name>.<gain>``), and the options a runner passes (``nullspace``).

    Raises
    ------
    FreejointValueError
        An empty name, a factory not callable, or a declared gain outside the law's
        namespace.

    """
    if not isinstance(name, str) or not name:
        raise FreejointValueError(f'name: expected a non-empty string, got {name!r}')
    if not callable(factory):
        raise FreejointValueError(f'factory: expected a callable, got {factory!r}')
    for gain in getattr(factory, 'gain_schema', ()):
        if not gain.name.startswith(name + '.'):
            raise FreejointValueError(
                f'factory: gain {gain.name!r} of law {name!r} is not named {name}.<gain>')
    LAWS[name] = factory
