"""The Taylor (DT) engine's step loop compiled by numba (issue 19): long arcs without per-order overhead.

The numpy engine (:mod:`trackproc.dynamics.taylor`, kernels in
:mod:`trackproc.dynamics.taylor_series`) pays interpreter overhead for every order of every
step (about 0.09 ms of CPU a step for the state, 0.2 ms with the STM, at order 24: 2.4 and
12 us compiled), which is what made a J2 day 57x slower than heyoka (1.6x compiled). Here the whole loop is compiled: the series of a step by the
same recurrences (seed 000 eq. 14, seed 004 eqs. 6 and 19-21), the same Jorba-Zou step size and
order, the new state from the series, the growing store of per-step spectra for the dense output,
and the end-time event (the last step is cut to land on ``t_end``). The result is the same
:class:`~trackproc.dynamics.taylor_dense.Propagation`; the two paths agree to rounding (tests in
tests/dynamics/test_taylor_jit.py: state and STM over a day to 1e-13 .. 1e-12 relative).

Two loop kernels, on purpose: state only, and state with sensitivities (the variational
recurrence of :func:`trackproc.dynamics.taylor_series.series_var_single`). The sensitivity
series cost about 5.5x the state's (9.5 against 1.7 us a step, J2 day), so one kernel with a
flag would make a state-only day about 5x slower. Two-body and J2 share each kernel (a branch per order). Only a single trajectory is
compiled: the batch kernels of the numpy engine already spread the per-order overhead over the
batch.

Dense output (:func:`dense`): Horner's scheme per step, the samples of a step in the inner loop
(contiguous, vectorisable). Used for propagations made here (``Propagation.engine``) when
steps are many and samples per step few; numpy's one BLAS product per step wins otherwise.

One module over 400 lines, on purpose: numba's on-disk cache is keyed on the file that defines a
kernel and does not follow the kernels it calls in other files (an edit there would leave a
stale compiled caller), so kernels that call each other live in one file.

Import this module only when :func:`trackproc.dynamics.jit.enabled` is true. The kernels are
compiled at their first call (about 6 s of CPU for all of them, once per installation: numba
keeps the machine code on disk) and later processes only load them (~0.03 s, after the ~0.15 s
of ``import numba``). :func:`ready` tells whether that is so; ``python -m
trackproc.dynamics.taylor_jit`` compiles them ahead of use.
"""

from __future__ import annotations

import math
import time

import numpy as np

from trackproc.dynamics.jit import njit

__all__ = ["propagate_state", "propagate_var", "dense", "ready", "compile_all", "OUTCOME_SUCCESS",
           "OUTCOME_STEP_LIMIT", "OUTCOME_NON_FINITE"]

OUTCOME_SUCCESS, OUTCOME_STEP_LIMIT, OUTCOME_NON_FINITE = 0, 1, 2

# IEEE division (x/0 = inf, then caught as NON_FINITE) instead of Python's ZeroDivisionError;
# cache=True (jit.njit's default) keeps the machine code on disk; no fastmath.
_KW = dict(error_model="numpy", nogil=True)


@njit(**_KW)
def _step_size(x, p, tol):
    """Jorba-Zou step from position spectra x (3, p+2); the scalar branch of taylor._step_size."""
    a = np.zeros(5)
    cols = (0, 1, p - 1, p, p + 1)
    for j in range(5):
        c = cols[j]
        m = 0.0
        for i in range(3):
            v = abs(x[i, c])
            if v > m:
                m = v
        a[j] = m
    lt = math.log(tol)
    lr = math.log(max(1.0, a[0]))
    lv = math.log(max(1.0, a[1]))
    cand = math.inf
    # |c_k| for position k = p-1, p and velocity k = p-1, p (V(k) = (k+1) X(k+1))
    cs = (a[2], a[3], a[3] * p, a[4] * (p + 1.0))
    los = (lr, lr, lv, lv)
    ks = (p - 1, p, p - 1, p)
    for j in range(4):
        if cs[j] > 0.0:
            cand = min(cand, (lt + los[j] - math.log(cs[j])) / ks[j])
    if cand < math.inf:
        return math.exp(cand - 0.7 / (p - 1))
    return math.inf


# The loops below compute several Cauchy sums of one order together: without fastmath a sum is a
# chain of dependent additions, and independent chains side by side keep the FPU busy (about 2x).
# The power-rule weight (a(K-l) - l)/K is split as a - (a+1) l/K (two plain sums, no division in
# the loop), as in taylor_series.series_state_single.


@njit(**_KW)
def _series_state(x, p, mu, kj2, s, z2, w3, w5, w7, hxy, hz):
    """Position spectra x (3, p+2) of one step (x[:, 0:2] = r0, v0 on entry).

    Implements seed 004 eq. 6 (two-body spectrum, r^-3 by the power rule) with J2: the
    recurrences of :func:`trackproc.dynamics.taylor_series.series_state`.
    """
    j2 = kj2 != 0.0
    mt = -5.0 * kj2
    inv_s0 = 0.0
    x0, x1, x2 = x[0], x[1], x[2]
    for k in range(p):
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for l in range(k + 1):
            sx += x0[l] * x0[k - l]
            sy += x1[l] * x1[k - l]
            sz += x2[l] * x2[k - l]
        sk = sx + sy + sz
        s[k] = sk
        z2[k] = sz
        fac = 1.0 / ((k + 1.0) * (k + 2.0))
        if not j2:
            if k == 0:
                inv_s0 = 1.0 / sk
                w3[0] = sk ** -1.5
            else:
                a3 = 0.0
                b3 = 0.0
                for l in range(k):
                    sl = s[k - l]
                    a3 += w3[l] * sl
                    b3 += (l * w3[l]) * sl
                w3[k] = inv_s0 * (-1.5 * a3 + (0.5 / k) * b3)
            ax = 0.0
            ay = 0.0
            az = 0.0
            for l in range(k + 1):
                wl = w3[k - l]
                ax += x0[l] * wl
                ay += x1[l] * wl
                az += x2[l] * wl
            f = -mu * fac
            x0[k + 2] = ax * f
            x1[k + 2] = ay * f
            x2[k + 2] = az * f
            continue
        tk = 0.0                                  # T = z^2 w7 without its l = 0 term here
        if k == 0:
            inv_s0 = 1.0 / sk
            w3[0] = sk ** -1.5
            w5[0] = w3[0] * inv_s0
            w7[0] = w5[0] * inv_s0
        else:
            a3 = 0.0
            b3 = 0.0
            a5 = 0.0
            b5 = 0.0
            a7 = 0.0
            b7 = 0.0
            for l in range(k):
                sl = s[k - l]
                a3 += w3[l] * sl
                b3 += (l * w3[l]) * sl
                a5 += w5[l] * sl
                b5 += (l * w5[l]) * sl
                a7 += w7[l] * sl
                b7 += (l * w7[l]) * sl
                tk += z2[k - l] * w7[l]
            w3[k] = inv_s0 * (-1.5 * a3 + (0.5 / k) * b3)
            w5[k] = inv_s0 * (-2.5 * a5 + (1.5 / k) * b5)
            w7[k] = inv_s0 * (-3.5 * a7 + (2.5 / k) * b7)
        tk += z2[0] * w7[k]
        hxy[k] = -mu * w3[k] + kj2 * w5[k] + mt * tk
        hz[k] = -mu * w3[k] + 3.0 * kj2 * w5[k] + mt * tk
        ax = 0.0
        ay = 0.0
        az = 0.0
        for l in range(k + 1):
            hl = hxy[k - l]
            ax += x0[l] * hl
            ay += x1[l] * hl
            az += x2[l] * hz[k - l]
        x0[k + 2] = ax * fac
        x1[k + 2] = ay * fac
        x2[k + 2] = az * fac


@njit(**_KW)
def _series_var(x, ph, p, mu, kj2, mu_col, wk):
    """Position spectra x (3, n) and sensitivity spectra ph (3, P, n) of one step.

    On entry x[:, 0:2] = r0, v0 and ph[:, :, 0:2] = dr0, dv0. The variational recurrence of
    :func:`trackproc.dynamics.taylor_series.series_var_single`,
    ``Phi(K+2) = [sum_l G(l) Phi(K-l) + delta_{p,mu} A(K)/mu] / ((K+1)(K+2))``, with the
    spectrum of the gravity gradient
    ``G = diag(h_xy, h_xy, h_z) + q r r^T - 10 k w7 z (r e_z^T + e_z r^T)``,
    ``q = 3 mu w5 - 5 k w7 + 35 k z^2 w9``. ``mu_col`` < 0: no mu column.

    Implements seed 004 eqs. 19-21 (first order) on seed 004 eq. 6 with J2.

    One numba kernel on purpose: the recurrence above, order by order, on the work arrays ``wk`` that every
    part of it reads and writes; split, the parts would pass them at every order of every step.
    """
    npar = ph.shape[1]
    k = kj2
    c10 = 10.0 * k
    # work rows: 0-5 P_ij (xx xy xz yy yz zz) | 6 s | 7-10 w3 w5 w7 w9 | 13 h_xy | 14 h_z | 15 q
    #            | 25-33 G (row-major)
    pxx, pxy, pxz, pyy, pyz, pzz = wk[0], wk[1], wk[2], wk[3], wk[4], wk[5]
    sr, w3, w5, w7, w9 = wk[6], wk[7], wk[8], wk[9], wk[10]
    hxy, hz, q = wk[13], wk[14], wk[15]
    x0, x1, x2 = x[0], x[1], x[2]
    inv_s0 = 0.0
    for kk in range(p):
        axx = 0.0
        axy = 0.0
        axz = 0.0
        ayy = 0.0
        ayz = 0.0
        azz = 0.0
        for l in range(kk + 1):
            u0, u1, u2 = x0[l], x1[l], x2[l]
            v0, v1, v2 = x0[kk - l], x1[kk - l], x2[kk - l]
            axx += u0 * v0
            axy += u0 * v1
            axz += u0 * v2
            ayy += u1 * v1
            ayz += u1 * v2
            azz += u2 * v2
        pxx[kk], pxy[kk], pxz[kk], pyy[kk], pyz[kk], pzz[kk] = axx, axy, axz, ayy, ayz, azz
        sk = axx + ayy + azz
        sr[kk] = sk
        tk = 0.0                                  # z^2 w7 and z^2 w9 without their l = 0 terms
        vk = 0.0
        if kk == 0:
            inv_s0 = 1.0 / sk
            w3[0] = sk ** -1.5
            w5[0] = w3[0] * inv_s0
            w7[0] = w5[0] * inv_s0
            w9[0] = w7[0] * inv_s0
        else:
            a3 = 0.0
            b3 = 0.0
            a5 = 0.0
            b5 = 0.0
            a7 = 0.0
            b7 = 0.0
            a9 = 0.0
            b9 = 0.0
            for l in range(kk):
                sl = sr[kk - l]
                a3 += w3[l] * sl
                b3 += (l * w3[l]) * sl
                a5 += w5[l] * sl
                b5 += (l * w5[l]) * sl
                a7 += w7[l] * sl
                b7 += (l * w7[l]) * sl
                a9 += w9[l] * sl
                b9 += (l * w9[l]) * sl
                zl = pzz[kk - l]
                tk += zl * w7[l]
                vk += zl * w9[l]
            w3[kk] = inv_s0 * (-1.5 * a3 + (0.5 / kk) * b3)
            w5[kk] = inv_s0 * (-2.5 * a5 + (1.5 / kk) * b5)
            w7[kk] = inv_s0 * (-3.5 * a7 + (2.5 / kk) * b7)
            w9[kk] = inv_s0 * (-4.5 * a9 + (3.5 / kk) * b9)
        tk += pzz[0] * w7[kk]
        vk += pzz[0] * w9[kk]
        h1 = k * (w5[kk] - 5.0 * tk) - mu * w3[kk]
        h2 = h1 + 2.0 * k * w5[kk]
        hxy[kk] = h1
        hz[kk] = h2
        q[kk] = 3.0 * mu * w5[kk] - 5.0 * k * w7[kk] + 35.0 * k * vk
        ax = 0.0
        ay = 0.0
        az = 0.0
        qxx = 0.0
        qxy = 0.0
        qxz = 0.0
        qyy = 0.0
        qyz = 0.0
        qzz = 0.0
        ux = 0.0
        uy = 0.0
        uz = 0.0
        for l in range(kk + 1):
            m = kk - l
            ql = q[m]
            wl = w7[m]
            ax += x0[l] * hxy[m]
            ay += x1[l] * hxy[m]
            az += x2[l] * hz[m]
            qxx += pxx[l] * ql
            qxy += pxy[l] * ql
            qxz += pxz[l] * ql
            qyy += pyy[l] * ql
            qyz += pyz[l] * ql
            qzz += pzz[l] * ql
            ux += pxz[l] * wl
            uy += pyz[l] * wl
            uz += pzz[l] * wl
        gxz = qxz - c10 * ux
        gyz = qyz - c10 * uy
        wk[25, kk] = h1 + qxx
        wk[26, kk] = qxy
        wk[27, kk] = gxz
        wk[28, kk] = qxy
        wk[29, kk] = h1 + qyy
        wk[30, kk] = gyz
        wk[31, kk] = gxz
        wk[32, kk] = gyz
        wk[33, kk] = h2 + qzz - 2.0 * c10 * uz
        fac = 1.0 / ((kk + 1.0) * (kk + 2.0))
        x0[kk + 2] = ax * fac
        x1[kk + 2] = ay * fac
        x2[kk + 2] = az * fac
        # Phi(K+2): the (3 x P) sums over l side by side (independent chains)
        acc = ph[:, :, kk + 2]
        acc[:, :] = 0.0
        for l in range(kk + 1):
            m = kk - l
            for i in range(3):
                g0 = wk[25 + 3 * i, l]
                g1 = wk[26 + 3 * i, l]
                g2 = wk[27 + 3 * i, l]
                for j in range(npar):
                    acc[i, j] += g0 * ph[0, j, m] + g1 * ph[1, j, m] + g2 * ph[2, j, m]
        if mu_col >= 0:
            acc[0, mu_col] += ax / mu
            acc[1, mu_col] += ay / mu
            acc[2, mu_col] += az / mu
        for i in range(3):
            for j in range(npar):
                acc[i, j] *= fac


@njit(**_KW)
def _all_finite(a):
    """True when every element of the 1-D ``a`` is finite (callers pass ``.ravel()``: one
    compiled signature for arrays of any rank)."""
    for v in a:
        if not math.isfinite(v):
            return False
    return True


@njit(**_KW)
def _step_offset(t, t1, h, direction):
    """(signed step, last?) with the numpy engine's end-time rule."""
    remaining = abs(t1 - t)
    last = not (h < remaining)
    hs = (t1 - t) if last else direction * h
    return hs, last


@njit(**_KW)
def _copy(dst, src):
    """``dst[:src.size] = src`` for 1-D arrays, by element. Callers pass flat views (``.ravel()``
    of C-contiguous arrays) instead of assigning slices of arrays: numba compiles each slice
    assignment with a formatted shape-mismatch error, seconds of compile for every array rank."""
    for i in range(src.size):
        dst[i] = src[i]


@njit(**_KW)
def _grow(a, cap):
    """``a`` (C-contiguous) in a new array of ``cap`` rows."""
    out = np.empty((cap,) + a.shape[1:])
    _copy(out.ravel(), a.ravel())
    return out


@njit(**_KW)
def propagate_state(r0, v0, t0, t1, p, mu, kj2, tol, max_steps):
    """Whole step loop, state only: (outcome, step times (N+1,), spectra (N, 3, p+2))."""
    n = p + 2
    x = np.zeros((3, n))
    s = np.zeros(p)
    z2 = np.zeros(p)
    w3 = np.zeros(p)
    w5 = np.zeros(p)
    w7 = np.zeros(p)
    hxy = np.zeros(p)
    hz = np.zeros(p)
    hp = np.empty(n)
    cap = 16
    coefs = np.empty((cap, 3, n))
    times = np.empty(cap + 1)
    times[0] = t0
    r = r0.copy()
    v = v0.copy()
    direction = 1.0 if t1 >= t0 else -1.0
    t = t0
    ns = 0
    outcome = OUTCOME_SUCCESS
    while t != t1:
        if ns >= max_steps:
            outcome = OUTCOME_STEP_LIMIT
            break
        for i in range(3):
            x[i, 0] = r[i]
            x[i, 1] = v[i]
        _series_state(x, p, mu, kj2, s, z2, w3, w5, w7, hxy, hz)
        if not _all_finite(x.ravel()):
            outcome = OUTCOME_NON_FINITE
            break
        hs, last = _step_offset(t, t1, _step_size(x, p, tol), direction)
        for k in range(n):
            hp[k] = hs ** float(k)
        for i in range(3):
            ri = 0.0
            vi = 0.0
            for k in range(n):
                ri += x[i, k] * hp[k]
            for k in range(1, n):
                vi += x[i, k] * (k * hp[k - 1])
            r[i] = ri
            v[i] = vi
        if not (_all_finite(r.ravel()) and _all_finite(v.ravel())):
            outcome = OUTCOME_NON_FINITE
            break
        if ns == cap:
            cap *= 2
            coefs = _grow(coefs, cap)
            times = _grow(times, cap + 1)
        _copy(coefs[ns].ravel(), x.ravel())
        ns += 1
        t = t1 if last else t + hs
        times[ns] = t
    return outcome, times[:ns + 1].copy(), coefs[:ns].copy()


@njit(**_KW)
def propagate_var(r0, v0, dr0, dv0, t0, t1, p, mu, kj2, mu_col, tol, max_steps):
    """Whole step loop with sensitivities: (outcome, times, spectra (N, 3, n), (N, 3, P, n))."""
    n = p + 2
    npar = dr0.shape[1]
    x = np.zeros((3, n))
    ph = np.zeros((3, npar, n))
    wk = np.zeros((34, p))
    hp = np.empty(n)
    cap = 16
    coefs = np.empty((cap, 3, n))
    sens = np.empty((cap, 3, npar, n))
    times = np.empty(cap + 1)
    times[0] = t0
    r = r0.copy()
    v = v0.copy()
    dr = dr0.copy()
    dv = dv0.copy()
    direction = 1.0 if t1 >= t0 else -1.0
    t = t0
    ns = 0
    outcome = OUTCOME_SUCCESS
    while t != t1:
        if ns >= max_steps:
            outcome = OUTCOME_STEP_LIMIT
            break
        for i in range(3):
            x[i, 0] = r[i]
            x[i, 1] = v[i]
            for j in range(npar):
                ph[i, j, 0] = dr[i, j]
                ph[i, j, 1] = dv[i, j]
        _series_var(x, ph, p, mu, kj2, mu_col, wk)
        if not (_all_finite(x.ravel()) and _all_finite(ph.ravel())):
            outcome = OUTCOME_NON_FINITE
            break
        hs, last = _step_offset(t, t1, _step_size(x, p, tol), direction)
        for k in range(n):
            hp[k] = hs ** float(k)
        for i in range(3):
            ri = 0.0
            vi = 0.0
            for k in range(n):
                ri += x[i, k] * hp[k]
            for k in range(1, n):
                vi += x[i, k] * (k * hp[k - 1])
            r[i] = ri
            v[i] = vi
            for j in range(npar):
                a = 0.0
                b = 0.0
                for k in range(n):
                    a += ph[i, j, k] * hp[k]
                for k in range(1, n):
                    b += ph[i, j, k] * (k * hp[k - 1])
                dr[i, j] = a
                dv[i, j] = b
        if not (_all_finite(r.ravel()) and _all_finite(v.ravel())):
            outcome = OUTCOME_NON_FINITE
            break
        if ns == cap:
            cap *= 2
            coefs = _grow(coefs, cap)
            sens = _grow(sens, cap)
            times = _grow(times, cap + 1)
        _copy(coefs[ns].ravel(), x.ravel())
        _copy(sens[ns].ravel(), ph.ravel())
        ns += 1
        t = t1 if last else t + hs
        times[ns] = t
    return outcome, times[:ns + 1].copy(), coefs[:ns].copy(), sens[:ns].copy()


@njit(**_KW)
def dense(coef, tb, idx, t, m):
    """Derivatives m and m+1 of the spectra coef (S, B, F, n) at times t: (B, M, 2, F).

    ``idx`` (M,) is the step of every time (sorted or not), ``tb`` the step start times.
    Horner's scheme per step, the samples of the step in the inner loop (contiguous).
    Implements seed 004 eq. 13 (the inverse transform) and its derivatives.
    """
    _, nb, nf, n = coef.shape
    nt = t.shape[0]
    out = np.zeros((nb, nt, 2, nf))
    fw = np.zeros((2, n))                    # K!/(K-d)! for d = m, m+1
    for d in range(2):
        for kk in range(m + d, n):
            g = 1.0
            for i in range(d + m):
                g *= kk - i
            fw[d, kk] = g
    # the samples grouped by step, in their order within a step: a stable counting sort of idx
    # (0 <= idx < S), the permutation np.argsort(idx, kind="mergesort") gives, without compiling
    # numba's mergesort
    start = np.zeros(coef.shape[0] + 1, np.int64)
    for j in range(nt):
        start[idx[j] + 1] += 1
    for j in range(coef.shape[0]):
        start[j + 1] += start[j]
    order = np.empty(nt, np.int64)
    for j in range(nt):
        order[start[idx[j]]] = j
        start[idx[j]] += 1
    dt = np.empty(nt)
    acc = np.empty(nt)
    a = 0
    while a < nt:
        s = idx[order[a]]
        b = a
        while b < nt and idx[order[b]] == s:
            dt[b - a] = t[order[b]] - tb[s]
            b += 1
        cnt = b - a
        for bb in range(nb):
            for f in range(nf):
                c = coef[s, bb, f]
                for d in range(2):
                    lo = m + d
                    if lo >= n:
                        continue                  # out stays 0
                    top = c[n - 1] * fw[d, n - 1]
                    for j in range(cnt):
                        acc[j] = top
                    for kk in range(n - 2, lo - 1, -1):
                        ck = c[kk] * fw[d, kk]
                        for j in range(cnt):
                            acc[j] = acc[j] * dt[j] + ck
                    for j in range(cnt):
                        out[bb, order[a + j], d, f] = acc[j]
        a = b
    return out


def ready(stm: bool) -> bool:
    """True when the loop kernel (with or without sensitivities) and :func:`dense` need no compiling.

    Compiled in this process already, or found in numba's on-disk cache for this source (an
    internal numba API; any surprise there counts as "not ready").
    """
    for kern in (propagate_var if stm else propagate_state, dense):
        if kern.signatures:
            continue
        try:
            if not kern._cache._cache_file._load_index():
                return False
        except Exception:                                 # noqa: BLE001 - numba internals moved
            return False
    return True


def compile_all() -> float:
    """Compile (or load) every kernel with the signatures the engine uses; CPU seconds taken.

    Under the engine's own locks (:func:`trackproc.dynamics.jit.compile_once`, families
    ``taylor`` and ``taylor-dense``, taken in that order as everywhere): a process propagating
    at the same time on a fresh cache waits and loads these kernels instead of compiling its own
    copy (~6 s of CPU)."""
    from trackproc.dynamics import jit

    c0 = time.process_time()
    r = np.array([7.0e6, 0.0, 0.0])
    v = np.array([0.0, 7.5e3, 0.0])
    e = np.zeros((3, 6))
    with jit.compile_once([propagate_state, propagate_var], "taylor"), jit.compile_once([dense], "taylor-dense"):
        _, tb, c = propagate_state(r, v, 0.0, 60.0, 24, 3.986e14, 0.0, 1e-15, 10)
        propagate_var(r, v, e, e, 0.0, 60.0, 24, 3.986e14, 0.0, -1, 1e-15, 10)
        dense(np.ascontiguousarray(c[:, None]), tb, np.zeros(2, dtype=np.int64), np.array([0.0, 1.0]), 0)
    return time.process_time() - c0


if __name__ == "__main__":
    import sys

    from trackproc.dynamics import jit, taylor_jit        # the module under its own name (cache)

    if not jit.enabled():
        sys.exit("trackproc: numba is not importable or TRACKPROC_JIT=0; nothing to compile")
    print(f"compiled Taylor kernels ready in {taylor_jit.compile_all():.1f} s CPU")
