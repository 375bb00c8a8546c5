"""
Internal-motion stabilisation: what the paper's law leaves to itself (issue 22).

The paper's law (eq. 15) fixes the m = 2 task accelerations and nothing else; its
Theorem 1 bounds the tracking error, not the arm's internal motion.  Two parts of
that motion are handled here (docs/internal-motion.md has the derivation and the
measurements):

* **r > m, the null space of Da** (:class:`NullSpace`, an option of
  ``control.RobustController``)::

      tau   = Da# (v_r - b) + N tau_0,        N = I_r - Da# Da            (r x r)
      tau_0 = -kd qd_a + kp (q_a0 - q_a)

  with the right inverse ``Da#`` either the paper's pseudo-inverse
  ``Da^T (Da Da^T)^-1`` (``inverse='pseudo'``) or the inertia-weighted one
  ``M~aa Da^T (Da M~aa Da^T)^-1`` (``inverse='weighted'``; ``M~aa`` the effective
  inertia of eq. 3, the dynamically consistent inverse of the constrained arm: it
  minimises ``tau^T M~aa^-1 tau`` and so does not send the torque to light joints).
  The projector ``N`` is built from the pseudo-inverse (``projector='kinematic'``)
  or from the weighted one (``'dynamic'``).  Any right inverse gives ``Da N = 0``:
  the null-space torque does not change the task acceleration of the nominal model.

* **r = m, the free link's zero dynamics**: see :class:`FreeLinkModulation`.

"""

from dataclasses import dataclass
import math

from freejoint_core.arm import check_vector
from freejoint_core.errors import FreejointValueError
import numpy as np

INVERSES = ('pseudo', 'weighted')
PROJECTORS = ('kinematic', 'dynamic')


def _gain(value, name):
    """A finite gain >= 0: a number or a sequence (kept as a tuple of floats)."""
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        vals = (float(value),)
        scalar = True
    else:
        try:
            vals = tuple(float(v) for v in value)
        except (TypeError, ValueError) as exc:
            raise FreejointValueError(
                f'{name}: expected a number or a sequence of numbers, got {value!r}') from exc
        scalar = False
    if not vals or not all(math.isfinite(v) and v >= 0.0 for v in vals):
        raise FreejointValueError(f'{name}: values must be finite and >= 0, got {value!r}')
    return vals[0] if scalar else vals


@dataclass(frozen=True)
class NullSpace:
    """
    Options of the null-space term and of the right inverse (r > m).

    Attributes
    ----------
    kd : float or tuple of float, (r,)
        Damping of the active joint rates in ``tau_0`` [N m s/rad], >= 0.
    kp : float or tuple of float, (r,)
        Posture stiffness [N m/rad], >= 0 (0: no posture term).
    posture : None or tuple of float, (r,)
        Active joint angles ``q_a0`` [rad] the posture term pulls to; required when
        ``kp`` is not 0.
    inverse : {'pseudo', 'weighted'}
        Right inverse of Da in the task term (module notes).
    projector : {'kinematic', 'dynamic'}
        Projector of ``tau_0``: ``I - Da+ Da`` or ``I - Da#w Da`` (module notes).

    """

    kd: object = 0.0
    kp: object = 0.0
    posture: object = None
    inverse: str = 'pseudo'
    projector: str = 'kinematic'

    def __post_init__(self):
        """Validate and normalise."""
        object.__setattr__(self, 'kd', _gain(self.kd, 'kd'))
        object.__setattr__(self, 'kp', _gain(self.kp, 'kp'))
        if self.inverse not in INVERSES:
            raise FreejointValueError(f'inverse: expected one of {INVERSES}, got {self.inverse!r}')
        if self.projector not in PROJECTORS:
            raise FreejointValueError(
                f'projector: expected one of {PROJECTORS}, got {self.projector!r}')
        if self.posture is not None:
            try:
                post = tuple(float(v) for v in self.posture)
            except (TypeError, ValueError) as exc:
                raise FreejointValueError(
                    f'posture: expected None or a sequence of angles, got {self.posture!r}'
                ) from exc
            if not all(map(math.isfinite, post)):
                raise FreejointValueError(f'posture: values must be finite, got {post}')
            object.__setattr__(self, 'posture', post)
        elif np.any(np.asarray(self.kp) != 0.0):
            raise FreejointValueError('posture: required when kp is not 0')

    def check(self, r):
        """
        Raise unless every per-joint field fits r active joints.

        Parameters
        ----------
        r : int
            Number of active joints.

        """
        for name in ('kd', 'kp', 'posture'):
            val = getattr(self, name)
            if isinstance(val, tuple) and len(val) != r:
                raise FreejointValueError(f'{name}: expected shape ({r},), got ({len(val)},)')

    def tau0(self, q_a, qd_a):
        """
        Null-space torque before projection, ``-kd qd_a + kp (q_a0 - q_a)``.

        Parameters
        ----------
        q_a, qd_a : numpy.ndarray, (r,)
            Active joint angles [rad] and rates [rad/s].

        Returns
        -------
        numpy.ndarray, (r,)
            [N m].

        """
        out = -np.asarray(self.kd) * qd_a
        if self.posture is not None:
            out = out + np.asarray(self.kp) * (np.asarray(self.posture) - q_a)
        return out


def pseudo_inverse(da, reg=0.0):
    """
    Right pseudo-inverse ``Da^T (Da Da^T + reg I)^-1``.

    Parameters
    ----------
    da : numpy.ndarray, (m, r)
        Decoupling matrix, full row rank (or ``reg`` > 0).
    reg : float
        Damping ``lam2`` >= 0 (damped least squares near a singularity).

    Returns
    -------
    numpy.ndarray, (r, m)

    """
    a = da @ da.T
    if reg:
        a = a + reg * np.eye(a.shape[0])
    return np.linalg.solve(a, da).T


def weighted_inverse(da, weight):
    """
    Inertia-weighted right inverse ``W Da^T (Da W Da^T)^-1``.

    With ``W = M~aa`` (the effective inertia of the active joints, eq. 3) it is the
    dynamically consistent inverse: of all ``tau`` with ``Da tau = w`` it returns the
    one of least ``tau^T W^-1 tau``.

    Parameters
    ----------
    da : numpy.ndarray, (m, r)
        Decoupling matrix, full row rank.
    weight : numpy.ndarray, (r, r)
        Symmetric positive definite weight.

    Returns
    -------
    numpy.ndarray, (r, m)
        ``X`` with ``Da X = I_m``.

    """
    wd = weight @ da.T
    return np.linalg.solve(da @ wd, wd.T).T


def projector(da, da_inv):
    """
    Null-space projector ``N = I - Da# Da`` of a right inverse.

    Parameters
    ----------
    da : numpy.ndarray, (m, r)
        Decoupling matrix.
    da_inv : numpy.ndarray, (r, m)
        A right inverse (``Da Da# = I``); then ``Da N = 0``.

    Returns
    -------
    numpy.ndarray, (r, r)

    """
    return np.eye(da.shape[1]) - da_inv @ da


def null_space_velocity(jac_a_eff, qd_a):
    """
    Size of the joint motion the task does not see, ``||(I - J+ J) qd_a||``.

    Parameters
    ----------
    jac_a_eff : numpy.ndarray, (m, r)
        Effective task Jacobian of the active joints (``ArmModel.effective``).
    qd_a : array_like, (r,)
        Active joint rates [rad/s].

    Returns
    -------
    float
        [rad/s].

    """
    qd_a = check_vector(qd_a, jac_a_eff.shape[1], 'qd_a')
    return float(np.linalg.norm(projector(jac_a_eff, pseudo_inverse(jac_a_eff)) @ qd_a))


def equilibrium_pose(model, p, guess, tol=1e-12, max_iter=50):
    """
    A configuration with the end effector at ``p`` where the free joints hang at rest.

    Solves ``fk(q) = p`` and ``G_p(q) = 0`` (the gravity torque of every passive joint)
    by Gauss-Newton minimum-norm steps from ``guess``: with the active joints held the
    free links are then in static equilibrium.  For r = m the solutions are isolated
    (e.g. the paper's arm: the free link vertical, hanging ``theta3 = -90 deg`` or
    upright ``+90 deg``); for r > m they form a family and the one reached lies near
    ``guess``.  The guess picks the solution: start it near the hanging branch.

    Parameters
    ----------
    model : freejoint_core.arm.ArmModel
        The arm (its gravity > 0 and at least one passive joint).
    p : array_like, (2,)
        End-effector point [m].
    guess : array_like, (n,)
        Start of the iteration [rad].
    tol : float
        Residual norm to reach [m, N m].
    max_iter : int
        Iteration bound.

    Returns
    -------
    numpy.ndarray, (n,)
        Joint angles [rad] (each wrapped to (-pi, pi]).

    Raises
    ------
    FreejointValueError
        No passive joint or no gravity (``model``), bad ``p`` / ``guess``, or no
        convergence (``p``: likely out of reach).

    """
    params = model.params
    if params.p == 0 or params.gravity <= 0.0:
        raise FreejointValueError('model: an equilibrium pose needs a passive joint and gravity')
    p = check_vector(p, 2, 'p')
    q = check_vector(guess, model.n, 'guess').copy()
    passive = list(params.passive)

    def residual(x):
        return np.concatenate([model.fk(x) - p, model.gravity_torque(x)[passive]])

    h = 1e-6
    for _ in range(max_iter):
        res = residual(q)
        if np.linalg.norm(res) < tol:
            return np.remainder(q + np.pi, 2.0 * np.pi) - np.pi
        jac = np.empty((res.size, model.n))
        for j in range(model.n):
            dq = np.zeros(model.n)
            dq[j] = h
            jac[:, j] = (residual(q + dq) - residual(q - dq)) / (2.0 * h)
        step = np.linalg.lstsq(jac, res, rcond=None)[0]
        q = q - step
    raise FreejointValueError(
        f'p: no equilibrium pose found near guess {np.asarray(guess).tolist()} '
        f'(residual {np.linalg.norm(residual(q)):.3g})')


def hanging_pose(params, p, branch=1):
    """
    The 3-link arm (joint 3 free) at ``p`` with its free link hanging straight down.

    Closed form: the free link's absolute angle is ``-pi/2`` (its gravity torque
    ``g m3 c3 cos(theta3)`` vanishes, and with the end effector held the equilibrium is
    stable when ``I3 + m3 c3 (c3 - L3) > 0``, as for Table I), so joint 3 sits at
    ``p + (0, L3)`` and joints 1 and 2 come from the two-link inverse kinematics.

    Parameters
    ----------
    params : freejoint_core.arm.ArmParams
        Arm with ``n == 3`` and ``passive == (2,)``.
    p : array_like, (2,)
        End-effector point [m].
    branch : {+1, -1}
        Sign of the elbow angle ``q2``.

    Returns
    -------
    numpy.ndarray, (3,)
        Joint angles [rad], each in (-pi, pi].

    Raises
    ------
    FreejointValueError
        Another arm (``params``), a bad branch, or joint 3's point out of reach (``p``).

    """
    if params.n != 3 or params.passive != (2,):
        raise FreejointValueError(
            f'params: hanging_pose needs 3 links with joint 3 free, got n = {params.n}, '
            f'passive {params.passive}')
    if branch not in (1, -1):
        raise FreejointValueError(f'branch: expected +1 or -1, got {branch!r}')
    p = check_vector(p, 2, 'p')
    l1, l2, l3 = params.lengths
    x, y = float(p[0]), float(p[1]) + l3
    c2 = (x * x + y * y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    if not -1.0 <= c2 <= 1.0:
        raise FreejointValueError(f'p: joint 3 at {[x, y]} is out of reach of links 1-2')
    q2 = branch * math.acos(c2)
    q1 = math.atan2(y, x) - math.atan2(l2 * math.sin(q2), l1 + l2 * math.cos(q2))
    q3 = -0.5 * math.pi - q1 - q2
    return np.array([math.remainder(v, 2.0 * math.pi) for v in (q1, q2, q3)])
