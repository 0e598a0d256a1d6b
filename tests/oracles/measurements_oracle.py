"""TEST ORACLE (not shipped): an independent implementation of the measurement physics.

This is the simulator's original, self-contained code (light time by Taylor expansion of the
satellite about the reception time, its own Newton iterations, its own range-rate, Doppler and
az/el formulas), kept when the production code was unified into
``trackproc.models.light_time`` and ``trackproc.models.observables``. The tests compare the
simulator (``trackproc.models.measurements``) and the estimator
(``trackproc.models.observation``) against it; do not make it import those modules.

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

import numpy as np

from trackproc.constants import C_LIGHT

#: Convergence threshold of the light-time iteration, s.
LIGHT_TIME_TOL_S = 1e-12
RANGE_RATE_MODELS = ("doppler", "instantaneous")
MODES = ("one-way", "two-way")


# --------------------------------------------------------------------------- stations

@dataclass(frozen=True)
class StationTrack:
    """Stations in GCRF at the reception times: ``r`` (m), ``v`` (m/s), ``a`` (m/s²) of shape
    (N, 3) or (S, N, 3), and ``gcrf_to_itrf`` (N, 3, 3), the rotation at those times."""

    r: np.ndarray
    v: np.ndarray
    a: np.ndarray
    gcrf_to_itrf: np.ndarray


def station_gcrf(r_itrf, jd1, jd2, eop=None) -> StationTrack:
    """Station position, velocity and acceleration in GCRF at UTC dates.

    Parameters
    ----------
    r_itrf : (3,) or (S, 3) ITRF positions (m) of S stations fixed on the Earth.
    jd1, jd2 : (N,) UTC two-part Julian dates (reception times).
    eop : :class:`~trackproc.dynamics.timescales.EarthOrientation` or None.

    Position and velocity are the exact IAU 2006/2000A transform
    (:func:`~trackproc.dynamics.frames.itrf_to_gcrf`, one Earth-orientation evaluation shared
    by all stations); the acceleration is the centripetal ``ω × v`` about the rotation axis
    (used only to move the station over a round-trip light time). Repeated dates (a range
    and a range-rate sample share their reception time) are evaluated once: the Earth
    orientation (``erfa.c2i06a`` per date) is the cost here.
    """
    from trackproc.dynamics import frames

    r_itrf = np.asarray(r_itrf, float)
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    jd1, jd2 = jd1.reshape(-1), jd2.reshape(-1)
    n = jd1.size
    inverse = None
    if n > 1:
        dates, inverse = np.unique(np.stack([jd1, jd2], -1), axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        if dates.shape[0] == n:
            inverse = None
        else:
            jd1, jd2 = dates[:, 0], dates[:, 1]
    m = jd1.size
    shape = (m, 3) if r_itrf.ndim == 1 else (r_itrf.shape[0], m, 3)
    r_src = np.broadcast_to(r_itrf if r_itrf.ndim == 1 else r_itrf[:, None, :], shape)
    rot = frames.earth_rotation(jd1, jd2, eop)
    r, v = frames.itrf_to_gcrf(r_src, np.zeros(shape), jd1, jd2, eop, rotation=rot)
    matrix = rot.matrix
    mid = n // 2 if inverse is None else inverse[n // 2]
    axis = rot.q[mid][2]  # the CIP (rotation axis) in GCRF, mid-span
    if inverse is not None:
        r, v, matrix = r[..., inverse, :], v[..., inverse, :], matrix[inverse]
    a = np.cross(frames.OMEGA_ERA * axis, v)
    return StationTrack(r=r, v=v, a=a, gcrf_to_itrf=matrix)


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
    (..., 3, 3) the rotation at ``t_r``; the station's geodetic latitude/longitude define the
    local east-north-up frame (:func:`~trackproc.dynamics.geodesy.enu_matrix`).
    """
    from trackproc.dynamics import geodesy

    d_itrf = np.einsum("...ij,...j->...i", gcrf_to_itrf_matrix, direction_gcrf)
    enu = np.einsum("...ij,...j->...i", geodesy.enu_matrix(lat_rad, lon_rad), d_itrf)
    az, el, _ = geodesy.enu_to_azel(enu)
    return wrap_2pi(az), el


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
