"""The observables of ground-station tracking, written once, with their partial derivatives.

Range, range-rate (both range-rate models, one- and two-way), Doppler and azimuth/elevation as
functions of the light-time geometry (:mod:`trackproc.models.light_time`), used by the simulator
(:mod:`trackproc.models.measurements`), the estimator (:mod:`trackproc.models.observation`), the
pass predictor and, for its conventions, the image-domain model
(:mod:`trackproc.dynamics.measurement_spectra`). All vectors in GCRF (m, m/s, s); ``t_r`` is the
reception time, ``t_e`` the emission (for two-way: bounce) time, ``û`` the unit vector from
``r_st(t_r)`` to ``r(t_e)``, ``ρ`` the light-time range.

    range              ρ                                                             (1)
    range-rate         doppler:       ρ̇ = û·(v(t_e) - v_st(t_r)) / (1 + û·v(t_e)/c)   (2)
                       instantaneous: ρ̇ = û·(v(t_e) - v_st(t_r))                       (3)
    Doppler            Δf = -k f ρ̇ / c  (+ offset + drift t),  k = 1 one-way, 2 two-way (4)
    azimuth/elevation  of r(t_e) - r_st(t_r) in the station's east-north-up frame    (5)

Seed 002 eq. 17 writes (1) and (2) without light time and without station velocity, and
seed 004 eqs. 11-12 the same range and its rate as spectra; (2) is the exact derivative of the
light-time range with respect to ``t_r``, (3) is Orekit's one-way ``RangeRate``. Positive
range-rate means the satellite recedes; Doppler is received minus nominal carrier (seed 004
item 1 gives ``Vr = c/(2 f0) f_D`` for two-way; one-way uses ``c/f0``).

Partials at fixed ``t_e`` (with ``P = I - ûûᵀ``, ``d = 1 + û·v_e/c``):

    ∂ρ/∂r_e = ûᵀ
    ∂ρ̇/∂r_e = (v_e - v_st)ᵀ P / (ρ d) - ρ̇ v_eᵀ P / (ρ c d),   ∂ρ̇/∂v_e = ûᵀ (1 - ρ̇/c) / d
    ∂(az, el)/∂r_e = ∂(az, el)/∂enu · E · M      (E: ITRF -> ENU, M: GCRF -> ITRF at t_r)

(instantaneous: ``d = 1`` and the ``ρ̇/c`` terms dropped). Two-way (round trip, turnaround
ratio 1; the up leg from ``R(T)``, ``V(T)`` of :func:`~trackproc.models.light_time.solve_up_leg`):

    range              (ρ_d + ρ_u)/2                                                 (6)
    range-rate         (ρ̇_d + ρ̇_u)/2,  doppler: ρ̇_u = (1 - ρ̇_d/c) û_u·(v_b - V) / (1 - û_u·V/c)  (7)
                                       instantaneous: ρ̇_u = û_u·(v_b - V)

(``ρ̇_u`` is dρ_u/dt_r: the up leg's ends move with ``dt_b/dt_r = 1 - ρ̇_d/c`` and
``dt_t/dt_r = dt_b/dt_r - ρ̇_u/c``). The partials of (6)-(7) are derived in
:mod:`trackproc.models.observation` (its eqs. 11-13). Every partial is checked against central
finite differences in ``tests/models/test_observation.py`` and ``tests/cli/test_two_way.py``, and every
value against the independent implementation in ``tests/oracles/measurements_oracle.py``.

Aberration is neglected (the station's inertial velocity, ≤ 465 m/s, shifts the apparent
direction by at most 1.6e-6 rad, far below angle noise), and so is refraction.
"""

from __future__ import annotations

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import geodesy
from trackproc.dynamics.geodesy import wrap_2pi  # noqa: F401  (re-exported)
from trackproc.vocabulary import check_mode, check_range_rate_model  # noqa: F401  (re-exported)

__all__ = ["check_range_rate_model", "check_mode", "range_partials", "range_rate_value", "range_rate_partials",
           "two_way_range_partials", "up_rate_partials", "two_way_range_rate_partials", "doppler_factor",
           "doppler_hz", "range_rate_per_hz", "range_rate_from_doppler", "azel", "azel_value", "azel_partials", "wrap_2pi", "wrap_pi"]


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


# ----------------------------------------------------------------------------- angles

def wrap_pi(angle_rad):
    """Angle in [-π, π) (residuals of azimuth)."""
    return np.mod(np.asarray(angle_rad, float) + np.pi, 2.0 * np.pi) - np.pi


# ----------------------------------------------------------------------------- range, range-rate

def range_partials(r_e, r_st):
    """Range ``ρ`` (m), unit vector ``û`` and ``∂ρ/∂r_e = û`` (fixed ``t_e``), eq. (1); shapes (...,), (..., 3).

    Implements seed 002 eq. 17 (range, with the light-time emission point) and, pointwise, seed 004
    eqs. 11-12 (D = √(ρ·ρ))."""
    d = np.asarray(r_e, float) - np.asarray(r_st, float)
    rho = np.linalg.norm(d, axis=-1)
    u = d / rho[..., None]
    return rho, u, u


def range_rate_value(r_e, v_e, r_st, v_st, model: str = "doppler", c: float = C_LIGHT):
    """One-way range-rate (m/s, positive receding): eq. (2) ``doppler`` or (3) ``instantaneous``.

    Implements seed 002 eq. 17 (range-rate) and seed 004 eq. 12 (the derivative of the range),
    with light time and station motion."""
    check_range_rate_model(model)
    d = np.asarray(r_e, float) - np.asarray(r_st, float)
    u = d / np.linalg.norm(d, axis=-1)[..., None]
    rr = _dot(u, np.asarray(v_e, float) - np.asarray(v_st, float))
    if model == "doppler":
        rr = rr / (1.0 + _dot(u, v_e) / c)
    return rr


def range_rate_partials(r_e, v_e, r_st, v_st, model: str = "doppler", c: float = C_LIGHT, *, rho=None, u=None):
    """Range-rate (eq. 2 or 3) and its partials ``∂ρ̇/∂r_e`` and ``∂ρ̇/∂v_e`` at fixed ``t_e``
    (module docstring). Implements seed 002 eq. 17 (range-rate) with its partials and, pointwise,
    seed 004 eqs. 11-12 (Vr = dD/dt).

    ``rho`` (...,) and ``u`` (..., 3): the range and unit vector of ``r_e - r_st`` when the caller
    has them by the same operations (the light time's), not computed again.
    Returns ``(rr, d_rr_d_r (..., 3), d_rr_d_v (..., 3))``.
    """
    check_range_rate_model(model)
    r_e, v_e, r_st, v_st = (np.asarray(x, float) for x in (r_e, v_e, r_st, v_st))
    if rho is None or u is None:
        d = r_e - r_st
        rho = np.sqrt(np.add.reduce(d * d, axis=-1))[..., None]   # np.linalg.norm(d, axis=-1), its operations
        u = d / rho
    else:
        rho = np.asarray(rho, float)[..., None]
    dv = v_e - v_st
    num = _dot(u, dv)[..., None]
    # P w = w - u (u·w): derivative of û along r_e, times rho
    proj_dv = dv - u * num
    if model == "instantaneous":
        return num[..., 0], proj_dv / rho, u.copy()
    uv = _dot(u, v_e)[..., None]
    den = 1.0 + uv / c
    rr = num / den
    proj_v = v_e - u * uv
    d_r = (proj_dv - rr * proj_v / c) / (rho * den)
    d_v = u * (1.0 - rr / c) / den
    return rr[..., 0], d_r, d_v


def two_way_range_partials(rho_down, u_down, rho_up, u_up, v_st_t):
    """Two-way range ``(ρ_d + ρ_u)/2`` (eq. 6), ``∂/∂r_b = (û_d + û_u)/2`` and ``∂/∂T = û_u·V/2``
    (the station recedes along ``-V`` as ``T`` grows). Returns ``(range, d_r (..., 3), d_t (...,))``."""
    u_down, u_up = np.asarray(u_down, float), np.asarray(u_up, float)
    return (0.5 * (np.asarray(rho_down, float) + np.asarray(rho_up, float)), 0.5 * (u_down + u_up),
            0.5 * _dot(u_up, v_st_t))


def up_rate_partials(r_b, v_b, r_st_t, v_st_t, a_st, rr_down, model: str = "doppler", c: float = C_LIGHT):
    """Up-leg rate ``ρ̇_u`` (eq. 7) and its partials (:mod:`trackproc.models.observation` eq. 13).

    ``r_b, v_b`` the bounce state, ``r_st_t, v_st_t`` the station ``R, V`` at ``t_t``, ``a_st``
    its acceleration, ``rr_down`` the down leg's rate ``ρ̇_d``. Returns ``(rr_u, d_r, d_v,
    d_rr_down (...,), d_t (...,))``: ``∂ρ̇_u/∂r_b``, ``∂ρ̇_u/∂v_b`` (..., 3) at fixed ``T`` and
    ``ρ̇_d``, ``∂ρ̇_u/∂ρ̇_d`` and ``∂ρ̇_u/∂T`` at fixed bounce state.
    """
    check_range_rate_model(model)
    r_b, v_b, big_r, big_v, a_st = (np.asarray(x, float) for x in (r_b, v_b, r_st_t, v_st_t, a_st))
    d = r_b - big_r
    rho = np.linalg.norm(d, axis=-1)[..., None]
    u = d / rho
    dv = v_b - big_v
    w = _dot(u, dv)
    if model == "instantaneous":
        rr, q, d_v, d_big_v, d_rrd = w, dv, u.copy(), -u, np.zeros_like(w)
    else:
        e = _dot(u, big_v)
        k = ((1.0 - np.asarray(rr_down, float) / c) / (1.0 - e / c))[..., None]
        rr = k[..., 0] * w
        s = (rr / (c - e))[..., None]               # ∂ρ̇_u/∂e
        q = k * dv + s * big_v
        d_v = k * u
        d_big_v = (s - k) * u
        d_rrd = -w / (c - e)
    d_r = (q - u * _dot(u, q)[..., None]) / rho     # P_u q / ρ_u
    d_t = _dot(d_r, big_v) - _dot(d_big_v, a_st)    # ∂R/∂T = -V, ∂R enters as -∂r_b; ∂V/∂T = -a_st
    return rr, d_r, d_v, d_rrd, d_t


def two_way_range_rate_partials(r_b, v_b, r_st, v_st, r_st_t, v_st_t, a_st, model: str = "doppler",
                                c: float = C_LIGHT):
    """Two-way range-rate ``(ρ̇_d + ρ̇_u)/2`` (eq. 7) with ``∂/∂r_b``, ``∂/∂v_b`` (..., 3) at fixed
    ``T`` and ``∂/∂T`` (...,) at fixed bounce state (:mod:`trackproc.models.observation`, after eq. 13).

    ``r_st, v_st`` the station at ``t_r`` (down leg), ``r_st_t, v_st_t`` at ``t_t`` (up leg),
    ``a_st`` its acceleration. Returns ``(rr, d_r, d_v, d_t)``.
    """
    rr_d, dd_r, dd_v = range_rate_partials(r_b, v_b, r_st, v_st, model, c)
    rr_u, du_r, du_v, du_dd, du_t = up_rate_partials(r_b, v_b, r_st_t, v_st_t, a_st, rr_d, model, c)
    chain = (1.0 + du_dd)[..., None]                # ρ̇_d enters directly and through ρ̇_u
    return 0.5 * (rr_d + rr_u), 0.5 * (dd_r * chain + du_r), 0.5 * (dd_v * chain + du_v), 0.5 * du_t


# ----------------------------------------------------------------------------- Doppler

def doppler_factor(mode: str = "one-way") -> float:
    """``k`` of eq. (4): 1 one-way, 2 two-way (the round trip doubles the shift).

    Implements seed 004 item 1 (``c/(2 f0)`` two-way, ``c/f0`` one-way).
    """
    return {"one-way": 1.0, "two-way": 2.0}[mode]


def doppler_hz(range_rate_m_s, carrier_hz: float, mode: str = "one-way", offset_hz: float = 0.0,
               drift_hz_s: float = 0.0, t_s=0.0, c: float = C_LIGHT) -> np.ndarray:
    """Doppler shift, received minus nominal (Hz), eq. (4): ``-k f ρ̇ / c + offset + drift · t_s``.

    Implements seed 004 item 1 (``Vr = c/(2 f0) f_D`` two-way; ``c/f0`` one-way).
    ``range_rate_m_s`` is the two-way mean rate when ``mode`` is two-way; ``t_s`` is the time
    (s) since the epoch of the frequency drift.
    """
    k = doppler_factor(mode)
    return -k * carrier_hz * np.asarray(range_rate_m_s, float) / c + offset_hz + drift_hz_s * np.asarray(t_s, float)


def range_rate_per_hz(carrier_hz, two_way=False, c: float = C_LIGHT):
    """Range-rate per Hz of Doppler, ``-c / (k f)`` (m/s per Hz; ``k`` 2 where ``two_way``, else 1):
    eq. (4) inverted, the one conversion between Doppler and range-rate. ``carrier_hz`` and
    ``two_way`` (bool) are scalars or arrays of one shape; a float for scalars.

    Implements seed 004 item 1 (``Vr = c/(2 f0) f_D`` two-way; ``c/f0`` one-way).
    """
    k = np.where(two_way, 2.0, 1.0) if np.ndim(two_way) else (2.0 if two_way else 1.0)
    out = -c / (k * np.asarray(carrier_hz, float))
    return out if np.ndim(out) else float(out)


def range_rate_from_doppler(doppler_hz_, carrier_hz: float, mode: str = "one-way", c: float = C_LIGHT) -> np.ndarray:
    """Inverse of :func:`doppler_hz` without offset or drift: ``ρ̇ = -c Δf / (k f)`` (seed 004 item 1)."""
    return np.asarray(doppler_hz_, float) * range_rate_per_hz(carrier_hz, doppler_factor(mode) == 2.0, c)


# ----------------------------------------------------------------------------- azimuth, elevation

def azel(direction_gcrf, gcrf_to_itrf_matrix, lat_rad, lon_rad):
    """Azimuth (rad, from north through east, [0, 2π)) and elevation (rad) of a GCRF direction,
    eq. (5), from the station's geodetic latitude/longitude.

    ``direction_gcrf`` (..., 3): e.g. ``r_sat(t_e) - r_st(t_r)``; ``gcrf_to_itrf_matrix``
    (..., 3, 3) the rotation at ``t_r``; the east-north-up frame is
    :func:`~trackproc.dynamics.geodesy.enu_matrix`.
    """
    d_itrf = np.einsum("...ij,...j->...i", gcrf_to_itrf_matrix, direction_gcrf)
    enu = np.einsum("...ij,...j->...i", geodesy.enu_matrix(lat_rad, lon_rad), d_itrf)
    az, el, _ = geodesy.enu_to_azel(enu)
    return az, el


def azel_value(direction_gcrf, gcrf_to_enu):
    """Azimuth (rad, [0, 2π), from north through east) and elevation (rad) of a GCRF direction,
    eq. (5); ``gcrf_to_enu`` (..., 3, 3) = E · M, the rotation to the station's east-north-up frame."""
    enu = np.einsum("...ij,...j->...i", gcrf_to_enu, direction_gcrf)
    az, el, _ = geodesy.enu_to_azel(enu)
    return az, el


def azel_partials(direction_gcrf, gcrf_to_enu):
    """Azimuth, elevation (eq. 5) and their gradients with respect to the GCRF direction vector.

    ``∂az/∂enu = (n, -e, 0)/h²``, ``∂el/∂enu = (-e u, -n u, h²)/(h ρ²)``, h = √(e² + n²), then
    times ``gcrf_to_enu``. Returns ``(az, el, d_az (..., 3), d_el (..., 3))``.
    """
    m = np.asarray(gcrf_to_enu, float)
    enu = np.einsum("...ij,...j->...i", m, direction_gcrf)
    e, n, up = enu[..., 0], enu[..., 1], enu[..., 2]
    h2 = e * e + n * n
    h = np.sqrt(h2)
    rho2 = h2 + up * up
    g_az = np.stack([n / h2, -e / h2, np.zeros_like(e)], -1)
    g_el = np.stack([-e * up / (h * rho2), -n * up / (h * rho2), h / rho2], -1)
    az, el = azel_value(direction_gcrf, m)
    return az, el, np.einsum("...i,...ij->...j", g_az, m), np.einsum("...i,...ij->...j", g_el, m)
