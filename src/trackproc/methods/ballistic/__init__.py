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
from trackproc.methods.ballistic.conic import (  # noqa: F401
    DIRECTIONS, MU_PAPER, R_PLANAR, angular_rate, anomaly_at, anomaly_by_ode, conic_to_impact, final_anomaly,
    impact_to_conic, mean_motion, radius, time_from_apogee)
from trackproc.methods.ballistic.encounter import (  # noqa: F401
    PlanarEncounter, elevation, horizon_anomalies, observer_motion_error, observer_speed)
from trackproc.methods.ballistic.three_d import AzEl3D, ballistic_azel, impact_state_3d  # noqa: F401
