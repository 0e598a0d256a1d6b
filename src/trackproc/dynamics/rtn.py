"""Radial / along-track / cross-track (RTN) axes of an orbit state, written once.

``R = r/|r|``, ``C = r × v / |r × v|``, ``A = C × R`` (along-track: the velocity direction for a
circular orbit). Used wherever a state error or covariance is reported on orbit axes
(``estimate``, ``refine``, ``accuracy``, the refinement's observability report).
"""

from __future__ import annotations

import numpy as np

__all__ = ["rtn_rotation", "rtn_jacobian", "to_rtn", "rtn_covariance"]


def rtn_rotation(r, v) -> np.ndarray:
    """Rows of the radial / along-track / cross-track unit vectors at states ``r, v (..., 3)``.

    Returns ``(..., 3, 3)``; ``M @ dr`` resolves a vector along R, A, C.
    """
    r = np.asarray(r, dtype=float)
    v = np.asarray(v, dtype=float)
    er = r / np.linalg.norm(r, axis=-1, keepdims=True)
    h = np.cross(r, v)
    ec = h / np.linalg.norm(h, axis=-1, keepdims=True)
    ea = np.cross(ec, er)
    return np.stack([er, ea, ec], axis=-2)


def rtn_jacobian(r, v, rotating: bool = True) -> np.ndarray:
    """6 x 6 map of inertial state errors to RTN errors at the nominal ``r, v (..., 3)``.

    Position: ``dr_rtn = M dr`` (rows of :func:`rtn_rotation`). Velocity, ``rotating=True``:
    the rate of change of the RTN position error, ``M dv - w x (M dr)`` with the frame's
    angular velocity ``w = (0, 0, |r x v| / r^2)`` in RTN (two-body; the slow turn of the plane
    under J2 is ~1e-3 of it) -- the Clohessy-Wiltshire convention, in which an along-track
    drift shows as a constant along-track rate, not as a growing radial velocity.
    ``rotating=False``: the inertial velocity error resolved on the same axes, ``M dv``.
    Returns ``(..., 6, 6)``.
    """
    m = rtn_rotation(r, v)
    big = np.zeros(m.shape[:-2] + (6, 6))
    big[..., :3, :3] = m
    big[..., 3:, 3:] = m
    if rotating:
        r = np.asarray(r, dtype=float)
        w = np.linalg.norm(np.cross(r, np.asarray(v, float)), axis=-1) / np.sum(r * r, axis=-1)
        # -[w]x M with [w]x = w [[0,-1,0],[1,0,0],[0,0,0]]: rows (w M_1, -w M_0, 0)
        big[..., 3, :3] = w[..., None] * m[..., 1, :]
        big[..., 4, :3] = -w[..., None] * m[..., 0, :]
    return big


def to_rtn(cov, r, v, rotating: bool = True) -> np.ndarray:
    """6 x 6 covariances ``(..., 6, 6)`` resolved along the RTN axes of the nominal ``r, v``.

    ``J P J^T`` with ``J`` from :func:`rtn_jacobian` (by default the velocity block is the rate
    of the RTN position errors; ``rotating=False``: inertial velocity errors on RTN axes).
    """
    big = rtn_jacobian(r, v, rotating)
    return np.einsum("...ij,...jk,...lk->...il", big, np.asarray(cov, float), big)


def rtn_covariance(r, v, cov6) -> np.ndarray:
    """One 6 × 6 covariance of the state ``r, v (3,)`` with its position and velocity errors both
    resolved on the RTN axes (inertial velocity errors, ``rotating=False``), symmetrized: the
    ``covariance_rtn`` of ``estimate`` and ``refine``."""
    big = rtn_jacobian(r, v, rotating=False)
    out = big @ np.asarray(cov6, float) @ big.T
    return 0.5 * (out + out.T)
