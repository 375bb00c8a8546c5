"""
Simulated arm (the "real" plant): eq. (1) integrated with fixed-step RK4.

Over one control period ``dt`` the actuator torque and one disturbance draw
are held constant (zero-order hold), and eq. (1)
``M qdd + C qd + G = B tau_a + d`` is integrated with classic fixed-step RK4
at ``dt_sub`` (``dt`` must be an integer multiple).  Because the forcing is
constant inside the period, the right-hand side is smooth there and RK4 keeps
its fourth order.

Disturbance: ``rng = numpy.random.default_rng(seed)``; every ``step`` draws
``rng.uniform(-dist_bound, dist_bound, n)`` once (passive joints included),
so ``|d_i| <= dist_bound`` (Section 4: 0.5 N m).  ``dist_bound = 0`` disables
it and no draw is made.

Step size: ``DEFAULT_DT_SUB`` = 0.5 ms, two RK4 sub-steps per 1 ms period
(``bench/core_law_plant.py`` compares it with a 10x finer step; the figures are in
docs/performance.md).
"""

import math

from freejoint_core.arm import ArmModel, ArmParams, check_vector
from freejoint_core.errors import FreejointValueError, PlantDivergedError, positive
from freejoint_core.models import make_model
import numpy as np

DEFAULT_DT_SUB = 0.0005
"""Default RK4 sub-step [s]."""
DEFAULT_DIST_BOUND = 0.5
"""Bound [N m] of the paper's uniform random joint disturbance."""


def check_torques(tau_active, r, name='tau_active'):
    """
    Return the active joint torques as a list of ``r`` finite numbers, or raise.

    Parameters
    ----------
    tau_active : array_like, (r,)
        Actuator torques on the active joints [N m].
    r : int
        Number of active joints.
    name : str
        Argument name used in the error message.

    Returns
    -------
    list of float or list of int, (r,)
        The values (``tolist`` of an array, else the sequence itself).

    """
    tau = tau_active.tolist() if isinstance(tau_active, np.ndarray) else tau_active
    try:
        ok = len(tau) == r and all(math.isfinite(v) for v in tau)
    except TypeError:
        ok = False
    if not ok:
        shape = np.shape(tau_active) if not isinstance(tau_active, (str, bytes)) else '?'
        raise FreejointValueError(
            f'{name}: expected {r} finite values (shape ({r},)), '
            f'got {tau_active!r} with shape {shape}')
    return tau


class PeriodPlant:
    """
    What every plant does per control period, whatever integrates eq. (1).

    The torque and one seeded disturbance draw are held over the period (see the
    module docstring), ``dt`` is split into ``dt / dt_sub`` sub-steps, the arguments
    are validated and a diverged step leaves the state as it was.  A subclass calls
    ``_setup`` then ``reset`` in its constructor and supplies the engine:
    ``_set_state(q0, qd0)`` (lists, (n,)), the ``q`` / ``qd`` properties and
    ``_advance(n_sub, force)``, which integrates ``n_sub`` sub-steps under the held
    generalised force (list, (n,)) and returns None, or, after putting the state back
    as it was, a short reason why the step diverged.

    Attributes
    ----------
    params : ArmParams
        Real physical parameters.
    model : ArmModel
        A model of ``params`` (the one integrated, or one for fk and the like).
    q, qd : numpy.ndarray, (n,)
        Copies of the current joint angles [rad] and velocities [rad/s].
    t : float
        Simulated time [s] (sum of the ``dt`` passed to ``step``).
    k : int
        Number of ``step`` calls since construction/reset.
    last_disturbance : tuple of float
        The disturbance [N m] held over the last step (zeros if disabled).
    last_effort : tuple of float, (n,)
        Actuator torque [N m] each joint received over the last step (0 on passive and
        failed joints; zeros before the first step).
    failed : tuple of int
        Joints whose failure has taken effect (see ``fail_joint``).

    """

    def _setup(self, params, model, dt_sub, dist_bound, seed, q0, qd0):
        """Validate and store what ``reset`` and ``step`` use (not the engine)."""
        self.params = params
        self.model = model
        self.n = params.n
        self.r = params.r
        self.dt_sub = positive('dt_sub', dt_sub)
        self.dist_bound = positive('dist_bound', dist_bound, allow_zero=True)
        self._check_seed(seed)
        self._seed0 = seed
        self._q0 = self._state(q0, 'q0')
        self._qd0 = self._state(qd0, 'qd0')
        self._active = params.active
        self._dt_cache = (None, 0)
        self._fail_at = {}

    @staticmethod
    def _check_seed(seed):
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                                 or seed < 0):
            raise FreejointValueError(f'seed: expected a non-negative int or None, got {seed!r}')

    def _state(self, x, name):
        if x is None:
            return [0.0] * self.n
        return check_vector(x, self.n, name).tolist()

    def reset(self, q0=None, qd0=None, seed=None):
        """
        Restart at t = 0, k = 0 with a freshly seeded disturbance generator.

        Parameters
        ----------
        q0, qd0 : array_like, (n,), optional
            New initial state; None keeps the one given at construction
            (or the last reset).
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
        self._set_state(self._q0, self._qd0)
        self._rng = np.random.default_rng(self._seed0)
        self.t = 0.0
        self.k = 0
        self.last_disturbance = (0.0,) * self.n
        self.last_effort = (0.0,) * self.n
        self._fail_at = {}

    def fail_joint(self, joint, at_s=None):
        """
        Make a joint's actuator and brake fail (from now or from a later time).

        Parameters
        ----------
        joint : int
            Joint index (0-based), in ``[0, n)``.  A passive joint has nothing to lose and
            is accepted (no effect).
        at_s : float, optional
            Simulated time [s] from which the joint gets no torque: the first period that
            starts at ``t >= at_s - 1e-9`` (tick-aligned); default now (``self.t``).  An
            earlier failure of the same joint is kept.  ``reset`` clears every failure.

        Raises
        ------
        FreejointValueError
            Naming ``joint`` or ``at_s`` if they are bad.

        """
        if isinstance(joint, bool) or not isinstance(joint, (int, np.integer)) \
                or not 0 <= joint < self.n:
            raise FreejointValueError(f'joint: expected an int in [0, {self.n}), got {joint!r}')
        at = self.t if at_s is None else float(at_s) if isinstance(
            at_s, (int, float, np.integer, np.floating)) and not isinstance(at_s, bool) \
            else math.nan
        if not math.isfinite(at) or at < 0.0:
            raise FreejointValueError(f'at_s: expected a finite time >= 0 s, got {at_s!r}')
        joint = int(joint)
        self._fail_at[joint] = min(at, self._fail_at.get(joint, math.inf))

    @property
    def failed(self):
        """Return the sorted tuple of joints whose failure has taken effect (t >= at_s)."""
        return tuple(sorted(j for j, at in self._fail_at.items() if self.t >= at - 1e-9))

    @property
    def failures(self):
        """Return ``{joint: at_s}`` of every scheduled or effective failure (a copy)."""
        return dict(self._fail_at)

    def _substeps(self, dt):
        if dt == self._dt_cache[0]:
            return self._dt_cache[1]
        dt_f = positive('dt', dt)
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
            If the integration produced a non-finite state (torques far beyond what
            ``dt_sub`` resolves) or the engine flagged it; the plant keeps its last
            finite state, the disturbance draw of the step is spent.

        """
        n_sub = self._substeps(dt)
        tau = check_torques(tau_active, self.r)
        if self.dist_bound > 0.0:
            full = self._rng.uniform(-self.dist_bound, self.dist_bound, self.n).tolist()
            self.last_disturbance = tuple(full)
        else:
            full = [0.0] * self.n
        effort = [0.0] * self.n
        if self._fail_at:
            dead = self.failed
            for j, v in zip(self._active, tau):
                if j not in dead:
                    effort[j] = float(v)
                    full[j] += float(v)
        else:
            for j, v in zip(self._active, tau):
                effort[j] = float(v)
                full[j] += float(v)
        why = self._advance(n_sub, full)
        if why is not None:
            raise PlantDivergedError(
                f'tau_active: the integration over step {self.k} diverged ({why}) from '
                f'q = {self.q.tolist()}, qd = {self.qd.tolist()}; the state is left as it was')
        self.last_effort = tuple(effort)
        self.t += dt
        self.k += 1


class Plant(PeriodPlant):
    """
    The simulated manipulator with bounded random joint disturbances.

    Parameters
    ----------
    params : ArmParams
        Real physical parameters.
    dt_sub : float
        RK4 step [s], > 0.
    dist_bound : float
        Disturbance bound [N m], >= 0 (0 disables the disturbance).
    seed : int or None
        Seed of ``numpy.random.default_rng``.
    q0, qd0 : array_like, (n,), optional
        Initial joint angles [rad] and velocities [rad/s]; zeros if None.
    use_fast : bool
        Integrate with the scalar 3-link kernel when n == 3 (default); False
        forces the general numpy model (the slower reference).

    Attributes
    ----------
    q, qd, t, k, last_disturbance
        As :class:`PeriodPlant`.

    """

    def __init__(self, params, dt_sub=DEFAULT_DT_SUB, dist_bound=DEFAULT_DIST_BOUND, seed=0,
                 q0=None, qd0=None, use_fast=True):
        if not isinstance(params, ArmParams):
            raise FreejointValueError(f'params: expected ArmParams, got {type(params).__name__}')
        model = make_model(params) if use_fast else ArmModel(params)
        self._setup(params, model, dt_sub, dist_bound, seed, q0, qd0)
        self._fast = hasattr(self.model, 'qdd')
        self._qdd = self.model.forward_dynamics
        self.reset()

    def _set_state(self, q0, qd0):
        self._q = list(q0)
        self._qd = list(qd0)

    def stop(self):
        """Zero every joint velocity: the arm stops where it is (brakes engaged)."""
        self._qd = [0.0] * self.n

    @property
    def q(self):
        """Return the joint angles [rad], numpy copy (n,)."""
        return np.array(self._q)

    @property
    def qd(self):
        """Return the joint velocities [rad/s], numpy copy (n,)."""
        return np.array(self._qd)

    def _advance(self, n_sub, force):
        q_before, qd_before = self._q, self._qd
        try:
            if self._fast:
                self._rk4_fast3(n_sub, force)
            else:
                with np.errstate(all='ignore'):
                    self._rk4_general(n_sub, np.array(force))
            finite = all(map(math.isfinite, self._q + self._qd))
        except (ArithmeticError, ValueError, RuntimeError):  # e.g. math.cos(inf)
            finite = False
        if finite:
            return None
        self._q, self._qd = q_before, qd_before
        return 'non-finite state'

    def _rk4_fast3(self, n_sub, tau):
        qdd = self.model.qdd
        h = self.dt_sub
        h2 = 0.5 * h
        h6 = h / 6.0
        t0, t1, t2 = tau
        q0, q1, q2 = self._q
        w0, w1, w2 = self._qd
        for _ in range(n_sub):
            a0, a1, a2 = qdd(q0, q1, q2, w0, w1, w2, t0, t1, t2)
            u0 = w0 + h2 * a0
            u1 = w1 + h2 * a1
            u2 = w2 + h2 * a2
            b0, b1, b2 = qdd(q0 + h2 * w0, q1 + h2 * w1, q2 + h2 * w2, u0, u1, u2, t0, t1, t2)
            v0 = w0 + h2 * b0
            v1 = w1 + h2 * b1
            v2 = w2 + h2 * b2
            c0, c1, c2 = qdd(q0 + h2 * u0, q1 + h2 * u1, q2 + h2 * u2, v0, v1, v2, t0, t1, t2)
            x0 = w0 + h * c0
            x1 = w1 + h * c1
            x2 = w2 + h * c2
            d0, d1, d2 = qdd(q0 + h * v0, q1 + h * v1, q2 + h * v2, x0, x1, x2, t0, t1, t2)
            q0 += h6 * (w0 + 2.0 * (u0 + v0) + x0)
            q1 += h6 * (w1 + 2.0 * (u1 + v1) + x1)
            q2 += h6 * (w2 + 2.0 * (u2 + v2) + x2)
            w0 += h6 * (a0 + 2.0 * (b0 + c0) + d0)
            w1 += h6 * (a1 + 2.0 * (b1 + c1) + d1)
            w2 += h6 * (a2 + 2.0 * (b2 + c2) + d2)
        self._q = [q0, q1, q2]
        self._qd = [w0, w1, w2]

    def _rk4_general(self, n_sub, tau):
        f = self._qdd
        h = self.dt_sub
        q = np.array(self._q)
        w = np.array(self._qd)
        for _ in range(n_sub):
            a = f(q, w, tau)
            u = w + 0.5 * h * a
            b = f(q + 0.5 * h * w, u, tau)
            v = w + 0.5 * h * b
            c = f(q + 0.5 * h * u, v, tau)
            x = w + h * c
            d = f(q + h * v, x, tau)
            q = q + (h / 6.0) * (w + 2.0 * (u + v) + x)
            w = w + (h / 6.0) * (a + 2.0 * (b + c) + d)
        self._q = q.tolist()
        self._qd = w.tolist()
