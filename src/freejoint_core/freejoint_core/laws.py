"""
The control-law seam: one small interface every control law implements, and its registry.

A law maps one measured state and one task-space setpoint to the active joint torques and
advances its own internal state over ``dt``::

    out = law.step(q, qd, p_d, pd_d, pdd_d, dt)        # LawOutput

The output (:class:`freejoint_core.law_base.LawOutput`) is the same for every law: the
torque, the task error, its rate and surface, the measured position, the status bits, and
``out.internal``, the values the law declares in ``law.internals`` (name, shape, unit),
read by name (``law.conditioning`` names the one reported as the task's conditioning).
Its internal state is explicit: ``law.state_names`` name the values ``law.state_values()``
returns (reported generically, so that a second law needs no message change), and
``law.save_state()`` / ``law.restore_state(saved)`` take and put back a snapshot (the
control loop restores the last good one after a law fault). ``law.reset()`` starts the
state afresh; ``law.model`` is the nominal model the law uses (forward kinematics of the
measured state), ``law.stiffness`` the hold stiffness scale it runs at
(``law.set_stiffness``); ``set_nominal`` / ``set_gains`` take a new nominal model or new
gains (effective on the next step). ``law.state_bounds`` gives each state value's
plausible range ``(lower, upper)``: a value outside it (or non-finite) is a law fault.

The paper's law (:class:`RobustLaw`, ``RobustController`` of ``freejoint_core.control``,
same numbers) is registered as ``'robust'``; :func:`register_law` adds another law (one
module defining it and calling ``register_law``), :func:`make_law` builds the one a
controller's parameter ``law`` names.  :class:`FreeLinkDampedLaw` wraps a law so that its
reference passes through the free link's damping first (the controller's parameter
``free_link_damping``).

"""

from dataclasses import replace

from freejoint_core.arm import ArmModel
from freejoint_core.control import RobustController
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import FreeLinkModulation, NullSpace
from freejoint_core.law_base import ControlLaw, INF, LawOutput, LAWS, LawValue, register_law

__all__ = ('ControlLaw', 'FreeLinkDampedLaw', 'gain_schema', 'INF', 'LAWS', 'LawOutput',
           'LawValue', 'make_law', 'register_law', 'RobustLaw')


class RobustLaw(RobustController, ControlLaw):
    """
    The paper's robust law with sigma-modified adaptation (``RobustController``).

    State: ``theta_hat[0..4]`` (after the tick's update), ``rho_hat`` (used in the tick)
    and ``delta_v[0..m-1]`` (the robust term [m/s^2], m the model's task dimension);
    ``theta_hat`` within ``[0, gains.theta_max]``.

    Options beyond ``RobustController``'s (``nullspace``, ``use_fast``): ``nullspace_kd``
    [N m s/rad], the null-space damping ``NullSpace(kd=nullspace_kd)`` while the nominal
    arm drives more joints than the task has (r > 2: installed, and dropped while a failure
    leaves r = 2); ``nullspace_kp`` must be 0 (no posture term on a planar arm).
    """

    name = 'robust'
    accelerator = 'robust'

    def __init__(self, nominal_params, gains=None, model=None, nullspace=None, use_fast=True,
                 nullspace_kd=None, nullspace_kp=0.0):
        self._last = None
        if nullspace_kp:
            raise FreejointValueError(f"nullspace_kp: law 'robust' (a planar arm) has no "
                                      f'posture term; expected 0, got {nullspace_kp!r}')
        # The null-space damping nullspace_kd: on an arm with driven joints to spare only,
        # dropped and put back as set_nominal's arm has them (a joint failing, its release).
        self._spare_nullspace = None if nullspace is not None or nullspace_kd is None \
            else NullSpace(kd=nullspace_kd)
        super().__init__(nominal_params, gains, use_fast=use_fast, model=model,
                         nullspace=nullspace)
        self.state_names = _robust_state_names(self.model.task_dim)

    def set_nominal(self, params, model=None):
        """Take a new nominal model (``RobustController.set_nominal``), the null space its."""
        if self._spare_nullspace is not None:
            self.nullspace = self._spare_nullspace if params.r > ArmModel.task_dim else None
        super().set_nominal(params, model)

    def set_gains(self, gains):
        """Install new gains (``RobustController.set_gains``) and the state's bounds."""
        super().set_gains(gains)
        tmax = gains.theta_max if gains.theta_max is not None else (INF,) * 5
        self.state_bounds = tuple((0.0, t) for t in tmax) + (
            (-INF, INF),) * (1 + self.model.task_dim)

    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """Return ``RobustController.step`` (the paper's law) and keep it for the state."""
        out = RobustController.step(self, q, qd, p_d, pd_d, pdd_d, dt)
        self._last = out
        return out

    def reset(self):
        """Set theta_hat back to ``gains.theta0``."""
        RobustController.reset(self)
        self._last = None

    def state_values(self):
        """Return theta_hat (5, now), rho_hat and delta_v (m) of the last step (or 0)."""
        out = self._last
        if out is None:
            return list(self._theta) + [0.0] * (1 + self.model.task_dim)
        internal = out.internal
        return list(self._theta) + [internal['rho_hat']] + internal['delta_v'].tolist()

    def save_state(self):
        """Return theta_hat (a tuple)."""
        return tuple(self._theta)

    def restore_state(self, saved):
        """Put theta_hat back (``set_theta``); rho_hat and delta_v read 0 until a step."""
        self.set_theta(saved)
        self._last = None


def _robust_state_names(m):
    """Return the names of the paper's law's state for task dimension ``m``."""
    return tuple('theta_hat[%d]' % i for i in range(5)) + ('rho_hat',) + tuple(
        'delta_v[%d]' % i for i in range(m))


def gain_schema():
    """Return every registered law's own gains (``LawGain``), in registration order."""
    return tuple(g for factory in LAWS.values() for g in getattr(factory, 'gain_schema', ()))


def make_law(name, nominal, gains, model=None, params=None, free_link=None, **options):
    """
    Build the control law registered as ``name``.

    Parameters
    ----------
    name : str
        A registered law (:data:`LAWS`).
    nominal : ArmParams
        Nominal parameters of the arm.
    gains : Gains
        The gains.
    model : ArmModel, optional
        The nominal model's implementation (default: the law's choice).
    params : mapping of str to float, optional
        Laws' own gains by namespaced name (``vsc.phi``); the ones of law ``name`` are
        passed to it (``params=``), the others ignored.
    free_link : mapping, optional
        The free link's damping: the law wrapped in :class:`FreeLinkDampedLaw` of these
        keywords (``delta_max`` and ``FreeLinkModulation``'s); None: none.
    **options
        Passed to the factory (e.g. ``nullspace`` of the paper's law, ``nullspace_kd``
        and ``nullspace_kp`` of the controller's parameters).

    Returns
    -------
    ControlLaw

    Raises
    ------
    FreejointValueError
        If no law is registered as ``name``, or its own gains are refused.

    """
    factory = LAWS.get(name)
    if factory is None:
        raise FreejointValueError(f'law: expected one of {tuple(LAWS)}, got {name!r}')
    own = {k: v for k, v in (params or {}).items() if k.startswith(name + '.')}
    if own:
        if not getattr(factory, 'gain_schema', ()):
            raise FreejointValueError(f'{next(iter(own))}: law {name!r} has no gains of its own')
        options['params'] = own
    law = factory(nominal, gains, model=model, **options)
    return law if free_link is None else FreeLinkDampedLaw(law, **free_link)


register_law(RobustLaw.name, RobustLaw)


def _spatial_law(nominal, gains, model=None, nullspace=None, free_damping=None,
                 nullspace_kd=0.0, nullspace_kp=0.0):
    """
    Build the spatial law (``freejoint_core.spatial_law``, imported on first use).

    ``SpatialControlLaw`` (the controller's, its null space of ``nullspace_kd`` and
    ``nullspace_kp``); with ``nullspace`` or ``free_damping`` the study's ``SpatialLaw`` of
    those options (the offline runner's, the planner's nominal closed loop).
    """
    if nullspace is None and free_damping is None:
        from freejoint_core.spatial_law import SpatialControlLaw
        return SpatialControlLaw(nominal, gains, model, nullspace_kd, nullspace_kp)
    from freejoint_core.spatial_law import SpatialLaw
    return SpatialLaw(nominal, gains, nullspace, free_damping=free_damping or 0.0)


register_law('spatial', _spatial_law)


class FreeLinkDampedLaw(ControlLaw):
    """
    A law whose reference passes through the free link's damping first (r = m).

    Each step the setpoint goes through
    :class:`freejoint_core.internal.FreeLinkModulation` (the bounded shift ``delta`` of the
    reference, ``|delta| <= delta_max``) and the wrapped law tracks the modulated one: what
    ``freejoint_core.circles.run_circles`` computes with ``stabilise``.  Everything else
    is the wrapped law's (``gains`` and ``nullspace`` read and set through); its state
    gains ``free_link_delta[0..1]`` (the shift [m] after the step), saved and restored
    with the law's.

    While the wrapped law's nominal arm does not have its last joint alone free (a fully
    actuated arm before a joint fails) the modulation is off: the wrapped law's
    step exactly, the shift 0.  :meth:`set_nominal` with such an arm (the failure
    monitor's switch) turns it on, its shift from 0, as
    ``freejoint_core.failure_offline.run_failure_case`` with ``free_link_damping`` does.

    Parameters
    ----------
    law : ControlLaw
        The wrapped law: its nominal arm with the last joint alone free (r = m = 2), or
        one a joint failure can bring there.
    delta_max : float
        Bound of the reference's shift [m], > 0.
    **options
        Further keywords of ``FreeLinkModulation`` (its defaults otherwise).

    Raises
    ------
    FreejointValueError
        Options ``FreeLinkModulation`` refuses (checked on the arm with its last joint
        free, whichever arm the wrapped law has now).

    """

    def __init__(self, law, delta_max, **options):
        self.law = law
        self._options = dict(options, delta_max=delta_max)
        nominal = law.nominal
        last_free = replace(nominal, passive=(nominal.n - 1,))
        self._bound = FreeLinkModulation(last_free, **self._options).delta_max
        self.modulation = self._modulation_for(nominal)
        self.name = law.name
        self.internals, self.conditioning = law.internals, law.conditioning   # its output's
        self.state_names = tuple(law.state_names) + ('free_link_delta[0]',
                                                     'free_link_delta[1]')

    def _modulation_for(self, nominal):
        """Return the modulation of ``nominal`` (None unless its last joint alone is free)."""
        if nominal.passive != (nominal.n - 1,) or nominal.r != 2:
            return None
        return FreeLinkModulation(nominal, **self._options)

    @property
    def state_bounds(self):
        """Return the wrapped law's bounds and the shift's (its disc, 1 % slack)."""
        d = 1.01 * self._bound
        return tuple(self.law.state_bounds) + ((-d, d), (-d, d))

    @property
    def model(self):
        """Return the wrapped law's nominal model."""
        return self.law.model

    @property
    def nominal(self):
        """Return the wrapped law's nominal parameters."""
        return self.law.nominal

    @property
    def gains(self):
        """Return the wrapped law's gains."""
        return self.law.gains

    @property
    def nullspace(self):
        """Return the wrapped law's null-space option (None: none, or a law without one)."""
        return getattr(self.law, 'nullspace', None)

    @nullspace.setter
    def nullspace(self, value):
        self.law.nullspace = value

    @property
    def stiffness(self):
        """Return the wrapped law's hold stiffness scale."""
        return self.law.stiffness

    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """Modulate the setpoint (``FreeLinkModulation.step``), then step the wrapped law."""
        if self.modulation is None:
            return self.law.step(q, qd, p_d, pd_d, pdd_d, dt)
        p_m, pd_m, pdd_m = self.modulation.step(q, qd, p_d, pd_d, pdd_d, dt)
        return self.law.step(q, qd, p_m, pd_m, pdd_m, dt)

    def reset(self):
        """Reset the wrapped law and the modulation (``delta`` = 0)."""
        self.law.reset()
        if self.modulation is not None:
            self.modulation.reset()

    def restart_motion(self):
        """
        Start the shift from 0 (the arm was braked); the wrapped law restarts too.

        The shift and its rate damped a swing the brake ended; kept, they would put the
        reference up to ``delta_max`` off the braked arm at the first tick after it.
        """
        self.law.restart_motion()
        if self.modulation is not None:
            self.modulation.reset()

    def state_values(self):
        """Return the wrapped law's state and the shift ``delta`` (2) [m] (0 while off)."""
        delta = [0.0, 0.0] if self.modulation is None else self.modulation.delta.tolist()
        return list(self.law.state_values()) + delta

    def save_state(self):
        """Return the wrapped law's snapshot and the modulation's (None while off)."""
        return (self.law.save_state(),
                None if self.modulation is None else self.modulation.snapshot())

    def restore_state(self, saved):
        """Put both snapshots back (the modulation's where it is on now and was then)."""
        self.law.restore_state(saved[0])
        if self.modulation is not None and saved[1] is not None:
            self.modulation.restore(saved[1])

    def set_stiffness(self, scale):
        """Scale the wrapped law's gains for a hold."""
        self.law.set_stiffness(scale)

    def set_nominal(self, params, model=None):
        """
        Give the wrapped law and the modulation a new nominal arm.

        The shift is kept while the modulation stays on; it starts from 0 when this turns
        it on (a failure left the last joint alone free), and is dropped when this turns
        it off.
        """
        saved = None if self.modulation is None else self.modulation.snapshot()
        modulation = self._modulation_for(params)
        self.law.set_nominal(params, model)
        if modulation is not None and saved is not None:
            modulation.restore(saved)
        self.modulation = modulation

    def set_gains(self, gains):
        """Give the wrapped law new gains."""
        self.law.set_gains(gains)


# The laws from the literature shipped with the stack, after the paper's (each module
# registers itself).
from freejoint_core import law_tdc, law_vsc  # noqa: E402,F401,I100,I202
