"""Solar radiation pressure on a cannon-ball spacecraft, with the Earth's conical shadow.

``a = ν Cr P☉ (AU/d)² (A/m) (r - r☉)/|r - r☉|``, ``P☉ = 4.56e-6 N/m²`` at 1 AU (Montenbruck &
Gill 2000 eq. 3.75 with the cannon-ball ``Cr``; Orekit's ``IsotropicRadiationSingleCoefficient``
uses the same ``P☉`` and reference distance), ``ν`` the visible fraction of the solar disc
(M&G section 3.4.2, conical shadow of a spherical Earth of radius ``R⊕``).
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics.forces.third_body import AU_M

__all__ = ["P_SUN", "R_SUN", "shadow_fraction", "acceleration"]

#: Solar radiation pressure at 1 AU, N/m² (M&G 2000 eq. 3.73; Orekit's reference value).
P_SUN = 4.56e-6
#: Solar radius, m (IAU 2015 nominal).
R_SUN = 6.957e8


def _discs(r, sun, r_earth, axis=None, flattening: float = 0.0):
    """Apparent radii of the Sun ``a`` and the Earth ``b`` and their separation ``c`` seen from
    ``r`` (P, 3), rad (M&G eqs. 3.80-3.82; the oblate Earth stretched to a sphere along ``axis``)."""
    r = np.atleast_2d(np.asarray(r, float))
    if axis is not None and flattening:
        k = 1.0 / (1.0 - flattening) - 1.0
        r = r + k * (r @ axis)[:, None] * axis
        sun = sun + k * (sun @ axis) * axis
    d_sun = sun - r
    rn = np.linalg.norm(r, axis=-1)
    dn = np.linalg.norm(d_sun, axis=-1)
    a = np.arcsin(np.clip(R_SUN / dn, -1, 1))               # apparent solar radius
    b = np.arcsin(np.clip(r_earth / rn, -1, 1))             # apparent Earth radius
    c = np.arccos(np.clip(np.einsum("ij,ij->i", -r, d_sun) / (rn * dn), -1, 1))   # separation
    return a, b, c


def shadow_boundaries(r, sun, r_earth: float, axis=None, flattening: float = 0.0) -> np.ndarray:
    """``(P, 2)``: ``c - (a + b)`` and ``c - (b - a)``, zero where the satellite enters or leaves
    the penumbra and the umbra: the kinks of :func:`shadow_fraction`, where the integrator ends
    its steps (an RK step across a kink loses its order: centimetres of LAGEOS in 3 days)."""
    a, b, c = _discs(r, sun, r_earth, axis, flattening)
    return np.stack([c - (a + b), c - (b - a)], -1)


def shadow_fraction(r, sun, r_earth: float, axis=None, flattening: float = 0.0) -> np.ndarray:
    """Fraction ``ν`` (0..1) of the solar disc seen from ``r`` (P, 3) past the Earth (conical model).

    Implements Montenbruck & Gill (2000) eqs. 3.79-3.86 (apparent radii a, b and separation c
    of the Sun and the occulting Earth; partial occultation by the overlap of two discs). With
    ``axis`` (the Earth's rotation axis) and ``flattening`` the oblate Earth is made a sphere of
    the equatorial radius by stretching the coordinates along the axis by ``1/(1-f)`` (exact for
    the shadow's cylinder, a close approximation for its cone): a LEO day's SRP then agrees with
    Orekit's ellipsoid occultation to 0.17 m instead of 0.95 m with the sphere.
    """
    a, b, c = _discs(r, sun, r_earth, axis, flattening)
    nu = np.ones(a.shape[0])
    total = c <= b - a
    nu[total] = 0.0
    part = (np.abs(a - b) < c) & (c < a + b)
    if part.any():
        ap, bp, cp = a[part], b[part], c[part]
        x = (cp ** 2 + ap ** 2 - bp ** 2) / (2 * cp)
        y = np.sqrt(np.maximum(ap ** 2 - x ** 2, 0.0))
        area = (ap ** 2 * np.arccos(np.clip(x / ap, -1, 1)) + bp ** 2 * np.arccos(np.clip((cp - x) / bp, -1, 1))
                - cp * y)
        nu[part] = 1.0 - area / (np.pi * ap ** 2)
    annular = (c < a - b) & ~total
    nu[annular] = 1.0 - (b[annular] / a[annular]) ** 2
    return nu


def acceleration(r, sun, area_over_mass: float, cr: float, r_earth: float, axis=None,
                 flattening: float = 0.0) -> np.ndarray:
    """SRP acceleration (m/s²) at ``r`` (P, 3) with the Sun at ``sun`` (3,), GCRS axes."""
    d = np.asarray(r, float) - sun
    dn = np.linalg.norm(d, axis=-1, keepdims=True)
    nu = shadow_fraction(r, sun, r_earth, axis, flattening)[:, None]
    return nu * cr * P_SUN * (AU_M / dn) ** 2 * area_over_mass * d / dn
