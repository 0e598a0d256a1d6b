"""Stations on the Earth: WGS-84 geodetic <-> ITRF, topocentric ENU, azimuth, elevation, range.

Azimuth is measured from north through east in [0, 2π); elevation from the local horizontal
(normal to the ellipsoid) in [-π/2, π/2]. ``earth="sphere"`` is the seed papers' spherical
Earth (R = 6371 km; seed 004 eq. 8).
"""

from __future__ import annotations

import erfa
import numpy as np

from trackproc.constants import R_SPHERE

WGS84 = 1  # ERFA ellipsoid identifier


def geodetic_to_itrf(lat_rad, lon_rad, height_m, earth: str = "wgs84") -> np.ndarray:
    """Geodetic latitude, longitude (rad) and height (m) -> ITRF position (m), shape (..., 3)."""
    lat, lon, h = np.broadcast_arrays(*(np.asarray(x, float) for x in (lat_rad, lon_rad, height_m)))
    if earth == "sphere":
        rr = R_SPHERE + h
        return np.stack([rr * np.cos(lat) * np.cos(lon), rr * np.cos(lat) * np.sin(lon), rr * np.sin(lat)], -1)
    return np.asarray(erfa.gd2gc(WGS84, lon, lat, h))


def itrf_to_geodetic(r_m, earth: str = "wgs84"):
    """ITRF position (m) -> (lat rad, lon rad, height m)."""
    r = np.asarray(r_m, float)
    if earth == "sphere":
        rr = np.linalg.norm(r, axis=-1)
        return np.arcsin(r[..., 2] / rr), np.arctan2(r[..., 1], r[..., 0]), rr - R_SPHERE
    lon, lat, h = erfa.gc2gd(WGS84, r)
    return np.asarray(lat), np.asarray(lon), np.asarray(h)


def enu_matrix(lat_rad, lon_rad) -> np.ndarray:
    """Rows: east, north, up unit vectors in ITRF at a geodetic (or spherical) position."""
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    so, co = np.sin(lon_rad), np.cos(lon_rad)
    z = np.zeros_like(sl)
    return np.stack([np.stack([-so, co, z], -1),
                     np.stack([-sl * co, -sl * so, cl], -1),
                     np.stack([cl * co, cl * so, sl], -1)], -2)


def itrf_to_enu(r_sat_itrf, r_st_itrf, lat_rad, lon_rad) -> np.ndarray:
    """Topocentric east/north/up (m) of a point seen from a station, both in ITRF."""
    d = np.asarray(r_sat_itrf, float) - np.asarray(r_st_itrf, float)
    return np.einsum("...ij,...j->...i", enu_matrix(lat_rad, lon_rad), d)


def enu_to_azel(enu):
    """ENU (m) -> azimuth (rad, from north through east, [0, 2π)), elevation (rad), range (m)."""
    e, n, u = np.moveaxis(np.asarray(enu, float), -1, 0)
    rng = np.sqrt(e * e + n * n + u * u)
    az = np.mod(np.arctan2(e, n), 2 * np.pi)
    az = np.where(az >= 2 * np.pi, 0.0, az)  # mod of a tiny negative number rounds up to 2π
    el = np.arctan2(u, np.hypot(e, n))
    return az, el, rng
