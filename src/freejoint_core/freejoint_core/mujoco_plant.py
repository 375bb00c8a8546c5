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

A spatial arm (``freejoint_core.spatial_model.SpatialArm``: a serial chain of a URDF, the
tip in 3-D) is :class:`SpatialMujocoPlant`, the same with MuJoCo's import of the arm's
URDF with its visual and collision elements left out (no meshes loaded) and every movable
joint off the chain made fixed at 0, as ``SpatialArm`` locks it (the Panda's fingers);
gravity ``SpatialArm.gravity``.

A step that MuJoCo flags as diverged (its bad qpos / qvel / qacc warnings: it
then resets its state) or that ends non-finite raises ``PlantDivergedError`` and
the plant keeps its last finite state, as ``Plant`` does.  MuJoCo's warnings are
taken by a handler during the step (not printed, no ``MUJOCO_LOG.TXT``).
"""

from freejoint_core.errors import FreejointValueError, positive
from freejoint_core.models import make_model
from freejoint_core.plant import DEFAULT_DT_SUB, PeriodPlant
from freejoint_core.urdf import UrdfArm
import mujoco
import numpy as np


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
    dt_sub = positive('dt_sub', dt_sub)
    try:
        model = mujoco.MjModel.from_xml_string(arm.urdf)
    except ValueError as exc:
        msg = ' '.join(str(exc).split())
        raise FreejointValueError(f'arm: MuJoCo cannot load the URDF ({msg})') from None
    _exact(model, arm.gravity_vector, dt_sub)
    return (model, *_addresses(model, arm.joint_names))


def _exact(model, gravity, dt_sub):
    """Set a model up to integrate eq. (1) exactly: RK4 at ``dt_sub``, nothing else."""
    model.opt.gravity[:] = gravity
    model.opt.timestep = dt_sub
    model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    model.opt.disableflags |= (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
                               | mujoco.mjtDisableBit.mjDSBL_CONTACT)
    model.dof_damping[:] = 0.0
    model.dof_frictionloss[:] = 0.0
    model.dof_armature[:] = 0.0
    model.jnt_stiffness[:] = 0.0


def _addresses(model, joint_names):
    """Return the ``qpos`` and ``qvel`` addresses of the joints (core order), or raise."""
    qpos_adr, dof_adr = [], []
    for name in joint_names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise FreejointValueError(f'arm: MuJoCo has no joint {name!r} after the import')
        if model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            raise FreejointValueError(f'arm: MuJoCo joint {name!r} is not a hinge')
        qpos_adr.append(int(model.jnt_qposadr[jid]))
        dof_adr.append(int(model.jnt_dofadr[jid]))
    if model.nv != len(joint_names):
        raise FreejointValueError(
            f'arm: MuJoCo model has nv = {model.nv}, expected {len(joint_names)} joints')
    return np.array(qpos_adr), np.array(dof_adr)


def spatial_urdf(arm):
    """
    Return the URDF text MuJoCo imports for a spatial arm (module notes).

    Parameters
    ----------
    arm : freejoint_core.spatial_model.SpatialArm
        The arm (``urdf``, ``joint_names``).

    Returns
    -------
    str
        The arm's URDF without visual and collision elements, every movable joint off the
        chain fixed at 0.

    Raises
    ------
    FreejointValueError
        ``arm: ...`` if a joint off the chain cannot sit at 0 (its limits exclude it:
        ``SpatialArm`` locks it at the nearer limit, which a fixed joint cannot be).

    """
    import xml.etree.ElementTree as ET
    robot = ET.fromstring(arm.urdf)
    for link in robot.findall('link'):
        for tag in ('visual', 'collision'):
            for element in link.findall(tag):
                link.remove(element)
    for joint in robot.findall('joint'):
        if joint.get('type') in ('fixed', None) or joint.get('name') in arm.joint_names:
            continue
        limit = joint.find('limit')
        if joint.get('type') != 'continuous' and limit is not None and not (
                float(limit.get('lower', 0.0)) <= 0.0 <= float(limit.get('upper', 0.0))):
            raise FreejointValueError(
                f"arm: joint {joint.get('name')!r} off the chain is locked at a limit, not at "
                '0: MuJoCo cannot fix it there')
        joint.set('type', 'fixed')
    return ET.tostring(robot, encoding='unicode')


def build_spatial_mj_model(arm, dt_sub=DEFAULT_DT_SUB):
    """
    Build the MuJoCo model of a spatial arm's chain, set up to integrate its dynamics exactly.

    Parameters
    ----------
    arm : freejoint_core.spatial_model.SpatialArm
        The arm (URDF, chain, gravity).
    dt_sub : float
        RK4 step [s], > 0.

    Returns
    -------
    model, qpos_adr, dof_adr
        As :func:`build_mj_model`.

    """
    dt_sub = positive('dt_sub', dt_sub)
    try:
        model = mujoco.MjModel.from_xml_string(spatial_urdf(arm))
    except ValueError as exc:
        msg = ' '.join(str(exc).split())
        raise FreejointValueError(f'arm: MuJoCo cannot load the URDF ({msg})') from None
    _exact(model, arm.gravity, dt_sub)
    return (model, *_addresses(model, arm.joint_names))


class MujocoPlant(PeriodPlant):
    """
    The URDF arm simulated by MuJoCo, with bounded random joint disturbances.

    Parameters
    ----------
    arm : UrdfArm
        The real arm (URDF, passive joints, gravity vector).
    dt_sub : float
        MuJoCo RK4 step [s], > 0.
    dist_bound, seed, q0, qd0
        As :class:`freejoint_core.plant.Plant`.

    Attributes
    ----------
    params : ArmParams
        ``arm.params``.
    model : ArmModel
        The core's model of ``params`` (for fk and the like, as ``Plant.model``).
    mj_model, mj_data : mujoco.MjModel, mujoco.MjData
        The MuJoCo model and state.
    q, qd, t, k, last_disturbance
        As :class:`freejoint_core.plant.PeriodPlant`.

    """

    def __init__(self, arm, dt_sub=DEFAULT_DT_SUB, dist_bound=0.5, seed=0, q0=None, qd0=None):
        # the core's angles are MuJoCo's (the URDF's) plus the arm's offsets
        self._start(arm, build_mj_model(arm, dt_sub),
                    np.array(arm.joint_offsets) if arm.joint_offsets else None,
                    arm.params, make_model(arm.params), dist_bound, seed, q0, qd0)

    def _start(self, arm, built, offsets, params, model, dist_bound, seed, q0, qd0):
        """Take the MuJoCo model ``built`` (model, qpos and qvel addresses) and reset."""
        self.mj_model, self._qadr, self._vadr = built
        self._offsets = offsets
        self.mj_data = mujoco.MjData(self.mj_model)
        self.arm = arm
        self._bad = [int(w) for w in (mujoco.mjtWarning.mjWARN_BADQPOS,
                                      mujoco.mjtWarning.mjWARN_BADQVEL,
                                      mujoco.mjtWarning.mjWARN_BADQACC)]
        self._setup(params, model, float(self.mj_model.opt.timestep), dist_bound, seed, q0,
                    qd0)
        self.reset()

    def _set_state(self, q0, qd0):
        mujoco.mj_resetData(self.mj_model, self.mj_data)
        self.mj_data.qpos[self._qadr] = q0 if self._offsets is None else q0 - self._offsets
        self.mj_data.qvel[self._vadr] = qd0
        self._take_bad_warnings()

    def _take_bad_warnings(self):
        """Return how many bad-state warnings MuJoCo counted, and zero the counters."""
        warning = self.mj_data.warning
        count = 0
        for i in self._bad:
            if warning[i].number:
                count += warning[i].number
                warning[i].number = 0
        return count

    def stop(self):
        """Zero every joint velocity: the arm stops where it is (brakes engaged)."""
        self.mj_data.qvel[:] = 0.0

    @property
    def q(self):
        """Return the joint angles [rad] (the core's: the URDF's plus the offsets), copy (n,)."""
        q = self.mj_data.qpos[self._qadr].copy()
        return q if self._offsets is None else q + self._offsets

    @property
    def qd(self):
        """Return the joint velocities [rad/s], numpy copy (n,)."""
        return self.mj_data.qvel[self._vadr].copy()

    def _advance(self, n_sub, force):
        data = self.mj_data
        q_before, qd_before = data.qpos.copy(), data.qvel.copy()
        data.qfrc_applied[:] = 0.0
        data.qfrc_applied[self._vadr] = force
        messages = []
        previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(messages.append)   # no print, no MUJOCO_LOG.TXT
        try:
            mujoco.mj_step(self.mj_model, data, n_sub)
        finally:
            mujoco.set_mju_user_warning(previous)
        finite = np.isfinite(data.qpos.sum() + data.qvel.sum())
        if not self._take_bad_warnings() and not messages and finite:
            return None
        data.qpos[:], data.qvel[:] = q_before, qd_before
        return 'MuJoCo: ' + (' '.join(' '.join(messages).split()) or 'non-finite state')


class SpatialMujocoPlant(MujocoPlant):
    """
    A spatial arm simulated by MuJoCo, with bounded random joint disturbances.

    ``freejoint_core.spatial_plant.SpatialPlant`` with MuJoCo's RK4 on its own import of
    the URDF instead of RK4 on Pinocchio's ABA (module notes).

    Parameters
    ----------
    arm : freejoint_core.spatial_model.SpatialArm
        The real arm (URDF, chain, free joints, gravity).
    dt_sub : float
        MuJoCo RK4 step [s], > 0.
    dist_bound, seed, q0, qd0
        As :class:`freejoint_core.plant.Plant`.
    passive_damping : float
        As :class:`freejoint_core.spatial_plant.SpatialPlant` (MuJoCo's ``dof_damping`` of
        the free joints).

    Attributes
    ----------
    params, model : SpatialArm
        ``arm`` (``n``, ``r``, ``active``; ``fk`` of the tip), as ``SpatialPlant``.
    mj_model, mj_data, q, qd, t, k, last_disturbance
        As :class:`MujocoPlant`.

    """

    def __init__(self, arm, dt_sub=DEFAULT_DT_SUB, dist_bound=0.5, seed=0, q0=None, qd0=None,
                 passive_damping=0.0):
        from freejoint_core.spatial_model import SpatialArm
        from freejoint_core.spatial_plant import passive_damping_vector
        if not isinstance(arm, SpatialArm):
            raise FreejointValueError(f'arm: expected SpatialArm, got {type(arm).__name__}')
        self.damping = passive_damping_vector(arm, passive_damping)
        built = build_spatial_mj_model(arm, dt_sub)
        # MuJoCo's RK4 takes joint damping explicitly at every stage, as SpatialPlant does
        built[0].dof_damping[built[2]] = self.damping
        self._start(arm, built, None, arm, arm, dist_bound, seed, q0, qd0)
