"""Sun and Moon as point masses: their positions from ERFA and their pull on the satellite.

Positions (GCRS axes, geometric, metres) from ERFA's maintained analytic series: ``epv00``
(Bretagnon & Francou VSOP2000-based Earth ephemeris, ~km for the Sun) and ``moon98``
(Meeus's ELP-2000/82 truncation, ~10 arcsec). What that costs at a satellite: the Moon's
tidal pull at LEO is ~1e-6 m/s², so a 10" direction error is ~5e-11 m/s² (< 0.2 m in a day).
"""

from __future__ import annotations

import erfa
import numpy as np

__all__ = ["GM_SUN", "GM_MOON", "AU_M", "sun_moon_gcrf", "point_mass"]

#: Heliocentric gravitational constant, m³/s² (IAU 2009/2012 system, TDB-compatible; DE440).
GM_SUN = 1.32712440041279419e20
#: Lunar gravitational constant, m³/s² (DE440: GM_Earth / 81.3005682214972).
GM_MOON = 4.902800118457551e12
#: Astronomical unit, m (IAU 2012 Resolution B2, exact).
AU_M = 149597870700.0
_AU_PER_DAY = AU_M / 86400.0


def sun_moon_gcrf(tt1, tt2):
    """Geocentric Sun and Moon position (m) and velocity (m/s), GCRS axes, at TT two-part JDs.

    Returns ``(sun_pv, moon_pv)`` each of shape (N, 2, 3). TDB is taken as TT (< 2 ms apart:
    2 m of lunar motion, 1e-9 relative in its pull).
    """
    pvh, _ = erfa.epv00(tt1, tt2)
    moon = erfa.moon98(tt1, tt2)
    scale = np.array([AU_M, _AU_PER_DAY])[:, None]

    def pv(a):
        return np.stack([np.asarray(a["p"]), np.asarray(a["v"])], -2).reshape(-1, 2, 3) * scale

    return -pv(pvh), pv(moon)                                # Earth heliocentric -> Sun geocentric


def point_mass(r, body, gm: float) -> np.ndarray:
    """Acceleration (m/s²) of a body of ``gm`` at geocentric ``body`` (3,) on satellites at ``r``
    (P, 3): the direct pull minus the pull on the Earth (the indirect term).

    Implements Montenbruck & Gill (2000) eq. 3.37: ``a = GM (s - r)/|s - r|³ - GM s/|s|³``.
    """
    d = body - np.asarray(r, float)
    dn = np.linalg.norm(d, axis=-1, keepdims=True)
    sn = np.linalg.norm(body)
    return gm * (d / dn ** 3 - body / sn ** 3)
