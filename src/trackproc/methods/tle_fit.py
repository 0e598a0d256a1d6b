"""SGP4 mean elements fitted by least squares (issue 18 item 3): the numerics, no files.

The fitted vector, at a fixed epoch, is the non-singular set

    x = [n (rev/day, Kozai), ex = e cos ω, ey = e sin ω, i (deg), Ω (deg), λ = M + ω (deg), B* (1/earth radii)]

(``e`` and ``ω`` separately are undefined for the near-circular orbits most trackers follow;
this is the set of DEFAULT_APRIORI_ELEMENTS in :mod:`trackproc.pipeline.refine`, with the mean
motion for the semi-major axis). An element set becomes an ``sgp4.api.Satrec`` through
``Satrec.sgp4init`` (WGS-72, improved mode 'i', as ``twoline2rv`` does), so what is fitted is
exactly what a TLE reader will propagate.

:func:`solve` is Gauss-Newton with Levenberg-Marquardt damping on

    cost = Σ ((z_k − h_k(x) − B_k c) / σ_k)² + (x − x_p)ᵀ P⁻¹ (x − x_p)

with ``h`` the SGP4 prediction (partials by central differences, steps of 1 % of the a-priori
sigma; STRF's rffit minimises a cost like it with a downhill simplex), ``B c`` the linear nuisance terms (a
transmitter's frequency offset and drift per pass) and the a-priori ``x_p, P`` (the initial
TLE). The covariance of ``[x_free, c]`` is the inverse normal matrix at the solution (Tapley,
Schutz & Born, Statistical Orbit Determination, 2004, section 4.4: least squares with a-priori).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from sgp4.api import WGS72, Satrec

# a TLE's measured accuracy (TLE differencing) has one home, the a-priori shared by every command
from trackproc.methods.estimation.prior import TLE_APRIORI, TLE_APRIORI_MAX_AGE_DAYS  # noqa: F401

from trackproc.errors import ProcessingError
from trackproc.methods.estimation.decision import probability_better as better

DEG = math.pi / 180.0
#: rev/day per rad/min.
REV_DAY_PER_RAD_MIN = 1440.0 / (2.0 * math.pi)
#: Julian date of the sgp4init epoch origin (1949 December 31 00:00 UT).
SGP4_EPOCH_ORIGIN_JD = 2433281.5
ELEMENT_NAMES = ("n_rev_per_day", "ex", "ey", "i_deg", "raan_deg", "lambda_deg", "bstar")
#: Relative central-difference step (of the a-priori sigma of each element).
STEP_FRACTION = 0.01


@dataclass(frozen=True)
class Epoch:
    """What an element set carries besides the fitted vector: catalogue number, UTC epoch (2-part JD)."""

    satnum: int
    jd1: float
    jd2: float


def elements_of(sat) -> np.ndarray:
    """The fitted vector of a ``Satrec``'s epoch elements (:data:`ELEMENT_NAMES`)."""
    e, w = float(sat.ecco), float(sat.argpo)
    return np.array([sat.no_kozai * REV_DAY_PER_RAD_MIN, e * math.cos(w), e * math.sin(w), sat.inclo / DEG,
                     sat.nodeo / DEG, (sat.mo + w) / DEG, sat.bstar])


def classical(x) -> dict:
    """The TLE's fields of a fitted vector: inclination, RAAN, eccentricity, argument of
    perigee, mean anomaly (degrees, angles in [0, 360)), mean motion (rev/day), B*."""
    n, ex, ey, inc, raan, lam, bstar = (float(a) for a in x)
    e = math.hypot(ex, ey)
    w = math.degrees(math.atan2(ey, ex)) % 360.0 if e > 0 else 0.0
    return {"inclination_deg": inc, "raan_deg": raan % 360.0, "eccentricity": e, "arg_perigee_deg": w,
            "mean_anomaly_deg": (lam - w) % 360.0, "mean_motion_rev_day": n, "bstar": bstar}


def satrec_of(x, epoch: Epoch):
    """The ``Satrec`` of a fitted vector (``sgp4init``, WGS-72, mode 'i'); ValueError when the
    elements are not an orbit SGP4 accepts (e outside [0, 1), inclination outside [0, 180°],
    non-positive mean motion, or an SGP4 initialisation error)."""
    c = classical(x)
    if not (c["mean_motion_rev_day"] > 0 and 0 <= c["eccentricity"] < 1 and 0 <= c["inclination_deg"] <= 180):
        raise ValueError(f"not an SGP4 orbit: n {c['mean_motion_rev_day']:.6g} rev/day, e {c['eccentricity']:.6g}, "
                         f"i {c['inclination_deg']:.6g} deg")
    sat = Satrec()
    sat.sgp4init(WGS72, "i", int(epoch.satnum), (epoch.jd1 - SGP4_EPOCH_ORIGIN_JD) + epoch.jd2, c["bstar"],
                 0.0, 0.0, c["eccentricity"], c["arg_perigee_deg"] * DEG, c["inclination_deg"] * DEG,
                 c["mean_anomaly_deg"] * DEG, c["mean_motion_rev_day"] / REV_DAY_PER_RAD_MIN, c["raan_deg"] * DEG)
    if sat.error:
        raise ValueError(f"SGP4 rejects the elements (error {sat.error})")
    return sat


def element_sigmas(a_m: float, ex: float, ey: float, i_rad: float, raan_rad: float, u_rad: float, bstar: float,
                   n_rev_day: float, semi_major_m: float) -> np.ndarray:
    """1-σ of the fitted vector from the osculating ones of refine's default a-priori (``a`` in
    m, angles in rad): ``σ_n = 1.5 n σ_a / a`` (n ∝ a^-3/2), angles in degrees."""
    return np.array([1.5 * n_rev_day * a_m / semi_major_m, ex, ey, i_rad / DEG, raan_rad / DEG, u_rad / DEG, bstar])



def tle_element_sigmas(radial_m: float, along_m: float, cross_m: float, along_m_per_day: float, bstar: float,
                       n_rev_day: float, semi_major_m: float, inclination_deg: float) -> np.ndarray:
    """1-σ of the fitted vector from a TLE's position error model (:data:`TLE_APRIORI`), near-circular
    orbit, first order: ``σ_n = along_m_per_day / (2π a)`` (rev/day: the along-track drift),
    ``σ_ex = σ_ey = radial / a`` (an eccentricity error ``δe`` gives a radial RMS ``a δe / √2`` per
    component), ``σ_i = cross / a``, ``σ_Ω = cross / (a sin i)`` (cross-track RMS ``a δi / √2``,
    ``a sin i δΩ / √2``), ``σ_λ = along / a``; angles in degrees."""
    a = float(semi_major_m)
    sin_i = max(abs(math.sin(math.radians(inclination_deg))), 0.1)
    return np.array([along_m_per_day / (2 * math.pi * a), radial_m / a, radial_m / a, math.degrees(cross_m / a),
                     math.degrees(cross_m / (a * sin_i)), math.degrees(along_m / a), bstar])


def age_covariance(sigmas, dt_days: float) -> np.ndarray:
    """The a-priori covariance (7, 7) of independent element errors ``sigmas`` given at the
    initial TLE's epoch, carried ``dt_days`` along: an error ``δn`` in the mean motion moves the
    mean argument of latitude by ``360° δn Δt`` (its along-track drift, the dominant growth of a
    TLE's error; the slow J2 drifts of Ω and ω are left out)."""
    p = np.diag(np.square(np.asarray(sigmas, float)))
    j = np.eye(7)
    j[5, 0] = 360.0 * dt_days
    return j @ p @ j.T


@dataclass
class Solution:
    """The result of :func:`solve`: all elements (fixed ones as given), the nuisance values, the
    covariance of ``[free elements, nuisance]``, residuals ``z − h − Bc`` and the cost split."""

    x: np.ndarray
    nuisance: np.ndarray
    covariance: np.ndarray
    free: np.ndarray
    residual: np.ndarray
    chi2_data: float
    chi2_prior: float
    n_data: int
    n_prior: int
    iterations: int
    converged: bool
    message: str = ""
    history: list = field(default_factory=list)

    @property
    def sigma(self) -> np.ndarray:
        """1-σ of all elements (0 for the fixed ones)."""
        out = np.zeros(self.x.size)
        m = int(self.free.sum())
        out[self.free] = np.sqrt(np.maximum(np.diag(self.covariance)[:m], 0.0))
        return out

    @property
    def element_covariance(self) -> np.ndarray:
        """Covariance (7, 7) of the elements (rows and columns of fixed ones zero)."""
        out = np.zeros((self.x.size, self.x.size))
        idx = np.flatnonzero(self.free)
        m = idx.size
        out[np.ix_(idx, idx)] = self.covariance[:m, :m]
        return out


def jacobian(model: Callable, x, free, steps) -> np.ndarray:
    """∂model/∂x of the free elements by central differences (step ``steps[k]``)."""
    cols = []
    for k in np.flatnonzero(free):
        d = np.zeros_like(x)
        d[k] = steps[k]
        cols.append((model(x + d) - model(x - d)) / (2.0 * steps[k]))
    return np.stack(cols, axis=1)


def solve(model: Callable, x0, observed, sigma, *, free=None, prior_mean=None, prior_cov=None, design=None,
          steps=None, keep=None, max_iterations: int = 30, tolerance: float = 1e-2) -> Solution:
    """Weighted least squares with a-priori information (Tapley, Schutz & Born 2004, section 4.4) of
    the elements (``free`` mask) and linear nuisance terms (``design`` columns), with an optional
    Gaussian a-priori (``prior_cov`` (7, 7), rows of the free ones used). ``keep`` excludes samples.
    Converged when every update is below ``tolerance`` of its formal 1-σ. ``model(x)`` may raise
    ValueError, ArithmeticError or ProcessingError for elements SGP4 cannot use: such a trial
    step is refused.

    Over 100 lines with this docstring; its code is under 100.
    """
    x = np.asarray(x0, float).copy()
    observed, sigma = np.asarray(observed, float), np.asarray(sigma, float)
    nobs = observed.size
    free = np.ones(x.size, bool) if free is None else np.asarray(free, bool)
    keep = np.ones(nobs, bool) if keep is None else np.asarray(keep, bool)
    b = np.zeros((nobs, 0)) if design is None else np.asarray(design, float)
    m, k = int(free.sum()), b.shape[1]
    steps = np.asarray(steps, float) if steps is not None else np.full(x.size, 1e-6)
    w = np.where(keep, 1.0 / sigma, 0.0)
    if prior_cov is not None:
        idx = np.flatnonzero(free)
        info = np.zeros((m + k, m + k))
        info[:m, :m] = np.linalg.inv(np.asarray(prior_cov, float)[np.ix_(idx, idx)])
        xp = np.asarray(prior_mean, float)
    else:
        info, xp = np.zeros((m + k, m + k)), None

    def prior_gap(xx):
        return np.zeros(m + k) if xp is None else np.r_[(xp - xx)[free], np.zeros(k)]

    def evaluate(xx):
        try:
            h = np.asarray(model(xx), float)
        except (ValueError, ArithmeticError, ProcessingError):     # SGP4 refuses these elements
            return None
        return h if np.all(np.isfinite(h[keep])) else None

    h = evaluate(x)
    if h is None:
        raise ValueError("the initial elements cannot be evaluated")
    c = np.zeros(k)
    if k:
        c = np.linalg.lstsq(b * w[:, None], (observed - h) * w, rcond=None)[0]

    def cost(hh, xx, cc):
        r = (observed - hh - b @ cc) * w
        g = prior_gap(xx)
        return float(r @ r + g @ info @ g)

    current = cost(h, x, c)
    lam, converged, message, history = 1e-3, False, "iteration limit reached", []
    normal = None
    it = 0
    for it in range(1, max_iterations + 1):
        jx = jacobian(model, x, free, steps)
        a = np.concatenate([jx, b], axis=1) * w[:, None]
        r = (observed - h - b @ c) * w
        normal = a.T @ a + info
        grad = a.T @ r + info @ prior_gap(x)
        scale = 1.0 / np.sqrt(np.maximum(np.diag(normal), 1e-300))
        ns = normal * scale[:, None] * scale[None, :]
        accepted = False
        for _ in range(12):
            step = scale * np.linalg.solve(ns + lam * np.eye(m + k), grad * scale)
            x_new = x.copy()
            x_new[free] += step[:m]
            c_new = c + step[m:]
            h_new = evaluate(x_new)
            if h_new is not None:
                trial = cost(h_new, x_new, c_new)
                if trial <= current * (1 + 1e-12):
                    accepted = True
                    break
            lam *= 10.0
        if not accepted:
            message = "no step lowers the cost (a minimum within the numerical precision)"
            converged = True
            break
        formal = np.sqrt(np.maximum(np.diag(np.linalg.pinv(normal)), 1e-300))
        ratio = float(np.max(np.abs(step) / formal))
        x, c, h, current = x_new, c_new, h_new, trial
        history.append({"iteration": it, "cost": current, "max_step_over_sigma": ratio})
        lam = max(lam / 10.0, 1e-9)
        if ratio < tolerance:
            converged, message = True, f"converged: last update {ratio:.2g} of its 1-sigma"
            break
    # the covariance at the solution (the last Jacobian when the last step was below the
    # tolerance: the Jacobian does not change over a hundredth of a sigma)
    if not (converged and history and history[-1]["max_step_over_sigma"] < tolerance):
        jx = jacobian(model, x, free, steps)
    a = np.concatenate([jx, b], axis=1) * w[:, None]
    normal = a.T @ a + info
    try:
        cov = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        raise ValueError("the normal matrix is singular: the data do not determine the elements "
                         "(an a-priori is needed)") from None
    resid = observed - h - b @ c
    g = prior_gap(x)
    rw = resid * w
    return Solution(x=x, nuisance=c, covariance=0.5 * (cov + cov.T), free=free, residual=resid,
                    chi2_data=float(rw @ rw), chi2_prior=float(g @ info @ g), n_data=int(keep.sum()),
                    n_prior=m if xp is not None else 0, iterations=it, converged=converged, message=message,
                    history=history)


def position_map(n_rev_day: float, semi_major_m: float, inclination_deg: float, dt_days: float) -> np.ndarray:
    """The linear map (6, 7) from element errors at the epoch to orbit-averaged position errors (m)
    ``dt_days`` after it, first order in a near-circular orbit: along-track ``a (δλ + 360° δn Δt)``,
    cross-track ``a δi`` and ``a sin i δΩ`` (each ``/√2``: the orbit average of its square is half),
    radial ``δa = −(2/3) a δn/n`` and ``a δex``, ``a δey`` (``/√2``). ``|G δx|²`` is the orbit
    average of the squared position error."""
    a, deg, r2 = float(semi_major_m), math.radians(1.0), math.sqrt(2.0)
    g = np.zeros((6, 7))
    g[0, 5], g[0, 0] = a * deg, a * deg * 360.0 * dt_days          # along-track
    g[1, 3] = a * deg / r2                                            # cross-track (i)
    g[2, 4] = a * deg * math.sin(math.radians(inclination_deg)) / r2  # cross-track (Ω)
    g[3, 0] = -2.0 / 3.0 * a / float(n_rev_day)                      # radial from the mean motion
    g[4, 1] = g[5, 2] = a / r2                                        # radial from the eccentricity
    return g


def position_variance(covariance, n_rev_day: float, semi_major_m: float, inclination_deg: float,
                      dt_days: float) -> float:
    """The orbit-averaged position variance (m²) ``dt_days`` after the epoch of elements with
    ``covariance`` (7, 7): ``trace(G C Gᵀ)``, ``G`` :func:`position_map`. A prediction's error in
    one number, to compare two element sets' covariances."""
    g = position_map(n_rev_day, semi_major_m, inclination_deg, dt_days)
    return max(float(np.trace(g @ np.asarray(covariance, float) @ g.T)), 0.0)


def probability_better(change, covariance, n_rev_day: float, semi_major_m: float, inclination_deg: float,
                       dt_days: float) -> tuple:
    """The probability that elements ``x_fit`` predict the position ``dt_days`` after the epoch
    better than ``x_init`` when ``x_fit``'s prediction error is ``N(0, covariance)`` (7, 7) and
    ``change = x_fit − x_init``: :func:`trackproc.methods.estimation.decision.probability_better` of
    the move ``G change`` with covariance ``G C Gᵀ`` (``G`` :func:`position_map`), the rule every
    command shares. Returns ``(probability, |d| in m, σ_u in m)``."""
    g = position_map(n_rev_day, semi_major_m, inclination_deg, dt_days)
    return better(g @ np.asarray(change, float), g @ np.asarray(covariance, float) @ g.T)