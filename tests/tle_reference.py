"""An independent path from a TLE (or a GCRF state table) to GCRF states and a station's
elevation, azimuth and geometric range-rate: the ``sgp4`` package and ERFA called directly,
without any trackproc module (used by test_propagate_tle.py, test_passes.py, test_compare.py).

TEME -> ITRF: GMST 1982 about z (Vallado et al. 2006, AIAA 2006-6753), no polar motion;
ITRF -> GCRF: ``erfa.c2t06a`` transposed. UT1 = UTC + dut1. No light time (the geometric
direction at the reception time): elevations agree with trackproc's light-time model to
~1e-3 deg in LEO.
"""

from __future__ import annotations

import erfa
import numpy as np
from sgp4.api import Satrec

ISS = ("ISS (ZARYA)\n"
       "1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991\n"
       "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482\n")
OMEGA = 7.292115146706979e-5


def _jd(times):
    t = np.asarray(times, dtype="datetime64[ns]")
    days = (t - np.datetime64("2000-01-01T12:00:00", "ns")) / np.timedelta64(86400, "s")
    return np.full(t.shape, 2451545.0), days.astype(float)


#: the last c2t result: a TLE's states and each station's view are usually asked at the same times
#: (a day of 1-s samples: 1.5 s of ERFA per call)
_C2T_LAST: dict = {}


def c2t(times, dut1=0.0):
    """GCRS -> ITRS matrices (N, 3, 3) and UT1 dates at UTC times (no polar motion)."""
    key = (np.asarray(times, dtype="datetime64[ns]").tobytes(), float(dut1))
    if key not in _C2T_LAST:
        u1, u2 = _jd(times)
        tai1, tai2 = erfa.utctai(u1, u2)
        tt1, tt2 = erfa.taitt(tai1, tai2)
        ut1, ut2 = u1, u2 + dut1 / 86400.0
        _C2T_LAST.clear()
        _C2T_LAST[key] = erfa.c2t06a(tt1, tt2, ut1, ut2, 0.0, 0.0), ut1, ut2
    return _C2T_LAST[key]


def sgp4_gcrf(tle_text: str, times, dut1=0.0):
    """GCRF position (m) and velocity (m/s) of a TLE at UTC times, shape (N, 3) each."""
    lines = [line for line in tle_text.splitlines() if line.startswith(("1 ", "2 "))]
    sat = Satrec.twoline2rv(lines[0], lines[1])
    u1, u2 = _jd(times)
    err, r, v = sat.sgp4_array(u1, u2)
    assert not np.any(err)
    r, v = np.asarray(r) * 1e3, np.asarray(v) * 1e3
    m, ut1, ut2 = c2t(times, dut1)
    g = erfa.gmst82(ut1, ut2)
    c, s = np.cos(g), np.sin(g)
    rot = np.zeros((len(g), 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, s, -s, c, 1.0
    r_pef = np.einsum("nij,nj->ni", rot, r)
    v_pef = np.einsum("nij,nj->ni", rot, v) - np.cross([0.0, 0.0, OMEGA], r_pef)
    # ITRF (= PEF without polar motion) -> GCRF: r = M^T r_itrf, v = M^T (v_itrf + w x r_itrf)
    r_g = np.einsum("nji,nj->ni", m, r_pef)
    v_g = np.einsum("nji,nj->ni", m, v_pef + np.cross([0.0, 0.0, OMEGA], r_pef))
    return r_g, v_g


def station_view(r_gcrf, v_gcrf, times, lat_deg, lon_deg, height_m, dut1=0.0):
    """Elevation, azimuth (deg) and geometric range-rate (m/s) of GCRF states from a WGS-84 station."""
    st = np.asarray(erfa.gd2gc(1, np.radians(lon_deg), np.radians(lat_deg), height_m))
    m, _, _ = c2t(times, dut1)
    r_itrf = np.einsum("nij,nj->ni", m, r_gcrf)
    v_itrf = np.einsum("nij,nj->ni", m, v_gcrf) - np.cross([0.0, 0.0, OMEGA], r_itrf)
    d = r_itrf - st
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    east = np.array([-np.sin(lon), np.cos(lon), 0.0])
    north = np.array([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    e, n, u = d @ east, d @ north, d @ up
    el = np.degrees(np.arctan2(u, np.hypot(e, n)))
    az = np.degrees(np.arctan2(e, n)) % 360.0
    rr = np.einsum("ni,ni->n", d, v_itrf) / np.linalg.norm(d, axis=1)
    return el, az, rr
