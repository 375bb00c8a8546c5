"""
Internal-motion stabilisation: what the paper's law leaves to itself.

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

from freejoint_core.arm import ArmModel, check_vector, number_or_numbers
from freejoint_core.errors import FreejointValueError
import numpy as np

INVERSES = ('pseudo', 'weighted')
DEFAULT_Q3_0_DEG = 120.0
"""The paper's initial passive joint angle [deg] (the offline runner's start)."""
PROJECTORS = ('kinematic', 'dynamic')


def _gain(value, name):
    """Return a finite gain >= 0 from a number or a sequence (as a tuple of floats)."""
    vals, scalar = number_or_numbers(value, name, 'a number or a sequence of numbers')
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
    Return a configuration with the end effector at ``p`` where the free joints hang at rest.

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
    Return the 3-link arm (joint 3 free) at ``p`` with its free link hanging straight down.

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


MODES = ('always', 'rest', 'settle')
SETTLE_AFTER_TRAVEL = 0.01
"""[m] Path the reference must have travelled (since the last reset) before a rest is
settled in ``settle`` mode: a task's motion, not a hold's resume blend (measured in real
time: a blend of under a millimetre before the first circle let the settle drive for
0.6 s and start that circle 1.2-1.8 mm off its path)."""
SETTLE_RETURN_GAINS = (400.0, 40.0)
"""``(k3, k4)`` [1/s^2, 1/s] of the ``settle`` mode's return once its window is over:
critically damped at 20 rad/s, a 3-cm shift is back under 0.1 mm 0.4 s later."""


def _floats(x, n, name):
    """Return ``x`` as ``n`` finite Python floats (a list), or raise as ``check_vector``."""
    try:
        out = [float(v) for v in x]
    except (TypeError, ValueError):
        out = None
    if out is None or len(out) != n or not math.isfinite(math.fsum(out)):
        # not a plain finite sequence: check_vector raises naming what is wrong (or, for a
        # sum that overflowed alone, returns the same floats)
        return check_vector(x, n, name).tolist()
    return out


class FreeLinkModulation:
    """
    Damping of the free link's zero dynamics by a bounded modulation of the task reference.

    For the arm whose last joint is free (r = m = 2, the paper's), with the end
    effector at the free link's tip the link obeys (docs/internal-motion.md's
    derivation)::

        J_eff thdd3 = -m3 c3 u3perp(th3) . (pdd_E + g y) + d3,
        J_eff = I3 + m3 c3 (c3 - L3),  u3perp = (-sin th3, cos th3)

    so an end-effector acceleration along ``u3perp`` proportional to the link's rate
    damps it.  The setpoint the paper's law tracks is shifted by ``delta`` (2,)::

        w      = k1 sin(th3 - th_qs) + k2 (thd3 - thd_qs)
        dd     = sigma(t) sat(u3perp w, a_max) - k3 delta - k4 d_delta
        th_qs  = atan2(-(pdd_d,y + g), -pdd_d,x)

    (``th_qs``: the angle the link would keep under the planned acceleration;
    ``thd_qs`` its finite-difference rate; ``sigma`` 1 always or only while the
    setpoint rests).  ``delta`` is the output of a critically (or over-) damped filter
    (``k4^2 >= 4 k3``: non-negative impulse response of gain ``1/k3``) driven by an
    input of norm ``<= sat``, so ``|delta| <= sat / k3`` from rest.  ``delta_max``
    bounds it harder: a step that would leave the disc ``|delta| <= delta_max`` is
    projected back onto it (and the outward part of ``d_delta`` dropped), so the
    task deviation the modulation adds never exceeds ``delta_max``.  (Scaling the
    drive down to ``k3 delta_max`` instead would also bound it, but the link swings at
    ~8 rad/s, where a millimetre offset already means ~0.1 m/s^2: that wastes the
    bound on the filter's DC gain and left a 21-degree swing undamped.)

    Parameters
    ----------
    params : freejoint_core.arm.ArmParams
        The nominal arm (last joint free: ``passive == (n - 1,)``).
    gains : tuple of float, (4,)
        ``(k1, k2, k3, k4)`` [m/s^2, m/s, 1/s^2, 1/s]; k1, k2 >= 0, k3, k4 > 0,
        ``k4^2 >= 4 k3``.
    sat : float
        Saturation of the drive [m/s^2], > 0.
    delta_max : float or None
        Bound of ``|delta|`` [m], > 0; None: none but ``sat / k3``.
    mode : {'always', 'rest', 'settle'}
        ``sigma = 1`` always, or only while the setpoint's velocity and acceleration are
        0, or (``settle``: the horizontal arm, whose free link is a free rotor that only a
        centimetre-scale motion of the end effector can slow) only during the first
        ``settle_window`` s of each rest of the setpoint that follows a task (a reference
        that travelled more than :data:`SETTLE_AFTER_TRAVEL` since the last :meth:`reset`:
        a rest before any task, e.g. a held start point that the control loop's resume
        blend moved by a fraction of a millimetre, has nothing to settle and would only
        start that task off its path), after which the drive is off and
        the filter's gains are :data:`SETTLE_RETURN_GAINS` (the shift goes back to 0
        before the next task; a rest shorter than the window plus ~0.4 s starts the task
        with the shift left; a longer rest has the shift back at 0 whenever the next task
        starts: driving later in it would start that task up to ``delta_max`` off, and
        measured it slowed the rotor little). In ``settle`` mode ``sat`` is ``k3 delta_max`` when
        ``delta_max`` is given: the filter alone keeps ``|delta| <= delta_max`` and the
        bound never clips (clipping the shift at a centimetre bound while the drive pushed
        made the reference inconsistent and lost the horizontal arm, measured).
    k2_rest : float or None
        The rate gain ``k2`` while the setpoint rests [m/s], >= 0 (the disturbance's
        swing floor falls with it); None: ``k2``.
    rest_after : float
        ``k2_rest`` applies once the setpoint has rested this long [s], >= 0 (a settle
        step after a task: rests between tasks shorter than it keep ``k2``).
    settle_window : float
        ``settle`` mode: seconds of each rest during which the drive acts, > 0.

    """

    def __init__(self, params, gains=(0.0, 0.2, 9.0, 6.0), sat=4.0, delta_max=None,
                 mode='always', k2_rest=None, rest_after=0.0, settle_window=0.6):
        if params.passive != (params.n - 1,):
            raise FreejointValueError(
                f'params: the modulation needs the last joint free, got passive {params.passive}')
        try:
            k1, k2, k3, k4 = (float(v) for v in gains)
        except (TypeError, ValueError) as exc:
            raise FreejointValueError(f'gains: expected 4 numbers, got {gains!r}') from exc
        if not (all(map(math.isfinite, (k1, k2, k3, k4))) and k1 >= 0.0 and k2 >= 0.0
                and k3 > 0.0 and k4 > 0.0 and k4 * k4 >= 4.0 * k3 * (1.0 - 1e-12)):
            raise FreejointValueError(
                f'gains: need k1, k2 >= 0, k3, k4 > 0 and k4^2 >= 4 k3, got {gains!r}')
        if mode not in MODES:
            raise FreejointValueError(f'mode: expected one of {MODES}, got {mode!r}')
        sat = float(sat)
        if not (math.isfinite(sat) and sat > 0.0):
            raise FreejointValueError(f'sat: must be finite and > 0, got {sat}')
        if mode == 'settle' and delta_max is not None:
            sat = k3 * float(delta_max)     # the filter's own bound: no clipping
        settle_window = float(settle_window)
        if not (math.isfinite(settle_window) and settle_window > 0.0):
            raise FreejointValueError(
                f'settle_window: must be finite and > 0 s, got {settle_window}')
        self.settle_window = settle_window
        if delta_max is not None:
            delta_max = float(delta_max)
            if not (math.isfinite(delta_max) and delta_max > 0.0):
                raise FreejointValueError(f'delta_max: must be finite and > 0, got {delta_max}')
            delta_max = min(delta_max, sat / k3)
        else:
            delta_max = sat / k3
        k2_rest = k2 if k2_rest is None else float(k2_rest)
        if not (math.isfinite(k2_rest) and k2_rest >= 0.0):
            raise FreejointValueError(f'k2_rest: must be finite and >= 0, got {k2_rest}')
        self.k2_rest = k2_rest
        rest_after = float(rest_after)
        if not (math.isfinite(rest_after) and rest_after >= 0.0):
            raise FreejointValueError(f'rest_after: must be finite and >= 0, got {rest_after}')
        self.rest_after = rest_after
        self.params = params
        self.gains = (k1, k2, k3, k4)
        self.a_max = sat
        self.delta_max = delta_max
        self.mode = mode
        self._g = params.gravity
        self.reset()

    def reset(self):
        """Zero ``delta`` and its rate; forget the last quasi-static angle, the rest, a task."""
        self._delta = (0.0, 0.0)
        self._delta_dot = (0.0, 0.0)
        self._th_qs = None
        self._rested = 0.0
        self._travel = 0.0

    def quasi_static_angle(self, pdd_d):
        """
        Free link angle ``atan2(-(pdd_y + g), -pdd_x)`` [rad] under the acceleration.

        Parameters
        ----------
        pdd_d : array_like, (2,)
            Planned end-effector acceleration [m/s^2].

        Returns
        -------
        float or None
            None when ``pdd_d + g y`` vanishes (horizontal arm at rest).

        """
        ax, ay = float(pdd_d[0]), float(pdd_d[1]) + self._g
        if ax * ax + ay * ay < 1e-18:
            return None
        return math.atan2(-ay, -ax)

    def step(self, q, qd, p_d, pd_d, pdd_d, dt):
        """
        Modulate one setpoint and advance ``delta`` over ``dt``.

        Parameters
        ----------
        q, qd : array_like, (n,)
            Measured joint angles [rad] and rates [rad/s].
        p_d, pd_d, pdd_d : array_like, (2,)
            The planned setpoint [m, m/s, m/s^2].
        dt : float
            Control period [s], > 0.

        Returns
        -------
        tuple of numpy.ndarray, (2,) each
            ``(p_d + delta, pd_d + d_delta, pdd_d + dd_delta)`` for this tick.

        """
        n = self.params.n
        q = _floats(q, n, 'q')
        qd = _floats(qd, n, 'qd')
        px, py = _floats(p_d, 2, 'p_d')
        vx, vy = _floats(pd_d, 2, 'pd_d')
        ax, ay = _floats(pdd_d, 2, 'pdd_d')
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise FreejointValueError(f'dt: must be finite and > 0, got {dt}')
        k1, k2, k3, k4 = self.gains
        th = math.fsum(q)
        thd = math.fsum(qd)
        th_qs = self.quasi_static_angle((ax, ay))
        resting = not (vx or vy or ax or ay)
        settle = self.mode == 'settle'
        drive = self.mode == 'always' or resting
        if settle:
            drive = (resting and self._travel > SETTLE_AFTER_TRAVEL
                     and self._rested < self.settle_window)
            if not drive:
                k3, k4 = SETTLE_RETURN_GAINS
        if resting:
            if self._rested >= self.rest_after and not settle:
                k2 = self.k2_rest
            self._rested += dt
        else:
            self._rested = 0.0
            if self._travel <= SETTLE_AFTER_TRAVEL:
                self._travel += math.hypot(vx, vy) * dt
        if th_qs is None:
            w = k2 * thd
            self._th_qs = None
        else:
            thd_qs = 0.0 if self._th_qs is None else math.remainder(
                th_qs - self._th_qs, 2.0 * math.pi) / dt
            self._th_qs = th_qs
            w = k1 * math.sin(th - th_qs) + k2 * (thd - thd_qs)
        dx = dy = 0.0
        if drive:
            dx, dy = -w * math.sin(th), w * math.cos(th)
            norm = math.hypot(dx, dy)
            if norm > self.a_max:
                dx *= self.a_max / norm
                dy *= self.a_max / norm
        x, y = self._delta
        u, v = self._delta_dot
        ddx = dx - k3 * x - k4 * u
        ddy = dy - k3 * y - k4 * v
        out = (np.array((px + x, py + y)), np.array((vx + u, vy + v)),
               np.array((ax + ddx, ay + ddy)))
        # semi-implicit Euler: exact enough at 1 ms for a 3 rad/s filter
        u += dt * ddx
        v += dt * ddy
        x += dt * u
        y += dt * v
        r = math.hypot(x, y)
        if r > self.delta_max:
            x *= self.delta_max / r
            y *= self.delta_max / r
            out_rate = (u * x + v * y) / (self.delta_max * self.delta_max)
            if out_rate > 0.0:
                u -= out_rate * x
                v -= out_rate * y
        self._delta = (x, y)
        self._delta_dot = (u, v)
        return out

    def snapshot(self):
        """Return the modulation's state (``delta``, its rate, the last angle, rest, travel)."""
        return (self._delta, self._delta_dot, self._th_qs, self._rested, self._travel)

    def restore(self, saved):
        """Put back a :meth:`snapshot`."""
        self._delta, self._delta_dot, self._th_qs, self._rested, self._travel = saved

    @property
    def delta(self):
        """Return the current offset ``delta`` [m], numpy copy (2,)."""
        return np.array(self._delta)

    @property
    def delta_dot(self):
        """Return its rate [m/s], numpy copy (2,)."""
        return np.array(self._delta_dot)


def free_link_swing(params, q, qd):
    """
    Swing amplitude of the free last link about hanging, from its energy [rad].

    With the end effector at rest the link is the pendulum of
    :class:`FreeLinkModulation` (``J_eff thdd = -m3 c3 g cos th``); its energy above
    the hanging angle ``-pi/2``, ``E = J_eff thd^2 / 2 + m3 c3 g (1 + sin th)``, gives
    the amplitude ``acos(1 - E / (m3 c3 g))`` (pi once it would revolve).

    Parameters
    ----------
    params : freejoint_core.arm.ArmParams
        The (real) arm, last joint free, gravity > 0, ``J_eff > 0``.
    q, qd : array_like, (n,)
        Joint angles [rad] and rates [rad/s].

    Returns
    -------
    float
        [rad], in [0, pi].

    """
    m3, c3, l3, i3 = (params.masses[-1], params.com[-1], params.lengths[-1],
                      params.inertias[-1])
    j_eff = i3 + m3 * c3 * (c3 - l3)
    mgc = m3 * c3 * params.gravity
    if mgc <= 0.0 or j_eff <= 0.0:
        raise FreejointValueError('params: the swing needs gravity and J_eff > 0')
    th = math.fsum(q)
    thd = math.fsum(qd)
    energy = 0.5 * j_eff * thd * thd + mgc * (1.0 + math.sin(th))
    return math.acos(max(-1.0, 1.0 - energy / mgc))


def initial_state(params, q3_0_deg=DEFAULT_Q3_0_DEG, start=(0.2, 0.0)):
    """
    Joint angles (rad) putting the end effector at ``start`` with ``q3 = q3_0_deg``.

    Parameters
    ----------
    params : ArmParams
        The (real) arm, one passive joint.
    q3_0_deg : float
        Initial passive joint angle (deg).
    start : sequence of float, shape (2,)
        End-effector start (m).

    Returns
    -------
    numpy.ndarray, shape (n,)
        ``q(0)`` (rad) from ``ArmModel.ik`` on branch +1.

    """
    try:
        q3 = math.radians(float(q3_0_deg))
    except (TypeError, ValueError):
        raise FreejointValueError(f'q3_0_deg: expected a number, got {q3_0_deg!r}') from None
    if not math.isfinite(q3):
        raise FreejointValueError(f'q3_0_deg: must be finite, got {q3_0_deg}')
    try:
        return ArmModel(params).ik(start, [q3], branch=1)
    except FreejointValueError as exc:
        raise FreejointValueError(f'q3_0_deg: no configuration reaches the start: {exc}') \
            from None
