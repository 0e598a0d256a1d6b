"""The Schwarzschild (post-Newtonian) correction of the Earth's point mass.

Implements IERS Conventions 2010 eq. 10.12 (Schwarzschild term, β = γ = 1; Lense-Thirring
and de Sitter left out: 1e-10 and 5e-10 m/s² at LEO against ~3e-9 here)::

    a = GM/(c² r³) [(4 GM/r - v²) r + 4 (r·v) v]
"""

from __future__ import annotations

import numpy as np

from trackproc.constants import C_LIGHT

__all__ = ["acceleration"]


def acceleration(r, v, gm: float) -> np.ndarray:
    """Schwarzschild acceleration (m/s²) at geocentric inertial ``r`` (m), ``v`` (m/s), (P, 3)."""
    r = np.asarray(r, float)
    v = np.asarray(v, float)
    rn = np.linalg.norm(r, axis=-1, keepdims=True)
    v2 = np.einsum("ij,ij->i", v, v)[:, None]
    rv = np.einsum("ij,ij->i", r, v)[:, None]
    return gm / (C_LIGHT ** 2 * rn ** 3) * ((4 * gm / rn - v2) * r + 4 * rv * v)
