"""The Taylor-series recurrences of two-body + J2 motion: one integration step's spectra.

With H = 1 s the spectrum of the position obeys ``X(K+2) = A(K) / ((K+1)(K+2))`` (seed 000
eq. 14, seed 004 eq. 6 written for the general case), A the spectrum of the acceleration built
from Cauchy products and the power rule (:mod:`trackproc.dynamics.taylor` gives the equations).

Four kernels compute these spectra, with one set of recurrences written in two layouts:
:func:`series_state` (a batch of trajectories, batch axis innermost, value only),
:func:`series_state_single` (one trajectory: every Cauchy sum of an order from one Gram-matrix
product plus scalar corrections, about 4x faster than the batch kernel with B = 1 — numpy pays
per call, not per flop), :func:`series_dual` (a batch with the sensitivities to the initial state
and mu, seed 004 eqs. 19-21) and :func:`series_var_single` (its single-trajectory fast path, the
variational recurrence). The kernels are separate on purpose: a generic kernel costs the
per-order Python overhead that dominates this engine (benchmarks/throughput.py), and the tests
(tests/dynamics/test_taylor.py) hold all four to the same numbers to rounding. Pure numpy; no state.
"""

from __future__ import annotations

import threading
from functools import lru_cache

import numpy as np

__all__ = ["series_state", "series_state_single", "series_dual", "series_var_single"]

#: Exponents of the powers of s = |r|^2 the recurrences need: w3, w5, w7 (w9 in the variational kernel).
_EXPONENTS = (-1.5, -2.5, -3.5)


@lru_cache(maxsize=32)
def _tables(order: int, n_pow: int):
    """Per-order constants: power-rule weights and 1/((K+1)(K+2))."""
    exps = np.array(_EXPONENTS[:n_pow])
    cw = [None]
    for k in range(1, order):
        l = np.arange(k, dtype=float)
        cw.append(np.ascontiguousarray((exps[:, None] * (k - l) - l) / k))
    k = np.arange(order, dtype=float)
    inv_fac = 1.0 / ((k + 1.0) * (k + 2.0))
    return exps, cw, inv_fac


def series_state(r0, v0, p, mu, kj2):
    """Position spectra (B, 3, p+2) of one step from r0, v0 (B, 3); value only.

    Works with the batch axis innermost (contiguous), so every contraction over the
    coefficient index is a multiply-add of whole batch vectors.

    Implements seed 004 eq. 6 (two-body spectrum, r^-3 by the power rule) with J2, batched.
    """
    b = r0.shape[0]
    n = p + 2
    j2 = kj2 != 0.0
    exps, cw, inv_fac = _tables(p, 3 if j2 else 1)
    einsum = np.einsum
    x = np.empty((3, n, b))
    x[:, 0] = r0.T
    x[:, 1] = v0.T
    s = np.empty((p, b))
    w = np.empty((exps.size, p, b))
    if j2:
        z2 = np.empty((p, b))
        h = np.empty((3, p, b))
        m2t = np.array([[-mu, kj2], [-mu, kj2], [-mu, 3.0 * kj2]])       # (3 coords, w3 w5)
        mt = -5.0 * kj2
        w7 = w[2]
        for k in range(p):
            xk = x[:, :k + 1]
            pr = einsum("ilb,ilb->ib", xk, x[:, k::-1])
            s[k] = pr.sum(0)
            z2[k] = pr[2]
            if k == 0:
                inv_s0 = 1.0 / s[0]
                w[:, 0] = s[0] ** exps[:, None]
            else:
                w[:, k] = einsum("alb,al,lb->ab", w[:, :k], cw[k], s[k:0:-1]) * inv_s0
            t = einsum("lb,lb->b", z2[:k + 1], w7[k::-1])
            hk = m2t @ w[:2, k]
            hk += mt * t
            h[:, k] = hk
            x[:, k + 2] = einsum("ilb,ilb->ib", xk, h[:, k::-1]) * inv_fac[k]
    else:
        w3 = w[0]
        fac = -mu * inv_fac
        for k in range(p):
            xk = x[:, :k + 1]
            s[k] = einsum("ilb,ilb->b", xk, x[:, k::-1])
            if k == 0:
                inv_s0 = 1.0 / s[0]
                w3[0] = s[0] ** exps[0]
            else:
                w3[k] = einsum("lb,l,lb->b", w3[:k], cw[k][0], s[k:0:-1]) * inv_s0
            x[:, k + 2] = einsum("ilb,lb->ib", xk, w3[k::-1]) * fac[k]
    return np.ascontiguousarray(x.transpose(2, 0, 1))


# Single-trajectory kernel. All series live as rows of one buffer F (row, coefficient); at
# order K one matrix product G = F[:, :K+1] @ F[:R, K::-1].T gives every Cauchy sum needed
# (with the order-K values not yet known still zero), and the few missing terms that involve
# the new order-K values are added in scalar arithmetic. The power-rule weights split as
# (a(K-l) - l)/K = a - (a+1) l/K, so its sum is two plain Cauchy sums (rows w and l*w).
# Same recurrences as series_state; about 4x faster for one trajectory (fewer numpy calls).
#   J2 rows: 0-2 x y z | 3 s | 4 w7 | 5 h_xy | 6 h_z | 7 w3 | 8 w5 | 9-11 l*w3 l*w5 l*w7 | 12 z^2
_G_J2_IDX = np.array([0 * 7 + 0, 1 * 7 + 1, 2 * 7 + 2, 7 * 7 + 3, 8 * 7 + 3, 4 * 7 + 3,
                      9 * 7 + 3, 10 * 7 + 3, 11 * 7 + 3, 12 * 7 + 4, 0 * 7 + 5, 1 * 7 + 5,
                      2 * 7 + 6])
#   two-body rows: 0-2 x y z | 3 s | 4 w3 | 5 l*w3
_G_2B_IDX = np.array([0 * 5 + 0, 1 * 5 + 1, 2 * 5 + 2, 4 * 5 + 3, 5 * 5 + 3, 0 * 5 + 4,
                      1 * 5 + 4, 2 * 5 + 4])


def series_state_single(r0, v0, p, mu, kj2):
    """Same result as :func:`series_state` for B = 1, with scalar bookkeeping per order.

    Implements seed 004 eq. 6 (two-body spectrum, r^-3 by the power rule) with J2.
    """
    n = p + 2
    x0, y0, z0 = (float(c) for c in r0[0])
    matmul = np.matmul
    if kj2 != 0.0:
        f = np.zeros((13, n))
        f[0:3, 0] = r0[0]
        f[0:3, 1] = v0[0]
        take = _G_J2_IDX
        k2 = 2.0 * kj2
        for k in range(p):
            g = matmul(f[:, :k + 1], f[:7, k::-1].T).take(take).tolist()
            sxx, syy, szz, gw3, gw5, gw7, glw3, glw5, glw7, gt, gax, gay, gaz = g
            sk = sxx + syy + szz
            if k == 0:
                inv_s0 = 1.0 / sk
                w30 = sk ** -1.5
                w50 = w30 * inv_s0
                w70 = w50 * inv_s0
                z20 = szz
                w3, w5, w7 = w30, w50, w70
                t = z20 * w70
            else:
                w3 = inv_s0 * (-1.5 * (gw3 + w30 * sk) + (0.5 / k) * glw3)
                w5 = inv_s0 * (-2.5 * (gw5 + w50 * sk) + (1.5 / k) * glw5)
                w7 = inv_s0 * (-3.5 * (gw7 + w70 * sk) + (2.5 / k) * glw7)
                t = gt + z20 * w7 + szz * w70
            hxy = kj2 * (w5 - 5.0 * t) - mu * w3
            hz = hxy + k2 * w5
            fac = 1.0 / ((k + 1.0) * (k + 2.0))
            f[3:13, k] = (sk, w7, hxy, hz, w3, w5, k * w3, k * w5, k * w7, szz)
            f[0:3, k + 2] = ((gax + x0 * hxy) * fac, (gay + y0 * hxy) * fac,
                             (gaz + z0 * hz) * fac)
    else:
        f = np.zeros((6, n))
        f[0:3, 0] = r0[0]
        f[0:3, 1] = v0[0]
        take = _G_2B_IDX
        for k in range(p):
            g = matmul(f[:, :k + 1], f[:5, k::-1].T).take(take).tolist()
            sxx, syy, szz, gw3, glw3, gax, gay, gaz = g
            sk = sxx + syy + szz
            if k == 0:
                inv_s0 = 1.0 / sk
                w30 = sk ** -1.5
                w3 = w30
            else:
                w3 = inv_s0 * (-1.5 * (gw3 + w30 * sk) + (0.5 / k) * glw3)
            fac = -mu / ((k + 1.0) * (k + 2.0))
            f[3:6, k] = (sk, w3, k * w3)
            f[0:3, k + 2] = ((gax + x0 * w3) * fac, (gay + y0 * w3) * fac, (gaz + z0 * w3) * fac)
    return f[None, 0:3].copy()


# Single-trajectory sensitivity kernel (the fast path of series_dual for B = 1). The
# gradient spectra dX(K)/dp are the Taylor coefficients of Phi(t) = d r(t)/d p, so instead of
# carrying a gradient through every rule they follow from the variational recurrence
#     Phi(K+2) = [sum_{l=0..K} G(l) Phi(K-l) + delta_{p,mu} A(K)/mu] / ((K+1)(K+2)),
# with the spectrum of the gravity gradient G = d a/d r,
#     G = diag(f_xy, f_xy, f_z) + q r r^T - 10 k w7 z (r e_z^T + e_z r^T),
#     f_xy = h_xy, f_z = h_z,  q = 3 mu w5 - 5 k w7 + 35 k z^2 w9,
# built by the same Gram-matrix scheme as series_state_single (one matrix product and
# scalar corrections per order) plus one contraction for Phi. Same numbers as series_dual
# to rounding (tested), about 3x faster for one trajectory.
#   rows: 0-2 x y z | 3 s | 4-7 w3 w5 w7 w9 | 8-11 l*w3 .. l*w9 | 12-17 Pxx Pxy Pxz Pyy Pyz Pzz
#         | 18 h_xy | 19 h_z | 20 q
def _gidx(pairs, r=21):
    return np.array([a * r + b for a, b in pairs])


_G_VAR_IDX = _gidx([(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2),          # P_ij
                    (4, 3), (5, 3), (6, 3), (7, 3), (8, 3), (9, 3), (10, 3), (11, 3),  # powers
                    (17, 6), (17, 7),                                        # z^2 w7, z^2 w9
                    (0, 18), (1, 18), (2, 19),                               # accelerations
                    (20, 12), (20, 13), (20, 14), (20, 15), (20, 16), (20, 17),  # q P_ij
                    (6, 14), (6, 16), (6, 17)])                              # w7 P_iz


class _VarWork(threading.local):
    """Per-thread work arrays of :func:`series_var_single`, with the views every order uses made
    once per (p, P): the kernel's cost is numpy's per-call overhead, so each order makes three
    numpy calls for the Cauchy sums, one ``put`` of its values and one product for Phi."""

    def __init__(self):
        self.by_shape = {}

    def get(self, p, npar):
        w = self.by_shape.get((p, npar))
        if w is None:
            w = self.by_shape[(p, npar)] = _var_work(p, npar)
        return w


def _var_work(p, npar):
    n = p + 2
    # one buffer: F (21, n), then G as (3, n, 3) so that G(0..K) is a contiguous (3, 3(K+1)) view
    buf = np.zeros(30 * n)
    f = buf[:21 * n].reshape(21, n)
    gs = buf[21 * n:].reshape(3, n, 3)
    phr = np.zeros((n, 3, npar))
    # flat positions of one order's values: x y z at column K+2, rows 3-20 at column K, G(K)
    rows = np.arange(3, 21)
    put = [np.concatenate([np.arange(3) * n + k + 2, rows * n + k,
                           21 * n + (np.arange(3)[:, None] * 3 * n + 3 * k + np.arange(3)).ravel()])
           for k in range(p)]
    views = [(f[:, :k + 1], f[:, k::-1].T, gs[:, :k + 1].reshape(3, 3 * (k + 1)),
              phr[n - 1 - k:].reshape(3 * (k + 1), npar), phr[n - 3 - k]) for k in range(p)]
    return buf, f, phr, put, views


_VAR_WORK = _VarWork()


def series_var_single(r0, v0, dr0, dv0, p, mu, kj2, mu_slot):
    """Same result as :func:`series_dual` for B = 1: (1, 3, 1+P, p+2). Implements seed 004
    eqs. 18-21 (two-dimensional DT, first order in the parameters)."""
    n = p + 2
    npar = dr0.shape[2]
    x0, y0, z0 = (float(c) for c in r0[0])
    buf, f, phr, put, views = _VAR_WORK.get(p, npar)
    buf[:] = 0.0
    f[0:3, 0] = r0[0]
    f[0:3, 1] = v0[0]
    # G(l) in the buffer's (3, n, 3) block and Phi(K) at row n-1-K of phr (reversed): the
    # convolution over l of order K is then one matrix product of two contiguous views,
    # (3, 3(K+1)) @ (3(K+1), P).
    phr[n - 1] = dr0[0]
    phr[n - 2] = dv0[0]
    mu_col = None if mu_slot is None else mu_slot - 1
    k = kj2
    matmul, take = np.matmul, _G_VAR_IDX
    c10 = 10.0 * k
    for kk in range(p):
        fa, fb, gk, phk, acc = views[kk]
        g = matmul(fa, fb).take(take).tolist()
        (pxx, pxy, pxz, pyy, pyz, pzz, gw3, gw5, gw7, gw9, glw3, glw5, glw7, glw9,
         gt, gv, gax, gay, gaz, gq0, gq1, gq2, gq3, gq4, gq5, gu0, gu1, gu2) = g
        sk = pxx + pyy + pzz
        if kk == 0:
            inv_s0 = 1.0 / sk
            w3 = w30 = sk ** -1.5
            w5 = w50 = w30 * inv_s0
            w7 = w70 = w50 * inv_s0
            w9 = w90 = w70 * inv_s0
            p0 = (pxx, pxy, pxz, pyy, pyz, pzz)
            t = pzz * w70
            v = pzz * w90
        else:
            w3 = inv_s0 * (-1.5 * (gw3 + w30 * sk) + (0.5 / kk) * glw3)
            w5 = inv_s0 * (-2.5 * (gw5 + w50 * sk) + (1.5 / kk) * glw5)
            w7 = inv_s0 * (-3.5 * (gw7 + w70 * sk) + (2.5 / kk) * glw7)
            w9 = inv_s0 * (-4.5 * (gw9 + w90 * sk) + (3.5 / kk) * glw9)
            t = gt + p0[5] * w7 + pzz * w70
            v = gv + p0[5] * w9 + pzz * w90
        hxy = k * (w5 - 5.0 * t) - mu * w3
        hz = hxy + 2.0 * k * w5
        ax, ay, az = gax + x0 * hxy, gay + y0 * hxy, gaz + z0 * hz
        q = 3.0 * mu * w5 - 5.0 * k * w7 + 35.0 * k * v
        if kk == 0:
            q0 = q
            qp0, qp1, qp2, qp3, qp4, qp5 = (q0 * c for c in p0)
            ux, uy, uz = w70 * pxz, w70 * pyz, w70 * pzz
        else:
            qp0 = gq0 + q0 * pxx + q * p0[0]
            qp1 = gq1 + q0 * pxy + q * p0[1]
            qp2 = gq2 + q0 * pxz + q * p0[2]
            qp3 = gq3 + q0 * pyy + q * p0[3]
            qp4 = gq4 + q0 * pyz + q * p0[4]
            qp5 = gq5 + q0 * pzz + q * p0[5]
            ux = gu0 + w70 * pxz + w7 * p0[2]
            uy = gu1 + w70 * pyz + w7 * p0[4]
            uz = gu2 + w70 * pzz + w7 * p0[5]
        gxz = qp2 - c10 * ux
        gyz = qp4 - c10 * uy
        fac = 1.0 / ((kk + 1.0) * (kk + 2.0))
        buf.put(put[kk], (ax * fac, ay * fac, az * fac,
                        sk, w3, w5, w7, w9, kk * w3, kk * w5, kk * w7, kk * w9,
                        pxx, pxy, pxz, pyy, pyz, pzz, hxy, hz, q,
                        hxy + qp0, qp1, gxz, qp1, hxy + qp3, gyz,
                        gxz, gyz, hz + qp5 - 2.0 * c10 * uz))
        matmul(gk, phk, out=acc)
        if mu_col is not None:
            acc[:, mu_col] += (ax / mu, ay / mu, az / mu)
        acc *= fac
    out = np.empty((1, 3, npar + 1, n))
    out[0, :, 0] = f[0:3]
    out[0, :, 1:] = phr[::-1].transpose(1, 2, 0)
    return out


def series_dual(r0, v0, dr0, dv0, p, mu, kj2, mu_slot):
    """Position spectra with first-order sensitivities: (B, 3, 1+P, p+2).

    Slot 0 of the third axis is the value, slots 1..P the gradient with respect to the
    parameters (seeded by dr0, dv0 of shape (B, 3, P)); ``mu_slot`` (1-based slot or None)
    receives the explicit dependence on mu. Truncated dual arithmetic on every rule used by
    :func:`series_state` (seed 004 eqs. 19-21 to first order): for a product,
    ``(U*V)_j = U_j*V_0 + U_0*V_j``; for the power rule, the relation ``s w' = a s' w`` that
    defines it holds for dual-valued series too, and the division by S(0) is a dual division.
    Batch axis innermost, as in :func:`series_state`.
    """
    b, _, np_ = dr0.shape
    nj = np_ + 1
    n = p + 2
    j2 = kj2 != 0.0
    exps, cw, inv_fac = _tables(p, 3 if j2 else 1)
    na = exps.size
    einsum = np.einsum
    x = np.empty((3, nj, n, b))
    x[:, 0, 0] = r0.T
    x[:, 1:, 0] = dr0.transpose(1, 2, 0)
    x[:, 0, 1] = v0.T
    x[:, 1:, 1] = dv0.transpose(1, 2, 0)
    s = np.empty((nj, p, b))
    w = np.empty((na, nj, p, b))
    two = np.full((nj, 1), 2.0)
    two[0] = 1.0
    if j2:
        z2 = np.empty((nj, p, b))
        h = np.empty((3, nj, p, b))
        m2 = np.array([[-mu, -mu, -mu], [kj2, kj2, 3.0 * kj2]])
        mt = np.full((3, 1, 1), -5.0 * kj2)
    for k in range(p):
        xk = x[:, :, :k + 1]
        x0r = x[:, 0, k::-1]
        if j2:
            pr = einsum("ijlb,ilb->ijb", xk, x0r)
            pr *= two
            s[:, k] = pr.sum(0)
            z2[:, k] = pr[2]
        else:
            sk = einsum("ijlb,ilb->jb", xk, x0r)
            sk *= two
            s[:, k] = sk
        if k == 0:
            s00 = s[0, 0]
            inv_s0 = 1.0 / s00
            ds0 = s[1:, 0] * inv_s0                                   # (P, B)
            w0 = s00 ** exps[:, None]                                 # (na, B)
            w[:, 0, 0] = w0
            w[:, 1:, 0] = (exps[:, None] * w0)[:, None, :] * ds0
        else:
            nk = einsum("ajlb,al,lb->ajb", w[:, :, :k], cw[k], s[0, k:0:-1])
            nk[:, 1:] += einsum("alb,al,jlb->ajb", w[:, 0, :k], cw[k], s[1:, k:0:-1])
            nk *= inv_s0
            nk[:, 1:] -= nk[:, :1] * ds0
            w[:, :, k] = nk
        if j2:
            w7 = w[2]
            t = einsum("jlb,lb->jb", z2[:, :k + 1], w7[0, k::-1])
            t[1:] += einsum("lb,jlb->jb", z2[0, :k + 1], w7[1:, k::-1])
            hk = einsum("ajb,ai->ijb", w[:2, :, k], m2)
            hk += mt * t
            if mu_slot is not None:
                hk[:, mu_slot] += hk[:, 0] * (1.0 / mu)
            h[:, :, k] = hk
            a = einsum("ijlb,ilb->ijb", xk, h[:, 0, k::-1])
            a[:, 1:] += einsum("ilb,ijlb->ijb", x[:, 0, :k + 1], h[:, 1:, k::-1])
            a *= inv_fac[k]
        else:
            w3 = w[0]
            a = einsum("ijlb,lb->ijb", xk, w3[0, k::-1])
            a[:, 1:] += einsum("ilb,jlb->ijb", x[:, 0, :k + 1], w3[1:, k::-1])
            a *= -mu * inv_fac[k]
            if mu_slot is not None:
                a[:, mu_slot] += a[:, 0] * (1.0 / mu)
        x[:, :, k + 2] = a
    return np.ascontiguousarray(x.transpose(3, 0, 1, 2))
