"""
What every Cartesian law of this stack shares: the task terms, the surface, the inverse.

A Cartesian law of a free-joint arm computes, from the nominal model (paper eqs. 4, 5),
the task-space dynamics ``pdd = Da tau + b`` of the end effector with the free joints'
dynamics eliminated, then asks for a task acceleration ``w`` and realises it with the
right inverse ``tau = Da# (w - b)`` (damped near a singularity, as the paper's law).
The laws differ in the acceleration they ask for.  :class:`TaskLaw` holds the shared
part; a law overrides :meth:`TaskLaw.command` (and, with internal state,
:meth:`TaskLaw.applied`, ``reset``, the state's methods)::

    e = p - p_d,   edot = J qd - pd_d,   s = edot + Lam e                  (sliding surface)
    u0 = pdd_d - Lam edot - K s = pdd_d - (K + Lam) edot - K Lam e         (paper eq. 16)
    tau = Da# (command(...) - b)  (law's command), limited to the torque limit

``K`` and ``Lambda`` (scaled by the hold stiffness), the torque limit and the
singularity threshold are the shared :class:`freejoint_core.control.Gains`; a law's own
gains are its ``gain_schema`` (``<law>.<gain>``, :class:`freejoint_core.law_base.LawGain`).

The output is :class:`freejoint_core.law_base.LawOutput`; its ``internal`` holds the
values a law's :meth:`TaskLaw.command` gives (declared in its ``internals``) and ``det``
(``|det(Da Da^T)|`` of the nominal model, the law's ``conditioning``), declared last.
"""

import math

from freejoint_core.arm import ArmParams, check_vector
from freejoint_core.control import (_dls_lambda2, clip_torque, DET, Gains, HoldStiffness,
                                    RobustController, STATUS_NEAR_SINGULAR)
from freejoint_core.errors import FreejointValueError
from freejoint_core.law_base import ControlLaw, law_params, LawOutput
from freejoint_core.models import make_model
import numpy as np


def dot(a, b):
    """Return ``sum(a_i b_i)`` of two float sequences, left to right (no BLAS, no FMA)."""
    out = a[0] * b[0]
    for x, y in zip(a[1:], b[1:]):
        out += x * y
    return out


def norm2(v):
    """
    Return the squared Euclidean norm ``v_0^2 + v_1^2 + ...`` of the vector ``v``.

    Plain float arithmetic, left to right, as the compiled kernel (``batch_kernel``)
    computes it; numpy's ``norm`` or ``@`` may sum otherwise (BLAS, FMA).
    """
    x = v.tolist()
    return dot(x, x)


def norm(v):
    """Return the Euclidean norm ``sqrt(norm2(v))`` of the vector ``v``."""
    return math.sqrt(norm2(v))


def damped_right_inverse(da, w, thr):
    """
    Return ``Da# w`` (damped least squares near a singularity), ``|det(Da Da^T)|``, status.

    Plain float arithmetic in a fixed order (no BLAS): the batched kernel of a task law
    (``batch_kernel``) does the same operations, so its runs equal the scalar ones.

    Parameters
    ----------
    da : numpy.ndarray, (2, r)
        Decoupling matrix of the nominal model (planar task).
    w : numpy.ndarray, (2,)
        Task acceleration to realise (drift already subtracted) [m/s^2].
    thr : float
        Threshold on ``|det(Da Da^T)|`` below which the inverse is damped (the paper's
        ``eps_d``; ``control`` module notes: the smallest damping reaching it).

    Returns
    -------
    tau : numpy.ndarray, (r,)
    det : float
    status : int
        ``STATUS_NEAR_SINGULAR`` when damped, else 0.

    """
    d0, d1 = da.tolist()
    a00 = dot(d0, d0)
    a01 = dot(d0, d1)
    a11 = dot(d1, d1)
    det = a00 * a11 - a01 * a01
    status = 0
    if abs(det) < thr:
        lam2 = _dls_lambda2(det, a00 + a11, thr)
        a00 += lam2
        a11 += lam2
        status = STATUS_NEAR_SINGULAR
    det_use = a00 * a11 - a01 * a01
    wx, wy = w.tolist()
    c0 = (a11 * wx - a01 * wy) / det_use
    c1 = (a00 * wy - a01 * wx) / det_use
    return np.array([x * c0 + y * c1 for x, y in zip(d0, d1)]), abs(det), status


def sat(s, phi):
    """
    Return the boundary-layer switching direction ``s / max(||s||, phi)`` (norm <= 1).

    Inside the layer (``||s|| < phi``) it is linear, ``s / phi``, continuous across the
    layer's edge; outside, the unit vector of ``s`` (the discontinuous ``sign`` of an
    ideal sliding mode, smoothed).
    """
    ns = norm(s)
    return s / (ns if ns > phi else phi)


class TaskLaw(HoldStiffness, ControlLaw):
    """
    The shared part of a planar Cartesian law on the nominal model (module notes).

    Parameters
    ----------
    nominal : ArmParams
        Nominal parameters (``Da``, ``b``).
    gains : Gains, optional
        The shared task gains (``K``, ``Lambda``, ``tau_limit``, ``det_threshold``).
    model : ArmModel, optional
        The nominal model's implementation (default ``make_model(nominal)``).
    params : mapping of str to float, optional
        The law's own gains by namespaced name (its ``gain_schema``; defaults otherwise).
    nullspace_kd, nullspace_kp : float
        The controller's null-space parameters: such a law has no null-space term, so
        both must be 0 on an arm with more driven joints than the task has (r > 2).

    Attributes
    ----------
    internals : tuple of LawValue
        The values :meth:`command` gives, then ``det`` (``control.DET``); a law adds its
        own before it (``internals = OWN + (DET,)``).
    conditioning : str or None
        ``'det'``: the output's ``|det(Da Da^T)|`` under this name; None: not reported (a
        law whose ``internals`` leave it out).

    Raises
    ------
    FreejointValueError
        A null-space parameter not 0 on such an arm.

    """

    internals = (DET,)
    conditioning = 'det'

    def __init__(self, nominal, gains=None, model=None, params=None, nullspace_kd=0.0,
                 nullspace_kp=0.0):
        for option, value in (('nullspace_kd', nullspace_kd), ('nullspace_kp', nullspace_kp)):
            if value != 0.0 and getattr(nominal, 'r', 0) > 2:
                raise FreejointValueError(f'{option}: law {self.name!r} has no null-space term; '
                                          f'expected 0, got {value!r}')
        self.stiffness = 1.0
        self.params = law_params(self.name, self.gain_schema, params)
        self.gains = None
        self.set_nominal(nominal, model)
        self.set_gains(Gains() if gains is None else gains)
        self.reset()

    def set_nominal(self, params, model=None):
        """Take a new nominal model (next step); the law's state is kept."""
        if not isinstance(params, ArmParams):
            raise FreejointValueError(
                f'nominal_params: expected ArmParams, got {type(params).__name__}')
        if model is None:
            model = make_model(params)
        elif getattr(model, 'params', None) != params:
            raise FreejointValueError('model: expected an ArmModel of the nominal parameters, '
                                      f'got {type(model).__name__}')
        if self.gains is not None and self.gains.tau_limit is not None:
            RobustController._resolve_limit(self.gains.tau_limit, params.r)
        self.nominal, self.model, self.n, self.r = params, model, params.n, params.r
        # the 3-link arm's closed forms (fast3.Arm3Model.task) when it has them
        self._task = model.task if params.n == 3 and params.r == 2 and hasattr(
            model, 'task') else None
        if self.gains is not None:
            self.set_gains(self.gains)

    def set_gains(self, gains):
        """Take new shared gains (next step); the state is kept."""
        if not isinstance(gains, Gains):
            raise FreejointValueError(f'gains: expected Gains, got {type(gains).__name__}')
        m = self.model.task_dim
        if m != 2:
            raise FreejointValueError(f'nominal: law {self.name!r} is planar (task_dim 2), '
                                      f'the model has task_dim {m}')
        if gains.task_dim != m:
            raise FreejointValueError(f'gains: sized for task dimension {gains.task_dim}, the '
                                      f'model has {m}')
        self._limit = RobustController._resolve_limit(gains.tau_limit, self.r)
        self.gains = gains
        self._scale_gains()

    def _scale_gains(self):
        s = self.stiffness
        self.k = np.array(self.gains.K) * s
        self.lam = np.array(self.gains.Lambda) * s

    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """
        Return the torques of one tick (``LawOutput``) and advance the law by ``dt``.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Measured joint angles [rad] and velocities [rad/s].
        p_d, pd_d, pdd_d : array_like, (m,)
            Setpoint position [m], velocity [m/s], acceleration [m/s^2].
        dt : float
            Time step [s], > 0.

        """
        try:
            dtf = float(dt)
        except (TypeError, ValueError):
            dtf = math.nan
        if not (math.isfinite(dtf) and dtf > 0.0):
            raise FreejointValueError(f'dt: must be finite and > 0, got {dt!r}')
        m = self.model.task_dim
        q = check_vector(q, self.n, 'q')
        qd = check_vector(qd, self.n, 'qd')
        p_d = check_vector(p_d, m, 'p_d')
        pd_d = check_vector(pd_d, m, 'pd_d')
        pdd_d = check_vector(pdd_d, m, 'pdd_d')
        p, v, da, b = self._terms(q, qd)
        e = p - p_d
        edot = v - pd_d
        s = edot + self.lam * e
        u0 = pdd_d - self.lam * edot - self.k * s
        w, internal = self.command(q, qd, v, da, b, e, edot, s, u0, pdd_d, dtf)
        tau, det, status = damped_right_inverse(da, w, self.gains.det_threshold)
        tau, limited = clip_torque(tau, self._limit)
        self.applied(tau, da)
        if self.conditioning is not None:
            internal[self.conditioning] = det
        return LawOutput(tau, e, edot, s, p, status | limited, internal)

    def _terms(self, q, qd):
        """Return ``p``, ``J qd`` (m,), ``Da`` (m, r), ``b`` (m,) of the nominal model."""
        if self._task is not None:
            px, py, vx, vy, d00, d01, d10, d11, bx, by = self._task(*q.tolist(), *qd.tolist())
            return (np.array((px, py)), np.array((vx, vy)),
                    np.array(((d00, d01), (d10, d11))), np.array((bx, by)))
        model = self.model
        da, b = model.decoupling(q, qd)
        return model.fk(q), model.jacobian(q) @ qd, da, b

    def command(self, q, qd, v, da, b, e, edot, s, u0, pdd_d, dt):
        """
        Return the law's task acceleration minus drift ``w`` and its internal values.

        The torque is ``Da# w``; the nominal computed torque is ``w = u0 - b`` (no
        values).  ``v`` is the task velocity ``J qd`` [m/s].  The values: a dict of the
        law's ``internals`` but ``det``, in their order.
        """
        return u0 - b, {}

    def applied(self, tau, da):
        """Take note of the torque the step returns (after the limit); nothing here."""
