"""``trackproc compare``: how well a prediction (state or TLE) matches a pass (issue 18 item 2).

1. The prediction at every sample: :class:`~trackproc.pipeline.orbit_source.Satellite` (SGP4 at
   each sample time for a TLE, the Taylor engine for a state) and the one-way (or two-way, per
   the pass file's ``doppler_mode``) foundation model
   :func:`~trackproc.models.measurements.observables`, the model ``simulate`` generates passes
   with. Residual = observed − predicted (azimuth wrapped to [−π, π)).
2. Per pass and kind, the offset (and drift) the pass's own data imply are fitted by weighted
   least squares, ``r_i = b + d (t_i − t_0) + e_i`` with weights ``1/σ_i²`` and ``t_0`` the
   pass's first sample (``--remove none|offset|offset+drift``); their 1-σ are the formal ones,
   ``sqrt(diag (AᵀWA)⁻¹)``, from the file's sigmas, and the a-posteriori ones scaled by
   ``sqrt(χ²/dof)`` (for files whose sigmas are not the noise; still optimistic when the residuals
   are correlated, as a TLE's are). A one-way Doppler pass's offset and drift
   are the transmitter's frequency error, which is why a prediction is judged after removing
   them (the RMS users quote).
3. The summary per pass and kind: samples, RMS before and after the removal, the fitted values,
   and ``rms_over_sigma`` (RMS after removal / RMS of the sigmas: about 1 when the prediction
   is as good as the noise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import pandas as pd

from trackproc.dynamics import timescales as ts
from trackproc.errors import InputError
from trackproc.io.statefile import format_epoch
from trackproc.io.validate import stated_carrier
from trackproc.models.observation import wrap_pi
from trackproc.pipeline.orbit_source import SGP4_LABEL, Satellite, observe, resolve_force

REMOVE = ("none", "offset", "offset+drift")
UNITS = {"range": "m", "range_rate": "m/s", "doppler": "Hz", "elevation": "rad", "azimuth": "rad"}


@dataclass
class CompareOptions:
    remove: str = "offset+drift"
    force: Optional[str] = None
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None
    earth: str = "wgs84"
    range_rate_model: str = "doppler"


def fit_trend(t_s, r, sigma, remove: str):
    """Weighted least squares of ``r = b + d t`` (``remove`` picks the columns): the fitted
    values ``{offset, drift}`` with their formal 1-σ, and the residuals after removal."""
    columns = {"none": 0, "offset": 1, "offset+drift": 2}[remove]
    fitted: dict = {}
    if columns == 0:
        return fitted, r
    if len(r) < columns:
        raise InputError("too few samples to fit the trend", column="--remove", found=f"{len(r)} samples",
                         expected=f"at least {columns} samples per pass and kind, or --remove none")
    a = np.stack([np.ones_like(t_s), t_s][:columns], axis=1)
    w = 1.0 / sigma
    coef, *_ = np.linalg.lstsq(a * w[:, None], r * w, rcond=None)
    cov = np.linalg.pinv((a * w[:, None]).T @ (a * w[:, None]))
    names = ("offset", "drift")[:columns]
    after = r - a @ coef
    dof = len(r) - columns
    # a-posteriori: the formal sigmas scaled by sqrt(chi2/dof), for files whose sigmas are not the noise
    scale = float(np.sqrt(np.sum((after * w) ** 2) / dof)) if dof > 0 else float("nan")
    for k, name in enumerate(names):
        fitted[name] = float(coef[k])
        fitted[f"{name}_sigma"] = float(np.sqrt(cov[k, k]))
        fitted[f"{name}_sigma_aposteriori"] = float(np.sqrt(cov[k, k])) * scale
    return fitted, after


def compare(table, orbit, options: CompareOptions, eop=None, stations: Optional[dict] = None):
    """Residuals of ``table`` (a :class:`~trackproc.io.passfile.PassTable`) against ``orbit``
    (:class:`~trackproc.pipeline.orbit_source.OrbitInput`): the residual frame (the columns of
    :mod:`trackproc.io.residuals`) and the summary dict."""
    if options.remove not in REMOVE:
        raise InputError("unknown trend removal", column="--remove", found=options.remove, expected=", ".join(REMOVE))
    force = resolve_force(orbit, options.force, allow_full=options.force_model is not None)
    frame = table.frame
    if len(frame) == 0:
        raise InputError("no samples", file=table.meta.get("source"), expected="a pass file with samples")
    known = dict(table.stations())
    known.update(stations or {})
    missing = sorted(set(frame["station"]) - set(known))
    if missing:
        raise InputError("station coordinates unknown", column="station", found=", ".join(missing),
                         expected="stations in the pass file's metadata or --stations STATIONS.csv")
    kinds = set(frame["kind"])
    carrier = stated_carrier(table.meta, needed="doppler" in kinds, missing=None)
    mode = table.meta.get("doppler_mode") or "one-way"
    times = pd.DatetimeIndex(frame["time"]).tz_convert("UTC").tz_localize(None).as_unit("ns").to_numpy()
    t0 = times.min()
    jd0 = ts.datetime64_to_jd_utc(t0)
    t_s = np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(times), jd0), float)
    sat = Satellite(orbit, force, t0, 0.0, float(t_s.max()), eop, force_model=options.force_model)
    predicted = np.full(len(frame), np.nan)
    station_col, kind_col = frame["station"].to_numpy(), frame["kind"].to_numpy()
    for name in sorted(set(station_col)):
        rows = np.flatnonzero(station_col == name)
        obs = observe(sat, known[name], t_s[rows], carrier_hz=carrier or 1.0, mode=mode,
                      range_rate_model=options.range_rate_model, earth=options.earth)
        for kind, series in obs.by_kind().items():
            sel = kind_col[rows] == kind
            predicted[rows[sel]] = series[sel]
    observed = frame["value"].to_numpy(dtype=float)
    residual = observed - predicted
    is_az = kind_col == "azimuth"
    residual[is_az] = wrap_pi(residual[is_az])
    sigma = frame["sigma"].to_numpy(dtype=float)
    out = pd.DataFrame({"time": frame["time"], "station": station_col, "pass_id": frame["pass_id"].to_numpy(),
                        "kind": kind_col, "unit": [UNITS.get(k, "") for k in kind_col], "observed": observed,
                        "computed": predicted, "residual": residual, "normalized_residual": residual / sigma,
                        "sigma": sigma, "edited": np.zeros(len(frame), bool)})
    passes = []
    # residual after removing the fitted trend (not written by io.residuals; for the plot)
    out["residual_after"] = np.nan
    for (pass_id, kind), group in out.groupby(["pass_id", "kind"], sort=True):
        idx = group.index.to_numpy()
        tt = t_s[idx] - t_s[idx].min()
        fitted, after = fit_trend(tt, residual[idx], sigma[idx], options.remove)
        out.loc[idx, "residual_after"] = after
        entry = {"pass_id": pass_id, "station": str(station_col[idx[0]]), "kind": kind, "unit": UNITS.get(kind, ""),
                 "samples": int(len(idx)), "start": format_epoch(times[idx].min()),
                 "end": format_epoch(times[idx].max()),
                 "rms_raw": float(np.sqrt(np.mean(residual[idx] ** 2))),
                 "rms": float(np.sqrt(np.mean(after ** 2))),
                 "rms_over_sigma": float(np.sqrt(np.mean(after ** 2)) / np.sqrt(np.mean(sigma[idx] ** 2)))}
        if fitted:
            entry["reference_time"] = format_epoch(times[idx].min())
            entry.update(fitted)
        passes.append(entry)
    summary = {
        "generator": "trackproc compare",
        "prediction": orbit.source,
        "force_model": (SGP4_LABEL if force == "sgp4" else options.force_model.label() if options.force_model is not None
                        else force),
        "remove": options.remove,
        "residual": "observed - predicted; rms after removing the fitted offset (and drift, per s from "
                    "reference_time) of each pass and kind; sigmas of the fit are formal (from the file's sigmas)",
        "doppler_mode": mode if "doppler" in kinds else None,
        "passes": passes,
    }
    if force != "sgp4" and orbit.tle is not None:
        summary["note"] = f"TLE integrated with {force} from its SGP4 state at {format_epoch(t0)}, not SGP4"
    return out, summary
