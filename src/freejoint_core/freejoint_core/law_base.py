"""
The interface every control law implements (``freejoint_core.laws`` keeps the registry).

A module defining a law imports :class:`ControlLaw` from here (or from ``laws``, which
re-exports it); ``laws`` imports a law module only when a controller asks for that law.
Every law's step returns a :class:`LawOutput`: the generic fields and the internal values
the law declares (:class:`LawValue`); :class:`RunValues` reads what a run reports of them.
"""

from dataclasses import dataclass
import math
from typing import NamedTuple

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


@dataclass(frozen=True)
class LawValue:
    """
    One internal value a law declares: a key of its output's ``internal``.

    Attributes
    ----------
    name : str
        The key (e.g. ``theta_hat``, ``det``).
    shape : tuple
        Its shape: ``()`` a float, ``(5,)`` an array of 5, ``('m',)`` an array of the
        task dimension m.
    unit : str
        Its unit (``-``: none).
    description : str
        What it is.

    """

    name: str
    shape: tuple
    unit: str
    description: str


class LawOutput(NamedTuple):
    """
    One tick of a control law (arrays fresh, owned by the caller).

    Attributes
    ----------
    tau : numpy.ndarray, (r,)
        Active joint torques [N m] (after the law's torque limit).
    e, edot, s : numpy.ndarray, (m,)
        Task error ``p - p_d`` [m] (a spatial arm with m = 6: then [rad]), its rate
        [m/s], the surface ``s = edot + Lam e``.
    p : numpy.ndarray, (m,) or (3,)
        Measured end-effector position [m] (the nominal model's forward kinematics).
    status : int
        Bitmask of ``freejoint_core.control.STATUS_*``.
    internal : dict of str to float or numpy.ndarray
        The law's internal values of this tick, keyed and ordered as the law's
        ``internals`` declare them (:class:`LawValue`: name, shape, unit).

    """

    tau: np.ndarray
    e: np.ndarray
    edot: np.ndarray
    s: np.ndarray
    p: np.ndarray
    status: int
    internal: dict


def finite_internal(internal):
    """Return True when every value of ``LawOutput.internal`` (float or array) is finite."""
    isfinite = math.isfinite
    for value in internal.values():
        if type(value) is np.ndarray:
            if not all(map(isfinite, value.tolist())):
                return False
        elif not isfinite(value):
            return False
    return True


def internal_size(law, name):
    """
    Return the size of the internal value ``name`` the law declares (None: not declared).

    Parameters
    ----------
    law : ControlLaw
        A law (its ``internals``).
    name : str
        The value's name (e.g. ``theta_hat``).

    Returns
    -------
    int or None
        1 for a float, k for an array of shape (k,), the task dimension for ``('m',)``.

    """
    for value in getattr(law, 'internals', ()):
        if value.name == name:
            if not value.shape:
                return 1
            size = value.shape[0]
            return law.model.task_dim if size == 'm' else int(size)
    return None


class RunValues:
    """
    What a run reports of a law's outputs, read from its declared internal values by name.

    The adaptive estimate ``theta_hat`` (the record's ``theta_final``; empty for a law that
    does not declare it) and the conditioning ``law.conditioning`` names (the record's
    ``min_det``; 0 for a law without one).

    Parameters
    ----------
    law : ControlLaw
        The run's law (its ``internals``, ``conditioning``).

    Attributes
    ----------
    theta_size : int
        Size of ``theta_hat`` (0: not declared).

    """

    def __init__(self, law):
        self.theta_size = internal_size(law, 'theta_hat') or 0
        self._cond = getattr(law, 'conditioning', None)
        self._empty = np.zeros(0)

    def theta(self, out):
        """Return ``theta_hat`` of ``out`` (numpy, (k,); empty when not declared)."""
        return out.internal['theta_hat'] if self.theta_size else self._empty

    def conditioning(self, out):
        """Return the conditioning of ``out`` (float; 0.0 when the law has none)."""
        return out.internal[self._cond] if self._cond else 0.0


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
    internals : tuple of LawValue
        The internal values of its output (``LawOutput.internal``), in order, each
        declared once (name, shape, unit); the loop, the runners and the metrics read
        them by name (``theta_hat``: the adaptive estimate a run reports at its end).
    conditioning : str or None
        The name of the internal value measuring how far the nominal task is from a
        singularity (``ControllerState.det_dd``, the metrics' ``min_det``); None: the
        law has none (reported as 0).

    """

    name = ''
    state_names = ()
    state_bounds = ()
    gain_schema = ()
    accelerator = None
    internals = ()
    conditioning = None

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
        LawOutput
            ``tau`` (r,) [N m], the task error, and the internal values the law declares
            (``internals``).

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
