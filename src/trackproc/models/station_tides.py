"""Solid-Earth tide displacement of a station, and its effect on a range.

IERS Conventions (2010), Technical Note 36, section 7.1.1, Step 1 (in-phase, degree 2 with the
latitude dependence of the Love numbers, and degree 3): for each tide-raising body j (Sun,
Moon) at geocentric ``R_j``, the station at ``r`` (unit vectors ``r̂``, ``R̂_j``) moves by

    Δr = Σ_j (GM_j / GM_E) (R_E⁴ / R_j³) { h₂ r̂ (3/2 (R̂_j·r̂)² − 1/2)
                                         + 3 l₂ (R̂_j·r̂) [R̂_j − (R̂_j·r̂) r̂] }             (7.5)
       + Σ_j (GM_j / GM_E) (R_E⁵ / R_j⁴) { h₃ r̂ (5/2 (R̂_j·r̂)³ − 3/2 (R̂_j·r̂))
                                         + l₃ (15/2 (R̂_j·r̂)² − 3/2) [R̂_j − (R̂_j·r̂) r̂] }   (7.6)

with h₂ = 0.6078 − 0.0006 (3 sin²φ − 1)/2, l₂ = 0.0847 + 0.0002 (3 sin²φ − 1)/2, h₃ = 0.292,
l₃ = 0.015 (eq. 7.2). The vector form holds in any geocentric frame (here GCRF). Left out: the
out-of-phase and latitude-correction terms of step 1 (below 1 mm) and step 2's frequency
dependence (up to ~13 mm radially, the K1 term) and the permanent tide (conventional
tide-free coordinates, as SINEX ITRF solutions are): checked against the IERS DEHANTTIDEINEL
test cases to 15 mm (``tests/models/test_station_tides.py``), against 0.1–0.4 m of signal.

A range to a station that moved by Δr changes by ``−û·Δr`` (``û`` from the station to the
satellite): :class:`SolidTideDisplacement`, a driver-free range modifier.
"""

from __future__ import annotations

import numpy as np

from trackproc.models import modifiers as md
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.forces.third_body import sun_moon_gcrf

GM_EARTH = 3.986004418e14
R_EARTH = 6378136.6                         # IERS 2010 (TN36 table 1.1)
GM_SUN = 1.32712442099e20
GM_MOON = 4.9028001e12


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def solid_tide_displacement(r_st, r_sun, r_moon) -> np.ndarray:
    """Displacement (m, same frame) of stations at ``r_st`` (..., 3) by the Sun and Moon at
    geocentric ``r_sun``, ``r_moon`` (..., 3), eqs. (7.5)-(7.6).

    Implements IERS Conventions (2010) eqs. 7.5-7.6 (step 1, in-phase, with the latitude dependence of eq. 7.2).
    """
    r_st = np.asarray(r_st, float)
    r_hat = r_st / np.linalg.norm(r_st, axis=-1, keepdims=True)
    sin_lat2 = r_hat[..., 2] ** 2                       # geocentric latitude: within 1e-5 of h2, l2
    p2 = (3.0 * sin_lat2 - 1.0) / 2.0
    h2 = 0.6078 - 0.0006 * p2
    l2 = 0.0847 + 0.0002 * p2
    h3, l3 = 0.292, 0.015
    out = np.zeros(np.broadcast_shapes(r_st.shape, np.shape(r_sun), np.shape(r_moon)))
    for body, gm in ((r_sun, GM_SUN), (r_moon, GM_MOON)):
        body = np.asarray(body, float)
        dist = np.linalg.norm(body, axis=-1)
        b_hat = body / dist[..., None]
        c = _dot(b_hat, r_hat)
        tangential = b_hat - c[..., None] * r_hat
        f2 = gm / GM_EARTH * R_EARTH ** 4 / dist ** 3
        f3 = gm / GM_EARTH * R_EARTH ** 5 / dist ** 4
        out += f2[..., None] * ((h2 * (1.5 * c * c - 0.5))[..., None] * r_hat + (3.0 * l2 * c)[..., None] * tangential)
        out += f3[..., None] * ((h3 * (2.5 * c ** 3 - 1.5 * c))[..., None] * r_hat
                                + (l3 * (7.5 * c * c - 1.5))[..., None] * tangential)
    return out


class SolidTideDisplacement(md.RangeCorrection):
    """The range change ``−û·Δr`` of the solid-Earth tide displacement of every station (a
    driver-free range modifier). ``epoch_jd_utc``: the UTC two-part Julian date the samples'
    seconds ``t_s`` count from (SI seconds); the Sun and Moon from ERFA
    (:func:`trackproc.dynamics.forces.third_body.sun_moon_gcrf`), in GCRF like the stations."""

    def __init__(self, epoch_jd_utc) -> None:
        super().__init__(None)
        self.epoch_jd_utc = tuple(float(a) for a in epoch_jd_utc)

    def __repr__(self) -> str:
        return "solid-Earth tide displacement (IERS 2010 step 1)"

    def delay(self, meas, rows, geometry) -> np.ndarray:
        if geometry is None:
            raise ValueError("the station tide correction needs the evaluation's geometry")
        jd1, jd2 = ts.add_seconds_utc(self.epoch_jd_utc, meas.t_s[rows])
        sun, moon = sun_moon_gcrf(*ts.utc_to_tt(jd1, jd2))
        dr = solid_tide_displacement(meas.r_st[rows], sun[:, 0], moon[:, 0])
        return -_dot(geometry.u[rows], dr)
