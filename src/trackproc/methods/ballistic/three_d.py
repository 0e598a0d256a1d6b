"""The 3-D counterpart (beyond the paper): the impact state through a real station and its azimuth and elevation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.dynamics import reference
from trackproc.models import measurements as mm

from trackproc.methods.ballistic.conic import DIRECTIONS


def _rotate(vec, axis, angle):
    """Rodrigues rotation of ``vec`` about the unit ``axis`` by ``angle`` (rad, right hand)."""
    k = np.asarray(axis, float)
    v = np.asarray(vec, float)
    return v * np.cos(angle) + np.cross(k, v) * np.sin(angle) + k * np.dot(k, v) * (1 - np.cos(angle))


def impact_state_3d(r_station_m, v_station_m_s, velocity_m_s: float, angle_rad: float, *,
                    direction: str = "with", heading_rad: float | None = None, displacement_m: float = 0.0):
    """GCRF position (m) and velocity (m/s) of the object at impact for the 3-D model.

    The impact point is the station (``r_station_m`` at the impact time, GCRF) under H0. The
    velocity ``V (cos α ĥ - sin α û)`` has the geocentric vertical ``û = r/|r|`` and the
    horizontal ``ĥ``: the station's inertial velocity direction ("with", the unfavourable
    orbit of seed 003 moving eastward), its opposite ("against"), or, when ``heading_rad`` is
    given, the geocentric horizontal at that azimuth (from north through east; east is the
    station's inertial velocity direction, so north refers to the true rotation axis). H1: the
    state rotated about the orbit normal by ``-Δ/|r|`` (the impact point moves back along the
    track by Δ: the observer lies Δ beyond it, as the planar ``+Δ/R``).
    """
    r = np.asarray(r_station_m, float)
    up = r / np.linalg.norm(r)
    v_st = np.asarray(v_station_m_s, float)
    v_h = v_st - np.dot(v_st, up) * up
    norm = np.linalg.norm(v_h)
    if norm < 1e-3:
        raise ValueError("the station does not move (pole): the 3-D model needs a station off the poles")
    east = v_h / norm                      # ω × r about the true rotation axis: exactly east
    if heading_rad is None:
        if DIRECTIONS[direction] == 0:
            raise ValueError("direction must be 'with' or 'against' for the 3-D model (or give a heading)")
        h = DIRECTIONS[direction] * east
    else:
        north = np.cross(up, east)
        h = np.sin(heading_rad) * east + np.cos(heading_rad) * north
    v = velocity_m_s * (np.cos(angle_rad) * h - np.sin(angle_rad) * up)
    if displacement_m:
        normal = np.cross(up, h)
        angle = -displacement_m / np.linalg.norm(r)
        r, v = _rotate(r, normal, angle), _rotate(v, normal, angle)
    return r, v


@dataclass(frozen=True)
class AzEl3D:
    """3-D model values at the sample times: azimuth, elevation (rad), range (m), object GCRF."""

    azimuth_rad: np.ndarray
    elevation_rad: np.ndarray
    range_m: np.ndarray
    r_sat: np.ndarray


def ballistic_azel(s_rel_s, r_impact_m, v_impact_m_s, station_r_gcrf, station_v_gcrf, station_a_gcrf,
                   gcrf_to_itrf, lat_rad: float, lon_rad: float, *, force: str = "two-body", q=None) -> AzEl3D:
    """Azimuth and elevation of the 3-D trajectory from a station at times ``s`` relative to impact.

    The object's state at impact (GCRF) is propagated to ``s_rel_s`` (≤ 0) by
    :func:`trackproc.dynamics.reference.propagate_gcrf` (DOP853, rtol 1e-13; two-body or J2
    about the z axis of ``q``, the quasi-inertial frame of the impact epoch); the station's
    GCRF track at the same reception times (from
    :func:`trackproc.models.measurements.station_gcrf`) and the one-way light time give az/el.
    """
    s = np.asarray(s_rel_s, float)
    q = np.eye(3) if q is None else np.asarray(q, float)
    r_sat, v_sat = reference.propagate_gcrf(r_impact_m, v_impact_m_s, s, q, force)
    a_sat, j_sat = reference.acceleration_gcrf(r_sat, v_sat, q, force)
    obs = mm.observables(r_sat, v_sat, a_sat, j_sat, station_r_gcrf, station_v_gcrf, station_a_gcrf,
                         gcrf_to_itrf, lat_rad, lon_rad, carrier_hz=1.0)
    return AzEl3D(azimuth_rad=obs.azimuth_rad, elevation_rad=obs.elevation_rad, range_m=obs.range_m, r_sat=r_sat)
