"""Measurement spectra in the image domain: a ground station, the topocentric vector, the one-way
light-time range and range-rate, and their sensitivities to the initial state.

Seed 004 eqs. 7-13 in general form, on the per-step spectra of the Taylor engine
(:mod:`trackproc.dynamics.taylor`, through :class:`trackproc.dynamics.propagator.Trajectory`).
All spectra have H = 1 s (Taylor coefficients; docs/equations.md, notation) and live in the
quasi-inertial frame of the trajectory (GCRF rotated by ``q_ref``, the precession-nutation
matrix of its reference epoch).

Station (seed 004 eqs. 7-10)
    GCRF -> ITRF is ``W R3(ERA) Q`` (IAU 2006/2000A), so a station fixed at ``r_itrf`` is, in
    the quasi-inertial frame,

        r_st(t) = P(t) R3(theta(t))^T p(t),   P = q_ref Q(t)^T,  p = W(t)^T r_itrf.

    ``theta`` is the Earth Rotation Angle, exactly linear in UT1 and so, inside a day of a
    tabulated EOP (UT1-TAI interpolated linearly), exactly linear in SI time:
    ``theta(c + tau) = ERA(c) + omega tau``. The spectra of ``cos theta``, ``sin theta`` are then
    closed form, ``C(K) = cos(ERA(c) + K pi/2) omega^K/K!`` and the same with sin -- the solution
    of the seed 004 eq. 9 recurrence for a linear angle (seed eq. 7 writes
    ``S = q Omega t + S0``). ``P`` (precession-nutation since the reference epoch: 0.15
    arcsec a day) and ``p`` (polar motion) vary slowly; each is interpolated quadratically
    through nodes at most 30 min apart and enters as an exact Cauchy product with a
    degree-2 polynomial. ``frozen=True`` drops that drift (P = I, p and omega those of the
    reference epoch, ``theta = era0 + omega t``): the seed-paper model, and exactly
    :meth:`QuasiInertialFrame.station <trackproc.dynamics.frames.QuasiInertialFrame.station>`.
    Its error is measured in the tests and reported in ``docs/propagate.md`` (about 1 cm of
    station position after 15 minutes from the reference epoch, metres after a day).

Topocentric vector, range, range-rate (seed 004 eqs. 11-12)
    ``rho(t) = r_sat(t_e) - r_st(t)``, ``D2 = rho . rho`` (Cauchy products),
    ``D = sqrt(D2)`` (square-root rule, eq. 12), ``Vr(K) = (K+1) D(K+1)`` (derivative rule).

One-way light time (README "Units, sign conventions, time and frames"; :mod:`trackproc.models.light_time`)
    A sample is time-tagged at reception ``t`` and the satellite is taken at the emission time
    ``t_e = t - T(t)``, ``c T = |r_sat(t - T) - r_st(t)|``. Here ``T`` is itself a spectrum:
    the composition ``r_sat(t - T(t)) = sum_m (-T)^m / m! r_sat^(m)(t)`` is a Taylor shift done
    in the image domain (derivative rule for ``r^(m)``, Cauchy powers of ``T``; ``m <= 4``,
    whose remainder ``T^5 |r^(5)| / 120`` is below 1e-13 m for LEO and GEO), and ``T`` is found
    by fixed-point iteration on spectra, ``T <- sqrt(D2(T)) / c``, which contracts by
    ``|u . v| / c ~ 3e-5`` per pass (after the geometric range, three passes reach 1e-12 m;
    the loop stops when the predicted next change is below 1e-12 m). The range
    spectrum ``D`` is then the light-time range as a function of reception time, so the
    derivative rule gives exactly the ``doppler`` range-rate model
    ``dD/dt = u . (v_sat(t_e) - v_st(t)) / (1 + u . v_sat(t_e)/c)``. The ``instantaneous``
    model (Orekit's) is ``u . (v_sat(t_e) - v_st(t))``, the same times the light-time factor
    ``F = 1 + u . v_sat(t_e)/c``.

Sensitivities (seed 004 eqs. 19-21, first order)
    The engine's sensitivity spectra ``dX/dx0`` go through the same retarded-time operator.
    Differentiating ``D = |rho|`` with ``T = D/c`` gives, as spectra,

        dD/dx0 = (rho . dr_sat(t_e)/dx0) / (D + rho . v_sat(t_e)/c)        (quotient rule)

    -- the light-time correction factor appears in the denominator -- and
    ``d Vr/dx0`` is its derivative rule. The instantaneous model's partials add the
    derivative of ``F`` (evaluated at the samples).

Segments
    A range series converges only within the distance (in complex time) to the nearest zero of
    ``D2``, about ``rho / |v_rel|`` (100 s at the top of an 800-km pass), which is shorter than
    a pass. Samples are therefore grouped in segments inside one Taylor step, each expanded
    about its midpoint with half-width ``w`` at most ``0.8 tol^(1/n) rho/|v_rel|``; the
    truncation ``sum_{K=n-2,n-1} |D(K)| w^K`` is then checked against ``tol max(D(0), 1 m)``
    and failing segments are halved (all segments of a pass are computed together, as
    arrays with a leading segment axis).

Products of spectra are done as matrix products: the Cauchy product ``u*v`` is ``u @ M(v)``
with the upper-triangular Toeplitz matrix ``M(v)[l, K] = V(K - l)``, the derivative rule is a
constant matrix and re-expanding about another point is ``u @ B(delta)``,
``B[j, K] = C(j, K) delta^(j-K)``; the retarded-time operator is
``E = sum_m (-1)^m/m! D^m M(T)^m``.

Limits: one-way measurements (no two-way round trip); aberration and refraction neglected,
as in :mod:`trackproc.models.observables` (whose conventions and range-rate models these series
follow); the station must never coincide with the
satellite (``D2(0) > 0``).
"""

from trackproc.vocabulary import RANGE_RATE_MODELS, check_range_rate_model  # noqa: F401  (re-exported)
from trackproc.dynamics.measurement_spectra.series import (  # noqa: F401
    cauchy_sum, derivative_matrix, evaluate_segments, evaluate_series, product_matrix, series_reciprocal,
    series_sqrt, shift_matrix)
from trackproc.dynamics.measurement_spectra.station import (  # noqa: F401
    SLOW_NODE_SPACING_S, StationModel, rotation_spectra)
from trackproc.dynamics.measurement_spectra.segments import (  # noqa: F401
    LIGHT_TIME_TERMS, MAX_LIGHT_TIME_ITER, SEGMENT_SAFETY, SegmentSpectra, initial_segments, segment_spectra)
from trackproc.dynamics.measurement_spectra.predict import Prediction, predict  # noqa: F401

__all__ = ["RANGE_RATE_MODELS", "StationModel", "Prediction", "rotation_spectra", "predict",
           "segment_spectra", "LIGHT_TIME_TERMS"]
