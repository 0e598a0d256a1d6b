"""Least-squares smoothing of one pass by a generalized polynomial, and the time of closest approach.

Implements seed 004 eq. 1: ``y_LSQ(t) = phi(t)^T C`` with ``C = (Psi^T W Psi)^-1 Psi^T W y``, where
``Psi`` holds the basis functions at the sample times and ``W = diag(1/sigma_i^2)``. The basis is
Chebyshev (default) or Legendre on the pass interval mapped to [-1, 1], so the columns of ``Psi``
stay of order one at any degree. The normal matrix is never formed: the whitened system
``(Psi / sigma) C = y / sigma`` is solved by a QR factorization ``Q R``, and the error matrix is
``(Psi^T W Psi)^-1 = R^-1 R^-T``.

Pure numpy; times are seconds (``t_s``) from a reference epoch the caller chooses, values and
sigmas are in one SI unit (m, m/s, Hz, rad). A polynomial is rebuilt from its record as
``numpy.polynomial.Chebyshev(coef, domain=domain_s)(t_s)`` (or ``Legendre``).

Noise model: the residuals of real passes are not white (DopTrack Doppler: lag-1 correlation
0.3-0.9; a polynomial too flexible for its sample count makes them strongly negative). The noise
``r_i / sigma_i`` is modelled as a stationary first-order Gauss-Markov (AR(1), Ornstein-Uhlenbeck)
process with correlation ``rho`` between samples one typical step ``step_s`` apart, ``rho^(dt /
step_s)`` across a gap ``dt`` (:class:`NoiseModel`). ``rho`` is estimated from the residuals of the
white-noise fit by the method of moments *corrected for the fit's own projection*: the observed
ratio ``sum r_i r_(i-1) / sum r_i^2`` is matched to its expectation ``tr(L M C M) / tr(M C M)``
(``M = I - Q Q^T`` the residual projector, ``C(rho)`` the correlation matrix, ``L`` the lag-1
pairs), so an over-fitted polynomial's negative residual correlation is not mistaken for white
noise and a few coefficients' worth of fitted noise is not mistaken for correlation. An estimate
within 2 standard errors (``2 / sqrt(n - p)``) of white is taken as white, which leaves white-noise
passes fitted exactly as before. With ``rho > 0`` the fit is generalized least squares: the
whitened system is further transformed by the exact inverse Cholesky factor of ``C``
(``e_i = (x_i - a_i x_(i-1)) / sqrt(1 - a_i^2)``, ``a_i = rho^(dt_i / step_s)``), so the coefficient
covariance and the curve's sigma carry the correlation; the effective number of independent
samples is ``n_eff = 1 + sum_i (1 - a_i) / (1 + a_i)`` (``n (1 - rho) / (1 + rho)`` for a regular
pass).
Residual correlation can also be curve the polynomial does not follow. The AR(1) model is refused
(``NoiseModel.unresolved``: white noise kept, and the caller told) when its correlation reaches
``MAX_RHO``, when it would cap the degree below the white-noise choice while the BIC still falls,
or when its variance factor exceeds the white fit's by more than ``MAX_VARIANCE_RATIO`` (4).

Degree selection (``degree="auto"``): the Bayesian information criterion with the variance factor
profiled out, ``BIC(d) = n ln(chi2_d / n) + (d + 1) ln n``, minimized over ``d = 0..cap``, where
``chi2_d`` is the (generalized) weighted residual sum of squares: for AR(1) noise the exact profile
likelihood, so correlated noise is not paid for with extra terms. It depends only on the relative
weights, so a wrong overall sigma level does not change the chosen degree; and it compares every
degree with every other, so it is not stopped early by a vanishing odd or even coefficient as a
sequential F-test is (an S-curve has nearly zero even terms). The cap keeps at least
``MIN_EFFECTIVE_SAMPLES_PER_COEFFICIENT`` (2) effective samples per coefficient, ``d + 1 <= n_eff / 2``,
and at most ``max_degree``: with the cap the profiled BIC cannot run to near-interpolation, where
``ln chi2_d`` falls without bound (before it, 25 samples were fitted at degree 20 and 32 at 29).

The default upper limit of the search, 30, keeps the polynomial from ringing inside data gaps:
on the DopTrack passes, limits of 40 or 60 did not bring the TCAs closer to the upstream values
and moved some passes with long gaps by seconds. BIC optimizes the
whole curve, not a derived quantity such as an inflection point: on a simulated Doppler pass the
BIC degree leaves a TCA bias of about 3 sigma, which :func:`tca_degree_spread` (the scatter of the
TCA over neighbouring degrees) makes visible.

Outliers (``clip=K``): iterative K-sigma rejection on the studentized residuals
``u_i = r_i / (sigma_i sqrt(1 - h_i))`` of the samples in use (``h_i`` the leverage: a sample the
polynomial bends to has a smaller residual) and ``r_i / (sigma_i sqrt(1 + h_i))`` of the rejected ones
(a prediction), with the robust scale ``s = 1.4826 MAD(u)`` of the samples in use: a sample is
rejected when ``|u_i| > K s``; every sample (including those rejected before) is re-tested against
each new fit, until the rejected set stops changing. At most ``MAX_REJECTED_FRACTION`` (10 %) of a
pass is rejected: when more exceed the threshold, only the most extreme 10 % are, the others are
kept and the fit says so (``rejection_capped``): a pass where more than a tenth of the samples
disagree with the curve is a modelling problem, not a few bad samples. Rejected samples are
flagged, never removed.
"""

from trackproc.methods.smoothing.fit import (  # noqa: F401
    BASES, MAX_RHO, WHITE, NoiseModel, PolynomialFit, SmoothingError, design_matrix, fit_polynomial)
from trackproc.methods.smoothing.correlation import RHO_SIGNIFICANCE, estimate_noise  # noqa: F401
from trackproc.methods.smoothing.degree import (  # noqa: F401
    DEFAULT_MAX_DEGREE, MAD_TO_SIGMA, MAX_CLIP_ITERATIONS, MAX_REJECTED_FRACTION, MAX_VARIANCE_RATIO,
    MIN_EFFECTIVE_SAMPLES_PER_COEFFICIENT, degree_cap, select_degree, smooth_pass)
from trackproc.methods.smoothing.tca import (  # noqa: F401
    TCA_SPREAD_RATIO, ClosestApproach, closest_approach, degree_spread_width, tca_degree_spread, tca_uncertain)
