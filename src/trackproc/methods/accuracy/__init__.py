"""Accuracy of a predicted trajectory: mean, variance and correlation from the initial uncertainty.

Pure functions on numpy arrays, SI units (m, m/s, s). Three independent ways to the same
second moments, so that each checks the others:

1. **The image-domain method of seed 000** (eqs. 12-25). The random initial errors make the
   discretes of the trajectory's differential spectrum random variables, ``X(K, V)``. A
   *random spectrum* is stored as an array ``(..., 1 + m, n)``: slot 0 holds the discretes at
   ``V = 0`` and slot ``j`` their derivative with respect to the random variable ``v_j``
   (``j = 1..m``), so that ``X(K, V) = X(K, 0) + sum_j dX(K)/dv_j v_j``. For zero-mean V with
   covariance C (seed 000 eqs. 7-8; correlated errors are first reduced to uncorrelated
   normalised variables ``xi`` by ``V = L xi``, ``L L^T = C``, as seed 000 prescribes after
   eq. 5, see :func:`normalizing_factor`):

   * mean discretes ``m_x(K) = E[X(K, V)] = X(K, 0)``                          (eqs. 17-20)
   * ``Q(K, t1, t2) = X(., t1) * X(., t2)`` (Cauchy product) and its mean     (eqs. 21-23)
   * ``R_x(K, t1, t2) = m_q(K) - (m_x(., t1) * m_x(., t2))(K)
     = sum_j (W_j(., t1) * W_j(., t2))(K)``, ``W = dX/dV L``                     (eq. 24)
   * ``R_x(t1, t2) = sum_K R_x(K, t1, t2)``, ``D_x(t) = R_x(t, t)``           (eq. 25)

   The subtraction of eq. 24 is carried out algebraically (the ``m * m`` terms cancel
   exactly for spectra affine in V): done numerically it would subtract two numbers of the
   size of ``|r|^2 ~ 5e13 m^2`` to get ``sigma^2 ~ 1e4 m^2`` and lose seven digits. The
   Cauchy products are complete (``n1 + n2 - 1`` discretes), as in the paper's eqs. 33-34,
   whose ``t^6`` terms come from four discretes; their sum is then exactly the product of
   the two series' sums.

   The method is exact for models linear in the random variables (the seed's worked example,
   :func:`seed000_spectra`). For the nonlinear two-body / J2 motion the discretes are not
   affine in V; their first-order expansion ``X(K, 0) + dX(K)/dV V`` is what the DT engine's
   sensitivity spectra are (seed 004 eqs. 19-21 to first order, :mod:`trackproc.dynamics.taylor`),
   so :func:`state_spectra` + :func:`correlation` give the first-order (linear) covariance.
   Each step of the engine has its own expansion point (its start ``t_s``) and the scale
   ``H = t - t_s`` takes the place of the paper's ``H = t - t0``; the random part of every
   step's discretes still refers to the same initial errors V, so R(t1, t2) across steps is
   the same Cauchy product of two spectra.

2. **Linear covariance propagation** ``P(t) = Phi(t) P0 Phi(t)^T`` with the engine's state
   transition matrix (:func:`stm_covariance`). Mathematically the same first-order moments as
   1 (the sum over K of the sensitivity discretes is Phi): they agree to round-off.

3. **Monte Carlo**: N initial states drawn from ``N(x0, P0)`` (:func:`sample_initial_states`)
   propagated by the engine's batch mode, and their sample covariance
   (:func:`sample_covariance`). Includes every nonlinearity; agrees with 1 and 2 within its
   statistical bound (:func:`monte_carlo_bounds`) while the errors stay small enough for the
   first order to hold.

Frames: covariances of the six state components ``(x, y, z, vx, vy, vz)`` in an inertial
frame; :func:`rtn_rotation` resolves them along radial / along-track / cross-track axes of
the nominal orbit, and :func:`range_range_rate_jacobian` maps them to a ground station's
range and range-rate.
"""
from trackproc.dynamics.rtn import rtn_jacobian, rtn_rotation, to_rtn  # noqa: F401  (re-exported)
from trackproc.methods.accuracy.moments import (  # noqa: F401
    correlation, correlation_spectrum, mean_spectrum, normalizing_factor, variance)
from trackproc.methods.accuracy.seed000 import (  # noqa: F401
    seed000_enough_discretes, seed000_spectra, seed000_statistics, seed000_variance_exact,
    seed000_velocity_variance_exact, seed000_velocity_weight)
from trackproc.methods.accuracy.engine import (  # noqa: F401
    spectral_covariance, spectral_cross_covariance, spectral_factors, state_spectra)
from trackproc.methods.accuracy.sampling import (  # noqa: F401
    covariance_sd, monte_carlo_bounds, sample_covariance, sample_initial_states, stm_covariance,
    stm_cross_covariance)
from trackproc.methods.accuracy.observables import (  # noqa: F401
    correlation_coefficients, observable_covariance, range_range_rate_jacobian, sigmas)

__all__ = [
    "normalizing_factor", "mean_spectrum", "correlation_spectrum", "correlation", "variance",
    "seed000_spectra", "seed000_variance_exact", "seed000_velocity_variance_exact",
    "seed000_statistics", "seed000_enough_discretes", "seed000_velocity_weight",
    "state_spectra", "spectral_covariance", "spectral_cross_covariance", "spectral_factors",
    "stm_covariance", "stm_cross_covariance",
    "sample_initial_states", "sample_covariance", "monte_carlo_bounds", "covariance_sd",
    "rtn_rotation", "rtn_jacobian", "to_rtn", "range_range_rate_jacobian", "observable_covariance",
    "sigmas", "correlation_coefficients",
]


