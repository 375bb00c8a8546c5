"""
A MuJoCo plant: the URDF arm simulated by MuJoCo, with the ``Plant`` interface.

The same forcing as ``freejoint_core.plant.Plant``: over one control period ``dt``
the actuator torque and one disturbance draw are held (zero-order hold), with
``rng = numpy.random.default_rng(seed)`` and one ``rng.uniform(-dist_bound,
dist_bound, n)`` per ``step`` (none if ``dist_bound = 0``), so a MuJoCo plant and an
RK4 plant with the same seed see the same disturbance sequence.  The held
generalised force goes to ``qfrc_applied``; MuJoCo integrates with its RK4
integrator at ``timestep = dt_sub``, ``dt / dt_sub`` steps per period.

The model is MuJoCo's own URDF import of ``UrdfArm.urdf`` with:

* gravity set to ``UrdfArm.gravity_vector`` (a URDF has no gravity element);
* contacts and every constraint disabled (joint limits included: the core's model
  has none), joint damping, friction loss and armature set to 0, so the
  equations are eq. (1) exactly, ``M qdd + C qd + G = B tau_a + d``;
* joints addressed by the URDF names, in the core's order.

A step that MuJoCo flags as diverged (its bad qpos / qvel / qacc warnings: it
then resets its state) or that ends non-finite raises ``PlantDivergedError`` and
the plant keeps its last finite state, as ``Plant`` does.  MuJoCo's warnings are
taken by a handler during the step (not printed, no ``MUJOCO_LOG.TXT``).
"""

import math

from freejoint_core.arm import check_vector, make_model
from freejoint_core.errors import FreejointValueError, PlantDivergedError
from freejoint_core.plant import DEFAULT_DT_SUB
from freejoint_core.urdf import UrdfArm
import mujoco
import numpy as np


def _positive(value, name, allow_zero=False):
    try:
        value = float(value)
    except (TypeError, ValueError) as exc:
        raise FreejointValueError(f'{name}: expected a number, got {value!r}') from exc
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        bound = '>= 0' if allow_zero else '> 0'
        raise FreejointValueError(f'{name}: must be finite and {bound}, got {value}')
    return value


def build_mj_model(arm, dt_sub=DEFAULT_DT_SUB):
    """
    Build the MuJoCo model of a URDF arm, set up to integrate eq. (1) exactly.

    Parameters
    ----------
    arm : UrdfArm
        The parsed description.
    dt_sub : float
        RK4 step [s], > 0.

    Returns
    -------
    model : mujoco.MjModel
    qpos_adr : numpy.ndarray of int, (n,)
        Address in ``qpos`` of each joint, core order.
    dof_adr : numpy.ndarray of int, (n,)
        Address in ``qvel`` / ``qfrc_applied`` of each joint, core order.

    """
    if not isinstance(arm, UrdfArm):
        raise FreejointValueError(f'arm: expected UrdfArm, got {type(arm).__name__}')
    dt_sub = _positive(dt_sub, 'dt_sub')
    try:
        model = mujoco.MjModel.from_xml_string(arm.urdf)
    except ValueError as exc:
        msg = ' '.join(str(exc).split())
        raise FreejointValueError(f'arm: MuJoCo cannot load the URDF ({msg})') from None
    model.opt.gravity[:] = arm.gravity_vector
    model.opt.timestep = dt_sub
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    model.opt.disableflags |= (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
                               | mujoco.mjtDisableBit.mjDSBL_CONTACT)
    model.dof_damping[:] = 0.0
    model.dof_frictionloss[:] = 0.0
    model.dof_armature[:] = 0.0
    model.jnt_stiffness[:] = 0.0
    qpos_adr, dof_adr = [], []
    for name in arm.joint_names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise FreejointValueError(f'arm: MuJoCo has no joint {name!r} after the import')
        if model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            raise FreejointValueError(f'arm: MuJoCo joint {name!r} is not a hinge')
        qpos_adr.append(int(model.jnt_qposadr[jid]))
        dof_adr.append(int(model.jnt_dofadr[jid]))
    if model.nv != arm.params.n:
        raise FreejointValueError(
            f'arm: MuJoCo model has nv = {model.nv}, expected {arm.params.n} joints')
    return model, np.array(qpos_adr), np.array(dof_adr)


class MujocoPlant:
    """
    The URDF arm simulated by MuJoCo, with bounded random joint disturbances.

    Parameters
    ----------
    arm : UrdfArm
        The real arm (URDF, passive joints, gravity vector).
    dt_sub : float
        MuJoCo RK4 step [s], > 0.
    dist_bound : float
        Disturbance bound [N m], >= 0 (0 disables the disturbance).
    seed : int or None
        Seed of ``numpy.random.default_rng``.
    q0, qd0 : array_like, (n,), optional
        Initial joint angles [rad] and velocities [rad/s]; zeros if None.

    Attributes
    ----------
    params : ArmParams
        ``arm.params``.
    model : ArmModel
        The core's model of ``params`` (for fk and the like, as ``Plant.model``).
    mj_model, mj_data : mujoco.MjModel, mujoco.MjData
        The MuJoCo model and state.
    q, qd : numpy.ndarray, (n,)
        Copies of the current joint angles [rad] and velocities [rad/s].
    t : float
        Simulated time [s] (sum of the ``dt`` passed to ``step``).
    k : int
        Number of ``step`` calls since construction/reset.
    last_disturbance : tuple of float
        The disturbance [N m] held over the last step (zeros if disabled).

    """

    def __init__(self, arm, dt_sub=DEFAULT_DT_SUB, dist_bound=0.5, seed=0, q0=None, qd0=None):
        self.mj_model, self._qadr, self._vadr = build_mj_model(arm, dt_sub)
        self.mj_data = mujoco.MjData(self.mj_model)
        self.arm = arm
        self.params = arm.params
        self.model = make_model(arm.params)
        self.n = arm.params.n
        self.r = arm.params.r
        self.dt_sub = float(self.mj_model.opt.timestep)
        self.dist_bound = _positive(dist_bound, 'dist_bound', allow_zero=True)
        self._check_seed(seed)
        self._seed0 = seed
        self._q0 = self._state(q0, 'q0')
        self._qd0 = self._state(qd0, 'qd0')
        self._active = list(arm.params.active)
        self._dt_cache = (None, 0)
        self._bad = [int(w) for w in (mujoco.mjtWarning.mjWARN_BADQPOS,
                                      mujoco.mjtWarning.mjWARN_BADQVEL,
                                      mujoco.mjtWarning.mjWARN_BADQACC)]
        self.reset()

    @staticmethod
    def _check_seed(seed):
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                                 or seed < 0):
            raise FreejointValueError(f'seed: expected a non-negative int or None, got {seed!r}')

    def _state(self, x, name):
        if x is None:
            return np.zeros(self.n)
        return check_vector(x, self.n, name)

    def reset(self, q0=None, qd0=None, seed=None):
        """
        Restart at t = 0, k = 0 with a freshly seeded disturbance generator.

        Parameters
        ----------
        q0, qd0 : array_like, (n,), optional
            New initial state; None keeps the previous one.
        seed : int, optional
            New seed; None keeps the previous one.

        """
        if q0 is not None:
            self._q0 = self._state(q0, 'q0')
        if qd0 is not None:
            self._qd0 = self._state(qd0, 'qd0')
        if seed is not None:
            self._check_seed(seed)
            self._seed0 = seed
        mujoco.mj_resetData(self.mj_model, self.mj_data)
        self.mj_data.qpos[self._qadr] = self._q0
        self.mj_data.qvel[self._vadr] = self._qd0
        self._rng = np.random.default_rng(self._seed0)
        self._take_bad_warnings()
        self.t = 0.0
        self.k = 0
        self.last_disturbance = (0.0,) * self.n

    def _take_bad_warnings(self):
        """Return how many bad-state warnings MuJoCo counted, and zero the counters."""
        warning = self.mj_data.warning
        count = 0
        for i in self._bad:
            if warning[i].number:
                count += warning[i].number
                warning[i].number = 0
        return count

    @property
    def q(self):
        """Return the joint angles [rad], numpy copy (n,)."""
        return self.mj_data.qpos[self._qadr].copy()

    @property
    def qd(self):
        """Return the joint velocities [rad/s], numpy copy (n,)."""
        return self.mj_data.qvel[self._vadr].copy()

    def _substeps(self, dt):
        if dt == self._dt_cache[0]:
            return self._dt_cache[1]
        dt_f = _positive(dt, 'dt')
        n_sub = round(dt_f / self.dt_sub)
        if n_sub < 1 or abs(n_sub * self.dt_sub - dt_f) > 1e-9 * dt_f:
            raise FreejointValueError(
                f'dt: {dt_f} s is not an integer multiple of dt_sub = {self.dt_sub} s')
        self._dt_cache = (dt, n_sub)
        return n_sub

    def step(self, tau_active, dt):
        """
        Advance by one control period with torque and disturbance held.

        Parameters
        ----------
        tau_active : array_like, (r,)
            Actuator torques on the active joints, in ``params.active`` order [N m].
        dt : float
            Control period [s], an integer multiple of ``dt_sub``.

        Raises
        ------
        FreejointValueError
            Naming ``tau_active`` or ``dt`` if they are bad.
        PlantDivergedError
            If MuJoCo flagged the integration (bad position, velocity or
            acceleration) or the state is not finite; the plant keeps its last
            finite state, the disturbance draw of the step is spent.

        """
        n_sub = self._substeps(dt)
        tau = tau_active.tolist() if isinstance(tau_active, np.ndarray) else tau_active
        try:
            ok = len(tau) == self.r and all(math.isfinite(v) for v in tau)
        except TypeError:
            ok = False
        if not ok:
            shape = np.shape(tau_active) if not isinstance(tau_active, (str, bytes)) else '?'
            raise FreejointValueError(
                f'tau_active: expected {self.r} finite values (shape ({self.r},)), '
                f'got {tau_active!r} with shape {shape}')
        if self.dist_bound > 0.0:
            full = self._rng.uniform(-self.dist_bound, self.dist_bound, self.n)
            self.last_disturbance = tuple(full.tolist())
        else:
            full = np.zeros(self.n)
        full[self._active] += np.asarray(tau, dtype=float)
        data = self.mj_data
        q_before, qd_before = data.qpos.copy(), data.qvel.copy()
        data.qfrc_applied[:] = 0.0
        data.qfrc_applied[self._vadr] = full
        messages = []
        previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(messages.append)   # no print, no MUJOCO_LOG.TXT
        try:
            mujoco.mj_step(self.mj_model, data, n_sub)
        finally:
            mujoco.set_mju_user_warning(previous)
        finite = math.isfinite(float(data.qpos.sum() + data.qvel.sum()))
        if self._take_bad_warnings() or messages or not finite:
            data.qpos[:], data.qvel[:] = q_before, qd_before
            why = ' '.join(' '.join(messages).split()) or 'non-finite state'
            raise PlantDivergedError(
                f'tau_active: the integration over step {self.k} diverged (MuJoCo: {why}) '
                f'from q = {q_before[self._qadr].tolist()}, qd = '
                f'{qd_before[self._vadr].tolist()}; the state is left as it was')
        self.t += dt
        self.k += 1
