"""Non-singular orbital elements and the Cartesian covariance of independent element errors (the default a-priori).
"""

from __future__ import annotations

import math

import numpy as np



#: Non-singular orbital elements (two-body, osculating): semi-major axis, eccentricity vector
#: components along the ascending node and 90 deg ahead of it in the plane, inclination, right
#: ascension of the ascending node, argument of latitude.
ELEMENT_NAMES = ("a_m", "ex", "ey", "i_rad", "raan_rad", "u_rad")


def nonsingular_elements(rv, mu_m3_s2: float) -> np.ndarray:
    """``(a, ex, ey, i, Ω, u)`` of a GCRF state (m, m/s); valid for e < 1 and i not near 0 or π."""
    rv = np.asarray(rv, float)
    r, v = rv[:3], rv[3:]
    rn = np.linalg.norm(r)
    h = np.cross(r, v)
    hn = np.linalg.norm(h)
    inc = math.acos(max(-1.0, min(1.0, h[2] / hn)))
    raan = math.atan2(h[0], -h[1])
    p_hat = np.array([math.cos(raan), math.sin(raan), 0.0])
    q_hat = np.cross(h / hn, p_hat)
    e_vec = ((v @ v - mu_m3_s2 / rn) * r - (r @ v) * v) / mu_m3_s2
    a = 1.0 / (2.0 / rn - (v @ v) / mu_m3_s2)
    u = math.atan2(r @ q_hat, r @ p_hat)
    return np.array([a, e_vec @ p_hat, e_vec @ q_hat, inc, raan, u])


def state_from_elements(q, mu_m3_s2: float) -> np.ndarray:
    """Inverse of :func:`nonsingular_elements`: the GCRF state (6,) of ``(a, ex, ey, i, Ω, u)``."""
    a, ex, ey, inc, raan, u = (float(x) for x in q)
    p = a * (1.0 - ex * ex - ey * ey)
    radius = p / (1.0 + ex * math.cos(u) + ey * math.sin(u))
    p_hat = np.array([math.cos(raan), math.sin(raan), 0.0])
    q_hat = np.array([-math.cos(inc) * math.sin(raan), math.cos(inc) * math.cos(raan), math.sin(inc)])
    r = radius * (math.cos(u) * p_hat + math.sin(u) * q_hat)
    w = math.sqrt(mu_m3_s2 / p)
    v = w * (-(math.sin(u) + ey) * p_hat + (math.cos(u) + ex) * q_hat)
    return np.concatenate([r, v])


#: Finite-difference steps of the element Jacobian.
ELEMENT_STEPS = np.array([1.0, 1e-7, 1e-7, 1e-8, 1e-8, 1e-8])


def element_covariance(rv, mu_m3_s2: float, sigma_elements) -> np.ndarray:
    """GCRF covariance (6, 6) of a state whose non-singular elements have independent errors
    ``sigma_elements`` (:data:`ELEMENT_NAMES` order; m and rad): ``J diag(σ²) Jᵀ`` with
    ``J = ∂state/∂elements`` by central differences. It keeps what an orbit catalogue knows well
    (the period: semi-major axis) apart from what it knows poorly (the along-track phase)."""
    q0 = nonsingular_elements(rv, mu_m3_s2)
    jac = np.empty((6, 6))
    for k in range(6):
        dq = np.zeros(6)
        dq[k] = ELEMENT_STEPS[k]
        jac[:, k] = (state_from_elements(q0 + dq, mu_m3_s2) - state_from_elements(q0 - dq, mu_m3_s2)) / (2 * dq[k])
    cov = jac @ np.diag(np.square(np.asarray(sigma_elements, float))) @ jac.T
    return 0.5 * (cov + cov.T)
