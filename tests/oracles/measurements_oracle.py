"""TEST ORACLE (not shipped): an independent implementation of the measurement physics.

This is the simulator's original, self-contained code (light time by Taylor expansion of the
satellite about the reception time, its own Newton iterations, its own range-rate, Doppler and
az/el formulas), kept when the production code was unified into
``trackproc.models.light_time`` and ``trackproc.models.observables``. The tests compare the
simulator (``trackproc.models.measurements``) and the estimator
(``trackproc.models.observation``) against it; do not make it import those modules, nor
``trackproc.dynamics``: its stations (geodetic -> ITRF -> GCRF, with their rates) and its
azimuth/elevation are written from Vallado and ERFA's top-level routines, so that they check
``trackproc.dynamics.geodesy`` and ``frames`` rather than repeat them.

Measurement models of ground-station tracking: range, range-rate, Doppler, azimuth, elevation.

Pure functions on numpy arrays, SI units, all vectors in GCRF (m, m/s, s). Every sample is
time-tagged at **reception** on the ground, ``t_r`` (as Orekit's ground measurements are).

One-way light time (README "Units, sign conventions, time and frames"): the signal received at
``t_r`` left the satellite at ``t_e = t_r - ρ/c`` with

    ρ = |r_sat(t_e) - r_st(t_r)|                                                   (1)

solved by Newton iteration on ``g(τ) = c τ - ρ(t_r - τ)`` to ``|Δτ| < 1e-12 s`` (two
iterations from τ = 0 in practice). The satellite state at ``t_e`` comes from a Taylor
expansion about ``t_r`` with the force model's acceleration and jerk (truncation below
1e-14 m for LEO and GEO: the next term is ``snap τ⁴/24``).

Range-rate (one-way), with ``û`` the unit vector from ``r_st(t_r)`` to ``r_sat(t_e)``:

    doppler:        dρ/dt_r = û·(v_sat(t_e) - v_st(t_r)) / (1 + û·v_sat(t_e)/c)   (2)
    instantaneous:            û·(v_sat(t_e) - v_st(t_r))                          (3)

(seed 002 eq. 17 writes ``((r - r_st)·(v - v_st))/|r - r_st|`` and ``|r - r_st| + D0`` without
light time or station motion; seed 004 eqs. 11-12 the same range and its rate as spectra.)
(2) is the exact derivative of (1) (the ``doppler`` model, default); (3) is Orekit's
one-way ``RangeRate``; they differ by up to ~0.15 m/s in LEO. Positive range-rate means the
satellite recedes. One-way Doppler, received minus nominal frequency (a received frequency
``f_r = f (1 - dρ/dt_r / c)`` exactly, non-relativistically):

    Δf = -f · ρ̇ / c  (+ offset + drift · t)                                         (4)

(seed 004 item 1 gives ``Vr = c/(2 f0) f_D`` for two-way tracking; one-way uses ``c/f0``.)

Two-way (round trip station -> satellite -> same station, transponder turnaround ratio 1):
the down leg as above (the satellite at the bounce time ``t_b = t_r - ρ_d/c``), the up leg
``ρ_u = |r_sat(t_b) - r_st(t_t)|`` with ``t_t = t_b - ρ_u/c``. Range = ``(ρ_d + ρ_u)/2``;
range-rate = ``(ρ̇_d + ρ̇_u)/2``, with

    ρ̇_u = (1 - ρ̇_d/c) û_u·(v_sat(t_b) - v_st(t_t)) / (1 - û_u·v_st(t_t)/c)       (5)

(the derivative of ρ_u with respect to t_r; ``instantaneous`` drops both factors), and
two-way Doppler ``Δf = -2 f · range-rate / c`` (received ``f_r = f dt_t/dt_r``).

Azimuth and elevation are those of the light-time-corrected geometric direction
``r_sat(t_e) - r_st(t_r)``, rotated to ITRF at ``t_r`` and expressed in the station's
east-north-up frame (normal to the WGS-84 ellipsoid). Aberration is neglected: the
station's inertial velocity (≤ 465 m/s) shifts the apparent direction by at most
v/c ≈ 1.6e-6 rad (0.32 arcsec, 9e-5 deg), far below angle-tracking noise (~0.01 deg).
Refraction is neglected too (it is a property of the data, not the geometry).
"""

from __future__ import annotations

from dataclasses import dataclass

import erfa
import numpy as np

from trackproc.constants import C_LIGHT

#: Convergence threshold of the light-time iteration, s.
LIGHT_TIME_TOL_S = 1e-12
RANGE_RATE_MODELS = ("doppler", "instantaneous")
MODES = ("one-way", "two-way")


# --------------------------------------------------------------------------- stations
# Written from the textbooks and ERFA's own top-level routines, not from trackproc.dynamics: the
# closed-form geodetic -> ECEF of Vallado, the whole celestial-to-terrestrial matrix from
# ``erfa.c2t06a`` at every date (no interpolation grid, no factor-by-factor assembly), linear
# interpolation of the raw EOP columns, and velocity and acceleration by central differences of
# the rotated position (no analytic rates).

#: WGS-84 defining parameters (NIMA TR8350.2, Table 3.1): semi-major axis (m), inverse flattening.
WGS84_A_M = 6378137.0
WGS84_INV_F = 298.257223563
#: Step (s) of the central differences. A date's rotated position carries ~1e-8 m of rounding (the
#: Earth Rotation Angle is rounded to ~3e-15 rad), which the seven-point formulas below divide by the
#: step: ~8e-9 m/s at 30 s, ~1e-9 m/s at 120 s; their truncation (h⁶ ω⁷ r / 140, h⁶ ω⁸ r / 560) is
#: below 2e-12 at 120 s.
DIFF_STEP_S = 120.0
#: Arcseconds to radians.
ARCSEC = np.pi / (180.0 * 3600.0)


def geodetic_to_ecef(lat_rad, lon_rad, height_m, a_m: float = WGS84_A_M, inv_f: float = WGS84_INV_F):
    """WGS-84 geodetic latitude, longitude (rad) and ellipsoidal height (m) -> ECEF (ITRF) position
    (m), shape (..., 3).

    Implements Vallado, *Fundamentals of Astrodynamics and Applications* (4th ed., 2013), eqs. 3-13
    and 3-14: ``C = a / sqrt(1 - e² sin²φ)``, ``S = C (1 - e²)``, and the site at
    ``((C + h) cos φ cos λ, (C + h) cos φ sin λ, (S + h) sin φ)``.
    """
    lat, lon, h = np.broadcast_arrays(*(np.asarray(x, float) for x in (lat_rad, lon_rad, height_m)))
    f = 1.0 / inv_f
    e2 = f * (2.0 - f)
    c = a_m / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    s = c * (1.0 - e2)
    return np.stack([(c + h) * np.cos(lat) * np.cos(lon), (c + h) * np.cos(lat) * np.sin(lon),
                     (s + h) * np.sin(lat)], -1)


@dataclass(frozen=True)
class StationTrack:
    """Stations in GCRF at the reception times: ``r`` (m), ``v`` (m/s), ``a`` (m/s²) of shape
    (N, 3) or (S, N, 3), and ``gcrf_to_itrf`` (N, 3, 3), the rotation at those times."""

    r: np.ndarray
    v: np.ndarray
    a: np.ndarray
    gcrf_to_itrf: np.ndarray


def _eop_at(mjd_utc, eop_columns):
    """UT1-UTC (s), xp, yp (rad) at UTC MJDs, linear between the table's daily rows.

    ``eop_columns``: ``(mjd, ut1_minus_utc_s, xp_arcsec, yp_arcsec)`` as IERS tabulates them, or
    None (all zero). UT1-UTC is interpolated as it is tabulated, so the table must not straddle a
    leap second (checked)."""
    mjd_utc = np.asarray(mjd_utc, float)
    if eop_columns is None:
        z = np.zeros(mjd_utc.shape)
        return z, z, z
    mjd, dut1, xp, yp = (np.asarray(c, float) for c in eop_columns)
    if np.any(np.abs(np.diff(dut1)) > 0.5):
        raise ValueError("the oracle's EOP table straddles a leap second")
    return (np.interp(mjd_utc, mjd, dut1), np.interp(mjd_utc, mjd, xp) * ARCSEC,
            np.interp(mjd_utc, mjd, yp) * ARCSEC)


def celestial_to_terrestrial(jd1, jd2, eop_columns=None) -> np.ndarray:
    """The GCRS -> ITRS matrix (N, 3, 3) at UTC two-part JDs: ``erfa.c2t06a`` (IAU 2006/2000A,
    CIO based, with polar motion and the TIO locator s') at TT and UT1 from ERFA's own UTC ->
    TAI -> TT and UTC -> UT1."""
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    dut1, xp, yp = _eop_at((jd1 - 2400000.5) + jd2, eop_columns)
    tt1, tt2 = erfa.taitt(*erfa.utctai(jd1, jd2))
    ut1, ut2 = erfa.utcut1(jd1, jd2, dut1)
    return np.asarray(erfa.c2t06a(tt1, tt2, ut1, ut2, xp, yp))


def station_gcrf(lat_rad, lon_rad, height_m, jd1, jd2, eop_columns=None) -> StationTrack:
    """Stations given by WGS-84 geodetic coordinates (scalars, or (S,) arrays) in GCRF at UTC
    dates ``jd1 + jd2`` (N,): position ``M(t)ᵀ r_ecef``, and its first and second time derivatives
    (per SI second; no leap second within 3 :data:`DIFF_STEP_S`) by the seven-point central
    differences ``(p₃ - 9p₂ + 45p₁ - 45p₋₁ + 9p₋₂ - p₋₃) / 60h`` and
    ``(2p₃ - 27p₂ + 270p₁ - 490p₀ + 270p₋₁ - 27p₋₂ + 2p₋₃) / 180h²`` (Fornberg 1988, Table 1)."""
    r_ecef = geodetic_to_ecef(lat_rad, lon_rad, height_m)
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    h = DIFF_STEP_S

    def position(k):
        m = celestial_to_terrestrial(jd1, jd2 + k * h / 86400.0, eop_columns)   # (N, 3, 3)
        return np.einsum("nji,...j->...ni", m, r_ecef), m                        # Mᵀ r: (N, 3) or (S, N, 3)

    p = {k: position(k)[0] for k in (-3, -2, -1, 1, 2, 3)}
    p0, m0 = position(0)
    v = (p[3] - 9.0 * p[2] + 45.0 * p[1] - 45.0 * p[-1] + 9.0 * p[-2] - p[-3]) / (60.0 * h)
    a = (2.0 * (p[3] + p[-3]) - 27.0 * (p[2] + p[-2]) + 270.0 * (p[1] + p[-1]) - 490.0 * p0) / (180.0 * h * h)
    return StationTrack(r=p0, v=v, a=a, gcrf_to_itrf=m0)


# --------------------------------------------------------------------------- light time

@dataclass(frozen=True)
class Leg:
    """One light-time leg between a station and the satellite (arrays along the samples).

    ``rho_m`` the range, ``tau_s`` the light time, ``u`` the unit vector from the station to
    the satellite, ``r_sat``/``v_sat`` the satellite at its end of the leg, ``r_st``/``v_st``
    the station at its end.
    """

    rho_m: np.ndarray
    tau_s: np.ndarray
    u: np.ndarray
    r_sat: np.ndarray
    v_sat: np.ndarray
    r_st: np.ndarray
    v_st: np.ndarray


def _taylor_back(r, v, a, j, tau):
    """Satellite state ``τ`` seconds before the expansion point (Taylor to the jerk term)."""
    t = np.asarray(tau, float)[..., None]
    return r - v * t + a * (t * t / 2) - j * (t * t * t / 6), v - a * t + j * (t * t / 2)


def light_time_down(r_sat, v_sat, a_sat, j_sat, r_st, v_st, *, c: float = C_LIGHT,
                    tol_s: float = LIGHT_TIME_TOL_S, max_iter: int = 10) -> Leg:
    """Down leg: the signal received at ``r_st`` at ``t_r`` left the satellite at ``t_e``.

    ``r_sat, v_sat, a_sat, j_sat``: satellite position, velocity, acceleration, jerk at
    ``t_r`` (GCRF; shape (..., 3)); ``r_st, v_st``: station at ``t_r``. Solves eq. (1) of the
    module docstring by Newton's method; raises ``ArithmeticError`` if it does not converge.
    """
    r_sat, v_sat, a_sat, j_sat, r_st = (np.asarray(x, float) for x in (r_sat, v_sat, a_sat, j_sat, r_st))
    tau = np.zeros(np.broadcast_shapes(r_sat.shape, r_st.shape)[:-1])
    for _ in range(max_iter):
        r_e, v_e = _taylor_back(r_sat, v_sat, a_sat, j_sat, tau)
        d = r_e - r_st
        rho = np.linalg.norm(d, axis=-1)
        u = d / rho[..., None]
        g = c * tau - rho
        step = g / (c + np.einsum("...i,...i->...", u, v_e))
        tau = tau - step
        if np.all(np.abs(step) < tol_s):
            break
    else:
        raise ArithmeticError("light-time iteration did not converge")
    r_e, v_e = _taylor_back(r_sat, v_sat, a_sat, j_sat, tau)
    d = r_e - r_st
    rho = np.linalg.norm(d, axis=-1)
    return Leg(rho_m=rho, tau_s=tau, u=d / rho[..., None], r_sat=r_e, v_sat=v_e,
               r_st=np.broadcast_to(r_st, d.shape), v_st=np.broadcast_to(np.asarray(v_st, float), d.shape))


def light_time_up(down: Leg, a_st, *, c: float = C_LIGHT, tol_s: float = LIGHT_TIME_TOL_S,
                  max_iter: int = 10) -> Leg:
    """Up leg of a two-way measurement: the signal that reached the satellite at the bounce
    time ``t_b`` (the emission time of ``down``) left the station at ``t_t = t_b - ρ_u/c``.

    The station is moved back from ``t_r`` by ``T = τ_d + τ_u`` with its velocity and
    (centripetal) acceleration ``a_st``; the neglected jerk term is below 1e-8 m even for
    GEO round trips.
    """
    a_st = np.asarray(a_st, float)
    r_b, r0, v0 = down.r_sat, down.r_st, down.v_st
    tau = down.tau_s.copy()
    for _ in range(max_iter):
        big_t = (down.tau_s + tau)[..., None]
        r_t = r0 - v0 * big_t + a_st * (big_t * big_t / 2)
        v_t = v0 - a_st * big_t
        d = r_b - r_t
        rho = np.linalg.norm(d, axis=-1)
        u = d / rho[..., None]
        step = (c * tau - rho) / (c - np.einsum("...i,...i->...", u, v_t))
        tau = tau - step
        if np.all(np.abs(step) < tol_s):
            break
    else:
        raise ArithmeticError("two-way up-leg light-time iteration did not converge")
    big_t = (down.tau_s + tau)[..., None]
    r_t = r0 - v0 * big_t + a_st * (big_t * big_t / 2)
    v_t = v0 - a_st * big_t
    d = r_b - r_t
    rho = np.linalg.norm(d, axis=-1)
    return Leg(rho_m=rho, tau_s=tau, u=d / rho[..., None], r_sat=r_b, v_sat=down.v_sat, r_st=r_t, v_st=v_t)


# --------------------------------------------------------------------------- observables

def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def range_rate_down(leg: Leg, model: str = "doppler", c: float = C_LIGHT) -> np.ndarray:
    """One-way range-rate (m/s, positive receding) of a down leg: eq. (2) or (3)."""
    _check_model(model)
    rr = _dot(leg.u, leg.v_sat - leg.v_st)
    if model == "doppler":
        rr = rr / (1.0 + _dot(leg.u, leg.v_sat) / c)
    return rr


def range_rate_up(up: Leg, rr_down: np.ndarray, model: str = "doppler", c: float = C_LIGHT) -> np.ndarray:
    """Up-leg rate dρ_u/dt_r (m/s): eq. (5), or ``û_u·(v_sat - v_st)`` when instantaneous."""
    _check_model(model)
    rr = _dot(up.u, up.v_sat - up.v_st)
    if model == "doppler":
        rr = rr * (1.0 - rr_down / c) / (1.0 - _dot(up.u, up.v_st) / c)
    return rr


def _check_model(model: str) -> None:
    if model not in RANGE_RATE_MODELS:
        raise ValueError(f"unknown range-rate model {model!r}; expected one of {RANGE_RATE_MODELS}")


def doppler_hz(range_rate_m_s, carrier_hz: float, mode: str = "one-way", offset_hz: float = 0.0,
               drift_hz_s: float = 0.0, t_s=0.0, c: float = C_LIGHT) -> np.ndarray:
    """Doppler shift, received minus nominal (Hz): ``-k f ρ̇ / c + offset + drift · t_s``.

    ``k = 1`` one-way, ``2`` two-way (``range_rate_m_s`` is then the two-way mean rate).
    ``t_s`` is the time (s) since the epoch of the frequency drift.
    """
    k = {"one-way": 1.0, "two-way": 2.0}[mode]
    return -k * carrier_hz * np.asarray(range_rate_m_s, float) / c + offset_hz + drift_hz_s * np.asarray(t_s, float)


def range_rate_from_doppler(doppler_hz_, carrier_hz: float, mode: str = "one-way", c: float = C_LIGHT) -> np.ndarray:
    """Inverse of :func:`doppler_hz` without offset or drift: ``ρ̇ = -c Δf / (k f)``."""
    k = {"one-way": 1.0, "two-way": 2.0}[mode]
    return -c * np.asarray(doppler_hz_, float) / (k * carrier_hz)


def azel(direction_gcrf, gcrf_to_itrf_matrix, lat_rad, lon_rad):
    """Azimuth (rad, from north through east, [0, 2π)) and elevation (rad) of a GCRF direction.

    ``direction_gcrf`` (..., 3): e.g. ``r_sat(t_e) - r_st(t_r)``; ``gcrf_to_itrf_matrix``
    (..., 3, 3) the rotation at ``t_r``. The ITRF direction is turned into the station's
    south-east-zenith frame, ``ρ_SEZ = ROT2(90° - φ) ROT3(λ) ρ_ECEF``, and
    ``el = asin(ρ_Z / ρ)``, ``az = atan2(ρ_E, -ρ_S)``: Vallado (4th ed., 2013), algorithm 27 (RAZEL).
    """
    d = np.einsum("...ij,...j->...i", gcrf_to_itrf_matrix, direction_gcrf)
    lat, lon = np.asarray(lat_rad, float), np.asarray(lon_rad, float)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    # ROT3(λ): into the frame whose x axis is in the station's meridian
    x1 = np.cos(lon) * x + np.sin(lon) * y
    y1 = -np.sin(lon) * x + np.cos(lon) * y
    # ROT2(90° - φ): tilt that frame's z axis onto the local vertical (the ellipsoid's normal)
    colat = np.pi / 2 - lat
    south = np.cos(colat) * x1 - np.sin(colat) * z
    east = y1
    zenith = np.sin(colat) * x1 + np.cos(colat) * z
    rho = np.sqrt(south * south + east * east + zenith * zenith)
    return wrap_2pi(np.arctan2(east, -south)), np.arcsin(zenith / rho)


def wrap_2pi(angle_rad):
    """Angle in [0, 2π): ``np.mod`` can return exactly 2π for tiny negative input; map it to 0."""
    a = np.mod(np.asarray(angle_rad, float), 2 * np.pi)
    return np.where(a >= 2 * np.pi, 0.0, a)


@dataclass(frozen=True)
class Observables:
    """Modelled values at the reception times (arrays of one shape, SI units).

    ``range_m`` (one-way: ρ; two-way: round trip / 2), ``range_rate_m_s`` (by the chosen
    model; two-way: mean of both legs), ``doppler_hz`` (carrier-scaled, no offset),
    ``elevation_rad``, ``azimuth_rad``, ``light_time_s`` (one-way: down leg; two-way: round trip).
    """

    range_m: np.ndarray
    range_rate_m_s: np.ndarray
    doppler_hz: np.ndarray
    elevation_rad: np.ndarray
    azimuth_rad: np.ndarray
    light_time_s: np.ndarray


def observables(r_sat, v_sat, a_sat, j_sat, r_st, v_st, a_st, gcrf_to_itrf_matrix, lat_rad, lon_rad, *,
                carrier_hz: float, mode: str = "one-way", range_rate_model: str = "doppler",
                c: float = C_LIGHT) -> Observables:
    """All observables of one station at the reception times (README one-way model).

    Satellite state (position, velocity, acceleration, jerk) and station state (position,
    velocity, acceleration) are GCRF at ``t_r`` with matching shapes (..., 3);
    ``gcrf_to_itrf_matrix`` (..., 3, 3) at ``t_r``. See the module docstring for equations.
    """
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; expected one of {MODES}")
    down = light_time_down(r_sat, v_sat, a_sat, j_sat, r_st, v_st, c=c)
    rr = range_rate_down(down, range_rate_model, c)
    rng, lt = down.rho_m, down.tau_s
    if mode == "two-way":
        up = light_time_up(down, a_st, c=c)
        rr_up = range_rate_up(up, rr, range_rate_model, c)
        rng = 0.5 * (down.rho_m + up.rho_m)
        rr = 0.5 * (rr + rr_up)
        lt = down.tau_s + up.tau_s
    az, el = azel(down.r_sat - down.r_st, gcrf_to_itrf_matrix, lat_rad, lon_rad)
    return Observables(range_m=rng, range_rate_m_s=rr, doppler_hz=doppler_hz(rr, carrier_hz, mode, c=c),
                       elevation_rad=el, azimuth_rad=az, light_time_s=lt)
