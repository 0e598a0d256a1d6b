"""The two-state Kalman filter's gain recursion of :class:`trackproc.methods.whitening.MarkovFactor`
compiled by numba (issue 19): the same scalar Riccati loop, the same operations in the same order
(IEEE arithmetic, no ``fastmath``), so the compiled and the Python loop give the same bits
(tests/pipeline/test_whitening_jit.py); :func:`kalman_whiten` applies the filter to a matrix's
columns (equal to the Python path's banded solve to rounding, not bit for bit).
Import this module only when :func:`trackproc.dynamics.jit.enabled`;
:mod:`trackproc.methods.whitening` decides when the import pays (:func:`~trackproc.methods.whitening.compiled_riccati`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["riccati", "kalman_whiten", "reml_terms"]


@numba.njit(cache=True, nogil=True)
def riccati(phi, v_ar, v_walk, w2, a2):
    """``(S, h0, h1)``: innovation variances and ``P hᵀ`` of the filter at each sample.
    Implements the Kalman (1960) filter's covariance recursion with a scalar measurement
    (the loop of ``MarkovFactor._kalman``, line for line)."""
    n = v_ar.size
    sv = np.empty(n)
    h0v = np.empty(n)
    h1v = np.empty(n)
    p00 = a2
    p01 = 0.0
    p11 = v_walk[0]
    for k in range(n):
        if k < n - 1:
            f = phi[k]
            va = v_ar[k + 1]
            vw = v_walk[k + 1]
        else:
            f = 0.0
            va = 0.0
            vw = 0.0
        hp0 = p00 + p01
        hp1 = p01 + p11
        s = hp0 + hp1 + w2
        sv[k] = s
        h0v[k] = hp0
        h1v[k] = hp1
        g0 = hp0 / s
        g1 = hp1 / s
        p00 = f * f * (p00 - g0 * hp0) + va
        p01 = f * (p01 - g0 * hp1)
        p11 = p11 - g1 * hp1 + vw
    return sv, h0v, h1v


@numba.njit(cache=True, nogil=True)
def kalman_whiten(phi, g0, g1, sd, m):
    """``L⁻¹ M``: the innovations of the two-state filter with gains ``g0, g1`` (from :func:`riccati`)
    applied to each column of ``M`` (n x k), divided by their standard deviations ``sd``.
    Implements the Kalman (1960) filter's state recursion with a scalar measurement: the same
    recursion as ``MarkovFactor.whiten``'s banded solve (``x̂_k+1 = F (x̂_k + g_k e_k)``, ``e_k =
    y_k - h x̂_k``), equal to it to rounding, not bit for bit (no triangular solve per column)."""
    n, k = m.shape
    out = np.empty((n, k))
    for j in range(k):
        x0 = 0.0
        x1 = 0.0
        for i in range(n):
            e = m[i, j] - x0 - x1
            out[i, j] = e / sd[i]
            if i < n - 1:
                x0 = phi[i] * (x0 + g0[i] * e)
                x1 = x1 + g1[i] * e
    return out


@numba.njit(cache=True, nogil=True)
def reml_terms(dt, ds, tau, a2, q2, w2, m, p):
    """``(log|C|, log|Xᵀ C⁻¹ X|, rᵀ P r)`` of the columns ``m = [X r]`` (n x (p+1)) under the
    covariance ``w2 I + a2 exp(-|Δt|/tau) + q2 min(s_i, s_j)`` (``tau = 0``: no AR(1); ``q2 = 0``:
    no walk) at the gaps ``dt`` and walk increments ``ds`` (:func:`~trackproc.methods.whitening.markov_grid`),
    in one compiled call: the two-state filter's gains and innovations (Kalman 1960; ``log|C| =
    Σ log S_k``, Schweppe 1965) whiten ``[X r]``, then a Householder QR (Golub & Van Loan 2013,
    alg. 5.2.1, R's diagonal only) whose first p diagonal entries give ``log|Xᵀ C⁻¹ X| = Σ log
    R_ii²`` and whose last one ``rᵀ P r = R_pp²``. Equal to ``MarkovFactor`` + LAPACK's QR in
    ``trackproc.methods.noise._Reml`` to rounding, not bit for bit (the REML search's points; its
    end point is evaluated by that path). All NaN when ``C`` is not positive definite."""
    n, k = m.shape
    x0 = np.zeros(k)
    x1 = np.zeros(k)
    wt = np.empty((k, n))                 # the whitened columns, each contiguous for the QR
    p00 = a2
    p01 = 0.0
    p11 = q2 * ds[0]
    logdet = 0.0
    prod = 1.0
    gap = math.nan
    f_gap = 0.0
    va_gap = 0.0
    for i in range(n):
        if i < n - 1 and tau > 0.0:
            if dt[i] != gap:              # a regular grid: the same gap, the same φ
                gap = dt[i]
                f_gap = math.exp(-gap / tau)
                va_gap = -math.expm1(-2.0 * gap / tau) * a2
            f = f_gap
            va = va_gap
        else:
            f = 0.0
            va = 0.0
        vw = q2 * ds[i + 1] if i < n - 1 else 0.0
        hp0 = p00 + p01
        hp1 = p01 + p11
        s = hp0 + hp1 + w2
        if not (s > 0.0 and math.isfinite(s)):
            return math.nan, math.nan, math.nan
        if 1e-100 < s < 1e100:            # Σ log S_k: one log per 1e150 of the product
            prod *= s
            if not 1e-150 < prod < 1e150:
                logdet += math.log(prod)
                prod = 1.0
        else:
            logdet += math.log(s)
        inv = 1.0 / s
        sd_inv = math.sqrt(inv)
        g0 = hp0 * inv
        g1 = hp1 * inv
        for j in range(k):
            e = m[i, j] - x0[j] - x1[j]
            wt[j, i] = e * sd_inv
            x0[j] = f * (x0[j] + g0 * e)
            x1[j] = x1[j] + g1 * e
        p00 = f * f * (p00 - g0 * hp0) + va
        p01 = f * (p01 - g0 * hp1)
        p11 = p11 - g1 * hp1 + vw
    logdet += math.log(prod)
    # Householder, R's diagonal only; two columns reflected per sweep of the reflector
    logx = 0.0
    for j in range(k):
        norm2 = 0.0
        for i in range(j, n):
            norm2 += wt[j, i] * wt[j, i]
        if j == k - 1:
            return logdet, logx, norm2
        if not norm2 > 0.0:
            logx = -math.inf
            continue
        norm = math.sqrt(norm2)
        if j < p:
            logx += math.log(norm2)
        alpha = -norm if wt[j, j] >= 0.0 else norm
        wt[j, j] -= alpha                  # v = x - alpha e_1, |v|^2 = 2 |x| (|x| + |x_1|)
        vn2 = 2.0 * norm * (norm + abs(wt[j, j] + alpha))
        col = j + 1
        while col < k:
            if col + 1 < k:
                da = 0.0
                db = 0.0
                for i in range(j, n):
                    v = wt[j, i]
                    da += v * wt[col, i]
                    db += v * wt[col + 1, i]
                fa = 2.0 * da / vn2
                fb = 2.0 * db / vn2
                for i in range(j, n):
                    v = wt[j, i]
                    wt[col, i] -= fa * v
                    wt[col + 1, i] -= fb * v
                col += 2
            else:
                da = 0.0
                for i in range(j, n):
                    da += wt[j, i] * wt[col, i]
                fa = 2.0 * da / vn2
                for i in range(j, n):
                    wt[col, i] -= fa * wt[j, i]
                col += 1
    return logdet, logx, 0.0
