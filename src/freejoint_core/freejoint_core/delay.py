"""
Compensation of a known command delay with the nominal model (a state predictor).

In real time the command computed from the state stamped ``t_k`` reaches the
plant late: with a delay of ``m`` control periods it acts over
``[t_{k+m}, t_{k+m+1}]``.  The law then corrects an error the arm no longer
has, and a loop with a small delay margin (the vertical case) diverges.  The
compensation: compute the command on the state the arm will have when the
command acts, predicted from the measured state by integrating the NOMINAL
model over the horizon ``h = m dt`` under the commands already sent that will
act in between::

    (q, qd) measured at t_k
    commands acting over [t_{k+j}, t_{k+j+1}], j = 0 .. m-1:
        tau_{k-m+j}  = the last m pushed, oldest first
    (q_pred, qd_pred) = RK4 of  M^ qdd + C^ qd + G^ = B tau_a  over h
    law(q_pred, qd_pred, setpoint at t_{k+m})  ->  tau_k ;  push(tau_k)

The integration is the plant's (``plant.Plant``): classic RK4 at ``dt_sub``
with the torque held over each period, passive joints unactuated, no
disturbance (it is unknown).  For the 3-link arm it runs on the scalar kernel
(``fast3.Arm3Model.qdd``) with the same floating-point operations as the
plant, so with the exact model and no disturbance the prediction equals the
plant's state to round-off; other arms use the general numpy model.

Model error: the nominal model (Table I: masses, inertias and COM distances
at 70 %) alone predicts badly: the commands are sized for the real arm (the
robust term makes up the difference), so the nominal model under them
accelerates wrongly, and the vertical loop with plain prediction is worse
than without it (docs/delay.md).  The predictor therefore learns an
acceleration bias ``a_b`` (n,), added to the nominal ``qdd`` in the
integration: at each ``predict`` that follows exactly one ``push``, the last
measured state is integrated over one period under the command that acted
over it (``applied`` if the caller knows it, e.g. from ``joint_states.effort``;
else the one pushed ``ticks + 1`` pushes ago) and, with the velocity residual
``r = qd_measured - qd_predicted``::

    a_b <- a_b + bias_gain * r / dt

an integrating observer (``bias_gain`` 0 .. 1; 0 turns it off).  It converges
to the model error along the path within a few tens of periods and averages
out the random disturbance.  The default ``bias_gain`` (0.05) is the best
compromise measured between accuracy and delay margin (docs/delay.md).

The pipeline must be right: with the 70 % model a horizon one period off the
real delay diverges the vertical case.  ``ticks_since(applied)`` reads the
delay from the command the plant reports it applied (docs/delay.md).

History before enough commands were sent: the missing (older) commands are
taken equal to the oldest pushed one, and as zero torque when none has been
pushed yet (the first tick).  This is exact for the offline runner's delay
option, where the first command also acts over the first ``m`` periods.

``extrapolate_setpoint`` shifts a setpoint ``(p_d, pd_d, pdd_d)`` sampled at
``t_k`` to ``t_k + h`` by its Taylor polynomial (the acceleration held), for a
controller that only has the setpoint of the state's tick.
"""

from collections import deque
import math
import operator

from freejoint_core.arm import ArmModel, ArmParams, check_vector
from freejoint_core.errors import FreejointValueError
from freejoint_core.models import make_model
from freejoint_core.plant import check_torques, DEFAULT_DT_SUB
import numpy as np

DEFAULT_MAX_TICKS = 20
"""Default capacity of the command history (periods)."""

DEFAULT_BIAS_GAIN = 0.05
"""Default gain of the acceleration-bias observer (per period)."""

_isfinite = math.isfinite


def _pos(name, value):
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise FreejointValueError(f'{name}: expected a number, got {value!r}') from None
    if not _isfinite(out) or out <= 0.0:
        raise FreejointValueError(f'{name}: must be finite and > 0, got {value!r}')
    return out


def _count(name, value, low, high):
    if isinstance(value, bool):
        raise FreejointValueError(f'{name}: expected an int, got {value!r}')
    try:
        out = operator.index(value)
    except TypeError:
        raise FreejointValueError(f'{name}: expected an int, got {value!r}') from None
    if out < low or out > high:
        raise FreejointValueError(f'{name}: must lie in [{low}, {high}], got {out}')
    return out


def _substeps(dt, dt_sub):
    n_sub = round(dt / dt_sub)
    if n_sub < 1 or abs(n_sub * dt_sub - dt) > 1e-9 * dt:
        raise FreejointValueError(
            f'dt_sub: dt = {dt} s is not an integer multiple of dt_sub = {dt_sub} s')
    return n_sub


class StatePredictor:
    """
    Predict the arm's state after a known command delay with the nominal model.

    Parameters
    ----------
    nominal_params : ArmParams
        Nominal (guessed) parameters, the controller's model.
    dt : float
        Control period [s], > 0: each pushed command acts over one period.
    dt_sub : float, optional
        RK4 step [s]; ``dt`` must be an integer multiple.  Default: the plant's
        ``DEFAULT_DT_SUB`` (0.5 ms) when ``dt`` is a multiple of it, else ``dt``.
    max_ticks : int
        Longest horizon [periods], 1 .. 1000; also the history's capacity.
    use_fast : bool
        Use the scalar 3-link kernel when ``n == 3`` (default); False forces
        the general numpy model (reference).
    bias_gain : float
        Gain of the acceleration-bias observer per period, in [0, 1]; 0 is
        plain prediction with the nominal model (see the module notes).

    Attributes
    ----------
    dt, dt_sub : float
        As given / resolved [s].
    max_ticks : int
        As given.
    n, r : int
        Joints and active joints of the model.

    """

    def __init__(self, nominal_params, dt, dt_sub=None, max_ticks=DEFAULT_MAX_TICKS,
                 use_fast=True, bias_gain=DEFAULT_BIAS_GAIN):
        if not isinstance(nominal_params, ArmParams):
            raise FreejointValueError(
                f'nominal_params: expected ArmParams, got {type(nominal_params).__name__}')
        self.dt = _pos('dt', dt)
        if dt_sub is None:
            n_sub = round(self.dt / DEFAULT_DT_SUB)
            ok = n_sub >= 1 and abs(n_sub * DEFAULT_DT_SUB - self.dt) <= 1e-9 * self.dt
            self.dt_sub = DEFAULT_DT_SUB if ok else self.dt
        else:
            self.dt_sub = _pos('dt_sub', dt_sub)
        self._n_sub = _substeps(self.dt, self.dt_sub)
        self.max_ticks = _count('max_ticks', max_ticks, 1, 1000)
        self.params = nominal_params
        self.n = nominal_params.n
        self.r = nominal_params.r
        self._active = nominal_params.active
        self.model = make_model(nominal_params) if use_fast else ArmModel(nominal_params)
        self._fast = bool(use_fast) and self.n == 3 and hasattr(self.model, 'qdd')
        try:
            self.bias_gain = float(bias_gain)
        except (TypeError, ValueError):
            raise FreejointValueError(f'bias_gain: expected a number, got {bias_gain!r}') \
                from None
        if not (0.0 <= self.bias_gain <= 1.0):
            raise FreejointValueError(f'bias_gain: must lie in [0, 1], got {bias_gain!r}')
        self._hist = deque(maxlen=self.max_ticks + 1)
        self._zero = (0.0,) * self.n
        self.reset()

    def reset(self):
        """Forget every pushed command and the bias estimate (start of a run)."""
        self._hist.clear()
        self._bias = (0.0,) * self.n
        self._last = None
        self._first = None
        self._pushes = 0

    @property
    def bias(self):
        """Return the acceleration bias estimate [rad/s^2], numpy copy (n,)."""
        return np.array(self._bias)

    def __len__(self):
        """Return the number of commands held (at most ``max_ticks``)."""
        return len(self._hist)

    def push(self, tau_active):
        """
        Record the command just sent; it acts over the next period after the delay.

        Parameters
        ----------
        tau_active : array_like, (r,)
            Active joint torques [N m], in ``params.active`` order, finite.

        """
        self._hist.append(self._full(tau_active, 'tau_active'))
        self._pushes += 1

    def _full(self, tau_active, name):
        """Validate (r,) active torques; return them as (n,) with zeros on passive joints."""
        tau = check_torques(tau_active, self.r, name)
        full = [0.0] * self.n
        for j, v in zip(self._active, tau):
            full[j] += float(v)
        return tuple(full)

    def ticks_since(self, applied):
        """
        Return how many commands were pushed after the one the plant last applied.

        With a plant that reports the command it applied over the period that led to
        the measured state (e.g. ``joint_states.effort`` of the active joints), this is
        the delay in periods, and those commands are the ones still to act: use it as
        ``predict``'s ``ticks``.

        Parameters
        ----------
        applied : array_like, (r,)
            Active joint torques [N m] applied over the last period, ``params.active``
            order.

        Returns
        -------
        int or None
            Pushes after the latest push equal to ``applied`` (exact match), 0 ..
            ``max_ticks``; None if no held push equals it (e.g. a refused command or
            zero effort at start).

        """
        full = self._full(applied, 'applied')
        hist = self._hist
        for back in range(len(hist) - 1, -1, -1):
            if hist[back] == full:
                since = len(hist) - 1 - back
                return since if since <= self.max_ticks else None
        return None

    def commands(self, ticks):
        """
        Return the generalised forces assumed over the next ``ticks`` periods.

        Parameters
        ----------
        ticks : int
            Horizon [periods], 0 .. ``max_ticks``.

        Returns
        -------
        list of tuple of float
            ``ticks`` entries, each (n,) [N m] (passive joints 0), oldest first:
            the last ``ticks`` pushed, padded in front with the oldest pushed
            (zeros if none was pushed).

        """
        return self._window(_count('ticks', ticks, 0, self.max_ticks), 0)

    def _window(self, ticks, skip):
        """``commands(ticks)`` as it was ``skip`` pushes ago."""
        full = self._hist
        hist = list(full)
        if skip:
            hist = hist[:-skip]
        have = len(hist)
        if have >= ticks:
            return hist[have - ticks:]
        pad = full[0] if full else self._zero
        return [pad] * (ticks - have) + hist

    def predict(self, q, qd, ticks, applied=None):
        """
        Integrate the nominal model over ``ticks`` periods under the pushed commands.

        Parameters
        ----------
        q : array_like, (n,)
            Measured joint angles [rad], passive joints included.
        qd : array_like, (n,)
            Measured joint velocities [rad/s], passive joints included.
        ticks : int
            Horizon ``m`` [periods], 0 .. ``max_ticks``; ``h = m dt``.
        applied : array_like, (r,), optional
            Active torques [N m] the plant applied over the period that led to
            ``(q, qd)`` (e.g. ``joint_states.effort``): the bias observer then uses
            it instead of assuming the command pushed ``ticks + 1`` pushes ago.

        Returns
        -------
        q_pred, qd_pred : numpy.ndarray, (n,)
            Predicted joint angles [rad] and velocities [rad/s] at ``t + h``
            (fresh arrays; for ``ticks == 0`` the input, but the observer
            still learns).

        Raises
        ------
        FreejointValueError
            Naming ``q``, ``qd`` or ``ticks`` if bad, or ``q`` if the
            integration left the finite range (a state far outside the model's
            validity).

        Notes
        -----
        Call once per control period with that period's measured state, then
        ``push`` the command computed from the prediction: the bias observer
        learns only at a call preceded by exactly one ``push`` (any other
        call just records the state, e.g. after a skipped or repeated tick).

        """
        ticks = _count('ticks', ticks, 0, self.max_ticks)
        cmds = self._window(ticks, 0)
        if self._fast:
            state = _floats3(q, 'q') + _floats3(qd, 'qd')
        else:
            state = tuple(check_vector(q, self.n, 'q').tolist()
                          + check_vector(qd, self.n, 'qd').tolist())
        acted = None if applied is None else self._full(applied, 'applied')
        if self.bias_gain > 0.0:
            self._observe(state, ticks, acted)
            if cmds:
                # kept: the next call's observer needs this first period
                first = self._integrate(state, cmds[:1])
                self._first = (cmds[0], first)
                out = self._integrate(first, cmds[1:])
            else:
                self._first = None
                out = state
        else:
            out = self._integrate(state, cmds)
        if not all(map(_isfinite, out)):
            raise FreejointValueError(
                f'q: the prediction over {len(cmds)} periods left the finite range '
                f'(from q = {q!r}, qd = {qd!r})')
        out = np.array(out)
        n = self.n
        return out[:n], out[n:]

    def _observe(self, state, ticks, acted):
        """Update the acceleration bias from the last period's velocity residual."""
        last = self._last
        pushes = self._pushes
        self._last = state
        self._pushes = 0
        if last is None or pushes != 1:
            return
        # The command that acted over the last period: pushed ticks + 1 ago.  The last
        # call integrated the same period already when its first command was this one.
        acted = self._window(1, ticks) if acted is None else [acted]
        first = self._first
        if first is not None and first[0] == acted[0]:
            y = first[1]
        else:
            y = self._integrate(last, acted)
        n = self.n
        g = self.bias_gain / self.dt
        self._bias = tuple(b + g * (w - yw) for b, w, yw in zip(self._bias, state[n:], y[n:]))

    def _integrate(self, state, cmds):
        """RK4 at ``dt_sub`` from ``state`` (2n floats) under ``cmds``, bias added."""
        if not self._fast:
            return self._integrate_general(state, cmds)
        q0, q1, q2, w0, w1, w2 = state
        e0, e1, e2 = self._bias
        qdd = self.model.qdd
        h = self.dt_sub
        h2 = 0.5 * h
        h6 = h / 6.0
        n_sub = self._n_sub
        for t0, t1, t2 in cmds:
            for _ in range(n_sub):
                a0, a1, a2 = qdd(q0, q1, q2, w0, w1, w2, t0, t1, t2)
                a0 += e0
                a1 += e1
                a2 += e2
                u0 = w0 + h2 * a0
                u1 = w1 + h2 * a1
                u2 = w2 + h2 * a2
                b0, b1, b2 = qdd(q0 + h2 * w0, q1 + h2 * w1, q2 + h2 * w2, u0, u1, u2,
                                 t0, t1, t2)
                b0 += e0
                b1 += e1
                b2 += e2
                v0 = w0 + h2 * b0
                v1 = w1 + h2 * b1
                v2 = w2 + h2 * b2
                c0, c1, c2 = qdd(q0 + h2 * u0, q1 + h2 * u1, q2 + h2 * u2, v0, v1, v2,
                                 t0, t1, t2)
                c0 += e0
                c1 += e1
                c2 += e2
                x0 = w0 + h * c0
                x1 = w1 + h * c1
                x2 = w2 + h * c2
                d0, d1, d2 = qdd(q0 + h * v0, q1 + h * v1, q2 + h * v2, x0, x1, x2,
                                 t0, t1, t2)
                d0 += e0
                d1 += e1
                d2 += e2
                q0 += h6 * (w0 + 2.0 * (u0 + v0) + x0)
                q1 += h6 * (w1 + 2.0 * (u1 + v1) + x1)
                q2 += h6 * (w2 + 2.0 * (u2 + v2) + x2)
                w0 += h6 * (a0 + 2.0 * (b0 + c0) + d0)
                w1 += h6 * (a1 + 2.0 * (b1 + c1) + d1)
                w2 += h6 * (a2 + 2.0 * (b2 + c2) + d2)
        return q0, q1, q2, w0, w1, w2

    def _integrate_general(self, state, cmds):
        n = self.n
        q = np.array(state[:n])
        w = np.array(state[n:])
        bias = np.array(self._bias)
        f = self.model.forward_dynamics
        h = self.dt_sub
        try:
            for tau in cmds:
                tau = np.array(tau)
                for _ in range(self._n_sub):
                    a = f(q, w, tau) + bias
                    u = w + 0.5 * h * a
                    b = f(q + 0.5 * h * w, u, tau) + bias
                    v = w + 0.5 * h * b
                    c = f(q + 0.5 * h * u, v, tau) + bias
                    x = w + h * c
                    d = f(q + h * v, x, tau) + bias
                    q = q + (h / 6.0) * (w + 2.0 * (u + v) + x)
                    w = w + (h / 6.0) * (a + 2.0 * (b + c) + d)
        except (FreejointValueError, np.linalg.LinAlgError):
            return (math.nan,) * (2 * n)
        return tuple(q.tolist() + w.tolist())


def _floats3(x, name):
    """Three finite floats from a sequence or ndarray."""
    if type(x) is np.ndarray:
        x = x.tolist()
    try:
        a, b, c = x
        a, b, c = float(a), float(b), float(c)
        if _isfinite(a) and _isfinite(b) and _isfinite(c):
            return a, b, c
    except (TypeError, ValueError):
        pass
    shape = np.shape(x) if not isinstance(x, (str, bytes)) else '?'
    raise FreejointValueError(
        f'{name}: expected 3 finite numbers (shape (3,)), got {x!r} with shape {shape}')


def extrapolate_setpoint(p_d, pd_d, pdd_d, h):
    """
    Shift a setpoint by ``h`` along its Taylor polynomial (acceleration held).

    Parameters
    ----------
    p_d, pd_d, pdd_d : array_like, (m,)
        Desired end-effector position [m], velocity [m/s], acceleration
        [m/s^2] at ``t`` (m, the task dimension, from ``p_d``).
    h : float
        Shift [s], >= 0.

    Returns
    -------
    p, pd, pdd : numpy.ndarray, (m,)
        ``p_d + h pd_d + h^2/2 pdd_d``, ``pd_d + h pdd_d``, ``pdd_d`` at ``t + h``.

    """
    m = np.shape(p_d)[0] if np.ndim(p_d) == 1 and np.shape(p_d)[0] > 0 else 2
    p_d = check_vector(p_d, m, 'p_d')
    pd_d = check_vector(pd_d, m, 'pd_d')
    pdd_d = check_vector(pdd_d, m, 'pdd_d')
    try:
        h = float(h)
    except (TypeError, ValueError):
        raise FreejointValueError(f'h: expected a number, got {h!r}') from None
    if not _isfinite(h) or h < 0.0:
        raise FreejointValueError(f'h: must be finite and >= 0, got {h}')
    return p_d + h * pd_d + (0.5 * h * h) * pdd_d, pd_d + h * pdd_d, pdd_d.copy()
