"""
Closed-form scalar kernel for the planar 3-link arm (the real-time hot path).

Derived in absolute link angles ``phi = S q`` (``S`` lower-triangular ones:
``phi_1 = q_1``, ``phi_2 = q_1 + q_2``, ``phi_3 = q_1 + q_2 + q_3``), where the
kinetic energy is ``1/2 phid^T M_phi phid`` with

    M_phi[a][b] = H_ab cos(phi_a - phi_b) + delta_ab I_a,
    H_aa = m_a Lc_a^2 + L_a^2 sum_{i > a} m_i,
    H_ab = L_a h_b (a < b),     h_b = m_b Lc_b + L_b sum_{i > b} m_i,

and Lagrange's equations give

    c_phi[a] = sum_b H_ab sin(phi_a - phi_b) phid_b^2,
    G_phi[a] = g h_a cos(phi_a).

Generalised forces transform as ``tau_phi = S^-T tau_q``, i.e.
``tau_phi[a] = tau[a] - tau[a+1]``, so the joint-space quantities are
``M = S^T M_phi S``, ``C qd = S^T c_phi``, ``G = S^T G_phi``, and

    qdd = S^-1 M_phi^-1 (S^-T tau - c_phi - G_phi),
    J M^-1 = (J_phi M_phi^-1) S^-T,  b = Jdot qd - (J_phi M_phi^-1)(c_phi + G_phi),

with ``J_phi[:, a] = L_a (-sin phi_a, cos phi_a)``.  The symmetric 3x3
``M_phi`` (constant diagonal) is inverted through its adjugate.  Every scalar
method works on plain Python floats with ``math`` only: no numpy call per
evaluation and no argument checks (the callers validate where data enters).

``Arm3Model`` has the ``ArmModel`` interface (numpy in, numpy out, validated)
on top of those kernels; ``freejoint_core.models.make_model`` returns it for n == 3.

"""

import math

from freejoint_core.arm import ArmModel, check_vector
from freejoint_core.errors import FreejointValueError
import numpy as np

_cos = math.cos
_sin = math.sin


class Arm3Model(ArmModel):
    """
    Planar 3-link arm, closed-form scalar kernel; any passive subset with r >= 2.

    Parameters
    ----------
    params : ArmParams
        Must have ``n == 3``.

    """

    def __init__(self, params):
        super().__init__(params)
        if params.n != 3:
            raise FreejointValueError(f'params: Arm3Model needs n == 3, got {params.n}')
        (l1, l2, l3), (m1, m2, m3) = params.lengths, params.masses
        (i1, i2, i3), (c1, c2, c3) = params.inertias, params.com
        self._l1, self._l2, self._l3 = l1, l2, l3
        h1 = m1 * c1 + l1 * (m2 + m3)
        h2 = m2 * c2 + l2 * m3
        h3 = m3 * c3
        self._d1 = m1 * c1 * c1 + l1 * l1 * (m2 + m3) + i1
        self._d2 = m2 * c2 * c2 + l2 * l2 * m3 + i2
        self._d3 = m3 * c3 * c3 + i3
        self._h12 = l1 * h2
        self._h13 = l1 * h3
        self._h23 = l2 * h3
        g = params.gravity
        self._gh1, self._gh2, self._gh3 = g * h1, g * h2, g * h3
        self._c = (self._d1, self._d2, self._d3, self._h12, self._h13, self._h23,
                   self._gh1, self._gh2, self._gh3)
        self._ln = (l1, l2, l3)
        if self.r == 2:
            self._ia, self._ib = self.active
        else:
            self._ia = self._ib = None

    # -- scalar kernels (hot path) ------------------------------------------
    def _terms(self, q0, q1, q2, w0, w1, w2):
        """Return :func:`terms` of this arm."""
        return terms(self._c, q0, q1, q2, w0, w1, w2)

    def qdd(self, q0, q1, q2, w0, w1, w2, t0, t1, t2):
        """
        Return the joint accelerations [rad/s^2] on floats (:func:`qdd`).

        ``q`` [rad], ``w`` [rad/s] the state, ``t`` [N m] the generalised force on each
        joint (actuator + disturbance).
        """
        return qdd(self._c, q0, q1, q2, w0, w1, w2, t0, t1, t2)

    def _task_full(self, q0, q1, q2, w0, w1, w2):
        """Kinematics, ``W = J M^-1`` (2x3, row-major) and ``b`` on floats (:func:`task`)."""
        px, py, vx, vy, x0, x1, x2, y0, y1, y2, bx, by = task(
            self._c, self._ln, q0, q1, q2, w0, w1, w2)
        return px, py, vx, vy, (x0, x1, x2), (y0, y1, y2), bx, by

    def task(self, q0, q1, q2, w0, w1, w2):
        """
        Everything the 2-active-joint controller needs, on floats.

        Valid only when ``r == 2`` (one passive joint).

        Parameters
        ----------
        q0, q1, q2 : float
            Joint angles [rad].
        w0, w1, w2 : float
            Joint velocities [rad/s].

        Returns
        -------
        tuple of float
            ``(px, py, vx, vy, d00, d01, d10, d11, bx, by)``: end-effector
            position [m] and velocity ``J qd`` [m/s], ``Da`` (2x2, row-major,
            columns in ``params.active`` order) and ``b`` [m/s^2] (eqs. 4, 5).

        """
        px, py, vx, vy, wx, wy, bx, by = self._task_full(q0, q1, q2, w0, w1, w2)
        ia = self._ia
        ib = self._ib
        return px, py, vx, vy, wx[ia], wx[ib], wy[ia], wy[ib], bx, by

    # -- ArmModel interface (numpy, validated) ------------------------------
    def fk(self, q):
        """End-effector position, see ``ArmModel.fk``."""
        q0, q1, q2 = self._q(q).tolist()
        f2 = q0 + q1
        f3 = f2 + q2
        return np.array([self._l1 * _cos(q0) + self._l2 * _cos(f2) + self._l3 * _cos(f3),
                         self._l1 * _sin(q0) + self._l2 * _sin(f2) + self._l3 * _sin(f3)])

    def jacobian(self, q):
        """End-effector Jacobian, see ``ArmModel.jacobian``."""
        q0, q1, q2 = self._q(q).tolist()
        f2 = q0 + q1
        f3 = f2 + q2
        x3, y3 = -self._l3 * _sin(f3), self._l3 * _cos(f3)
        x2, y2 = x3 - self._l2 * _sin(f2), y3 + self._l2 * _cos(f2)
        x1, y1 = x2 - self._l1 * _sin(q0), y2 + self._l1 * _cos(q0)
        return np.array([[x1, x2, x3], [y1, y2, y3]])

    def jdot_qdot(self, q, qd):
        """Velocity-product acceleration ``Jdot qd``, see ``ArmModel.jdot_qdot``."""
        q0, q1, q2 = self._q(q).tolist()
        w0, w1, w2 = self._q(qd, 'qd').tolist()
        f2, o2 = q0 + q1, w0 + w1
        f3, o3 = f2 + q2, o2 + w2
        k1, k2, k3 = self._l1 * w0 * w0, self._l2 * o2 * o2, self._l3 * o3 * o3
        return np.array([-(k1 * _cos(q0) + k2 * _cos(f2) + k3 * _cos(f3)),
                         -(k1 * _sin(q0) + k2 * _sin(f2) + k3 * _sin(f3))])

    def _phi_terms(self, q, qd):
        """``M_phi`` (3x3), ``c_phi``, ``G_phi`` as numpy arrays."""
        q0, q1, q2 = self._q(q).tolist()
        w0, w1, w2 = self._q(qd, 'qd').tolist()
        phi = (q0, q0 + q1, q0 + q1 + q2)
        om = (w0, w0 + w1, w0 + w1 + w2)
        h = {(0, 1): self._h12, (0, 2): self._h13, (1, 2): self._h23}
        m_phi = np.diag([self._d1, self._d2, self._d3])
        c_phi = np.zeros(3)
        for (a, b), hab in h.items():
            m_phi[a, b] = m_phi[b, a] = hab * _cos(phi[a] - phi[b])
            s = hab * _sin(phi[a] - phi[b])
            c_phi[a] += s * om[b] ** 2
            c_phi[b] -= s * om[a] ** 2
        g_phi = np.array([self._gh1 * _cos(phi[0]), self._gh2 * _cos(phi[1]),
                          self._gh3 * _cos(phi[2])])
        return m_phi, c_phi, g_phi

    _S = np.tril(np.ones((3, 3)))

    def mass_matrix(self, q):
        """Inertia matrix ``M = S^T M_phi S``, see ``ArmModel.mass_matrix``."""
        m_phi = self._phi_terms(q, np.zeros(3))[0]
        return self._S.T @ m_phi @ self._S

    def coriolis(self, q, qd):
        """Coriolis/centrifugal torques ``S^T c_phi``, see ``ArmModel.coriolis``."""
        return self._S.T @ self._phi_terms(q, qd)[1]

    def gravity_torque(self, q):
        """Gravity torques ``S^T G_phi``, see ``ArmModel.gravity_torque``."""
        return self._S.T @ self._phi_terms(q, np.zeros(3))[2]

    def forward_dynamics(self, q, qd, tau):
        """Joint accelerations via the scalar kernel, see ``ArmModel.forward_dynamics``."""
        args = self._q(q).tolist() + self._q(qd, 'qd').tolist()
        args += check_vector(tau, 3, 'tau').tolist()
        return np.array(self.qdd(*args))

    def decoupling(self, q, qd):
        """``Da`` (2, r) and ``b`` (2,) via the scalar kernel, see ``ArmModel.decoupling``."""
        args = self._q(q).tolist() + self._q(qd, 'qd').tolist()
        _, _, _, _, wx, wy, bx, by = self._task_full(*args)
        cols = list(self.active)
        return np.array([wx, wy])[:, cols], np.array([bx, by])

    def energy(self, q, qd):
        """Total mechanical energy, see ``ArmModel.energy``."""
        q0, q1, q2 = self._q(q).tolist()
        w0, w1, w2 = self._q(qd, 'qd').tolist()
        m_phi = self._phi_terms((q0, q1, q2), (0.0, 0.0, 0.0))[0]
        om = np.array([w0, w0 + w1, w0 + w1 + w2])
        pot = (self._gh1 * _sin(q0) + self._gh2 * _sin(q0 + q1)
               + self._gh3 * _sin(q0 + q1 + q2))
        return float(0.5 * om @ m_phi @ om + pot)


# -- the closed forms, on floats; the campaign kernel compiles these same functions --------
# ``c``: the arm's constants (d1, d2, d3, h12, h13, h23, g h1, g h2, g h3) (Arm3Model's,
# ``batch._consts``); ``ln``: the link lengths (3,).


def terms(c, q0, q1, q2, w0, w1, w2):
    """
    Return the terms :func:`qdd` and :func:`task` share, on floats.

    The tuple is ``(c1, s1, c2, s2, c3, s3, o2, o3, k1, k2, k3, a12, a13, a23, a11, b12,
    b13, a22, b23, a33, inv)``: ``cos`` / ``sin`` of the absolute angles, the absolute
    rates ``o2, o3`` (``o1 = w0``) and their squares ``k``, the ``H_ab sin(phi_a -
    phi_b)`` terms ``a``, the adjugate of ``M_phi`` (``a11 .. a33``, symmetric) and
    ``1 / det M_phi``.
    """
    f2 = q0 + q1
    f3 = f2 + q2
    c1 = math.cos(q0)
    s1 = math.sin(q0)
    c2 = math.cos(f2)
    s2 = math.sin(f2)
    c3 = math.cos(f3)
    s3 = math.sin(f3)
    o2 = w0 + w1
    o3 = o2 + w2
    k1 = w0 * w0
    k2 = o2 * o2
    k3 = o3 * o3
    h12 = c[3]
    h13 = c[4]
    h23 = c[5]
    x = h12 * (c1 * c2 + s1 * s2)
    y = h13 * (c1 * c3 + s1 * s3)
    z = h23 * (c2 * c3 + s2 * s3)
    a12 = h12 * (s1 * c2 - c1 * s2)
    a13 = h13 * (s1 * c3 - c1 * s3)
    a23 = h23 * (s2 * c3 - c2 * s3)
    d1 = c[0]
    d2 = c[1]
    d3 = c[2]
    a11 = d2 * d3 - z * z
    b12 = y * z - x * d3
    b13 = x * z - d2 * y
    a22 = d1 * d3 - y * y
    b23 = x * y - d1 * z
    a33 = d1 * d2 - x * x
    inv = 1.0 / (d1 * a11 + x * b12 + y * b13)
    return (c1, s1, c2, s2, c3, s3, o2, o3, k1, k2, k3, a12, a13, a23,
            a11, b12, b13, a22, b23, a33, inv)


def qdd(c, q0, q1, q2, w0, w1, w2, t0, t1, t2):
    """Return the joint accelerations [rad/s^2] under the joint forces ``t`` [N m]."""
    (c1, _, c2, _, c3, _, _, _, k1, k2, k3, a12, a13, a23,
     a11, b12, b13, a22, b23, a33, inv) = terms(c, q0, q1, q2, w0, w1, w2)
    r1 = t0 - t1 - (a12 * k2 + a13 * k3) - c[6] * c1
    r2 = t1 - t2 - (a23 * k3 - a12 * k1) - c[7] * c2
    r3 = t2 + (a13 * k1 + a23 * k2) - c[8] * c3
    p1 = (a11 * r1 + b12 * r2 + b13 * r3) * inv
    p2 = (b12 * r1 + a22 * r2 + b23 * r3) * inv
    p3 = (b13 * r1 + b23 * r2 + a33 * r3) * inv
    return p1, p2 - p1, p3 - p2


def task(c, ln, q0, q1, q2, w0, w1, w2):
    """
    Return the task terms: ``px, py, vx, vy``, ``W = J M^-1`` by rows and ``b`` (eq. 5).

    ``(px, py, vx, vy, x0, x1, x2, y0, y1, y2, bx, by)``: the end effector [m], its
    velocity ``J qd`` [m/s], the rows of ``J M^-1`` (the decoupling matrix's columns
    of the active joints) and the drift [m/s^2].
    """
    (c1, s1, c2, s2, c3, s3, o2, o3, k1, k2, k3, a12, a13, a23,
     a11, b12, b13, a22, b23, a33, inv) = terms(c, q0, q1, q2, w0, w1, w2)
    # c_phi + G_phi
    f1v = a12 * k2 + a13 * k3 + c[6] * c1
    f2v = a23 * k3 - a12 * k1 + c[7] * c2
    f3v = -(a13 * k1 + a23 * k2) + c[8] * c3
    lc1 = ln[0] * c1
    lc2 = ln[1] * c2
    lc3 = ln[2] * c3
    ls1 = ln[0] * s1
    ls2 = ln[1] * s2
    ls3 = ln[2] * s3
    px = lc1 + lc2 + lc3
    py = ls1 + ls2 + ls3
    vx = -(ls1 * w0 + ls2 * o2 + ls3 * o3)
    vy = lc1 * w0 + lc2 * o2 + lc3 * o3
    jdx = -(lc1 * k1 + lc2 * k2 + lc3 * k3)
    jdy = -(ls1 * k1 + ls2 * k2 + ls3 * k3)
    # V = J_phi M_phi^-1, rows x and y (J_phi x-row = -ls, y-row = lc).
    vx1 = -(a11 * ls1 + b12 * ls2 + b13 * ls3) * inv
    vx2 = -(b12 * ls1 + a22 * ls2 + b23 * ls3) * inv
    vx3 = -(b13 * ls1 + b23 * ls2 + a33 * ls3) * inv
    vy1 = (a11 * lc1 + b12 * lc2 + b13 * lc3) * inv
    vy2 = (b12 * lc1 + a22 * lc2 + b23 * lc3) * inv
    vy3 = (b13 * lc1 + b23 * lc2 + a33 * lc3) * inv
    bx = jdx - (vx1 * f1v + vx2 * f2v + vx3 * f3v)
    by = jdy - (vy1 * f1v + vy2 * f2v + vy3 * f3v)
    return px, py, vx, vy, vx1, vx2 - vx1, vx3 - vx2, vy1, vy2 - vy1, vy3 - vy2, bx, by
