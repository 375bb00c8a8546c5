"""
The paper's robust law for spatial arms (m = 3 or 6 task rows), and its plan-time checks.

:class:`SpatialLaw` is ``control.RobustController``'s general path with the task sized by
``m`` (:class:`SpatialGains`, the planar ``Gains`` with m in {3, 6}), on a
:class:`freejoint_core.spatial_model.SpatialArm` nominal model::

    e = (p - p_d, log(R R_d^T)),   edot = J qd - pd_d,   s = edot + Lam e
    v = pdd_d - (K + Lam) edot - K Lam e,   dv = -rho a / h   (a = R s; eqs. 16-19)
    tau = X (v + dv - b) + N tau_0,   X = W Da^T (Da W Da^T)^-1,   N = I - X Da

with ``W = M~aa`` (``inverse='weighted'``) or ``I`` (``'pseudo'``), the projector from
the same inverse, ``tau_0`` of ``freejoint_core.internal.NullSpace`` (null-space
damping ``-kd qd_a``), and ``tau`` clipped to the URDF's effort limits.

Free-joint damping (option ``free_damping = kf``): a free joint has no torque and no
damping, so a random joint disturbance makes its rate a random walk (over 15 s the
Panda's joint 7 passes its URDF speed limit).  For r > m the null space can act on it:
``tau_0`` gets ``y`` with ``(M^-1)[p, a] N y = -kf qd_p`` (damped least squares), so the
nominal free-joint acceleration gains ``-kf qd_p`` while ``Da N y = 0`` leaves the task
untouched; ``y`` is scaled down to at most ``FREE_SHARE`` (10 %) of each active joint's
effort limit (where the coupling is weak the request would be large).

Singularity (:func:`task_conditioning`): ``kappa = sqrt(lmin / lmax)`` of
``A = Ds Da M~aa Da^T Ds``, ``Ds = diag(1, 1, 1, L, L, L)[:m, :m] / L`` (``L`` the arm's
reach, so the position rows are in rad/s^2 like the orientation rows).  ``A`` is the
inverse of the task-space inertia of the constrained arm (``Da M~aa Da^T =
J~ M~aa^-1 J~^T``), the matrix the weighted inverse inverts; ``kappa`` is in [0, 1], 0 at
a singularity, and unchanged by a common factor on every mass and inertia (``Da`` scales
by ``1/s``, ``M~aa`` by ``s``), by the gravity (no gravity term) and, with ``L``, by the
unit of length.  Below ``gains.kappa_min`` the tick damps ``A`` to ``A + lam2 I``,
``lam2 = kappa_min^2 lmax - lmin`` (``kappa`` of the damped matrix about ``kappa_min``)
and reports ``STATUS_NEAR_SINGULAR``.

Gravity-carrying free joints (:func:`gravity_carrying_free_joint`): the free joints must
be at rest at the start of the path (the arm starts and holds from rest; a free joint
has no torque, so it must sit where its gravity torque vanishes).  The criterion: from
the planned start posture, Gauss-Newton minimum-norm steps on
``(fk(q) - fk(q_start), G_p(q))`` (the tip held, the free joints' gravity torque) must
reach ``|G_p| <= tol`` inside the URDF position limits; a free joint for which no such
pose is found (Panda joint 4, UR5 elbow: the forearm cannot hang vertically over its
axis with the tip in front) is refused with one line naming it and the closest iterate
(tip error, gravity torque).  The search is local (the posture branch of the plan): a rest posture
in another branch is not looked for.
"""

from dataclasses import dataclass
import math

from freejoint_core.arm_gains import delay_capped_damping
from freejoint_core.control import _vector, Gains, ROBUST_INTERNALS, STATUS_NEAR_SINGULAR
from freejoint_core.control import HoldStiffness, STATUS_OK, STATUS_TORQUE_LIMITED
from freejoint_core.errors import FreejointValueError
from freejoint_core.internal import NullSpace
from freejoint_core.law_base import ControlLaw, INF, LawOutput, LawValue
from freejoint_core.spatial_model import SpatialArm
import numpy as np
import pinocchio as pin


FREE_SHARE = 0.1
"""Largest share of an active joint's effort limit the free-joint damping may ask."""


@dataclass(frozen=True)
class SpatialGains(Gains):
    """
    Gains of the spatial law: :class:`control.Gains` with ``task_dim`` m in {3, 6}.

    The task-space diagonals (K, Lambda, R) are sized by m, the rest as ``Gains``; the
    planar ``det_threshold`` is replaced by ``kappa_min``; the torque is clipped to the
    model's (URDF) effort limits, or to ``tau_limit`` (r values, active joints in model
    order) where that is smaller.

    Attributes
    ----------
    task_dim : {3, 6}
        Task rows m (default 3: position; 6: position and orientation).
    kappa_min : float
        Singularity threshold on ``kappa`` (module notes), in (0, 1).

    """

    task_dim: int = 3
    kappa_min: float = 1e-3

    def __post_init__(self):
        """Validate and normalise (``Gains``), then m and kappa_min."""
        if self.task_dim not in (3, 6) or isinstance(self.task_dim, bool):
            raise FreejointValueError(f'task_dim: expected 3 or 6, got {self.task_dim!r}')
        super().__post_init__()
        kmin = _vector(self.kappa_min, 1, 'kappa_min', 0.0, True)[0]
        if kmin >= 1.0:
            raise FreejointValueError(f'kappa_min: must be < 1, got {kmin}')
        object.__setattr__(self, 'kappa_min', kmin)

    @property
    def m(self):
        """Return the task rows (``task_dim``)."""
        return self.task_dim


INTERNALS = (
    ROBUST_INTERNALS[0],
    LawValue('rho_hat', (), 'm/s^2; rad/s^2', 'robust gain theta_hat^T psi used this tick '
             '(0 when robust is False)'),
    LawValue('kappa', (), '-', 'scale-free conditioning of the nominal task in [0, 1], 0 at '
             'a singularity (module notes, task_conditioning)'),
)
"""The internal values of the spatial law's output (``LawOutput.internal``)."""


def arm_reach(arm):
    """
    Length scale ``L`` of an arm [m]: the sum of the joint-to-joint distances to the tip at q = 0.

    Parameters
    ----------
    arm : SpatialArm
        The arm (its Pinocchio model and tip frame).

    Returns
    -------
    float

    """
    q = np.zeros(arm.n)
    pin.framesForwardKinematics(arm.model, arm.data, q)
    pts = [np.array(arm.data.oMi[j].translation) for j in range(1, arm.model.njoints)]
    pts.append(np.array(arm.data.oMf[arm.frame].translation))
    return float(sum(np.linalg.norm(b - a) for a, b in zip(pts[:-1], pts[1:])))


def task_conditioning(da, maa, reach):
    """
    Scale-free conditioning ``kappa`` of the task (module notes) and the matrix ``A``.

    Parameters
    ----------
    da : numpy.ndarray, (m, r)
        Decoupling matrix.
    maa : numpy.ndarray, (r, r)
        Effective inertia of the active joints.
    reach : float
        Length scale ``L`` [m].

    Returns
    -------
    kappa : float
        In [0, 1].
    a : numpy.ndarray, (m, m)
        ``Da M~aa Da^T`` (unscaled).
    lmax : float
        Largest eigenvalue of the scaled ``A``.

    """
    a = da @ maa @ da.T
    eig = np.linalg.eigvalsh(a * _row_scale(a.shape[0], reach))
    lmax = float(eig[-1])
    kappa = math.sqrt(max(float(eig[0]), 0.0) / lmax) if lmax > 0.0 else 0.0
    return kappa, a, lmax


_ROW_SCALES = {}
"""``outer(Ds, Ds)`` of :func:`task_conditioning` per (m, reach) (a few arms per process)."""


def _row_scale(m, reach):
    """Return ``outer(Ds, Ds)`` (m, m), ``Ds = diag(1, 1, 1, L, L, L)[:m] / L`` (cached)."""
    key = (m, reach)
    scale = _ROW_SCALES.get(key)
    if scale is None:
        ds = np.ones(m) / reach
        if m == 6:
            ds[3:] = 1.0
        scale = np.outer(ds, ds)
        scale.flags.writeable = False
        if len(_ROW_SCALES) >= 64:
            _ROW_SCALES.clear()
        _ROW_SCALES[key] = scale
    return scale


def rotation_error(rot, rot_d):
    """Rotation vector of ``R R_d^T`` (root frame) [rad], (3,)."""
    return np.array(pin.log3(rot @ rot_d.T))


class SpatialLaw(HoldStiffness):
    """
    The robust law on a spatial arm (module notes).

    Parameters
    ----------
    nominal : SpatialArm
        Nominal model (e.g. ``arm.nominal(0.7)``).
    gains : SpatialGains
        ``gains.m`` must equal ``nominal.m``.
    nullspace : NullSpace, optional
        Inverse, projector and null-space damping; default weighted inverse, dynamic
        projector, ``kd = 0``.
    free_damping : float
        ``kf`` [1/s], >= 0: the null-space torque also asks the free joints for
        ``qdd_p = -kf qd_p`` (module notes); 0 (default): off.

    """

    internals = INTERNALS          # the output's internal values
    conditioning = 'kappa'         # the one that says how near a singularity the task is

    def __init__(self, nominal, gains=None, nullspace=None, free_damping=0.0):
        kf = float(free_damping)
        if not (math.isfinite(kf) and kf >= 0.0):
            raise FreejointValueError(f'free_damping: must be finite and >= 0, got {kf!r}')
        self.free_damping = kf
        if not isinstance(nominal, SpatialArm):
            raise FreejointValueError(
                f'nominal: expected SpatialArm, got {type(nominal).__name__}')
        gains = SpatialGains(task_dim=nominal.m) if gains is None else gains
        if not isinstance(gains, SpatialGains) or gains.m != nominal.m:
            raise FreejointValueError(f'gains: expected SpatialGains with m = {nominal.m}')
        ns = NullSpace(inverse='weighted', projector='dynamic') if nullspace is None \
            else nullspace
        if not isinstance(ns, NullSpace):
            raise FreejointValueError(f'nullspace: expected NullSpace, got {type(ns).__name__}')
        ns.check(nominal.r)
        self.model, self.gains, self.nullspace = nominal, gains, ns
        self.reach = arm_reach(nominal)
        self.stiffness = 1.0
        self._scale_gains()
        self._limit = nominal.effort[list(nominal.active)]
        if gains.tau_limit is not None:     # the smaller of the URDF's and the given limits
            self._limit = np.minimum(self._limit, np.asarray(gains.tau_limit, dtype=float))
        self._low = -self._limit
        self._eye = np.eye(nominal.r)
        self._act = np.array(nominal.active, dtype=int)
        self._dt = None
        self._coef = None
        self.reset()

    def _scale_gains(self):
        """Set the loop gains of ``gains`` with K and Lambda times ``stiffness``."""
        k = np.array(self.gains.K) * self.stiffness
        self._lam = np.array(self.gains.Lambda) * self.stiffness
        self._kd = k + self._lam
        self._kp = k * self._lam

    def reset(self):
        """Set theta back to ``gains.theta0``."""
        self.theta = np.array(self.gains.theta0)

    def _decay(self, dt):
        if self._dt != dt:
            g, sg = np.array(self.gains.Gamma), np.array(self.gains.sigma)
            with np.errstate(divide='ignore', invalid='ignore'):
                a = np.exp(-g * sg * dt)
                c = np.where(sg > 0.0, (1.0 - a) / np.where(sg > 0.0, sg, 1.0), g * dt)
            self._dt, self._coef = dt, (a, c)
        return self._coef

    def step(self, q, qd, p_d, pd_d, pdd_d, dt, rot_d=None):
        """
        Torques of one tick; advances the adaptation by ``dt``.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Measured angles [rad] and rates [rad/s].
        p_d : array_like, (3,)
            Desired tip position [m].
        pd_d, pdd_d : array_like, (m,)
            Desired task velocity and acceleration (linear, then angular for m = 6).
        dt : float
            Period [s], > 0.
        rot_d : numpy.ndarray, (3, 3), optional
            Desired orientation (required for m = 6).

        Returns
        -------
        LawOutput
            With the internal values :data:`INTERNALS` (``theta_hat`` after the update,
            ``rho_hat``, ``kappa``).

        """
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise FreejointValueError(f'dt: must be finite and > 0, got {dt!r}')
        arm, m = self.model, self.model.m
        vals = {}
        for name, val, k in (('p_d', p_d, 3), ('pd_d', pd_d, m), ('pdd_d', pdd_d, m)):
            arr = np.asarray(val, dtype=float)
            if arr.shape != (k,) or not np.isfinite(arr).all():
                raise FreejointValueError(f'{name}: expected {k} finite numbers, got {val!r}')
            vals[name] = arr
        if m == 6:
            rot_d = np.asarray(rot_d, dtype=float) if rot_d is not None else None
            if rot_d is None or rot_d.shape != (3, 3) or not np.all(np.isfinite(rot_d)):
                raise FreejointValueError(f'rot_d: expected a 3 x 3 rotation, got {rot_d!r}')
        terms = arm.terms(q, qd)
        qd = np.asarray(qd, dtype=float)
        e = terms.p - vals['p_d']
        if m == 6:
            e = np.concatenate([e, rotation_error(terms.R, rot_d)])
        edot = terms.J @ qd - vals['pd_d']
        s = edot + self._lam * e
        pdd = vals['pdd_d']
        v = pdd - self._kd * edot - self._kp * e
        gains = self.gains
        rho = 0.0
        if gains.robust:
            alpha = np.array(gains.R) * s
            na = math.sqrt(alpha @ alpha)       # np.linalg.norm's sqrt(x . x), less overhead
            h = na + gains.epsilon if gains.h_form == 'sum' else max(na, gains.epsilon)
            psi = np.array([1.0, float(qd @ qd), math.sqrt(pdd @ pdd), math.sqrt(edot @ edot),
                            math.sqrt(e @ e)])
            rho = float(self.theta @ psi)
            v = v - rho * alpha / h
            a_c, c_c = self._decay(dt)
            new = a_c * self.theta + c_c * (na * na / h) * psi
            if gains.theta_max is not None:
                new = np.minimum(new, gains.theta_max)
            self.theta = new
        da, b, maa = arm.decoupling(terms)
        kappa, amat, lmax = task_conditioning(da, maa, self.reach)
        status = STATUS_OK
        weight = maa if self.nullspace.inverse == 'weighted' else self._eye
        wd = weight @ da.T
        amat = da @ wd
        if kappa < gains.kappa_min:
            scale = np.ones(m) * self.reach
            if m == 6:
                scale[3:] = 1.0
            lam2 = gains.kappa_min ** 2 * lmax - kappa ** 2 * lmax
            amat = amat + lam2 * np.diag(scale * scale)
            status = STATUS_NEAR_SINGULAR
        x = np.linalg.solve(amat, wd.T).T
        tau = x @ (v - b)
        if arm.r > m:
            act = self._act
            proj = self._eye - x @ da
            if self.nullspace.projector == 'kinematic':
                xp = np.linalg.solve(da @ da.T, da).T
                proj = self._eye - xp @ da
            tau0 = self.nullspace.tau0(np.asarray(q, dtype=float)[act], qd[act])
            if self.free_damping > 0.0:
                tau0 = tau0 + self._free_damping(terms, proj, qd)
            tau = tau + proj @ tau0
        clipped = np.minimum(np.maximum(tau, self._low), self._limit)   # np.clip's values
        if np.any(clipped != tau):
            status |= STATUS_TORQUE_LIMITED
        return LawOutput(clipped, e, edot, s, terms.p, status,
                         {'theta_hat': self.theta.copy(), 'rho_hat': rho, 'kappa': kappa})

    def _free_damping(self, terms, proj, qd):
        """``y`` with ``(M^-1)[p, a] N y = -kf qd_p`` (damped least squares)."""
        arm = self.model
        gmat = terms.Minv[np.ix_(list(arm.passive), list(arm.active))] @ proj
        ggt = gmat @ gmat.T
        mu = 1e-6 * max(float(np.trace(ggt)), 1e-300)
        target = -self.free_damping * qd[list(arm.passive)]
        y = gmat.T @ np.linalg.solve(ggt + mu * np.eye(len(target)), target)
        # at most FREE_SHARE of each active joint's effort limit (weak coupling: no blow-up)
        peak = float(np.max(np.abs(y) / self._limit))
        return y if peak <= FREE_SHARE else y * (FREE_SHARE / peak)


def gravity_carrying_free_joint(arm, q, tol=1e-6, max_iter=60):
    """
    Find a rest posture of the free joints with the tip where ``q`` puts it (plan time).

    Gauss-Newton minimum-norm steps from ``q`` on ``(fk(x) - fk(q), G_p(x))`` (tip
    position held; for m = 6 the orientation too), inside the URDF position limits
    (module notes).

    Parameters
    ----------
    arm : SpatialArm
        The arm (its free joints).
    q : array_like, (n,)
        Planned start posture [rad].
    tol : float
        Residual bound [m, N m].
    max_iter : int
        Iteration bound.

    Returns
    -------
    (numpy.ndarray or None, str or None)
        The rest posture (n,) and None, or None and one line saying which free joint
        carries gravity and why.

    """
    if not isinstance(arm, SpatialArm):
        raise FreejointValueError(f'arm: expected SpatialArm, got {type(arm).__name__}')
    x = np.array(arm._state(q), dtype=float)
    passive = list(arm.passive)
    if not passive:
        return x, None
    p0, r0 = arm.placement(x)

    def residual(y):
        pos, rot = arm.placement(y)
        parts = [pos - p0]
        if arm.m == 6:
            parts.append(rotation_error(rot, r0))
        parts.append(arm.gravity_torque(y)[passive])
        return np.concatenate(parts)

    best = (math.inf, math.inf, math.inf)
    step_h = 1e-6
    for _ in range(max_iter):
        res = residual(x)
        norm = float(np.linalg.norm(res))
        if norm < best[0]:
            best = (norm, float(np.linalg.norm(res[:3])),
                    float(np.max(np.abs(res[-len(passive):]))))
        if np.linalg.norm(res) < tol:
            if np.all(x >= arm.lower - 1e-9) and np.all(x <= arm.upper + 1e-9):
                return x, None
            break
        jac = np.empty((res.size, arm.n))
        for j in range(arm.n):
            dx = np.zeros(arm.n)
            dx[j] = step_h
            jac[:, j] = (residual(x + dx) - residual(x - dx)) / (2.0 * step_h)
        x = np.clip(x - np.linalg.lstsq(jac, res, rcond=None)[0], arm.lower, arm.upper)
    names = ', '.join(arm.joint_names[i] for i in passive)
    return None, (f'free joint {names} must carry gravity: no rest posture within the joint '
                  f'limits holds the tip at {np.round(p0, 3).tolist()} m (closest: tip off by '
                  f'{1e3 * best[1]:.3g} mm, gravity torque {best[2]:.3g} N m)')


class SpatialControlLaw(ControlLaw):
    """
    :class:`SpatialLaw` behind the control-law seam (``freejoint_core.laws``, ``'spatial'``).

    The controller's loop steps it as any law: ``step(q, qd, p_d, pd_d, pdd_d, dt)`` with
    m-sized setpoints (m = 3: the tip position; m = 6 needs an orientation setpoint, which
    the seam does not carry: refused).  The inverse is the inertia-weighted one with the
    dynamically consistent projector (the pseudo-inverse diverges on spatial arms);
    ``set_nullspace_gains`` sets the null-space damping ``kd`` and posture
    stiffness ``kp`` (``nullspace_kd``, ``nullspace_kp``): the posture is the active
    joints' angles at the first step after construction or :meth:`reset` (where the task
    began), so that the redundant joints do not drift over a long hold.

    State: ``theta_hat[0..4]`` (after the tick's update), ``rho_hat`` (used in the tick)
    and ``kappa`` (the scale-free conditioning of the tick, :func:`task_conditioning`);
    the output's internal values are :class:`SpatialLaw`'s, ``kappa`` its conditioning
    (the planar law's ``|det(Da Da^T)|`` has no scale-free meaning in 3-D).

    Parameters
    ----------
    nominal : SpatialArm
        The nominal model (m = 3).
    gains : SpatialGains, optional
        Default ``SpatialGains(task_dim=nominal.m)``.
    model : None
        Not used (the nominal model is the model); accepted for the registry's signature.
    nullspace_kd : float or tuple of float, (r,)
        Null-space damping [N m s/rad] (:meth:`set_nullspace_gains`).
    nullspace_kp : float
        Posture stiffness [N m/rad] (:meth:`set_nullspace_gains`).

    """

    name = 'spatial'
    internals = INTERNALS
    conditioning = 'kappa'

    def __init__(self, nominal, gains=None, model=None, nullspace_kd=0.0, nullspace_kp=0.0):
        if isinstance(nominal, SpatialArm) and nominal.m != 3:
            raise FreejointValueError(
                f'nominal: the spatial law takes m = 3 through the controller (a position '
                f'setpoint), got m = {nominal.m}')
        self.law = SpatialLaw(nominal, gains, _nullspace(0.0))
        self._last = None
        self._kd = self._kp = 0.0
        self._posture = None
        self._delay = None      # real time: (periods, control period) the damping must stand
        self._kd_now = None     # the damping in use (None: taken at the next step)
        names = tuple('theta_hat[%d]' % i for i in range(5))
        self.state_names = names + ('rho_hat', 'kappa')
        self._bounds()
        if nullspace_kd != 0.0 or nullspace_kp:     # a tuple: per joint
            self.set_nullspace_gains(nullspace_kd, nullspace_kp)

    def _bounds(self):
        tmax = self.law.gains.theta_max
        tmax = tmax if tmax is not None else (INF,) * 5
        self.state_bounds = tuple((0.0, t) for t in tmax) + ((-INF, INF), (0.0, 1.0))

    @property
    def model(self):
        """Return the nominal ``SpatialArm``."""
        return self.law.model

    @property
    def nominal(self):
        """Return the nominal ``SpatialArm``."""
        return self.law.model

    @property
    def stiffness(self):
        """Return the hold stiffness scale of the gains."""
        return self.law.stiffness

    def set_nullspace_gains(self, kd, kp=0.0):
        """
        Set the null-space damping ``kd`` [N m s/rad] and posture stiffness ``kp`` [N m/rad].

        The weighted inverse and dynamic projector are kept; with ``kp`` > 0 the posture is
        taken at the next step (the active joints' angles then).
        """
        ns = _nullspace(kd, kp, (0.0,) * self.law.model.r if kp else None)
        ns.check(self.law.model.r)
        self._kd, self._kp = kd, kp
        self._posture = None
        self._kd_now = None
        self.law.nullspace = _nullspace(kd)

    def set_nullspace_delay(self, periods, dt):
        """
        Cap the null-space damping for a real-time loop ``periods`` control periods late.

        From the next step on (and after each :meth:`reset`), the damping is
        ``freejoint_core.arm_gains.delay_capped_damping`` of the configured ``kd`` at the
        state of that step (the posture pulled to is kept): a light joint's damping that
        lockstep stands would reverse and grow at the delay of a real-time loop.
        ``periods`` >= 1 [periods], ``dt`` the control period [s] > 0; ``periods`` None:
        uncapped (lockstep).
        """
        delay = None if periods is None else (int(periods), float(dt))
        if delay != self._delay:
            self._delay = delay
            self._kd_now = None

    @property
    def nullspace_kd(self):
        """Return the null-space damping in use (None: taken at the next step)."""
        return self._kd_now

    @property
    def posture(self):
        """Return the angles (r,) [rad] the null space pulls to (None: not yet, or kp 0)."""
        return self._posture

    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """Return one tick of :class:`SpatialLaw` (its ``LawOutput``)."""
        if self._kd_now is None or (self._kp and self._posture is None):
            self._take_nullspace(q)
        out = self.law.step(q, qd, p_d, pd_d, pdd_d, dt)
        self._last = out
        return out

    def _take_nullspace(self, q):
        """Take the posture (``kp`` > 0) and the damping (capped in real time) at ``q``."""
        if self._kp and self._posture is None:
            self._posture = tuple(float(q[i]) for i in self.law.model.active)
        if self._kd_now is None:
            kd = self._kd
            if self._delay is not None and np.any(np.asarray(kd) != 0.0):
                kd = delay_capped_damping(self.law.model, np.asarray(q, dtype=float), kd,
                                          *self._delay)
            self._kd_now = kd
        self.law.nullspace = _nullspace(self._kd_now, self._kp, self._posture)

    def reset(self):
        """Set theta_hat back to ``gains.theta0``; posture and damping taken again next step."""
        self.law.reset()
        self._last = None
        self._kd_now = None
        if self._posture is not None:
            self._posture = None
            self.law.nullspace = _nullspace(self._kd)

    def state_values(self):
        """Return theta_hat (5, now), rho_hat and kappa of the last step (0 before one)."""
        out = self._last
        if out is None:
            return self.law.theta.tolist() + [0.0, 0.0]
        return self.law.theta.tolist() + [out.internal['rho_hat'], out.internal['kappa']]

    def save_state(self):
        """Return theta_hat (a tuple)."""
        return tuple(self.law.theta.tolist())

    def restore_state(self, saved):
        """Put theta_hat back; rho_hat and kappa read 0 until a step."""
        self.law.theta = np.array(saved, dtype=float)
        self._last = None

    def set_stiffness(self, scale):
        """Scale K and Lambda for a hold (``SpatialLaw.set_stiffness``)."""
        self.law.set_stiffness(scale)

    def set_nominal(self, params, model=None):
        """Take a new nominal ``SpatialArm`` (theta_hat, stiffness, null space kept)."""
        self._rebuild(params, self.law.gains)

    def set_gains(self, gains):
        """Take new gains (theta_hat, stiffness and null space kept)."""
        self._rebuild(self.law.model, gains)
        self._bounds()

    def _rebuild(self, nominal, gains):
        """Replace the law by one of ``nominal`` and ``gains`` with the old one's state."""
        old = self.law
        law = SpatialLaw(nominal, gains, old.nullspace, old.free_damping)
        law.theta = old.theta.copy()
        law.set_stiffness(old.stiffness)
        self.law = law


def _nullspace(kd, kp=0.0, posture=None):
    """Return the spatial law's null-space options: weighted inverse, dynamic projector."""
    return NullSpace(kd=kd, kp=kp if posture is not None else 0.0, posture=posture,
                     inverse='weighted', projector='dynamic')
