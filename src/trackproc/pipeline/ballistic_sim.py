"""``trackproc simulate --ballistic``: elevation (and azimuth) passes of a seed 003 trajectory.

The test bench of ``trackproc detect``: the nominal trajectory of NOMINAL.json (see
:mod:`trackproc.pipeline.detect`) seen from one station, under H0 (displacement 0) or H1
(displacement Δ*, from ``--displacement-m`` or the nominal file).

1. Times: UTC labels ``T - k·step``, k = 1, 2, ... (the last sample one step before impact),
   back to the horizon rise of the simulated hypothesis; elapsed seconds through TAI.
2. Model: ``planar`` — seed 003 eqs. 9-11 (:class:`~trackproc.methods.ballistic.PlanarEncounter`,
   elevation only; the observer's latitude is the station's unless the nominal file gives one);
   ``3d`` — the trajectory through the station propagated by DOP853 (two-body or J2) with
   azimuth and elevation from :func:`trackproc.models.measurements.observables` (light time,
   IAU 2006/2000A, WGS-84 or spherical station).
3. Visibility: the last uninterrupted stretch of samples at or above the elevation mask
   before impact, one pass ``<station>-001``.
4. Noise: independent Gaussian, sigma ``--sigma-angle-deg`` on both angles
   (``numpy.random.default_rng(seed)``, elevation drawn before azimuth); azimuth wrapped to
   [0, 2π). A noiseless run (sigma 0) writes sigma = 0.01 deg in the table, as ``simulate``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Optional

import numpy as np
import pandas as pd

from trackproc.errors import InputError, ProcessingError
from trackproc.io.passfile import base_meta
from trackproc.io.statefile import format_epoch
from trackproc.pipeline import detect as dp

DEG = math.pi / 180.0
HYPOTHESES = ("h0", "h1")
#: Sigma written to the table for a noiseless run (deg), as ``simulate``'s default.
NOISELESS_SIGMA_DEG = 0.01


@dataclass
class BallisticOptions:
    """Options of :func:`simulate_ballistic` (units in the names)."""

    hypothesis: str = "h0"
    displacement_m: Optional[float] = None
    step_s: float = 1.0
    elevation_mask_deg: float = 0.0
    sigma_angle_deg: float = 0.01
    seed: Optional[int] = None
    kinds: tuple = ("elevation", "azimuth")


@dataclass
class BallisticSimulation:
    """Result: canonical pass table (``frame``), its metadata, the noiseless values aligned
    with ``frame`` and the station used."""

    frame: pd.DataFrame
    meta: dict
    truth_values: np.ndarray
    station: str
    extra: dict = field(default_factory=dict)


def _check(options: BallisticOptions) -> None:
    if options.hypothesis not in HYPOTHESES:
        raise InputError("unknown hypothesis", column="--hypothesis", found=options.hypothesis, expected="h0 or h1")
    if not (math.isfinite(options.step_s) and options.step_s > 0):
        raise InputError("must be positive", column="--step", found=options.step_s, expected="a number > 0")
    if not (math.isfinite(options.sigma_angle_deg) and options.sigma_angle_deg >= 0):
        raise InputError("must not be negative", column="--sigma-angle-deg", found=options.sigma_angle_deg,
                         expected="a number >= 0 (0 = noiseless)")
    if not -90.0 <= options.elevation_mask_deg <= 90.0:
        raise InputError("out of range", column="--elevation-mask-deg", found=options.elevation_mask_deg,
                         expected="degrees in [-90, 90]")
    if options.displacement_m is not None and not (math.isfinite(options.displacement_m)
                                                   and options.displacement_m != 0):
        raise InputError("invalid displacement", column="--displacement-m", found=options.displacement_m,
                         expected="a non-zero number of metres")


@dataclass(frozen=True)
class _Encounter:
    """The model a simulation samples: the planar encounter (always; its parameters are
    recorded), the station geometry (None for the planar model) and the kinds it predicts."""

    planar: object
    geometry: Optional[object]
    kinds: tuple


@dataclass(frozen=True)
class _Span:
    """The sample times before impact (UTC labels and seconds from impact), the model's values
    at them per kind, and the indices of the visible pass."""

    times: np.ndarray
    model: dict
    visible: np.ndarray


def _station_name(nominal, stations: Mapping) -> str:
    """The nominal file's station, or the stations table's only one."""
    name = nominal.station
    if name is None:
        if len(stations) != 1:
            raise InputError("which station?", file=nominal.source, column="station",
                             found=", ".join(sorted(stations)) or "(no stations)",
                             expected="station in the nominal file, or a stations table with one station")
        name = next(iter(stations))
    if name not in stations:
        raise InputError("unknown station", file=nominal.source, column="station", found=name,
                         expected="a station of the stations table: " + ", ".join(sorted(stations)))
    return name


def _encounter(nominal, station, options: BallisticOptions) -> _Encounter:
    """The planar model (seed 003 eqs. 9-11, elevation only) or the 3-D one (elevation, azimuth)."""
    if nominal.model == "planar":
        kinds = tuple(k for k in ("elevation",) if k in options.kinds)
        if not kinds:
            raise InputError("the planar model predicts elevation only", column="--kinds",
                             found=",".join(options.kinds), expected="a list including elevation")
        return _Encounter(dp.planar_encounter(nominal, station), None, kinds)
    kinds = tuple(k for k in ("elevation", "azimuth") if k in options.kinds)
    if not kinds:
        raise InputError("a ballistic pass has elevation and azimuth only", column="--kinds",
                         found=",".join(options.kinds), expected="elevation and/or azimuth")
    geometry = dp.StationGeometry.of(station, nominal.earth)
    return _Encounter(dp.planar_for_3d(nominal, geometry), geometry, kinds)


def _sample_times(nominal, enc: _Encounter, displacement: float, step_s: float) -> np.ndarray:
    """UTC labels ``T - k·step``, k = n ... 1, back to the rise of the simulated hypothesis
    (15 % earlier for the 3-D model, whose rise the planar one only approximates)."""
    try:
        rise = enc.planar.rise_time(displacement)
    except ValueError as exc:
        raise ProcessingError(f"no visible pass: {exc}") from None
    launch = -2.0 * enc.planar.impact_from_apogee_s
    window = min(-rise * (1.0 if enc.geometry is None else 1.15) + step_s, -launch)
    n = math.floor(window / step_s)
    if n < 1:
        raise ProcessingError("no visible pass: the step is longer than the visible flight "
                              f"({-rise:.1f} s); use a smaller --step")
    if n > 2_000_000:
        raise InputError("too many samples", column="--step", found=step_s,
                         expected=f"a step giving at most 2e6 samples over {window:.0f} s")
    k = np.arange(n, 0, -1, dtype=np.int64)
    return np.datetime64(nominal.impact_time, "ns") - k * np.timedelta64(round(step_s * 1e9), "ns")


def _visible_span(nominal, enc: _Encounter, displacement: float, options: BallisticOptions,
                  name: str, eop) -> _Span:
    """The model at the sample times and the last uninterrupted stretch above the mask."""
    times = _sample_times(nominal, enc, displacement, options.step_s)
    s = dp.seconds_from_impact(times, nominal.impact_time)
    if enc.geometry is None:
        model = {"elevation": enc.planar.elevation(s, displacement)}
    else:
        m = dp.model_3d(nominal, enc.geometry, s, displacement, eop)
        model = {"elevation": m.elevation_rad, "azimuth": m.azimuth_rad}
    el = model["elevation"]
    visible = el >= options.elevation_mask_deg * DEG
    if not visible.any():
        raise ProcessingError(f"no visible pass: the object never rises above the {options.elevation_mask_deg:g} "
                              f"deg mask of {name} (maximum elevation {np.degrees(el.max()):.2f} deg)")
    last = np.flatnonzero(visible)[-1]
    below = np.flatnonzero(~visible[: last + 1])
    first = below[-1] + 1 if below.size else 0
    return _Span(times=times, model=model, visible=np.arange(first, last + 1))


def _noisy_table(span: _Span, kinds: tuple, name: str, options: BallisticOptions) -> tuple[pd.DataFrame, np.ndarray]:
    """The pass table (noise drawn kind by kind in ``kinds`` order, azimuth wrapped to [0, 2π))
    sorted by time then kind, and the noiseless values in the same order."""
    idx = span.visible
    rng = np.random.default_rng(options.seed)
    sigma = options.sigma_angle_deg * DEG
    pieces, truth = [], []
    pass_id = f"{name}-001"
    for kind in kinds:
        value = span.model[kind][idx].copy()
        truth.append(value.copy())
        if sigma > 0:
            value = value + rng.normal(0.0, sigma, idx.size)
        if kind == "azimuth":
            value = np.mod(value, 2 * np.pi)
            value = np.where(value >= 2 * np.pi, 0.0, value)
        pieces.append(pd.DataFrame({"time": span.times[idx], "station": name, "pass_id": pass_id, "kind": kind,
                                    "value": value, "sigma": sigma if sigma > 0 else NOISELESS_SIGMA_DEG * DEG}))
    frame = pd.concat(pieces, ignore_index=True)
    truth_values = np.concatenate(truth)
    order = np.lexsort((frame["kind"].to_numpy(dtype=str), frame["time"].to_numpy()))
    frame = frame.iloc[order].reset_index(drop=True)
    frame["time"] = pd.DatetimeIndex(frame["time"]).tz_localize("UTC")
    return frame, truth_values[order]


def _simulation_record(nominal, enc: _Encounter, span: _Span, displacement: float,
                       options: BallisticOptions, eop) -> dict:
    """The ``simulation`` block of the pass file's metadata: what was simulated and how."""
    planar = enc.planar
    simulation = {
        "generator": "trackproc simulate --ballistic",
        "hypothesis": options.hypothesis,
        "displacement_m": float(displacement),
        "nominal": nominal.describe(),
        "model": nominal.model,
        "step_s": float(options.step_s),
        "elevation_mask_deg": float(options.elevation_mask_deg),
        "kinds": list(enc.kinds),
        "noise_sigma": {"angle_deg": float(options.sigma_angle_deg)},
        "seed": options.seed,
        "start": format_epoch(span.times[span.visible[0]]), "end": format_epoch(span.times[span.visible[-1]]),
        "impact_time": format_epoch(nominal.impact_time),
        "planar": {"p_m": planar.p_m, "e": planar.e, "theta_f_deg": planar.theta_f / DEG,
                   "radius_m": planar.radius_m, "observer_rate_rad_s": planar.observer_rate},
    }
    if enc.geometry is not None:
        simulation.update(force=nominal.force, earth=nominal.earth,
                          propagator="DOP853 rtol 1e-13 (scipy), from the impact state backwards",
                          earth_orientation=getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)")
    return simulation


def simulate_ballistic(nominal, stations: Mapping, options: BallisticOptions, eop=None) -> BallisticSimulation:
    """Simulate the pass of ``nominal`` (:class:`~trackproc.pipeline.detect.Nominal`) at its station.

    ``stations``: name -> :class:`~trackproc.io.stations.Station`. Raises
    :class:`~trackproc.errors.InputError` for bad options or an unknown station and
    :class:`~trackproc.errors.ProcessingError` when nothing is visible.
    """
    _check(options)
    name = _station_name(nominal, stations)
    station = stations[name]
    displacement = 0.0
    if options.hypothesis == "h1":
        displacement = options.displacement_m if options.displacement_m is not None else nominal.displacement_m
    enc = _encounter(nominal, station, options)
    span = _visible_span(nominal, enc, displacement, options, name, eop)
    frame, truth_values = _noisy_table(span, enc.kinds, name, options)
    station_meta = station.as_dict() if hasattr(station, "as_dict") else {
        "lat_deg": float(station.lat_deg), "lon_deg": float(station.lon_deg), "height_m": float(station.height_m)}
    simulation = _simulation_record(nominal, enc, span, displacement, options, eop)
    meta = base_meta(sources=["trackproc simulate --ballistic"], stations={name: station_meta}, simulation=simulation)
    return BallisticSimulation(frame=frame, meta=meta, truth_values=truth_values, station=name)


def planar_vs_3d(nominal, station, *, step_s: float = 1.0, displacement_m: float | None = None, eop=None) -> dict:
    """Error of the planar model against the 3-D one for one nominal trajectory and station.

    Noiseless H0 and H1 on the grid ``T - τ - k·step`` back to the horizon rise (samples where
    the 3-D and planar H0 elevations are both >= 0). Returns
    :func:`~trackproc.pipeline.detect.compare_planar`'s record (with sigma 1 rad, so its γ
    values are ``sqrt(Σ Δ²)``) plus the information distances ``‖Δε‖ ≈ sqrt(step Σ Δ²)``
    (rad·s^½) of the planar elevations, the 3-D elevations, and the 3-D azimuths and elevations.
    """
    geometry = dp.StationGeometry.of(station, nominal.earth)
    enc = dp.planar_for_3d(nominal, geometry)
    disp = displacement_m if displacement_m is not None else nominal.displacement_m
    rise = enc.rise_time()
    end = -max(nominal.tau_s, step_s)
    s = np.arange(end, rise * 1.05, -step_s)[::-1]
    m0 = dp.model_3d(nominal, geometry, s, 0.0, eop)
    m1 = dp.model_3d(nominal, geometry, s, disp, eop)
    keep = (m0.elevation_rad >= 0) & (enc.elevation(s) >= 0)
    s = s[keep]
    kinds = np.array(["elevation"] * s.size + ["azimuth"] * s.size)
    ss = np.concatenate([s, s])
    a = np.concatenate([m0.elevation_rad[keep], m0.azimuth_rad[keep]])
    b = np.concatenate([m1.elevation_rad[keep], m1.azimuth_rad[keep]])
    b = np.where(kinds == "azimuth", a + dp.wrap_pi(b - a), b)
    out = dp.compare_planar(nominal, geometry, ss, kinds, a, b, np.ones(a.shape), disp)
    if out.get("available"):
        root = math.sqrt(step_s)
        out["distance_planar"] = out.pop("gamma_planar_elevation") * root
        out["distance_3d_elevation"] = out.pop("gamma_3d_elevation") * root
        out["distance_3d_azimuth_elevation"] = out.pop("gamma_3d_azimuth_elevation") * root
        out["relative_distance_error"] = out.pop("relative_gamma_error")
        out.pop("sigma_elevation_rad", None)
        out["window_s"] = [float(s.min()), float(s.max())]
    return out
