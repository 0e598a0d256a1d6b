""":func:`detect`: the samples chosen, the predictions under H0 and H1, the statistic and the decision (seed
003); its JSON.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from trackproc.errors import InputError, ProcessingError
from trackproc.isotime import iso_utc
from trackproc.methods import detection as dt

from trackproc.pipeline.detect.geometry import (StationGeometry, flight_time_s, model_3d, planar_encounter,
                                                planar_for_3d, seconds_from_impact, wrap_pi)
from trackproc.pipeline.detect.nominal import DEG, Nominal


@dataclass
class DetectOptions:
    """Overrides of :func:`detect`: Δ* (m), false-alarm probability (None = equal-error), σ (rad)."""

    displacement_m: Optional[float] = None
    false_alarm: Optional[float] = None
    sigma_rad: Optional[float] = None


@dataclass
class DetectResult:
    """Outcome of :func:`detect`: the JSON document, the statistic and the decision objects,
    and the per-sample arrays (``times``, ``kinds``, ``x``, ``a``, ``b``, ``sigma``)."""

    document: dict
    statistic: object
    decision: object
    samples: dict = field(default_factory=dict)


def _chosen(given, available: list, source: str, column: str, several: str, which: str, unknown: str):
    """The nominal file's ``given`` choice among ``available``, or the only one when it gives none."""
    if given is None:
        if len(available) > 1:
            raise InputError(several, file=source, column=column, found=", ".join(available), expected=which)
        return available[0]
    if given not in available:
        raise InputError(unknown, file=source, column=column, found=given, expected="one of " + ", ".join(available))
    return given


def select_samples(table, nominal: Nominal, source: str):
    frame = table.frame
    kinds_wanted = nominal.kinds or (("elevation", "azimuth") if nominal.model == "3d" else ("elevation",))
    elev = frame[frame["kind"] == "elevation"]
    if elev.empty:
        raise InputError("no elevation samples", file=source, column="kind",
                         found=", ".join(sorted(frame["kind"].unique())) or "(none)", expected="elevation rows")
    stations = sorted(elev["station"].unique())
    name = _chosen(nominal.station, stations, nominal.source, "station", "several stations have elevations",
                   "the station to use", "station has no elevation samples in the pass file")
    rows = frame[(frame["station"] == name) & frame["kind"].isin(kinds_wanted)]
    passes = sorted(rows["pass_id"].unique())
    pass_id = _chosen(nominal.pass_id, passes, nominal.source, "pass_id", "the station has several passes",
                      "the pass to use", "unknown pass")
    rows = rows[rows["pass_id"] == pass_id]
    if nominal.kinds is not None and "azimuth" in nominal.kinds and not (rows["kind"] == "azimuth").any():
        raise InputError("no azimuth samples for the requested kinds", file=source, column="kind",
                         expected="azimuth rows, or kinds [\"elevation\"] in the nominal file")
    return name, pass_id, rows


@dataclass(frozen=True)
class _Flight:
    """The pass's samples during the flight up to ``T - tau``: their rows, UTC times (``keep``
    selects them from ``times_all``), seconds from impact, and how many later ones were dropped."""

    rows: object
    times_all: np.ndarray
    keep: np.ndarray
    s: np.ndarray
    dropped: int


@dataclass(frozen=True)
class _Predictions:
    """The observations ``x`` and the predictions under H0 (``a``) and H1 (``b``), azimuths on
    the branch of ``a``; ``info`` the model's extra record for the document."""

    x: np.ndarray
    a: np.ndarray
    b: np.ndarray
    info: dict


def _flight_samples(rows, nominal: Nominal, source: str) -> _Flight:
    """The samples before ``T - tau`` (the reaction time), none before the launch."""
    times = rows["time"].dt.tz_convert("UTC").dt.tz_localize(None).to_numpy("datetime64[ns]")
    s_all = seconds_from_impact(times, nominal.impact_time)
    keep = s_all <= -nominal.tau_s
    keep &= s_all < 0
    if not keep.any():
        raise InputError("no samples before impact_time - tau_s", file=source, column="time",
                         found=f"{iso_utc(times.min())} .. {iso_utc(times.max())}",
                         expected=f"samples before {iso_utc(nominal.impact_time)} minus {nominal.tau_s:g} s")
    flight = flight_time_s(nominal)
    early = keep & (s_all < -flight)
    if early.any():
        i = int(np.flatnonzero(early)[0])
        raise InputError(f"{int(early.sum())} samples before the launch of the nominal trajectory "
                         f"(a flight of {flight:.1f} s ending at {iso_utc(nominal.impact_time)})",
                         file=source, column="time", found=iso_utc(times[i]),
                         expected="samples of the flight (check impact_time in the nominal file and the pass)")
    return _Flight(rows=rows[keep], times_all=times, keep=keep, s=s_all[keep], dropped=int((~keep).sum()))


def _sigmas(rows, options: DetectOptions, nominal: Nominal, source: str) -> tuple[np.ndarray, str]:
    """Each sample's sigma and where it came from: ``--sigma-rad``, the nominal file, or the pass file."""
    n = len(rows)
    if options.sigma_rad is not None:
        return np.full(n, float(options.sigma_rad)), "--sigma-rad"
    if nominal.sigma_rad is not None:
        return np.full(n, nominal.sigma_rad), "nominal sigma_rad"
    sigma = rows["sigma"].to_numpy(float)
    bad = ~(np.isfinite(sigma) & (sigma > 0))
    if bad.any():
        raise InputError("sigma must be positive", file=source, column="sigma", found=float(sigma[bad][0]),
                         expected="a positive sigma in rad, or sigma_rad in the nominal file")
    return sigma, "pass file sigma column"


def _predictions(station, name: str, nominal: Nominal, flight: _Flight, kinds: np.ndarray, x: np.ndarray,
                 sigma: np.ndarray, displacement: float, eop, source: str) -> _Predictions:
    """H0 and H1 predictions by the planar model (elevation) or the 3-D one (azimuth, elevation)."""
    s = flight.s
    if nominal.model == "planar":
        if nominal.direction != "none" and nominal.latitude_deg is None and station is None:
            raise InputError("station missing from the pass file metadata", file=source, column="stations",
                             found=name, expected="its latitude there, or latitude_deg in the nominal file")
        enc = planar_encounter(nominal, station)
        return _Predictions(x=x, a=enc.elevation(s), b=enc.elevation(s, displacement), info=_planar_info(enc))
    if station is None:
        raise InputError("station missing from the pass file metadata", file=source, column="stations",
                         found=name, expected="the station's lat_deg, lon_deg, height_m (from ingest/simulate)")
    geometry = StationGeometry.of(station, nominal.earth)
    m0 = model_3d(nominal, geometry, s, 0.0, eop)
    m1 = model_3d(nominal, geometry, s, displacement, eop)
    az = kinds == "azimuth"
    a = np.where(az, m0.azimuth_rad, m0.elevation_rad)
    b = np.where(az, m1.azimuth_rad, m1.elevation_rad)
    # wrap azimuth differences: compare on the branch of a
    x = np.where(az, a + wrap_pi(x - a), x)
    b = np.where(az, a + wrap_pi(b - a), b)
    info = {"planar_comparison": compare_planar(nominal, geometry, s, kinds, a, b, sigma, displacement)}
    return _Predictions(x=x, a=a, b=b, info=info)


def _document(stat, decision, nominal: Nominal, flight: _Flight, kinds: np.ndarray, pred: _Predictions, *,
              source: str, name: str, pass_id, displacement: float, sigma_source: str) -> dict:
    """The JSON document of one test: decision, statistic, error probabilities, samples used."""
    s = flight.s
    times = flight.times_all[flight.keep]
    spacing = float(np.median(np.diff(np.unique(s)))) if np.unique(s).size > 1 else float("nan")
    by_kind = {k: int((kinds == k).sum()) for k in ("elevation", "azimuth") if (kinds == k).any()}
    info = dict(pred.info)
    return {
        "decision": "H1" if decision.decide_h1 else "H0",
        "displaced": decision.decide_h1,
        "model": nominal.model,
        "pass_file": source,
        "station": name,
        "pass_id": pass_id,
        "displacement_m": displacement,
        "criterion": decision.criterion,
        "threshold": decision.threshold,
        "statistic": {
            "S": float(stat.s), "mean_h0": stat.mean_h0, "mean_h1": stat.mean_h1, "variance": stat.variance,
            "std": stat.std, "z": decision.z, "log_likelihood_ratio": stat.log_likelihood_ratio,
        },
        "gamma": stat.gamma,
        "false_alarm_probability": decision.alpha,
        "miss_probability": decision.beta,
        "equal_error_probability": dt.equal_error(stat.gamma),
        "sigma_rad": stat.sigma0,
        "sigma_source": sigma_source,
        "uniform_sigma": stat.uniform_sigma,
        "samples": {
            "used": stat.n, "by_kind": by_kind, "not_used_after_T_minus_tau": flight.dropped,
            "first": iso_utc(times.min()), "last": iso_utc(times.max()),
            "first_s_from_impact": float(s.min()), "last_s_from_impact": float(s.max()),
            "median_spacing_s": spacing,
        },
        "g_achieved_rad_s05": float(stat.sigma0 * math.sqrt(spacing)) if math.isfinite(spacing) else None,
        "information_distance_rad_s05": float(math.sqrt(stat.c_n * spacing)) if math.isfinite(spacing) else None,
        "max_abs_b_minus_a_rad": float(np.max(np.abs(pred.b - pred.a))),
        "nominal": {**nominal.describe(), **info.pop("nominal", {})},
        **info,
        "units": {"angles": "rad", "S": "rad^2", "variance": "rad^4", "g": "rad s^0.5", "time": "UTC"},
        "method": "seed 003 eqs. 1-8: S = sum w_i (x_i - a_i)(b_i - a_i), w_i = (sigma0/sigma_i)^2 (1 when "
                  "sigma is uniform); E[S|H0] = 0, E[S|H1] = C_n, Var S = sigma0^2 C_n",
    }


def detect(table, nominal: Nominal, options: DetectOptions | None = None, *, source: str = "<pass>",
           eop=None) -> DetectResult:
    """Run the seed 003 test on one pass of ``table`` (:class:`~trackproc.io.passfile.PassTable`)."""
    options = options or DetectOptions()
    displacement = options.displacement_m if options.displacement_m is not None else nominal.displacement_m
    if not math.isfinite(displacement) or displacement == 0:
        raise InputError("invalid displacement", column="--displacement-m", found=displacement,
                         expected="a non-zero number of metres")
    name, pass_id, rows = select_samples(table, nominal, source)
    flight = _flight_samples(rows, nominal, source)
    kinds = flight.rows["kind"].to_numpy(dtype=str)
    sigma, sigma_source = _sigmas(flight.rows, options, nominal, source)
    pred = _predictions(table.stations().get(name), name, nominal, flight, kinds,
                        flight.rows["value"].to_numpy(float), sigma, displacement, eop, source)
    try:
        stat = dt.statistic(pred.x, pred.a, pred.b, sigma)
        decision = dt.decide(stat, options.false_alarm)
    except ValueError as exc:
        raise ProcessingError(str(exc)) from None
    doc = _document(stat, decision, nominal, flight, kinds, pred, source=source, name=name, pass_id=pass_id,
                    displacement=displacement, sigma_source=sigma_source)
    return DetectResult(document=doc, statistic=stat, decision=decision,
                        samples={"times": flight.times_all[flight.keep], "s": flight.s, "kinds": kinds,
                                 "x": pred.x, "a": pred.a, "b": pred.b, "sigma": sigma})


def _planar_info(enc) -> dict:
    rise = None
    try:
        rise = enc.rise_time()
    except ValueError:
        pass
    return {"nominal": {"p_m": enc.p_m, "e": enc.e, "theta_f_deg": enc.theta_f / DEG,
                        "phi_impact_deg": enc.phi_impact / DEG, "radius_m": enc.radius_m,
                        "observer_rate_rad_s": enc.observer_rate,
                        "rise_s_from_impact": rise}}


def compare_planar(nominal: Nominal, geometry: StationGeometry, s, kinds, a, b, sigma, displacement) -> dict:
    """The planar model's error against the 3-D one at the pass's elevation samples.

    Planar: R = |r_station|, in-plane observer motion ω_E cos(geocentric latitude). Reports the
    largest elevation difference under H0 and in Δε = ε₁ - ε₀, and γ = sqrt(Σ w Δ²)/σ₀ of the
    planar elevations, of the 3-D elevations, and of the 3-D azimuths and elevations together.
    """
    el = kinds == "elevation"
    if nominal.heading_deg is not None and abs(math.cos(nominal.heading_deg * DEG)) > math.sin(DEG):
        return {"available": False, "reason": "the planar model is the unfavourable geometry: heading 90 or 270 deg "
                                              "(direction with/against)"}
    try:
        enc = planar_for_3d(nominal, geometry)
        p0, p1 = enc.elevation(s[el]), enc.elevation(s[el], displacement)
    except (ValueError, InputError) as exc:
        return {"available": False, "reason": str(exc)}
    sig = sigma[el]
    w = (np.sqrt(np.mean(sigma ** 2)) / sigma) ** 2 if np.any(sigma != sigma.flat[0]) else np.ones_like(sigma)
    s0 = float(np.sqrt(np.mean(sigma ** 2))) if np.any(sigma != sigma.flat[0]) else float(sigma.flat[0])

    def gamma(d, weights):
        return float(np.sqrt(np.sum(weights * d * d)) / s0)

    d3 = (b - a)[el]
    dp = p1 - p0
    return {
        "available": True,
        "planar_radius_m": enc.radius_m,
        "planar_latitude_deg": geometry.geocentric_latitude / DEG,
        "max_abs_elevation_error_h0_rad": float(np.max(np.abs(p0 - a[el]))),
        "max_abs_elevation_error_h1_rad": float(np.max(np.abs(p1 - b[el]))),
        "max_abs_delta_elevation_error_rad": float(np.max(np.abs(dp - d3))),
        "gamma_planar_elevation": gamma(dp, w[el]),
        "gamma_3d_elevation": gamma(d3, w[el]),
        "gamma_3d_azimuth_elevation": gamma(b - a, w),
        "relative_gamma_error": float(gamma(dp, w[el]) / gamma(d3, w[el]) - 1.0) if np.any(d3) else None,
        "samples": int(el.sum()),
        "sigma_elevation_rad": float(np.sqrt(np.mean(sig ** 2))),
    }


def result_json(doc: dict) -> str:
    """Deterministic JSON (indent 2, no NaN: non-finite numbers become null)."""
    return json.dumps(_finite(doc), indent=2, allow_nan=False) + "\n"


def _finite(value):
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value
