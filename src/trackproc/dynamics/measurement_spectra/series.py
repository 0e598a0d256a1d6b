"""Matrix forms of operations on truncated Taylor series (H = 1 s): derivative, Cauchy product,
time shift, square root and reciprocal, and their evaluation on segments.
"""

from __future__ import annotations

import math
import sys
from functools import lru_cache

import numpy as np

from trackproc.dynamics import spectra as sp


@lru_cache(maxsize=16)
def derivative_matrix(n: int) -> np.ndarray:
    """D with ``(u @ D)[K] = (K+1) U(K+1)``: the derivative rule (docs/equations.md, notation)."""
    d = np.zeros((n, n))
    k = np.arange(n - 1)
    d[k + 1, k] = k + 1.0
    return d


@lru_cache(maxsize=16)
def _toeplitz_index(n: int) -> tuple[np.ndarray, np.ndarray]:
    row, col = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return np.where(col >= row, col - row, n), (col >= row)


def product_matrix(v) -> np.ndarray:
    """``M(v)`` (..., n, n) with ``u @ M(v) = u * v`` (Cauchy product, docs/equations.md, notation).

    Upper-triangular Toeplitz: ``M[l, K] = V(K - l)`` for ``K >= l``. ``M(u) M(v) = M(u*v)``:
    truncated series and these matrices form the same commutative algebra.
    """
    v = np.asarray(v, float)
    n = v.shape[-1]
    idx, _ = _toeplitz_index(n)
    pad = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], axis=-1)
    return pad[..., idx]


@lru_cache(maxsize=16)
def _binomials(n: int) -> np.ndarray:
    j, k = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    out = np.zeros((n, n))
    mask = j >= k
    out[mask] = [math.comb(int(a), int(b)) for a, b in zip(j[mask], k[mask])]
    return out


def shift_matrix(delta_s, n: int) -> np.ndarray:
    """``B(delta)`` (..., n, n): ``u @ B`` re-expands a spectrum about ``t* + delta``.

    ``B[j, K] = C(j, K) delta^(j - K)`` (Taylor's theorem for the polynomial the spectrum is).

    Implements the re-expansion of a spectrum about another centre (docs/equations.md, notation).
    """
    d = np.asarray(delta_s, float)[..., None, None]
    e, upper = _shift_exponents(n)
    return _binomials(n) * np.where(upper, d ** e, 0.0)


@lru_cache(maxsize=16)
def _shift_exponents(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The exponents ``j - K`` (0 below the diagonal) and the mask ``j >= K`` of :func:`shift_matrix`."""
    j, k = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return np.where(j >= k, j - k, 0), j >= k


def cauchy_sum(u, v) -> np.ndarray:
    """``sum_i u_i * v_i`` over axis -2 (a dot product of vector spectra), (..., 3, n) -> (..., n)."""
    return np.einsum("...il,...ilk->...k", u, product_matrix(v))


def evaluate_series(spec, dt, derivative: int = 0, *, vander=None):
    """Inverse transform of per-sample spectra ``spec`` (N, ..., n) at offsets ``dt`` (N,).

    ``vander`` may give the matrix ``sp.vandermonde(dt, n, derivative=derivative)`` once for all.
    """
    v = vander if vander is not None else sp.vandermonde(dt, spec.shape[-1], derivative=derivative)
    return np.einsum("n...k,nk->n...", spec, v)


def evaluate_segments(spec, bounds, vander) -> np.ndarray:
    """Inverse transform of segment spectra ``spec`` (S, ..., n) at the samples: segment ``i``
    covers the sorted samples ``bounds[i, 0]:bounds[i, 1]``, ``vander`` (N, n) their powers of
    ``t - centre`` (one small matrix product per segment; no per-sample copy of the spectra)."""
    n = spec.shape[-1]
    tail = spec.shape[1:-1]
    flat = spec.reshape(spec.shape[0], -1, n)
    out = np.empty((vander.shape[0], flat.shape[1]))
    for i, (a, b) in enumerate(bounds):
        out[a:b] = vander[a:b] @ flat[i].T
    return out.reshape((vander.shape[0],) + tail)


def series_sqrt(d2) -> np.ndarray:
    """Seed 004 eq. 12 on (S, n) spectra: ``D(K) = (D2(K) - sum_{l=1..K-1} D(K-l) D(l)) / (2 D(0))``.

    The same rule as :func:`trackproc.dynamics.spectra.sqrt`, with less per-order overhead (the
    orders' recurrence compiled where numba is loaded: :mod:`.series_jit`, the same numbers).
    """
    if np.any(d2[:, 0] <= 0):
        raise ArithmeticError("the station-satellite distance vanishes (D2(0) <= 0)")
    n = d2.shape[-1]
    d = np.zeros_like(d2)
    d[:, 0] = np.sqrt(d2[:, 0])
    inv2 = 0.5 / d[:, 0]
    if n > 1:
        d[:, 1] = d2[:, 1] * inv2
    if n > 2 and _compiled():
        from trackproc.dynamics import jit
        from trackproc.dynamics.measurement_spectra import series_jit  # numba is loaded already (_compiled)

        work = np.ascontiguousarray(d)              # C order for the kernel; d keeps d2's layout
        with jit.compile_once([series_jit.sqrt_orders], "series-sqrt"):
            series_jit.sqrt_orders(np.ascontiguousarray(d2), work, np.ascontiguousarray(inv2))
        d[...] = work
        return d
    for k in range(2, n):
        d[:, k] = (d2[:, k] - np.einsum("sl,sl->s", d[:, 1:k], d[:, k - 1:0:-1])) * inv2
    return d


def _compiled() -> bool:
    """The compiled recurrence (:mod:`.series_jit`, the same numbers) where numba is loaded and
    allowed, and the work is many predictions in one process (``TRACKPROC_JIT=1``, a batch's tasks)
    or the kernel is in this process already: its first load (~40 ms of CPU from numba's cache,
    ~0.4 s to compile) is not paid by a single command's few predictions (0.2 ms saved each)."""
    if "numba" not in sys.modules:
        return False
    from trackproc.dynamics import jit

    if not jit.enabled():
        return False
    if jit.forced():
        return True
    kernels = sys.modules.get("trackproc.dynamics.measurement_spectra.series_jit")
    return kernels is not None and bool(kernels.sqrt_orders.signatures)


def series_reciprocal(u) -> np.ndarray:
    """Spectrum of 1/u on (S, n) spectra: ``R(K) = -sum_{l=1..K} U(l) R(K-l) / U(0)`` (product rule)."""
    n = u.shape[-1]
    r = np.zeros_like(u)
    inv = 1.0 / u[:, 0]
    r[:, 0] = inv
    for k in range(1, n):
        r[:, k] = -np.einsum("sl,sl->s", u[:, 1:k + 1], r[:, k - 1::-1]) * inv
    return r
