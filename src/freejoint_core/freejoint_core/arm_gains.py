"""
Null-space gains of a spatial arm from its own inertia (the rule of ``fj arm init``).

The spatial law (``spatial_law.SpatialControlLaw``) adds to the task torque
``N tau_0``, ``tau_0 = -D qd_a + kp (q_a0 - q_a)`` (null-space damping, per active joint
``D = diag(kd_i)``: the controller's ``nullspace_kd_joints``, or ``nullspace_kd`` for all;
posture stiffness ``nullspace_kp``).  The task rows are decoupled by the nominal inertia,
so the task gains ``K``, ``Lambda`` (s^-1) and the robust bound ``R`` are accelerations and
do not depend on the arm's size; the null-space gains are torques per rate and per angle,
and do.

**Derivation.** Let ``Z`` (r x (r - m)) be an orthonormal basis of the kernel of
``J~ = Da M~aa`` (the constrained Jacobian: the active joint motions that do not move the
tip, the free joints following).  Internal motion ``qd_a = Z nu`` is driven only by the
projected null-space torque (``Z^T N = Z^T`` for the dynamically consistent projector
``N = I - X Da``), so ``(Z^T M~aa Z) nud = -(Z^T D Z) nu``: the internal modes decay at
the generalized eigenvalues ``lambda`` of ``(Z^T D Z, Z^T M~aa Z)`` [1/s].  A controller
that holds its torque over a period ``dt`` (zero-order hold) maps each mode by
``1 - dt lambda``: stable for ``dt lambda < 2``, without overshoot for ``< 1``.  With one
``kd`` for all joints, ``lambda = kd / I`` with ``I`` the eigenvalues of ``Z^T M~aa Z``
(the *null-space inertia*), so the lightest mode (a light wrist spinning) bounds ``kd`` and
leaves the heavy modes undamped.  Per joint, ``kd_i`` in proportion to the joint's own
effective inertia ``I_i = (M~aa)_ii`` (about its axis, the free joints following) gives
every mode a similar rate.  The rule::

    kd_i = min(KD_REF, BETA I_i / CHECK_DT),   then all kd_i / s where
    s = max(1, CHECK_DT lambda_max)  (no internal mode reverses in one check step)
    kp = KD_REF / POSTURE_TIME

``BETA`` = 1 at the planner's check period ``CHECK_DT`` = 2 ms (the coarsest loop that
must stay stable): a joint alone would lose its whole rate in one check step, half of it
per 1-ms control period, the no-reversal bound.  Not less: the disturbance's speed noise
on a light joint grows as ``1 / sqrt(1 - (1 - a)^2)`` with ``a`` the share removed per
control period (with 0.5 here, ``a`` = 0.25, the UR10's wrist_3, 4e-4 kg m^2, passed its
3.2 rad/s under the +-0.5 N m disturbance, 1.10 x; ``a`` = 0.5 gives 0.76 of that noise).
``KD_REF`` = 20 N m s/rad caps it
(the value the UR5 and Panda were tuned with; a heavier joint is damped no harder).
``kp`` = 10 N m/rad (their value): the posture term is a slow pull (time constant
``kd_i / kp`` = 2 s on a capped joint); on a light joint it is damped by
``zeta_i = kd_i / (2 sqrt(kp I_i)) = (BETA / (2 CHECK_DT)) sqrt(I_i / kp)`` (1.77 at
``I_i`` = 5e-4 kg m^2), and ``kp dt^2 / I_i`` stays below 0.02 at 1 ms.  Everything is
taken at the start posture on the nominal model; the planner's nominal closed loop checks
the whole circle with these gains.

Hand figures: ``I_i`` = 5e-4 kg m^2 gives 1 x 5e-4 / 0.002 = 0.25 N m s/rad; 0.02 gives
10; 0.04 and above the cap 20.  (The UR5's shipped scalar ``kd`` = 20 has
``dt lambda`` = 3.3 at 2 ms on its wrist_3 mode, 0.012 kg m^2: that mode is not excited by
the circle, and at the controller's 1 ms it is 1.67, stable but reversing every tick.)

**The free joints' drivetrain damping** (:func:`drivetrain_damping`; the simulator's
``passive_damping``).  A free joint has no torque, and the law reaches it only through the
inertial coupling of the active joints' null-space torques, which a light wrist barely
feels (the law's ``free_damping`` on the UR10's wrist_2 at 5 to 50 1/s, 10 % of each
effort: no change).  Its rate under the simulator's disturbance ``d_k``
(``|d_k| <= d``, uniform, held over each control period ``dt``) is then set by the
drivetrain's viscous damping ``b`` on its effective inertia ``I = 1 / (M^-1)_pp``
(the joint's inertia with the active joints free to follow, the smallest it can have):
``I qdd = d_k - b qd``.  Two bounds follow, one per URDF limit of the joint:

* speed: from rest ``|qd| <= max |d_k| / b`` for any disturbance sequence (the rate is
  a weighted mean of the ``d_k / b``), so ``b >= d / (SPEED_SHARE v)`` keeps it at most
  ``SPEED_SHARE`` of its rated speed ``v`` (the rest is left to the arm's own motion,
  which the joint feels through the coupling);
* position: each period's impulse ``d_k dt`` ends as a displacement ``d_k dt / b``
  whatever ``I``, so over a run of ``T`` the joint walks ``sum d_k dt / b``, of standard
  deviation ``sigma sqrt(T dt) / b`` with ``sigma = d / sqrt(3)``; ``b >= Z sigma
  sqrt(T dt) / g`` keeps ``Z`` of them between the start and the nearer limit at
  ``g`` (none for a continuous joint): the walk's largest excursion passes ``Z`` standard
  deviations in about ``4 Phi(-Z)`` = 1.3e-4 of runs at ``Z`` = 4.

The floor is the larger (over all free joints); the URDF's ``<dynamics damping>`` is
taken where it is larger.  The simulator integrates the joint by explicit RK4 at
``dt_sub``, stable for ``dt_sub b / I`` up to 2.78: ``b`` is capped at ``I / dt_sub``
(the lightest free joint), and a floor above that cap is a free joint the simulated arm
cannot keep within its limits: refused, with the numbers (:class:`DampingFloor`).
Hand figures (d = 0.5 N m, dt = 1 ms, T = 15 s): the UR10's wrist_2 (3.2 rad/s, 6.11 rad
from its limit) 0.5 / (0.8 x 3.2) = 0.195 N m s/rad (position: 4 x 0.2887 x 0.1225 / 6.11
= 0.0232); the Jaco2's joint 6 (continuous, 0.838 rad/s) 0.746.
"""


import math
from typing import NamedTuple

from freejoint_core.errors import FreejointValueError
import numpy as np

KD_REF = 20.0
"""[N m s/rad] Largest null-space damping the rule gives (the shipped arms' value)."""
BETA = 1.0
"""Share of the lightest internal mode's rate the damping removes per check period."""
CHECK_DT = 2e-3
"""[s] The period the rule is stable at (the planner's nominal-loop period)."""
POSTURE_TIME = 2.0
"""[s] ``kd / kp``: the time constant of the posture term's pull."""
SPEED_SHARE = 0.8
"""Share of a free joint's rated speed the disturbance alone may drive it to."""
Z = 4.0
"""Standard deviations of the free joint's walk kept from its nearer position limit."""
DELAY_MARGIN = 0.5
"""Share of :func:`delay_step_bound` the real-time null-space damping is capped at."""
RK4_STEP = 1.0
"""Largest ``dt_sub b / I`` the simulator's damping is given (RK4 is stable to 2.78)."""


def kernel_basis(da, tol=1e-10):
    """
    Return an orthonormal basis (r, r - rank) of the kernel of ``da`` (m, r).

    Parameters
    ----------
    da : numpy.ndarray, (m, r)
        The decoupling matrix.
    tol : float
        Singular values at or below ``tol`` times the largest count as zero.

    """
    da = np.asarray(da, dtype=float)
    _, sv, vt = np.linalg.svd(da)
    rank = int(np.sum(sv > tol * (sv[0] if sv.size else 1.0)))
    return vt[rank:].T


def _terms(nominal, q):
    terms = nominal.terms(np.asarray(q, dtype=float), np.zeros(nominal.n))
    da, _, maa = nominal.decoupling(terms)
    return da, maa


def nullspace_inertia(nominal, q):
    """
    Return the null-space inertia's eigenvalues (ascending, kg m^2) (module notes).

    ``nominal`` (the law's ``SpatialArm``) at the posture ``q`` (n,) [rad]; an array of
    ``r - m`` values, empty when the arm has no redundancy (r = m).
    """
    da, maa = _terms(nominal, q)
    basis = kernel_basis(da @ maa)
    if basis.shape[1] == 0:
        return np.zeros(0)
    return np.linalg.eigvalsh(basis.T @ maa @ basis)


def active_inertia(model, q):
    """
    Return ``M~aa = ((M^-1)_aa)^-1`` (r, r) [kg m^2]: the active joints' effective inertia.

    The inertia the active joints move with the free joints following (no torque on them),
    at the angles ``q`` (n,) [rad]: a ``SpatialArm``'s from its ``decoupling`` (the law's
    own), a planar model's (``active``, ``mass_matrix(q)``) the same way from its mass matrix.
    """
    if not hasattr(model, 'mass_matrix'):
        return _terms(model, q)[1]
    q = np.asarray(q, dtype=float)
    act = list(model.active)
    inertia = np.linalg.inv(np.linalg.inv(model.mass_matrix(q))[np.ix_(act, act)])
    return 0.5 * (inertia + inertia.T)


def joint_inertia(nominal, q):
    """Return ``diag(M~aa)`` (r,) [kg m^2]: each active joint's inertia about its axis."""
    return np.diag(_terms(nominal, q)[1]).copy()


def mode_steps(nominal, q, kd, dt=CHECK_DT):
    """
    Return ``dt lambda`` of the internal modes (descending) and each one's leading joint.

    Parameters
    ----------
    nominal : SpatialArm
        The law's model.
    q : array_like, (n,)
        Posture [rad].
    kd : float or sequence of float, (r,)
        Null-space damping [N m s/rad] (one for all or per active joint).
    dt : float
        Period [s].

    Returns
    -------
    (numpy.ndarray, list of str)
        ``dt lambda`` per mode (module notes) and the name of the active joint moving most
        in it; empty without redundancy.

    """
    da, maa = _terms(nominal, q)
    basis = kernel_basis(da @ maa)
    if basis.shape[1] == 0:
        return np.zeros(0), []
    damp = np.diag(np.broadcast_to(np.asarray(kd, dtype=float), (nominal.r,)))
    inertia = basis.T @ maa @ basis
    # symmetric form: inertia^-1/2 (Z^T D Z) inertia^-1/2
    w, v = np.linalg.eigh(inertia)
    half = v @ np.diag(w ** -0.5) @ v.T
    rates, modes = np.linalg.eigh(half @ basis.T @ damp @ basis @ half)
    order = np.argsort(rates)[::-1]
    shapes = basis @ half @ modes
    joints = [nominal.joint_names[nominal.active[int(np.argmax(np.abs(shapes[:, i])))]]
              for i in order]
    return dt * rates[order], joints


def nullspace_gains(nominal, q, dt=CHECK_DT):
    """
    Return ``(kd, kp, inertia)`` of the rule (module notes) at the posture ``q``.

    Parameters
    ----------
    nominal : SpatialArm
        The law's (nominal) model.
    q : array_like, (n,)
        Start posture [rad].
    dt : float
        The period the damping must be stable at [s], > 0.

    Returns
    -------
    (tuple of float, float, numpy.ndarray)
        ``kd_i`` (r,) [N m s/rad], ``kp`` [N m/rad] and ``I_i`` (r,) [kg m^2].

    Raises
    ------
    FreejointValueError
        ``dt`` not a finite number > 0.

    """
    if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0.0):
        raise FreejointValueError(f'dt: expected a finite number > 0 [s], got {dt!r}')
    inertia = joint_inertia(nominal, q)
    kd = rule(inertia, dt)
    steps, _ = mode_steps(nominal, q, kd, dt)
    if steps.size and steps[0] > 1.0:
        kd = kd / steps[0]
    return tuple(float(v) for v in kd), KD_REF / POSTURE_TIME, inertia


def delay_step_bound(periods):
    """
    Return the largest ``dt lambda`` a mode stands when its damping acts ``periods`` late.

    A mode damped by a torque computed from the rate measured ``periods`` control periods
    before it acts maps ``x_{k+1} = x_k - a x_{k-periods}`` (``a = dt lambda``); its roots
    stay in the unit circle while ``a < 2 sin(pi / (2 (2 periods + 1)))``: 2 with none (the
    zero-order hold alone, lockstep), 1 at one period, 0.618 at two, 0.445 at three.
    ``periods``: an integer >= 0.
    """
    return 2.0 * math.sin(math.pi / (2.0 * (2 * int(periods) + 1)))


def delay_capped_damping(nominal, q, kd, periods, dt):
    """
    Return the null-space damping (r,) [N m s/rad] ``kd`` capped for a loop ``periods`` late.

    Real time, a command acts one period after its state at the least and later with the
    loop's delay, and the null-space damping of a light joint that is stable in lockstep
    is not then: the UR5's ``kd`` = 20 on its wrist_3 (``dt lambda`` 1.2 at 1 ms on the
    real arm) grows by about 9 % per period at one period more, to its rated speed within
    tens of milliseconds of the first command.  The cap keeps every internal mode within
    half the bound of :func:`delay_step_bound` (a gain margin of 2 for the model's inertia
    error and commands held over missed states): each joint's ``kd_i`` first capped at
    ``a I_i / dt`` (``I_i`` its effective inertia on ``nominal`` at ``q``), then all of them
    scaled down together if a coupled mode still steps further (:func:`mode_steps`).  A
    ``kd`` already within it is returned unchanged.

    Parameters
    ----------
    nominal : SpatialArm
        The law's (nominal) model.
    q : array_like, (n,)
        Posture [rad] (where the task begins).
    kd : float or sequence of float, (r,)
        The configured damping [N m s/rad].
    periods : int
        Control periods from a state to the period its command acts in, >= 1.
    dt : float
        Control period [s], > 0.

    Returns
    -------
    tuple of float, (r,)

    """
    kd = np.broadcast_to(np.asarray(kd, dtype=float), (nominal.r,)).copy()
    step = DELAY_MARGIN * delay_step_bound(periods)
    kd = np.minimum(kd, step * joint_inertia(nominal, q) / dt)
    steps, _ = mode_steps(nominal, q, kd, dt)
    if steps.size and steps[0] > step:
        kd = kd * (step / steps[0])
    return tuple(float(v) for v in kd)


def rule(inertia, dt=CHECK_DT):
    """Return ``min(KD_REF, BETA I_i / dt)`` [N m s/rad] of joint inertias ``I_i`` [kg m^2]."""
    return np.minimum(KD_REF, BETA * np.asarray(inertia, dtype=float) / dt)


class DampingFloor(NamedTuple):
    """
    The free joints' drivetrain damping of :func:`drivetrain_damping` and its terms.

    Attributes
    ----------
    floor : float
        [N m s/rad] The least damping the rule asks (module notes).
    cap : float
        [N m s/rad] The largest the simulator integrates stably (``I / dt_sub``).
    joint : str
        The free joint whose bound sets ``floor``.
    cause : str
        ``'speed'`` or ``'position'``: which of its limits sets it.
    reason : str
        '' or why no damping serves (``floor > cap``), one line with the numbers.

    """

    floor: float
    cap: float
    joint: str
    cause: str
    reason: str


def drivetrain_damping(real, q0, dist, dt, dt_sub, run_s):
    """
    Return the free joints' damping floor and cap (:class:`DampingFloor`, module notes).

    Parameters
    ----------
    real : SpatialArm
        The real arm (its free joints, URDF limits and inertia).
    q0 : array_like, (n,)
        The start posture [rad], at rest.
    dist : float
        The disturbance bound ``d`` [N m] (the simulator's ``dist_bound``), >= 0.
    dt, dt_sub : float
        The control period and the simulator's RK4 step [s], > 0.
    run_s : float
        The run's length ``T`` [s] (circle and hold), > 0.

    Raises
    ------
    FreejointValueError
        A number not finite or out of range.

    """
    for name, value, low in (('dist', dist, 0.0), ('dt', dt, None), ('dt_sub', dt_sub, None),
                             ('run_s', run_s, None)):
        ok = isinstance(value, (int, float)) and np.isfinite(value) and (
            value >= low if low is not None else value > 0.0)
        if not ok:
            raise FreejointValueError(f'{name}: expected a finite number '
                                      f"{'>= 0' if low is not None else '> 0'}, got {value!r}")
    q0 = np.asarray(q0, dtype=float)
    minv = real.terms(q0, np.zeros(real.n)).Minv
    sigma = dist / np.sqrt(3.0)
    best = (0.0, '', '')
    caps = []
    for p in real.passive:
        name = real.joint_names[p]
        inertia = 1.0 / float(minv[p, p])
        caps.append((RK4_STEP * inertia / dt_sub, name, inertia))
        speed = dist / (SPEED_SHARE * float(real.velocity[p]))
        best = max(best, (speed, name, 'speed'))
        gap = min(q0[p] - real.lower[p], real.upper[p] - q0[p])
        if np.isfinite(gap):
            walk = Z * sigma * np.sqrt(run_s * dt) / max(gap, 1e-9)
            best = max(best, (walk, name, 'position'))
    cap, cap_joint, inertia = min(caps)
    floor, joint, cause = best
    reason = ''
    if floor > cap:
        p = real.joint_names.index(joint)
        why = (f'its rated speed {real.velocity[p]:.4g} rad/s needs b >= d / '
               f'({SPEED_SHARE} v) = {floor:.4g}' if cause == 'speed' else
               f'its position limits [{real.lower[p]:.4g}, {real.upper[p]:.4g}] rad from '
               f'{q0[p]:.4g} rad over {run_s:g} s need b >= {Z:g} sigma sqrt(T dt) / gap = '
               f'{floor:.4g}')
        reason = (f'free joint {joint} cannot be kept within its limits under the '
                  f'+-{dist:g} N m disturbance: {why} N m s/rad, above the {cap:.4g} N m s/rad '
                  f"the simulator's RK4 integrates stably on {cap_joint}'s effective inertia "
                  f'{inertia:.3g} kg m^2 at dt_sub {dt_sub:g} s (I / dt_sub)')
    return DampingFloor(float(floor), float(cap), joint, cause, reason)
