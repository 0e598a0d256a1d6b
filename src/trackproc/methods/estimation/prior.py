"""The a-priori of an orbit solution, once for every command (``refine``, ``estimate``, ``fit-tle``,
``filter``): where its accuracy comes from, its share of χ², the test of a conflict with the data,
and its scaling.

A list of :class:`~trackproc.methods.least_squares.Prior` constrains parameters by index; the state
``x..vz`` is indices 0-5. A prior that spans state and other parameters (``--apriori-sigma`` on the
state and a bias, always diagonal) counts here by its state rows.

Where the a-priori of a state comes from (:data:`SOURCES`):

* ``stated`` — its accuracy is known: a state file's covariance, ``--apriori-sigma``, or a TLE's
  (:func:`tle_apriori_covariance`: TLE differencing, growing with the TLE's age). Data that
  contradict a stated a-priori are declined, not allowed to loosen it
  (:mod:`trackproc.methods.estimation.decision`).
* ``default`` — a state with no stated accuracy: refine's documented element sigmas
  (:data:`DEFAULT_APRIORI_ELEMENTS`); only this one may be adapted to the data.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods import quality as qm
from trackproc.methods.least_squares import Prior
from trackproc.methods.refinement import ELEMENT_NAMES, element_covariance

#: Where a state a-priori came from: its accuracy is known (``stated``), or a documented default.
SOURCES = ("stated", "default")

#: The a-priori of a state without covariance (non-singular elements, m and rad): the along-track
#: phase loose and the period tight, as an orbit catalogue knows them (docs/refine.md, "A-priori").
DEFAULT_APRIORI_ELEMENTS = {"a_m": 50.0, "ex": 5e-5, "ey": 5e-5, "i_rad": 1e-4, "raan_rad": 1e-4, "u_rad": 4e-4}

#: A TLE's position error at its epoch (1σ, m, radial / along-track / cross-track) and the growth of
#: the along-track error per day of age (a mean-motion error). Calibrated by TLE differencing (each
#: older TLE's SGP4 prediction against a newer one's, over 1.6 h about the newer epoch, RMS over the
#: pairs; ages 0.4-3.2 days) on the 10 Delfi-C3 TLEs of the DopTrack development days (1-10 April
#: 2020), no Doppler data: along-track 250 m at 0.4-0.8 d, 680 m at 0.8-1.7 d, 1300 m at 1.7-3.2 d
#: (drift ~520 m/day), radial 30-125 m, cross-track 17-52 m (``benchmarks/fit_tle_doptrack.py
#: tle-apriori``). Refine's default element sigmas are ~10x looser along-track.
TLE_APRIORI = {"radial_m": 100.0, "along_m": 200.0, "cross_m": 50.0, "along_m_per_day": 550.0}
#: The ages (days) :data:`TLE_APRIORI` was measured at. Older TLEs drift faster than linearly (drag):
#: along-track 2.6 km at 3.2-5 d, 5.3 km at 5-7 d, 17 km at 7-10 d against the linear model's 2.2,
#: 3.3 and 4.7 km; :func:`tle_along_sigma_m` follows those beyond this age.
TLE_APRIORI_MAX_AGE_DAYS = 3.2
#: Along-track 1σ (m) of older TLEs by age (days): the TLE-differencing figures above, linear between
#: them and beyond the last (the drift of a decaying orbit grows with age).
TLE_OLD_ALONG_M = ((3.2, 1960.0), (4.1, 2600.0), (6.0, 5300.0), (8.5, 17000.0))


def tle_along_sigma_m(age_days: float) -> float:
    """Along-track 1σ (m) of a TLE ``age_days`` old (either side of its epoch): :data:`TLE_APRIORI`'s
    linear model to :data:`TLE_APRIORI_MAX_AGE_DAYS`, then :data:`TLE_OLD_ALONG_M` (never below the
    linear model)."""
    age = abs(float(age_days))
    linear = TLE_APRIORI["along_m"] + TLE_APRIORI["along_m_per_day"] * age
    if age <= TLE_APRIORI_MAX_AGE_DAYS:
        return linear
    ages, sig = zip(*TLE_OLD_ALONG_M)
    if age <= ages[-1]:
        return max(linear, float(np.interp(age, ages, sig)))
    slope = (sig[-1] - sig[-2]) / (ages[-1] - ages[-2])
    return max(linear, sig[-1] + slope * (age - ages[-1]))


def tle_apriori_elements(rv, mu_m3_s2: float, age_days: float) -> dict:
    """A TLE's accuracy at ``age_days`` as independent errors of the non-singular elements (m and rad,
    :data:`~trackproc.methods.refinement.ELEMENT_NAMES`), near-circular orbit, first order (as
    :func:`trackproc.methods.tle_fit.tle_element_sigmas` for mean elements): the semi-major axis from
    the along-track drift per day (``δλ̇ = −(3/2) n δa / a``), the eccentricity vector from the radial
    error, inclination and node from the cross-track error, the argument of latitude from the
    along-track error at that age (:func:`tle_along_sigma_m`); the older the TLE, the looser also its
    radial and cross-track terms (in proportion to the along-track one)."""
    rv = np.asarray(rv, float)
    r, v = rv[:3], rv[3:6]
    a = 1.0 / (2.0 / float(np.linalg.norm(r)) - float(v @ v) / mu_m3_s2)
    n = math.sqrt(mu_m3_s2 / a ** 3)
    h = np.cross(r, v)
    sin_i = max(abs(math.sqrt(h[0] ** 2 + h[1] ** 2) / float(np.linalg.norm(h))), 0.1)
    along = tle_along_sigma_m(age_days)
    grow = along / (TLE_APRIORI["along_m"] + TLE_APRIORI["along_m_per_day"] * min(abs(age_days),
                                                                                   TLE_APRIORI_MAX_AGE_DAYS))
    radial, cross = TLE_APRIORI["radial_m"] * grow, TLE_APRIORI["cross_m"] * grow
    per_day = max(TLE_APRIORI["along_m_per_day"], along / max(abs(age_days), 1.0))
    return {"a_m": per_day / (1.5 * n * 86400.0), "ex": radial / a, "ey": radial / a, "i_rad": cross / a,
            "raan_rad": cross / (a * sin_i), "u_rad": along / a}


def tle_apriori_covariance(rv, mu_m3_s2: float, age_days: float) -> np.ndarray:
    """GCRF covariance (6, 6) of a TLE's state ``rv`` ``age_days`` from its epoch
    (:func:`tle_apriori_elements`)."""
    sig = tle_apriori_elements(rv, mu_m3_s2, age_days)
    return element_covariance(rv, mu_m3_s2, [sig[k] for k in ELEMENT_NAMES])


def default_apriori_covariance(rv, mu_m3_s2: float) -> np.ndarray:
    """GCRF covariance (6, 6) of :data:`DEFAULT_APRIORI_ELEMENTS` at the state ``rv``."""
    return element_covariance(rv, mu_m3_s2, [DEFAULT_APRIORI_ELEMENTS[k] for k in ELEMENT_NAMES])


def default_apriori_text() -> str:
    """:data:`DEFAULT_APRIORI_ELEMENTS` in words, for the notes."""
    return "orbital-element sigmas " + ", ".join(f"{k} {v:g}" for k, v in DEFAULT_APRIORI_ELEMENTS.items())


def _state_rows(p: Prior) -> np.ndarray:
    return np.flatnonzero(np.asarray(p.index, int) < 6)


def has_state_prior(priors) -> bool:
    """Does any prior constrain the state?"""
    return any(_state_rows(p).size for p in priors)


def state_prior_chi2(priors, x) -> tuple[float, int]:
    """The state a-priori's share of χ² at ``x`` and its number of rows (the x..vz rows of every prior)."""
    chi2, rows = 0.0, 0
    for p in priors:
        sel = _state_rows(p)
        if sel.size:
            r = np.asarray(x, float)[np.asarray(p.index, int)[sel]] - np.asarray(p.centre, float)[sel]
            chi2 += float(r @ np.linalg.solve(np.asarray(p.covariance, float)[np.ix_(sel, sel)], r))
            rows += sel.size
    return chi2, rows


def state_prior_centre(priors) -> np.ndarray:
    """The a-priori centre of x..vz (NaN where none)."""
    centre = np.full(6, np.nan)
    for p in priors:
        sel = _state_rows(p)
        centre[np.asarray(p.index, int)[sel]] = np.asarray(p.centre, float)[sel]
    return centre


def state_prior_covariance(priors):
    """The 6 × 6 a-priori covariance of x..vz (None unless all six have one)."""
    cov = np.full((6, 6), np.nan)
    for p in priors:
        sel = _state_rows(p)
        idx = np.asarray(p.index, int)[sel]
        cov[np.ix_(idx, idx)] = np.asarray(p.covariance, float)[np.ix_(sel, sel)]
    return None if np.isnan(np.diag(cov)).any() else np.nan_to_num(cov, nan=0.0)


def scaled_priors(priors, factor: float) -> list:
    """``priors`` with the state rows' covariance times ``factor``; a prior on state and other
    parameters (always diagonal) is split in two, its other rows unchanged."""
    out = []
    for p in priors:
        idx, cov = np.asarray(p.index, int), np.asarray(p.covariance, float)
        sel = _state_rows(p)
        if sel.size == idx.size:
            out.append(Prior(idx, np.asarray(p.centre, float), cov * factor))
            continue
        rest = np.setdiff1d(np.arange(idx.size), sel)
        if sel.size:
            out.append(Prior(idx[sel], np.asarray(p.centre, float)[sel], cov[np.ix_(sel, sel)] * factor))
        out.append(Prior(idx[rest], np.asarray(p.centre, float)[rest], cov[np.ix_(rest, rest)]))
    return out


def apriori_test(priors, x, posterior_cov=None, innovation: bool = True, consider_cov=None):
    """Do the data contradict the state's a-priori? With a full 6 × 6 state a-priori and the
    solution's covariance ``posterior_cov`` (state first), the innovation of the a-priori
    (:func:`~trackproc.methods.quality.prior_innovation_chi2`: the correction against its own
    covariance ``P − C`` over the directions the data see), χ² with that many degrees of freedom
    when the a-priori is right; it keeps its power when the data are weak against the a-priori (one
    short pass, one station's evening), where the a-priori's share of χ² (mean: its redundancy, a
    fraction of the rows) stays below χ²(rows)'s point whatever the initial error. Otherwise (no full
    a-priori, no covariance, or ``innovation`` False: a sandwich or constrained covariance) that
    share against χ²(rows). ``consider_cov`` (6 × 6): what errors the solution does not estimate add
    to its covariance (a station's time-tag offset): the correction is judged with them. Returns
    ``{"chi2", "rows" (the share), "statistic", "dof", "limit", "conflict", "test"}``, or None
    without a state a-priori."""
    chi2, rows = state_prior_chi2(priors, x)
    if not rows:
        return None
    pcov = state_prior_covariance(priors)
    if pcov is None or posterior_cov is None or not innovation:
        return qm.apriori_conflict(chi2, rows)
    return qm.apriori_conflict(chi2, rows, np.asarray(x, float)[:6] - state_prior_centre(priors), pcov,
                               np.asarray(posterior_cov, float)[:6, :6],
                               None if consider_cov is None else np.asarray(consider_cov, float)[:6, :6])


def prior_dominance(posterior_cov, prior_cov) -> float:
    """How much a solution rests on its a-priori rather than on the data: the largest generalised
    eigenvalue of ``C v = λ P v`` (``C`` the posterior, ``P`` the a-priori covariance of the same
    parameters; ``λ = 1 / (1 + d)`` with ``d`` the data's information in that direction relative
    to the a-priori's). Above 1/2 the a-priori weighs more than the data in some direction."""
    from scipy.linalg import eigh

    return float(eigh(np.asarray(posterior_cov, float), np.asarray(prior_cov, float), eigvals_only=True).max())


def test_report(test: dict) -> dict:
    """The a-priori test (:func:`apriori_test`) as the diagnostics give it."""
    return {k: test[k] for k in ("test", "statistic", "dof", "limit", "conflict")}


def adapt_step(chi2: float, redundancy: float, factor: float) -> tuple:
    """One step of the a-priori's variance-component fixed point (the maximum-likelihood component
    ``σ²_p = vᵀPv / r_p``, Koch 1999 eq. 3.291: :func:`~trackproc.methods.quality.prior_variance_component`),
    the rule of every command's gate: ``(k̂, next factor)``, the next factor None when the iteration
    stops — k̂ cannot be estimated, is within 0.1 of 1 (converged), or would tighten an a-priori
    that is not loosened (never below the stated one, ``max(1, factor k̂)``)."""
    k_hat = qm.prior_variance_component(chi2, redundancy)
    if k_hat is None or abs(k_hat - 1.0) < 0.1 or (k_hat < 1.0 and factor <= 1.0):
        return k_hat, None
    return k_hat, max(1.0, factor * k_hat)
