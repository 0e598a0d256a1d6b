"""The circular-orbit constraints of seed 004 eq. 5, their scales, and the covariance of their values for an orbit
circular only to an eccentricity (the soft constraints of :func:`~trackproc.methods.refinement.solve_soft_kkt`).
"""

from __future__ import annotations

import numpy as np



#: Names of the circular-orbit constraints (seed 004 eq. 5), in order.
CONSTRAINT_NAMES = ("|r|^2 - r_ka^2", "|v|^2 - mu/r_ka", "r.v")


def circular_constraints(x, mu_m3_s2: float, *, state_index=(0, 1, 2, 3, 4, 5), rka_index: int = 6):
    """Seed 004 eq. 5: ``f = (|r|² - r_ka², |v|² - μ/r_ka, r·v)`` and its Jacobian ``A`` (3, n).

    ``x`` holds the GCRF state at ``state_index`` (m, m/s) and ``r_ka`` (m) at ``rka_index``;
    every other entry (e.g. Doppler offsets) has zero partials.
    """
    x = np.asarray(x, float)
    idx = list(state_index)
    r, v, rka = x[idx[:3]], x[idx[3:]], float(x[rka_index])
    f = np.array([r @ r - rka * rka, v @ v - mu_m3_s2 / rka, r @ v])
    a = np.zeros((3, x.size))
    a[0, idx[:3]] = 2.0 * r
    a[0, rka_index] = -2.0 * rka
    a[1, idx[3:]] = 2.0 * v
    a[1, rka_index] = mu_m3_s2 / (rka * rka)
    a[2, idx[:3]] = v
    a[2, idx[3:]] = r
    return f, a


def constraint_scales(x, mu_m3_s2: float, *, state_index=(0, 1, 2, 3, 4, 5), rka_index: int = 6) -> np.ndarray:
    """Scales that make eq. 5 relative: ``(r_ka², μ/r_ka, |r| |v|)``.

    Implements seed 004 eq. 5 (the constraints' natural scales).
    """
    x = np.asarray(x, float)
    idx = list(state_index)
    rka = abs(float(x[rka_index]))
    return np.array([rka * rka, mu_m3_s2 / rka, np.linalg.norm(x[idx[:3]]) * np.linalg.norm(x[idx[3:]])])


def circular_tolerance_covariance(x, mu_m3_s2: float, eccentricity: float, *, state_index=(0, 1, 2, 3, 4, 5)):
    """Covariance (3, 3) of the constraint values of eq. 5 for an orbit that is circular only to
    ``eccentricity``: with r_ka = |r| the first is exact; ``|v|² - μ/r = (μ/r) e cos E`` and
    ``r·v = √(μ r) e sin E`` to first order in e, for an unknown eccentric anomaly E (variance e²/2).

    Implements seed 004 eq. 5 (as soft constraints).
    """
    x = np.asarray(x, float)
    r = float(np.linalg.norm(x[list(state_index)[:3]]))
    e2 = float(eccentricity) ** 2 / 2.0
    return np.diag([0.0, (mu_m3_s2 / r) ** 2 * e2, mu_m3_s2 * r * e2])
