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


_IDENTITIES: dict = {}


def _identity(n: int) -> np.ndarray:
    """The n × n identity, made once and not writeable (shared by every update)."""
    eye = _IDENTITIES.get(n)
    if eye is None:
        eye = _IDENTITIES[n] = np.eye(n)
        eye.flags.writeable = False
    return eye


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
    # few temporaries and no np.eye or np.outer: a filter calls this once per sample, and its
    # cost is the number of numpy calls (the identity is built once per size, read only)
    a = np.subtract(_identity(x.size), k[:, None] * h)
    p = a @ p @ a.T
    p += variance * (k[:, None] * k)
    p += p.T
    p *= 0.5
    return x, p, s


def rts_gain(p_f, p_p_next, phi_next):
    """The Rauch–Tung–Striebel gain ``C = P_f Φᵀ (P⁻_{k+1})⁻¹`` (Tapley et al. 2004 eq. 4.15.10)
    of one step, or of a stack of steps (…, n, n) in one call: it needs the filter's quantities
    only, not the smoothed ones."""
    swap = (lambda a: a.T) if np.ndim(p_f) == 2 else (lambda a: np.swapaxes(a, -1, -2))
    return swap(np.linalg.solve(swap(p_p_next), swap(p_f @ swap(phi_next))))


def rts_step(x_f, p_f, x_p_next, p_p_next, phi_next, x_s_next, p_s_next, gain=None):
    """One backward step of the Rauch–Tung–Striebel smoother (RTS 1965; Tapley et al. 2004
    eqs. 4.15.9-4.15.11): ``C = P_f Φᵀ (P⁻_{k+1})⁻¹``, ``x_s = x_f + C (x_s,k+1 − x⁻_{k+1})``,
    ``P_s = P_f + C (P_s,k+1 − P⁻_{k+1}) Cᵀ``. ``phi_next`` = Φ(t_{k+1}, t_k); ``gain``: C when
    already computed (:func:`rts_gain` over all the steps at once)."""
    c = rts_gain(p_f, p_p_next, phi_next) if gain is None else gain
    x_s = x_f + c @ (x_s_next - x_p_next)
    p_s = p_f + c @ (p_s_next - p_p_next) @ c.T
    p_s += p_s.T
    p_s *= 0.5
    return x_s, p_s


def snc_noise(dt: float, psd) -> np.ndarray:
    """Process noise of state noise compensation: a white acceleration of power spectral density
    ``psd`` (3 × 3, m²/s³, i.e. (m/s²)²/Hz) over ``dt`` seconds, integrated through the
    two-body-free kinematics ``ṙ = v, v̇ = w`` (Tapley et al. 2004 eq. 4.9.50 with Φ ≈ the
    kinematic transition over the step): ``Q = [[dt³/3 Q̃, dt²/2 Q̃], [dt²/2 Q̃, dt Q̃]]``."""
    dt = abs(float(dt))
    q = np.asarray(psd, float)
    m = q.shape[0]
    out = np.empty((2 * m, 2 * m))              # filled by blocks: np.block costs more than the products
    out[:m, :m] = dt ** 3 / 3.0 * q
    out[:m, m:] = out[m:, :m] = dt ** 2 / 2.0 * q
    out[m:, m:] = dt * q
    return out


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


def gm_transition(dt: float, tau: float) -> tuple[float, float, float]:
    """``(f_r, f_v, e)`` of a first-order Gauss–Markov acceleration ``ȧ = −a/τ + w`` over ``dt``:
    ``e = exp(−dt/τ)`` its own transition, and the factors by which its effect on position and
    velocity differs from a constant acceleration's (``dt²/2``, ``dt``) in the kinematics
    ``ṙ = v, v̇ = a``: ``f_v = τ(1 − e)/dt``, ``f_r = 2(τ dt − τ²(1 − e))/dt²``
    (Tapley, Schutz & Born 2004 eqs. 4.9.47-4.9.49; Myers & Tapley, AIAA J. 13(3) 1975).
    A constant acceleration's columns of the orbit's transition, scaled by these, are the GM
    state's (exact for a step short against the orbital period)."""
    dt = abs(float(dt))
    x = dt / float(tau)
    if x == 0.0:
        return 1.0, 1.0, 1.0
    e = np.exp(-x)
    f_v = -np.expm1(-x) / x
    # x + expm1(-x) cancels for small x: its series x²/2 − x³/6 + x⁴/24
    f_r = 1.0 - x / 3.0 + x * x / 12.0 if x < 1e-3 else 2.0 * (x + np.expm1(-x)) / (x * x)
    return float(f_r), float(f_v), float(e)


_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)


def dmc_noise(dt: float, tau: float, sigma: float) -> np.ndarray:
    """Exact discrete process noise (3 × 3, over ``(r, v, a)`` of one axis) of dynamic model
    compensation: a first-order Gauss–Markov acceleration of steady-state sigma ``sigma``
    (m/s²) and time constant ``tau`` (s), driving noise of PSD ``q = 2σ²/τ``, integrated
    through ``ṙ = v, v̇ = a``: ``Q = ∫₀^dt q g(u) g(u)ᵀ du`` with
    ``g = ((e^{−βu} − 1 + βu)/β², (1 − e^{−βu})/β, e^{−βu})``, β = 1/τ (Tapley, Schutz & Born
    2004 eqs. 4.9.51-4.9.56; Myers & Tapley 1975). Closed form for dt/τ ≥ 0.1; below, where the
    closed form cancels, 16-point Gauss–Legendre of the same integrand (smooth: exact to
    rounding)."""
    dt = abs(float(dt))
    tau = float(tau)
    q = 2.0 * sigma * sigma / tau
    if dt == 0.0 or q == 0.0:
        return np.zeros((3, 3))
    b = 1.0 / tau
    x = b * dt
    if x < 0.1:
        u = 0.5 * dt * (_GL_NODES + 1.0)
        w = 0.5 * dt * _GL_WEIGHTS
        em = np.exp(-b * u)
        g = np.stack([(np.expm1(-b * u) + b * u) / b ** 2, -np.expm1(-b * u) / b, em])
        return q * (g * w) @ g.T
    e, e2 = np.exp(-x), np.exp(-2.0 * x)
    i1 = (1.0 - e) / b                       # ∫ e^{−βu}
    i2 = (1.0 - e2) / (2.0 * b)              # ∫ e^{−2βu}
    iu = (1.0 - e - x * e) / b ** 2          # ∫ u e^{−βu}
    qaa = i2
    qva = (i1 - i2) / b
    qvv = (dt - 2.0 * i1 + i2) / b ** 2
    qra = (i2 - dt * e) / b ** 2
    qrv = (2.0 * i1 - dt + b * dt * dt / 2.0 - i2 - b * iu) / b ** 3
    qrr = (i2 + dt + b * b * dt ** 3 / 3.0 - 2.0 * i1 + 2.0 * b * iu - b * dt * dt) / b ** 4
    return q * np.array([[qrr, qrv, qra], [qrv, qvv, qva], [qra, qva, qaa]])


def gm_bias_noise(dt: float, tau: float, sigma: float) -> float:
    """Process noise of a first-order Gauss–Markov bias over ``dt`` (transition ``e^{−dt/τ}``):
    ``σ²(1 − e^{−2dt/τ})``, which keeps its variance at ``σ²`` in steady state (Tapley, Schutz &
    Born 2004 eq. 4.9.52; Gelb 1974 table 3.3-1)."""
    return float(-sigma * sigma * np.expm1(-2.0 * abs(float(dt)) / float(tau)))
