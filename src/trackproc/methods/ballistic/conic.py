"""The ballistic conic through the impact point (seed 003 App. A) and the motion along it (eqs. 9-10).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from trackproc.constants import MU_EARTH, R_SPHERE


#: Radius of the planar model's Earth, m (the paper's R_З is not stated; mean radius 6371 km).
R_PLANAR = R_SPHERE
#: The paper's μ (3.9860044e14) differs from MU_EARTH by 5e-10 relative: MU_EARTH is used.
MU_PAPER = 3.9860044e14
#: Direction of the observer's motion relative to the object: +1 with, -1 against, 0 none.
DIRECTIONS = {"with": 1, "against": -1, "none": 0}


def impact_to_conic(velocity_m_s, angle_rad, radius_m: float = R_PLANAR, mu: float = MU_EARTH):
    """Focal parameter ``p`` (m) and eccentricity ``e`` from the impact speed and angle.

    Implements seed 003 App. A: ``p = R² V² cos²α / μ``, ``e² = (p_R tan α)² + (1 - p_R)²``.
    ``angle_rad`` is the flight-path angle below the horizontal at ``r = R`` (0 < α < π/2).
    """
    v = np.asarray(velocity_m_s, float)
    a = np.asarray(angle_rad, float)
    p = radius_m ** 2 * v ** 2 * np.cos(a) ** 2 / mu
    pr = p / radius_m
    e = np.sqrt((pr * np.tan(a)) ** 2 + (1.0 - pr) ** 2)
    return p, e


def conic_to_impact(p_m, e, radius_m: float = R_PLANAR, mu: float = MU_EARTH):
    """Inverse of :func:`impact_to_conic`: speed (m/s) and angle (rad) where ``r(θ) = R``.

    From ``y = 1 - e cos θ_f = p/R`` and ``x = e sin θ_f`` (App. A): ``tan α = x / y``,
    ``V² = (μ/p)(x² + y²)``. Raises ``ValueError`` when the orbit does not reach ``r = R``.

    Implements seed 003 App. A (inverse).
    """
    p = np.asarray(p_m, float)
    e = np.asarray(e, float)
    y = p / radius_m
    x2 = e ** 2 - (1.0 - y) ** 2
    if np.any(x2 < 0):
        raise ValueError("the orbit does not intersect the sphere r = R (e < |1 - p/R|)")
    x = np.sqrt(x2)
    return np.sqrt(mu / p * (x * x + y * y)), np.arctan2(x, y)


def final_anomaly(p_m, e, radius_m: float = R_PLANAR):
    """θ_f (rad, in (0, π)): the descending intersection of eq. 9 with ``r = R`` (App. A/B)."""
    p = np.asarray(p_m, float)
    c = (1.0 - p / radius_m) / np.asarray(e, float)
    if np.any(np.abs(c) > 1):
        raise ValueError("the orbit does not intersect the sphere r = R")
    return np.arccos(c)


def radius(theta, p_m, e):
    """Eq. 9: ``r = p / (1 - e cos θ)`` (m), θ from apogee.

    Implements seed 003 eq. 9: ``r(θ) = p / (1 - e cos θ)``.
    """
    return p_m / (1.0 - e * np.cos(theta))


def angular_rate(theta, p_m, e, mu: float = MU_EARTH):
    """Eq. 10: ``dθ/dt = sqrt(μ/p³) (1 - e cos θ)²`` (rad/s).

    Implements seed 003 eq. 10: ``dθ/dt = sqrt(mu)/p^1.5 (1 - e cos θ)^2``.
    """
    return np.sqrt(mu / p_m ** 3) * (1.0 - e * np.cos(theta)) ** 2


def mean_motion(p_m, e, mu: float = MU_EARTH):
    """n = sqrt(μ / a³) (rad/s) with a = p / (1 - e²)."""
    return np.sqrt(mu * (1.0 - e * e) ** 3 / p_m ** 3)


def time_from_apogee(theta, p_m, e, mu: float = MU_EARTH):
    """Time (s) from apogee to the anomaly θ ∈ (-π, π): the closed-form solution of eq. 10.

    ``η = 2 atan2(sqrt(1+e) sin(θ/2), sqrt(1-e) cos(θ/2))``, ``t = (η + e sin η) / n``.

    Implements seed 003 eq. 10 (integrated in closed form).
    """
    theta = np.asarray(theta, float)
    eta = 2.0 * np.arctan2(np.sqrt(1.0 + e) * np.sin(theta / 2), np.sqrt(1.0 - e) * np.cos(theta / 2))
    return (eta + e * np.sin(eta)) / mean_motion(p_m, e, mu)


def anomaly_at(t_from_apogee_s, p_m, e, mu: float = MU_EARTH, tol: float = 1e-14, max_iter: int = 60):
    """θ (rad) at a time from apogee (s): inverse of :func:`time_from_apogee`.

    Newton's method on Kepler's equation ``E - e sin E = M`` with ``E = η + π``,
    ``M = n t + π`` and Danby's starter ``E₀ = M + 0.85 e sign(sin M)``; |t| must be below half
    a period. Raises ``ArithmeticError`` if it does not converge.
    """
    n = mean_motion(p_m, e, mu)
    m = n * np.asarray(t_from_apogee_s, float) + np.pi
    if np.any((m <= 0) | (m >= 2 * np.pi)):
        raise ValueError("time from apogee must be within half an orbital period")
    big_e = m + 0.85 * e * np.sign(np.sin(m))
    for _ in range(max_iter):
        step = (big_e - e * np.sin(big_e) - m) / (1.0 - e * np.cos(big_e))
        big_e = big_e - step
        if np.all(np.abs(step) < tol):
            break
    else:  # pragma: no cover - Newton with Danby's start converges for e < 1
        raise ArithmeticError("Kepler's equation did not converge")
    eta = big_e - np.pi
    return 2.0 * np.arctan2(np.sqrt(1.0 - e) * np.sin(eta / 2), np.sqrt(1.0 + e) * np.cos(eta / 2))


def anomaly_by_ode(t_s, t0_s: float, theta0: float, p_m: float, e: float, mu: float = MU_EARTH,
                   rtol: float = 1e-12, atol: float = 1e-14):
    """θ at times ``t_s`` by integrating eq. 10 from ``θ(t0) = θ0`` (scipy DOP853, rtol 1e-12).

    The paper's own route; here a cross-check of :func:`anomaly_at` (dense output of DOP853,
    7th order, whose interpolation error at this tolerance is far below 1e-9 rad).

    Implements seed 003 eq. 10 (integrated numerically, as a check).
    """
    t_s = np.atleast_1d(np.asarray(t_s, float))
    t_end = float(t_s.max()) if np.all(t_s >= t0_s) else float(t_s.min())
    sol = solve_ivp(lambda _t, y: angular_rate(y, p_m, e, mu), (t0_s, t_end), [theta0], method="DOP853",
                    rtol=rtol, atol=atol, dense_output=True)
    if not sol.success:  # pragma: no cover
        raise ArithmeticError(f"DOP853 failed: {sol.message}")
    return sol.sol(t_s)[0]
