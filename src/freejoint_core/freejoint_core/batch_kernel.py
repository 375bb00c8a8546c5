"""
Compiled kernel of :func:`freejoint_core.batch.simulate` (numba, runs split over threads).

One run per loop iteration, tick by tick: the arm's closed forms are ``fast3``'s own
functions (``terms``, ``qdd``, ``task``) compiled, the law and the RK4 step the very
operations (same order) of ``RobustController._step_fast`` and ``Plant._rk4_fast3``; no
fast-math; numpy's error model (a division by zero gives inf, caught by the divergence
rule like the exception ``offline.run_case`` catches).  No parfors: ``run_range``
releases the GIL and ``batch`` runs one per thread (a short compile; docs/campaigns.md).
The random numbers are drawn outside (``batch``), per run, from the generators the scalar
reference uses.

Layouts (n runs, N ticks):

* ``cr``, ``cn`` (n, 9): real and nominal constants ``d1 d2 d3 h12 h13 h23 gh1 gh2 gh3``;
* ``gp`` (34,): ``lam(2) K+lam(2) K*lam(2) R(2) eps sum robust thr a(5) c(5)
  theta0(5) theta_max(5) limit(2)`` (``inf`` for no bound);
* ``law`` (:data:`ROBUST`, :data:`VSC`, :data:`TDC`) and ``lp``: empty for the paper's
  law (``gp`` holds it), else ``K(2)`` then ``phi eta delta beta0 beta1`` (vsc) or
  ``mbar a`` (tdc, ``a = 1 - exp(-dt / filter)`` the low-pass coefficient, 1: none);
* ``dist`` (n, N, 3) per-tick disturbance [N m]; ``nq``, ``nqd`` (n, N, 3), ``ntau``
  (n, N, 2) already scaled noise (rows of a run without it are not read: ``flags``);
* ``out`` (n, 11): the ``batch.METRICS`` columns; ``out_p`` (n, N, 2) with ``record``.
"""

import math
import types

from freejoint_core import fast3
import numba
import numpy as np

N_OUT = 11
ROBUST, VSC, TDC = 0, 1, 2
"""``law`` of :func:`run_range`: the paper's law, ``law_vsc``, ``law_tdc``."""


_jit = numba.njit(cache=True, error_model='numpy')


def _compiled(fn, **calls):
    """Return ``fn`` compiled, the functions it calls by name replaced by compiled ones."""
    return _jit(types.FunctionType(fn.__code__, dict(fn.__globals__, **calls), fn.__name__))


# the scalar model's own closed forms (fast3), compiled: one definition of the arithmetic
_terms = _compiled(fast3.terms)
_qdd = _compiled(fast3.qdd, terms=_terms)
_task_full = _compiled(fast3.task, terms=_terms)


@_jit
def _task(c, ln, q0, q1, q2, w0, w1, w2):
    """Return ``fast3.task`` with ``Da`` of joints 1, 2 (joint 3 passive), row-major."""
    px, py, vx, vy, x0, x1, _, y0, y1, _, bx, by = _task_full(c, ln, q0, q1, q2, w0, w1, w2)
    return px, py, vx, vy, x0, x1, y0, y1, bx, by


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _run(i, cr, cn, ln, q_init, des, gp, law, lp, dist, nq, nqd, ntau, flags, delay, alpha,
         dt, h, n_sub, limit2, qd_max, record, out, out_p):
    n_ticks = des.shape[0]
    cri = cr[i]
    cni = cn[i]
    q0 = q_init[i, 0]
    q1 = q_init[i, 1]
    q2 = q_init[i, 2]
    w0 = 0.0
    w1 = 0.0
    w2 = 0.0
    th = np.zeros(5)
    if law == ROBUST:
        for j in range(5):
            th[j] = gp[22 + j]
    # tdc: the filtered estimate, the previous tick's task velocity and torque
    nhx = 0.0
    nhy = 0.0
    vpx = 0.0
    vpy = 0.0
    tq0 = 0.0
    tq1 = 0.0
    has_prev = False
    cmds = np.empty((n_ticks, 2))
    m = delay[i]
    al = alpha[i]
    has_lag = al < 1.0
    u0 = 0.0
    u1 = 0.0
    h2 = 0.5 * h
    h6 = h / 6.0
    err_sum = 0.0
    err_max = 0.0
    err_last = 0.0
    tp0 = 0.0
    tp1 = 0.0
    q3_min = np.inf
    q3_max = -np.inf
    det_min = np.inf
    thn = 0.0
    diverged = np.nan
    n_rec = 0
    noisy_q = flags[i, 0]
    noisy_qd = flags[i, 1]
    noisy_tau = flags[i, 2]
    for k in range(n_ticks):
        t = k * dt
        pdx = des[k, 0]
        pdy = des[k, 1]
        vdx = des[k, 2]
        vdy = des[k, 3]
        adx = des[k, 4]
        ady = des[k, 5]
        m0, m1, m2 = q0, q1, q2
        n0, n1, n2 = w0, w1, w2
        if noisy_q:
            m0 = q0 + nq[i, k, 0]
            m1 = q1 + nq[i, k, 1]
            m2 = q2 + nq[i, k, 2]
        if noisy_qd:
            n0 = w0 + nqd[i, k, 0]
            n1 = w1 + nqd[i, k, 1]
            n2 = w2 + nqd[i, k, 2]
        px, py, vx, vy, d00, d01, d10, d11, bx, by = _task(cni, ln, m0, m1, m2, n0, n1, n2)
        ex = px - pdx
        ey = py - pdy
        edx = vx - vdx
        edy = vy - vdy
        sx = edx + gp[0] * ex
        sy = edy + gp[1] * ey
        t_0 = th[0]
        t_1 = th[1]
        t_2 = th[2]
        t_3 = th[3]
        t_4 = th[4]
        if law == ROBUST:
            vvx = adx - gp[2] * edx - gp[4] * ex
            vvy = ady - gp[3] * edy - gp[5] * ey
            if gp[10] != 0.0:
                alx = gp[6] * sx
                aly = gp[7] * sy
                na2 = alx * alx + aly * aly
                na = math.sqrt(na2)
                eps = gp[8]
                if gp[9] != 0.0:
                    hh = na + eps
                else:
                    hh = na if na > eps else eps
                ps1 = n0 * n0 + n1 * n1 + n2 * n2
                ps2 = math.sqrt(adx * adx + ady * ady)
                ps3 = math.sqrt(edx * edx + edy * edy)
                ps4 = math.sqrt(ex * ex + ey * ey)
                rho = t_0 + t_1 * ps1 + t_2 * ps2 + t_3 * ps3 + t_4 * ps4
                f = rho / hh
                dvx = -f * alx
                dvy = -f * aly
                uu = na2 / hh
                t_0 = gp[12] * t_0 + gp[17] * (uu * 1.0)
                t_1 = gp[13] * t_1 + gp[18] * (uu * ps1)
                t_2 = gp[14] * t_2 + gp[19] * (uu * ps2)
                t_3 = gp[15] * t_3 + gp[20] * (uu * ps3)
                t_4 = gp[16] * t_4 + gp[21] * (uu * ps4)
                t_0 = gp[27] if t_0 > gp[27] else t_0
                t_1 = gp[28] if t_1 > gp[28] else t_1
                t_2 = gp[29] if t_2 > gp[29] else t_2
                t_3 = gp[30] if t_3 > gp[30] else t_3
                t_4 = gp[31] if t_4 > gp[31] else t_4
            else:
                dvx = 0.0
                dvy = 0.0
            wx = vvx + dvx - bx
            wy = vvy + dvy - by
        else:
            # a task law (task_law.TaskLaw.step): u0 = pdd_d - Lam edot - K s, then its command
            u0x = adx - gp[0] * edx - lp[0] * sx
            u0y = ady - gp[1] * edy - lp[1] * sy
            if law == VSC:      # law_vsc.SlidingModeLaw.command
                delta = lp[4]
                phi = lp[2]
                gx = u0x - bx
                gy = u0y - by
                kk = (delta * math.sqrt(gx * gx + gy * gy) + lp[5]
                      + lp[6] * (n0 * n0 + n1 * n1 + n2 * n2) + lp[3]) / (1.0 - delta)
                ns = math.sqrt(sx * sx + sy * sy)
                dd = ns if ns > phi else phi
                wx = u0x + -kk * (sx / dd) - bx
                wy = u0y + -kk * (sy / dd) - by
            else:               # TDC: law_tdc.TimeDelayLaw.command
                mbar = lp[2]
                if has_prev:
                    nrx = (vx - vpx) / dt - (d00 * tq0 + d01 * tq1) / mbar
                    nry = (vy - vpy) / dt - (d10 * tq0 + d11 * tq1) / mbar
                    nhx = nhx + lp[3] * (nrx - nhx)
                    nhy = nhy + lp[3] * (nry - nhy)
                else:
                    nhx = bx
                    nhy = by
                wx = mbar * (u0x - nhx)
                wy = mbar * (u0y - nhy)
        a00 = d00 * d00 + d01 * d01
        a01 = d00 * d10 + d01 * d11
        a11 = d10 * d10 + d11 * d11
        det = a00 * a11 - a01 * a01
        thr = gp[11]
        if abs(det) < thr:
            gap = thr - det
            tr = a00 + a11
            lam2 = 2.0 * gap / (tr + math.sqrt(tr * tr + 4.0 * gap))
            a00 += lam2
            a11 += lam2
            det_use = a00 * a11 - a01 * a01
        else:
            det_use = det
        y0 = (a11 * wx - a01 * wy) / det_use
        y1 = (a00 * wy - a01 * wx) / det_use
        c0 = d00 * y0 + d10 * y1
        c1 = d01 * y0 + d11 * y1
        l0 = gp[32]
        l1 = gp[33]
        if c0 > l0 or c0 < -l0 or c1 > l1 or c1 < -l1:
            c0 = l0 if c0 > l0 else (-l0 if c0 < -l0 else c0)
            c1 = l1 if c1 > l1 else (-l1 if c1 < -l1 else c1)
        if law == TDC:          # TimeDelayLaw.applied: this tick's torque and velocity
            tq0 = c0
            tq1 = c1
            vpx = vx
            vpy = vy
            has_prev = True
        if noisy_q or noisy_qd:
            f2 = q0 + q1
            f3 = f2 + q2
            px = ln[0] * math.cos(q0) + ln[1] * math.cos(f2) + ln[2] * math.cos(f3)
            py = ln[0] * math.sin(q0) + ln[1] * math.sin(f2) + ln[2] * math.sin(f3)
            ex = px - pdx
            ey = py - pdy
        err2 = ex * ex + ey * ey
        adet = abs(det)
        if not (math.isfinite(err2) and math.isfinite(c0) and math.isfinite(c1)
                and math.isfinite(adet)):
            diverged = t
            break
        th[0] = t_0
        th[1] = t_1
        th[2] = t_2
        th[3] = t_3
        th[4] = t_4
        e_mm = 1000.0 * math.hypot(ex, ey)
        err_sum += e_mm * e_mm
        err_max = e_mm if e_mm > err_max else err_max
        err_last = e_mm
        a = abs(c0)
        tp0 = a if a > tp0 else tp0
        a = abs(c1)
        tp1 = a if a > tp1 else tp1
        q3_min = q2 if q2 < q3_min else q3_min
        q3_max = q2 if q2 > q3_max else q3_max
        det_min = adet if adet < det_min else det_min
        if record:
            out_p[i, k, 0] = px
            out_p[i, k, 1] = py
        n_rec = k + 1
        if err2 > limit2 or max(abs(w0), abs(w1), abs(w2)) > qd_max:
            diverged = t
            break
        cmds[k, 0] = c0
        cmds[k, 1] = c1
        src = k - m
        if src < 0:
            src = 0
        a0 = cmds[src, 0]
        a1 = cmds[src, 1]
        if has_lag:
            if k == 0:
                u0 = cmds[0, 0]
                u1 = cmds[0, 1]
            u0 = u0 + al * (a0 - u0)
            u1 = u1 + al * (a1 - u1)
            a0 = u0
            a1 = u1
        if noisy_tau:
            a0 = a0 + ntau[i, k, 0]
            a1 = a1 + ntau[i, k, 1]
        f0 = dist[i, k, 0] + a0
        f1 = dist[i, k, 1] + a1
        fp = dist[i, k, 2]
        x0, x1, x2, v0, v1, v2 = q0, q1, q2, w0, w1, w2
        for _ in range(n_sub):
            ka0, ka1, ka2 = _qdd(cri, x0, x1, x2, v0, v1, v2, f0, f1, fp)
            s0 = v0 + h2 * ka0
            s1 = v1 + h2 * ka1
            s2 = v2 + h2 * ka2
            kb0, kb1, kb2 = _qdd(cri, x0 + h2 * v0, x1 + h2 * v1, x2 + h2 * v2, s0, s1, s2,
                                 f0, f1, fp)
            r0 = v0 + h2 * kb0
            r1 = v1 + h2 * kb1
            r2 = v2 + h2 * kb2
            kc0, kc1, kc2 = _qdd(cri, x0 + h2 * s0, x1 + h2 * s1, x2 + h2 * s2, r0, r1, r2,
                                 f0, f1, fp)
            z0 = v0 + h * kc0
            z1 = v1 + h * kc1
            z2 = v2 + h * kc2
            kd0, kd1, kd2 = _qdd(cri, x0 + h * r0, x1 + h * r1, x2 + h * r2, z0, z1, z2,
                                 f0, f1, fp)
            x0 += h6 * (v0 + 2.0 * (s0 + r0) + z0)
            x1 += h6 * (v1 + 2.0 * (s1 + r1) + z1)
            x2 += h6 * (v2 + 2.0 * (s2 + r2) + z2)
            v0 += h6 * (ka0 + 2.0 * (kb0 + kc0) + kd0)
            v1 += h6 * (ka1 + 2.0 * (kb1 + kc1) + kd1)
            v2 += h6 * (ka2 + 2.0 * (kb2 + kc2) + kd2)
        if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2)
                and math.isfinite(v0) and math.isfinite(v1) and math.isfinite(v2)):
            diverged = (k + 1) * dt
            break
        q0, q1, q2, w0, w1, w2 = x0, x1, x2, v0, v1, v2
    for j in range(5):
        thn += th[j] * th[j]
    out[i, 0] = math.sqrt(err_sum / n_rec) if n_rec else np.nan
    out[i, 1] = err_max
    out[i, 2] = err_last
    out[i, 3] = tp0
    out[i, 4] = tp1
    out[i, 5] = math.degrees(q3_min)
    out[i, 6] = math.degrees(q3_max)
    out[i, 7] = det_min
    out[i, 8] = math.sqrt(thn)
    out[i, 9] = diverged
    out[i, 10] = n_rec


@numba.njit(cache=True, nogil=True, error_model='numpy')
def run_range(lo, hi, step, cr, cn, ln, q_init, des, gp, law, lp, dist, nq, nqd, ntau, flags,
              delay, alpha, dt, h, n_sub, limit2, qd_max, record, out, out_p):
    """Run the runs ``lo, lo + step, ... < hi`` (without the GIL); fills ``out``, ``out_p``."""
    for i in range(lo, hi, step):
        _run(i, cr, cn, ln, q_init, des, gp, law, lp, dist, nq, nqd, ntau, flags, delay, alpha,
             dt, h, n_sub, limit2, qd_max, record, out, out_p)
