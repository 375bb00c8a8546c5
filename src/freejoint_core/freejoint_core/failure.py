"""
Joint failure: detection, isolation and the reconfiguration verdict (no ROS).

Momentum residual (De Luca and Mattone, ICRA 2003).  With the generalised momentum
``p = M(q) qd``, eq. (1) gives ``pdot = tau + C^T qd - G + d`` (``Mdot = C + C^T``), so
on the nominal model::

    r(t) = K_O (p(t) - p(0) - int_0^t (tau + C^T qd - G + r) ds)

obeys ``rdot = K_O (Delta - r)``: ``r`` is ``Delta``, the generalised force the model
does not explain (disturbance, model error, a lost actuator torque), first-order
filtered with bandwidth ``K_O``, and decoupled per joint (``r_i`` sees only joint i's
force).  A joint whose actuator fails loses its commanded torque ``tau_i``: ``r_i ->
-tau_i``.

Discrete form (:class:`MomentumObserver`), at ticks ``k = 0, 1, ...`` with the torque
``tau_{k-1}`` applied over the last period (zero-order hold)::

    S_k = S_{k-1} + dt (tau_{k-1} + (beta_{k-1} + beta_k) / 2 + r_{k-1}),  S_0 = 0
    r_k = K_O (p_k - p_0 - S_k),                                        r_0 = 0

with ``beta = C^T qd - G`` (trapezoid over the period).  For a constant unexplained
force ``Delta`` it gives ``r_k = Delta (1 - (1 - K_O dt)^k)`` exactly (the tests check
it), stable for ``K_O dt < 2``.  ``C^T qd = dT/dq`` (``T`` the kinetic energy) is
computed in closed form for the 3-link arm (absolute link angles, as
``freejoint_core.fast3``) and from the Christoffel ``C`` of ``ArmModel`` otherwise.

Detection (:class:`ResidualDetector`): joint ``i`` is flagged when ``|r_i| > margin
level_i`` for ``ticks`` consecutive ticks; if several are flagged at once, the one with
the largest ``|r_i| / (margin level_i)`` is isolated.  ``level_i`` is the largest
fault-free ``|r_i|`` measured for the configuration (``DEFAULT_LEVELS``; how they were
measured: docs/failures.md).  :class:`EffortDetector` compares the command of the last
period with the measured effort (``joint_states.effort``): a failed joint reads 0.

Reconfiguration (:class:`Reconfigurer`): the failed joint joins the passive set; the
new arm is judged by :func:`assess_passive_set`: ``r >= m``, ``det(Da Da^T)`` at the
current pose, and the internal motion (the zero dynamics) simulated along the rest of
the path: the nominal model driven by the exact nominal law (computed torque: the end
effector follows the path exactly, only the passive joints move freely), from the
current state and from a state with the passive angles moved by ``delta``.  The set
cannot be held when that motion leaves the controllable region (``det`` below
``det_min``), turns faster than ``qd_max``, or amplifies the perturbation more than
``growth_max`` times (an unstable zero dynamics: the law keeps the end effector on the
path while the free links run away, as joint 2 free in the vertical plane does).
Then the verdict is ``cannot_track`` and :func:`least_harm_torque` gives what the
remaining joints should do.

"""

from dataclasses import dataclass, replace
import math

from freejoint_core.arm import ArmModel, ArmParams, check_vector
from freejoint_core.errors import FreejointValueError, positive
from freejoint_core.models import make_model
import numpy as np

M_TASK = 2
"""Task dimension (planar end-effector position)."""

DEFAULT_K_O = 100.0
"""Observer gain [1/s] (residual bandwidth)."""
DEFAULT_MARGIN = 1.5
"""Threshold = margin x level."""
DEFAULT_TICKS = 3
"""Consecutive ticks over the threshold before a joint is flagged."""

DEFAULT_LEVELS = {
    # (gravity > 0, passive set): largest fault-free |r_i| [N m] measured offline (70 %
    # nominal, |d| <= 0.5 N m, seeds 0-9, circle + 5 s hold, K_O = 100; for passive (2,)
    # the larger of the paper's arm from the start and the arm after joint 3's failure):
    # docs/failures.md.
    (False, ()): (0.24, 0.44, 0.29),
    (False, (2,)): (3.62, 3.31, 0.23),
    (True, ()): (1.55, 3.22, 1.36),
    (True, (2,)): (31.9, 18.9, 0.96),
}
"""Fault-free residual levels of the paper's arm per (vertical, passive set)."""

DEFAULT_EFFORT_TOL = 0.05
"""Effort detector: absolute tolerance [N m] on |command - measured|."""
DEFAULT_EFFORT_REL = 0.1
"""Effort detector: relative tolerance (of |command|)."""
DEFAULT_EFFORT_TICKS = 2
"""Effort detector: consecutive ticks over the tolerance."""

DEFAULT_DAMPING = 0.3
"""Least harm, no gravity: ``tau = -c qd`` on the remaining joints [N m s/rad]."""
DEFAULT_HOLD_KP = 10.0
"""Least harm with gravity: soft hold stiffness [N m/rad]."""
DEFAULT_HOLD_KD = 5.0
"""Least harm with gravity: soft hold damping [N m s/rad]."""

TRACKING = 'tracking'
CANNOT_TRACK = 'cannot_track'
DETECTED_BY = ('residual', 'effort', 'notice')


def default_levels(params):
    """
    Return the measured fault-free residual levels for the paper's arm, or None.

    Parameters
    ----------
    params : ArmParams
        The nominal arm (its gravity and passive set choose the row).

    Returns
    -------
    tuple of float, (n,), or None
        The ``DEFAULT_LEVELS`` row [N m]; for a passive set without a measured row (e.g.
        joint 2 free) the element-wise largest row of the same case (conservative: fewer
        false alarms, slower detection); None when the arm is not the paper's 3-link arm
        (levels must then be measured and given).

    """
    if not isinstance(params, ArmParams):
        raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
    if params.n != 3:
        return None
    vertical = params.gravity > 0.0
    row = DEFAULT_LEVELS.get((vertical, params.passive))
    if row is None:
        rows = [v for (g, _), v in DEFAULT_LEVELS.items() if g == vertical]
        row = tuple(max(col) for col in zip(*rows))
    return row


def _n_vector(x, n, name):
    if type(x) is np.ndarray:
        x = x.tolist()
    try:
        vals = [float(v) for v in x]
    except (TypeError, ValueError):
        vals = None
    if vals is None or len(vals) != n or not all(map(math.isfinite, vals)):
        shape = np.shape(x) if not isinstance(x, (str, bytes)) else '?'
        raise FreejointValueError(
            f'{name}: expected {n} finite numbers (shape ({n},)), got {x!r} with shape {shape}')
    return vals


class MomentumObserver:
    """
    Generalised-momentum residual on a (nominal) model, one call per control tick.

    Parameters
    ----------
    params : ArmParams
        The model's parameters (nominal); the passive set does not matter (``M``,
        ``C``, ``G`` are joint-space).
    k_o : float
        Observer gain ``K_O`` [1/s], > 0; ``k_o dt`` must stay below 2 (checked).

    Attributes
    ----------
    residual : numpy.ndarray, (n,)
        The last residual [N m] (zeros before the second tick).

    """

    def __init__(self, params, k_o=DEFAULT_K_O):
        if not isinstance(params, ArmParams):
            raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
        self.k_o = positive('k_o', k_o)
        self.params = params
        self.n = params.n
        self._model = ArmModel(params)
        if self.n == 3:
            (l1, l2, _), (m1, m2, m3) = params.lengths, params.masses
            (i1, i2, i3), (c1, c2, c3) = params.inertias, params.com
            self._d = (m1 * c1 * c1 + l1 * l1 * (m2 + m3) + i1,
                       m2 * c2 * c2 + l2 * l2 * m3 + i2, m3 * c3 * c3 + i3)
            h2 = m2 * c2 + l2 * m3
            h3 = m3 * c3
            self._h = (l1 * h2, l1 * h3, l2 * h3)
            g = params.gravity
            self._gh = (g * (m1 * c1 + l1 * (m2 + m3)), g * h2, g * h3)
        self.rebase()

    def rebase(self):
        """Restart the integral at the next tick (``p_0`` = the momentum then, ``r`` = 0)."""
        self._s = None
        self._p0 = None
        self._beta = None
        self._r = [0.0] * self.n
        self.residual = np.zeros(self.n)

    def momentum_terms(self, q, qd):
        """
        Return ``p = M(q) qd`` and ``beta = C(q, qd)^T qd - G(q)`` of the model.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Joint angles [rad] and velocities [rad/s].

        Returns
        -------
        p : list of float, (n,)
            Generalised momentum [N m s].
        beta : list of float, (n,)
            [N m].

        """
        q = _n_vector(q, self.n, 'q')
        qd = _n_vector(qd, self.n, 'qd')
        if self.n == 3:
            return self._terms3(q, qd)
        model = self._model
        mom = model.mass_matrix(q) @ qd
        beta = model.coriolis_matrix(q, qd).T @ qd - model.gravity_torque(q)
        return mom.tolist(), beta.tolist()

    def _terms3(self, q, qd):
        """Compute ``p = S^T M_phi w``, ``beta = S^T (dT/dphi - G)`` on absolute angles."""
        f1 = q[0]
        f2 = f1 + q[1]
        f3 = f2 + q[2]
        w1 = qd[0]
        w2 = w1 + qd[1]
        w3 = w2 + qd[2]
        d1, d2, d3 = self._d
        h12, h13, h23 = self._h
        x12 = h12 * math.cos(f1 - f2)
        x13 = h13 * math.cos(f1 - f3)
        x23 = h23 * math.cos(f2 - f3)
        s12 = h12 * math.sin(f1 - f2) * w1 * w2
        s13 = h13 * math.sin(f1 - f3) * w1 * w3
        s23 = h23 * math.sin(f2 - f3) * w2 * w3
        a1 = d1 * w1 + x12 * w2 + x13 * w3
        a2 = x12 * w1 + d2 * w2 + x23 * w3
        a3 = x13 * w1 + x23 * w2 + d3 * w3
        g1, g2, g3 = self._gh
        # dT/dphi_a = -sum_b H_ab sin(phi_a - phi_b) w_a w_b
        b1 = -(s12 + s13) - g1 * math.cos(f1)
        b2 = (s12 - s23) - g2 * math.cos(f2)
        b3 = (s13 + s23) - g3 * math.cos(f3)
        return [a1 + a2 + a3, a2 + a3, a3], [b1 + b2 + b3, b2 + b3, b3]

    def step(self, q, qd, tau_applied, dt):
        """
        Advance the residual to this tick.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Measured joint angles [rad] and velocities [rad/s] at this tick.
        tau_applied : array_like, (n,)
            Actuator torque on every joint over the period that ended now [N m] (the
            command sent last tick, 0 on passive and known-failed joints); ignored on
            the first tick after construction or ``rebase``.
        dt : float
            That period [s], > 0, with ``k_o dt < 2``.

        Returns
        -------
        numpy.ndarray, (n,)
            The residual ``r`` [N m] (zeros on the first tick).

        """
        dt = positive('dt', dt)
        if self.k_o * dt >= 2.0:
            raise FreejointValueError(f'dt: k_o dt = {self.k_o * dt} must be < 2 (unstable)')
        tau = _n_vector(tau_applied, self.n, 'tau_applied')
        mom, beta = self.momentum_terms(q, qd)
        if self._s is None:
            self._s = [0.0] * self.n
            self._p0 = mom
        else:
            self._s = [s + dt * (t + 0.5 * (b0 + b1) + r)
                       for s, t, b0, b1, r in zip(self._s, tau, self._beta, beta, self._r)]
            self._r = [self.k_o * (p - p0 - s) for p, p0, s in zip(mom, self._p0, self._s)]
        self._beta = beta
        self.residual = np.array(self._r)
        return self.residual.copy()


def _count(name, value, low=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise FreejointValueError(f'{name}: expected an int >= {low}, got {value!r}')
    return int(value)


class ResidualDetector:
    """
    Per-joint threshold on the residual, flagged after consecutive ticks, isolated.

    Parameters
    ----------
    levels : array_like, (n,)
        Fault-free residual level of each joint [N m], > 0.
    margin : float
        Threshold = ``margin * levels``, > 0.
    ticks : int
        Consecutive ticks over the threshold, >= 1.
    watch : iterable of int, optional
        Joints that can be flagged (default all; give the active ones: a passive
        joint has nothing to lose).

    """

    def __init__(self, levels, margin=DEFAULT_MARGIN, ticks=DEFAULT_TICKS, watch=None):
        lev = check_vector(levels, len(np.atleast_1d(levels)), 'levels')
        if np.any(lev <= 0.0):
            raise FreejointValueError(f'levels: must be > 0, got {lev.tolist()}')
        self.n = lev.size
        self.margin = positive('margin', margin)
        self.ticks = _count('ticks', ticks)
        self.thresholds = (self.margin * lev).tolist()
        self.set_watch(range(self.n) if watch is None else watch)

    def set_watch(self, joints):
        """Watch only ``joints`` (indices in ``[0, n)``) from now; counts restart."""
        joints = tuple(sorted({int(j) for j in joints}))
        if any(j < 0 or j >= self.n for j in joints):
            raise FreejointValueError(f'joints: indices must lie in [0, {self.n}), got {joints}')
        self.watch = joints
        self.reset()

    def reset(self):
        """Clear the consecutive-tick counts."""
        self._count = [0] * self.n

    def update(self, residual):
        """
        Feed one tick's residual; return the isolated joint, or None.

        Parameters
        ----------
        residual : array_like, (n,)
            The observer's residual [N m].

        Returns
        -------
        int or None
            The watched joint flagged this tick (largest ratio to its threshold among
            those at ``ticks`` consecutive ticks), else None.

        """
        res = _n_vector(residual, self.n, 'residual')
        best, best_ratio = None, 0.0
        for j in self.watch:
            ratio = abs(res[j]) / self.thresholds[j]
            if ratio > 1.0:
                self._count[j] += 1
                if self._count[j] >= self.ticks and ratio > best_ratio:
                    best, best_ratio = j, ratio
            else:
                self._count[j] = 0
        return best


class EffortDetector:
    """
    Commanded versus measured effort: a failed joint reads 0 against its command.

    Parameters
    ----------
    n : int
        Number of joints.
    tol : float
        Absolute tolerance [N m], > 0.
    rel : float
        Relative tolerance (fraction of ``|command|``), >= 0.
    ticks : int
        Consecutive ticks over the tolerance, >= 1.
    watch : iterable of int, optional
        Joints that can be flagged (default all).

    """

    def __init__(self, n, tol=DEFAULT_EFFORT_TOL, rel=DEFAULT_EFFORT_REL,
                 ticks=DEFAULT_EFFORT_TICKS, watch=None):
        self.n = _count('n', n)
        self.tol = positive('tol', tol)
        self.rel = positive('rel', rel, allow_zero=True)
        self.ticks = _count('ticks', ticks)
        self.set_watch(range(self.n) if watch is None else watch)

    def set_watch(self, joints):
        """Watch only ``joints`` from now; counts restart."""
        joints = tuple(sorted({int(j) for j in joints}))
        if any(j < 0 or j >= self.n for j in joints):
            raise FreejointValueError(f'joints: indices must lie in [0, {self.n}), got {joints}')
        self.watch = joints
        self._count = [0] * self.n

    def update(self, commanded, measured):
        """
        Feed one period's command and the effort measured over it.

        Parameters
        ----------
        commanded : array_like, (n,)
            Torque commanded for the last period [N m].
        measured : array_like, (n,)
            Effort the driver reports for it [N m].

        Returns
        -------
        int or None
            The watched joint with the largest mismatch among those over the tolerance
            for ``ticks`` consecutive ticks, else None.

        """
        cmd = _n_vector(commanded, self.n, 'commanded')
        meas = _n_vector(measured, self.n, 'measured')
        best, best_gap = None, 0.0
        for j in self.watch:
            gap = abs(cmd[j] - meas[j])
            if gap > self.tol + self.rel * abs(cmd[j]):
                self._count[j] += 1
                if self._count[j] >= self.ticks and gap > best_gap:
                    best, best_gap = j, gap
            else:
                self._count[j] = 0
        return best


@dataclass(frozen=True)
class Assessment:
    """
    Whether the law can hold an arm with a given passive set (see the module notes).

    Attributes
    ----------
    verdict : str
        ``'tracking'`` or ``'cannot_track'``.
    reason : str
        Why (empty when tracking).
    det : float
        ``det(Da Da^T)`` of the nominal model at the current pose (0 if r < m).
    min_det : float
        Smallest ``det`` along the simulated internal motion (nan if not simulated).
    growth : float
        Largest ``|dq_p(t)| / delta`` of the perturbed internal motion (nan if not
        simulated).
    max_qd : float
        Fastest joint speed [rad/s] along it (nan if not simulated).

    """

    verdict: str
    reason: str
    det: float
    min_det: float = math.nan
    growth: float = math.nan
    max_qd: float = math.nan


DEFAULT_DET_MIN = 1e-3
"""Assessment: smallest acceptable det(Da Da^T) at the pose and along the internal motion."""
DEFAULT_GROWTH_MAX = math.inf
"""Assessment: largest acceptable amplification of a passive-angle perturbation (default
no limit: reported only; a swinging free link's phase drift grows it without divergence)."""
DEFAULT_QD_MAX = 100.0
"""Assessment: fastest acceptable joint speed of the internal motion [rad/s]."""


def _rates_general(model, passive, kv, kp):
    """qdd(q, qd, ref) of the nominal model under computed torque (any n, r = m)."""
    n = model.n
    active = [j for j in range(n) if j not in passive]

    def rates(q, qd, ref):
        e = model.fk(q) - ref[0:2]
        jac = model.jacobian(q)
        a_ref = ref[4:6] - kv * (jac @ qd - ref[2:4]) - kp * e - model.jdot_qdot(q, qd)
        # unknowns (qdd (n), tau_a (r)); rows: M qdd - B tau = -h (n), J qdd = a_ref (2)
        mat = np.zeros((n + M_TASK, n + len(active)))
        mat[:n, :n] = model.mass_matrix(q)
        for c, j in enumerate(active):
            mat[j, n + c] = -1.0
        mat[n:, :n] = jac
        rhs = np.concatenate([-(model.coriolis(q, qd) + model.gravity_torque(q)), a_ref])
        return np.linalg.solve(mat, rhs)[:n]

    return rates


def _rates_fast3(model, kv, kp):
    """Return the same for the 3-link kernel with one passive joint: ``Da^-1 (a_ref - b)``."""
    ia, ib = model.active

    def rates(q, qd, ref):
        q0, q1, q2 = q.tolist()
        w0, w1, w2 = qd.tolist()
        px, py, vx, vy, d00, d01, d10, d11, bx, by = model.task(q0, q1, q2, w0, w1, w2)
        wx = ref[4] - kv * (vx - ref[2]) - kp * (px - ref[0]) - bx
        wy = ref[5] - kv * (vy - ref[3]) - kp * (py - ref[1]) - by
        det = d00 * d11 - d01 * d10
        tau = [0.0, 0.0, 0.0]
        tau[ia] = (d11 * wx - d01 * wy) / det
        tau[ib] = (d00 * wy - d10 * wx) / det
        return np.array(model.qdd(q0, q1, q2, w0, w1, w2, *tau))

    return rates


def _simulate_internal(sub, q, qd, trajectory, t0, horizon, dt, kv, kp):
    """RK4 of the zero dynamics; returns (min det, list of passive angles, max |qd|)."""
    steps = int(round(horizon / dt))
    passive = list(sub.passive)
    model = make_model(sub)
    rates = _rates_fast3(model, kv, kp) if hasattr(model, 'task') else \
        _rates_general(model, passive, kv, kp)
    q = np.array(q, dtype=float)
    qd = np.array(qd, dtype=float)
    min_det, qp, max_qd = math.inf, [], 0.0

    def ref(t):
        return np.array(trajectory.sample_tuple(t))

    for k in range(steps):
        t = t0 + k * dt
        da, _ = model.decoupling(q, qd)
        min_det = min(min_det, float(np.linalg.det(da @ da.T)))
        qp.append(q[passive].copy())
        r0, r1, r2 = ref(t), ref(t + 0.5 * dt), ref(t + dt)
        a1 = rates(q, qd, r0)
        a2 = rates(q + 0.5 * dt * qd, qd + 0.5 * dt * a1, r1)
        a3 = rates(q + 0.5 * dt * (qd + 0.5 * dt * a1), qd + 0.5 * dt * a2, r1)
        a4 = rates(q + dt * (qd + 0.5 * dt * a2), qd + dt * a3, r2)
        q = q + dt * qd + dt * dt / 6.0 * (a1 + a2 + a3)
        qd = qd + dt / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
            return min_det, qp, math.inf
        max_qd = max(max_qd, float(np.max(np.abs(qd))))
        if max_qd > 1e3:
            return min_det, qp, math.inf
    qp.append(q[passive].copy())
    return min_det, qp, max_qd


def assess_passive_set(params, passive, q, qd, trajectory=None, t=0.0, horizon=None,
                       dt=4e-3, delta=1e-3, det_min=DEFAULT_DET_MIN,
                       growth_max=DEFAULT_GROWTH_MAX, qd_max=DEFAULT_QD_MAX,
                       gains=(100.0, 50.0)):
    """
    Decide whether the law can hold the arm with ``passive`` free (see the module notes).

    Parameters
    ----------
    params : ArmParams
        The nominal arm (its own passive set is replaced by ``passive``).
    passive : iterable of int
        The new passive set (the old one plus the failed joints).
    q, qd : array_like, (n,)
        Current joint angles [rad] and velocities [rad/s].
    trajectory : object with ``sample_tuple(t)``, optional
        The path still to follow (``CircleQuintic``); None: only the pose checks.
    t : float
        Current time on the path [s].
    horizon : float, optional
        Simulated span [s]; default the rest of the path plus 1 s (``duration - t + 1``).
    dt : float
        RK4 step of the internal-motion simulation [s].
    delta : float
        Perturbation of the passive angles [rad].
    det_min, growth_max, qd_max : float
        Limits (module constants' docs).
    gains : tuple of float
        ``(K, Lambda)`` of the error dynamics that keep the simulated end effector on
        the path (the law's K and Lambda).

    Returns
    -------
    Assessment

    """
    if not isinstance(params, ArmParams):
        raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
    passive = tuple(sorted({int(j) for j in passive}))
    if any(j < 0 or j >= params.n for j in passive):
        raise FreejointValueError(f'passive: indices must lie in [0, {params.n}), got {passive}')
    q = check_vector(q, params.n, 'q')
    qd = check_vector(qd, params.n, 'qd')
    r = params.n - len(passive)
    if r < M_TASK:
        return Assessment(CANNOT_TRACK, f'r = {r} active joints < m = {M_TASK}', 0.0)
    sub = replace(params, passive=passive)
    model = make_model(sub)
    da, _ = model.decoupling(q, qd)
    det = float(np.linalg.det(da @ da.T))
    if det < det_min:
        return Assessment(CANNOT_TRACK, f'det(Da Da^T) = {det:.3g} < {det_min:g} at the pose',
                          det)
    if trajectory is None or not passive:
        return Assessment(TRACKING, '', det)
    if horizon is None:
        horizon = max(0.0, trajectory.duration - t) + 1.0
    horizon = positive('horizon', horizon)
    k, lam = gains
    kv, kp = k + lam, k * lam
    try:
        with np.errstate(all='ignore'):
            min_det, base, max_qd = _simulate_internal(sub, q, qd, trajectory, t, horizon, dt,
                                                       kv, kp)
            q_pert = q.copy()
            q_pert[list(passive)] += delta
            _, pert, max_qd2 = _simulate_internal(sub, q_pert, qd, trajectory, t, horizon, dt,
                                                  kv, kp)
    except (np.linalg.LinAlgError, ArithmeticError, ValueError):
        return Assessment(CANNOT_TRACK, 'the internal motion cannot be integrated', det)
    max_qd = max(max_qd, max_qd2)
    steps = min(len(base), len(pert))
    growth = max(float(np.max(np.abs(pert[i] - base[i]))) for i in range(steps)) / delta \
        if math.isfinite(max_qd) else math.inf
    if not math.isfinite(max_qd) or max_qd > qd_max:
        why = f'the internal motion runs away (joint speed {max_qd:.3g} rad/s)'
    elif min_det < det_min:
        why = f'the internal motion reaches det(Da Da^T) = {min_det:.3g}'
    elif growth > growth_max:
        why = f'the internal motion is unstable (perturbation x{growth:.3g})'
    else:
        return Assessment(TRACKING, '', det, min_det, growth, max_qd)
    return Assessment(CANNOT_TRACK, why, det, min_det, growth, max_qd)


def least_harm_torque(params, active, q, qd, q_hold, damping=DEFAULT_DAMPING,
                      kp=DEFAULT_HOLD_KP, kd=DEFAULT_HOLD_KD, limit=None):
    """
    Return the torque of the remaining joints when the arm cannot track.

    No gravity: a light damper ``tau_i = -damping qd_i``.  With gravity: a soft hold
    with gravity compensation ``tau_i = G_i(q) - kp (q_i - q_hold_i) - kd qd_i`` (nominal
    ``G``).  Both on the still-working joints ``active`` only.

    Parameters
    ----------
    params : ArmParams
        The nominal arm (its gravity decides the form).
    active : iterable of int
        Joints that can still be driven.
    q, qd : array_like, (n,)
        Joint angles [rad] and velocities [rad/s].
    q_hold : array_like, (n,)
        Angles to hold [rad] (the pose when the verdict was given).
    damping, kp, kd : float
        Gains, >= 0.
    limit : array_like, (len(active),), optional
        Per-joint torque bound [N m]; the torque is clipped to it.

    Returns
    -------
    numpy.ndarray, (len(active),)
        Torques [N m] in ``active`` order.

    """
    if not isinstance(params, ArmParams):
        raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
    active = [int(j) for j in active]
    q = check_vector(q, params.n, 'q')
    qd = check_vector(qd, params.n, 'qd')
    q_hold = check_vector(q_hold, params.n, 'q_hold')
    if params.gravity > 0.0:
        g = make_model(params).gravity_torque(q)
        tau = np.array([g[j] - positive('kp', kp, True) * (q[j] - q_hold[j])
                        - positive('kd', kd, True) * qd[j] for j in active])
    else:
        tau = -positive('damping', damping, True) * qd[active]
    if limit is not None:
        lim = check_vector(limit, len(active), 'limit')
        tau = np.clip(tau, -lim, lim)
    return tau


@dataclass(frozen=True)
class Switch:
    """
    The outcome of a failure given to :class:`Reconfigurer`.

    Attributes
    ----------
    joint : int
        The failed joint.
    t : float
        When it was detected or notified [s].
    detected_by : str
        ``'residual'``, ``'effort'`` or ``'notice'``.
    passive : tuple of int
        The passive set from now (old passive plus every failed joint).
    nominal : ArmParams or None
        The nominal arm with that passive set (None when r < m or after cannot_track).
    assessment : Assessment
        The verdict and why.

    """

    joint: int
    t: float
    detected_by: str
    passive: tuple
    nominal: object
    assessment: Assessment

    @property
    def verdict(self):
        """Return ``'tracking'`` or ``'cannot_track'``."""
        return self.assessment.verdict


class Reconfigurer:
    """
    Keeps the passive set, the observer and the detectors consistent across failures.

    Parameters
    ----------
    nominal : ArmParams
        The nominal arm at start (its passive set: the joints free from the start).
    dt : float
        Control period [s].
    k_o, margin, ticks : float, float, int
        Observer gain and residual detector settings.
    levels : callable or None
        ``levels(nominal) -> (n,)`` fault-free levels per configuration; default
        :func:`default_levels` (raises if it has none for the arm).
    effort : bool
        Also run the :class:`EffortDetector` (when the driver reports effort).
    assess : dict, optional
        Keyword arguments of :func:`assess_passive_set`.
    trajectory : object, optional
        The path (for the internal-motion check).

    """

    def __init__(self, nominal, dt, k_o=DEFAULT_K_O, margin=DEFAULT_MARGIN,
                 ticks=DEFAULT_TICKS, levels=None, effort=False, assess=None,
                 trajectory=None):
        if not isinstance(nominal, ArmParams):
            raise FreejointValueError(
                f'nominal: expected ArmParams, got {type(nominal).__name__}')
        self.dt = positive('dt', dt)
        self.nominal = nominal
        self.n = nominal.n
        self.failed = ()
        self.switches = []
        self.verdict = TRACKING
        self._levels = default_levels if levels is None else levels
        self._margin = margin
        self._ticks = ticks
        self._assess = dict(assess or {})
        self.trajectory = trajectory
        self.observer = MomentumObserver(nominal, k_o)
        self.effort = EffortDetector(self.n) if effort else None
        self._make_detector()

    def _make_detector(self):
        lev = self._levels(self.nominal)
        if lev is None:
            raise FreejointValueError(
                'levels: no fault-free residual levels for this arm; measure and give them')
        watch = [j for j in self.nominal.active if j not in self.failed]
        self.detector = ResidualDetector(lev, self._margin, self._ticks, watch)
        if self.effort is not None:
            self.effort.set_watch(watch)

    @property
    def active(self):
        """Return the joints still driven (active and not failed)."""
        return tuple(j for j in self.nominal.active if j not in self.failed)

    def applied(self, tau_active):
        """Full (n,) torque vector of a command in ``active`` order (0 elsewhere)."""
        full = [0.0] * self.n
        for j, v in zip(self.active, tau_active):
            full[j] = float(v)
        return full

    def observe(self, q, qd, tau_last, effort=None):
        """
        One tick of detection.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Measured state at this tick.
        tau_last : array_like, (n,)
            Torque commanded for the last period, all joints [N m].
        effort : array_like, (n,), optional
            Effort measured over it (used when the effort detector runs).

        Returns
        -------
        (joint, how) or None
            A newly isolated failed joint and ``'residual'`` or ``'effort'``.

        """
        res = self.observer.step(q, qd, tau_last, self.dt)
        if self.effort is not None and effort is not None:
            j = self.effort.update(tau_last, effort)
            if j is not None:
                return j, 'effort'
        if self.verdict != TRACKING:
            # a falling arm's model error is no fault-free level: only the effort
            # mismatch still isolates a further failure (dropped from the least-harm set)
            return None
        j = self.detector.update(res)
        if j is not None:
            return j, 'residual'
        return None

    def switch(self, joint, t, detected_by, q, qd):
        """
        Take a failed joint out of the active set and judge the new arm.

        Parameters
        ----------
        joint : int
            The failed joint.
        t : float
            Time of the detection or notice [s] (the path time of the check).
        detected_by : {'residual', 'effort', 'notice'}
            How it was found.
        q, qd : array_like, (n,)
            Current state.

        Returns
        -------
        Switch

        """
        if detected_by not in DETECTED_BY:
            raise FreejointValueError(
                f'detected_by: expected one of {DETECTED_BY}, got {detected_by!r}')
        if isinstance(joint, bool) or not isinstance(joint, (int, np.integer)) \
                or not 0 <= joint < self.n:
            raise FreejointValueError(f'joint: expected an int in [0, {self.n}), got {joint!r}')
        joint = int(joint)
        self.failed = tuple(sorted(set(self.failed) | {joint}))
        if self.verdict != TRACKING:
            passive = tuple(sorted(set(self.nominal.passive) | set(self.failed)))
            sw = Switch(joint, float(t), detected_by, passive, None, Assessment(
                CANNOT_TRACK, 'a further failure after cannot_track', 0.0))
            self.detector.set_watch([j for j in self.detector.watch if j != joint])
            if self.effort is not None:
                self.effort.set_watch([j for j in self.effort.watch if j != joint])
            self.switches.append(sw)
            return sw
        passive = tuple(sorted(set(self.nominal.passive) | set(self.failed)))
        assessment = assess_passive_set(self.nominal, passive, q, qd, self.trajectory, t,
                                        **self._assess)
        new = None
        if self.n - len(passive) >= M_TASK:
            new = replace(self.nominal, passive=passive)
        self.verdict = assessment.verdict
        if new is not None and assessment.verdict == TRACKING:
            self.nominal = new
            self.failed = ()
            self._make_detector()
        else:
            self.detector.set_watch([j for j in self.detector.watch if j != joint])
            if self.effort is not None:
                self.effort.set_watch([j for j in self.effort.watch if j != joint])
        self.observer.rebase()
        sw = Switch(joint, float(t), detected_by, passive, new, assessment)
        self.switches.append(sw)
        return sw
