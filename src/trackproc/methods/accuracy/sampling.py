"""Linear covariance propagation by the STM (method 2) and Monte Carlo sampling with its statistical bounds (method 3).
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods.accuracy.moments import normalizing_factor


def stm_covariance(phi, cov0) -> np.ndarray:
    """Linear covariance propagation ``P(t) = Phi(t) P0 Phi(t)^T``: ``phi (..., 6, 6)`` -> ``(..., 6, 6)``."""
    phi = np.asarray(phi, dtype=float)
    p = np.einsum("...ij,jk,...lk->...il", phi, np.asarray(cov0, float), phi)
    return 0.5 * (p + np.swapaxes(p, -1, -2))


def stm_cross_covariance(phi1, phi2, cov0) -> np.ndarray:
    """``R(t1_i, t2_j) = Phi(t1_i) P0 Phi(t2_j)^T``: ``(M1, 6, 6), (M2, 6, 6)`` -> ``(M1, M2, 6, 6)``."""
    return np.einsum("aij,jk,blk->abil", np.asarray(phi1, float), np.asarray(cov0, float),
                     np.asarray(phi2, float))


def sample_initial_states(state0, cov0, n_samples: int, seed: int | None = None) -> np.ndarray:
    """``n_samples`` draws of ``N(state0, cov0)``: ``state0 + L xi``, ``xi ~ N(0, I)`` (``(N, 6)``).

    ``L`` from :func:`normalizing_factor` (a semi-definite covariance is fine);
    ``numpy.random.default_rng(seed)``: the same seed gives the same draws.
    """
    n = int(n_samples)
    if n < 2:
        raise ValueError(f"Monte Carlo needs at least 2 samples; found {n}")
    x0 = np.asarray(state0, dtype=float).reshape(-1)
    lo = normalizing_factor(cov0)
    xi = np.random.default_rng(seed).standard_normal((n, lo.shape[1]))
    return x0[None, :] + xi @ lo.T


def sample_covariance(samples) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean and covariance (divisor N - 1) over the first axis of ``samples (N, ..., k)``.

    Returns ``(mean (..., k), cov (..., k, k))``.
    """
    x = np.asarray(samples, dtype=float)
    n = x.shape[0]
    mean = x.mean(axis=0)
    d = x - mean
    cov = np.einsum("n...i,n...j->...ij", d, d) / (n - 1)
    return mean, cov


def monte_carlo_bounds(n_samples: int) -> dict:
    """Statistical spread of Monte Carlo second moments from N Gaussian draws.

    * sample variance ``s^2`` of a Gaussian component: ``sd(s^2) / sigma^2 = sqrt(2/(N-1))``;
    * sample standard deviation: ``sd(s) / sigma ~ 1/sqrt(2(N-1))`` (first order);
    * sample covariance: ``sd(s_ij) = sqrt((sigma_i^2 sigma_j^2 + sigma_ij^2) / (N-1))``
      (use :func:`covariance_sd`).

    Exact for linear propagation of Gaussian errors (the propagated state is then Gaussian);
    for the nonlinear motion it is the spread around the Monte Carlo's own limit.
    """
    n = int(n_samples)
    if n < 2:
        raise ValueError(f"Monte Carlo needs at least 2 samples; found {n}")
    return {"n_samples": n, "variance_relative_sd": math.sqrt(2.0 / (n - 1)),
            "sigma_relative_sd": 1.0 / math.sqrt(2.0 * (n - 1))}


def covariance_sd(cov, n_samples: int) -> np.ndarray:
    """Standard deviation of each element of a sample covariance of N Gaussian draws."""
    c = np.asarray(cov, dtype=float)
    d = np.diagonal(c, axis1=-2, axis2=-1)
    return np.sqrt((d[..., :, None] * d[..., None, :] + c * c) / (int(n_samples) - 1))
