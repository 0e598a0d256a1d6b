"""The two-state Kalman filter's gain recursion of :class:`trackproc.methods.whitening.MarkovFactor`
compiled by numba (issue 19): the same scalar Riccati loop, the same operations in the same order
(IEEE arithmetic, no ``fastmath``), so the compiled and the Python loop give the same bits
(tests/pipeline/test_whitening_jit.py); :func:`kalman_whiten` applies the filter to a matrix's
columns (equal to the Python path's banded solve to rounding, not bit for bit).
Import this module only when :func:`trackproc.dynamics.jit.enabled`;
:mod:`trackproc.methods.whitening` decides when the import pays (:func:`~trackproc.methods.whitening.compiled_riccati`).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["riccati"]


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
