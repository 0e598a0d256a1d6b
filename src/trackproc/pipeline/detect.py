"""``trackproc detect``: is the measured pass the nominal trajectory (H0) or the displaced one (H1)?

Seed 003. From a canonical pass file (elevations, and azimuths for the 3-D model) and a
nominal trajectory (NOMINAL.json), the predictions ``a_i`` (H0: displacement 0) and ``b_i``
(H1: displacement Δ*) are computed at the sample times, then the statistic S of eq. 2, its
moments (eqs. 3-4), the threshold for a chosen false-alarm probability or the equal-error
threshold, the decision and the achieved γ, α, β (:mod:`trackproc.methods.detection`).

NOMINAL.json (one JSON object; units in the names; unknown keys are an error)::

    impact_time     required  ISO 8601 UTC time T of impact (θ = θ_f) under H0
    velocity_kms | velocity_m_s, angle_deg
                    impact speed V (inertial) and flight-path angle α below the horizontal
    p_m, e [, phi_deg]
                    or the conic itself (planar only); φ (observer angle from the apse line,
                    from apogee, degrees) defaults to θ_f: the unfavourable orbit
    model           "planar" (default; seed 003 eqs. 9-11, elevation only) or "3d"
                    (DOP853 trajectory, real station, azimuth and elevation)
    displacement_m  Δ* of H1, m (default 500; ``--displacement-m`` overrides); > 0 puts the
                    observer beyond the impact point
    station         station name in the pass file (default: the only one with elevations)
    pass_id         pass to use when the station has several
    direction       "with" | "against" (object moving with / against the observer, i.e. east
                    / west for the 3-D model) | "none" (stationary observer; planar default)
    latitude_deg    observer latitude for the planar in-plane motion ω_E cos(lat)
                    (default: the station's latitude from the pass metadata)
    heading_deg     3-D only: azimuth of the impact velocity instead of with/against
    radius_m        planar Earth radius R (default 6371000)
    sigma_rad       measurement sigma, rad, when the pass's sigma column is not to be used
    tau_s           reaction time τ: samples after T - τ are not used (default 0)
    force           3-D: "two-body" (default, as the planar model) or "j2"
    earth           3-D: "wgs84" (default) or "sphere" (R = 6371 km, vertical = radial)
    kinds           3-D: ["elevation"] or ["elevation", "azimuth"] (default: both when present)

Azimuth residuals ``x - a`` and differences ``b - a`` are wrapped to (-π, π].
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from trackproc.errors import InputError, ProcessingError
from trackproc.vocabulary import EARTHS, FORCES, TAYLOR_FORCES  # noqa: F401  (re-exported)

DEG = math.pi / 180.0
MODELS = ("planar", "3d")
FIELDS = ("impact_time", "velocity_kms", "velocity_m_s", "angle_deg", "p_m", "e", "phi_deg", "model",
          "displacement_m", "station", "pass_id", "direction", "latitude_deg", "heading_deg", "radius_m",
          "sigma_rad", "tau_s", "force", "earth", "kinds", "comment", "schema_version")


@dataclass(frozen=True)
class Nominal:
    """The nominal trajectory of NOMINAL.json (SI units; see the module docstring)."""

    impact_time: np.datetime64
    model: str = "planar"
    velocity_m_s: Optional[float] = None
    angle_rad: Optional[float] = None
    p_m: Optional[float] = None
    e: Optional[float] = None
    phi_rad: Optional[float] = None
    displacement_m: float = 500.0
    station: Optional[str] = None
    pass_id: Optional[str] = None
    direction: str = "none"
    latitude_deg: Optional[float] = None
    heading_deg: Optional[float] = None
    radius_m: Optional[float] = None
    sigma_rad: Optional[float] = None
    tau_s: float = 0.0
    force: str = "two-body"
    earth: str = "wgs84"
    kinds: Optional[tuple] = None
    source: str = "<nominal>"

    def describe(self) -> dict:
        """JSON-ready echo (angles in degrees, time ISO)."""
        from trackproc.io.statefile import format_epoch

        out = {"impact_time": format_epoch(self.impact_time), "model": self.model,
               "displacement_m": self.displacement_m, "direction": self.direction, "tau_s": self.tau_s}
        if self.velocity_m_s is not None:
            out.update(velocity_m_s=self.velocity_m_s, angle_deg=self.angle_rad / DEG)
        if self.p_m is not None:
            out.update(p_m=self.p_m, e=self.e)
        if self.phi_rad is not None:
            out["phi_deg"] = self.phi_rad / DEG
        for key in ("station", "pass_id", "latitude_deg", "heading_deg", "radius_m", "sigma_rad"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.model == "3d":
            out.update(force=self.force, earth=self.earth)
        if self.kinds is not None:
            out["kinds"] = list(self.kinds)
        return out


# --------------------------------------------------------------------------- NOMINAL.json

def read_nominal(path: str) -> Nominal:
    """Read and check NOMINAL.json (``-`` = stdin)."""
    from trackproc.io.atomic import is_stdio, read_input_bytes

    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_nominal(read_input_bytes(path), source)


def parse_nominal(data: bytes | str, source: str = "<nominal>") -> Nominal:
    """The :class:`Nominal` in the JSON text ``data``; errors name ``source`` and the field."""
    from trackproc.io.statefile import parse_epoch

    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid JSON ({getattr(exc, 'msg', exc)})", file=source,
                         row=getattr(exc, "lineno", None), expected="a JSON object (NOMINAL.json)") from None
    except RecursionError:
        raise InputError("JSON nested too deeply", file=source, expected="a JSON object (NOMINAL.json)") from None
    if not isinstance(doc, dict):
        raise InputError("not a nominal-trajectory file", file=source, found=type(doc).__name__,
                         expected="a JSON object")
    unknown = sorted(k for k in doc if k not in FIELDS)
    if unknown:
        raise InputError("unknown field", file=source, column=unknown[0], expected="one of " + ", ".join(FIELDS))

    def number(key, *, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False, expected=None):
        if key not in doc or doc[key] is None:
            return None
        value = doc[key]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if ok:
            value = float(value)
            ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
        if not ok:
            raise InputError("invalid value", file=source, column=key, found=doc[key],
                             expected=expected or f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}"
                                                  f"{')' if hi_open else ']'}")
        return value

    def choice(key, options, default):
        value = doc.get(key, default)
        if value is None:
            value = default
        if not isinstance(value, str) or value.strip().lower() not in options:
            raise InputError("invalid value", file=source, column=key, found=value, expected=" or ".join(options))
        return value.strip().lower()

    def text(key):
        value = doc.get(key)
        if value is None:
            return None
        if not isinstance(value, str) or not value.strip():
            raise InputError("invalid value", file=source, column=key, found=value, expected="a non-empty string")
        from trackproc.io.validate import check_name

        return check_name(value.strip(), key.replace("_", " "), file=source, column=key)

    if "impact_time" not in doc:
        raise InputError("missing field", file=source, column="impact_time",
                         expected="the impact time T, ISO 8601 UTC (e.g. 2026-03-20T10:00:00Z)")
    impact = parse_epoch(doc["impact_time"], file=source, column="impact_time")
    model = choice("model", MODELS, "planar")

    v_kms = number("velocity_kms", lo=0, hi=7.9, lo_open=True, hi_open=True,
                   expected="an impact speed in km/s in (0, 7.9) (sub-orbital)")
    v_ms = number("velocity_m_s", lo=0, hi=7900, lo_open=True, hi_open=True,
                  expected="an impact speed in m/s in (0, 7900) (sub-orbital)")
    if v_kms is not None and v_ms is not None:
        raise InputError("give the speed once", file=source, column="velocity_m_s",
                         expected="either velocity_kms or velocity_m_s")
    velocity = v_ms if v_ms is not None else (v_kms * 1000.0 if v_kms is not None else None)
    angle = number("angle_deg", lo=0, hi=90, lo_open=True, hi_open=True,
                   expected="the flight-path angle below the horizontal, degrees in (0, 90)")
    p_m = number("p_m", lo=0, lo_open=True, expected="the focal parameter in metres, > 0")
    ecc = number("e", lo=0, hi=1, hi_open=True, expected="the eccentricity in [0, 1)")
    phi = number("phi_deg", lo=-360, hi=360, expected="degrees in [-360, 360]")
    by_impact = velocity is not None or angle is not None
    by_conic = p_m is not None or ecc is not None
    if by_impact and by_conic:
        raise InputError("give the trajectory once", file=source, column="p_m",
                         expected="either velocity_kms/velocity_m_s + angle_deg, or p_m + e (+ phi_deg)")
    if by_impact and (velocity is None or angle is None):
        raise InputError("missing field", file=source, column="angle_deg" if angle is None else "velocity_kms",
                         expected="both the impact speed and angle_deg")
    if by_conic and (p_m is None or ecc is None):
        raise InputError("missing field", file=source, column="e" if ecc is None else "p_m",
                         expected="both p_m and e")
    if not (by_impact or by_conic):
        raise InputError("missing field", file=source, column="velocity_kms",
                         expected="velocity_kms (or velocity_m_s) and angle_deg, or p_m and e")
    if model == "3d" and not by_impact:
        raise InputError("the 3-D model needs the impact speed and angle", file=source, column="velocity_kms",
                         expected="velocity_kms (or velocity_m_s) and angle_deg")
    if phi is not None and not by_conic:
        raise InputError("phi_deg goes with p_m and e", file=source, column="phi_deg",
                         expected="no phi_deg with velocity/angle (the unfavourable orbit φ = θ_f is used)")
    radius = number("radius_m", lo=6.0e6, hi=7.0e6, expected="an Earth radius in metres in [6.0e6, 7.0e6]")
    if by_conic:
        from trackproc.methods.ballistic import R_PLANAR

        r_model = radius or R_PLANAR
        if ecc < abs(1.0 - p_m / r_model):
            raise InputError("the orbit does not reach the Earth's surface", file=source, column="e", found=ecc,
                             expected=f"e >= |1 - p/R| = {abs(1.0 - p_m / r_model):.6g}")
    displacement = number("displacement_m", expected="a displacement in metres")
    if displacement is not None and displacement == 0:
        raise InputError("invalid value", file=source, column="displacement_m", found=0,
                         expected="a non-zero displacement Δ* in metres")
    direction = choice("direction", ("with", "against", "none"), "none")
    heading = number("heading_deg", lo=0, hi=360, hi_open=True, expected="degrees in [0, 360)")
    if model == "3d" and direction == "none" and heading is None:
        raise InputError("the 3-D model needs the direction of flight", file=source, column="direction",
                         expected="with or against (or heading_deg)")
    if heading is not None and model != "3d":
        raise InputError("heading_deg is for the 3-D model", file=source, column="heading_deg",
                         expected="model = \"3d\", or direction with/against")
    kinds = doc.get("kinds")
    if kinds is not None:
        if (not isinstance(kinds, list) or not kinds or any(k not in ("elevation", "azimuth") for k in kinds)
                or "elevation" not in kinds):
            raise InputError("invalid value", file=source, column="kinds", found=kinds,
                             expected='["elevation"] or ["elevation", "azimuth"]')
        if model == "planar" and "azimuth" in kinds:
            raise InputError("the planar model predicts elevation only", file=source, column="kinds",
                             found=kinds, expected='["elevation"] (or model "3d")')
        kinds = tuple(k for k in ("elevation", "azimuth") if k in kinds)
    return Nominal(
        impact_time=impact, model=model, velocity_m_s=velocity, angle_rad=None if angle is None else angle * DEG,
        p_m=p_m, e=ecc, phi_rad=None if phi is None else phi * DEG,
        displacement_m=500.0 if displacement is None else displacement,
        station=text("station"), pass_id=text("pass_id"), direction=direction,
        latitude_deg=number("latitude_deg", lo=-90, hi=90, expected="degrees in [-90, 90]"),
        heading_deg=heading, radius_m=radius,
        sigma_rad=number("sigma_rad", lo=0, hi=0.5, lo_open=True, expected="a sigma in rad in (0, 0.5]"),
        tau_s=number("tau_s", lo=0, expected="a reaction time in s, >= 0") or 0.0,
        force=choice("force", TAYLOR_FORCES, "two-body"), earth=choice("earth", EARTHS, "wgs84"),
        kinds=kinds, source=source)


# --------------------------------------------------------------------------- model values

def seconds_from_impact(times, impact_time) -> np.ndarray:
    """SI seconds (through TAI) from the impact time to UTC ``times`` (negative before impact)."""
    from trackproc.dynamics import timescales as ts

    return np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(np.asarray(times, "datetime64[ns]")),
                                       ts.datetime64_to_jd_utc(np.datetime64(impact_time, "ns"))), float)


def flight_time_s(nominal: Nominal) -> float:
    """Seconds from launch to impact of the nominal conic: twice the time from apogee to impact
    (the arc is symmetric about apogee; seed 003 App. A conic, eq. 10 time). A 1 % margin covers the
    3-D model's station radius differing from the planar one."""
    from trackproc.methods import ballistic as bl

    radius = nominal.radius_m or bl.R_PLANAR
    try:
        if nominal.velocity_m_s is not None:
            p, e = bl.impact_to_conic(nominal.velocity_m_s, nominal.angle_rad, radius)
        else:
            p, e = nominal.p_m, nominal.e
        t_imp = float(bl.time_from_apogee(bl.final_anomaly(float(p), float(e), radius), float(p), float(e)))
    except (ValueError, ArithmeticError) as exc:
        raise InputError(str(exc), file=nominal.source, column="e") from None
    if not (math.isfinite(t_imp) and t_imp > 0):
        raise InputError("the nominal trajectory has no flight time", file=nominal.source, column="velocity_kms",
                         found=t_imp, expected="a sub-orbital arc from the surface to the surface")
    return 2.0 * t_imp * 1.01


def planar_encounter(nominal: Nominal, station=None, *, radius_m: float | None = None,
                     latitude_rad: float | None = None):
    """The :class:`~trackproc.methods.ballistic.PlanarEncounter` of a nominal trajectory.

    Observer latitude: ``latitude_rad`` if given, else the nominal's, else the station's; only
    used when the direction is with/against.
    """
    from trackproc.methods import ballistic as bl

    radius = radius_m or nominal.radius_m or bl.R_PLANAR
    direction = nominal.direction
    if direction == "none" and nominal.heading_deg is not None:
        direction = "with" if math.sin(nominal.heading_deg * DEG) >= 0 else "against"
    lat = latitude_rad
    if lat is None and nominal.latitude_deg is not None:
        lat = nominal.latitude_deg * DEG
    if lat is None and station is not None:
        lat = station.lat_deg * DEG
    if direction != "none" and lat is None:
        raise InputError("an observer moving with/against the object needs a latitude", file=nominal.source,
                         column="latitude_deg", expected="latitude_deg, or a station with a latitude")
    rate = bl.observer_speed(lat, direction)
    try:
        if nominal.velocity_m_s is not None:
            p, e = bl.impact_to_conic(nominal.velocity_m_s, nominal.angle_rad, radius)
            p, e = float(p), float(e)
        else:
            p, e = nominal.p_m, nominal.e
        theta_f = float(bl.final_anomaly(p, e, radius))
    except ValueError as exc:
        raise InputError(str(exc), file=nominal.source, column="e") from None
    phi = theta_f if nominal.phi_rad is None else nominal.phi_rad
    return bl.PlanarEncounter(p_m=p, e=e, phi_impact=phi, observer_rate=rate, radius_m=radius)


@dataclass(frozen=True)
class StationGeometry:
    """A station for the 3-D model: geodetic (or spherical) lat/lon (rad), ITRF position (m)."""

    name: str
    lat_rad: float
    lon_rad: float
    r_itrf: np.ndarray

    @classmethod
    def of(cls, station, earth: str = "wgs84") -> "StationGeometry":
        from trackproc.dynamics import geodesy

        lat, lon, r_itrf = geodesy.station_itrf(station, earth)
        return cls(station.name, lat, lon, np.asarray(r_itrf))

    @property
    def geocentric_latitude(self) -> float:
        return float(math.asin(self.r_itrf[2] / np.linalg.norm(self.r_itrf)))


def model_3d(nominal: Nominal, geometry: StationGeometry, s_rel, displacement_m: float = 0.0, eop=None):
    """Azimuth/elevation (:class:`~trackproc.methods.ballistic.AzEl3D`) of the 3-D trajectory at ``s_rel``."""
    from trackproc.dynamics import frames
    from trackproc.dynamics import timescales as ts
    from trackproc.methods import ballistic as bl
    from trackproc.dynamics.geodesy import station_gcrf

    jd_t = ts.datetime64_to_jd_utc(np.datetime64(nominal.impact_time, "ns"))
    at_t = station_gcrf(geometry.r_itrf, jd_t[0], jd_t[1], eop)
    try:
        r_imp, v_imp = bl.impact_state_3d(
            at_t.r[0], at_t.v[0], nominal.velocity_m_s, nominal.angle_rad, direction=nominal.direction,
            heading_rad=None if nominal.heading_deg is None else nominal.heading_deg * DEG,
            displacement_m=displacement_m)
    except ValueError as exc:
        raise InputError(str(exc), file=nominal.source, column="direction") from None
    s = np.asarray(s_rel, float)
    jd1, jd2 = ts.add_seconds_utc(jd_t, s)
    track = station_gcrf(geometry.r_itrf, jd1, jd2, eop)
    q = frames.QuasiInertialFrame.at(jd_t[0], jd_t[1], eop).q
    try:
        return bl.ballistic_azel(s, r_imp, v_imp, track.r, track.v, track.a, track.gcrf_to_itrf,
                                 geometry.lat_rad, geometry.lon_rad, force=nominal.force, q=q)
    except ArithmeticError as exc:
        raise ProcessingError(f"3-D trajectory failed: {exc}") from None


def planar_for_3d(nominal: Nominal, geometry: StationGeometry):
    """The planar encounter matching a 3-D one: R = |r_station|, latitude = its geocentric latitude."""
    return planar_encounter(nominal, radius_m=float(np.linalg.norm(geometry.r_itrf)),
                            latitude_rad=geometry.geocentric_latitude)


def wrap_pi(angle):
    """Angle in (-π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(angle, float), 2 * np.pi)


# --------------------------------------------------------------------------- detection

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


def _select(table, nominal: Nominal, source: str):
    frame = table.frame
    kinds_wanted = nominal.kinds or (("elevation", "azimuth") if nominal.model == "3d" else ("elevation",))
    elev = frame[frame["kind"] == "elevation"]
    if elev.empty:
        raise InputError("no elevation samples", file=source, column="kind",
                         found=", ".join(sorted(frame["kind"].unique())) or "(none)", expected="elevation rows")
    stations = sorted(elev["station"].unique())
    name = nominal.station
    if name is None:
        if len(stations) > 1:
            raise InputError("several stations have elevations", file=nominal.source, column="station",
                             found=", ".join(stations), expected="the station to use")
        name = stations[0]
    elif name not in stations:
        raise InputError("station has no elevation samples in the pass file", file=nominal.source,
                         column="station", found=name, expected="one of " + ", ".join(stations))
    rows = frame[(frame["station"] == name) & frame["kind"].isin(kinds_wanted)]
    passes = sorted(rows["pass_id"].unique())
    pass_id = nominal.pass_id
    if pass_id is None:
        if len(passes) > 1:
            raise InputError("the station has several passes", file=nominal.source, column="pass_id",
                             found=", ".join(passes), expected="the pass to use")
        pass_id = passes[0]
    elif pass_id not in passes:
        raise InputError("unknown pass", file=nominal.source, column="pass_id", found=pass_id,
                         expected="one of " + ", ".join(passes))
    rows = rows[rows["pass_id"] == pass_id]
    if nominal.kinds is not None and "azimuth" in nominal.kinds and not (rows["kind"] == "azimuth").any():
        raise InputError("no azimuth samples for the requested kinds", file=source, column="kind",
                         expected="azimuth rows, or kinds [\"elevation\"] in the nominal file")
    return name, pass_id, rows


def detect(table, nominal: Nominal, options: DetectOptions | None = None, *, source: str = "<pass>",
           eop=None) -> DetectResult:
    """Run the seed 003 test on one pass of ``table`` (:class:`~trackproc.io.passfile.PassTable`)."""
    from trackproc.io.statefile import format_epoch
    from trackproc.methods import detection as dt

    options = options or DetectOptions()
    displacement = options.displacement_m if options.displacement_m is not None else nominal.displacement_m
    if not math.isfinite(displacement) or displacement == 0:
        raise InputError("invalid displacement", column="--displacement-m", found=displacement,
                         expected="a non-zero number of metres")
    name, pass_id, rows = _select(table, nominal, source)
    times = rows["time"].dt.tz_convert("UTC").dt.tz_localize(None).to_numpy("datetime64[ns]")
    s_all = seconds_from_impact(times, nominal.impact_time)
    keep = s_all <= -nominal.tau_s
    keep &= s_all < 0
    dropped = int((~keep).sum())
    if not keep.any():
        raise InputError("no samples before impact_time - tau_s", file=source, column="time",
                         found=f"{format_epoch(times.min())} .. {format_epoch(times.max())}",
                         expected=f"samples before {format_epoch(nominal.impact_time)} minus {nominal.tau_s:g} s")
    flight = flight_time_s(nominal)
    early = keep & (s_all < -flight)
    if early.any():
        i = int(np.flatnonzero(early)[0])
        raise InputError(f"{int(early.sum())} samples before the launch of the nominal trajectory "
                         f"(a flight of {flight:.1f} s ending at {format_epoch(nominal.impact_time)})",
                         file=source, column="time", found=format_epoch(times[i]),
                         expected="samples of the flight (check impact_time in the nominal file and the pass)")
    rows = rows[keep]
    s = s_all[keep]
    kinds = rows["kind"].to_numpy(dtype=str)
    x = rows["value"].to_numpy(float)
    sigma_source = "pass file sigma column"
    if options.sigma_rad is not None:
        sigma = np.full(x.shape, float(options.sigma_rad))
        sigma_source = "--sigma-rad"
    elif nominal.sigma_rad is not None:
        sigma = np.full(x.shape, nominal.sigma_rad)
        sigma_source = "nominal sigma_rad"
    else:
        sigma = rows["sigma"].to_numpy(float)
        bad = ~(np.isfinite(sigma) & (sigma > 0))
        if bad.any():
            raise InputError("sigma must be positive", file=source, column="sigma", found=float(sigma[bad][0]),
                             expected="a positive sigma in rad, or sigma_rad in the nominal file")

    station = table.stations().get(name)
    info: dict = {}
    if nominal.model == "planar":
        if nominal.direction != "none" and nominal.latitude_deg is None and station is None:
            raise InputError("station missing from the pass file metadata", file=source, column="stations",
                             found=name, expected="its latitude there, or latitude_deg in the nominal file")
        enc = planar_encounter(nominal, station)
        a = enc.elevation(s)
        b = enc.elevation(s, displacement)
        info = _planar_info(enc)
    else:
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

    try:
        stat = dt.statistic(x, a, b, sigma)
        decision = dt.decide(stat, options.false_alarm)
    except ValueError as exc:
        raise ProcessingError(str(exc)) from None
    spacing = float(np.median(np.diff(np.unique(s)))) if np.unique(s).size > 1 else float("nan")
    by_kind = {k: int((kinds == k).sum()) for k in ("elevation", "azimuth") if (kinds == k).any()}
    doc = {
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
            "used": stat.n, "by_kind": by_kind, "not_used_after_T_minus_tau": dropped,
            "first": format_epoch(times[keep].min()), "last": format_epoch(times[keep].max()),
            "first_s_from_impact": float(s.min()), "last_s_from_impact": float(s.max()),
            "median_spacing_s": spacing,
        },
        "g_achieved_rad_s05": float(stat.sigma0 * math.sqrt(spacing)) if math.isfinite(spacing) else None,
        "information_distance_rad_s05": float(math.sqrt(stat.c_n * spacing)) if math.isfinite(spacing) else None,
        "max_abs_b_minus_a_rad": float(np.max(np.abs(b - a))),
        "nominal": {**nominal.describe(), **info.pop("nominal", {})},
        **info,
        "units": {"angles": "rad", "S": "rad^2", "variance": "rad^4", "g": "rad s^0.5", "time": "UTC"},
        "method": "seed 003 eqs. 1-8: S = sum w_i (x_i - a_i)(b_i - a_i), w_i = (sigma0/sigma_i)^2 (1 when "
                  "sigma is uniform); E[S|H0] = 0, E[S|H1] = C_n, Var S = sigma0^2 C_n",
    }
    return DetectResult(document=doc, statistic=stat, decision=decision,
                        samples={"times": times[keep], "s": s, "kinds": kinds, "x": x, "a": a, "b": b,
                                 "sigma": sigma})


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


__all__ = ["DetectOptions", "DetectResult", "Nominal", "StationGeometry", "compare_planar", "detect", "model_3d",
           "parse_nominal", "planar_encounter", "read_nominal", "result_json", "seconds_from_impact"]
