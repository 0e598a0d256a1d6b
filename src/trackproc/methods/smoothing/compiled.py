"""The smoothing's compiled kernels (numba), each the same operations on the same numbers as the
path it replaces (IEEE arithmetic, no fastmath: no fused multiply-add, no reassociation), so the
same bits; tests/methods/test_smoothing_compiled.py compares them with ``==``.

:func:`ou_solve`: the two recurrences of :func:`trackproc.methods.smoothing.fit.ou_apply` (``C x``
for the AR(1) correlation): LAPACK ``dpttrs`` (reference ``dptts2``) on the time-reversed
``L D L^T`` factors, written out in the original time order over the rows of a C-ordered ``x``.

``dptts2`` solves column by column, one dependent multiply-subtract per element (latency-bound:
~110 us of CPU for 600 x 31); here each step is one row, the ``p`` columns side by side.

:func:`cheb_der_rows`: ``numpy.polynomial.chebyshev.chebder(c, m, scl, axis=0)`` of a matrix (the
derivative rows of :func:`~trackproc.methods.smoothing.fit.design_matrix`, ~110 us of numpy
row operations an order at degree 30).

:func:`polish_roots`, :func:`cheb_values`: the TCA spread's Newton polish of the companion
matrix's roots and its evaluations of the derivative series (:func:`trackproc.methods.smoothing.tca._cheb_tca`),
which loop in Python floats.
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics.jit import njit

__all__ = ["cheb_der_rows", "cheb_value", "cheb_values", "ou_solve", "polish_roots"]


@njit(nogil=True)
def ou_solve(d, e, x, out):
    """``out = C x`` (``x``, ``out`` C-ordered n x p, n >= 2): ``d`` the diagonal of ``V^-1``
    (``d_0 = 1``, ``d_i = 1 / (1 - a_i^2)``), ``e = -a`` (length n - 1).

    ``dptts2`` on the reversed arrays ``D = d[::-1]``, ``E = e[::-1]``, ``B = x[::-1]`` maps
    ``B(k) = B(k) - B(k-1) E(k-1)`` to row ``i = n-1-k``: ``x_i - x_(i+1) e_i`` for ``i = n-2 .. 0``;
    ``B(N) / D(N)`` to ``x_0 / d_0``; ``B(k) / D(k) - B(k+1) E(k)`` to ``x_i / d_i - x_(i-1) e_(i-1)``
    for ``i = 1 .. n-1``."""
    n, p = x.shape
    for j in range(p):
        out[n - 1, j] = x[n - 1, j]
    for i in range(n - 2, -1, -1):
        ei = e[i]
        for j in range(p):
            out[i, j] = x[i, j] - out[i + 1, j] * ei
    d0 = d[0]
    for j in range(p):
        out[0, j] = out[0, j] / d0
    for i in range(1, n):
        di = d[i]
        ei = e[i - 1]
        for j in range(p):
            out[i, j] = out[i, j] / di - out[i - 1, j] * ei


@njit(nogil=True)
def cheb_der_rows(c, m, scl):
    """``chebder(c, m, scl, axis=0)`` of a C-ordered float matrix ``c`` (rows: coefficients), ``m``
    below its number of rows: numpy's recurrence ``c'_(j-1) = c'_(j+1) + 2 j c_j`` as numpy writes
    it (scale first, ``der[j-1] = (2 j) c[j]``, ``c[j-2] += (j c[j]) / (j-2)``, j descending)."""
    c = c.copy()
    for _ in range(m):
        n = c.shape[0] - 1
        c *= scl
        der = np.empty((n, c.shape[1]))
        for j in range(n, 2, -1):
            for k in range(c.shape[1]):
                der[j - 1, k] = (2 * j) * c[j, k]
                c[j - 2, k] += (j * c[j, k]) / (j - 2)
        if n > 1:
            for k in range(c.shape[1]):
                der[1, k] = 4 * c[2, k]
        for k in range(c.shape[1]):
            der[0, k] = c[1, k]
        c = der
    return c


@njit(nogil=True)
def cheb_value(c, off, scl, x):
    """:func:`trackproc.methods.smoothing.tca._cheb_scalar`'s value of the Chebyshev series ``c``
    (domain map ``off + scl x``) at one float ``x``: its operations in its order."""
    n = c.size
    u = off + scl * x
    if n == 1:
        return c[0] + 0.0 * u
    if n == 2:
        return c[0] + c[1] * u
    x2 = 2 * u
    c0, c1 = c[n - 2], c[n - 1]
    for i in range(3, n + 1):
        c0, c1 = c[n - i] - c1, c0 + c1 * x2
    return c0 + c1 * u


@njit(nogil=True)
def cheb_values(c, off, scl, xs):
    """:func:`cheb_value` at each of ``xs``."""
    out = np.empty(xs.size)
    for k in range(xs.size):
        out[k] = cheb_value(c, off, scl, xs[k])
    return out


@njit(nogil=True)
def polish_roots(zr, zi, cv, cd, off, scl, lo, hi):
    """:func:`trackproc.methods.smoothing.tca._polish` before its rounding: the roots
    ``zr + i zi`` real to 1e-3 of the half-width of ``[lo, hi]``, after up to 5 Newton steps on the
    series ``cv`` (derivative ``cd``), inside it; NaN for the others."""
    half = 0.5 * (hi - lo)
    out = np.empty(zr.size)
    for k in range(zr.size):
        out[k] = np.nan
        if abs(zi[k]) > 1e-3 * half:
            continue
        x = zr[k]
        for _ in range(5):
            slope = cheb_value(cd, off, scl, x)
            if slope == 0:
                break
            step = cheb_value(cv, off, scl, x) / slope
            x -= step
            if abs(step) < 1e-12 * half:
                break
        if lo <= x <= hi and np.isfinite(x):
            out[k] = x
    return out
