"""
Planar n-link arm with free (passive) joints: parameters and the reference model.

Conventions (shared by the whole package, see ``docs/CONTRACT.md``):

* joint angles ``q`` are relative (joint i measured from link i-1), 0-based;
  the absolute angle of link i is ``phi_i = q_0 + ... + q_i``;
* link i runs from joint i to joint i+1 (length ``L_i``); its centre of mass
  lies on the link at distance ``com_i`` from joint i;
* the end effector is the tip of the last link; task space is its (x, y), m = 2;
* gravity acts along -y with magnitude ``params.gravity`` (0 for the paper's
  horizontal case, 9.81 for the vertical one);
* units are SI: m, kg, kg m^2, rad, s, N m.

The equations of motion are eq. (1) of the paper,
``M(q) qdd + C(q, qd) qd + G(q) = B tau_a + d``, and the task-space form is
eqs. (4)-(5): ``pdd - b(q, qd) = Da(q) tau_a + J M^-1 d`` with
``Da = J M^-1 B`` and ``b = Jdot qd - J M^-1 (C qd + G)``.

``ArmModel`` is the general numpy reference, derived directly in joint
coordinates (link Jacobians, Christoffel symbols).  ``freejoint_core.models.make_model``
returns the specialised 3-link kernel (``freejoint_core.fast3.Arm3Model``, derived in
absolute link angles) when ``n == 3``; both expose the same interface.

"""

from dataclasses import dataclass
import math

from freejoint_core.errors import FreejointValueError
import numpy as np

CASES = ('horizontal', 'vertical')

NOMINAL_SCALE = 0.7
"""The paper's nominal model: Table I masses, inertias and COM distances times this."""

DEFAULT_DT = 1e-3
"""The paper's control period [s]."""

GRAVITY_VERTICAL = 9.81
"""Gravity [m/s^2] for the paper's vertical case (Table I, Case 2)."""


def _float_tuple(name, values):
    """Return ``values`` as a tuple of finite floats, or raise naming ``name``."""
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise FreejointValueError(
            f'{name}: expected a sequence of numbers, got {values!r}') from exc
    for v in out:
        if not math.isfinite(v):
            raise FreejointValueError(f'{name}: values must be finite, got {out}')
    return out


@dataclass(frozen=True)
class ArmParams:
    """
    Physical parameters of a planar arm with passive joints.

    Attributes
    ----------
    lengths : tuple of float, (n,)
        Link lengths ``L_i`` [m], > 0.
    masses : tuple of float, (n,)
        Link masses ``m_i`` [kg], > 0.
    inertias : tuple of float, (n,)
        Link moments of inertia about their centre of mass ``I_i`` [kg m^2], > 0.
    com : tuple of float, (n,)
        Distance from joint i to the centre of mass of link i, ``L_ci`` [m],
        in ``(0, L_i]``.
    passive : tuple of int
        0-based indices of the free (unactuated, unbraked) joints, unique, in
        ``[0, n)``; stored sorted.  At least ``m = 2`` joints must stay active.
    gravity : float
        Gravity magnitude [m/s^2] along -y (0.0 horizontal, 9.81 vertical), >= 0.

    Raises
    ------
    FreejointValueError
        If any field is invalid; the message starts with the field's name.

    """

    lengths: tuple
    masses: tuple
    inertias: tuple
    com: tuple
    passive: tuple = (2,)
    gravity: float = 0.0

    def __post_init__(self):
        """Validate and normalise the fields (tuples of floats, sorted passive)."""
        lengths = _float_tuple('lengths', self.lengths)
        n = len(lengths)
        if n < 2:
            raise FreejointValueError(f'lengths: need at least 2 links, got {n}')
        fields = {'lengths': lengths}
        for name in ('masses', 'inertias', 'com'):
            vals = _float_tuple(name, getattr(self, name))
            if len(vals) != n:
                raise FreejointValueError(
                    f'{name}: expected {n} values (one per link), got {len(vals)}')
            fields[name] = vals
        for name in ('lengths', 'masses', 'inertias', 'com'):
            if any(v <= 0.0 for v in fields[name]):
                raise FreejointValueError(f'{name}: values must be > 0, got {fields[name]}')
        for i, (c, length) in enumerate(zip(fields['com'], lengths)):
            if c > length:
                raise FreejointValueError(
                    f'com: com[{i}] = {c} must lie in (0, L] = (0, {length}]')
        try:
            passive = tuple(int(i) for i in self.passive)
        except (TypeError, ValueError) as exc:
            raise FreejointValueError(
                f'passive: expected a sequence of joint indices, got {self.passive!r}') from exc
        if any(i != float(j) for i, j in zip(passive, self.passive)):
            raise FreejointValueError(f'passive: indices must be integers, got {self.passive}')
        if any(i < 0 or i >= n for i in passive):
            raise FreejointValueError(f'passive: indices must lie in [0, {n}), got {passive}')
        if len(set(passive)) != len(passive):
            raise FreejointValueError(f'passive: indices must be unique, got {passive}')
        if n - len(passive) < 2:
            raise FreejointValueError(
                f'passive: {len(passive)} passive of {n} joints leaves r = '
                f'{n - len(passive)} active, need r >= m = 2')
        try:
            gravity = float(self.gravity)
        except (TypeError, ValueError) as exc:
            raise FreejointValueError(f'gravity: expected a number, got {self.gravity!r}') from exc
        if not math.isfinite(gravity) or gravity < 0.0:
            raise FreejointValueError(f'gravity: must be finite and >= 0, got {gravity}')
        for name, vals in fields.items():
            object.__setattr__(self, name, vals)
        object.__setattr__(self, 'passive', tuple(sorted(passive)))
        object.__setattr__(self, 'gravity', gravity)

    @property
    def n(self):
        """Return the number of joints (= links)."""
        return len(self.lengths)

    @property
    def active(self):
        """Return the sorted tuple of the active joint indices."""
        return tuple(i for i in range(self.n) if i not in self.passive)

    @property
    def r(self):
        """Return the number of active joints."""
        return self.n - len(self.passive)

    @property
    def p(self):
        """Return the number of passive joints."""
        return len(self.passive)

    def scaled(self, scale):
        """
        Return a copy with masses, inertias and com multiplied by ``scale``.

        Lengths stay exact (the paper assumes exactly known lengths); the Table I
        nominal model is ``table1(case).scaled(0.7)``.

        Parameters
        ----------
        scale : float
            Factor > 0.

        Returns
        -------
        ArmParams

        """
        try:
            scale = float(scale)
        except (TypeError, ValueError) as exc:
            raise FreejointValueError(f'scale: expected a number, got {scale!r}') from exc
        if not math.isfinite(scale) or scale <= 0.0:
            raise FreejointValueError(f'scale: must be finite and > 0, got {scale}')
        return ArmParams(
            lengths=self.lengths,
            masses=tuple(scale * v for v in self.masses),
            inertias=tuple(scale * v for v in self.inertias),
            com=tuple(scale * v for v in self.com),
            passive=self.passive,
            gravity=self.gravity)


def table1(case='horizontal'):
    """
    Return the real parameters of Table I (3 identical links, joint 3 passive).

    Parameters
    ----------
    case : {'horizontal', 'vertical'}
        'horizontal': motion in the horizontal plane, G(q) = 0 (Case 1);
        'vertical': gravity 9.81 m/s^2 along -y (Case 2).

    Returns
    -------
    ArmParams
        L = 0.5 m, m = 1 kg, I = 0.1 kg m^2, L_c = 0.25 m per link, passive (2,).

    """
    if case not in CASES:
        raise FreejointValueError(f'case: expected one of {CASES}, got {case!r}')
    return ArmParams(
        lengths=(0.5, 0.5, 0.5), masses=(1.0, 1.0, 1.0), inertias=(0.1, 0.1, 0.1),
        com=(0.25, 0.25, 0.25), passive=(2,),
        gravity=GRAVITY_VERTICAL if case == 'vertical' else 0.0)


def number_or_numbers(value, name, expected):
    """
    Return ``(values, scalar)``: a number as ``((x,), True)``, a sequence as a tuple, False.

    Parameters
    ----------
    value : float or sequence of float
        Input (a bool is not a number).
    name : str
        Argument name used in the error message.
    expected : str
        What the message says was expected (e.g. ``'a number or 3 numbers'``).

    """
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        return (float(value),), True
    try:
        return tuple(float(v) for v in value), False
    except (TypeError, ValueError) as exc:
        raise FreejointValueError(f'{name}: expected {expected}, got {value!r}') from exc


def check_vector(x, n, name):
    """
    Return ``x`` as a finite float numpy array of shape (n,), or raise.

    Parameters
    ----------
    x : array_like
        Input.
    n : int
        Expected length.
    name : str
        Argument name used in the error message.

    Returns
    -------
    numpy.ndarray, (n,)

    """
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FreejointValueError(f'{name}: expected a numeric array, got {x!r}') from exc
    if arr.shape != (n,):
        raise FreejointValueError(f'{name}: expected shape ({n},), got {arr.shape}')
    if not np.all(np.isfinite(arr)):
        raise FreejointValueError(f'{name}: values must be finite, got {arr}')
    return arr


class ArmModel:
    """
    General n-link planar arm model (numpy reference implementation).

    Derived in joint coordinates: link COM Jacobians ``Jv_i`` (2, n) and
    angular Jacobians give ``M = sum_i m_i Jv_i^T Jv_i + I_i w_i^T w_i``; the
    Coriolis matrix comes from Christoffel symbols of the analytic ``dM/dq``.

    Parameters
    ----------
    params : ArmParams
        Physical parameters.

    Attributes
    ----------
    task_dim : int
        Task dimension m: the number of end-effector coordinates the model's ``fk`` and
        ``jacobian`` give (a planar arm: 2, ``(x, y)``).

    """

    task_dim = 2

    def __init__(self, params):
        if not isinstance(params, ArmParams):
            raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
        self.params = params
        n = params.n
        self.n = n
        self.r = params.r
        self.active = params.active
        self.passive = params.passive
        self._L = np.array(params.lengths)
        self._m = np.array(params.masses)
        self._inertia = np.array(params.inertias)
        self._g = params.gravity
        # ell[i, k]: lever of link k in the COM position of link i (k <= i).
        ell = np.zeros((n, n))
        for i in range(n):
            ell[i, :i] = self._L[:i]
            ell[i, i] = params.com[i]
        self._ell = ell
        # upto[i, j] = 1 if j <= i (joint j moves link i).
        self._upto = np.tril(np.ones((n, n)))
        self._B = np.eye(n)[:, list(self.active)]

    # -- validation -------------------------------------------------------
    def _q(self, q, name='q'):
        return check_vector(q, self.n, name)

    # -- kinematics -------------------------------------------------------
    def _phi(self, q):
        return np.cumsum(q)

    def fk(self, q):
        """
        End-effector position.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].

        Returns
        -------
        numpy.ndarray, (2,)
            End-effector (x, y) [m].

        """
        phi = self._phi(self._q(q))
        return np.array([self._L @ np.cos(phi), self._L @ np.sin(phi)])

    def jacobian(self, q):
        """
        End-effector Jacobian ``J = df/dq``.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].

        Returns
        -------
        numpy.ndarray, (2, n)
            [m/rad].

        """
        phi = self._phi(self._q(q))
        lx = -self._L * np.sin(phi)
        ly = self._L * np.cos(phi)
        # column j sums links k >= j: reverse cumulative sum.
        return np.array([np.cumsum(lx[::-1])[::-1], np.cumsum(ly[::-1])[::-1]])

    def jdot_qdot(self, q, qd):
        """
        Velocity-product term of the end-effector acceleration, ``Jdot qd``.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].
        qd : array_like, (n,)
            Joint velocities [rad/s].

        Returns
        -------
        numpy.ndarray, (2,)
            [m/s^2].

        """
        phi = self._phi(self._q(q))
        w = np.cumsum(self._q(qd, 'qd'))
        w2 = self._L * w * w
        return np.array([-(w2 @ np.cos(phi)), -(w2 @ np.sin(phi))])

    def _com_jacobians(self, phi):
        n = self.n
        s, c = np.sin(phi), np.cos(phi)
        jv = np.zeros((n, 2, n))
        for i in range(n):
            for j in range(i + 1):
                jv[i, 0, j] = -(self._ell[i, j:i + 1] @ s[j:i + 1])
                jv[i, 1, j] = self._ell[i, j:i + 1] @ c[j:i + 1]
        return jv

    def _com_jacobian_derivs(self, phi):
        """``dJv[l, i] = d Jv_i / d q_l``, shape (n, n, 2, n)."""
        n = self.n
        s, c = np.sin(phi), np.cos(phi)
        djv = np.zeros((n, n, 2, n))
        for ll in range(n):
            for i in range(n):
                for j in range(i + 1):
                    k0 = max(j, ll)
                    if k0 > i:
                        continue
                    djv[ll, i, 0, j] = -(self._ell[i, k0:i + 1] @ c[k0:i + 1])
                    djv[ll, i, 1, j] = -(self._ell[i, k0:i + 1] @ s[k0:i + 1])
        return djv

    # -- dynamics ---------------------------------------------------------
    def mass_matrix(self, q):
        """
        Inertia matrix ``M(q)``.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].

        Returns
        -------
        numpy.ndarray, (n, n)
            Symmetric positive definite [kg m^2].

        """
        return self._mass(self._phi(self._q(q)))

    def _mass(self, phi):
        jv = self._com_jacobians(phi)
        mass = np.einsum('i,iaj,iak->jk', self._m, jv, jv)
        # angular velocity of link i is sum_{j <= i} qd_j.
        mass += np.einsum('i,ij,ik->jk', self._inertia, self._upto, self._upto)
        return mass

    def _mass_derivs(self, phi):
        """``dM[l] = dM/dq_l``, shape (n, n, n)."""
        jv = self._com_jacobians(phi)
        djv = self._com_jacobian_derivs(phi)
        half = np.einsum('i,liaj,iak->ljk', self._m, djv, jv)
        return half + half.transpose(0, 2, 1)

    def coriolis_matrix(self, q, qd):
        """
        Coriolis/centrifugal matrix ``C(q, qd)`` from Christoffel symbols.

        With this choice ``Mdot - 2 C`` is skew-symmetric.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].
        qd : array_like, (n,)
            Joint velocities [rad/s].

        Returns
        -------
        numpy.ndarray, (n, n)
            [kg m^2/s].

        """
        phi = self._phi(self._q(q))
        qd = self._q(qd, 'qd')
        dm = self._mass_derivs(phi)  # dm[l, k, j] = dM_kj / dq_l
        # c_kjl = 1/2 (dM_kj/dq_l + dM_kl/dq_j - dM_lj/dq_k); C_kj = sum_l c_kjl qd_l
        gamma = 0.5 * (dm.transpose(1, 2, 0) + dm.transpose(1, 0, 2) - dm.transpose(0, 2, 1))
        return gamma @ qd

    def coriolis(self, q, qd):
        """
        Coriolis and centrifugal torques ``C(q, qd) qd``.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].
        qd : array_like, (n,)
            Joint velocities [rad/s].

        Returns
        -------
        numpy.ndarray, (n,)
            [N m].

        """
        qd = self._q(qd, 'qd')
        return self.coriolis_matrix(q, qd) @ qd

    def gravity_torque(self, q):
        """
        Gravity torques ``G(q) = dV/dq`` (gravity along -y).

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].

        Returns
        -------
        numpy.ndarray, (n,)
            [N m].

        """
        jv = self._com_jacobians(self._phi(self._q(q)))
        return self._g * (self._m @ jv[:, 1, :])

    def forward_dynamics(self, q, qd, tau):
        """
        Joint accelerations ``qdd = M^-1 (tau - C qd - G)``.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].
        qd : array_like, (n,)
            Joint velocities [rad/s].
        tau : array_like, (n,)
            Generalised force on every joint (including disturbance; zero
            actuator torque on passive joints is the caller's business) [N m].

        Returns
        -------
        numpy.ndarray, (n,)
            [rad/s^2].

        """
        tau = check_vector(tau, self.n, 'tau')
        rhs = tau - self.coriolis(q, qd) - self.gravity_torque(q)
        return np.linalg.solve(self.mass_matrix(q), rhs)

    def partition(self, mat):
        """
        Split an (n, n) matrix into active/passive blocks (eq. 2).

        Parameters
        ----------
        mat : array_like, (n, n)
            Joint-space matrix, e.g. ``M(q)``.

        Returns
        -------
        tuple of numpy.ndarray
            ``(M_aa (r, r), M_ap (r, p), M_pa (p, r), M_pp (p, p))``.

        """
        mat = np.asarray(mat, dtype=float)
        if mat.shape != (self.n, self.n):
            raise FreejointValueError(
                f'mat: expected shape ({self.n}, {self.n}), got {mat.shape}')
        a, p = list(self.active), list(self.passive)
        return mat[np.ix_(a, a)], mat[np.ix_(a, p)], mat[np.ix_(p, a)], mat[np.ix_(p, p)]

    def effective(self, q):
        """
        Effective Jacobian and inertia of eq. (3).

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].

        Returns
        -------
        Ja_eff : numpy.ndarray, (2, r)
            ``J_a - J_p M_pp^-1 M_pa``.
        Maa_eff : numpy.ndarray, (r, r)
            ``M_aa - M_ap M_pp^-1 M_pa`` [kg m^2].

        """
        jac = self.jacobian(q)
        maa, map_, mpa, mpp = self.partition(self.mass_matrix(q))
        ja, jp = jac[:, list(self.active)], jac[:, list(self.passive)]
        if self.params.p == 0:
            return ja, maa
        x = np.linalg.solve(mpp, mpa)
        return ja - jp @ x, maa - map_ @ x

    def terms(self, q, qd):
        """
        Return the joint-space terms the task-space quantities are derived from.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Joint angles [rad] and velocities [rad/s].

        Returns
        -------
        mass : numpy.ndarray, (n, n)
            ``M(q)`` [kg m^2].
        h : numpy.ndarray, (n,)
            ``C(q, qd) qd + G(q)`` [N m].
        jac : numpy.ndarray, (2, n)
            End-effector Jacobian [m/rad].
        jdqd : numpy.ndarray, (2,)
            ``Jdot qd`` [m/s^2].
        p : numpy.ndarray, (2,)
            End-effector position [m].

        """
        q = self._q(q)
        qd = self._q(qd, 'qd')
        return (self.mass_matrix(q), self.coriolis(q, qd) + self.gravity_torque(q),
                self.jacobian(q), self.jdot_qdot(q, qd), self.fk(q))

    def decoupling(self, q, qd):
        """
        Decoupling matrix and drift of the task-space dynamics (eqs. 4, 5).

        Computed by :func:`task_space` from the model's ``J M^-1``, ``h`` and ``Jdot qd``.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].
        qd : array_like, (n,)
            Joint velocities [rad/s].

        Returns
        -------
        Da : numpy.ndarray, (2, r)
            ``J M^-1 B`` [m/(s^2 N m)].
        b : numpy.ndarray, (2,)
            ``Jdot qd - J M^-1 (C qd + G)`` [m/s^2].

        """
        return task_space(*self._task_terms(q, qd), self._B)

    def _task_terms(self, q, qd):
        """``J M^-1`` (2, n), ``h`` (n,) and ``Jdot qd`` (2,): what ``task_space`` takes."""
        mass, h, jac, jdqd, _ = self.terms(q, qd)
        return np.linalg.solve(mass, jac.T).T, h, jdqd  # J M^-1 (M symmetric)

    def energy(self, q, qd):
        """
        Total mechanical energy ``1/2 qd^T M qd + V(q)``, V = 0 at y = 0.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].
        qd : array_like, (n,)
            Joint velocities [rad/s].

        Returns
        -------
        float
            [J].

        """
        q = self._q(q)
        qd = self._q(qd, 'qd')
        phi = self._phi(q)
        y_com = self._ell @ np.sin(phi)
        return float(0.5 * qd @ self.mass_matrix(q) @ qd + self._g * (self._m @ y_com))

    def ik(self, p, q_passive, branch=1):
        """
        Inverse kinematics for the two active joints, passive angles given.

        Needs r == 2 (e.g. the 3-link arm with one passive joint).  The links
        between and after the two active joints are rigid once the passive
        angles are fixed, so the problem is a two-link one with an
        "elbow" angle ``gamma`` between the two rigid segments.

        Parameters
        ----------
        p : array_like, (2,)
            Desired end-effector position [m].
        q_passive : array_like, (p,)
            Passive joint angles [rad], in ``params.passive`` order.
        branch : {+1, -1}
            Sign of the equivalent elbow angle ``gamma``.  For the 3-link arm
            with passive joint 3, ``gamma = q2 + atan2(L3 sin q3, L2 + L3 cos q3)``,
            so +1 gives q2 > 0 when q3 = 0.

        Returns
        -------
        numpy.ndarray, (n,)
            Full joint vector [rad] with the passive entries equal to
            ``q_passive``; active angles wrapped to (-pi, pi].

        Raises
        ------
        FreejointValueError
            ``p`` unreachable, bad shapes, ``branch`` not +-1, or r != 2
            (message names ``params``).

        """
        if self.r != 2:
            raise FreejointValueError(
                f'params: ik needs exactly 2 active joints, got r = {self.r}')
        p = check_vector(p, 2, 'p')
        qp = check_vector(q_passive, self.params.p, 'q_passive')
        if branch not in (1, -1):
            raise FreejointValueError(f'branch: expected +1 or -1, got {branch!r}')
        a, b = self.active
        q = np.zeros(self.n)
        q[list(self.passive)] = qp
        lengths = self.params.lengths
        # base -> joint a: joints before a are passive and known.
        ang = 0.0
        base = np.zeros(2)
        for k in range(a):
            ang += q[k]
            base += lengths[k] * np.array([math.cos(ang), math.sin(ang)])
        ang_before_a = ang
        # rigid segment joint a -> joint b, in the frame of link a.
        u = np.zeros(2)
        rel = 0.0
        for k in range(a, b):
            if k > a:
                rel += q[k]
            u += lengths[k] * np.array([math.cos(rel), math.sin(rel)])
        theta_u = rel  # rotation of link b-1 relative to link a
        # rigid segment joint b -> end effector, in the frame of link b.
        w = np.zeros(2)
        rel = 0.0
        for k in range(b, self.n):
            if k > b:
                rel += q[k]
            w += lengths[k] * np.array([math.cos(rel), math.sin(rel)])
        l1, mu = math.hypot(u[0], u[1]), math.atan2(u[1], u[0])
        l2, nu = math.hypot(w[0], w[1]), math.atan2(w[1], w[0])
        d = p - base
        ca, sa = math.cos(ang_before_a), math.sin(ang_before_a)
        x, y = ca * d[0] + sa * d[1], -sa * d[0] + ca * d[1]
        r2 = x * x + y * y
        cg = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        if not -1.0 - 1e-12 <= cg <= 1.0 + 1e-12:
            raise FreejointValueError(
                f'p: {p.tolist()} is out of reach for q_passive = {qp.tolist()}')
        gamma = branch * math.acos(min(1.0, max(-1.0, cg)))
        shoulder = math.atan2(y, x) - math.atan2(l2 * math.sin(gamma), l1 + l2 * math.cos(gamma))
        q[a] = _wrap(shoulder - mu)
        q[b] = _wrap(gamma - theta_u + mu - nu)
        return q


def task_space(jac_minv, h, jdqd, selection):
    """
    Decoupling matrix and drift of eqs. (4, 5) from the joint-space terms.

    Parameters
    ----------
    jac_minv : numpy.ndarray, (2, n)
        ``J M^-1`` [m/(rad kg m^2)].
    h, jdqd : numpy.ndarray
        ``C qd + G`` (n,) [N m] and ``Jdot qd`` (2,) [m/s^2], as returned by
        ``ArmModel.terms``.
    selection : numpy.ndarray, (n, r)
        Actuation matrix ``B`` (columns of the identity at the active joints).

    Returns
    -------
    Da : numpy.ndarray, (2, r)
        ``J M^-1 B`` [m/(s^2 N m)].
    b : numpy.ndarray, (2,)
        ``Jdot qd - J M^-1 h`` [m/s^2].

    """
    return jac_minv @ selection, jdqd - jac_minv @ h


def _wrap(angle):
    """Wrap an angle to (-pi, pi]."""
    w = math.remainder(angle, 2.0 * math.pi)
    return math.pi if w == -math.pi else w
