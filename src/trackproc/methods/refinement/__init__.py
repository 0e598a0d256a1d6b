"""Refinement of a stale orbit from one Doppler pass (seed 004): the integral cost, the circular-orbit
constraints by Lagrange multipliers, and the observability of one pass.

Seed 004 refines the state ``X_T = (x0, y0, z0, vx, vy, vz, r_ka)`` at the *traverse point* (where
the range-rate vanishes) by minimising the integral over the pass

    I(X_T) = ∫_T (Vr_LSQ(t) - Vr(X_T, t))² dt                                  (eq. 14)

of the squared difference between the smoothed range-rate polynomial ``Vr_LSQ = φ(t)ᵀ C``
(eq. 1, :mod:`trackproc.methods.smoothing`) and the range-rate of the orbit, computed in the
image domain (eqs. 6-13, :mod:`trackproc.dynamics.measurement_spectra`; one-way light time) or,
for a two-way (round-trip) pass, the seed's own ``Vr = c/(2 f0) f_D`` convention, by the
estimator's round-trip model on the same Taylor trajectory and STM (:class:`IntegralModel`),
optionally under the circular-orbit constraints

    f(X_T) = (|r|² - r_ka²,  |v|² - μ/r_ka,  r·v) = 0                              (eq. 5)

by Lagrange multipliers, ``L = I + λᵀ f`` (eqs. 15-17), with the gradients of ``Vr`` from the
first-order two-dimensional DT (eqs. 18-21), i.e. the sensitivity spectra of the Taylor engine
carried through the range and range-rate spectra.

Here:

* **Quadrature.** ``I`` is evaluated by composite Gauss-Legendre quadrature
  (:func:`gauss_legendre`) over the parts of the pass covered by data (:func:`covered_intervals`;
  a polynomial says nothing inside a long gap). With nodes ``t_k`` and weights ``w_k``,
  ``I ≈ Σ w_k (Vr_LSQ(t_k) - Vr(X, t_k))²``: a weighted least-squares problem in *pseudo-observations*
  ``Vr_LSQ(t_k)``. It is normalised to the scale of the samples' own χ², ``χ²_I = I / (σ̄² Δt̄)``
  (σ̄ the RMS sample sigma, Δt̄ the mean sample spacing: the integral of a curve sampled every Δt̄
  is Δt̄ times the sum), which is the pseudo-sigma ``σ_k = σ̄ √(Δt̄ / w_k)`` of
  :func:`pseudo_sigma`. That puts the integral cost and an a-priori constraint on one scale and
  lets the unconstrained problem be solved by the ordinary solver,
  :func:`trackproc.methods.least_squares.solve`.
* **Constraints (KKT).** :func:`solve_kkt` is Gauss-Newton with equality constraints: each step
  solves the KKT system of the linearised problem,

      [ 2 JᵀJ   Aᵀ ] [ δ ]   [ 2 Jᵀ b ]
      [  A      0  ] [ λ ] = [  -f    ],

  (J the whitened Jacobian, b the whitened residual, A = ∂f/∂X), by the null-space method: a QR
  factorisation ``Aᵀ = [Y Z] [R; 0]`` splits ``δ = Y p + Z q`` with ``Rᵀ p = -f`` (the
  constraint step) and ``q`` the least-squares solution of ``J Z q ≈ b - J Y p`` (by the same
  QR + SVD as the unconstrained solver: no normal matrix is formed). After each step the
  state is put back on the constraint surface by minimum-norm Newton steps, so every iterate is
  feasible and the cost alone decides whether a step is accepted (Levenberg-Marquardt damping
  of ``q`` otherwise). The multipliers follow from the first KKT row at the solution,
  ``Aᵀ λ = -∇χ²`` (least squares), and the covariance is that of the constrained estimate,
  ``Z (Zᵀ JᵀJ Z)⁻¹ Zᵀ`` (zero across the constraint surface).
* **Covariance of the integral estimate.** The pseudo-observations are a smoothed curve, not
  independent samples; :func:`sandwich_covariance` propagates the polynomial's coefficient
  covariance (from ``smooth``) through the linearised estimator:
  ``Cov = K J_dᵀ Σ⁻¹ Φ Σ_C Φᵀ Σ⁻¹ J_d K + K J_pᵀ J_p K`` (K the solver's (constrained) inverse
  normal matrix, J_d/J_p its data/a-priori rows, Φ the basis at the nodes).
* **Observability.** :func:`observability` reports the singular values of the whitened
  Jacobian and, with the bias parameters projected out, the state directions a pass determines
  and those it cannot see, in radial / along-track / cross-track terms (the weakest is a
  rotation of the orbit about the station's geocentric axis, which leaves every
  station-satellite distance unchanged).
* **Geodesic steps.** One pass leaves narrow, curved valleys in the cost; :func:`geodesic_retraction`
  adds the geodesic acceleration of Transtrum & Sethna to each Gauss-Newton step (one extra
  model evaluation) so that it follows them instead of creeping.
* **A default a-priori.** :func:`element_covariance` maps independent errors of non-singular
  orbital elements to a Cartesian covariance: tight in the period, loose along the track, as a
  stale catalogue orbit is.

Pure numpy on SI units (m, m/s, s); nothing here reads files or prints.
"""
from trackproc.methods.refinement.quadrature import (  # noqa: F401
    covered_intervals, gauss_legendre, pseudo_sigma, range_rate_samples)
from trackproc.methods.refinement.constraints import (  # noqa: F401
    CONSTRAINT_NAMES, circular_constraints, circular_tolerance_covariance, constraint_scales)
from trackproc.methods.refinement.elements import (  # noqa: F401
    ELEMENT_NAMES, element_covariance, nonsingular_elements, state_from_elements)
from trackproc.methods.refinement.geodesic import CachedModel, geodesic_retraction  # noqa: F401
from trackproc.methods.refinement.integral import IntegralModel, sandwich_covariance  # noqa: F401
from trackproc.methods.refinement.kkt import FEASIBILITY_RTOL, KKTResult, solve_kkt, solve_soft_kkt  # noqa: F401
from trackproc.methods.refinement.observability import (  # noqa: F401
    PROFILE_NODES, RTN_NAMES, Observability, observability, profile_mixture)

__all__ = ["nonsingular_elements", "state_from_elements", "element_covariance", "ELEMENT_NAMES", "gauss_legendre",
           "covered_intervals", "pseudo_sigma", "circular_constraints", "constraint_scales", "IntegralModel",
           "KKTResult", "CachedModel", "geodesic_retraction", "solve_kkt", "solve_soft_kkt",
           "circular_tolerance_covariance", "sandwich_covariance", "observability",
           "Observability", "RTN_NAMES", "CONSTRAINT_NAMES", "profile_mixture", "PROFILE_NODES", "range_rate_samples"]
