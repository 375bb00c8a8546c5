"""
Dynamics of a URDF arm from Pinocchio (rigid-body algorithms on the robot description).

``PinArmModel`` has the ``ArmModel`` interface (``fk``, ``jacobian``, ``jdot_qdot``,
``mass_matrix``, ``coriolis``, ``gravity_torque``, ``forward_dynamics``,
``terms``, plus the inherited ``decoupling``, ``partition``, ``effective``, ``energy``, ``ik``),
computed by Pinocchio from the URDF text of a :class:`freejoint_core.urdf.UrdfArm`:

* ``M(q)``: ``crba`` (the Python bindings return both triangles; the tests compare
  the full matrix);
* ``C(q, qd) qd = nonLinearEffects(q, qd) - computeGeneralizedGravity(q)``;
* ``G(q)``: ``computeGeneralizedGravity`` with the model's gravity set to the arm's
  gravity vector in the base frame;
* ``J``: the x, y rows of the end-effector frame Jacobian (``LOCAL_WORLD_ALIGNED``);
* ``Jdot qd``: the x, y rows of the end-effector frame's classical acceleration after
  ``forwardKinematics(q, qd, 0)`` (zero joint acceleration);
* ``fk``: the x, y of the end-effector frame placement.

x, y are those of the arm's task frame (``UrdfArm.task_frame``: the base frame's own for
an arm in its x-y plane, else the placement, Jacobian and acceleration projected on the
frame's axes from its origin), and the core's angles are the URDF's plus
``UrdfArm.joint_offsets`` (taken off before Pinocchio sees them).

A nominal model (``scale != 1``) multiplies every body's mass, centre-of-mass lever
and rotational inertia by ``scale``, as ``ArmParams.scaled``.  Continuous joints
(two configuration entries, cos and sin) are mapped from the core's angles.

``terms(q, qd)`` gives ``M``, ``h = C qd + G``, ``J``, ``Jdot qd`` and ``fk`` from one
pass (the per-tick cost measured in ``bench/core_urdf.py``); ``decoupling`` is
``ArmModel``'s, :func:`freejoint_core.arm.task_space` of ``h``, ``Jdot qd`` and
``J M^-1`` from ``computeMinverse``.
"""

import math

from freejoint_core.arm import ArmModel, check_vector
from freejoint_core.errors import FreejointValueError
from freejoint_core.urdf import UrdfArm
import numpy as np
import pinocchio as pin

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class PinArmModel(ArmModel):
    """
    Planar arm dynamics from Pinocchio, ``ArmModel`` interface.

    Parameters
    ----------
    arm : UrdfArm
        The parsed description (URDF text, joint order, passive joints, gravity).
    scale : float
        Nominal factor on masses, inertias and COM levers (1.0: the URDF's values).

    """

    def __init__(self, arm, scale=1.0):
        if not isinstance(arm, UrdfArm):
            raise FreejointValueError(f'arm: expected UrdfArm, got {type(arm).__name__}')
        params = arm.params if scale == 1.0 else arm.nominal(scale)
        super().__init__(params)
        self.arm = arm
        try:
            model = pin.buildModelFromXML(arm.urdf)
        except (RuntimeError, ValueError) as exc:
            raise FreejointValueError(f'arm: Pinocchio cannot read the URDF ({exc})') from None
        if scale != 1.0:
            for j in range(1, model.njoints):
                inert = model.inertias[j]
                model.inertias[j] = pin.Inertia(scale * inert.mass, scale * inert.lever,
                                                scale * inert.inertia)
        model.gravity.linear = np.array(arm.gravity_vector, dtype=float)
        self.pin_model = model
        self.pin_data = model.createData()
        if not model.existFrame(arm.ee_link):
            raise FreejointValueError(f'arm: Pinocchio has no frame {arm.ee_link!r}')
        self._frame = model.getFrameId(arm.ee_link)
        # core joint i -> Pinocchio (idx_q, nq, idx_v)
        slots = []
        for jname in arm.joint_names:
            jid = model.getJointId(jname)
            if jid >= model.njoints:
                raise FreejointValueError(f'arm: Pinocchio has no joint {jname!r}')
            jm = model.joints[jid]
            slots.append((jm.idx_q, jm.nq, jm.idx_v))
        if model.nv != self.n:
            raise FreejointValueError(
                f'arm: Pinocchio model has nv = {model.nv}, expected {self.n} joints')
        self._slots = slots
        self._vperm = np.array([s[2] for s in slots])
        self._identity = (all(nq == 1 for _, nq, _ in slots)
                          and [s[0] for s in slots] == list(range(self.n))
                          and list(self._vperm) == list(range(self.n)))
        self._zero = np.zeros(model.nv)
        self._offsets = np.array(arm.joint_offsets) if arm.joint_offsets else None
        origin, x_axis, y_axis = arm.task_frame
        base = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
        self._plane = None if arm.task_frame == base else (
            np.array(origin), np.array([x_axis, y_axis]))

    # -- conversions --------------------------------------------------------
    def _q(self, q, name='q'):
        """Return ``q`` validated as ``check_vector`` does (fast path for float arrays)."""
        if (type(q) is np.ndarray and q.dtype == np.float64 and q.shape == (self.n,)
                and math.isfinite(q.sum())):
            return q
        return check_vector(q, self.n, name)

    @staticmethod
    def _sym(mat):
        """Return a copy of a Pinocchio joint-space matrix (the bindings fill both triangles)."""
        return np.array(mat)

    def _config(self, q):
        """Pinocchio configuration of the core's joint angles (validated)."""
        q = self._q(q)
        if self._offsets is not None:
            q = q - self._offsets
        if self._identity:
            return q
        cfg = np.zeros(self.pin_model.nq)
        for qi, (iq, nq, _) in zip(q, self._slots):
            if nq == 1:
                cfg[iq] = qi
            else:
                cfg[iq], cfg[iq + 1] = np.cos(qi), np.sin(qi)
        return cfg

    def _vel(self, qd, name='qd'):
        qd = self._q(qd, name)
        if self._identity:
            return qd
        out = np.zeros(self.pin_model.nv)
        out[self._vperm] = qd
        return out

    def _back(self, vec):
        """Core order of a Pinocchio velocity-space vector."""
        return np.array(vec[self._vperm]) if not self._identity else np.array(vec)

    def _back_mat(self, mat):
        return np.array(mat[np.ix_(self._vperm, self._vperm)])

    def _point(self, pos):
        """Task-frame x, y (2,) of a position (3,) in the base frame."""
        if self._plane is None:
            return np.array(pos[:2])
        origin, axes = self._plane
        return axes @ (np.asarray(pos) - origin)

    def _rows(self, vec):
        """Task-frame x, y rows of a base-frame vector (3,) or of the linear rows of a Jacobian."""
        if self._plane is None:
            return np.array(vec[:2])
        return self._plane[1] @ np.asarray(vec)[:3]

    # -- kinematics ---------------------------------------------------------
    def fk(self, q):
        """End-effector position from the frame placement, see ``ArmModel.fk``."""
        m, d = self.pin_model, self.pin_data
        pin.framesForwardKinematics(m, d, self._config(q))
        return self._point(d.oMf[self._frame].translation)

    def jacobian(self, q):
        """x, y rows of the frame Jacobian, see ``ArmModel.jacobian``."""
        m, d = self.pin_model, self.pin_data
        jac = pin.computeFrameJacobian(m, d, self._config(q), self._frame, _LWA)
        return np.array(self._rows(jac)[:, self._vperm])

    def jdot_qdot(self, q, qd):
        """Frame's classical acceleration at zero qdd, see ``ArmModel.jdot_qdot``."""
        m, d = self.pin_model, self.pin_data
        pin.forwardKinematics(m, d, self._config(q), self._vel(qd), self._zero)
        pin.updateFramePlacement(m, d, self._frame)
        acc = pin.getFrameClassicalAcceleration(m, d, self._frame, _LWA)
        return self._rows(acc.linear)

    # -- dynamics -----------------------------------------------------------
    def mass_matrix(self, q):
        """Inertia matrix ``M(q)`` (crba), see ``ArmModel.mass_matrix``."""
        m, d = self.pin_model, self.pin_data
        mass = self._sym(pin.crba(m, d, self._config(q)))
        return mass if self._identity else self._back_mat(mass)

    def coriolis(self, q, qd):
        """Coriolis torques: nonLinearEffects - gravity, see ``ArmModel.coriolis``."""
        m, d = self.pin_model, self.pin_data
        cfg = self._config(q)
        nle = np.array(pin.nonLinearEffects(m, d, cfg, self._vel(qd)))
        return self._back(nle - pin.computeGeneralizedGravity(m, d, cfg))

    def gravity_torque(self, q):
        """Generalized gravity, see ``ArmModel.gravity_torque``."""
        m, d = self.pin_model, self.pin_data
        return self._back(pin.computeGeneralizedGravity(m, d, self._config(q)))

    def coriolis_matrix(self, q, qd):
        """``C(q, qd)`` from ``computeCoriolisMatrix``, see ``ArmModel.coriolis_matrix``."""
        m, d = self.pin_model, self.pin_data
        cmat = pin.computeCoriolisMatrix(m, d, self._config(q), self._vel(qd))
        return self._back_mat(np.array(cmat))

    def forward_dynamics(self, q, qd, tau):
        """Joint accelerations by ABA, see ``ArmModel.forward_dynamics``."""
        m, d = self.pin_model, self.pin_data
        tau = self._vel(check_vector(tau, self.n, 'tau'), 'tau')
        return self._back(pin.aba(m, d, self._config(q), self._vel(qd), tau))

    def _pass(self, cfg, vel):
        """``h``, ``J`` (x, y rows; Pinocchio's velocity order) and ``Jdot qd``, one pass."""
        m, d = self.pin_model, self.pin_data
        h = np.array(pin.nonLinearEffects(m, d, cfg, vel))
        # The joint Jacobians, then the zero-acceleration kinematics the frame's classical
        # acceleration reads (velocities and accelerations of the joints).
        pin.computeJointJacobians(m, d, cfg)
        pin.forwardKinematics(m, d, cfg, vel, self._zero)
        pin.updateFramePlacement(m, d, self._frame)
        jac = self._rows(pin.getFrameJacobian(m, d, self._frame, _LWA))
        acc = self._rows(pin.getFrameClassicalAcceleration(m, d, self._frame, _LWA).linear)
        return h, jac, acc

    def terms(self, q, qd):
        """Return the five terms from one Pinocchio pass, see ``ArmModel.terms``."""
        cfg, vel = self._config(q), self._vel(qd)
        mass = self._sym(pin.crba(self.pin_model, self.pin_data, cfg))
        h, jac, jdqd = self._pass(cfg, vel)
        p = self._point(self.pin_data.oMf[self._frame].translation)
        if self._identity:
            return mass, h, np.array(jac), jdqd, p
        return self._back_mat(mass), self._back(h), np.array(jac[:, self._vperm]), jdqd, p

    def _task_terms(self, q, qd):
        """``J M^-1`` from ``computeMinverse``, ``h`` and ``Jdot qd``, one pass (core order)."""
        cfg, vel = self._config(q), self._vel(qd)
        minv = self._sym(pin.computeMinverse(self.pin_model, self.pin_data, cfg))
        h, jac, jdqd = self._pass(cfg, vel)
        w = jac @ minv                       # J M^-1 in Pinocchio's velocity order
        if not self._identity:
            w, h = w[:, self._vperm], h[self._vperm]
        return w, h, jdqd
