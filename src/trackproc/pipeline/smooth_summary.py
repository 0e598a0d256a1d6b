"""What ``smooth`` writes about its fits: the per-fit record (read back by
:mod:`trackproc.io.smoothing_record`), the summary in the output's metadata and as JSON, and the
fitted curve on a time grid (``--grid``). Pure functions of :class:`~trackproc.pipeline.smooth.PassFit`
lists; :func:`trackproc.pipeline.smooth.smooth` calls them."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from trackproc.io.jsonutil import json_ready
from trackproc.io.passfile import COLUMNS
from trackproc.io.raw import KIND_UNITS
from trackproc.isotime import iso_utc, to_datetime64_ns
from trackproc.methods.smoothing import DEFAULT_MAX_DEGREE, TCA_SPREAD_RATIO, PolynomialFit
from trackproc.io.jsonutil import dumps_indented
from trackproc import __version__

if TYPE_CHECKING:
    from trackproc.pipeline.smooth import PassFit, SmoothOptions

#: Kinds whose fit gives a time of closest approach.
TCA_KINDS = ("range_rate", "range", "doppler")

DEGREE_CRITERION = ("BIC with the variance factor profiled out: n ln(chi2_d / n) + (d + 1) ln n, chi2_d the "
                    "generalized (AR(1)-whitened) residual sum of squares, minimum over d = 0..cap, "
                    "cap = min(max_degree, floor(n_eff / 2) - 1): at least 2 effective samples per coefficient")
CLIP_RULE = ("iterative: reject |u| > K * 1.4826 * MAD(u of the samples in use), u = r / (sigma sqrt(1 - h)) "
             "(leverage h; sqrt(1 + h) for samples out of the fit); every sample re-tested against each new "
             "fit until the rejected set is stable; at most 10 % of a pass (beyond: the worst 10 %, and "
             "warning many_rejected)")
NOISE_MODEL = ("r / sigma = stationary AR(1) (first-order Gauss-Markov): correlation rho^(dt / step_s); rho by "
               "the method of moments on the residuals of the white-noise fit, corrected for the fit's projection; "
               "rho = 0 (white) unless 2 standard errors above; rho > 0: generalized least squares, "
               "n_eff = 1 + sum (1 - a_i) / (1 + a_i), a_i = rho^(dt_i / step_s)")

GRID_NOTE = ("value = fitted curve, sigma = its 1-sigma from the scaled coefficient covariance; "
             "grid values are strongly correlated (functions of degree + 1 coefficients): weight "
             "with the coefficient covariance, not as independent samples")


def summary_json(summary: dict, ready: bool = False) -> str:
    """The summary as strict JSON text (NaN and infinities as null), indented, newline-terminated.
    ``ready``: ``summary`` is :func:`json_ready`'s output already (``SmoothResult.summary`` is), so
    not converted again (the same text: ``json_ready`` of its own output is that output)."""
    return dumps_indented(summary if ready else json_ready(summary), 2) + "\n"


def iso(ts) -> str:
    return iso_utc(ts, 9)


def at_offset(epoch, t_s: float) -> np.datetime64:
    """``epoch`` (UTC ``datetime64[ns]``, or a pandas Timestamp) plus ``t_s`` seconds rounded to the ns."""
    return to_datetime64_ns(epoch) + np.timedelta64(int(round(t_s * 1e9)), "ns")


def finite_or_none(x):
    return float(x) if x is not None and math.isfinite(x) else None


def degree_notes(fit: PolynomialFit, max_degree: int) -> list:
    if not (fit.degree_scores and fit.degree_at_limit):
        return []
    if fit.degree_cap is not None and fit.degree_cap < max_degree:
        return [f"degree_at_limit: BIC still falls at degree {fit.degree}, the largest the {fit.n_used} samples "
                f"({fit.n_eff:.0f} effective) support with 2 per coefficient; the curve may be under-fitted "
                "(its residuals and degree spread show it)"]
    return [f"degree_at_limit: BIC still falls at degree {fit.degree}, the search limit; the curve may "
            "be under-fitted (try a larger --max-degree, or shorter passes)"]


def fit_record(f: PassFit, carrier_hz, doppler_mode, max_degree: int = DEFAULT_MAX_DEGREE) -> dict:
    unit = KIND_UNITS.get(f.kind, "")
    rec = {"station": f.station, "pass_id": f.pass_id, "kind": f.kind, "unit": unit, "status": f.status,
           "error": f.error, "reason": f.reason, "warnings": list(f.warnings), "n_samples": int(f.t_s.size),
           "epoch_utc": iso(f.epoch_utc)}
    fit = f.fit
    if fit is None:
        rec.update({"n_used": 0, "n_rejected": int(f.t_s.size)})
        return rec
    tu = f.t_s[fit.used]
    ru = fit.residual[fit.used]
    lag1 = float(np.corrcoef(ru[:-1], ru[1:])[0, 1]) if ru.size > 3 and np.std(ru) > 0 else None
    rec.update({
        "n_used": fit.n_used, "n_rejected": fit.n_rejected,
        "basis": fit.basis,
        "domain_s": [float(fit.domain_s[0]), float(fit.domain_s[1])],
        "domain_utc": [iso(at_offset(f.epoch_utc, fit.domain_s[0])), iso(at_offset(f.epoch_utc, fit.domain_s[1]))],
        "degree": fit.degree,
        "degree_selection": ({"criterion": "bic", "at_limit": bool(fit.degree_at_limit),
                              "cap": fit.degree_cap, "max_degree": int(max_degree),
                              "bic": {str(k): float(v) for k, v in fit.degree_scores.items()}}
                             if fit.degree_scores else {"criterion": "fixed"}),
        "noise": {"model": "white" if fit.noise.white else "ar1", "rho": fit.noise.rho,
                  "unresolved": bool(fit.noise.unresolved),
                  "rho_estimate": fit.noise.rho_estimate, "step_s": fit.noise.step_s,
                  "lag1_observed": finite_or_none(fit.noise.lag1_observed),
                  "estimated_at_degree": fit.noise.degree},
        "rho": fit.noise.rho,
        "n_eff": fit.n_eff,
        "coefficients": fit.coef.tolist(),
        "covariance_unscaled": fit.cov_unscaled.tolist(),
        "covariance_scaled": fit.cov_scaled.tolist(),
        "variance_factor": fit.variance_factor,
        "chi2": fit.chi2, "dof": fit.dof,
        "rms": fit.rms, "weighted_rms": fit.wrms,
        "robust_scale": fit.robust_scale if math.isfinite(fit.robust_scale) else None,
        "iterations": fit.iterations, "clip_converged": bool(fit.clip_converged),
        "n_over_threshold": fit.n_over_threshold, "rejection_capped": bool(fit.rejection_capped),
        "condition_number": fit.condition_number,
        "largest_gap_s": float(np.max(np.diff(tu))) if tu.size > 1 else 0.0,
        "residual_lag1_correlation": lag1,
        "notes": degree_notes(fit, max_degree),
    })
    if f.kind in TCA_KINDS:
        if f.tca is None:
            rec["tca"] = {"status": "not_observed", "error": f.tca_error}
        else:
            ca = f.tca
            spread = f.tca_spread[0]
            tca = {"status": "uncertain" if "tca_uncertain" in f.warnings else "ok", "definition": ca.definition,
                   "time_utc": iso(at_offset(f.epoch_utc, ca.t_s)),
                   "t_s": ca.t_s, "sigma_s": ca.sigma_s, "sigma_s_unscaled": ca.sigma_s_unscaled,
                   "gap_s": f.tca_gap_s, "candidates": ca.n_candidates,
                   "degree_spread_s": spread, "degree_spread_fits": f.tca_spread[2],
                   "uncertainty_s": math.hypot(ca.sigma_s, spread) if math.isfinite(spread) else ca.sigma_s,
                   "spread_to_sigma": spread / ca.sigma_s if math.isfinite(spread) and ca.sigma_s > 0 else None,
                   "note": f.tca_error,
                   "value": ca.value, "value_sigma": ca.value_sigma, "value_unit": unit,
                   "value_degree_spread": f.tca_spread[1],
                   "correlation_t_value": float(ca.cov[0, 1] / math.sqrt(ca.cov[0, 0] * ca.cov[1, 1]))
                   if ca.cov[0, 0] > 0 and ca.cov[1, 1] > 0 else None}
            rec["tca"] = tca
            if f.kind == "doppler" and doppler_mode != "two-way" and carrier_hz is not None:
                rec["carrier_hz"] = float(carrier_hz)
                rec["fca_hz"] = float(carrier_hz) + ca.value
                rec["fca_sigma_hz"] = ca.value_sigma
                rec["fca_sigma_hz_unscaled"] = ca.value_sigma_unscaled
                rec["fca_degree_spread_hz"] = f.tca_spread[1]
    return rec


def summary_of(fits, options: SmoothOptions, meta, source, doppler_mode, carrier_hz) -> dict:
    counts = {s: sum(f.status == s for f in fits) for s in ("ok", "suspect", "failed")}
    return {
        "trackproc_version": __version__,
        "command": "smooth",
        "source": source,
        "method": {
            "model": "weighted least squares, generalized polynomial y(t) = phi(t)^T C (seed 004 eq. 1), "
                     "QR of the whitened system",
            "basis": options.basis,
            "time_argument": "t_s = seconds from epoch_utc; x = (2 t_s - (a + b)) / (b - a) on domain_s = [a, b]; "
                             "numpy.polynomial.<Basis>(coefficients, domain=domain_s)(t_s)",
            "degree": options.degree if isinstance(options.degree, str) else int(options.degree),
            "degree_criterion": DEGREE_CRITERION if options.degree == "auto" else "fixed",
            "max_degree": int(options.max_degree),
            "clip": options.clip if options.clip else None,
            "clip_rule": CLIP_RULE if options.clip else "no rejection",
            "covariance": "covariance_unscaled = (A^T W A)^-1 from the a-priori sigmas (W = (S C S)^-1 with the AR(1) "
                          "correlation C; diag(1/sigma^2) when white); covariance_scaled = variance_factor * "
                          "covariance_unscaled, variance_factor = chi2 / dof (chi2 generalized)",
            "noise": NOISE_MODEL,
            "tca": {"range_rate": "zero of the fitted range-rate (negative to positive)",
                    "range": "minimum of the fitted range",
                    "doppler": ("zero of the fitted Doppler" if doppler_mode == "two-way" else
                                "inflection point of the fitted one-way Doppler (zero of the second derivative); "
                                "fca_hz = carrier_hz + fitted Doppler there"),
                    "sigma": "first order: sigma_t = sigma_g(t*) / |g'(t*)| for g the curve or derivative that "
                             "vanishes, from covariance_scaled; value sigma includes its correlation with t*",
                    "degree_spread": "standard deviation of t* (and of the value there) over refits with degree "
                                     "-2..+2 on the same samples: model error, not in sigma",
                    "status": f"ok, or uncertain when degree_spread_s > {TCA_SPREAD_RATIO:g} sigma_s or the noise "
                              "is curve_unresolved (use uncertainty_s = hypot(sigma_s, degree_spread_s)); "
                              "not_observed",
                    "max_gap_s": options.tca_max_gap_s},
        },
        "doppler_mode": doppler_mode,
        "carrier_hz": carrier_hz,
        "counts": {"fits": len(fits), **counts},
        "fits": [fit_record(f, carrier_hz, doppler_mode, options.max_degree) for f in fits],
    }


def grid_of(fits, step_s: float):
    """The fitted curves every ``step_s`` seconds as a DataFrame of :data:`COLUMNS`."""
    import pandas as pd  # start-up: pandas only for a grid output (smooth --grid)

    parts = []
    for f in fits:
        if f.fit is None:
            continue
        a, b = f.fit.domain_s
        t = a + step_s * np.arange(int(math.floor((b - a) / step_s + 1e-9)) + 1)
        ns = np.round(t * 1e9).astype(np.int64)
        times = pd.DatetimeIndex(to_datetime64_ns(f.epoch_utc).astype(np.int64) + ns, tz="UTC")
        parts.append(pd.DataFrame({"time": times, "station": f.station, "pass_id": f.pass_id, "kind": f.kind,
                                   "value": np.mod(f.fit(t), 2 * np.pi) if f.kind == "azimuth" else f.fit(t),
                                   "sigma": f.fit.sigma(t)}))
    if not parts:
        return pd.DataFrame({c: [] for c in COLUMNS})
    grid = pd.concat(parts, ignore_index=True)
    return grid.sort_values(["station", "time", "kind"], kind="mergesort").reset_index(drop=True)[list(COLUMNS)]
