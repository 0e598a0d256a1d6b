"""Adaptive Taylor (DT) integrator for two-body + J2 motion, with dense output and the STM.

The equations of motion, in a quasi-inertial frame whose z axis is the Earth's rotation
axis (the caller converts frames; README "Units, sign conventions, time and frames")::

    r'' = -mu r / |r|^3 + a_J2,
    a_J2 = -3/2 J2 mu Re^2 / r^5 [x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]

are turned into a *P-model* (seed 000 eq. 14): with H = 1 s the spectrum of the position
obeys ``X(K+2) = A(K) / ((K+1)(K+2))`` where A is the spectrum of the acceleration (seed 004
eq. 6, written for the general case instead of the paper's constant r):

    s = x*x + y*y + z*z                 (Cauchy products, docs/equations.md, notation)
    w3, w5, w7 = s^(-3/2), s^(-5/2), s^(-7/2)   (power rule, docs/equations.md, notation)
    T = z*z * w7
    h_xy = -mu w3 + k (w5 - 5 T),  h_z = h_xy + 2 k w5,   k = -3/2 J2 mu Re^2
    A_x = x * h_xy,  A_y = y * h_xy,  A_z = z * h_z

For two-body motion only ``h = -mu w3``. Each order K costs a handful of vectorised
contractions (only the new K-th coefficient of each product is computed), over any number of
trajectories at once (batch axis).

Step size and order follow Jorba & Zou (2005, Exp. Math. 14, 99), as heyoka does, with two
deliberate differences. The step is
``h = min over k in {p-1, p} of (tol * scale / |c_k|)^(1/k) * exp(-0.7/(p-1))``, with c_k the
k-th Taylor coefficients of position and of velocity (each against its own
``scale = max(1, |.|_inf)``: combined absolute/relative tolerance, per-vector so that metres
and m/s are not mixed); heyoka writes ``rho e^-2`` for ``rho tol^(1/p)``, equal when
``p = -ln(tol)/2``. The order is :func:`default_order` (24 at tol = 1e-15, where heyoka takes
19): numpy pays per order, not per flop, and a near-circular 600 s LEO pass then fits in one
step. In batch mode every trajectory takes the same (smallest) step. The step size is chosen
from the state only, never from the sensitivities.

Three kernels compute the same spectra: one trajectory with scalar bookkeeping
(:func:`_series_state_single`, the fast path), a batch with the batch axis innermost
(:func:`_series_state`), and the sensitivity kernel (:func:`_series_dual`, any batch).

Dense output: every step keeps its position spectrum; the state at any set of times is the
inverse transform (one matrix product per step: powers of the offsets x coefficients),
without re-integration. Velocity and higher derivatives are derivatives of the same series.

Sensitivities (seed 004 eqs. 19-21, kept to the first order in the parameters): every
coefficient carries its gradient with respect to the initial state (and optionally mu); the
same recurrences, applied to these truncated dual numbers, give the state transition matrix
Phi(t, t0) and d state/d mu, dense like the state.

Limits: two-body and J2 only; the frame must have its z axis along the J2 axis; times are
plain float seconds (about 1e-16 relative resolution, so keep t0 near the data, not at
J2000); no event detection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from functools import lru_cache

import numpy as np

from trackproc import vocabulary
from trackproc.constants import J2, MU_EARTH, RE_EARTH
from trackproc.errors import ProcessingError

__all__ = ["Outcome", "Propagation", "propagate", "default_order", "acceleration", "FORCES",
           "STATE_PARAMETERS"]

FORCES = vocabulary.FORCES
STATE_PARAMETERS = vocabulary.STATE_NAMES
_EXPONENTS = (-1.5, -2.5, -3.5)


class Outcome(Enum):
    """How a propagation ended."""

    SUCCESS = "success"          #: the requested end time was reached
    STEP_LIMIT = "step_limit"    #: ``max_steps`` steps were taken before the end time
    NON_FINITE = "non_finite"    #: a coefficient became NaN or infinite (e.g. r = 0)


def default_order(tol: float) -> int:
    """Taylor order for a tolerance: ``ceil(-2/3 ln(tol))`` (24 at tol = 1e-15).

    With the step ``h = rho tol^(1/p)`` the work per unit time is ``c(p) / tol^(1/p)``. Jorba &
    Zou (2005) and heyoka count floating-point work, ``c ~ p^2``, whose minimum is
    ``p = -ln(tol)/2`` (heyoka uses ``ceil(-ln(tol)/2 + 1)``, 19 at 1e-15). In numpy the cost of
    an order is interpreter overhead (``c ~ p``, optimum ``-ln tol``) for one trajectory and
    flops (``c ~ p^2``) for large batches; ``c ~ p^1.5`` in between gives ``-2/3 ln(tol)``.
    Near-circular orbits gain more: their series converge far beyond the step.
    """
    return max(3, math.ceil(-2.0 * math.log(tol) / 3.0))


def acceleration(r_m, *, force: str = "j2", mu_m3_s2: float = MU_EARTH, j2: float = J2,
                 re_m: float = RE_EARTH) -> np.ndarray:
    """Acceleration (m/s^2) of the force model at positions ``r_m`` shaped ``(..., 3)``.

    The right-hand side whose spectrum the integrator builds (:func:`trackproc.dynamics.gravity.acceleration`);
    used by tests and by conventional integrators for comparison.
    """
    from trackproc.dynamics import gravity

    if force not in FORCES:
        raise ValueError(f"unknown force model {force!r}; expected one of {FORCES}")
    return gravity.acceleration(r_m, mu_m3_s2, j2 if force == "j2" else 0.0, re_m)


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


def _series_state(r0, v0, p, mu, kj2):
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
# Same recurrences as _series_state; about 4x faster for one trajectory (fewer numpy calls).
#   J2 rows: 0-2 x y z | 3 s | 4 w7 | 5 h_xy | 6 h_z | 7 w3 | 8 w5 | 9-11 l*w3 l*w5 l*w7 | 12 z^2
_G_J2_IDX = np.array([0 * 7 + 0, 1 * 7 + 1, 2 * 7 + 2, 7 * 7 + 3, 8 * 7 + 3, 4 * 7 + 3,
                      9 * 7 + 3, 10 * 7 + 3, 11 * 7 + 3, 12 * 7 + 4, 0 * 7 + 5, 1 * 7 + 5,
                      2 * 7 + 6])
#   two-body rows: 0-2 x y z | 3 s | 4 w3 | 5 l*w3
_G_2B_IDX = np.array([0 * 5 + 0, 1 * 5 + 1, 2 * 5 + 2, 4 * 5 + 3, 5 * 5 + 3, 0 * 5 + 4,
                      1 * 5 + 4, 2 * 5 + 4])


def _series_state_single(r0, v0, p, mu, kj2):
    """Same result as :func:`_series_state` for B = 1, with scalar bookkeeping per order.

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


# Single-trajectory sensitivity kernel (the fast path of _series_dual for B = 1). The
# gradient spectra dX(K)/dp are the Taylor coefficients of Phi(t) = d r(t)/d p, so instead of
# carrying a gradient through every rule they follow from the variational recurrence
#     Phi(K+2) = [sum_{l=0..K} G(l) Phi(K-l) + delta_{p,mu} A(K)/mu] / ((K+1)(K+2)),
# with the spectrum of the gravity gradient G = d a/d r,
#     G = diag(f_xy, f_xy, f_z) + q r r^T - 10 k w7 z (r e_z^T + e_z r^T),
#     f_xy = h_xy, f_z = h_z,  q = 3 mu w5 - 5 k w7 + 35 k z^2 w9,
# built by the same Gram-matrix scheme as _series_state_single (one matrix product and
# scalar corrections per order) plus one contraction for Phi. Same numbers as _series_dual
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


def _series_var_single(r0, v0, dr0, dv0, p, mu, kj2, mu_slot):
    """Same result as :func:`_series_dual` for B = 1: (1, 3, 1+P, p+2)."""
    n = p + 2
    npar = dr0.shape[2]
    x0, y0, z0 = (float(c) for c in r0[0])
    f = np.zeros((21, n))
    f[0:3, 0] = r0[0]
    f[0:3, 1] = v0[0]
    # G(l) as gs[:, l, :] and Phi(K) at row n-1-K (reversed): the convolution over l of order K
    # is then one matrix product of two contiguous views, (3, 3(K+1)) @ (3(K+1), P).
    gs = np.zeros((3, n, 3))
    phr = np.zeros((n, 3, npar))
    phr[n - 1] = dr0[0]
    phr[n - 2] = dv0[0]
    mu_col = None if mu_slot is None else mu_slot - 1
    k = kj2
    matmul, take = np.matmul, _G_VAR_IDX
    for kk in range(p):
        g = matmul(f[:, :kk + 1], f[:, kk::-1].T).take(take).tolist()
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
        pk = (pxx, pxy, pxz, pyy, pyz, pzz)
        if kk == 0:
            q0 = q
            qp = [q0 * c for c in p0]
            ux, uy, uz = w70 * pxz, w70 * pyz, w70 * pzz
        else:
            qp = [gq + q0 * c + q * c0 for gq, c, c0 in
                  zip((gq0, gq1, gq2, gq3, gq4, gq5), pk, p0)]
            ux = gu0 + w70 * pxz + w7 * p0[2]
            uy = gu1 + w70 * pyz + w7 * p0[4]
            uz = gu2 + w70 * pzz + w7 * p0[5]
        c10 = 10.0 * k
        gxz = qp[2] - c10 * ux
        gyz = qp[4] - c10 * uy
        gs[:, kk] = ((hxy + qp[0], qp[1], gxz), (qp[1], hxy + qp[3], gyz),
                     (gxz, gyz, hz + qp[5] - 2.0 * c10 * uz))
        fac = 1.0 / ((kk + 1.0) * (kk + 2.0))
        f[3:21, kk] = (sk, w3, w5, w7, w9, kk * w3, kk * w5, kk * w7, kk * w9,
                       pxx, pxy, pxz, pyy, pyz, pzz, hxy, hz, q)
        f[0:3, kk + 2] = (ax * fac, ay * fac, az * fac)
        m = 3 * (kk + 1)
        acc = matmul(gs[:, :kk + 1].reshape(3, m), phr[n - 1 - kk:].reshape(m, npar))
        if mu_col is not None:
            acc[:, mu_col] += (ax / mu, ay / mu, az / mu)
        acc *= fac
        phr[n - 3 - kk] = acc
    out = np.empty((1, 3, npar + 1, n))
    out[0, :, 0] = f[0:3]
    out[0, :, 1:] = phr[::-1].transpose(1, 2, 0)
    return out


def _series_dual(r0, v0, dr0, dv0, p, mu, kj2, mu_slot):
    """Position spectra with first-order sensitivities: (B, 3, 1+P, p+2).

    Slot 0 of the third axis is the value, slots 1..P the gradient with respect to the
    parameters (seeded by dr0, dv0 of shape (B, 3, P)); ``mu_slot`` (1-based slot or None)
    receives the explicit dependence on mu. Truncated dual arithmetic on every rule used by
    :func:`_series_state` (seed 004 eqs. 19-21 to first order): for a product,
    ``(U*V)_j = U_j*V_0 + U_0*V_j``; for the power rule, the relation ``s w' = a s' w`` that
    defines it holds for dual-valued series too, and the division by S(0) is a dual division.
    Batch axis innermost, as in :func:`_series_state`.
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


class _PerOrder(dict):
    def __init__(self, fn):
        super().__init__()
        self.fn = fn

    def __missing__(self, p):
        self[p] = v = self.fn(p)
        return v


_ORDER_FACTORS = _PerOrder(lambda p: np.array([1.0, 1.0, float(p), p + 1.0]))
_INV_K = _PerOrder(lambda p: np.array([1.0 / (p - 1), 1.0 / p, 1.0 / (p - 1), 1.0 / p]))


def _step_size(x, p, tol):
    """Jorba-Zou step (>= 0, may be inf) common to the batch, from value spectra (B, 3, p+2)."""
    a = np.abs(x[:, :, [0, 1, p - 1, p, p + 1]]).max(axis=1)          # (B, 5) max over x, y, z
    lt = math.log(tol)
    if a.shape[0] == 1:                     # one trajectory: the same formula in scalar arithmetic
        r, v, c1, c2, c3 = a[0].tolist()
        lr, lv = math.log(max(1.0, r)), math.log(max(1.0, v))
        cand = math.inf
        # |c_k| for position k = p-1, p and velocity k = p-1, p (V(k) = (k+1) X(k+1))
        for c, lo, k in ((c1, lr, p - 1), (c2, lr, p), (c2 * p, lv, p - 1), (c3 * (p + 1.0), lv, p)):
            if c > 0.0:
                cand = min(cand, (lt + lo - math.log(c)) / k)
        return math.exp(cand - 0.7 / (p - 1)) if cand < math.inf else math.inf
    lo = np.log(np.maximum(1.0, a[:, :2]))                             # (B, 2): r, v scale
    with np.errstate(divide="ignore"):
        hi = np.log(a[:, [2, 3, 3, 4]] * _ORDER_FACTORS[p])
    cand = ((lt + lo[:, [0, 0, 1, 1]] - hi) * _INV_K[p]).min()    # log (tol scale/|c_k|)^(1/k)
    return math.exp(float(cand) - 0.7 / (p - 1))


def _powers(dt, n):
    """Powers ``dt^k``, k = 0..n-1, shape (n, M), by doubling (log2 n vector products)."""
    p = np.empty((n, dt.size))
    p[0] = 1.0
    if n > 1:
        p[1] = dt
    k = 2
    while k < n:
        j = min(k, n - k)
        np.multiply(p[:j], p[k - 1] * dt, out=p[k:k + j])
        k += j
    return p


@lru_cache(maxsize=64)
def _deriv_factors(n, m):
    """(2, max(n-m,1)): K!/(K-d)! for K = d..n-1 at power K-d, d = m and m+1."""
    nm = max(n - m, 1)
    out = np.zeros((2, nm))
    for i, d in enumerate((m, m + 1)):
        for j in range(max(n - d, 0)):
            out[i, j] = math.perm(j + d, d)
    return out


@dataclass(frozen=True, eq=False)
class Propagation:
    """Result of :func:`propagate`: the outcome and every step's spectra (dense output).

    Attributes
    ----------
    outcome : Outcome
    step_times_s : array ``(n_steps + 1,)``
        Step boundaries, s (decreasing for a backward propagation); ``step_times_s[-1]`` is the
        time reached.
    coefficients : array ``(n_steps, B, 3, p + 2)``
        Position spectra of each step with H = 1 s around the step's start (the velocity is
        their derivative). B = 1 for a single trajectory.
    sensitivities : array ``(n_steps, B, 3, P, p + 2)`` or None
        Spectra of d position / d parameter, parameters named in ``parameters``.
    order, tol, force, mu_m3_s2, j2, re_m : the settings used.
    batch : bool
        True when the initial state had a leading batch axis (outputs keep it).

    Evaluation (dense output, no re-integration): :meth:`state` (and its time derivatives),
    :meth:`stm`, :meth:`jacobian`, :meth:`dstate_dmu` at any times inside the interval covered.

    Examples
    --------
    A circular orbit of radius 7000 km comes back after one period:

    >>> import numpy as np
    >>> from trackproc.constants import MU_EARTH
    >>> v = np.sqrt(MU_EARTH / 7.0e6); period = 2 * np.pi * 7.0e6 / v
    >>> res = propagate([7.0e6, 0, 0, 0, v, 0], 0.0, period, force="two-body")
    >>> res.outcome.value, res.n_steps
    ('success', 4)
    >>> bool(np.abs(res.state(period)[:3] - [7.0e6, 0, 0]).max() < 1e-6)
    True
    >>> res.state(np.linspace(0.0, 600.0, 601)).shape
    (601, 6)
    """

    outcome: Outcome
    step_times_s: np.ndarray
    coefficients: np.ndarray
    sensitivities: np.ndarray | None
    parameters: tuple
    order: int
    tol: float
    force: str
    mu_m3_s2: float
    j2: float
    re_m: float
    batch: bool

    # -- summary -----------------------------------------------------------------------------
    @property
    def n_steps(self) -> int:
        return self.coefficients.shape[0]

    @property
    def step_sizes_s(self) -> np.ndarray:
        return np.diff(self.step_times_s)

    @property
    def t0_s(self) -> float:
        return float(self.step_times_s[0])

    @property
    def t_end_s(self) -> float:
        return float(self.step_times_s[-1])

    def raise_for_outcome(self) -> "Propagation":
        """Raise :class:`ProcessingError` unless the end time was reached; return self."""
        if self.outcome is not Outcome.SUCCESS:
            raise ProcessingError(
                f"Taylor propagation stopped ({self.outcome.value}) at t = {self.t_end_s} s "
                f"after {self.n_steps} steps",
                {"outcome": self.outcome.value, "t_reached_s": self.t_end_s,
                 "steps": self.n_steps})
        return self

    # -- dense output ------------------------------------------------------------------------
    def _locate(self, t):
        """Step index of every time in ``t`` (1-D); ValueError outside the interval."""
        tb = self.step_times_s
        if self.n_steps == 0:
            raise ValueError("no step was taken; nothing to evaluate")
        lo, hi = (tb[0], tb[-1]) if tb[-1] >= tb[0] else (tb[-1], tb[0])
        slack = 8 * np.finfo(float).eps * max(abs(lo), abs(hi), 1.0)
        tmin, tmax = (t.min(), t.max()) if t.size else (lo, hi)
        if not (lo - slack <= tmin and tmax <= hi + slack):
            raise ValueError(f"times must lie in the propagated interval [{lo}, {hi}] s; "
                             f"found [{tmin}, {tmax}]")
        if self.n_steps == 1:
            return None
        if tb[-1] >= tb[0]:
            idx = np.searchsorted(tb, t, side="right") - 1
        else:
            idx = np.searchsorted(-tb, -t, side="right") - 1
        return np.clip(idx, 0, self.n_steps - 1)

    def _dense(self, coef, t_s, m):
        """Derivatives m and m+1 of spectra coef (n_steps, B, F, n) at t_s.

        Returns (B, M, 2, F) and the shape of t_s. One matrix product per step touched:
        powers of the offsets (M, n) x derivative spectra (n, 2F).
        """
        t = np.asarray(t_s, dtype=float)
        tf = t.reshape(-1)
        idx = self._locate(tf)
        _, nb, nf, n = coef.shape
        tb = self.step_times_s
        nm = max(n - m, 1)
        fac = _deriv_factors(n, m)                                    # (2, nm)
        if tf.size == 0:
            return np.empty((nb, 0, 2, nf)), t.shape
        if idx is None:
            groups = [(0, None)]
        elif np.all(idx[1:] >= idx[:-1]):                            # sorted: slices
            cuts = np.flatnonzero(np.diff(idx)) + 1
            starts = np.concatenate([[0], cuts])
            ends = np.concatenate([cuts, [idx.size]])
            groups = [(int(idx[a]), slice(int(a), int(b))) for a, b in zip(starts, ends)]
        else:
            order = np.argsort(idx, kind="stable")
            sidx = idx[order]
            cuts = np.flatnonzero(np.diff(sidx)) + 1
            groups = [(int(idx[g[0]]), g) for g in np.split(order, cuts)]
        out = None if len(groups) == 1 else np.empty((nb, tf.size, 2, nf))
        for s, sel in groups:
            cs = coef[s]                                              # (B, F, n)
            cd = np.zeros((nb, 2, nf, nm))
            if m < n:
                cd[:, 0, :, :n - m] = cs[..., m:] * fac[0, :n - m]
            if m + 1 < n:
                cd[:, 1, :, :n - m - 1] = cs[..., m + 1:] * fac[1, :n - m - 1]
            dt = (tf if sel is None else tf[sel]) - tb[s]
            # one 2-D product of contiguous operands (BLAS), (B*2F, nm) @ (nm, M)
            res = (cd.reshape(nb * 2 * nf, nm) @ _powers(dt, nm)).reshape(nb, 2, nf, -1)
            res = res.transpose(0, 3, 1, 2)
            if out is None:
                out = res
            else:
                out[:, sel] = res
        return out, t.shape

    def _finish(self, arr, tshape, tail):
        """(B, M, ...) -> (B?,) + tshape + tail."""
        shape = tshape + tail
        if self.batch:
            return arr.reshape((arr.shape[0],) + shape)
        return arr.reshape(shape)

    def state(self, t_s, derivative: int = 0) -> np.ndarray:
        """State ``[r, v]`` (m, m/s) at times ``t_s``, or its ``derivative``-th time derivative.

        Shape ``t_s.shape + (6,)``, with a leading batch axis in batch mode. ``derivative=1``
        gives ``[v, a]``, and so on (derivatives of the step's series, exact to the tolerance).
        Times must lie inside the propagated interval.
        """
        m = int(derivative)
        if m < 0:
            raise ValueError(f"derivative must be >= 0; found {m}")
        out, tshape = self._dense(self.coefficients, t_s, m)
        return self._finish(out, tshape, (6,))

    def jacobian(self, t_s) -> np.ndarray:
        """d state(t) / d parameters, shape ``t_s.shape + (6, P)`` (parameters in ``.parameters``)."""
        if self.sensitivities is None:
            raise ValueError("this propagation carries no sensitivities; "
                             "call propagate(..., stm=True)")
        sens = self.sensitivities
        nsteps, nb, _, npar, n = sens.shape
        coef = sens.reshape(nsteps, nb, 3 * npar, n)
        out, tshape = self._dense(coef, t_s, 0)
        out = out.reshape(out.shape[:2] + (6, npar))
        return self._finish(out, tshape, (6, npar))

    def stm(self, t_s) -> np.ndarray:
        """State transition matrix ``Phi(t, t0) = d state(t) / d state(t0)``, ``(..., 6, 6)``."""
        return self.jacobian(t_s)[..., :6]

    def dstate_dmu(self, t_s) -> np.ndarray:
        """d state(t) / d mu (state units per m^3/s^2), ``(..., 6)``; needs ``mu_sensitivity``."""
        if "mu" not in self.parameters:
            raise ValueError("this propagation has no mu sensitivity; "
                             "call propagate(..., stm=True, mu_sensitivity=True)")
        return self.jacobian(t_s)[..., self.parameters.index("mu")]


def propagate(state0, t0_s: float, t_end_s: float, *, force: str = "j2",
              mu_m3_s2: float = MU_EARTH, j2: float = J2, re_m: float = RE_EARTH,
              tol: float = 1e-15, order: int | None = None, stm: bool = False,
              mu_sensitivity: bool = False, max_steps: int = 100_000) -> Propagation:
    """Integrate two-body (+ J2) motion from t0 to t_end with the adaptive Taylor method.

    Parameters
    ----------
    state0 : array ``(6,)`` or ``(B, 6)``
        Position (m) and velocity (m/s) at ``t0_s`` in the quasi-inertial frame whose z axis
        is the rotation axis of J2. A leading axis B integrates B trajectories together with a
        common step (the smallest any of them needs).
    t0_s, t_end_s : float
        Start and end times, s (any origin); ``t_end_s < t0_s`` integrates backward.
    force : ``"two-body"`` or ``"j2"``
    mu_m3_s2, j2, re_m : float
        Gravitational parameter (m^3/s^2), unnormalised J2 and its reference radius (m).
    tol : float
        Combined absolute/relative tolerance per step (down to about 1e-16).
    order : int, optional
        Taylor order; default :func:`default_order` (24 at 1e-15).
    stm : bool
        Also propagate first-order sensitivities (state transition matrix).
    mu_sensitivity : bool
        With ``stm``, also d state / d mu.
    max_steps : int
        Stop with ``Outcome.STEP_LIMIT`` after this many steps.

    Returns
    -------
    Propagation
        Outcome, step times, per-step spectra; ``.state(t)``, ``.stm(t)``,
        ``.dstate_dmu(t)`` evaluate them at any times inside the interval covered.

    Implements seed 000 eq. 14 (P-model) with seed 004 eq. 6 in general form (power rule for
    r^-3, r^-5, r^-7), and seed 004 eqs. 19-21 (first order) for the sensitivities.
    """
    s0 = np.asarray(state0, dtype=float)
    batch = s0.ndim == 2
    if s0.shape[-1] != 6 or s0.ndim not in (1, 2) or (batch and s0.shape[0] == 0):
        raise ValueError(f"state0 must have shape (6,) or (B, 6); found {s0.shape}")
    if not np.all(np.isfinite(s0)):
        raise ValueError("state0 must be finite; found NaN or infinity")
    if force not in FORCES:
        raise ValueError(f"unknown force model {force!r}; expected one of {FORCES}")
    if not (0.0 < tol < 1.0):
        raise ValueError(f"tol must lie in (0, 1); found {tol}")
    t0, t1 = float(t0_s), float(t_end_s)
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise ValueError(f"t0_s and t_end_s must be finite; found {t0_s}, {t_end_s}")
    p = default_order(tol) if order is None else int(order)
    if p < 3:
        raise ValueError(f"order must be >= 3; found {p}")
    if mu_sensitivity and not stm:
        raise ValueError("mu_sensitivity needs stm=True")
    s0 = s0.reshape(-1, 6)
    nb = s0.shape[0]
    kj2 = -1.5 * j2 * mu_m3_s2 * re_m ** 2 if force == "j2" else 0.0
    if force == "j2" and kj2 == 0.0:
        force = "two-body"
    params = STATE_PARAMETERS + (("mu",) if mu_sensitivity else ())
    npar = len(params)
    mu_slot = 7 if mu_sensitivity else None

    r = s0[:, :3].copy()
    v = s0[:, 3:].copy()
    if stm:
        dr = np.zeros((nb, 3, npar))
        dv = np.zeros((nb, 3, npar))
        dr[:, [0, 1, 2], [0, 1, 2]] = 1.0
        dv[:, [0, 1, 2], [3, 4, 5]] = 1.0
    n = p + 2
    kpow = np.arange(n, dtype=float)
    kder = np.arange(1, n, dtype=float)
    direction = 1.0 if t1 >= t0 else -1.0
    times = [t0]
    coefs, senss = [], []
    outcome = Outcome.SUCCESS
    t = t0
    if stm:
        kern = _series_var_single if nb == 1 else _series_dual
    else:
        kern = _series_state_single if nb == 1 else _series_state
    with np.errstate(all="ignore"):                          # overflow is detected below
        while t != t1:
            if len(coefs) >= max_steps:
                outcome = Outcome.STEP_LIMIT
                break
            try:
                if stm:
                    xd = kern(r, v, dr, dv, p, mu_m3_s2, kj2, mu_slot)
                    x = xd[:, :, 0]
                else:
                    x = kern(r, v, p, mu_m3_s2, kj2)
            except (ZeroDivisionError, OverflowError):         # scalar kernel, e.g. r = 0
                outcome = Outcome.NON_FINITE
                break
            if not (np.isfinite(x).all() and (not stm or np.isfinite(xd).all())):
                outcome = Outcome.NON_FINITE
                break
            h = _step_size(x, p, tol)
            remaining = abs(t1 - t)
            last = not (h < remaining)
            hs = (t1 - t) if last else direction * h
            hp = hs ** kpow
            hd = kder * hp[:-1]
            if stm:
                rv = xd @ hp                               # (B, 3, J)
                vv = xd[..., 1:] @ hd
                r, v = rv[:, :, 0], vv[:, :, 0]
                dr, dv = rv[:, :, 1:], vv[:, :, 1:]
                senss.append(xd[:, :, 1:])
                coefs.append(x)
            else:
                r = x @ hp
                v = x[..., 1:] @ hd
                coefs.append(x)
            if not (np.isfinite(r).all() and np.isfinite(v).all()):
                coefs.pop()
                if stm:
                    senss.pop()
                outcome = Outcome.NON_FINITE
                break
            t = t1 if last else t + hs
            times.append(t)
    if coefs:
        coef_arr = np.stack(coefs)
        sens_arr = np.stack(senss) if stm else None
    else:
        coef_arr = np.empty((0, nb, 3, n))
        sens_arr = np.empty((0, nb, 3, npar, n)) if stm else None
    return Propagation(outcome=outcome, step_times_s=np.array(times), coefficients=coef_arr,
                       sensitivities=sens_arr, parameters=params if stm else (),
                       order=p, tol=tol, force=force, mu_m3_s2=mu_m3_s2,
                       j2=j2 if force == "j2" else 0.0, re_m=re_m, batch=batch)
