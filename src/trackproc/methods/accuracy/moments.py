"""The image-domain moments of seed 000 (eqs. 12-25) on random spectra: mean, correlation, variance.
"""

from __future__ import annotations

import numpy as np



def normalizing_factor(cov) -> np.ndarray:
    """A factor ``L`` with ``L L^T = cov``: ``V = L xi`` with uncorrelated normalised ``xi``.

    Seed 000, the paragraph after eq. 5 and eq. 7: correlated random variables are reduced by
    a linear transform to uncorrelated ones with zero mean and unit variance. Built from the
    symmetric eigen-decomposition ``U diag(lambda) U^T`` as ``U diag(sqrt(lambda))``, so a
    positive *semi*-definite covariance (an unobservable direction, a parameter held fixed)
    is accepted; eigenvalues below ``-1e-10`` times the largest raise ``ValueError``, smaller
    negative ones (round-off) count as zero.
    """
    c = np.asarray(cov, dtype=float)
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise ValueError(f"a covariance must be a square matrix; found shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("the covariance must be finite")
    c = 0.5 * (c + c.T)
    # scale to a correlation-like matrix first so that m^2 and m^2/s^2 blocks are treated alike
    d = np.sqrt(np.clip(np.diag(c), 0.0, None))
    s = np.where(d > 0, d, 1.0)
    lam, u = np.linalg.eigh(c / np.outer(s, s))
    top = max(float(lam.max(initial=0.0)), 0.0)
    if lam.size and lam.min() < -1e-10 * max(top, 1.0):
        raise ValueError(f"the covariance is not positive semi-definite (eigenvalue {lam.min():.3g} "
                         "of its correlation matrix)")
    return s[:, None] * (u * np.sqrt(np.clip(lam, 0.0, None)))


def mean_spectrum(spec) -> np.ndarray:
    """Mean discretes ``m_x(K) = E[X(K, V)]`` of a random spectrum ``(..., 1 + m, n)``.

    Seed 000 eqs. 17-20 (and 19-20 for the two scales ``H1 = t1``, ``H2 = t2``): for a spectrum
    affine in zero-mean random variables the expectation is the value at ``V = 0``, slot 0.
    """
    s = np.asarray(spec, dtype=float)
    return s[..., 0, :]


def _weights(spec, cov):
    """The random part ``dX/dV L`` of a random spectrum: (..., m', n)."""
    s = np.asarray(spec, dtype=float)
    d = s[..., 1:, :]
    if cov is None:
        return d
    lo = normalizing_factor(cov)
    if lo.shape[0] != d.shape[-2]:
        raise ValueError(f"the covariance is {lo.shape[0]} x {lo.shape[0]} but the spectrum carries "
                         f"{d.shape[-2]} random variables")
    return np.einsum("...jn,jk->...kn", d, lo)


def correlation_spectrum(spec1, spec2=None, cov=None) -> np.ndarray:
    """Correlation spectrum ``R_x(K, t1, t2)`` of two random spectra (seed 000 eqs. 21-24).

    Parameters
    ----------
    spec1 : array ``(..., A, 1 + m, n1)``
        Random spectrum of A components at the scale ``H1`` (e.g. the state at t1): slot 0 the
        discretes at V = 0, slots 1..m their derivatives with respect to ``v_1..v_m``.
    spec2 : array ``(..., B, 1 + m, n2)``, optional
        The same at ``H2`` (default ``spec1``: the variance spectrum).
    cov : array ``(m, m)``, optional
        Covariance of V (zero mean). Default: the identity (V already normalised, eq. 7).

    Returns
    -------
    array ``(..., A, B, n1 + n2 - 1)``
        ``R(K) = m_q(K) - (m_x(., t1) * m_x(., t2))(K) = sum_j (W_aj * W_bj)(K)``, complete
        Cauchy products (docs/equations.md, notation: "product") of the normalised random parts
        ``W = dX/dV L``. Exact for spectra affine in V (see the module docstring on eq. 24).
    """
    w1 = _weights(spec1, cov)
    w2 = w1 if spec2 is None else _weights(spec2, cov)
    n1, n2 = w1.shape[-1], w2.shape[-1]
    n = n1 + n2 - 1
    lead = np.broadcast_shapes(w1.shape[:-3], w2.shape[:-3])
    a, b = w1.shape[-3], w2.shape[-3]
    out = np.zeros(lead + (a, b, n))
    # (W1_a * W2_b)(K) summed over the random variables j: one contraction per discrete of W1
    for l in range(n1):
        out[..., l:l + n2] += np.einsum("...aj,...bjn->...abn", w1[..., l], w2)
    return out


def correlation(spec1, spec2=None, cov=None) -> np.ndarray:
    """``R_x(t1, t2) = sum_K R_x(K, t1, t2)`` (seed 000 eq. 25): ``(..., A, B)``.

    With ``spec2 = None`` this is the covariance matrix of the A components at one time, whose
    diagonal is the variance ``D_x(t) = R_x(t, t)``.
    """
    return correlation_spectrum(spec1, spec2, cov).sum(axis=-1)


def variance(spec, cov=None) -> np.ndarray:
    """``D_x(t) = R_x(t, t)`` of every component of ``spec`` ``(..., A, 1 + m, n)``: ``(..., A)``."""
    w = _weights(spec, cov)
    n = w.shape[-1]
    out = np.zeros(w.shape[:-3] + (w.shape[-3], 2 * n - 1))
    for l in range(n):
        out[..., l:l + n] += np.einsum("...aj,...ajn->...an", w[..., l], w)
    return out.sum(axis=-1)
