"""
Spatial serial arm from any URDF, on Pinocchio.

:class:`SpatialArm` cuts the chain ``base_link -> tip_link`` out of a URDF: every joint
outside it (e.g. the Panda's fingers) is locked at its reference angle (0 clipped into
its position limits) with ``pinocchio.buildReducedModel``; the chain's joints must be
one-degree-of-freedom (revolute, prismatic or continuous).  Effort, velocity and position
limits come from the URDF.

A continuous joint (Pinocchio's unbounded revolute: two configuration entries, cos and
sin, one velocity) is read as a revolute joint about the same axis whose coordinate is
its angle (:func:`angle_coordinates`): the same kinematics and dynamics, one
configuration entry per joint as every node's ``q`` has, and no position limits
(``lower`` / ``upper`` -inf / +inf; :attr:`SpatialArm.continuous` names them).  Gravity is
``(0, 0, -9.81)`` in the URDF's root frame unless given.

The task has ``m = 3`` rows (tip position) or ``m = 6`` (position, then orientation),
in the root frame (``LOCAL_WORLD_ALIGNED``: the angular rows are the world angular
velocity).  :meth:`SpatialArm.terms` gives, from one Pinocchio pass,

* ``M`` (crba, n x n), ``h = C qd + G`` (``nonLinearEffects``), ``Minv``
  (``computeMinverse``);
* ``J`` (m x n) and ``Jdot qd`` (m,): the frame Jacobian rows and the frame's classical
  acceleration at zero joint acceleration;
* ``p`` (3,), ``R`` (3, 3): the tip frame's placement.

:meth:`SpatialArm.decoupling` is the paper's eqs. 3-5 for the active set ``a`` and free
set ``p``: with no torque on the free joints, ``qdd = M^-1 (B tau - h)``, so::

    pdd = Da tau + b,   Da = (J M^-1)[:, a],   b = Jdot qd - J M^-1 h,
    M~aa = ((M^-1)[a, a])^-1     (the Schur complement Maa - Map Mpp^-1 Mpa)

``M~aa`` is the effective inertia of the active joints (the weight of the inertia-
weighted inverse, ``freejoint_core.internal.weighted_inverse``).

A nominal model (``scale != 1``) multiplies every body's mass, centre-of-mass lever and
rotational inertia by ``scale`` (as ``ArmParams.scaled`` of the planar arms).
"""

import glob
import math
import os
import sys
from typing import NamedTuple

from freejoint_core.errors import FreejointValueError
import numpy as np
import pinocchio as pin

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
TASK_DIMS = (3, 6)
GRAVITY = (0.0, 0.0, -9.81)

#: The arms of example-robot-data the runner knows: URDF path (under its ``robots``
#: directory), base link, tip link.
KNOWN_ARMS = {
    'ur5': ('ur_description/urdf/ur5_robot.urdf', 'base_link', 'tool0'),
    'panda': ('panda_description/urdf/panda.urdf', 'panda_link0', 'panda_hand_tcp'),
}


def robot_data_dir():
    """
    Directory ``robots`` of the PyPI package example-robot-data (its URDFs and meshes).

    Returns
    -------
    str
        Absolute path.

    Raises
    ------
    FreejointValueError
        The package is not installed (``example-robot-data``, tools/requirements.txt).

    """
    for entry in sys.path:
        cand = os.path.join(entry, 'cmeel.prefix', 'share', 'example-robot-data', 'robots')
        if os.path.isdir(cand):
            return cand
    found = glob.glob(os.path.join(sys.prefix, 'lib', 'python*', 'site-packages', 'cmeel.prefix',
                                   'share', 'example-robot-data', 'robots'))
    if found:
        return found[0]
    raise FreejointValueError('example-robot-data: not installed (pip install -r '
                              'tools/requirements.txt)')


def root_link(text):
    """
    Return the root link of a URDF (the one link that is no joint's child).

    Parameters
    ----------
    text : str
        URDF text.

    Raises
    ------
    FreejointValueError
        ``robot_description: ...`` if the text is not XML or has not exactly one root.

    """
    import xml.etree.ElementTree as ET
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as exc:
        raise FreejointValueError(f'robot_description: not XML ({exc})') from None
    links = [el.get('name') for el in robot.findall('link')]
    children = {el.get('link') for joint in robot.findall('joint')
                for el in joint.findall('child')}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise FreejointValueError(
            f'robot_description: expected one root link, got {roots}; give base_link')
    return roots[0]


def continuous_joints(text):
    """
    Return the names of a URDF's continuous joints (a set; none: empty).

    Parameters
    ----------
    text : str
        URDF text (well-formed XML: :func:`root_link`'s check).

    """
    import xml.etree.ElementTree as ET
    try:
        robot = ET.fromstring(text)
    except ET.ParseError:
        return set()
    return {el.get('name') for el in robot.iter('joint') if el.get('type') == 'continuous'}


def angle_coordinates(text):
    """
    Return a URDF's text with each continuous joint made a revolute joint without limits.

    Pinocchio gives a continuous joint two configuration entries (cos, sin) and one
    velocity; the nodes, the plants and the law take one angle per joint.  A revolute
    joint about the same axis, its angle the coordinate, has the same kinematics and
    dynamics; its ``<limit>`` keeps the URDF's effort and velocity, and its position
    limits (which a continuous joint does not have) are replaced by -inf / +inf in
    :class:`SpatialArm`.  Text without a continuous joint is returned unchanged (so
    Pinocchio reads the same bytes as before).

    Parameters
    ----------
    text : str
        URDF text.

    Returns
    -------
    str

    """
    if 'continuous' not in text:
        return text
    import xml.etree.ElementTree as ET
    try:
        robot = ET.fromstring(text)
    except ET.ParseError:
        return text             # Pinocchio's own error names what is wrong
    changed = False
    for joint in robot.iter('joint'):
        if joint.get('type') != 'continuous':
            continue
        joint.set('type', 'revolute')
        limit = joint.find('limit')
        if limit is None:
            limit = ET.SubElement(joint, 'limit', {'effort': '0', 'velocity': '0'})
        limit.set('lower', '-1e9')
        limit.set('upper', '1e9')
        changed = True
    return ET.tostring(robot, encoding='unicode') if changed else text


class SpatialTerms(NamedTuple):
    """
    Model terms of one state (core joint order, task rows of ``m``).

    Attributes
    ----------
    M, Minv : numpy.ndarray, (n, n)
        Inertia matrix [kg m^2] and its inverse.
    h : numpy.ndarray, (n,)
        ``C qd + G`` [N m].
    J : numpy.ndarray, (m, n)
        Task Jacobian [m/rad; rad/rad].
    jdqd : numpy.ndarray, (m,)
        ``Jdot qd`` [m/s^2; rad/s^2].
    p : numpy.ndarray, (3,)
        Tip position [m].
    R : numpy.ndarray, (3, 3)
        Tip orientation (root frame).

    """

    M: np.ndarray
    Minv: np.ndarray
    h: np.ndarray
    J: np.ndarray
    jdqd: np.ndarray
    p: np.ndarray
    R: np.ndarray


class SpatialArm:
    """
    A serial arm ``base_link -> tip_link`` of a URDF, with free (passive) joints.

    Parameters
    ----------
    urdf : str
        URDF text, or a path to a ``.urdf`` file.
    base_link, tip_link : str
        Links bounding the chain (the base fixed in the world).
    passive : sequence of str
        Names of the free joints (in the chain).
    m : {3, 6}
        Task dimension: tip position, or position and orientation.
    scale : float
        Nominal factor on masses, inertias and COM levers, > 0 (1: the URDF's).
    gravity : sequence of float, (3,)
        Gravity in the root frame [m/s^2].

    Attributes
    ----------
    n, r, m : int
        Chain joints, active joints, task rows.
    joint_names : tuple of str
        Chain joints from the base (the core order).
    active, passive : tuple of int
        Indices of the active and free joints.
    effort, velocity, lower, upper : numpy.ndarray, (n,)
        URDF limits [N m, rad/s, rad, rad] (a continuous joint: -inf, +inf).
    continuous : tuple of str
        The chain's continuous joints (no position limits).

    """

    def __init__(self, urdf, base_link, tip_link, passive=(), m=3, scale=1.0,
                 gravity=GRAVITY):
        if not isinstance(urdf, str):
            raise FreejointValueError(f'urdf: expected URDF text or a path, got {urdf!r}')
        if m not in TASK_DIMS:
            raise FreejointValueError(f'm: expected one of {TASK_DIMS}, got {m!r}')
        scale = float(scale)
        if not (math.isfinite(scale) and scale > 0.0):
            raise FreejointValueError(f'scale: must be finite and > 0, got {scale!r}')
        text = urdf
        if '<robot' not in urdf:
            try:
                with open(urdf, encoding='utf-8') as fh:
                    text = fh.read()
            except OSError as exc:
                raise FreejointValueError(f'urdf: cannot read {urdf!r} ({exc})') from None
        try:
            full = pin.buildModelFromXML(angle_coordinates(text))
        except (RuntimeError, ValueError) as exc:
            raise FreejointValueError(f'urdf: Pinocchio cannot read it ({exc})') from None
        for name, link in (('base_link', base_link), ('tip_link', tip_link)):
            if not full.existFrame(link):
                raise FreejointValueError(f'{name}: the URDF has no link {link!r}')
        tip_joint = full.frames[full.getFrameId(tip_link)].parentJoint
        base_joint = full.frames[full.getFrameId(base_link)].parentJoint
        above_base = set(full.supports[base_joint])
        chain = [j for j in full.supports[tip_joint] if j != 0 and j not in above_base]
        if not chain:
            raise FreejointValueError(f'tip_link: no joint between {base_link!r} and '
                                      f'{tip_link!r}')
        if base_joint not in full.supports[tip_joint]:
            raise FreejointValueError(f'base_link: {base_link!r} is not on the path to '
                                      f'{tip_link!r}')
        for j in chain:
            if full.joints[j].nq != 1 or full.joints[j].nv != 1:
                raise FreejointValueError(
                    f'urdf: joint {full.names[j]!r} has {full.joints[j].nq} configuration '
                    'entries; the chain needs one-degree-of-freedom joints')
        locked = [j for j in range(1, full.njoints) if j not in chain]
        q_ref = np.clip(np.zeros(full.nq), full.lowerPositionLimit, full.upperPositionLimit)
        model = pin.buildReducedModel(full, locked, q_ref) if locked else full
        if scale != 1.0:
            for j in range(1, model.njoints):
                inert = model.inertias[j]
                model.inertias[j] = pin.Inertia(scale * inert.mass, scale * inert.lever,
                                                scale * inert.inertia)
        grav = np.array(gravity, dtype=float)
        if grav.shape != (3,) or not np.all(np.isfinite(grav)):
            raise FreejointValueError(f'gravity: expected 3 finite numbers, got {gravity!r}')
        model.gravity.linear = grav
        self.model = model
        self.data = model.createData()
        self.frame = model.getFrameId(tip_link)
        self.n = model.nv
        self.m = m
        self.scale = scale
        self.gravity = grav
        self.base_link, self.tip_link, self.urdf = base_link, tip_link, text
        self.joint_names = tuple(model.names[1:])
        passive = tuple(passive)
        for name in passive:
            if name not in self.joint_names:
                raise FreejointValueError(
                    f'passive: {name!r} is not a joint of the chain {self.joint_names}')
        self.passive = tuple(sorted(self.joint_names.index(p) for p in passive))
        self.active = tuple(i for i in range(self.n) if i not in self.passive)
        self.r = len(self.active)
        if self.r < m:
            raise FreejointValueError(f'passive: {self.r} active joints cannot drive m = {m} '
                                      'task rows')
        self.effort = np.array(model.effortLimit, dtype=float)
        self.velocity = np.array(model.velocityLimit, dtype=float)
        self.continuous = tuple(sorted(set(self.joint_names) & continuous_joints(text)))
        self.lower = np.array(model.lowerPositionLimit, dtype=float)
        self.upper = np.array(model.upperPositionLimit, dtype=float)
        for name in self.continuous:
            j = self.joint_names.index(name)
            self.lower[j], self.upper[j] = -np.inf, np.inf
        self._zero = np.zeros(self.n)
        self._ia = np.array(self.active, dtype=int)
        self._ip = np.array(self.passive, dtype=int)
        self._iaa = np.ix_(self._ia, self._ia)

    @property
    def task_dim(self):
        """Return the task rows m (the name the control loop reads)."""
        return self.m

    def nominal(self, scale):
        """Return the same arm with masses, inertias and COM levers times ``scale``."""
        return SpatialArm(self.urdf, self.base_link, self.tip_link,
                          [self.joint_names[i] for i in self.passive], self.m, scale,
                          self.gravity)

    def _state(self, q, qd=None):
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,) or not np.isfinite(q).all():
            raise FreejointValueError(f'q: expected {self.n} finite numbers, got {q!r}')
        if qd is None:
            return q
        qd = np.asarray(qd, dtype=float)
        if qd.shape != (self.n,) or not np.isfinite(qd).all():
            raise FreejointValueError(f'qd: expected {self.n} finite numbers, got {qd!r}')
        return q, qd

    # -- kinematics ---------------------------------------------------------
    def placement(self, q):
        """
        Tip frame placement.

        Parameters
        ----------
        q : array_like, (n,)
            Joint angles [rad].

        Returns
        -------
        (numpy.ndarray (3,), numpy.ndarray (3, 3))
            Position [m] and rotation (root frame).

        """
        q = self._state(q)
        pin.framesForwardKinematics(self.model, self.data, q)
        pl = self.data.oMf[self.frame]
        return np.array(pl.translation), np.array(pl.rotation)

    def fk(self, q):
        """Tip position [m], (3,), of joint angles ``q`` (n,) [rad]."""
        return self.placement(q)[0]

    def jacobian(self, q):
        """Task Jacobian (m, n) of ``q`` (n,) [rad]: linear rows, then angular (m = 6)."""
        q = self._state(q)
        jac = pin.computeFrameJacobian(self.model, self.data, q, self.frame, _LWA)
        return np.array(jac[:self.m])

    # -- dynamics -----------------------------------------------------------
    def terms(self, q, qd):
        """
        All model terms of one state, one Pinocchio pass (see :class:`SpatialTerms`).

        Parameters
        ----------
        q, qd : array_like, (n,)
            Joint angles [rad] and rates [rad/s].

        Returns
        -------
        SpatialTerms

        """
        q, qd = self._state(q, qd)
        mod, dat = self.model, self.data
        mass = np.array(pin.crba(mod, dat, q))
        minv = np.array(pin.computeMinverse(mod, dat, q))
        h = np.array(pin.nonLinearEffects(mod, dat, q, qd))
        pin.computeJointJacobians(mod, dat, q)
        pin.forwardKinematics(mod, dat, q, qd, self._zero)
        pin.updateFramePlacement(mod, dat, self.frame)
        jac = np.array(pin.getFrameJacobian(mod, dat, self.frame, _LWA)[:self.m])
        acc = pin.getFrameClassicalAcceleration(mod, dat, self.frame, _LWA).vector
        pl = dat.oMf[self.frame]
        return SpatialTerms(mass, minv, h, jac, np.array(acc[:self.m]),
                            np.array(pl.translation), np.array(pl.rotation))

    def decoupling(self, terms):
        """
        ``Da``, ``b`` and ``M~aa`` of one state (module notes).

        Parameters
        ----------
        terms : SpatialTerms
            From :meth:`terms`.

        Returns
        -------
        da : numpy.ndarray, (m, r)
        b : numpy.ndarray, (m,)
        maa : numpy.ndarray, (r, r)
            Effective inertia of the active joints [kg m^2].

        """
        w = terms.J @ terms.Minv
        da = w[:, self._ia]
        b = terms.jdqd - w @ terms.h
        maa = np.linalg.inv(terms.Minv[self._iaa])
        return da, b, 0.5 * (maa + maa.T)

    def gravity_torque(self, q):
        """Generalized gravity ``G(q)`` (n,) [N m]."""
        q = self._state(q)
        return np.array(pin.computeGeneralizedGravity(self.model, self.data, q))

    def forward_dynamics(self, q, qd, tau):
        """
        Joint accelerations (ABA) under joint torques ``tau`` (n,) [N m].

        Parameters
        ----------
        q, qd, tau : numpy.ndarray, (n,)
            Angles [rad], rates [rad/s], torques [N m] (free joints: their disturbance).

        Returns
        -------
        numpy.ndarray, (n,)
            [rad/s^2].

        """
        return np.array(pin.aba(self.model, self.data, q, qd, tau))


def known_arm(name, passive=(), m=3, scale=1.0):
    """
    One of :data:`KNOWN_ARMS` from example-robot-data.

    Parameters
    ----------
    name : {'ur5', 'panda'}
        The arm.
    passive : sequence of str
        Free joint names.
    m : {3, 6}
        Task rows.
    scale : float
        Nominal factor on masses, inertias and COM levers.

    Returns
    -------
    SpatialArm

    """
    if name not in KNOWN_ARMS:
        raise FreejointValueError(f'name: expected one of {sorted(KNOWN_ARMS)}, got {name!r}')
    path, base, tip = KNOWN_ARMS[name]
    return SpatialArm(os.path.join(robot_data_dir(), path), base, tip, passive, m, scale)
