"""The model values of ``detect``: the planar encounter (seed 003 eqs. 9-11) and the 3-D trajectory seen from a
real station.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trackproc.dynamics import frames, geodesy
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.geodesy import station_gcrf
from trackproc.errors import InputError, ProcessingError
from trackproc.methods import ballistic as bl

from trackproc.pipeline.detect.nominal import DEG, Nominal


def seconds_from_impact(times, impact_time) -> np.ndarray:
    """SI seconds (through TAI) from the impact time to UTC ``times`` (negative before impact)."""
    return np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(np.asarray(times, "datetime64[ns]")),
                                       ts.datetime64_to_jd_utc(np.datetime64(impact_time, "ns"))), float)


def flight_time_s(nominal: Nominal) -> float:
    """Seconds from launch to impact of the nominal conic: twice the time from apogee to impact
    (the arc is symmetric about apogee; seed 003 App. A conic, eq. 10 time). A 1 % margin covers the
    3-D model's station radius differing from the planar one."""
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
        lat, lon, r_itrf = geodesy.station_itrf(station, earth)
        return cls(station.name, lat, lon, np.asarray(r_itrf))

    @property
    def geocentric_latitude(self) -> float:
        return float(math.asin(self.r_itrf[2] / np.linalg.norm(self.r_itrf)))


def model_3d(nominal: Nominal, geometry: StationGeometry, s_rel, displacement_m: float = 0.0, eop=None):
    """Azimuth/elevation (:class:`~trackproc.methods.ballistic.AzEl3D`) of the 3-D trajectory at ``s_rel``."""
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
