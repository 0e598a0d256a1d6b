"""Atmospheric drag on a cannon-ball spacecraft: Harris-Priester density (default), NRLMSIS optional.

``a = -½ ρ Cd (A/m) |v_r| v_r`` with ``v_r = v - ω⊕ × r`` the velocity relative to an
atmosphere co-rotating with the Earth (Montenbruck & Gill 2000 eq. 3.97).

Harris-Priester (M&G section 3.5.2, Table 3.8, mean solar activity; the same table and the
same 30° bulge lag as Orekit's ``HarrisPriester``): between tabulated heights ``h_i`` the
minimum (antapex) and maximum (apex) densities are interpolated exponentially, and
``ρ = ρ_min + (ρ_max - ρ_min) cos^n(ψ/2)`` with ψ the angle between the satellite and the
apex of the diurnal bulge (the Sun direction turned 30° east about the Earth's axis); zero
above 1000 km, and the density at 100 km held below it. NRLMSIS 2.1 (Emmert et al. 2022, the
current release of the NRLMSIS 2.0 line of Emmert et al. 2021) through ``pymsis`` when installed,
with fixed F10.7, 81-day F10.7 and daily Ap (no space-weather file).
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics.geodesy import itrf_to_geodetic

__all__ = ["harris_priester", "acceleration", "nrlmsis_density", "HP_TABLE", "NRLMSIS_VERSION"]

#: Height (km), minimum and maximum density (g/km³ = 1e-12 kg/m³): M&G 2000 Table 3.8.
HP_TABLE = np.array([
    (100, 497400.0, 497400.0), (120, 24900.0, 24900.0), (130, 8377.0, 8710.0), (140, 3899.0, 4059.0),
    (150, 2122.0, 2215.0), (160, 1263.0, 1344.0), (170, 800.8, 875.8), (180, 528.3, 601.0),
    (190, 361.7, 429.7), (200, 255.7, 316.2), (210, 183.9, 239.6), (220, 134.1, 185.3),
    (230, 99.49, 145.5), (240, 74.88, 115.7), (250, 57.09, 93.08), (260, 44.03, 75.55),
    (270, 34.30, 61.82), (280, 26.97, 50.95), (290, 21.39, 42.26), (300, 17.08, 35.26),
    (320, 10.99, 25.11), (340, 7.214, 18.19), (360, 4.824, 13.37), (380, 3.274, 9.955),
    (400, 2.249, 7.492), (420, 1.558, 5.684), (440, 1.091, 4.355), (460, 0.7701, 3.362),
    (480, 0.5474, 2.612), (500, 0.3916, 2.042), (520, 0.2819, 1.605), (540, 0.2042, 1.267),
    (560, 0.1488, 1.005), (580, 0.1092, 0.7997), (600, 0.08070, 0.6390), (620, 0.06012, 0.5123),
    (640, 0.04519, 0.4121), (660, 0.03430, 0.3325), (680, 0.02632, 0.2691), (700, 0.02043, 0.2185),
    (720, 0.01607, 0.1779), (740, 0.01281, 0.1452), (760, 0.01036, 0.1190), (780, 0.008496, 0.09776),
    (800, 0.007069, 0.08059), (840, 0.004680, 0.05741), (880, 0.003200, 0.04210), (920, 0.002210, 0.03130),
    (960, 0.001560, 0.02360), (1000, 0.001150, 0.01810)])
_H_M = HP_TABLE[:, 0] * 1e3
_LOG_MIN = np.log(HP_TABLE[:, 1] * 1e-12)
_LOG_MAX = np.log(HP_TABLE[:, 2] * 1e-12)
#: Lag of the bulge apex behind the sub-solar point (M&G: 30° in right ascension).
LAG_RAD = np.radians(30.0)


def harris_priester(height_m, r_itrf, sun_itrf, n: float = 4.0) -> np.ndarray:
    """Density (kg/m³) at geodetic heights ``height_m`` (P,) and ITRF positions (P, 3).

    ``n`` the cosine exponent (M&G: 2 for low, 6 for polar inclinations; Orekit's default 4).
    Implements Montenbruck & Gill (2000) eqs. 3.99-3.104.
    """
    h = np.asarray(height_m, float)
    hc = np.clip(h, _H_M[0], _H_M[-1])
    rho_min = np.exp(np.interp(hc, _H_M, _LOG_MIN))
    rho_max = np.exp(np.interp(hc, _H_M, _LOG_MAX))
    s = np.asarray(sun_itrf, float)
    s = s / np.linalg.norm(s)
    c, sn = np.cos(LAG_RAD), np.sin(LAG_RAD)
    apex = np.array([c * s[0] - sn * s[1], sn * s[0] + c * s[1], s[2]])
    r = np.asarray(r_itrf, float)
    cos_psi = (r @ apex) / np.linalg.norm(r, axis=-1)
    cos2 = np.clip(0.5 * (1.0 + cos_psi), 0.0, 1.0)
    rho = rho_min + (rho_max - rho_min) * cos2 ** (n / 2.0)
    return np.where(h > _H_M[-1], 0.0, rho)


def acceleration(v_rel, rho, cd: float, area_over_mass: float) -> np.ndarray:
    """Drag acceleration (m/s²) from the air-relative velocity ``v_rel`` (P, 3) and density ``rho`` (P,)."""
    v_rel = np.asarray(v_rel, float)
    vn = np.linalg.norm(v_rel, axis=-1, keepdims=True)
    return -0.5 * np.asarray(rho)[:, None] * cd * area_over_mass * vn * v_rel


#: The NRLMSIS release asked of pymsis: named, not pymsis's default (which changed 2.0 -> 2.1 once).
NRLMSIS_VERSION = "2.1"


def nrlmsis_density(datetime_utc, r_itrf, height_m, f107: float, f107a: float, ap: float) -> np.ndarray:
    """Total mass density (kg/m³) of NRLMSIS 2.1 through ``pymsis`` (optional dependency), (P,).

    ``datetime_utc`` a UTC ``datetime64``; the geodetic (WGS-84) longitude and latitude from the ITRF
    positions ``r_itrf`` (P, 3), ``height_m`` (P,) their geodetic heights; ``f107`` the previous
    day's F10.7, ``f107a`` its 81-day mean, ``ap`` the daily Ap (pymsis's daily-Ap mode reads only
    the first of its seven ap values). NRLMSIS computes in single precision: the
    density scatters by ~1e-6 relative about a smooth curve (docs/propagate.md "NRLMSIS").
    Raises ``ImportError`` with the install hint when pymsis is absent.
    """
    try:
        import pymsis  # optional: the msis extra
    except ImportError:                                            # pragma: no cover - optional
        raise ImportError("--atmosphere nrlmsis needs the pymsis package (pip install pymsis)") from None
    lat, lon, _ = itrf_to_geodetic(np.atleast_2d(r_itrf))
    n = lat.size
    # equal lengths: pymsis's fly-through mode (one output row per point, no grid)
    out = pymsis.calculate(np.full(n, np.datetime64(datetime_utc, "ns")), np.degrees(lon), np.degrees(lat),
                           np.broadcast_to(np.asarray(height_m, float) / 1e3, (n,)), f107s=np.full(n, float(f107)),
                           f107as=np.full(n, float(f107a)), aps=np.full((n, 7), float(ap)), version=NRLMSIS_VERSION)
    return np.asarray(out[..., 0], float).reshape(n)
