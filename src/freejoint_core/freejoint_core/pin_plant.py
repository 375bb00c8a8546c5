"""
The RK4 plant of a URDF arm with Pinocchio's forward dynamics (ABA).

``PinPlant`` is ``freejoint_core.plant.Plant`` for any planar arm read from URDF: the
same forcing (torque and one disturbance draw held per control period, the same
``numpy.random.default_rng(seed)`` draws), the same classic RK4 at ``dt_sub``, with
``qdd = aba(q, qd, tau)`` from :class:`freejoint_core.pin_model.PinArmModel` instead
of the core's numpy ``ArmModel.forward_dynamics``.  For arms without the scalar
3-link kernel (n != 3) it is the fast RK4 engine: the general numpy path costs
milliseconds per period (``bench/core_urdf.py``).
"""

import math

from freejoint_core.arm import check_vector
from freejoint_core.errors import FreejointValueError, PlantDivergedError
from freejoint_core.pin_model import PinArmModel
from freejoint_core.plant import DEFAULT_DT_SUB
from freejoint_core.urdf import UrdfArm
import numpy as np
import pinocchio


def _positive(value, name, allow_zero=False):
    try:
        value = float(value)
    except (TypeError, ValueError) as exc:
        raise FreejointValueError(f'{name}: expected a number, got {value!r}') from exc
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        bound = '>= 0' if allow_zero else '> 0'
        raise FreejointValueError(f'{name}: must be finite and {bound}, got {value}')
    return value


class PinPlant:
    """
    The URDF arm integrated by RK4 on Pinocchio's ABA, with bounded random disturbances.

    Parameters
    ----------
    arm : UrdfArm
        The real arm (URDF, passive joints, gravity vector).
    dt_sub : float
        RK4 step [s], > 0.
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
    model : PinArmModel
        The Pinocchio model it integrates.
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
        if not isinstance(arm, UrdfArm):
            raise FreejointValueError(f'arm: expected UrdfArm, got {type(arm).__name__}')
        self.arm = arm
        self.params = arm.params
        self.model = PinArmModel(arm)
        self.n = arm.params.n
        self.r = arm.params.r
        self.dt_sub = _positive(dt_sub, 'dt_sub')
        self.dist_bound = _positive(dist_bound, 'dist_bound', allow_zero=True)
        self._check_seed(seed)
        self._seed0 = seed
        self._q0 = self._state(q0, 'q0')
        self._qd0 = self._state(qd0, 'qd0')
        self._active = list(arm.params.active)
        self._dt_cache = (None, 0)
        if self.model._identity:    # revolute joints in core order: ABA straight on q, qd
            pin_model, pin_data = self.model.pin_model, self.model.pin_data

            def qdd(q, qd, tau):
                return pinocchio.aba(pin_model, pin_data, q, qd, tau).copy()
            self._qdd = qdd
        else:
            self._qdd = self.model.forward_dynamics
        self.reset()

    @staticmethod
    def _check_seed(seed):
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                                 or seed < 0):
            raise FreejointValueError(f'seed: expected a non-negative int or None, got {seed!r}')

    def _state(self, x, name):
        if x is None:
            return np.zeros(self.n)
        return check_vector(x, self.n, name).copy()

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
        self._q = self._q0.copy()
        self._qd = self._qd0.copy()
        self._rng = np.random.default_rng(self._seed0)
        self.t = 0.0
        self.k = 0
        self.last_disturbance = (0.0,) * self.n

    @property
    def q(self):
        """Return the joint angles [rad], numpy copy (n,)."""
        return self._q.copy()

    @property
    def qd(self):
        """Return the joint velocities [rad/s], numpy copy (n,)."""
        return self._qd.copy()

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
            If the integration produced a non-finite state; the plant keeps its last
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
        f = self._qdd
        h = self.dt_sub
        q, w = self._q, self._qd
        try:
            with np.errstate(all='ignore'):
                for _ in range(n_sub):
                    a = f(q, w, full)
                    u = w + 0.5 * h * a
                    b = f(q + 0.5 * h * w, u, full)
                    v = w + 0.5 * h * b
                    c = f(q + 0.5 * h * u, v, full)
                    x = w + h * c
                    d = f(q + h * v, x, full)
                    q = q + (h / 6.0) * (w + 2.0 * (u + v) + x)
                    w = w + (h / 6.0) * (a + 2.0 * (b + c) + d)
            finite = math.isfinite(float(q.sum() + w.sum()))
        except (ArithmeticError, ValueError, RuntimeError, FreejointValueError):
            finite = False
        if not finite:
            raise PlantDivergedError(
                f'tau_active: the integration over step {self.k} diverged (non-finite state '
                f'from q = {self._q.tolist()}, qd = {self._qd.tolist()}); the state is left '
                f'as it was')
        self._q, self._qd = q, w
        self.t += dt
        self.k += 1
