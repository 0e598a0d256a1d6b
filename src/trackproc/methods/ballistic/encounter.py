"""The planar encounter: the elevation seen by the observer (seed 003 eq. 11, App. B), :class:`PlanarEncounter`,
and the observer-motion error (App. C).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.constants import MU_EARTH, OMEGA_EARTH

from trackproc.methods.ballistic.conic import (DIRECTIONS, R_PLANAR, anomaly_at, final_anomaly, impact_to_conic, radius,
                                               time_from_apogee)
from trackproc.methods.roots import brentq


def elevation(theta, phi, p_m, e, radius_m: float = R_PLANAR):
    """Eq. 11: elevation (rad) of the object at anomaly θ seen from the observer at angle φ.

    ``ε = atan2(r cos(φ-θ) - R, r |sin(φ-θ)|)``; equal to the paper's ``tan ε`` while the
    object approaches (``sin(φ - θ) > 0``).

    Implements seed 003 eq. 11: ``tan ε = (r cos(φ - θ) - R) / (r sin(φ - θ))``.
    """
    r = radius(theta, p_m, e)
    d = np.asarray(phi, float) - np.asarray(theta, float)
    return np.arctan2(r * np.cos(d) - radius_m, r * np.abs(np.sin(d)))


def horizon_anomalies(phi, p_m, e, radius_m: float = R_PLANAR):
    """App. B: the anomalies (θ₀, θ₂) where the orbit crosses the observer's horizon (ε = 0).

    θ₀ (rise) and θ₂ from the quadratic in ``x = tan(θ/2)``; for ``φ = θ_f``, θ₂ = θ_f.
    Raises ``ValueError`` when the discriminant is negative (the orbit never rises).

    Implements seed 003 App. B.
    """
    c = radius_m / p_m
    a = np.cos(phi) + e * c
    b = np.sin(phi)
    big_a, big_b, big_c = a + c, -2.0 * b, c - a
    disc = big_b * big_b - 4.0 * big_a * big_c
    if np.any(disc < 0):
        raise ValueError("the orbit never rises above the observer's horizon (negative discriminant)")
    root = np.sqrt(disc)
    return (2.0 * np.arctan((-big_b - root) / (2.0 * big_a)),
            2.0 * np.arctan((-big_b + root) / (2.0 * big_a)))


@dataclass(frozen=True)
class PlanarEncounter:
    """One unfavourable (or given-φ) planar encounter, times ``s`` in seconds **relative to impact**.

    ``p_m, e``: the conic; ``phi_impact``: the observer's angle at impact under H0 (θ_f for the
    unfavourable orbit); ``observer_rate``: ``±ω_E cos(lat)`` (rad/s; + with, - against, 0 a
    stationary observer); ``radius_m``, ``mu``.

    Implements seed 003 eqs. 9-11 and App. A-B for one encounter.
    """

    p_m: float
    e: float
    phi_impact: float
    observer_rate: float = 0.0
    radius_m: float = R_PLANAR
    mu: float = MU_EARTH

    @classmethod
    def from_impact(cls, velocity_m_s: float, angle_rad: float, *, latitude_rad: float | None = None,
                    direction: str = "none", radius_m: float = R_PLANAR, mu: float = MU_EARTH,
                    omega_rad_s: float = OMEGA_EARTH) -> "PlanarEncounter":
        """The unfavourable orbit (φ = θ_f) of impact speed V and angle α (App. A).

        Implements seed 003 App. A.
        """
        p, e = impact_to_conic(velocity_m_s, angle_rad, radius_m, mu)
        p, e = float(p), float(e)
        return cls(p, e, float(final_anomaly(p, e, radius_m)),
                   observer_speed(latitude_rad, direction, omega_rad_s), radius_m, mu)

    @property
    def theta_f(self) -> float:
        """Final (impact) anomaly, rad."""
        return float(final_anomaly(self.p_m, self.e, self.radius_m))

    @property
    def impact_from_apogee_s(self) -> float:
        return float(time_from_apogee(self.theta_f, self.p_m, self.e, self.mu))

    def theta(self, s):
        """Anomaly at ``s`` seconds relative to impact (s ≤ 0)."""
        return anomaly_at(self.impact_from_apogee_s + np.asarray(s, float), self.p_m, self.e, self.mu)

    def phi(self, s, displacement_m: float = 0.0):
        """Observer angle φ(t) = φ_impact - rate·(T - t) + Δ/R (section "observer motion")."""
        return self.phi_impact + self.observer_rate * np.asarray(s, float) + displacement_m / self.radius_m

    def elevation(self, s, displacement_m: float = 0.0):
        """ε(s) (rad) under the hypothesis "displacement Δ" (0 = H0)."""
        s = np.asarray(s, float)
        return elevation(self.theta(s), self.phi(s, displacement_m), self.p_m, self.e, self.radius_m)

    def rise_time(self, displacement_m: float = 0.0) -> float:
        """Time of horizon rise (s relative to impact, < 0).

        Stationary observer: App. B's θ₀ turned into time by eq. 10's closed form. Moving
        observer: the last upward zero of ε(s) before impact, bracketed on a grid from the
        launch point (θ = -θ_f) and refined by Brent's method.

        Implements seed 003 App. B with eq. 10.
        """
        t_imp = self.impact_from_apogee_s
        if self.observer_rate == 0.0:
            theta0, _ = horizon_anomalies(self.phi(0.0, displacement_m), self.p_m, self.e, self.radius_m)
            return float(time_from_apogee(theta0, self.p_m, self.e, self.mu) - t_imp)
        grid = np.linspace(-2.0 * t_imp, -1e-3 * t_imp, 4001)
        el = self.elevation(grid, displacement_m)
        up = np.flatnonzero((el[:-1] < 0) & (el[1:] >= 0))
        if up.size == 0 or np.any(el[up[-1] + 1:] < 0):
            raise ValueError("the object does not rise above the moving observer's horizon before impact")
        k = up[-1]
        return float(brentq(lambda x: float(self.elevation(x, displacement_m)), grid[k], grid[k + 1],
                            xtol=1e-9, rtol=1e-14))


def observer_speed(latitude_rad: float | None, direction: str = "none", omega_rad_s: float = OMEGA_EARTH) -> float:
    """In-plane angular rate of the fictitious observer: ``±ω_E cos(lat)`` (rad/s), 0 if stationary.

    Implements seed 003 item 7 (the observer's in-plane speed).
    """
    sign = DIRECTIONS[direction]
    if sign == 0 or latitude_rad is None:
        return 0.0
    return sign * omega_rad_s * float(np.cos(latitude_rad))


def observer_motion_error(t_s, elevation_rad, range_m, latitude_rad: float, *, radius_m: float = R_PLANAR,
                          omega_rad_s: float = OMEGA_EARTH, side: int = -1):
    """App. C: range error of replacing the observer's motion along its parallel by in-plane motion.

    Frame at the common point O: x up (in the orbit plane), y along the observer's velocity,
    z north (normal to the plane). After ``t_s`` seconds of (time-reversed) motion from O::

        true:        r_H = (-R cos²φ_H (1 - cos ω t),  R cos φ_H sin ω t,  R sin 2φ_H (1 - cos ω t) / 2)
        fictitious:  r_f = (-R (1 - cos ω_f t),  R sin ω_f t,  0),   ω_f = ω cos φ_H

    (the paper prints ``cos ω t`` in z_H; ``1 - cos ω t`` is what its u_H gives). The object is
    at range d and elevation ε from O in the orbit plane, ``r = (d sin ε, side · d cos ε, 0)``.
    ``side = -1``: the object on the other side of O than the observer's (time-reversed)
    displacement, i.e. in forward time the two converge on O from opposite sides (head-on,
    "against"); this side reproduces Table 1 cell by cell (tests/pipeline/test_ballistic_model.py).
    ``side = +1`` (converging from the same side, "with") gives errors of the same order.
    Returns ``(Δd, Δl, Δε)``: ``Δd = d_f - d_H`` (m), the shift ``Δl = Δd / cos ε`` (m) and
    the elevation error ``Δε = (Δd / d) tan ε`` (rad), as the paper's Fig. 2.

    Implements seed 003 App. C (its Table 1).
    """
    t = np.asarray(t_s, float)
    el = np.asarray(elevation_rad, float)
    d = np.asarray(range_m, float)
    c, s = np.cos(latitude_rad), np.sin(latitude_rad)
    wt, wft = omega_rad_s * t, omega_rad_s * c * t
    # 1 - cos x without cancellation
    one_minus_cos = 2.0 * np.sin(wt / 2) ** 2
    one_minus_cos_f = 2.0 * np.sin(wft / 2) ** 2
    r_h = np.stack([-radius_m * c * c * one_minus_cos, radius_m * c * np.sin(wt),
                    radius_m * 2 * s * c * one_minus_cos / 2], -1)
    r_f = np.stack([-radius_m * one_minus_cos_f, radius_m * np.sin(wft), np.zeros_like(wft)], -1)
    obj = np.stack([d * np.sin(el), side * d * np.cos(el), np.zeros_like(d)], -1)
    d_h = np.linalg.norm(obj - r_h, axis=-1)
    d_f = np.linalg.norm(obj - r_f, axis=-1)
    dd = d_f - d_h
    return dd, dd / np.cos(el), dd / d * np.tan(el)
