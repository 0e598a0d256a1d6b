"""``trackproc simulate``: tracking passes of a known orbit, with noise, biases and a truth state.

The test bench of every later command, so the models are the reference ones:

1. The orbit: :func:`trackproc.dynamics.reference.propagate_gcrf` (DOP853, rtol 1e-13,
   two-body or two-body + J2 about the rotation axis of the initial epoch) from the initial
   state to every sample time; acceleration and jerk from the same force model.
2. The stations: WGS-84 (or spherical) geodetic -> ITRF -> GCRF at each reception time by
   IAU 2006/2000A (:func:`trackproc.models.measurements.station_gcrf`).
3. The observables: :func:`trackproc.models.measurements.observables` (one-way light time,
   range-rate model ``doppler`` or ``instantaneous``, one- or two-way).
4. Visibility: samples with elevation >= the mask, split into passes where the satellite
   drops below it, numbered ``<station>-001``, ``-002``, ... per station.
5. Errors: per-station range bias (added), a frequency offset and drift common to the
   spacecraft oscillator (added to every Doppler sample, drift counted from the start
   time), then independent Gaussian noise per sample (``numpy.random.default_rng(seed)``,
   drawn station by station in name order, kind by kind in canonical order).

``earth="sphere"`` places the stations on the sphere R = 6371 km (seed 004 eq. 8) with the
radial direction as their vertical; the Earth's orientation stays IAU 2006/2000A (the seed's
linear sidereal time is not used here).

The sample grid is ``start + k * step`` in UTC labels (what a station's clock prints), for
``k = 0 .. floor(duration / step)``; elapsed time for the dynamics is counted in SI
seconds through TAI, so a leap second inside the span is honoured.

Sigma column: the noise sigma of each kind; a kind simulated noiseless (sigma 0) keeps the
default sigma of :class:`SimulateOptions` in the table (downstream weighting needs a
positive sigma), and ``meta["simulation"]["noise_sigma"]`` records the zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Optional

import numpy as np
import pandas as pd

from trackproc import vocabulary
from trackproc.constants import force_model_constants
from trackproc.dynamics import frames, geodesy, propagator, reference, timescales as ts
from trackproc.errors import InputError, ProcessingError
from trackproc.io.passfile import base_meta
from trackproc.io.statefile import FORCE_LABELS, State
from trackproc.isotime import iso_utc
from trackproc.models import measurements as mm

#: Kinds in canonical order (the order noise is drawn in).
KINDS = vocabulary.KINDS
DEG = np.pi / 180.0
#: Default noise sigmas, SI (angles in degrees): the CLI defaults.
DEFAULT_SIGMAS = {"range": 10.0, "range_rate": 0.01, "doppler": 0.1, "angle_deg": 0.01}
#: Columns of the wide CSV, by kind, with the factor from SI.
WIDE_COLUMNS = {"range": ("range_m", 1.0), "range_rate": ("range_rate_m_s", 1.0), "doppler": ("doppler_hz", 1.0),
                "elevation": ("elevation_deg", 1.0 / DEG), "azimuth": ("azimuth_deg", 1.0 / DEG)}


@dataclass
class SimulateOptions:
    """Options of :func:`simulate` (units in the names; ``start`` UTC ``datetime64`` or None =
    the initial state's epoch)."""

    duration_s: float
    step_s: float
    start: Optional[np.datetime64] = None
    elevation_mask_deg: float = 10.0
    kinds: tuple = KINDS
    carrier_hz: float = 2.2e9
    mode: str = "one-way"
    sigma_range_m: float = DEFAULT_SIGMAS["range"]
    sigma_range_rate_m_s: float = DEFAULT_SIGMAS["range_rate"]
    sigma_doppler_hz: float = DEFAULT_SIGMAS["doppler"]
    sigma_angle_deg: float = DEFAULT_SIGMAS["angle_deg"]
    range_bias_m: Mapping[str, float] = field(default_factory=dict)
    freq_offset_hz: float = 0.0
    freq_drift_hz_s: float = 0.0
    seed: Optional[int] = None
    force: str = "j2"
    earth: str = "wgs84"
    range_rate_model: str = "doppler"
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None

    def noise_sigmas(self) -> dict:
        """Noise 1-sigma per kind, SI (angles in rad)."""
        angle = self.sigma_angle_deg * DEG
        return {"range": self.sigma_range_m, "range_rate": self.sigma_range_rate_m_s,
                "doppler": self.sigma_doppler_hz, "elevation": angle, "azimuth": angle}


@dataclass
class Simulation:
    """Result of :func:`simulate`: the canonical long table (``frame``: time, station, pass_id,
    kind, value, sigma), its metadata, the truth state at the start, the noiseless model values
    (``truth_values``, aligned with ``frame``), and the full per-station model on the grid."""

    frame: pd.DataFrame
    meta: dict
    truth: object
    truth_values: np.ndarray
    grid: dict

    def wide(self) -> pd.DataFrame:
        """One row per (station, time): ``time, station, range_m, range_rate_m_s, doppler_hz,
        elevation_deg, azimuth_deg`` (the requested kinds), as a station's raw output."""
        frame = self.frame
        out = frame.pivot_table(index=["station", "time"], columns="kind", values="value", aggfunc="first",
                                sort=False)
        out = out.reset_index()
        cols = {"time": out["time"], "station": out["station"]}
        for kind in KINDS:
            if kind in out.columns:
                name, factor = WIDE_COLUMNS[kind]
                cols[name] = out[kind].to_numpy(float) * factor
        wide = pd.DataFrame(cols)
        return wide.sort_values(["station", "time"], kind="mergesort").reset_index(drop=True)


def _check_options(options: SimulateOptions, stations: Mapping) -> None:
    def positive(flag, value):
        if not (np.isfinite(value) and value > 0):
            raise InputError("must be positive", column=flag, found=value, expected="a number > 0")

    def non_negative(flag, value):
        if not (np.isfinite(value) and value >= 0):
            raise InputError("must not be negative", column=flag, found=value, expected="a number >= 0 (0 = noiseless)")

    positive("--duration", options.duration_s)
    positive("--step", options.step_s)
    positive("--carrier-hz", options.carrier_hz)
    if options.duration_s / options.step_s > 5_000_000:
        raise InputError("too many samples", column="--step", found=options.step_s,
                         expected="at most 5e6 steps over --duration")
    for flag, value in (("--sigma-range-m", options.sigma_range_m),
                        ("--sigma-range-rate-m-s", options.sigma_range_rate_m_s),
                        ("--sigma-doppler-hz", options.sigma_doppler_hz),
                        ("--sigma-angle-deg", options.sigma_angle_deg)):
        non_negative(flag, value)
    if not -90.0 <= options.elevation_mask_deg <= 90.0:
        raise InputError("out of range", column="--elevation-mask-deg", found=options.elevation_mask_deg,
                         expected="degrees in [-90, 90]")
    bad = [k for k in options.kinds if k not in KINDS]
    if bad or not options.kinds:
        raise InputError("unknown measurement kind", column="--kinds", found=",".join(bad) or "(none)",
                         expected="a comma list of " + ",".join(KINDS))
    if options.mode not in vocabulary.LINK_MODES:
        raise InputError("unknown mode", column="--mode", found=options.mode,
                         expected=" or ".join(vocabulary.LINK_MODES))
    if options.range_rate_model not in vocabulary.RANGE_RATE_MODELS:
        raise InputError("unknown range-rate model", column="--range-rate-model", found=options.range_rate_model,
                         expected=" or ".join(vocabulary.RANGE_RATE_MODELS))
    for name, bias in options.range_bias_m.items():
        if name not in stations:
            raise InputError("range bias for an unknown station", column="--range-bias", found=name,
                             expected="a station of the stations table: " + ", ".join(sorted(stations)))
        if not np.isfinite(bias):
            raise InputError("range bias must be finite", column="--range-bias", found=bias, expected="metres")
    if not stations:
        raise InputError("no stations", column="--stations", expected="at least one station")


def time_grid(start: np.datetime64, duration_s: float, step_s: float) -> np.ndarray:
    """UTC labels ``start + k step``, k = 0 .. floor(duration/step), as ``datetime64[ns]``."""
    step_ns = int(round(step_s * 1e9))
    n = int(np.floor(duration_s / step_s * (1 + 1e-12))) + 1
    return np.datetime64(start, "ns") + np.arange(n, dtype=np.int64) * np.timedelta64(step_ns, "ns")


def simulate(initial, stations: Mapping, options: SimulateOptions, eop=None) -> Simulation:
    """Simulate the tracking passes of ``initial`` seen from ``stations``.

    Parameters
    ----------
    initial : :class:`~trackproc.io.statefile.State` (GCRF) — the orbit's initial state.
    stations : name -> object with ``lat_deg``, ``lon_deg``, ``height_m`` (WGS-84 geodetic).
    options : :class:`SimulateOptions`.
    eop : :class:`~trackproc.dynamics.timescales.EarthOrientation` or None.

    Raises :class:`~trackproc.errors.ProcessingError` when no pass is visible.

    Over 100 lines with this docstring; its code is under 100.
    """

    _check_options(options, stations)
    start = np.datetime64(options.start if options.start is not None else initial.epoch, "ns")
    times = time_grid(start, options.duration_s, options.step_s)
    jd1, jd2 = ts.datetime64_to_jd_utc(times)
    t_rel = ts.seconds_since((jd1, jd2), initial.jd_utc)
    start_rel = float(ts.seconds_since(ts.datetime64_to_jd_utc(start), initial.jd_utc))

    # the orbit, in the quasi-inertial frame of the initial epoch (J2 about its z axis)
    qframe = frames.QuasiInertialFrame.at(*initial.jd_utc, eop)
    if options.force_model is not None:
        r_all, v_all, a_all, j_all = _full_force_orbit(initial, np.r_[start_rel, t_rel], options.force_model, eop)
    else:
        try:
            r_all, v_all = reference.propagate_gcrf(initial.r_m, initial.v_m_s, np.r_[start_rel, t_rel], qframe.q,
                                                    options.force)
        except ArithmeticError as exc:
            raise ProcessingError(f"propagation failed: {exc}") from None
    r_sat, v_sat = r_all[1:], v_all[1:]
    if np.any(np.linalg.norm(r_sat, axis=1) < 6_300_000.0):
        raise ProcessingError("the orbit enters the Earth within the simulated span (|r| < 6300 km)")
    if options.force_model is not None:
        a_sat, j_sat = a_all[1:], j_all[1:]
    else:
        a_sat, j_sat = reference.acceleration_gcrf(r_sat, v_sat, qframe.q, options.force)

    # the stations
    names = sorted(stations)
    lat, lon, r_itrf = geodesy.station_itrf([stations[n] for n in names], options.earth)
    track = geodesy.station_gcrf(r_itrf, jd1, jd2, eop)
    obs = mm.observables(r_sat, v_sat, a_sat, j_sat, track.r, track.v, track.a, track.gcrf_to_itrf,
                         lat[:, None], lon[:, None], carrier_hz=options.carrier_hz, mode=options.mode,
                         range_rate_model=options.range_rate_model)
    model = obs.by_kind()

    visible = obs.elevation_rad >= options.elevation_mask_deg * DEG     # (S, N)
    if not visible.any():
        raise ProcessingError(
            f"no visible pass: the satellite never rises above the {options.elevation_mask_deg:g} deg mask "
            f"of {', '.join(names)} between {iso_utc(times[0])} and {iso_utc(times[-1])} "
            f"(maximum elevation {np.degrees(obs.elevation_rad.max()):.1f} deg); try a longer --duration, "
            "a lower --elevation-mask-deg or other stations")

    rng = np.random.default_rng(options.seed)
    sigmas = options.noise_sigmas()
    nominal = SimulateOptions(duration_s=1, step_s=1).noise_sigmas()
    drift_t = np.asarray(t_rel - start_rel)
    pieces, truth_parts = [], []
    pass_ids_all = np.full(visible.shape, "", dtype=object)
    for s, name in enumerate(names):
        idx = np.flatnonzero(visible[s])
        if idx.size == 0:
            continue
        new_pass = np.r_[True, np.diff(idx) > 1]
        numbers = np.cumsum(new_pass)
        pass_ids = np.array([f"{name}-{k:03d}" for k in range(1, numbers[-1] + 1)], dtype=object)[numbers - 1]
        pass_ids_all[s, idx] = pass_ids
        for kind in KINDS:
            if kind not in options.kinds:
                continue
            truth = model[kind][s, idx]
            value = truth.copy()
            if kind == "range":
                value = value + float(options.range_bias_m.get(name, 0.0))
            if kind == "doppler":
                value = value + options.freq_offset_hz + options.freq_drift_hz_s * drift_t[idx]
            sigma = sigmas[kind]
            if sigma > 0:
                value = value + rng.normal(0.0, sigma, idx.size)
            if kind == "azimuth":
                value = mm.wrap_2pi(value)
            pieces.append(pd.DataFrame({
                "time": times[idx], "station": name, "pass_id": pass_ids, "kind": kind,
                "value": value, "sigma": sigma if sigma > 0 else nominal[kind]}))
            truth_parts.append(truth)
    frame = pd.concat(pieces, ignore_index=True)
    truth_values = np.concatenate(truth_parts)
    order = np.lexsort((frame["kind"].to_numpy(dtype=str), frame["time"].to_numpy(),
                        frame["station"].to_numpy(dtype=str)))
    frame = frame.iloc[order].reset_index(drop=True)
    truth_values = truth_values[order]
    frame["time"] = pd.DatetimeIndex(frame["time"]).tz_localize("UTC")

    r0, v0 = (initial.r_m, initial.v_m_s) if start_rel == 0.0 else (r_all[0], v_all[0])
    truth = State.from_vectors(start, r0, v0, force_model=options.force,
                               eop_source=getattr(eop, "source", None),
                               extra={"source": "trackproc simulate (truth at the start time)"})
    meta = _meta(options, stations, names, visible, pass_ids_all, start, times, truth, initial, eop, sigmas)
    grid = {"times": times, "stations": names, "elevation_rad": obs.elevation_rad, "range_m": obs.range_m,
            "range_rate_m_s": obs.range_rate_m_s, "doppler_hz": obs.doppler_hz, "azimuth_rad": obs.azimuth_rad,
            "r_sat": r_sat, "v_sat": v_sat, "visible": visible}
    return Simulation(frame=frame, meta=meta, truth=truth, truth_values=truth_values, grid=grid)


def _full_force_orbit(initial, t_s, force_model, eop):
    """GCRF position, velocity, acceleration and jerk at ``t_s`` (s from the state's epoch) under
    the full force model (DOP853 + dense polynomials, trackproc.dynamics.forces)."""

    try:
        traj = propagator.propagate_state(initial, t_s, force=force_model, eop=eop).raise_for_outcome()
    except (ValueError, ArithmeticError) as exc:
        raise ProcessingError(f"propagation failed: {exc}") from None
    x, d1, d2 = traj.state(t_s), traj.state(t_s, derivative=1), traj.state(t_s, derivative=2)
    return x[:, :3], x[:, 3:], d1[:, 3:], d2[:, 3:]


def _meta(options, stations, names, visible, pass_ids_all, start, times, truth, initial, eop, sigmas) -> dict:
    used = [n for s, n in enumerate(names) if visible[s].any()]
    passes = sorted({p for p in pass_ids_all[visible]})
    station_meta = {}
    for n in used:
        st = stations[n]
        station_meta[n] = st.as_dict() if hasattr(st, "as_dict") else {
            "lat_deg": float(st.lat_deg), "lon_deg": float(st.lon_deg), "height_m": float(st.height_m)}
    eop_source = getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)"
    simulation = {
        "generator": "trackproc simulate",
        "start": iso_utc(start), "end": iso_utc(times[-1]),
        "duration_s": float(options.duration_s), "step_s": float(options.step_s),
        "elevation_mask_deg": float(options.elevation_mask_deg),
        "kinds": [k for k in KINDS if k in options.kinds],
        "initial_epoch": iso_utc(initial.epoch),
        "truth_epoch": iso_utc(truth.epoch),
        "truth_position_m": [float(x) for x in truth.r_m],
        "truth_velocity_m_s": [float(x) for x in truth.v_m_s],
        "seed": options.seed,
        "noise_sigma": {"range_m": options.sigma_range_m, "range_rate_m_s": options.sigma_range_rate_m_s,
                        "doppler_hz": options.sigma_doppler_hz, "angle_deg": options.sigma_angle_deg},
        "range_bias_m": {k: float(v) for k, v in sorted(options.range_bias_m.items())},
        "frequency_offset_hz": float(options.freq_offset_hz),
        "frequency_drift_hz_s": float(options.freq_drift_hz_s),
        "frequency_drift_epoch": iso_utc(start),
        "earth": options.earth if options.earth != "sphere" else
        "sphere (R = 6371 km station coordinates and vertical; Earth orientation still IAU 2006/2000A)",
        "passes": len(passes),
        "propagator": ("DOP853 rtol 1e-13 (scipy solve_ivp method), J2 about the rotation axis of the initial epoch"
                       if options.force_model is None else
                       "DOP853 rtol 1e-12 with dense output, full force model (trackproc.dynamics.forces)"),
        "aberration": "neglected (<= 0.32 arcsec)",
    }
    return base_meta(
        carrier_hz=float(options.carrier_hz),
        doppler_mode=options.mode,
        sources=["trackproc simulate"],
        stations=station_meta,
        force_model=(options.force_model.label() if options.force_model is not None
                     else FORCE_LABELS.get(options.force, options.force)),
        constants=(options.force_model.describe() if options.force_model is not None
                   else force_model_constants(options.force)),
        earth_orientation=eop_source,
        range_rate_model=options.range_rate_model,
        simulation=simulation,
    )
