"""Optical tropospheric delay of a range: Mendes–Pavlis zenith delay with the FCULa mapping.

The IERS Conventions (2010), Technical Note 36, section 9.2 (Mendes & Pavlis 2004, Mendes et
al. 2002): the one-way path delay of a laser range at elevation ``e`` is

    d = (d_h^z + d_nh^z) · m(e)                                                        (1)

with the zenith hydrostatic and non-hydrostatic delays (m; P, e_w in hPa, φ latitude, H height
in m, λ the wavelength in µm, σ = 1/λ)

    d_h^z  = 0.002416579 f_h(λ) P / f_s(φ, H)                                          (2)
    d_nh^z = 1e-4 (5.316 f_nh(λ) - 3.759 f_h(λ)) e_w / f_s(φ, H)                        (3)
    f_s    = 1 - 0.00266 cos 2φ - 0.00000028 H
    f_h    = 1e-2 (k1 (k0 + σ²)/(k0 - σ²)² + k3 (k2 + σ²)/(k2 - σ²)²) · C_CO2           (4)
    f_nh   = 0.003101 (ω0 + 3 ω1 σ² + 5 ω2 σ⁴ + 7 ω3 σ⁶)                                (5)

(C_CO2 = 1 + 0.534e-6 (x_c - 450), x_c = 375 ppm), the water-vapour pressure from the relative
humidity by Giacomo's (CIPM 1981/91) saturation formula

    e_w = RH/100 · f_w · 0.01 exp(1.2378847e-5 T² - 1.9121316e-2 T + 33.93711047 - 6.3431645e3 / T)
    f_w = 1.00062 + 3.14e-6 P + 5.6e-7 (T - 273.15)²                                   (6)

and the FCULa mapping function (a continued fraction of sin e, coefficients linear in the
temperature t °C, cos φ and H)

    m(e) = (1 + a1/(1 + a2/(1 + a3))) / (sin e + a1/(sin e + a2/(sin e + a3)))          (7)
    a_i = a_i0 + a_i1 t + a_i2 cos φ + a_i3 H

The model is for optical wavelengths (0.355–1.064 µm); a radio range needs another model
(its wet delay is not dispersive like this). The delay lengthens the measured range: it is
*added* to the modelled one-way-equivalent range (for a two-way range the mean of the up and
down legs, which at one elevation is ``d`` itself).

Checked against the IERS Conventions' McDonald test case (ZHD 1.932992 m, ZWD 2.23375 mm,
m(15°) = 3.80024367) in ``tests/models/test_troposphere.py``.
"""

from __future__ import annotations

import numpy as np

from trackproc.models import modifiers as md

#: Default laser wavelength (frequency-doubled Nd:YAG), µm.
DEFAULT_WAVELENGTH_UM = 0.532
#: Valid wavelength range of the model, µm.
WAVELENGTH_RANGE_UM = (0.355, 1.064)

_K0, _K1, _K2, _K3 = 238.0185, 19990.975, 57.362, 579.55174
_W0, _W1, _W2, _W3 = 295.235, 2.6422, -0.032380, 0.004028
_XC_PPM = 375.0

#: FCULa coefficients (IERS TN36 table 9.1): a_i = c0 + c1 t(°C) + c2 cos φ + c3 H(m).
_FCULA = np.array([
    [12100.8e-7, 1729.5e-9, 319.1e-7, -1847.8e-11],
    [30496.5e-7, 234.6e-8, -103.5e-6, -185.6e-10],
    [6877.7e-5, 197.2e-7, -345.8e-5, 106.0e-9],
])


def water_vapour_pressure_hpa(pressure_hpa, temperature_k, humidity_percent):
    """Water-vapour pressure (hPa) from relative humidity, eq. (6) (Giacomo 1982, as IERS TN36 9.2)."""
    p, t, rh = (np.asarray(x, float) for x in (pressure_hpa, temperature_k, humidity_percent))
    saturation = 0.01 * np.exp(1.2378847e-5 * t * t - 1.9121316e-2 * t + 33.93711047 - 6.3431645e3 / t)
    enhancement = 1.00062 + 3.14e-6 * p + 5.6e-7 * (t - 273.15) ** 2
    return rh / 100.0 * enhancement * saturation


def _dispersion(wavelength_um):
    sigma2 = 1.0 / np.asarray(wavelength_um, float) ** 2
    c_co2 = 1.0 + 0.534e-6 * (_XC_PPM - 450.0)
    f_h = 0.01 * (_K1 * (_K0 + sigma2) / (_K0 - sigma2) ** 2 + _K3 * (_K2 + sigma2) / (_K2 - sigma2) ** 2) * c_co2
    f_nh = 0.003101 * (_W0 + 3 * _W1 * sigma2 + 5 * _W2 * sigma2 ** 2 + 7 * _W3 * sigma2 ** 3)
    return f_h, f_nh


def zenith_delay_m(lat_rad, height_m, pressure_hpa, water_vapour_hpa, wavelength_um=DEFAULT_WAVELENGTH_UM):
    """Zenith hydrostatic and non-hydrostatic delays (m), eqs. (2)-(5).

    Implements IERS Conventions (2010) eqs. 9.11-9.13 (Mendes & Pavlis 2004).
    """
    f_h, f_nh = _dispersion(wavelength_um)
    f_s = 1.0 - 0.00266 * np.cos(2.0 * np.asarray(lat_rad, float)) - 0.00000028 * np.asarray(height_m, float)
    hydro = 0.002416579 * f_h * np.asarray(pressure_hpa, float) / f_s
    wet = 1e-4 * (5.316 * f_nh - 3.759 * f_h) * np.asarray(water_vapour_hpa, float) / f_s
    return hydro, wet


def fcula_mapping(elevation_rad, lat_rad, height_m, temperature_k):
    """FCULa mapping factor, eq. (7).

    Implements IERS Conventions (2010) eqs. 9.14-9.15 (Mendes et al. 2002, FCULa).
    """
    t_c = np.asarray(temperature_k, float) - 273.15
    cos_lat = np.cos(np.asarray(lat_rad, float))
    h = np.asarray(height_m, float)
    a1, a2, a3 = (c[0] + c[1] * t_c + c[2] * cos_lat + c[3] * h for c in _FCULA)
    s = np.sin(np.asarray(elevation_rad, float))
    return (1.0 + a1 / (1.0 + a2 / (1.0 + a3))) / (s + a1 / (s + a2 / (s + a3)))


def slant_delay_m(elevation_rad, lat_rad, height_m, pressure_hpa, temperature_k, humidity_percent,
                  wavelength_um=DEFAULT_WAVELENGTH_UM):
    """One-way optical path delay (m) at elevation ``e``, eq. (1), from surface meteo.

    Implements IERS Conventions (2010) eq. 9.10 (Mendes–Pavlis zenith delay, FCULa mapping).
    """
    e_w = water_vapour_pressure_hpa(pressure_hpa, temperature_k, humidity_percent)
    hydro, wet = zenith_delay_m(lat_rad, height_m, pressure_hpa, e_w, wavelength_um)
    return (hydro + wet) * fcula_mapping(elevation_rad, lat_rad, height_m, temperature_k)


def standard_meteo(height_m):
    """Standard atmosphere at a height when no meteo was recorded: (P hPa, T K, RH %).

    1013.25 hPa and 291.15 K at sea level, 50 % humidity, with the pressure and temperature
    lapse of the Berg model (as Orekit's standard atmosphere): ``P = P0 (1 - 2.26e-5 H)^5.225``,
    ``T = T0 - 6.5e-3 H``.
    """
    h = np.asarray(height_m, float)
    return 1013.25 * (1.0 - 2.26e-5 * h) ** 5.225, 291.15 - 6.5e-3 * h, np.full_like(h, 50.0)


def _in_spans(t, spans) -> np.ndarray:
    t = np.asarray(t, float)
    out = np.zeros(t.shape, dtype=bool)
    for lo, hi in spans:
        out |= (t >= lo) & (t <= hi)
    return out


class TroposphereDelay(md.RangeCorrection):
    """The Mendes–Pavlis delay, eq. (1), of one station's range samples (a driver-free modifier).

    ``lat_rad``, ``height_m``: the station; ``wavelength_um``; the surface meteo as records at
    ``meteo_t_s`` (s on the measurement set's time axis) of ``pressure_hpa``, ``temperature_k``,
    ``humidity_percent``, linearly interpolated to each sample (held at the ends); without
    records the standard atmosphere (:func:`standard_meteo`). ``spans_s``: only samples inside
    these ``(start, end)`` intervals (None: all); ``exclude_s``: not those inside these.
    The delay is evaluated at the elevation of each model evaluation's geometry; its partial
    with respect to the orbit (through the elevation, about 1e-4 of the range partial at 10°)
    is left out of the Jacobian.
    """

    def __init__(self, station: str, lat_rad: float, height_m: float, wavelength_um: float = DEFAULT_WAVELENGTH_UM,
                 meteo_t_s=None, pressure_hpa=None, temperature_k=None, humidity_percent=None,
                 spans_s=None, exclude_s=None) -> None:
        super().__init__(station)
        self.lat_rad, self.height_m, self.wavelength_um = float(lat_rad), float(height_m), float(wavelength_um)
        self.meteo = None
        if meteo_t_s is not None and len(meteo_t_s):
            order = np.argsort(np.asarray(meteo_t_s, float))
            self.meteo = tuple(np.asarray(a, float)[order] for a in
                               (meteo_t_s, pressure_hpa, temperature_k, humidity_percent))
        self.spans_s = spans_s
        self.exclude_s = exclude_s or []

    def __repr__(self) -> str:
        meteo = "CRD meteo" if self.meteo is not None else "standard atmosphere"
        return f"Mendes-Pavlis/FCULa {self.station} ({self.wavelength_um * 1e3:g} nm, {meteo})"

    def rows(self, meas) -> np.ndarray:
        rows = super().rows(meas)
        t = meas.t_s[rows]
        keep = np.ones(rows.size, dtype=bool) if self.spans_s is None else _in_spans(t, self.spans_s)
        keep &= ~_in_spans(t, self.exclude_s)
        return rows[keep]

    def meteo_at(self, t_s):
        """(P hPa, T K, RH %) at the times ``t_s`` (NaN records give way to the standard atmosphere)."""
        t_s = np.asarray(t_s, float)
        std = standard_meteo(np.full(t_s.shape, self.height_m))
        if self.meteo is None:
            return std
        t, *values = self.meteo
        out = []
        for v, fallback in zip(values, std):
            ok = np.isfinite(v)
            out.append(np.interp(t_s, t[ok], v[ok]) if ok.any() else fallback)
        return tuple(out)

    def delay(self, meas, rows, geometry) -> np.ndarray:
        if geometry is None:
            raise ValueError("the troposphere delay needs the evaluation's geometry")
        p, t, rh = self.meteo_at(meas.t_s[rows])
        return slant_delay_m(md.elevation(meas, rows, geometry), self.lat_rad, self.height_m, p, t, rh,
                             self.wavelength_um)


class CentreOfMassOffset(md.RangeCorrection):
    """The target's centre-of-mass offset: the reflectors are ``offset_m`` nearer than the centre
    of mass the orbit describes, so the modelled range is shortened by it (LAGEOS: 0.251 m)."""

    def __init__(self, offset_m: float, station: str | None = None) -> None:
        super().__init__(station)
        self.offset_m = float(offset_m)

    def __repr__(self) -> str:
        return f"centre-of-mass offset {self.offset_m:g} m"

    def delay(self, meas, rows, geometry) -> np.ndarray:
        return np.full(rows.shape, -self.offset_m)
