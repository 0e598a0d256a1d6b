"""Covariances mapped to a station's range and range-rate, sigmas and correlation coefficients.
"""

from __future__ import annotations

import numpy as np

from trackproc.models.observables import range_partials, range_rate_partials


def range_range_rate_jacobian(r, v, r_st, v_st) -> np.ndarray:
    """Partials of range and range-rate with respect to the satellite state: ``(..., 2, 6)``.

    Geometric (instantaneous) range ``rho = |r - r_st|`` and range-rate
    ``rho' = u . (v - v_st)``, ``u = (r - r_st)/rho`` (seed 002 eq. 17 with the station's
    motion): ``d rho/d r = u``, ``d rho'/d r = (dv - u (u . dv)) / rho``, ``d rho'/d v = u``.
    The light time changes these partials by ``v/c`` (~3e-5 relative), below the statistics'
    own accuracy. The partials are :func:`trackproc.models.observables.range_partials` and
    :func:`~trackproc.models.observables.range_rate_partials` (``instantaneous``) at ``r, v``.
    """
    _, _, d_rho = range_partials(r, r_st)
    _, d_rr_r, d_rr_v = range_rate_partials(r, v, r_st, v_st, "instantaneous")
    out = np.zeros(d_rho.shape[:-1] + (2, 6))
    out[..., 0, :3] = d_rho
    out[..., 1, :3] = d_rr_r
    out[..., 1, 3:] = d_rr_v
    return out


def observable_covariance(jac, cov) -> np.ndarray:
    """``J P J^T`` for ``jac (..., k, 6)`` and ``cov (..., 6, 6)``: ``(..., k, k)``."""
    return np.einsum("...ij,...jk,...lk->...il", np.asarray(jac, float), np.asarray(cov, float),
                     np.asarray(jac, float))


def sigmas(cov) -> np.ndarray:
    """Standard deviations ``sqrt(diag)`` of covariances ``(..., k, k)`` (negative round-off -> 0)."""
    return np.sqrt(np.clip(np.diagonal(np.asarray(cov, float), axis1=-2, axis2=-1), 0.0, None))


def correlation_coefficients(cross, var1, var2) -> np.ndarray:
    """``R(t1, t2) / sqrt(D(t1) D(t2))`` with 0 where a variance vanishes."""
    den = np.sqrt(np.multiply.outer(np.asarray(var1, float), np.asarray(var2, float)))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, np.asarray(cross, float) / np.where(den > 0, den, 1.0), 0.0)
