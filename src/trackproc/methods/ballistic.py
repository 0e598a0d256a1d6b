"""Ballistic encounter geometry: the planar motion–measurement model of seed 003, and its 3-D check.

Planar model (seed 003 eqs. 9-11, appendices A-C). The object moves on a Keplerian ellipse in
a plane through the Earth's centre; the observer H stands on the circle of radius ``R`` (the
Earth's trace in that plane) at the polar angle ``φ`` from the apse line. Angles are counted
in the direction of motion and the true anomaly ``θ`` from **apogee** (the paper's choice)::

    r(θ)   = p / (1 - e cos θ)                                                    (eq. 9)
    dθ/dt  = sqrt(μ p) / r² = sqrt(μ / p³) (1 - e cos θ)²                         (eq. 10)
    tan ε  = (r cos(φ - θ) - R) / (r sin(φ - θ))                                 (eq. 11)

Eq. 11 is evaluated as ``ε = atan2(r cos(φ-θ) - R, r |sin(φ-θ)|)``: the same for an object
still approaching the observer (``θ < φ``, the paper's case) and continuous through the zenith
if a displaced trajectory passes over H (elevation in [-π/2, π/2]).

Impact parameters (App. A): speed ``V`` and flight-path angle ``α`` (below the local
horizontal, positive descending) where the orbit meets the sphere ``r = R``::

    p = R² V² cos² α / μ,   p_R = p / R,   e² = (p_R tan α)² + (1 - p_R)²,
    cos θ_f = (1 - p_R) / e,  sin θ_f = p_R tan α / e  (θ_f in (0, π), descending branch).

``V`` and ``α`` are inertial: the orbit is a fixed conic; the observer moves (below).

Time along the orbit (eq. 10). Eq. 10 has the closed-form solution of Kepler's equation; with
the eccentric anomaly counted from apogee, ``η = E - π``::

    tan(η/2) = sqrt((1+e)/(1-e)) tan(θ/2),   n (t - t_apogee) = η + e sin η,   n = sqrt(μ (1-e²)³ / p³)

:func:`time_from_apogee` evaluates it (exact, vectorized); :func:`anomaly_at` inverts it by
Newton's method on Kepler's equation (Danby's starter, |ΔE| < 1e-14). :func:`anomaly_by_ode`
integrates eq. 10 itself by scipy's DOP853 at rtol 1e-12, as the paper does; the tests check
that both agree to better than 1e-9 rad. The closed form is the default: it needs no
integration and no step-size choice, and it is exact at every sample time.

Horizon rise (App. B). With ``ε₀ = 0``, eq. 11 becomes ``a cos θ + b sin θ = c`` with
``a = cos φ + e R/p``, ``b = sin φ``, ``c = R/p``; ``x = tan(θ/2)`` gives
``A x² + B x + C = 0``, ``A = a + c, B = -2b, C = c - a`` and::

    θ₀ = 2 arctan((-B - sqrt(B² - 4AC)) / 2A)  (rise),   θ₂ = 2 arctan((-B + sqrt(B² - 4AC)) / 2A)

For a sub-circular impact speed (``p < R``, always so here) ``c > 1`` gives ``A > 0``, so θ₀ is
the smaller root: the object rises at θ₀ and, for the unfavourable orbit ``φ = θ_f``, the
second root is the impact itself, ``θ₂ = θ_f`` (the horizon line touches the sphere at H).

Observer motion (the paper's "Учет движения наблюдателя" and App. C). The unfavourable orbit
is the one whose plane contains the observer's velocity at impact and whose impact point is
the observer: ``φ = θ_f``. The observer's motion along its parallel (speed
``ω_E R cos(lat)``) is replaced by an in-plane motion on the circle R at the same speed,
``ω_f = ω_E cos(lat)``; with the displacement Δ of the hypothesis H1::

    φ(t) = θ_f ∓ ω_f (T - t) + Δ / R

with the upper sign when the object moves in the same direction as the observer ("with",
i.e. eastward) and the lower sign "against" (westward). The paper writes ``±`` without fixing
which is which; ours follows from the geometry (an observer moving with the object lay behind
its final position earlier). Δ > 0 puts the observer beyond the impact point (the displaced
trajectory falls short of H), as the paper's ``+Δ/R``.

:func:`observer_motion_error` evaluates App. C: the difference of the ranges from the object
to the true observer (on its parallel, out of the plane) and to the in-plane fictitious one.

3-D counterpart (beyond the paper): :func:`impact_state_3d` builds the GCRF state at impact of
the unfavourable trajectory through a real station (velocity in the plane spanned by the
geocentric vertical and the station's inertial velocity) and, for H1, the same state rotated
back along the track by Δ / |r_station|; :func:`ballistic_azel` propagates it with
:mod:`trackproc.dynamics.reference` and measures azimuth and elevation from the station with
:func:`trackproc.models.measurements.observables` (light time, IAU 2006/2000A Earth rotation,
WGS-84 or spherical station).

All functions are pure, SI units (m, s, rad), numpy arrays in and out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.constants import MU_EARTH, OMEGA_EARTH, R_SPHERE

#: Radius of the planar model's Earth, m (the paper's R_З is not stated; mean radius 6371 km).
R_PLANAR = R_SPHERE
#: The paper's μ (3.9860044e14) differs from MU_EARTH by 5e-10 relative: MU_EARTH is used.
MU_PAPER = 3.9860044e14
#: Direction of the observer's motion relative to the object: +1 with, -1 against, 0 none.
DIRECTIONS = {"with": 1, "against": -1, "none": 0}


# --------------------------------------------------------------------------- App. A

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


# --------------------------------------------------------------------------- eqs. 9-10

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
    from scipy.integrate import solve_ivp

    t_s = np.atleast_1d(np.asarray(t_s, float))
    t_end = float(t_s.max()) if np.all(t_s >= t0_s) else float(t_s.min())
    sol = solve_ivp(lambda _t, y: angular_rate(y, p_m, e, mu), (t0_s, t_end), [theta0], method="DOP853",
                    rtol=rtol, atol=atol, dense_output=True)
    if not sol.success:  # pragma: no cover
        raise ArithmeticError(f"DOP853 failed: {sol.message}")
    return sol.sol(t_s)[0]


# --------------------------------------------------------------------------- eq. 11, App. B

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


# --------------------------------------------------------------------------- the encounter

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
        from scipy.optimize import brentq

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


# --------------------------------------------------------------------------- App. C

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
    "against"); this side reproduces Table 1 cell by cell (tests/test_ballistic_model.py).
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


# --------------------------------------------------------------------------- 3-D counterpart

def _rotate(vec, axis, angle):
    """Rodrigues rotation of ``vec`` about the unit ``axis`` by ``angle`` (rad, right hand)."""
    k = np.asarray(axis, float)
    v = np.asarray(vec, float)
    return v * np.cos(angle) + np.cross(k, v) * np.sin(angle) + k * np.dot(k, v) * (1 - np.cos(angle))


def impact_state_3d(r_station_m, v_station_m_s, velocity_m_s: float, angle_rad: float, *,
                    direction: str = "with", heading_rad: float | None = None, displacement_m: float = 0.0):
    """GCRF position (m) and velocity (m/s) of the object at impact for the 3-D model.

    The impact point is the station (``r_station_m`` at the impact time, GCRF) under H0. The
    velocity ``V (cos α ĥ - sin α û)`` has the geocentric vertical ``û = r/|r|`` and the
    horizontal ``ĥ``: the station's inertial velocity direction ("with", the unfavourable
    orbit of seed 003 moving eastward), its opposite ("against"), or, when ``heading_rad`` is
    given, the geocentric horizontal at that azimuth (from north through east; east is the
    station's inertial velocity direction, so north refers to the true rotation axis). H1: the
    state rotated about the orbit normal by ``-Δ/|r|`` (the impact point moves back along the
    track by Δ: the observer lies Δ beyond it, as the planar ``+Δ/R``).
    """
    r = np.asarray(r_station_m, float)
    up = r / np.linalg.norm(r)
    v_st = np.asarray(v_station_m_s, float)
    v_h = v_st - np.dot(v_st, up) * up
    norm = np.linalg.norm(v_h)
    if norm < 1e-3:
        raise ValueError("the station does not move (pole): the 3-D model needs a station off the poles")
    east = v_h / norm                      # ω × r about the true rotation axis: exactly east
    if heading_rad is None:
        if DIRECTIONS[direction] == 0:
            raise ValueError("direction must be 'with' or 'against' for the 3-D model (or give a heading)")
        h = DIRECTIONS[direction] * east
    else:
        north = np.cross(up, east)
        h = np.sin(heading_rad) * east + np.cos(heading_rad) * north
    v = velocity_m_s * (np.cos(angle_rad) * h - np.sin(angle_rad) * up)
    if displacement_m:
        normal = np.cross(up, h)
        angle = -displacement_m / np.linalg.norm(r)
        r, v = _rotate(r, normal, angle), _rotate(v, normal, angle)
    return r, v


@dataclass(frozen=True)
class AzEl3D:
    """3-D model values at the sample times: azimuth, elevation (rad), range (m), object GCRF."""

    azimuth_rad: np.ndarray
    elevation_rad: np.ndarray
    range_m: np.ndarray
    r_sat: np.ndarray


def ballistic_azel(s_rel_s, r_impact_m, v_impact_m_s, station_r_gcrf, station_v_gcrf, station_a_gcrf,
                   gcrf_to_itrf, lat_rad: float, lon_rad: float, *, force: str = "two-body", q=None) -> AzEl3D:
    """Azimuth and elevation of the 3-D trajectory from a station at times ``s`` relative to impact.

    The object's state at impact (GCRF) is propagated to ``s_rel_s`` (≤ 0) by
    :func:`trackproc.dynamics.reference.propagate_gcrf` (DOP853, rtol 1e-13; two-body or J2
    about the z axis of ``q``, the quasi-inertial frame of the impact epoch); the station's
    GCRF track at the same reception times (from
    :func:`trackproc.models.measurements.station_gcrf`) and the one-way light time give az/el.
    """
    from trackproc.dynamics import reference
    from trackproc.models import measurements as mm

    s = np.asarray(s_rel_s, float)
    q = np.eye(3) if q is None else np.asarray(q, float)
    r_sat, v_sat = reference.propagate_gcrf(r_impact_m, v_impact_m_s, s, q, force)
    a_sat, j_sat = reference.acceleration_gcrf(r_sat, v_sat, q, force)
    obs = mm.observables(r_sat, v_sat, a_sat, j_sat, station_r_gcrf, station_v_gcrf, station_a_gcrf,
                         gcrf_to_itrf, lat_rad, lon_rad, carrier_hz=1.0)
    return AzEl3D(azimuth_rad=obs.azimuth_rad, elevation_rad=obs.elevation_rad, range_m=obs.range_m, r_sat=r_sat)
