"""Detection of a displacement from angle measurements: the likelihood-ratio test of seed 003.

Observations ``x_i`` (elevations, optionally azimuths) at times ``t_i`` with independent
Gaussian errors. Under H0 (displacement 0) ``E x_i = a_i``, under H1 (displacement Δ*)
``E x_i = b_i`` (eq. 1). The log-likelihood ratio is linear in the statistic (eq. 2)::

    S = Σ w_i (x_i - a_i)(b_i - a_i),      w_i = (σ₀ / σ_i)²

with moments (eqs. 3-4)::

    E[S | H0] = 0,   E[S | H1] = C_n = Σ w_i (b_i - a_i)²,   Var S = σ₀² C_n  (both hypotheses)

and ``ln Λ = (S - C_n/2) / σ₀²``. With one sigma for every sample (``σ_i = σ₀``, the paper's
case) ``w_i = 1`` and these are exactly eqs. 2-4; with per-sample sigmas they are the
likelihood-ratio statistic of the whitened problem (σ₀ is then the RMS of the σ_i, a scale only).

Discrimination (eqs. 5-7): ``γ = E[S|H1] / sqrt(Var S) = sqrt(C_n) / σ₀``, and for samples
spaced Δt over [t0, T - τ], ``C_n ≈ ‖Δε‖² / Δt`` with ``‖Δε‖² = ∫ (ε₁ - ε₀)² dt``, so
``γ = ‖Δε‖ / (σ sqrt(Δt))`` and the sensor requirement (eq. 8) is ``g = σ sqrt(Δt) = ‖Δε‖ / γ``.

Thresholds: deciding H1 when ``S > h``,
false alarm ``α = 1 - Φ(h / (σ₀ sqrt C_n))``, miss ``β = Φ((h - C_n) / (σ₀ sqrt C_n))``;
so ``h = σ₀ sqrt(C_n) Φ⁻¹(1 - α)`` for a chosen α, ``β = Φ(Φ⁻¹(1-α) - γ)``, and the
equal-error threshold ``h = C_n / 2`` gives ``α = β = 1 - Φ(γ/2)`` (γ = 5: 0.0062). For
unequal prescribed (α, β), ``γ = Φ⁻¹(1 - α) + Φ⁻¹(1 - β)``.

Pure numpy/scipy; angles in rad, times in s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

#: Gauss-Legendre nodes per panel and panels of :func:`information_distance`.
GL_NODES = 12
GL_PANELS = 24


# --------------------------------------------------------------------------- error probabilities

def gamma_from_errors(alpha: float, beta: float | None = None) -> float:
    """γ needed for false-alarm α and miss β: ``Φ⁻¹(1-α) + Φ⁻¹(1-β)`` (β = α: ``2 Φ⁻¹(1-α)``).

    Implements seed 003 eq. 7 (solved for γ).
    """
    beta = alpha if beta is None else beta
    for name, value in (("alpha", alpha), ("beta", beta)):
        if not 0.0 < value < 0.5:
            raise ValueError(f"{name} must be in (0, 0.5), got {value}")
    return float(ndtri(1.0 - alpha) + ndtri(1.0 - beta))


def equal_error(gamma) -> float:
    """α = β = 1 - Φ(γ/2) of the equal-error threshold (seed 003, after eq. 7)."""
    return float(ndtr(-np.asarray(gamma, float) / 2.0))


def miss_probability(alpha: float, gamma: float) -> float:
    """β = Φ(Φ⁻¹(1 - α) - γ) for the threshold of false-alarm probability α.

    Implements seed 003 eq. 7 (unequal error probabilities).
    """
    return float(ndtr(ndtri(1.0 - alpha) - gamma))


# --------------------------------------------------------------------------- the statistic

@dataclass(frozen=True)
class Statistic:
    """The statistic of eq. 2 and its moments (eqs. 3-4) for one pass.

    ``s``: S; ``c_n``: C_n = E[S|H1]; ``sigma0``: σ₀; ``variance``: σ₀² C_n (both hypotheses);
    ``gamma``: sqrt(C_n)/σ₀; ``n``: samples used; ``uniform_sigma``: whether w_i = 1.

    Implements seed 003 eqs. 2-4.
    """

    s: float
    c_n: float
    sigma0: float
    n: int
    uniform_sigma: bool

    @property
    def mean_h0(self) -> float:
        return 0.0

    @property
    def mean_h1(self) -> float:
        return self.c_n

    @property
    def variance(self) -> float:
        return self.sigma0 ** 2 * self.c_n

    @property
    def std(self) -> float:
        return float(np.sqrt(self.variance))

    @property
    def gamma(self) -> float:
        return float(np.sqrt(self.c_n) / self.sigma0)

    @property
    def log_likelihood_ratio(self) -> float:
        """ln p(x|H1)/p(x|H0) = (S - C_n/2) / σ₀²."""
        return (self.s - self.c_n / 2.0) / self.sigma0 ** 2


def statistic(x, a, b, sigma) -> Statistic:
    """S = Σ w_i (x_i - a_i)(b_i - a_i) and C_n = Σ w_i (b_i - a_i)² (eqs. 2-3), w_i = (σ₀/σ_i)².

    ``x, a, b, sigma``: arrays of one shape (the last axis is the samples; leading axes batch
    Monte Carlo draws of ``x``), angles in rad. Azimuth differences must be wrapped by the
    caller. Returns :class:`Statistic` (``s`` an array when ``x`` has leading axes).

    Implements seed 003 eqs. 2-4.
    """
    x = np.asarray(x, float)
    a, b, sigma = (np.asarray(v, float) for v in (a, b, sigma))
    if np.any(~np.isfinite(sigma)) or np.any(sigma <= 0):
        raise ValueError("every sigma must be positive and finite")
    sigma0 = float(np.sqrt(np.mean(sigma ** 2)))
    uniform = bool(np.all(sigma == sigma.flat[0]))
    w = np.ones_like(sigma) if uniform else (sigma0 / sigma) ** 2
    d = b - a
    s = np.sum(w * (x - a) * d, axis=-1)
    c_n = float(np.sum(w * d * d))
    return Statistic(s=s if np.ndim(s) else float(s), c_n=c_n, sigma0=sigma0 if not uniform else float(sigma.flat[0]),
                     n=int(d.shape[-1]), uniform_sigma=uniform)


@dataclass(frozen=True)
class Decision:
    """Threshold, decision and error probabilities of one test."""

    criterion: str            # "false-alarm" or "equal-error"
    threshold: float          # h: decide H1 when S > h
    decide_h1: bool
    alpha: float              # false-alarm probability at h
    beta: float               # miss probability at h
    z: float                  # S / sqrt(Var S)


def decide(stat: Statistic, false_alarm: float | None = None) -> Decision:
    """Threshold for the chosen false-alarm probability (or the equal-error one, ``h = C_n/2``)."""
    std = stat.std
    if stat.c_n <= 0 or std <= 0:
        raise ValueError("the hypotheses give identical predictions (C_n = 0): nothing to test")
    if false_alarm is None:
        h = stat.c_n / 2.0
        alpha = beta = equal_error(stat.gamma)
        criterion = "equal-error"
    else:
        if not 0.0 < false_alarm < 1.0:
            raise ValueError(f"false-alarm probability must be in (0, 1), got {false_alarm}")
        h = std * float(ndtri(1.0 - false_alarm))
        alpha = float(false_alarm)
        beta = miss_probability(false_alarm, stat.gamma)
        criterion = "false-alarm"
    return Decision(criterion=criterion, threshold=float(h), decide_h1=bool(np.asarray(stat.s) > h),
                    alpha=alpha, beta=beta, z=float(np.asarray(stat.s) / std))


# --------------------------------------------------------------------------- information distance

def information_distance(delta_fn, t_start_s: float, t_end_s: float, *, panels: int = GL_PANELS,
                         nodes: int = GL_NODES) -> float:
    """‖Δε‖ = sqrt(∫ Δε(t)² dt) over [t_start, t_end] (eq. 5), rad·s^½.

    ``delta_fn(t)`` returns ε₁(t) - ε₀(t) for an array of times (s relative to impact, so
    ``t_end = -τ < 0``). The integrand grows like 1/t² towards impact; the quadrature runs in
    ``u = ln(-t)`` (``dt = -t du``) with composite Gauss-Legendre (``panels`` × ``nodes``),
    which the tests check against scipy's adaptive ``quad`` to 1e-9 relative. An empty window
    (``t_end <= t_start``) gives 0.

    Implements seed 003 eq. 5.
    """
    if not t_end_s < 0:
        raise ValueError("the window must end before impact (t_end = -tau < 0)")
    if t_end_s <= t_start_s:
        return 0.0
    u0, u1 = np.log(-t_end_s), np.log(-t_start_s)
    x, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.linspace(u0, u1, panels + 1)
    half = np.diff(edges) / 2.0
    mid = (edges[:-1] + edges[1:]) / 2.0
    u = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    weights = (half[:, None] * w[None, :]).ravel()
    t = -np.exp(u)
    d = np.asarray(delta_fn(t), float)
    return float(np.sqrt(np.sum(weights * d * d * (-t))))


def requirement_g(distance: float, gamma: float) -> float:
    """Eq. 8: ``g = σ sqrt(Δt) = ‖Δε‖ / γ`` (rad·s^½).

    Implements seed 003 eq. 8.
    """
    return float(distance) / float(gamma)


def sample_spacing(g: float, sigma_rad: float) -> float:
    """Δt = (g / σ)² (s): the spacing that meets the requirement with noise σ (Fig. 3).

    Implements seed 003 eq. 8 (solved for Δt).
    """
    return (float(g) / float(sigma_rad)) ** 2
