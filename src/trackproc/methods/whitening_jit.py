"""The two-state Kalman filter's gain recursion of :class:`trackproc.methods.whitening.MarkovFactor`
compiled by numba (issue 19): the same scalar Riccati loop, the same operations in the same order
(IEEE arithmetic, no ``fastmath``), so the compiled and the Python loop give the same bits
(tests/pipeline/test_whitening_jit.py). Import this module only when :func:`trackproc.dynamics.jit.enabled`;
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
