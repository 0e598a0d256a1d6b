"""Spectrum algebra: Pukhov's differential transformations (DT) of time series.

A *spectrum* is the array of DT discretes of a function z(t) around a point t*::

    Z(K) = H^K / K! * d^K z/dt^K (t*),        z(t) = sum_K ((t - t*)/H)^K Z(K)

(docs/equations.md, "Notation"). With H = 1 (in the time unit, seconds in
trackproc) a spectrum is the list of Taylor coefficients; every function here works with
H = 1 unless it takes an ``h`` argument, and :func:`rescale` converts between scales.

Conventions
-----------
* Arrays are shaped ``(..., K)``: the coefficient index is the LAST axis, any leading axes are
  batch axes (many trajectories, coordinates, parameters) and broadcast like numpy ufuncs.
* Every rule returns as many coefficients as its operands carry (``derivative`` one fewer,
  ``integral`` one more); operands of different lengths are truncated to the shorter one.
* Functions are pure: they never modify their arguments.

Each rule has two forms where a recurrence needs it: the full spectrum (``cauchy``,
``power`` ...) and the single K-th coefficient from the previous ones (``cauchy_k``,
``power_k`` ...). The integrator in :mod:`trackproc.dynamics.taylor` fuses the K-th forms of
these rules into one loop per order.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "taylor_unit", "constant", "cauchy", "cauchy_k", "quotient", "quotient_k", "power",
    "power_k", "power_weights", "sqrt", "sqrt_k", "sin_cos", "exp", "derivative", "integral",
    "rescale", "evaluate", "vandermonde", "from_derivatives",
]


def _as_series(u) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.ndim == 0 or u.shape[-1] == 0:
        raise ValueError(f"a spectrum needs a last axis with at least one coefficient; "
                         f"found shape {u.shape}")
    return u


def _common(u, v):
    u, v = _as_series(u), _as_series(v)
    n = min(u.shape[-1], v.shape[-1])
    return u[..., :n], v[..., :n], n


def taylor_unit(m: int, n: int) -> np.ndarray:
    """The Taylor unit delta(K - m) with ``n`` coefficients: 1 at K = m, 0 elsewhere.

    Implements the notation of docs/equations.md ("Taylor unit"): the spectrum of
    ((t - t*)/H)^m. ``constant(c, n) = c * taylor_unit(0, n)``.
    """
    if not 0 <= m < n:
        raise ValueError(f"taylor_unit needs 0 <= m < n; found m={m}, n={n}")
    out = np.zeros(n)
    out[m] = 1.0
    return out


def constant(c, n: int) -> np.ndarray:
    """Spectrum of a constant c (any shape): ``c * delta(K)``, shape ``c.shape + (n,)``.

    Implements the notation of docs/equations.md ("constants enter as c*delta(K)").
    """
    c = np.asarray(c, dtype=float)
    out = np.zeros(c.shape + (n,))
    out[..., 0] = c
    return out


def cauchy_k(u, v, k: int) -> np.ndarray:
    """The K-th coefficient of the product u*v: ``sum_{l=0..K} U(l) V(K-l)``.

    Implements the DT product rule (docs/equations.md, notation, "product"; seed 004 eq. 6 uses it for
    X * r^-3). Only ``U(0..K)`` and ``V(0..K)`` are read, so it can run inside a recurrence
    whose higher coefficients are not known yet. Returns the broadcast leading shape.
    """
    u, v = _as_series(u), _as_series(v)
    if k >= u.shape[-1] or k >= v.shape[-1]:
        raise ValueError(f"cauchy_k needs K+1 = {k + 1} coefficients; found "
                         f"{u.shape[-1]} and {v.shape[-1]}")
    return np.einsum("...l,...l->...", *np.broadcast_arrays(u[..., :k + 1], v[..., k::-1]))


def cauchy(u, v) -> np.ndarray:
    """Spectrum of the product u*v (Cauchy product, truncated to the common length).

    Implements the DT product rule (docs/equations.md, notation, "product", written ``*``):
    ``(U*V)(K) = sum_{l=0..K} U(l) V(K-l)``.
    """
    u, v, n = _common(u, v)
    shape = np.broadcast_shapes(u.shape, v.shape)
    out = np.zeros(shape)
    for l in range(n):
        out[..., l:] += u[..., l, None] * v[..., :n - l]
    return out


def quotient_k(q, u, v, k: int) -> np.ndarray:
    """The K-th coefficient of q = u/v from ``Q(0..K-1)``.

    ``Q(K) = (U(K) - sum_{l=0..K-1} Q(l) V(K-l)) / V(0)`` (the product rule solved for the
    unknown factor; docs/equations.md, notation, "product"). ``q`` must hold at least K coefficients.
    """
    q, u, v = _as_series(q), _as_series(u), _as_series(v)
    acc = u[..., k]
    if k:
        acc = acc - np.einsum("...l,...l->...",
                              *np.broadcast_arrays(q[..., :k], v[..., k:0:-1]))
    return acc / v[..., 0]


def quotient(u, v) -> np.ndarray:
    """Spectrum of u/v, for V(0) != 0.

    Implements the product rule (docs/equations.md, notation) solved for the quotient:
    ``Q(K) = (U(K) - sum_{l=0..K-1} Q(l) V(K-l)) / V(0)``.
    """
    u, v, n = _common(u, v)
    if np.any(v[..., 0] == 0):
        raise ValueError("quotient needs V(0) != 0 (the divisor vanishes at the expansion point)")
    q = np.zeros(np.broadcast_shapes(u.shape, v.shape))
    for k in range(n):
        q[..., k] = quotient_k(q, u, v, k)
    return q


def power_weights(a, k: int) -> np.ndarray:
    """Weights ``(a(K-l) - l) / K`` for l = 0..K-1 of the power rule's K-th coefficient.

    ``a`` may be an array of exponents (shape ``A``); the result has shape ``A + (K,)``. The
    integrator precomputes them once per order, so the K-th power coefficient of several
    exponents is a single contraction (see :func:`power_k`).

    Implements the power rule's weights (docs/equations.md, notation: "power u^a").
    """
    a = np.asarray(a, dtype=float)
    l = np.arange(k, dtype=float)
    return (a[..., None] * (k - l) - l) / k


def power_k(w, u, a: float, k: int) -> np.ndarray:
    """The K-th coefficient (K >= 1) of w = u^a from ``W(0..K-1)`` and ``U(0..K)``.

    Implements the power rule of docs/equations.md, notation ("power u^a"; used for r^-3 in the general
    form of seed 004 eq. 6):
    ``W(K) = 1/(K U(0)) sum_{l=0..K-1} (a(K-l) - l) U(K-l) W(l)``.
    """
    wts = power_weights(a, k)
    w, u = _as_series(w), _as_series(u)
    return np.einsum("...l,...l->...", *np.broadcast_arrays(w[..., :k] * wts,
                                                            u[..., k:0:-1])) / u[..., 0]


def power(u, a: float) -> np.ndarray:
    """Spectrum of u^a for a real exponent a.

    Implements the power rule (docs/equations.md, notation, "power u^a"):
    ``W(0) = U(0)^a; W(K) = 1/(K U(0)) sum_{l=0..K-1} (a(K-l) - l) U(K-l) W(l)``.
    It gives r^-3 = (r^2)^(-3/2), r^-5, ... in the general (non-circular) form of seed 004
    eq. 6. Preconditions: U(0) > 0 for a non-integer a, U(0) != 0 for a negative integer;
    a non-negative integer exponent with U(0) = 0 is computed by repeated Cauchy products.
    """
    u = _as_series(u)
    a = float(a)
    u0 = u[..., 0]
    if a.is_integer() and a >= 0 and np.any(u0 == 0):
        out = constant(np.ones(u.shape[:-1]), u.shape[-1])
        base, e = u, int(a)
        while e:
            if e & 1:
                out = cauchy(out, base)
            base, e = cauchy(base, base), e >> 1
        return out
    if not a.is_integer() and np.any(u0 <= 0):
        raise ValueError(f"power with the non-integer exponent {a} needs U(0) > 0; "
                         f"found min U(0) = {np.min(u0)}")
    if np.any(u0 == 0):
        raise ValueError(f"power with the exponent {a} needs U(0) != 0")
    w = np.zeros_like(u)
    w[..., 0] = u0 ** a
    for k in range(1, u.shape[-1]):
        w[..., k] = power_k(w, u, a, k)
    return w


def sqrt_k(d, d2, k: int) -> np.ndarray:
    """The K-th coefficient (K >= 1) of d = sqrt(d2) from ``D(0..K-1)``.

    Implements seed 004 eq. 12: ``D(K) = (D2(K) - sum_{l=1..K-1} D(K-l) D(l)) / (2 D(0))``.
    """
    d, d2 = _as_series(d), _as_series(d2)
    acc = d2[..., k]
    if k > 1:
        acc = acc - np.einsum("...l,...l->...", d[..., 1:k], d[..., k - 1:0:-1])
    return acc / (2.0 * d[..., 0])


def sqrt(d2) -> np.ndarray:
    """Spectrum of sqrt(d2), for D2(0) > 0.

    Implements seed 004 eq. 12 (range from the squared range):
    ``D(0) = sqrt(D2(0)); D(K) = (D2(K) - sum_{l=1..K-1} D(K-l) D(l)) / (2 D(0))``.
    """
    d2 = _as_series(d2)
    if np.any(d2[..., 0] <= 0):
        raise ValueError("sqrt needs D2(0) > 0 (the series of sqrt is not analytic at 0)")
    d = np.zeros_like(d2)
    d[..., 0] = np.sqrt(d2[..., 0])
    for k in range(1, d2.shape[-1]):
        d[..., k] = sqrt_k(d, d2, k)
    return d


def sin_cos(s) -> tuple[np.ndarray, np.ndarray]:
    """Spectra of sin(s) and cos(s) of a series s.

    Implements seed 004 eq. 9 (the sidereal-angle rotation in the image domain), with
    ``sin(0) = sin(S(0))``, ``cos(0) = cos(S(0))`` and for K >= 0::

        sin(K+1) =  sum_{l=0..K} (l+1)/(K+1) S(l+1) cos(K-l)
        cos(K+1) = -sum_{l=0..K} (l+1)/(K+1) S(l+1) sin(K-l)

    For a linear angle S = S0 + w t this gives sin(S0 + w t) exactly (its Taylor series).
    """
    s = _as_series(s)
    n = s.shape[-1]
    sn, cs = np.zeros_like(s), np.zeros_like(s)
    sn[..., 0], cs[..., 0] = np.sin(s[..., 0]), np.cos(s[..., 0])
    ds = s[..., 1:] * np.arange(1, n)            # (l+1) S(l+1), l = 0..n-2
    for k in range(n - 1):
        sn[..., k + 1] = np.einsum("...l,...l->...", ds[..., :k + 1], cs[..., k::-1]) / (k + 1)
        cs[..., k + 1] = -np.einsum("...l,...l->...", ds[..., :k + 1], sn[..., k::-1]) / (k + 1)
    return sn, cs


def exp(u) -> np.ndarray:
    """Spectrum of exp(u).

    From e' = u' e (the same construction as seed 004 eq. 9):
    ``E(0) = exp(U(0)); E(K) = 1/K sum_{l=1..K} l U(l) E(K-l)``.
    """
    u = _as_series(u)
    n = u.shape[-1]
    e = np.zeros_like(u)
    e[..., 0] = np.exp(u[..., 0])
    du = u[..., 1:] * np.arange(1, n)            # l U(l), l = 1..n-1
    for k in range(1, n):
        e[..., k] = np.einsum("...l,...l->...", du[..., :k], e[..., k - 1::-1]) / k
    return e


def derivative(z, h: float = 1.0) -> np.ndarray:
    """Spectrum of dz/dt: ``P{z'}(K) = (K+1)/H Z(K+1)``; one coefficient fewer than z.

    Implements the derivative rule of docs/equations.md, notation; seed 004 eq. 12 uses it for the
    range-rate ``Vr(K) = (K+1)/H D(K+1)``.
    """
    z = _as_series(z)
    n = z.shape[-1]
    return z[..., 1:] * (np.arange(1, n) / h)


def integral(z, z0=0.0, h: float = 1.0) -> np.ndarray:
    """Spectrum of the integral of z from t*, plus the constant z0; one coefficient more.

    ``I(0) = z0; I(K+1) = H/(K+1) Z(K)`` -- the P-model rule of seed 000 eq. 14
    (``Z(K+1) = H/(K+1) F(K)`` for z' = F).
    """
    z = _as_series(z)
    n = z.shape[-1]
    z0 = np.broadcast_to(np.asarray(z0, dtype=float), z.shape[:-1])
    out = np.empty(z.shape[:-1] + (n + 1,))
    out[..., 0] = z0
    out[..., 1:] = z * (h / np.arange(1, n + 1))
    return out


def rescale(z, h: float) -> np.ndarray:
    """Change the time scale of a spectrum: ``Z_H(K) = H^K Z_1(K)``.

    With the DT definition (docs/equations.md, notation) the discretes at scale H are H^K times the
    Taylor coefficients; ``rescale(z, 1/H)`` goes back. The function value at
    ``t* + H tau`` is then ``sum_K tau^K Z_H(K)``.
    """
    z = _as_series(z)
    return z * float(h) ** np.arange(z.shape[-1])


def vandermonde(dt, n: int, h: float = 1.0, derivative: int = 0) -> np.ndarray:
    """Matrix ``V`` with ``V @ Z = d^m z/dt^m`` at offsets ``dt`` for spectra Z of length n.

    ``V[i, K] = K!/(K-m)! dt_i^(K-m) / H^K`` (zero for K < m). Dense output of a batch of
    spectra is then one matrix product (the inverse transform, docs/equations.md, notation). Shape
    ``(len(dt), n)``. Implements seed 004 eq. 13 (the inverse transform) for many offsets at once.
    """
    x = np.asarray(dt, dtype=float).reshape(-1)
    m = int(derivative)
    if m < 0:
        raise ValueError(f"derivative order must be >= 0; found {m}")
    out = np.zeros((x.size, n))
    if m >= n:
        return out
    out[:, m:] = np.vander(x, n - m, increasing=True)
    if m:
        k = np.arange(m, n)
        out[:, m:] *= np.array([math.perm(int(j), m) for j in k], dtype=float)
    if h != 1.0:
        out *= float(h) ** -np.arange(n, dtype=float)
    return out


def evaluate(z, dt, h: float = 1.0, derivative: int = 0) -> np.ndarray:
    """Inverse transform (Horner): ``z^(m)(t* + dt) = d^m/dt^m sum_K (dt/H)^K Z(K)``.

    Implements the inverse DT of docs/equations.md, notation (seed 004 eq. 13). ``z`` has shape
    ``(..., K)``; ``dt`` any shape; the result has shape ``z.shape[:-1] + dt.shape``.
    """
    z = _as_series(z)
    x = np.asarray(dt, dtype=float)
    for _ in range(int(derivative)):
        if z.shape[-1] == 1:
            return np.zeros(z.shape[:-1] + x.shape)
        z = z[..., 1:] * (np.arange(1, z.shape[-1]) / h)
    lead = z.shape[:-1]
    xs = x / h
    zz = z.reshape(lead + (1,) * x.ndim + (z.shape[-1],))
    y = np.broadcast_to(zz[..., -1], lead + x.shape).copy()
    for k in range(z.shape[-1] - 2, -1, -1):
        y *= xs
        y += zz[..., k]
    return y


def from_derivatives(derivs, h: float = 1.0) -> np.ndarray:
    """Direct transform from derivatives: ``Z(K) = H^K / K! * d^K z/dt^K``; derivs ``(..., K)``."""
    d = _as_series(derivs)
    k = np.arange(d.shape[-1])
    fact = np.array([math.factorial(int(i)) for i in k], dtype=float)
    return d * (float(h) ** k / fact)
