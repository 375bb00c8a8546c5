"""
Robust Cartesian control law for free-joint manipulators (paper eqs. 15-19).

One tick at t_k, with the measured state (q, qd) and the setpoint
(p_d, pd_d, pdd_d)::

    e   = p - p_d,             edot = J qd - pd_d,        s = edot + Lam e
    v   = pdd_d - (K + Lam) edot - K Lam e                            (16)
    a   = R s,   h = ||a|| + eps ('sum', the paper's) or
                 h = ||a|| if ||a|| > eps else eps ('sat')
    psi = (1, ||qd||^2, ||pdd_d||, ||edot||, ||e||)                    (18)
    rho = theta^T psi,         dv = -rho a / h                         (17)
    tau = Da#(v + dv - b),     Da# = Da^T (Da Da^T)^-1                  (15)

with ``Da``, ``b`` (eqs. 4, 5) from the NOMINAL parameters, and the
adaptation law (19) ``theta_dot = Gamma (psi ||a||^2 / h - sigma theta)``.

Timing of the adaptation: the torque of tick k uses ``theta_k`` (the estimate
before the update).  Then (19) is advanced over ``dt`` with its input
``u = psi_k ||a_k||^2 / h_k`` held (zero-order hold, like the torque), by the
exact solution of the linear low-pass, per component::

    theta_{k+1} = exp(-Gamma sigma dt) theta_k + (1 - exp(-Gamma sigma dt)) u / sigma
    theta_{k+1} = theta_k + Gamma u dt                      (sigma = 0)

a convex combination of ``theta_k >= 0`` and ``u / sigma >= 0``, so
``theta >= 0`` holds exactly for ``theta(0) >= 0`` for any dt (Remark 2).
The output's ``theta_hat`` (:data:`ROBUST_INTERNALS`) is ``theta_{k+1}``.

Beyond the paper (Assumption 2 may fail): when ``|det(Da Da^T)| <
det_threshold`` the pseudoinverse is replaced by damped least squares
``Da^T (Da Da^T + lam2 I)^-1``, with the smallest ``lam2 >= 0`` for which
``det(Da Da^T + lam2 I) = det_threshold``:

    lam2 = 2 (thr - det) / (tr + sqrt(tr^2 + 4 (thr - det))),  tr = trace(Da Da^T).

It equals the exact pseudoinverse as ``det -> thr`` (continuous switch) and is
bounded: the singular values ``sig_i / (sig_i^2 + lam2)`` of the fallback
satisfy ``||Da#|| <= sqrt((||Da||_F^2 + sqrt(thr)) / thr)`` whatever the
configuration (same order as the exact inverse at the threshold).  The tick
then reports ``STATUS_NEAR_SINGULAR``.  An optional per-joint torque limit
clips ``tau`` and reports ``STATUS_TORQUE_LIMITED``; an optional element-wise bound
``theta_max`` clamps ``theta_{k+1}`` (a non-finite value passes through, for the caller
to detect).

Hot path: for the 3-link arm with one passive joint (``fast3.Arm3Model``,
r = 2) the tick is scalar Python floats (no numpy call except building the
output arrays); so is it for the 3-link arm with every joint driven (r = 3: the
pseudo-inverse ``Da^T (Da Da^T)^-1`` and, with a null-space term, the kinematic
projector ``I - Da# Da``, from ``Arm3Model``'s closed forms); any other arm, option
(``NullSpace`` with the weighted inverse or the dynamic projector) or
``use_fast=False`` uses the general numpy path, which computes the same law (tests check
they agree to round-off).

"""

from dataclasses import dataclass
import math

from freejoint_core.arm import ArmModel, ArmParams, check_vector, number_or_numbers
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import NullSpace, projector, weighted_inverse
from freejoint_core.law_base import LawOutput, LawValue
from freejoint_core.models import make_model
import numpy as np

STATUS_OK = 0
STATUS_NEAR_SINGULAR = 1
STATUS_TORQUE_LIMITED = 2
STATUS_STALE_STATE = 4
STATUS_STALE_SETPOINT = 8
STATUS_BAD_INPUT = 16

H_FORMS = ('sum', 'sat')

_isfinite = math.isfinite
_sqrt = math.sqrt


def _vector(value, n, name, lower, strict):
    """Validate a gain vector: scalar (broadcast) or n numbers, bounded below."""
    vals, scalar = number_or_numbers(value, name, f'a number or {n} numbers')
    if scalar:
        vals *= n
    if len(vals) != n:
        raise FreejointValueError(f'{name}: expected shape ({n},), got ({len(vals)},)')
    for v in vals:
        if not _isfinite(v) or v < lower or (strict and v == lower):
            cmp = '>' if strict else '>='
            raise FreejointValueError(f'{name}: values must be finite and {cmp} {lower}, '
                                      f'got {vals}')
    return vals


@dataclass(frozen=True)
class Gains:
    """
    Controller gains (paper Sec. 4 defaults).

    Attributes
    ----------
    K, Lambda, R : tuple of float, (m,)
        Diagonals of K, Lambda, R, > 0 (a scalar is broadcast), m = ``task_dim``.
    Gamma, sigma : tuple of float, (5,)
        Diagonals of the adaptation gain and sigma-modification, >= 0.
    epsilon : float
        Chattering bound epsilon of h_alpha, > 0.
    h_form : {'sum', 'sat'}
        'sum': ``h = ||a|| + epsilon`` (paper); 'sat': ``max(||a||, epsilon)``.
    theta0 : tuple of float, (5,)
        Initial estimate, >= 0 (used at construction and by ``reset``).
    robust : bool
        False: ``dv = 0`` and no adaptation (plain nominal inverse dynamics).
    det_threshold : float
        Fallback threshold on ``|det(Da Da^T)|``, > 0 (paper's eps_d).
    tau_limit : None, float or tuple of float, (r,)
        Per-joint torque limit [N m], > 0; None disables it.
    theta_max : None, float or tuple of float, (5,)
        Element-wise upper bound of theta_hat, > 0, applied inside the update
        (``theta_{k+1} = min(theta_{k+1}, theta_max)``); None disables it.
    task_dim : int
        Task dimension m the task-space gains are sized by (2: the planar arms); a law
        refuses gains of another m than its model's.

    """

    K: object = 100.0
    Lambda: object = 50.0
    R: object = 2.0
    Gamma: tuple = (0.01,) * 5
    sigma: tuple = (0.1,) * 5
    epsilon: float = 0.1
    h_form: str = 'sum'
    theta0: tuple = (0.0,) * 5
    robust: bool = True
    det_threshold: float = 1e-7
    tau_limit: object = None
    theta_max: object = None
    task_dim: int = 2

    def __post_init__(self):
        """Validate and normalise to tuples of floats."""
        m = self.task_dim
        if not isinstance(m, (int, np.integer)) or isinstance(m, bool) or m < 1:
            raise FreejointValueError(f'task_dim: expected an int >= 1, got {m!r}')
        object.__setattr__(self, 'task_dim', int(m))
        for name, n, lower, strict in (('K', m, 0.0, True), ('Lambda', m, 0.0, True),
                                       ('R', m, 0.0, True), ('Gamma', 5, 0.0, False),
                                       ('sigma', 5, 0.0, False), ('theta0', 5, 0.0, False)):
            object.__setattr__(self, name, _vector(getattr(self, name), n, name, lower, strict))
        for name in ('epsilon', 'det_threshold'):
            object.__setattr__(self, name, _vector(getattr(self, name), 1, name, 0.0, True)[0])
        if self.h_form not in H_FORMS:
            raise FreejointValueError(f'h_form: expected one of {H_FORMS}, got {self.h_form!r}')
        if not isinstance(self.robust, (bool, np.bool_)):
            raise FreejointValueError(f'robust: expected a bool, got {self.robust!r}')
        object.__setattr__(self, 'robust', bool(self.robust))
        lim = self.tau_limit
        if lim is not None:
            if isinstance(lim, (int, float, np.integer, np.floating)) and not isinstance(
                    lim, bool):
                lim = float(lim)
                if not _isfinite(lim) or lim <= 0.0:
                    raise FreejointValueError(f'tau_limit: must be finite and > 0, got {lim}')
            else:
                try:
                    n = len(lim)
                except TypeError as exc:
                    raise FreejointValueError(
                        f'tau_limit: expected None, a number or r numbers, got {lim!r}') from exc
                lim = _vector(lim, n, 'tau_limit', 0.0, True)
            object.__setattr__(self, 'tau_limit', lim)
        if self.theta_max is not None:
            object.__setattr__(self, 'theta_max',
                               _vector(self.theta_max, 5, 'theta_max', 0.0, True))


DET = LawValue('det', (), 'model units', '|det(Da Da^T)| of the nominal model, before any '
               'damping (its conditioning: near 0, near a singularity)')
"""The conditioning value of a planar law that inverts ``Da Da^T``."""

ROBUST_INTERNALS = (
    LawValue('theta_hat', (5,), '-', "adaptive estimate after this tick's update, eq. 19 "
             '(the torque used the one before)'),
    LawValue('rho_hat', (), 'm/s^2', 'robust gain theta_hat^T psi used this tick (0 when '
             'robust is False)'),
    LawValue('delta_v', ('m',), 'm/s^2', 'robust term, eq. 17'),
    DET,
)
"""The internal values of the paper's law (``LawOutput.internal``)."""


def stiffness_scale(scale):
    """
    Return a hold stiffness scale as a float (``set_stiffness`` of the laws).

    Raises
    ------
    FreejointValueError
        If ``scale`` is not finite and > 0.

    """
    value = float(scale)
    if not (math.isfinite(value) and value > 0.0):
        raise FreejointValueError(f'scale: must be finite and > 0, got {scale!r}')
    return value


def clip_torque(tau, limit):
    """
    Return ``tau`` within ``[-limit, limit]`` and ``STATUS_TORQUE_LIMITED`` if it clipped.

    Parameters
    ----------
    tau : numpy.ndarray, (r,)
        Torques [N m].
    limit : None or sequence of float, (r,)
        Per-joint limits [N m], > 0; None: ``tau`` as is, status 0.

    """
    if limit is None:
        return tau, 0
    lim = np.array(limit)
    clipped = np.clip(tau, -lim, lim)
    return clipped, STATUS_TORQUE_LIMITED if np.any(clipped != tau) else 0


def _bad(name, value, n):
    shape = np.shape(value) if not isinstance(value, (str, bytes)) else '?'
    return FreejointValueError(
        f'{name}: expected {n} finite numbers (shape ({n},)), got {value!r} with shape {shape}')


def _vec2(x, name):
    """Two finite floats from a sequence or ndarray (no numpy math)."""
    if type(x) is np.ndarray:
        x = x.tolist()
    try:
        a, b = x
        if _isfinite(a) and _isfinite(b):
            return a, b
    except (TypeError, ValueError):
        pass
    raise _bad(name, x, 2)


def _vec3(x, name):
    """Three finite floats from a sequence or ndarray (no numpy math)."""
    if type(x) is np.ndarray:
        x = x.tolist()
    try:
        a, b, c = x
        if _isfinite(a) and _isfinite(b) and _isfinite(c):
            return a, b, c
    except (TypeError, ValueError):
        pass
    raise _bad(name, x, 3)


def decay_coefficients(gamma, sigma, dt):
    """
    Return the exact zero-order-hold step of the adaptation (19), per component.

    ``theta <- a_i theta + c_i u_i`` with ``a_i = exp(-Gamma_i sigma_i dt)``,
    ``c_i = (1 - a_i) / sigma_i`` (``sigma_i = 0``: ``a_i = 1``, ``c_i = Gamma_i dt``).

    Parameters
    ----------
    gamma, sigma : sequence of float, (5,)
        Diagonals of Gamma and sigma.
    dt : float
        Step [s].

    Returns
    -------
    tuple of (float, float), (5,)

    """
    coef = []
    for g, sg in zip(gamma, sigma):
        if sg > 0.0:
            a = math.exp(-g * sg * dt)
            coef.append((a, (1.0 - a) / sg))
        else:
            coef.append((1.0, g * dt))
    return tuple(coef)


def _dot(u, v):
    """Return ``u . v`` of two or three floats, summed left to right."""
    if len(u) == 2:
        return u[0] * v[0] + u[1] * v[1]
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _dls_lambda2(det, trace, thr):
    """Smallest lam2 >= 0 with det(A + lam2 I) = thr for a 2x2 PSD A (det < thr)."""
    gap = thr - det
    return 2.0 * gap / (trace + _sqrt(trace * trace + 4.0 * gap))


class HoldStiffness:
    """A law whose hold scales its ``K`` and ``Lambda`` (``_scale_gains`` caches them)."""

    def set_stiffness(self, scale):
        """
        Scale K and Lambda by ``scale`` from the next step (1: the gains as given).

        Holding a point against a constant model error ``eta`` [m/s^2], the law's static
        error is ``eta / (K Lambda)``: ``scale`` 2 quarters it (a stiffer hold).  The step
        then equals a law built with ``K * scale`` and ``Lambda * scale`` exactly.

        Parameters
        ----------
        scale : float
            Factor, finite and > 0; ``scale * (K + Lambda)`` should stay well below
            ``1 / dt`` (the caller's parameters check it).

        Raises
        ------
        FreejointValueError
            If ``scale`` is not finite and > 0.

        """
        self.stiffness = stiffness_scale(scale)
        self._scale_gains()


class RobustController(HoldStiffness):
    """
    The paper's robust controller with sigma-modified adaptation.

    Parameters
    ----------
    nominal_params : ArmParams
        Guessed (nominal) parameters used for ``Da`` and ``b`` (Table I: 70 %).
    gains : Gains
        Controller gains.
    use_fast : bool
        Use the scalar 3-link kernel when possible (n == 3, r == 2); False
        forces the general numpy path (for checks).
    model : ArmModel, optional
        The nominal model's implementation, of ``nominal_params`` (e.g.
        ``freejoint_core.pin_model.PinArmModel`` of a URDF arm: Pinocchio instead of
        the general numpy path); default ``make_model(nominal_params)``.
    nullspace : freejoint_core.internal.NullSpace, optional
        Null-space term and right inverse for r > m (``freejoint_core.internal``);
        None (default): the paper's law exactly.  Set, the tick runs on the general
        numpy path.

    Attributes
    ----------
    theta : numpy.ndarray, (5,)
        Current adaptive estimate (copy).
    internals : tuple of LawValue
        :data:`ROBUST_INTERNALS`, the output's internal values.
    conditioning : str
        ``'det'``: the internal value of the nominal task's conditioning.

    """

    internals = ROBUST_INTERNALS
    conditioning = 'det'

    def __init__(self, nominal_params, gains=None, use_fast=True, model=None, nullspace=None):
        self._use_fast = bool(use_fast)
        if nullspace is not None and not isinstance(nullspace, NullSpace):
            raise FreejointValueError(
                f'nullspace: expected None or NullSpace, got {type(nullspace).__name__}')
        self.nullspace = nullspace
        self.set_nominal(nominal_params, model)
        self._theta = None
        self.stiffness = 1.0
        self.set_gains(Gains() if gains is None else gains)
        self.reset()

    # -- configuration ----------------------------------------------------
    def set_nominal(self, params, model=None):
        """
        Replace the nominal model (next step); keeps theta.

        Parameters
        ----------
        params : ArmParams
            New nominal parameters.
        model : ArmModel, optional
            Its implementation (``params`` equal to ``params``); default
            ``make_model(params)``.

        """
        if not isinstance(params, ArmParams):
            raise FreejointValueError(
                f'nominal_params: expected ArmParams, got {type(params).__name__}')
        if getattr(self, 'gains', None) is not None and self.gains.tau_limit is not None:
            self._resolve_limit(self.gains.tau_limit, params.r)
        self.nominal = params
        self.n = params.n
        self.r = params.r
        if model is not None and (not isinstance(model, ArmModel) or model.params != params):
            raise FreejointValueError(
                'model: expected an ArmModel of the nominal parameters, got '
                f'{type(model).__name__}')
        if model is None:
            model = make_model(params) if self._use_fast else ArmModel(params)
        self.model = model
        if getattr(self, 'nullspace', None) is not None:
            self.nullspace.check(self.r)
        self._fast = self._use_fast and self.n == 3 and self.r == 2 and hasattr(
            self.model, 'task') and getattr(self, 'nullspace', None) is None
        self._task = self.model.task if self._fast else None
        ns = getattr(self, 'nullspace', None)
        self._fast_full = (self._use_fast and self.n == 3 and self.r == 3
                           and hasattr(self.model, '_task_full')
                           and (ns is None or (ns.inverse == 'pseudo'
                                               and ns.projector == 'kinematic')))
        self._task_full = self.model._task_full if self._fast_full else None
        if getattr(self, 'gains', None) is not None:
            self.set_gains(self.gains)

    @staticmethod
    def _resolve_limit(lim, r):
        if lim is None:
            return None
        if isinstance(lim, float):
            return (lim,) * r
        if len(lim) != r:
            raise FreejointValueError(f'tau_limit: expected shape ({r},), got ({len(lim)},)')
        return tuple(lim)

    def set_gains(self, gains):
        """
        Install new gains (effective next step); theta is kept (see ``reset``).

        Parameters
        ----------
        gains : Gains
            New gains; ``tau_limit`` must have r entries.

        """
        if not isinstance(gains, Gains):
            raise FreejointValueError(f'gains: expected Gains, got {type(gains).__name__}')
        m = self.model.task_dim
        if gains.task_dim != m:
            raise FreejointValueError(f'gains: sized for task dimension {gains.task_dim}, the '
                                      f'model has {m}')
        limit = self._resolve_limit(gains.tau_limit, self.r)
        self.gains = gains
        self._limit = limit
        self._scale_gains()
        self._rr = gains.R
        self._eps = gains.epsilon
        self._sum = gains.h_form == 'sum'
        self._robust = gains.robust
        self._thr = gains.det_threshold
        self._gamma = gains.Gamma
        self._sigma = gains.sigma
        self._decay_cache = (None, None)
        self._theta_max = gains.theta_max
        if self._theta_max is not None and self._theta is not None:
            self._theta = [min(th, tm) for th, tm in zip(self._theta, self._theta_max)]

    def _scale_gains(self):
        """Cache the (scaled) K, Lambda terms of the step."""
        kx, ky = self.gains.K
        lx, ly = self.gains.Lambda
        s = self.stiffness
        if s != 1.0:
            kx, ky, lx, ly = s * kx, s * ky, s * lx, s * ly
        self._lam = (lx, ly)
        self._k_plus_lam = (kx + lx, ky + ly)    # gain on the velocity error
        self._k_times_lam = (kx * lx, ky * ly)   # gain on the position error

    def reset(self):
        """Set theta back to ``gains.theta0``."""
        self._theta = list(self.gains.theta0)

    def set_theta(self, theta):
        """
        Replace the adaptive estimate (e.g. restore the last good one after a fault).

        Parameters
        ----------
        theta : array_like, (5,)
            New estimate, finite and >= 0 (clamped to ``gains.theta_max`` when set).

        """
        vals = list(_vector(theta, 5, 'theta', 0.0, False))
        if self._theta_max is not None:
            vals = [min(th, tm) for th, tm in zip(vals, self._theta_max)]
        self._theta = vals

    @property
    def uses_fast_path(self):
        """Return True when ticks run on the scalar 3-link kernel."""
        return self._fast or self._fast_full

    @property
    def theta(self):
        """Return the current adaptive estimate, numpy copy (5,)."""
        return np.array(self._theta)

    # -- adaptation -------------------------------------------------------
    def _decay(self, dt):
        """Per-component (a_i, c_i): theta <- a_i theta + c_i u_i."""
        if self._decay_cache[0] == dt:
            return self._decay_cache[1]
        coef = decay_coefficients(self._gamma, self._sigma, dt)
        self._decay_cache = (dt, coef)
        return coef

    # -- tick -------------------------------------------------------------
    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """
        Compute the torque for one tick and advance the adaptation by dt.

        Parameters
        ----------
        q : array_like, (n,)
            Measured joint angles [rad].
        qd : array_like, (n,)
            Measured joint velocities [rad/s].
        p_d, pd_d, pdd_d : array_like, (2,)
            Desired end-effector position [m], velocity [m/s], acceleration [m/s^2].
        dt : float
            Control period [s], > 0 (used for the adaptation update).

        Returns
        -------
        LawOutput
            With the internal values :data:`ROBUST_INTERNALS`.

        """
        if not (type(dt) is float and dt > 0.0 and dt < math.inf):
            try:
                dtf = float(dt)
            except (TypeError, ValueError):
                dtf = math.nan
            if not (_isfinite(dtf) and dtf > 0.0):
                raise FreejointValueError(f'dt: must be finite and > 0, got {dt!r}')
            dt = dtf
        if self._fast or self._fast_full:
            return self._step_fast(q, qd, p_d, pd_d, pdd_d, dt)
        return self._step_general(q, qd, p_d, pd_d, pdd_d, dt)

    def _robust_term(self, sx, sy, w0, w1, w2, adx, ady, edx, edy, ex, ey, dt):
        """Return ``rho, dvx, dvy`` and advance ``theta`` (scalar paths, eqs. 17-19)."""
        theta = self._theta
        rx, ry = self._rr
        alx = rx * sx
        aly = ry * sy
        na2 = alx * alx + aly * aly
        na = _sqrt(na2)
        eps = self._eps
        if self._sum:
            h = na + eps
        else:
            h = na if na > eps else eps
        psi = (1.0, w0 * w0 + w1 * w1 + w2 * w2, _sqrt(adx * adx + ady * ady),
               _sqrt(edx * edx + edy * edy), _sqrt(ex * ex + ey * ey))
        rho = (theta[0] + theta[1] * psi[1] + theta[2] * psi[2] + theta[3] * psi[3]
               + theta[4] * psi[4])
        f = rho / h
        u = na2 / h
        coef = self._decay(dt)
        theta = [a * th + c * (u * ps) for (a, c), th, ps in zip(coef, theta, psi)]
        tmax = self._theta_max
        if tmax is not None:
            theta = [tm if th > tm else th for th, tm in zip(theta, tmax)]
        self._theta = theta
        return rho, -f * alx, -f * aly

    def _step_fast(self, q, qd, p_d, pd_d, pdd_d, dt):
        """
        Compute the tick of the 3-link arm on floats (r = 2, or r = 3 every joint driven).

        ``Da`` comes by rows, ``(x_0 .. x_{r-1})`` and ``(y_0 .. y_{r-1})``: of
        ``Arm3Model.task`` (r = 2, the active columns) or ``_task_full`` (r = 3, with the
        optional kinematic null-space term); every sum in the order of the general path.
        """
        q0, q1, q2 = _vec3(q, 'q')
        w0, w1, w2 = _vec3(qd, 'qd')
        pdx, pdy = _vec2(p_d, 'p_d')
        vdx, vdy = _vec2(pd_d, 'pd_d')
        adx, ady = _vec2(pdd_d, 'pdd_d')
        if self._fast:
            px, py, vx, vy, d00, d01, d10, d11, bx, by = self._task(q0, q1, q2, w0, w1, w2)
            rx, ry = (d00, d01), (d10, d11)
        else:
            px, py, vx, vy, rx, ry, bx, by = self._task_full(q0, q1, q2, w0, w1, w2)
        ex = px - pdx
        ey = py - pdy
        edx = vx - vdx
        edy = vy - vdy
        lx, ly = self._lam
        sx = edx + lx * ex
        sy = edy + ly * ey
        gdx, gdy = self._k_plus_lam
        gpx, gpy = self._k_times_lam
        vvx = adx - gdx * edx - gpx * ex
        vvy = ady - gdy * edy - gpy * ey
        if self._robust:
            rho, dvx, dvy = self._robust_term(sx, sy, w0, w1, w2, adx, ady, edx, edy, ex, ey,
                                              dt)
        else:
            rho = dvx = dvy = 0.0
        wx = vvx + dvx - bx
        wy = vvy + dvy - by
        # A = Da Da^T (2x2, symmetric), damped near a singularity as the general path
        a00 = _dot(rx, rx)
        a01 = _dot(rx, ry)
        a11 = _dot(ry, ry)
        det = a00 * a11 - a01 * a01
        status = 0
        if abs(det) < self._thr:
            lam2 = _dls_lambda2(det, a00 + a11, self._thr)
            a00 += lam2
            a11 += lam2
            det_use = a00 * a11 - a01 * a01
            status = STATUS_NEAR_SINGULAR
        else:
            det_use = det
        # tau = Da^T A^-1 w (the pseudo-inverse)
        c0 = (a11 * wx - a01 * wy) / det_use
        c1 = (a00 * wy - a01 * wx) / det_use
        tau = [x * c0 + y * c1 for x, y in zip(rx, ry)]
        if self.nullspace is not None:
            self._null_space_fast(tau, (q0, q1, q2), (w0, w1, w2), rx, ry, a00, a01, a11,
                                  det_use)
        lim = self._limit
        if lim is not None and any(t > lm or t < -lm for t, lm in zip(tau, lim)):
            tau = [lm if t > lm else (-lm if t < -lm else t) for t, lm in zip(tau, lim)]
            status |= STATUS_TORQUE_LIMITED
        r = len(tau)
        arr = np.array((*tau, ex, ey, edx, edy, sx, sy, dvx, dvy, px, py, *self._theta))
        return LawOutput(arr[0:r], arr[r:r + 2], arr[r + 2:r + 4], arr[r + 4:r + 6],
                         arr[r + 8:r + 10], status,
                         {'theta_hat': arr[r + 10:r + 15], 'rho_hat': rho,
                          'delta_v': arr[r + 6:r + 8], 'det': abs(det)})

    def _null_space_fast(self, tau, q, w, rx, ry, a00, a01, a11, det_use):
        """Add ``(I - Da# Da) tau0``, ``tau0 = -kd qd (+ kp (posture - q))``, to ``tau``."""
        ns = self.nullspace
        kd = ns.kd if isinstance(ns.kd, tuple) else (ns.kd,) * 3
        n = [-k * v for k, v in zip(kd, w)]
        if ns.posture is not None:
            kp = ns.kp if isinstance(ns.kp, tuple) else (ns.kp,) * 3
            n = [ni + k * (p - qi) for ni, k, p, qi in zip(n, kp, ns.posture, q)]
        zx = _dot(rx, n)
        zy = _dot(ry, n)
        u0 = (a11 * zx - a01 * zy) / det_use
        u1 = (a00 * zy - a01 * zx) / det_use
        for i, (x, y) in enumerate(zip(rx, ry)):
            tau[i] += n[i] - (x * u0 + y * u1)

    def _step_general(self, q, qd, p_d, pd_d, pdd_d, dt):
        q = check_vector(q, self.n, 'q')
        qd = check_vector(qd, self.n, 'qd')
        p_d = check_vector(p_d, 2, 'p_d')
        pd_d = check_vector(pd_d, 2, 'pd_d')
        pdd_d = check_vector(pdd_d, 2, 'pdd_d')
        model = self.model
        p = model.fk(q)
        da, b = model.decoupling(q, qd)
        e = p - p_d
        edot = model.jacobian(q) @ qd - pd_d
        lam = np.array(self._lam)
        s = edot + lam * e
        v = pdd_d - np.array(self._k_plus_lam) * edot - np.array(self._k_times_lam) * e
        if self._robust:
            alpha = np.array(self._rr) * s
            na = float(np.linalg.norm(alpha))
            h = na + self._eps if self._sum else max(na, self._eps)
            psi = np.array([1.0, float(qd @ qd), np.linalg.norm(pdd_d), np.linalg.norm(edot),
                            np.linalg.norm(e)])
            theta = np.array(self._theta)
            rho = float(theta @ psi)
            dv = -rho * alpha / h
            coef = np.array(self._decay(dt))
            new = coef[:, 0] * theta + coef[:, 1] * (na * na / h) * psi
            if self._theta_max is not None:
                new = np.where(new > np.array(self._theta_max), self._theta_max, new)
            self._theta = new.tolist()
        else:
            rho = 0.0
            dv = np.zeros(2)
        a = da @ da.T
        det = float(np.linalg.det(a))
        status = STATUS_OK
        if abs(det) < self._thr:
            a = a + _dls_lambda2(det, float(np.trace(a)), self._thr) * np.eye(2)
            status = STATUS_NEAR_SINGULAR
        if self.nullspace is None:
            tau = da.T @ np.linalg.solve(a, v + dv - b)
        else:
            tau = self._null_space_torque(q, qd, da, a, status, v + dv - b)
        tau, limited = clip_torque(tau, self._limit)
        return LawOutput(tau, e, edot, s, p, status | limited,
                         {'theta_hat': np.array(self._theta), 'rho_hat': rho, 'delta_v': dv,
                          'det': abs(det)})

    def _null_space_torque(self, q, qd, da, a, status, w):
        """``Da# w + N tau_0`` of ``freejoint_core.internal`` (a: ``Da Da^T``, damped)."""
        ns = self.nullspace
        pinv = np.linalg.solve(a, da).T
        weighted = None
        if (ns.inverse == 'weighted' or ns.projector == 'dynamic') and not (
                status & STATUS_NEAR_SINGULAR):
            weighted = weighted_inverse(da, self.model.effective(q)[1])
        task_inv = weighted if ns.inverse == 'weighted' and weighted is not None else pinv
        tau = task_inv @ w
        if self.r > 2:
            act = list(self.nominal.active)
            # near a singularity both fall back to the damped pinv: N stays bounded (<= 1)
            proj_inv = weighted if ns.projector == 'dynamic' and weighted is not None else pinv
            tau = tau + projector(da, proj_inv) @ ns.tau0(q[act], qd[act])
        return tau
