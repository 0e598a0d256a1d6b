"""``trackproc smooth``: least-squares generalized-polynomial smoothing of every pass (seed 004 eq. 1).

Each (station, pass_id, kind) group of the canonical pass table is fitted on its own by
:func:`trackproc.methods.smoothing.smooth_pass` (Chebyshev or Legendre basis on the pass interval
mapped to [-1, 1]; fixed degree or BIC-selected; iterative K-sigma rejection with a robust scale).
For range-rate, range and Doppler the time of closest approach (TCA) follows from the fitted curve
(:func:`trackproc.methods.smoothing.closest_approach`); for one-way Doppler also the carrier at
closest approach ``fca = carrier_hz + doppler(tca)``.

Status of each fit, in the summary and the metadata:

- ``ok``: fitted, no warning;
- ``suspect``: fitted, with warnings: ``tca_not_observed`` (no TCA inside the pass, or it falls
  in a data gap longer than ``tca_max_gap_s`` or closer than that to either end of the data, so
  it would be an interpolation or extrapolation of the polynomial), ``tca_uncertain`` (the TCA
  moves over neighbouring degrees by more than ``TCA_SPREAD_RATIO`` times its formal sigma: the
  curve, not the noise, limits it; or the noise is ``curve_unresolved``; ``tca.status = uncertain``), ``largest_gap`` (one data gap
  covers more than half of the pass), ``curve_unresolved`` (the residuals are correlated, but
  correlated noise and curve the polynomial does not follow cannot be told apart with these
  samples: the noise is taken as white and the sigmas may be too small), ``many_rejected`` (more than 10 % of the samples exceed the
  rejection threshold: only the worst 10 % are flagged, the rest kept), ``clip_not_converged``
  (the rejected set kept changing);
- ``failed``: not fitted (too few points for the degree, a single time, too few left after
  rejection, rank deficient); the other passes proceed.

:func:`smooth` raises :class:`~trackproc.errors.ProcessingError` only when no fit succeeded.

Azimuth is unwrapped before the fit (a pass through north jumps by 2 pi), so its coefficients
describe the continuous angle; ``smoothed`` and grid values are wrapped back to [0, 2 pi) and
residuals are the wrapped differences.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import pandas as pd

from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)
from trackproc.isotime import iso_utc
from trackproc.io.jsonutil import json_ready
from trackproc.errors import InputError, ProcessingError
from trackproc.io.passfile import COLUMNS, KINDS, PassTable
from trackproc.io.raw import KIND_UNITS
from trackproc.methods.smoothing import (DEFAULT_MAX_DEGREE, ClosestApproach, PolynomialFit, SmoothingError,
                                         TCA_SPREAD_RATIO, closest_approach, degree_spread_width,
                                         smooth_pass, tca_degree_spread, tca_uncertain)

#: Kinds that have a time of closest approach.
TCA_KINDS = ("range_rate", "range", "doppler")
#: Default limits of the TCA observability check and of the per-pass warnings.
DEFAULT_TCA_MAX_GAP_S = 30.0
LARGEST_GAP_FRACTION = 0.5
#: Columns added to the sample table.
ADDED_COLUMNS = ("smoothed", "residual", "flag")

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


@dataclass
class SmoothOptions:
    """Options of ``trackproc smooth``.

    ``degree``: an integer >= 0 or ``"auto"``; ``clip``: K (None or 0 = no rejection);
    ``kinds``: kinds to fit (None = all present); ``grid_step_s``: write the curve every STEP
    seconds instead of at the samples; ``tca_max_gap_s``: longest data gap (s) allowed around the
    TCA, and shortest data span on each side of it.
    """

    degree: int | str = "auto"
    clip: float | None = 4.0
    kinds: Sequence[str] | None = None
    basis: str = "chebyshev"
    max_degree: int = DEFAULT_MAX_DEGREE
    grid_step_s: float | None = None
    tca_max_gap_s: float = DEFAULT_TCA_MAX_GAP_S


@dataclass
class PassFit:
    """The fit of one station, pass and kind (``fit`` None when it failed)."""

    station: str
    pass_id: str
    kind: str
    rows: np.ndarray                      # positions in the input frame
    epoch: pd.Timestamp                   # t = 0 of the polynomial (first sample), UTC
    t_s: np.ndarray                       # sample times, s from epoch
    status: str = "ok"                    # ok | suspect | failed
    error: str | None = None
    reason: str | None = None
    fit: PolynomialFit | None = None
    tca: ClosestApproach | None = None
    tca_error: str | None = None          # why the TCA is not observed, or uncertain
    tca_gap_s: float | None = None
    tca_spread: tuple = (float("nan"), float("nan"), 0)   # (s, value unit, degrees) over degree +- 2
    warnings: list = field(default_factory=list)

    @property
    def label(self) -> str:
        return f"{self.station}/{self.pass_id}/{self.kind}"


@dataclass
class SmoothResult:
    """``table``: what ``-o`` receives (samples with smoothed/residual/flag, or the grid);
    ``samples``: always the sample table; ``summary``: the JSON summary (also in the metadata)."""

    table: PassTable
    samples: PassTable
    fits: list[PassFit]
    summary: dict

    @property
    def failed(self) -> list[PassFit]:
        return [f for f in self.fits if f.status == "failed"]

    @property
    def suspect(self) -> list[PassFit]:
        return [f for f in self.fits if f.status == "suspect"]


def smooth(table: PassTable, options: SmoothOptions | None = None, *, source: str | None = None) -> SmoothResult:
    """Fit every (station, pass, kind) of ``table``; see the module docstring for the statuses."""
    options = options or SmoothOptions()
    _check_options(options)
    frame = table.frame.drop(columns=[c for c in ADDED_COLUMNS if c in table.frame.columns])
    frame = frame.reset_index(drop=True)
    present = sorted(frame["kind"].unique())
    kinds = list(options.kinds) if options.kinds else present
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise InputError("unknown kind", column="--kinds", found=", ".join(unknown),
                         expected="one or more of " + ", ".join(KINDS))
    chosen = [k for k in kinds if k in present]
    if not chosen:
        raise InputError("no samples of the requested kinds", file=source, column="kind",
                         found=", ".join(present) or "no samples", expected=", ".join(kinds))
    _check_sigma(frame, chosen, source)

    doppler_mode = str(table.meta.get("doppler_mode") or "one-way")
    carrier_hz = table.meta.get("carrier_hz")
    fits = []
    selected = frame[frame["kind"].isin(chosen)]
    for (station, pass_id, kind), group in selected.groupby(["station", "pass_id", "kind"], sort=True):
        fits.append(_fit_group(group, str(station), str(pass_id), str(kind), options, doppler_mode))

    if all(f.status == "failed" for f in fits):
        details = "; ".join(f"{f.label}: {f.error}" for f in fits)
        raise ProcessingError(f"no pass could be fitted ({len(fits)} tried): {details}",
                              {"failed": [f.label for f in fits]})

    smoothed = np.full(len(frame), np.nan)
    residual = np.full(len(frame), np.nan)
    flag = np.zeros(len(frame), bool)
    for f in fits:
        if f.fit is None:
            flag[f.rows] = True
            continue
        residual[f.rows] = f.fit.residual
        smoothed[f.rows] = f.fit(f.t_s)
        if f.kind == "azimuth":
            smoothed[f.rows] = np.mod(smoothed[f.rows], 2 * np.pi)
        flag[f.rows] = ~f.fit.used
    samples = frame.copy()
    samples["smoothed"] = smoothed
    samples["residual"] = residual
    samples["flag"] = flag

    summary = json_ready(_summary(fits, options, table.meta, source, doppler_mode, carrier_hz))
    meta = dict(table.meta)
    meta["smoothing"] = summary
    sample_table = PassTable(samples, {**meta, "smoothing": {**summary, "output": "samples"}})
    if options.grid_step_s is None:
        out = sample_table
    else:
        grid_meta = {**meta, "smoothing": {**summary, "output": "grid", "grid_step_s": options.grid_step_s,
                                           "grid_note": GRID_NOTE}}
        out = PassTable(_grid(fits, options.grid_step_s), grid_meta)
    return SmoothResult(table=out, samples=sample_table, fits=fits, summary=summary)


GRID_NOTE = ("value = fitted curve, sigma = its 1-sigma from the scaled coefficient covariance; "
             "grid values are strongly correlated (functions of degree + 1 coefficients): weight "
             "with the coefficient covariance, not as independent samples")


def summary_json(summary: dict) -> str:
    """The summary as strict JSON text (NaN and infinities as null), indented, newline-terminated."""
    import json

    return json.dumps(json_ready(summary), indent=2, allow_nan=False) + "\n"


def plot_bytes(result: SmoothResult, max_panels: int = 24) -> bytes:
    """PNG: per fit, the data (rejected samples marked), the fitted curve and the TCA; residuals beside."""
    require_matplotlib()
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fits = [f for f in result.fits][:max_panels]
    frame = result.samples.frame
    fig, axes = plt.subplots(len(fits), 2, figsize=(13, 3.2 * len(fits)), squeeze=False,
                             gridspec_kw={"width_ratios": [3, 2]})
    for (ax_data, ax_res), f in zip(axes, fits):
        unit = KIND_UNITS.get(f.kind, "")
        values = frame["value"].to_numpy()[f.rows]
        title = f"{f.label}  [{f.status}]"
        if f.fit is None:
            ax_data.plot(f.t_s, values, ".", ms=2, color="0.5")
            ax_data.set_title(f"{title}: {f.error}", fontsize=9)
            ax_res.set_axis_off()
            continue
        used = f.fit.used
        ax_data.plot(f.t_s[used], values[used], ".", ms=2, label="used")
        if (~used).any():
            ax_data.plot(f.t_s[~used], values[~used], "x", ms=4, color="red", label="rejected")
        grid = np.linspace(*f.fit.domain_s, 600)
        ax_data.plot(grid, f.fit(grid), "-", color="black", lw=1, label=f"degree {f.fit.degree}")
        lo, hi = np.nanmin(values), np.nanmax(values)
        pad = 0.1 * (hi - lo) if hi > lo else 1.0
        ax_data.set_ylim(lo - pad, hi + pad)
        if f.tca is not None:
            ax_data.axvline(f.tca.t_s, color="green", lw=0.8, label=f"TCA ±{f.tca.sigma_s:.3g} s")
        ax_data.set_title(title + (f"  {', '.join(f.warnings)}" if f.warnings else ""), fontsize=9)
        ax_data.set_ylabel(f"{f.kind} [{unit}]")
        ax_data.legend(fontsize=7, loc="best")
        ax_res.plot(f.t_s[used], f.fit.residual[used], ".", ms=2)
        if (~used).any():
            ax_res.plot(f.t_s[~used], f.fit.residual[~used], "x", ms=4, color="red")
        span = 6 * max(f.fit.rms, 1e-300)
        ax_res.set_ylim(-span, span)
        ax_res.set_title(f"residual, RMS {f.fit.rms:.3g} {unit}", fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("s from the first sample of the pass")
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    return buffer.getvalue()


# --------------------------------------------------------------------------- internals


def _check_options(options: SmoothOptions) -> None:
    degree = options.degree
    if isinstance(degree, str):
        if degree != "auto":
            raise InputError("invalid option", column="--degree", found=degree, expected="an integer >= 0 or auto")
    elif int(degree) < 0:
        raise InputError("invalid option", column="--degree", found=degree, expected="an integer >= 0 or auto")
    if options.clip is not None and not (math.isfinite(options.clip) and options.clip >= 0):
        raise InputError("invalid option", column="--clip", found=options.clip, expected="K >= 0 (0: no rejection)")
    if options.clip is not None and 0 < options.clip < 1.5:
        raise InputError("invalid option", column="--clip", found=options.clip,
                         expected="K >= 1.5 (smaller K rejects good data), or 0 for no rejection")
    if options.grid_step_s is not None and not (math.isfinite(options.grid_step_s) and options.grid_step_s > 0):
        raise InputError("invalid option", column="--grid", found=options.grid_step_s, expected="a step > 0 (s)")
    if int(options.max_degree) < 0:
        raise InputError("invalid option", column="--max-degree", found=options.max_degree, expected="an integer >= 0")
    if not options.tca_max_gap_s > 0:
        raise InputError("invalid option", column="--tca-max-gap", found=options.tca_max_gap_s,
                         expected="a duration > 0 (s)")
    if options.basis not in ("chebyshev", "legendre"):
        raise InputError("invalid option", column="--basis", found=options.basis, expected="chebyshev or legendre")


def _check_sigma(frame: pd.DataFrame, kinds, source) -> None:
    sel = frame["kind"].isin(kinds).to_numpy()
    sigma = frame["sigma"].to_numpy(dtype=float)
    bad = sel & ~(np.isfinite(sigma) & (sigma > 0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        row = frame.iloc[i]
        raise InputError(f"sigma must be finite and > 0 ({int(bad.sum())} samples are not; first: "
                         f"{row['station']}/{row['pass_id']}/{row['kind']} at {row['time']})",
                         file=source, column="sigma", found=float(sigma[i]), expected="a 1-sigma > 0")


def _fit_group(group: pd.DataFrame, station, pass_id, kind, options: SmoothOptions, doppler_mode) -> PassFit:
    group = group.sort_values("time", kind="mergesort")
    rows = group.index.to_numpy()
    times = group["time"]
    epoch = times.iloc[0]
    t_s = (times.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy().astype("datetime64[ns]").astype(np.int64)
           - pd.Timestamp(epoch).tz_convert("UTC").tz_localize(None).as_unit("ns").value) * 1e-9
    out = PassFit(station=station, pass_id=pass_id, kind=kind, rows=rows, epoch=pd.Timestamp(epoch), t_s=t_s)
    y = group["value"].to_numpy(dtype=float)
    if kind == "azimuth":       # fit the continuous angle; a pass through north jumps by 2 pi
        y = np.unwrap(y)
    sigma = group["sigma"].to_numpy(dtype=float)
    try:
        fit = smooth_pass(t_s, y, sigma, options.degree, clip=options.clip, basis=options.basis,
                          max_degree=options.max_degree)
    except SmoothingError as exc:
        out.status, out.error, out.reason = "failed", str(exc), exc.reason
        return out
    out.fit = fit
    if kind in TCA_KINDS:
        try:
            ca = closest_approach(fit, kind, doppler_mode)
            gap, margin = _coverage(t_s[fit.used], ca.t_s)
            out.tca_gap_s = gap
            where = f"closest approach of the fit at {_iso(_at(out.epoch, ca.t_s))} ({ca.t_s:.1f} s into the pass)"
            if gap > options.tca_max_gap_s:
                raise SmoothingError("tca_not_observed", f"{where} falls in a {gap:.1f} s data gap "
                                     f"(limit {options.tca_max_gap_s:g} s): not observed")
            if margin < options.tca_max_gap_s:
                raise SmoothingError("tca_not_observed", f"{where} is {margin:.1f} s from an end of the data "
                                     f"(need {options.tca_max_gap_s:g} s on each side): not observed")
            out.tca = ca
            out.tca_spread = tca_degree_spread(t_s, y, sigma, fit, kind, doppler_mode)
            if tca_uncertain(fit, ca, out.tca_spread[0]):
                out.warnings.append("tca_uncertain")
                spread, width = out.tca_spread[0], degree_spread_width(fit.degree)
                why = (f"moves by {spread:.3g} s over degrees {max(0, fit.degree - width)}-{fit.degree + width}, "
                       f"{spread / ca.sigma_s:.1f} times its sigma of {ca.sigma_s:.3g} s"
                       if math.isfinite(spread) and spread > TCA_SPREAD_RATIO * ca.sigma_s else
                       "has a sigma that assumes white noise, and the residuals are correlated (curve_unresolved)")
                out.tca_error = (f"{where} {why}: uncertain (uncertainty_s "
                                 f"{math.hypot(ca.sigma_s, spread) if math.isfinite(spread) else ca.sigma_s:.3g} s)")
        except SmoothingError as exc:
            out.tca_error = str(exc)
            out.warnings.append("tca_not_observed")
    span = fit.domain_s[1] - fit.domain_s[0]
    tu = t_s[fit.used]
    largest = float(np.max(np.diff(tu))) if tu.size > 1 else span
    if span > 0 and largest > LARGEST_GAP_FRACTION * span:
        out.warnings.append("largest_gap")
    if fit.rejection_capped:
        out.warnings.append("many_rejected")
    if fit.noise.unresolved:
        out.warnings.append("curve_unresolved")
    if not fit.clip_converged:
        out.warnings.append("clip_not_converged")
    out.status = "suspect" if out.warnings else "ok"
    return out


def _coverage(t_used: np.ndarray, t_star: float) -> tuple[float, float]:
    """(length of the data gap containing t*, shortest data span on either side of t*), seconds."""
    before = t_used[t_used <= t_star]
    after = t_used[t_used >= t_star]
    if before.size == 0 or after.size == 0:
        return math.inf, 0.0
    return float(after[0] - before[-1]), float(min(t_star - before[0], after[-1] - t_star))


def _iso(ts: pd.Timestamp) -> str:
    return iso_utc(ts, 9)


def _at(epoch: pd.Timestamp, t_s: float) -> pd.Timestamp:
    return pd.Timestamp(epoch) + pd.Timedelta(int(round(t_s * 1e9)), unit="ns")


def _finite(x):
    return float(x) if x is not None and math.isfinite(x) else None


def _notes(fit: PolynomialFit, max_degree: int) -> list:
    if not (fit.degree_scores and fit.degree_at_limit):
        return []
    if fit.degree_cap is not None and fit.degree_cap < max_degree:
        return [f"degree_at_limit: BIC still falls at degree {fit.degree}, the largest the {fit.n_used} samples "
                f"({fit.n_eff:.0f} effective) support with 2 per coefficient; the curve may be under-fitted "
                "(its residuals and degree spread show it)"]
    return [f"degree_at_limit: BIC still falls at degree {fit.degree}, the search limit; the curve may "
            "be under-fitted (try a larger --max-degree, or shorter passes)"]


def _fit_record(f: PassFit, carrier_hz, doppler_mode, max_degree: int = DEFAULT_MAX_DEGREE) -> dict:
    unit = KIND_UNITS.get(f.kind, "")
    rec = {"station": f.station, "pass_id": f.pass_id, "kind": f.kind, "unit": unit, "status": f.status,
           "error": f.error, "reason": f.reason, "warnings": list(f.warnings), "n_samples": int(f.t_s.size),
           "epoch_utc": _iso(f.epoch)}
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
        "domain_utc": [_iso(_at(f.epoch, fit.domain_s[0])), _iso(_at(f.epoch, fit.domain_s[1]))],
        "degree": fit.degree,
        "degree_selection": ({"criterion": "bic", "at_limit": bool(fit.degree_at_limit),
                              "cap": fit.degree_cap, "max_degree": int(max_degree),
                              "bic": {str(k): float(v) for k, v in fit.degree_scores.items()}}
                             if fit.degree_scores else {"criterion": "fixed"}),
        "noise": {"model": "white" if fit.noise.white else "ar1", "rho": fit.noise.rho,
                  "unresolved": bool(fit.noise.unresolved),
                  "rho_estimate": fit.noise.rho_estimate, "step_s": fit.noise.step_s,
                  "lag1_observed": _finite(fit.noise.lag1_observed),
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
        "notes": _notes(fit, max_degree),
    })
    if f.kind in TCA_KINDS:
        if f.tca is None:
            rec["tca"] = {"status": "not_observed", "error": f.tca_error}
        else:
            ca = f.tca
            spread = f.tca_spread[0]
            tca = {"status": "uncertain" if "tca_uncertain" in f.warnings else "ok", "definition": ca.definition, "time_utc": _iso(_at(f.epoch, ca.t_s)),
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


def _summary(fits, options: SmoothOptions, meta, source, doppler_mode, carrier_hz) -> dict:
    from trackproc import __version__

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
        "fits": [_fit_record(f, carrier_hz, doppler_mode, options.max_degree) for f in fits],
    }


def _grid(fits, step_s: float) -> pd.DataFrame:
    parts = []
    for f in fits:
        if f.fit is None:
            continue
        a, b = f.fit.domain_s
        t = a + step_s * np.arange(int(math.floor((b - a) / step_s + 1e-9)) + 1)
        ns = np.round(t * 1e9).astype(np.int64)
        times = pd.DatetimeIndex(pd.Timestamp(f.epoch).tz_convert("UTC").as_unit("ns").value + ns, tz="UTC")
        parts.append(pd.DataFrame({"time": times, "station": f.station, "pass_id": f.pass_id, "kind": f.kind,
                                   "value": np.mod(f.fit(t), 2 * np.pi) if f.kind == "azimuth" else f.fit(t),
                                   "sigma": f.fit.sigma(t)}))
    if not parts:
        return pd.DataFrame({c: [] for c in COLUMNS})
    grid = pd.concat(parts, ignore_index=True)
    return grid.sort_values(["station", "time", "kind"], kind="mergesort").reset_index(drop=True)[list(COLUMNS)]


