"""Sequential estimation: the Kalman filter's time and measurement updates, the Rauch–Tung–Striebel
smoother, state-noise-compensation process noise and the filter-smoother consistency test.

Pure numpy on arrays; the orbit, the measurement model and the bookkeeping live in
:mod:`trackproc.pipeline.filter`. References: Tapley, Schutz & Born, *Statistical Orbit
Determination* (2004), ch. 4.7-4.9 (linearised and extended Kalman filter, Joseph form, process
noise); Rauch, Tung & Striebel, AIAA J. 3(8) 1965 (fixed-interval smoother); McReynolds'
filter-smoother consistency test as stated by Wright (ODTK, "Sequential orbit determination with
auto-correlated gravity modeling errors", and Vallado's *Fundamentals of Astrodynamics*, 4th ed.,
10.8): ``(x_s − x_f) / sqrt(P_f − P_s)`` is N(0, 1) per state component when the models hold.
"""

from __future__ import annotations

import numpy as np


def time_update(x, p, phi, q=None):
    """Prediction ``x⁻ = Φ x``, ``P⁻ = Φ P Φᵀ + Q`` (Tapley et al. 2004 eqs. 4.7.1, 4.9.1)."""
    x = phi @ x
    p = phi @ p @ phi.T
    if q is not None:
        p = p + q
    return x, 0.5 * (p + p.T)


def scalar_update(x, p, h, innovation, variance):
    """Measurement update by one scalar observation with the Joseph form
    ``P⁺ = (I − K h) P (I − K h)ᵀ + K r Kᵀ`` (Tapley et al. 2004 eq. 4.7.19; Bucy & Joseph 1968),
    which stays symmetric positive definite where ``(I − K h) P`` loses it to rounding.

    ``h`` (n,) the row of partials, ``innovation`` ``y − h(x⁻)`` (the deviation form: already
    net of ``h δx⁻``), ``variance`` r the sample's noise variance. Returns ``(x⁺, P⁺, S)`` with
    ``S = h P hᵀ + r`` the innovation variance."""
    ph = p @ h
    s = float(h @ ph) + variance
    k = ph / s
    x = x + k * innovation
    a = np.eye(x.size) - np.outer(k, h)
    p = a @ p @ a.T + variance * np.outer(k, k)
    return x, 0.5 * (p + p.T), s


def rts_step(x_f, p_f, x_p_next, p_p_next, phi_next, x_s_next, p_s_next):
    """One backward step of the Rauch–Tung–Striebel smoother (RTS 1965; Tapley et al. 2004
    eqs. 4.15.9-4.15.11): ``C = P_f Φᵀ (P⁻_{k+1})⁻¹``, ``x_s = x_f + C (x_s,k+1 − x⁻_{k+1})``,
    ``P_s = P_f + C (P_s,k+1 − P⁻_{k+1}) Cᵀ``. ``phi_next`` = Φ(t_{k+1}, t_k)."""
    c = np.linalg.solve(p_p_next.T, (p_f @ phi_next.T).T).T
    x_s = x_f + c @ (x_s_next - x_p_next)
    p_s = p_f + c @ (p_s_next - p_p_next) @ c.T
    return x_s, 0.5 * (p_s + p_s.T)


def snc_noise(dt: float, psd) -> np.ndarray:
    """Process noise of state noise compensation: a white acceleration of power spectral density
    ``psd`` (3 × 3, m²/s³, i.e. (m/s²)²/Hz) over ``dt`` seconds, integrated through the
    two-body-free kinematics ``ṙ = v, v̇ = w`` (Tapley et al. 2004 eq. 4.9.50 with Φ ≈ the
    kinematic transition over the step): ``Q = [[dt³/3 Q̃, dt²/2 Q̃], [dt²/2 Q̃, dt Q̃]]``."""
    dt = abs(float(dt))
    q = np.asarray(psd, float)
    return np.block([[dt ** 3 / 3.0 * q, dt ** 2 / 2.0 * q], [dt ** 2 / 2.0 * q, dt * q]])


def nis_test(chi2: float, dof: int, probability: float = 0.999) -> tuple[float, float]:
    """Two-sided band of the normalised innovation squared summed over a run: χ²(dof) between its
    ``(1 − p)/2`` and ``(1 + p)/2`` points (Bar-Shalom, Li & Kirubarajan 2001, 5.4.2)."""
    from scipy.stats import chi2 as chi2_dist

    lo = float(chi2_dist.ppf((1.0 - probability) / 2.0, dof))
    hi = float(chi2_dist.ppf((1.0 + probability) / 2.0, dof))
    return lo, hi


def mcreynolds(x_f, p_f, x_s, p_s, floor: float = 1e-12):
    """McReynolds' filter-smoother consistency statistic per component: ``(x_s − x_f) / σ`` with
    ``σ² = diag(P_f − P_s)`` (the difference is independent of the smoothed error, so the ratio
    is N(0, 1) when the filter's models hold). Components where the smoother adds nothing
    (``σ² ≤ floor · P_f``, e.g. at the last time) are NaN."""
    d = np.asarray(x_s, float) - np.asarray(x_f, float)
    var = np.diagonal(np.asarray(p_f, float) - np.asarray(p_s, float), axis1=-2, axis2=-1)
    pf = np.diagonal(np.asarray(p_f, float), axis1=-2, axis2=-1)
    ok = var > floor * np.abs(pf)
    out = np.full(d.shape, np.nan)
    out[ok] = d[ok] / np.sqrt(var[ok])
    return out
