"""
Null-space gains of a spatial arm from its own inertia (the rule of ``fj arm init``).

The spatial law (``spatial_law.SpatialControlLaw``) adds to the task torque
``N tau_0``, ``tau_0 = -kd qd_a + kp (q_a0 - q_a)`` (null-space damping and posture
stiffness, the controller's ``nullspace_kd`` / ``nullspace_kp``).  The task rows are
decoupled by the nominal inertia, so the task gains ``K``, ``Lambda`` (s^-1) and the
robust bound ``R`` are accelerations and do not depend on the arm's size; the null-space
gains are torques per rate and per angle, and do.

**Derivation.** Let ``Z`` (r x (r - m)) be an orthonormal basis of the kernel of
``J~ = Da M~aa`` (the constrained Jacobian: the active joint motions that do not move the
tip, the free joints following).  Internal motion ``qd_a = Z nu``
has kinetic energy ``nu^T (Z^T M~aa Z) nu / 2`` and, with the dynamically consistent
projector, is driven only by the null-space torque, whose damping part does work
``-kd nu^T Z^T Z nu = -kd |nu|^2``.  So each internal mode ``i`` obeys
``I_i nud_i = -kd nu_i`` with ``I_i`` the eigenvalues of ``Z^T M~aa Z`` (the
*null-space inertia*, kg m^2).  A controller that holds its torque over a period ``dt``
(zero-order hold) maps ``nu_{k+1} = (1 - dt kd / I_i) nu_k``: stable for
``dt kd / I_i < 2``, without overshoot for ``< 1``.  The lightest mode ``I_min`` decides.
The rule::

    kd = min(KD_REF, BETA I_min / CHECK_DT),   kp = kd / POSTURE_TIME

``BETA`` = 0.5 at the planner's check period ``CHECK_DT`` = 2 ms (the coarsest loop that
must stay stable; 0.25 at the controller's 1 ms): the fastest internal mode loses at most
half its rate per check step and never reverses.  ``KD_REF`` = 20 N m s/rad caps it (the
value the UR5 and Panda were tuned with; a heavier arm is damped no harder than they are).
``kp = kd / POSTURE_TIME``, ``POSTURE_TIME`` = 2 s (their ratio 10 / 20): the posture
term is a slow pull, ``kp dt^2 / I_min`` is ``BETA dt / POSTURE_TIME`` = 5e-4, far below
the damping's share.  ``I_min`` is taken at the start posture on the nominal model.

Hand figures: UR5 (wrist_2 free, 70 % model, its start posture) ``I_min`` = 0.518 kg m^2
gives 0.5 x 0.518 / 0.002 = 129.6 -> capped at 20; a mode of 0.0005 kg m^2 gives
0.125 N m s/rad.
"""

from freejoint_core.errors import FreejointValueError
import numpy as np

KD_REF = 20.0
"""[N m s/rad] Largest null-space damping the rule gives (the shipped arms' value)."""
BETA = 0.5
"""Share of the lightest internal mode's rate the damping removes per check period."""
CHECK_DT = 2e-3
"""[s] The period the rule is stable at (the planner's nominal-loop period)."""
POSTURE_TIME = 2.0
"""[s] ``kd / kp``: the time constant of the posture term's pull."""


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


def nullspace_inertia(nominal, q):
    """
    Return the null-space inertia's eigenvalues at ``q`` (ascending, kg m^2) (module notes).

    Parameters
    ----------
    nominal : SpatialArm
        The law's model.
    q : array_like, (n,)
        Posture [rad].

    Returns
    -------
    numpy.ndarray, (r - m,)
        Empty when the arm has no redundancy (r = m).

    """
    terms = nominal.terms(np.asarray(q, dtype=float), np.zeros(nominal.n))
    da, _, maa = nominal.decoupling(terms)
    basis = kernel_basis(da @ maa)
    if basis.shape[1] == 0:
        return np.zeros(0)
    return np.linalg.eigvalsh(basis.T @ maa @ basis)


def nullspace_gains(nominal, q, dt=CHECK_DT):
    """
    Return ``(kd, kp, i_min)`` of the rule (module notes) at the posture ``q``.

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
    (float, float, float)
        ``kd`` [N m s/rad], ``kp`` [N m/rad], and ``I_min`` [kg m^2] (inf: no redundancy,
        then ``kd = KD_REF``).

    Raises
    ------
    FreejointValueError
        ``dt`` not a finite number > 0.

    """
    if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0.0):
        raise FreejointValueError(f'dt: expected a finite number > 0 [s], got {dt!r}')
    inertia = nullspace_inertia(nominal, q)
    i_min = float(inertia[0]) if inertia.size else float('inf')
    kd = min(KD_REF, BETA * i_min / dt)
    return kd, kd / POSTURE_TIME, i_min


def damping_step(kd, i_min, dt=CHECK_DT):
    """Return ``dt kd / I_min``: the share of the lightest internal mode's rate one step removes."""
    return dt * kd / i_min
