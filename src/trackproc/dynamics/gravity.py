"""Gravity of the force models, written once: two-body plus the J2 zonal term, and its jerk.

The DOP853 reference integrator (:mod:`trackproc.dynamics.reference`) integrates it; the Taylor
engine (:mod:`trackproc.dynamics.taylor`) builds the spectrum of the same right-hand side by
its own recurrences and exposes it as :func:`trackproc.dynamics.taylor.acceleration`, which
calls this function. J2 acts about the z axis of the frame the positions are given in (the
quasi-inertial frame of :class:`trackproc.dynamics.frames.QuasiInertialFrame`).
"""

from __future__ import annotations

import numpy as np

from trackproc.constants import J2 as J2_EARTH
from trackproc.constants import MU_EARTH, RE_EARTH

__all__ = ["acceleration", "force_parameters", "jerk"]


def force_parameters(force: str) -> tuple[float, float, float]:
    """``(mu, j2, re)`` of a force model name: ``"two-body"`` or ``"j2"`` (constants module)."""
    key = str(getattr(force, "value", force)).strip().lower()
    if key in ("two-body", "twobody", "2body", "keplerian"):
        return MU_EARTH, 0.0, RE_EARTH
    if key in ("j2", "two-body+j2"):
        return MU_EARTH, J2_EARTH, RE_EARTH
    raise ValueError(f"unknown force model {force!r}; expected two-body or j2")


def acceleration(r, mu: float = MU_EARTH, j2: float = 0.0, re: float = RE_EARTH) -> np.ndarray:
    """Gravitational acceleration (m/s²) at positions ``r`` (m, shape (..., 3)).

    Two-body plus, when ``j2 != 0``, the J2 zonal term about the z axis (Vallado eq. 8-30).
    Implements seed 004 eq. 4 (two-body motion ``r'' = -mu r / r^3``), extended by J2.
    """
    r = np.asarray(r, float)
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    r2 = x * x + y * y + z * z
    rn = np.sqrt(r2)
    a = -mu / (r2 * rn)
    out = a[..., None] * r
    if j2:
        k = -1.5 * j2 * mu * re * re / (r2 * r2 * rn)
        s5 = 5.0 * z * z / r2
        out = out + np.stack([k * x * (1.0 - s5), k * y * (1.0 - s5), k * z * (3.0 - s5)], -1)
    return out


def jerk(r, v, mu: float = MU_EARTH, j2: float = 0.0, re: float = RE_EARTH) -> np.ndarray:
    """Time derivative of :func:`acceleration` along the motion, ``(∂a/∂r) v`` (m/s³).

    Analytic: two-body ``-mu (v/r³ - 3 r (r·v)/r⁵)``; J2 by the product rule on the
    expression in :func:`acceleration`.

    Implements the time derivative of seed 004 eq. 4 (with J2).
    """
    r = np.asarray(r, float)
    v = np.asarray(v, float)
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    r2 = x * x + y * y + z * z
    rn = np.sqrt(r2)
    rv = x * vx + y * vy + z * vz
    out = -mu * (v / (r2 * rn)[..., None] - 3.0 * r * (rv / (r2 * r2 * rn))[..., None])
    if j2:
        k = -1.5 * j2 * mu * re * re
        rdot = rv / rn
        s = z * z / r2
        sdot = 2.0 * z * (vz * rn - z * rdot) / (r2 * rn)
        g, gdot = 1.0 - 5.0 * s, -5.0 * sdot
        h = 3.0 - 5.0 * s
        inv5 = 1.0 / (r2 * r2 * rn)
        dinv5 = -5.0 * inv5 * rdot / rn
        out = out + k * np.stack([
            (vx * g + x * gdot) * inv5 + x * g * dinv5,
            (vy * g + y * gdot) * inv5 + y * g * dinv5,
            (vz * h + z * gdot) * inv5 + z * h * dinv5,
        ], -1)
    return out
