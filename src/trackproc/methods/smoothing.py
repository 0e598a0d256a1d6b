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

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import chebyshev as _cheb
from numpy.polynomial import legendre as _leg

from trackproc.errors import ProcessingError

#: Supported bases: (numpy series class, Vandermonde function, derivative function).
BASES = {
    "chebyshev": (np.polynomial.Chebyshev, _cheb.chebvander, _cheb.chebder),
    "legendre": (np.polynomial.Legendre, _leg.legvander, _leg.legder),
}

#: Default upper bound of the degree search of ``degree="auto"``.
DEFAULT_MAX_DEGREE = 30
#: ``degree="auto"`` keeps at least this many effective samples per coefficient: d + 1 <= n_eff / 2.
MIN_EFFECTIVE_SAMPLES_PER_COEFFICIENT = 2.0
#: The rejection never flags more than this fraction of a pass.
MAX_REJECTED_FRACTION = 0.1
#: An AR(1) estimate within this many standard errors (1 / sqrt(n - p)) of white noise is white.
RHO_SIGNIFICANCE = 2.0
#: A TCA whose spread over neighbouring degrees exceeds this many formal sigmas is ``uncertain``.
TCA_SPREAD_RATIO = 3.0
#: An AR(1) fit whose variance factor exceeds the white fit's by more than this leaves curve out.
MAX_VARIANCE_RATIO = 4.0
#: Largest AR(1) correlation of consecutive samples (keeps the whitening transform finite).
MAX_RHO = 0.99
#: Iterations of the rejection loop before giving up (the last fit is kept, and said so).
MAX_CLIP_ITERATIONS = 30
#: 1 / Phi^-1(3/4): MAD -> standard deviation of a Gaussian.
MAD_TO_SIGMA = 1.482602218505602


class SmoothingError(ProcessingError):
    """A pass (one station, pass and kind) cannot be fitted; ``reason`` is a short code.

    Codes: ``too_few_points``, ``single_time``, ``all_rejected``, ``rank_deficient``,
    ``bad_input``, ``no_tca``.
    """

    def __init__(self, reason: str, message: str):
        self.reason = reason
        super().__init__(message, {"reason": reason})


@dataclass(frozen=True)
class NoiseModel:
    """AR(1) (first-order Gauss-Markov) model of the normalized noise ``r_i / sigma_i``.

    ``rho`` is the correlation of two samples ``step_s`` apart (0: white), ``rho^(dt / step_s)``
    for a separation ``dt``; ``rho_estimate`` the projection-corrected moment estimate before the
    significance test (``rho`` is 0 when it is within 2 standard errors of 0), ``lag1_observed`` the
    raw lag-1 correlation of the residuals it came from, ``degree`` the degree of that fit, and
    ``n_eff`` the effective number of independent samples of the times it was estimated on.
    ``unresolved``: the residual correlation could not be told apart from curve the polynomial
    does not follow (see :func:`smooth_pass`); the noise is then taken as white and the fit says so.
    """

    rho: float = 0.0
    step_s: float = 1.0
    rho_estimate: float = 0.0
    lag1_observed: float = float("nan")
    degree: int | None = None
    n_eff: float = float("nan")
    unresolved: bool = False

    @property
    def white(self) -> bool:
        return not self.rho > 0.0

    def neighbour_correlation(self, t_sorted: np.ndarray) -> np.ndarray:
        """Correlation ``a_i`` of each sample with the one before it (sorted times), length n - 1."""
        if self.white:
            return np.zeros(max(t_sorted.size - 1, 0))
        return np.minimum(self.rho ** (np.diff(t_sorted) / self.step_s), MAX_RHO)

    def effective_samples(self, t_s) -> float:
        """``n_eff = 1 + sum (1 - a_i) / (1 + a_i)``: n (1 - rho) / (1 + rho) for a regular pass."""
        t = np.sort(np.asarray(t_s, float))
        a = self.neighbour_correlation(t)
        return float(1.0 + np.sum((1.0 - a) / (1.0 + a))) if t.size else 0.0


WHITE = NoiseModel()


@dataclass(frozen=True)
class PolynomialFit:
    """A weighted least-squares polynomial over one pass (seed 004 eq. 1) and its statistics.

    ``coef`` are the series coefficients in ``basis`` on ``domain_s`` (seconds from the caller's
    epoch), ``cov_unscaled = (A^T W A)^-1`` the error matrix from the a-priori sigmas,
    ``variance_factor = chi2 / dof`` the a-posteriori variance factor, and
    ``cov_scaled = variance_factor * cov_unscaled``. ``used`` marks the samples in the final fit
    (False = rejected); ``residual`` is ``y - fit(t)`` for every sample, rejected ones included.
    ``rms`` is the root mean square of the used residuals (value unit), ``wrms`` that of the
    normalized residuals ``r / sigma`` (``wrms^2 = chi2 / n_used``).
    """

    basis: str
    domain_s: tuple[float, float]
    degree: int
    coef: np.ndarray
    cov_unscaled: np.ndarray
    chi2: float
    dof: int
    used: np.ndarray
    residual: np.ndarray
    rms: float
    wrms: float
    condition_number: float
    iterations: int = 1
    clip_converged: bool = True
    t_used: np.ndarray | None = None
    robust_scale: float = float("nan")
    degree_scores: dict = field(default_factory=dict)
    degree_at_limit: bool = False
    noise: NoiseModel = WHITE
    degree_cap: int | None = None
    rejection_capped: bool = False
    n_over_threshold: int = 0

    @property
    def n_eff(self) -> float:
        """Effective number of independent samples among those used (``n_used`` for white noise)."""
        return self.noise.effective_samples(self.t_used) if self.t_used is not None else float(self.n_used)

    @property
    def variance_factor(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def cov_scaled(self) -> np.ndarray:
        return self.cov_unscaled * self.variance_factor

    @property
    def n_used(self) -> int:
        return int(np.count_nonzero(self.used))

    @property
    def n_rejected(self) -> int:
        return int(self.used.size - np.count_nonzero(self.used))

    def covariance(self, scaled: bool = True) -> np.ndarray:
        return self.cov_scaled if scaled else self.cov_unscaled

    def series(self, deriv: int = 0):
        """The fitted curve (or its ``deriv``-th time derivative) as a numpy series in t_s."""
        cls = BASES[self.basis][0]
        poly = cls(self.coef, domain=list(self.domain_s))
        return poly.deriv(deriv) if deriv else poly

    def __call__(self, t_s, deriv: int = 0) -> np.ndarray:
        return self.series(deriv)(np.asarray(t_s, dtype=float))

    def design(self, t_s, deriv: int = 0) -> np.ndarray:
        """Rows ``d^m phi(t)/dt^m`` for the times ``t_s``: shape (n, degree + 1)."""
        return design_matrix(t_s, self.degree, self.domain_s, self.basis, deriv)

    def sigma(self, t_s, deriv: int = 0, scaled: bool = True) -> np.ndarray:
        """1-sigma of the fitted curve (or derivative) at ``t_s``: sqrt(diag(Phi Sigma Phi^T))."""
        phi = self.design(t_s, deriv)
        cov = self.covariance(scaled)
        return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", phi, cov, phi), 0.0))


@dataclass(frozen=True)
class ClosestApproach:
    """Time of closest approach from a fitted curve, with its first-order error propagation.

    ``t_s`` is the root of the ``order``-th derivative of the fit (0: range-rate = 0,
    1: range minimum, 2: inflection of a one-way Doppler S-curve); ``value`` the fitted curve at
    ``t_s`` (for one-way Doppler: the Doppler at closest approach, so ``fca = carrier + value``).
    ``cov`` (2x2, scaled by the variance factor) and ``cov_unscaled`` are the covariance of
    ``(t_s, value)``, including their correlation: ``J Sigma_C J^T`` with
    ``J = [dt*/dC; dvalue/dC]``, ``dt*/dC = -phi^(m)(t*) / f^(m+1)(t*)`` and
    ``dvalue/dC = phi(t*) + f'(t*) dt*/dC``.
    """

    definition: str
    order: int
    t_s: float
    value: float
    cov: np.ndarray
    cov_unscaled: np.ndarray
    slope: float
    n_candidates: int

    @property
    def sigma_s(self) -> float:
        return float(np.sqrt(self.cov[0, 0]))

    @property
    def sigma_s_unscaled(self) -> float:
        return float(np.sqrt(self.cov_unscaled[0, 0]))

    @property
    def value_sigma(self) -> float:
        return float(np.sqrt(self.cov[1, 1]))

    @property
    def value_sigma_unscaled(self) -> float:
        return float(np.sqrt(self.cov_unscaled[1, 1]))


def design_matrix(t_s, degree: int, domain_s, basis: str = "chebyshev", deriv: int = 0) -> np.ndarray:
    """Basis functions (or their ``deriv``-th time derivatives) at ``t_s``: the matrix Psi of seed 004 eq. 1.

    Column k is ``d^m/dt^m P_k(x(t))`` with ``x = (2 t - (a + b)) / (b - a)`` on ``domain_s = (a, b)``.
    """
    _, vander, der = _basis(basis)
    a, b = float(domain_s[0]), float(domain_s[1])
    x = (2.0 * np.asarray(t_s, dtype=float) - (a + b)) / (b - a)
    if deriv == 0:
        return vander(x, degree)
    if deriv > degree:
        return np.zeros((x.size, degree + 1))
    # Coefficients of d^m P_k / dt^m, for each k (columns), in the same basis; dx/dt = 2/(b-a).
    dcoef = der(np.eye(degree + 1), deriv, scl=2.0 / (b - a), axis=0)
    return vander(x, degree - deriv) @ dcoef


def fit_polynomial(t_s, y, sigma, degree: int, *, basis: str = "chebyshev", domain_s=None,
                   used=None, noise: NoiseModel | None = None) -> PolynomialFit:
    """Weighted least-squares fit of one degree, no rejection (seed 004 eq. 1).

    Parameters: ``t_s`` sample times (s), ``y`` values and ``sigma`` (> 0) their 1-sigma, in one
    unit; ``domain_s`` the interval mapped to [-1, 1] (default: min and max of ``t_s``);
    ``used`` a boolean mask of the samples to fit (default all); ``noise`` an AR(1) model of the
    normalized noise (default white: ``W = diag(1/sigma^2)``; else generalized least squares with
    ``W = (S C S)^-1``). Residuals are returned for all samples.
    Raises :class:`SmoothingError` when the samples cannot determine the polynomial.
    """
    t, y, s = _check_arrays(t_s, y, sigma)
    domain = _domain(t, domain_s)
    mask = np.ones(t.size, bool) if used is None else np.asarray(used, bool)
    _check_enough(t[mask], int(degree))
    return _solve(t, y, s, int(degree), domain, basis, mask, noise or WHITE)


def smooth_pass(t_s, y, sigma, degree: int | str = "auto", *, clip: float | None = 4.0,
                basis: str = "chebyshev", max_degree: int = DEFAULT_MAX_DEGREE,
                domain_s=None, noise: NoiseModel | str | None = "auto") -> PolynomialFit:
    """Fit a pass robustly: fixed or BIC-selected degree, AR(1) noise, bounded K-sigma rejection.

    ``degree`` an integer or ``"auto"`` (BIC over 0..``max_degree``, capped at ``n_eff / 2``
    coefficients); ``clip`` the rejection threshold K in robust standard deviations of the
    studentized residuals (None or 0: no rejection; never more than 10 % of the pass);
    ``noise`` ``"auto"`` (AR(1) estimated from the residuals, white when not significant),
    ``"white"`` / None, or a :class:`NoiseModel`. Raises :class:`SmoothingError` for an unfittable
    pass: fewer distinct times than the degree needs (``too_few_points``), one single time
    (``single_time``), too few samples left after rejection (``all_rejected``).
    """
    t, y, s = _check_arrays(t_s, y, sigma)
    domain = _domain(t, domain_s)
    auto = isinstance(degree, str)
    if auto and degree != "auto":
        raise ValueError(f"degree must be an integer or 'auto', got {degree!r}")
    if not auto and int(degree) < 0:
        raise ValueError(f"degree must be >= 0, got {degree}")
    if noise is None or noise == "white":
        noise = WHITE
    elif isinstance(noise, str) and noise != "auto":
        raise ValueError(f"noise must be 'auto', 'white' or a NoiseModel, got {noise!r}")
    used = np.ones(t.size, bool)
    if not auto:
        _check_enough(t, int(degree))
    clipping = clip is not None and clip > 0
    max_rejected = int(np.floor(MAX_REJECTED_FRACTION * t.size))
    history: list[bytes] = []
    fit = None
    for iteration in range(1, MAX_CLIP_ITERATIONS + 1):
        if np.count_nonzero(used) < 2:
            raise SmoothingError("all_rejected", f"only {np.count_nonzero(used)} of {t.size} samples "
                                 "left after outlier rejection")
        try:
            deg, scores, at_limit, model, cap = _choose(t[used], y[used], s[used], degree, basis, max_degree,
                                                        domain, noise)
        except SmoothingError as exc:
            if iteration > 1:
                raise SmoothingError("all_rejected", f"after outlier rejection: {exc}") from None
            raise
        fit = _replace(_solve(t, y, s, deg, domain, basis, used, model), degree_scores=scores,
                       degree_at_limit=at_limit, degree_cap=cap)
        if not clipping:
            return fit
        u, scale = _studentized(t, s, fit, domain, basis)
        # residuals at the rounding level of the values are never outliers (an exact curve)
        floor = 1e3 * np.finfo(float).eps * float(np.max(np.abs(y[used]))) / s
        over = np.abs(u) > np.maximum(clip * scale, floor)
        n_over = int(np.count_nonzero(over))
        capped = n_over > max_rejected
        if capped:     # keep all but the most extreme tenth: this is not "a few bad samples"
            keep_out = np.argsort(-np.abs(u) / np.maximum(clip * scale, floor), kind="stable")[:max_rejected]
            over = np.zeros(t.size, bool)
            over[keep_out] = True
        new_used = ~over
        fit = _replace(fit, iterations=iteration, robust_scale=scale, rejection_capped=capped,
                       n_over_threshold=n_over)
        if np.array_equal(new_used, used):
            return fit
        key = np.packbits(new_used).tobytes()
        if key in history:        # the rejected set cycles: stop, keep this fit, say so
            return _replace(fit, clip_converged=False)
        history.append(np.packbits(used).tobytes())
        used = new_used
    return _replace(fit, clip_converged=False)


def select_degree(t_s, y, sigma, *, basis: str = "chebyshev", max_degree: int = DEFAULT_MAX_DEGREE,
                  domain_s=None, noise: NoiseModel | None = None) -> tuple[int, dict, bool]:
    """Degree minimizing ``BIC(d) = n ln(chi2_d / n) + (d + 1) ln n`` over ``0..cap``.

    ``chi2_d`` is the weighted (for an AR(1) ``noise``: generalized) residual sum of squares. One QR
    factorization of the whitened design matrix at the largest degree gives every nested fit:
    ``chi2_d = |y_w|^2 - |(Q^T y_w)[:d+1]|^2``. The search stops at the smallest of ``max_degree``,
    ``n_distinct - 2`` (each candidate keeps a degree of freedom) and the effective-sample cap
    ``floor(n_eff / 2) - 1`` (:func:`degree_cap`). Returns (degree, {degree: BIC}, at_limit) where
    ``at_limit`` says the minimum is at the upper end of the search (more terms might help).
    """
    t, y, s = _check_arrays(t_s, y, sigma)
    domain = _domain(t, domain_s)
    dmax = degree_cap(t, max_degree, noise)
    order = np.argsort(t, kind="stable")
    t, y, s = t[order], y[order], s[order]
    a = _whiten(t, design_matrix(t, dmax, domain, basis) / s[:, None], noise)
    yw = _whiten(t, y / s, noise)
    q, r = np.linalg.qr(a)
    qty = q.T @ yw
    total = float(yw @ yw)
    n = t.size
    scores = {}
    tiny = np.finfo(float).tiny
    for d in range(dmax + 1):
        chi2 = max(total - float(qty[: d + 1] @ qty[: d + 1]), 0.0)
        # Guard against cancellation: recompute small chi2 directly from the residual.
        if chi2 < 1e-8 * total:
            coef = np.linalg.lstsq(r[: d + 1, : d + 1], qty[: d + 1], rcond=None)[0]
            res = yw - a[:, : d + 1] @ coef
            chi2 = float(res @ res)
        scores[d] = n * np.log(max(chi2, tiny) / n) + (d + 1) * np.log(n)
    best = min(scores, key=scores.get)
    return best, scores, best == dmax


def degree_cap(t_s, max_degree: int = DEFAULT_MAX_DEGREE, noise: NoiseModel | None = None) -> int:
    """Largest degree ``degree="auto"`` may choose for samples at ``t_s``.

    The smallest of ``max_degree``, ``n_distinct - 2`` and ``floor(n_eff / 2) - 1`` (at least
    two effective samples per coefficient; ``n_eff`` from the AR(1) ``noise``, ``n`` for white).
    Raises :class:`SmoothingError` when not even a constant can be fitted and tested.
    """
    t = np.asarray(t_s, float)
    n_distinct = np.unique(t).size
    if n_distinct < 2:
        raise SmoothingError("single_time", f"all {t.size} samples at one time: no curve can be fitted")
    n_eff = (noise or WHITE).effective_samples(t) if noise is not None and not noise.white else float(t.size)
    by_samples = int(np.floor(n_eff / MIN_EFFECTIVE_SAMPLES_PER_COEFFICIENT + 1e-9)) - 1
    dmax = int(min(max_degree, n_distinct - 2, t.size - 2, max(by_samples, 0)))
    if dmax < 0:
        raise SmoothingError("too_few_points", f"{t.size} samples are too few to fit and test a curve")
    return dmax


def estimate_noise(t_s, y, sigma, degree: int, *, basis: str = "chebyshev", domain_s=None) -> NoiseModel:
    """AR(1) correlation of the normalized noise from the residuals of a white-noise fit of ``degree``.

    Method of moments corrected for the projection of the fit: with ``z = M u`` the normalized
    residuals (``M = I - Q Q^T``, ``Q`` an orthonormal basis of the whitened design matrix) and
    ``u`` unit-variance noise of correlation ``C(rho)`` (``rho^(|t_i - t_j| / step)``), the observed
    ``c = sum z_i z_(i-1) / sum z_i^2`` is solved for ``rho`` from
    ``E[sum z_i z_(i-1)] / E[sum z_i^2] = tr(L M C M) / tr(M C M)``; both traces cost O(n p) because
    ``C`` is Markov (:func:`_ou_apply`). ``step`` is the median sample spacing. An estimate within
    ``RHO_SIGNIFICANCE`` standard errors (``1 / sqrt(n - p)``) of white gives ``rho = 0``.
    """
    t, y, s = _check_arrays(t_s, y, sigma)
    domain = _domain(t, domain_s)
    order = np.argsort(t, kind="stable")
    t, y, s = t[order], y[order], s[order]
    n, p = t.size, int(degree) + 1
    steps = np.diff(t)
    positive = steps[steps > 0]
    step = float(np.median(positive)) if positive.size else 1.0
    if n - p < 4:
        return NoiseModel(step_s=step, degree=int(degree), n_eff=float(n))
    a = design_matrix(t, int(degree), domain, basis) / s[:, None]
    q, _ = np.linalg.qr(a)
    yw = y / s
    z = yw - q @ (q.T @ yw)
    den = float(z @ z)
    if not den > 0:
        return NoiseModel(step_s=step, degree=int(degree), n_eff=float(n))
    c_obs = float(z[1:] @ z[:-1]) / den
    lag1 = c_obs

    def expected(rho: float) -> float:
        model = NoiseModel(rho=rho, step_s=step)
        acorr = model.neighbour_correlation(t)
        w = _ou_apply(acorr, q)
        g = q.T @ w
        tr_mcm = n - float(np.sum(q * w))
        lag = (float(np.sum(acorr)) - float(np.sum(q[1:] * w[:-1])) - float(np.sum(w[1:] * q[:-1]))
               + float(np.sum((q[1:] @ g) * q[:-1])))
        return lag / tr_mcm

    e0 = expected(0.0)
    if c_obs <= e0:
        rho_hat = 0.0
    elif c_obs >= expected(MAX_RHO):
        rho_hat = MAX_RHO
    else:
        from scipy.optimize import brentq

        rho_hat = float(brentq(lambda r: expected(r) - c_obs, 0.0, MAX_RHO, xtol=1e-6))
    significant = (c_obs - e0) > RHO_SIGNIFICANCE / np.sqrt(n - p)
    rho = rho_hat if significant else 0.0
    model = NoiseModel(rho=rho, step_s=step, rho_estimate=rho_hat, lag1_observed=lag1, degree=int(degree))
    return _replace(model, n_eff=model.effective_samples(t))


def closest_approach(fit: PolynomialFit, kind: str, doppler_mode: str = "one-way") -> ClosestApproach:
    """Time of closest approach (TCA) of a fitted pass, its standard error and the curve value there.

    - ``range_rate``: the zero of the fitted range-rate where it goes from negative to positive;
      ``sigma_t = sigma_f(t*) / |f'(t*)|``.
    - ``range``: the minimum of the fitted range (zero of f', f'' > 0).
    - ``doppler``, one-way (received minus nominal carrier, Hz): the transmitter's own frequency
      offset is unknown, so the zero of the Doppler is not the TCA. The TCA is the inflection point
      of the S-curve (zero of f'', f''' > 0: the steepest descent), which an offset and a linear
      drift of the onboard oscillator do not move; ``value`` there is the Doppler at closest
      approach, ``fca = carrier + value``. This is the definition of DopTrack's own processing
      (``estimate_tca``: root of the second derivative of the fitted curve; ``fca = fit(tca)``).
    - ``doppler``, two-way: the zero of the Doppler where it goes from positive to negative.

    Among several roots inside the pass, the one with the steepest fitted curve is taken
    (the S-curve is steepest at closest approach); roots outside the fitted interval are never used.
    Raises :class:`SmoothingError` (``no_tca``) when no root of the right sign lies in the pass.
    """
    if kind == "range_rate":
        order, sign, definition = 0, +1, "zero of the fitted range-rate (negative to positive)"
    elif kind == "range":
        order, sign, definition = 1, +1, "minimum of the fitted range (zero of its derivative)"
    elif kind == "doppler" and doppler_mode == "two-way":
        order, sign, definition = 0, -1, "zero of the fitted two-way Doppler (positive to negative)"
    elif kind == "doppler":
        order, sign, definition = 2, +1, ("inflection point of the fitted one-way Doppler S-curve "
                                          "(zero of the second derivative, steepest descent)")
    else:
        raise ValueError(f"no closest approach is defined for kind {kind!r}")

    g = fit.series(order)
    gp = fit.series(order + 1)
    candidates = _real_roots(g, fit.domain_s)
    good = [r for r in candidates if sign * gp(r) > 0]
    if not good:
        what = {0: "zero", 1: "minimum", 2: "inflection point"}[order]
        found = f" ({len(candidates)} of the wrong sense)" if candidates else ""
        raise SmoothingError("no_tca", f"no {what} of the fitted {kind.replace('_', '-')} inside the pass"
                             f"{found}: closest approach not observed")
    if order == 2:      # Doppler S-curve: steepest descent = most negative f'
        f1 = fit.series(1)
        t_star = min(good, key=lambda r: f1(r))
    elif order == 1:    # range: the lowest minimum
        t_star = min(good, key=lambda r: fit(r))
    else:               # steepest crossing
        t_star = max(good, key=lambda r: abs(gp(r)))

    slope = float(gp(t_star))
    phi_m = design_matrix([t_star], fit.degree, fit.domain_s, fit.basis, order)[0]
    phi_0 = design_matrix([t_star], fit.degree, fit.domain_s, fit.basis, 0)[0]
    dt_dc = -phi_m / slope
    dv_dc = phi_0 + float(fit(t_star, 1)) * dt_dc
    jac = np.vstack([dt_dc, dv_dc])
    cov_u = jac @ fit.cov_unscaled @ jac.T
    return ClosestApproach(definition=definition, order=order, t_s=float(t_star), value=float(fit(t_star)),
                           cov=cov_u * fit.variance_factor, cov_unscaled=cov_u, slope=slope,
                           n_candidates=len(candidates))


def tca_uncertain(fit: PolynomialFit, ca: ClosestApproach, spread_s: float) -> bool:
    """True when the TCA's formal sigma does not describe its error: its spread over neighbouring
    degrees exceeds ``TCA_SPREAD_RATIO`` (3) sigmas (the curve, not the noise, limits it), or the
    residual correlation could not be modelled (``fit.noise.unresolved``: the sigma assumes white
    noise that is not; in simulation such TCAs were off by 4-9 sigma)."""
    return bool(fit.noise.unresolved or (math.isfinite(spread_s) and spread_s > TCA_SPREAD_RATIO * ca.sigma_s))


def degree_spread_width(degree: int) -> int:
    """Half-width of the degree window of :func:`tca_degree_spread`: ``max(2, ceil(degree / 5))``.

    A fixed +-2 misses the slow drift of the TCA with degree on passes whose curve the
    polynomial does not resolve (a low DopTrack pass: -17 s at degree 26, -19 s at 29, -27 s at 36,
    while +-2 gives a spread of 1.4 s); +-20 % of the degree follows it.
    """
    return max(2, int(np.ceil(degree / 5.0)))


def tca_degree_spread(t_s, y, sigma, fit: PolynomialFit, kind: str, doppler_mode: str = "one-way",
                      width: int | None = None) -> tuple[float, float, int]:
    """Sensitivity of the TCA to the choice of degree: a model-error indicator.

    Refits the samples ``fit`` used with degrees ``fit.degree - width .. fit.degree + width`` (default
    width: :func:`degree_spread_width`) and
    returns the standard deviation of t* and of the curve value at t* over those that give a
    closest approach, and how many did (NaN when fewer than 3). The coefficient covariance cannot
    show this error: it assumes the polynomial of the chosen degree is the true curve.
    """
    t, yy, s = _check_arrays(t_s, y, sigma)
    if width is None:
        width = degree_spread_width(fit.degree)
    times, values = [], []
    for d in range(max(0, fit.degree - width), fit.degree + width + 1):
        try:
            other = fit if d == fit.degree else fit_polynomial(t, yy, s, d, basis=fit.basis,
                                                               domain_s=fit.domain_s, used=fit.used,
                                                               noise=fit.noise)
            ca = closest_approach(other, kind, doppler_mode)
        except SmoothingError:
            continue
        times.append(ca.t_s)
        values.append(ca.value)
    if len(times) < 3:
        return float("nan"), float("nan"), len(times)
    return float(np.std(times, ddof=1)), float(np.std(values, ddof=1)), len(times)


# --------------------------------------------------------------------------- internals


def _basis(basis: str):
    try:
        return BASES[basis]
    except KeyError:
        raise ValueError(f"unknown basis {basis!r}; expected one of {sorted(BASES)}") from None


def _check_arrays(t_s, y, sigma):
    t = np.asarray(t_s, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    s = np.broadcast_to(np.asarray(sigma, dtype=float), t.shape).astype(float)
    if y.shape != t.shape:
        raise ValueError(f"t_s and y differ in length: {t.size} and {y.size}")
    if t.size == 0:
        raise SmoothingError("too_few_points", "no samples")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise SmoothingError("bad_input", "non-finite time or value")
    if not np.all(np.isfinite(s) & (s > 0)):
        raise SmoothingError("bad_input", "sigma must be finite and > 0 for every sample")
    return t, y, s


def _domain(t, domain_s):
    if domain_s is None:
        a, b = float(t.min()), float(t.max())
    else:
        a, b = float(domain_s[0]), float(domain_s[1])
    if not b > a:
        raise SmoothingError("single_time", f"all {t.size} samples at one time: no curve can be fitted")
    return (a, b)


def _check_enough(t, degree: int) -> None:
    n_distinct = np.unique(t).size
    if n_distinct < 2:
        raise SmoothingError("single_time", f"all {t.size} samples at one time: no curve can be fitted")
    if n_distinct < degree + 2:
        raise SmoothingError("too_few_points", f"{t.size} samples at {n_distinct} distinct times; degree "
                             f"{degree} needs at least {degree + 2} (degree + 1 coefficients and one "
                             "degree of freedom)")


def _solve(t, y, s, degree, domain, basis, used, noise: NoiseModel = WHITE) -> PolynomialFit:
    """QR solution of the whitened system for the samples ``used``; residuals for all samples.

    White noise: rows ``psi_i / sigma_i``; AR(1) noise: those rows, in time order, further
    whitened by the inverse Cholesky factor of the correlation (generalized least squares).
    """
    psi = design_matrix(t, degree, domain, basis)
    idx = np.flatnonzero(used)
    idx = idx[np.argsort(t[idx], kind="stable")]
    tu = t[idx]
    a = _whiten(tu, psi[idx] / s[idx, None], noise)
    yw = _whiten(tu, y[idx] / s[idx], noise)
    q, r = np.linalg.qr(a)
    sv = np.linalg.svd(r, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    if not cond < 1.0 / (np.finfo(float).eps * 1e3):
        raise SmoothingError("rank_deficient", f"degree {degree} is not determined by the sample times "
                             f"(condition number {cond:.3g})")
    coef = np.linalg.solve(r, q.T @ yw)
    r_inv = np.linalg.solve(r, np.eye(degree + 1))
    cov = r_inv @ r_inv.T
    residual = y - psi @ coef
    ru = residual[used]
    chi2 = float(np.sum((yw - a @ coef) ** 2))
    n_used = int(np.count_nonzero(used))
    return PolynomialFit(
        basis=basis, domain_s=domain, degree=degree, coef=coef, cov_unscaled=cov, chi2=chi2,
        dof=n_used - (degree + 1), used=np.asarray(used, bool).copy(), residual=residual,
        rms=float(np.sqrt(np.mean(ru ** 2))), wrms=float(np.sqrt(np.mean((ru / s[used]) ** 2))),
        condition_number=cond, noise=noise, t_used=tu)


def _replace(fit: PolynomialFit, **changes) -> PolynomialFit:
    from dataclasses import replace
    return replace(fit, **changes)


def _real_roots(series, domain) -> list[float]:
    """Real roots of a numpy series inside [a, b], polished by Newton steps."""
    a, b = domain
    if series.degree() < 1:
        return []
    roots = series.roots()
    half = 0.5 * (b - a)
    d1 = series.deriv()
    out = []
    for z in roots:
        if abs(z.imag) > 1e-3 * half:
            continue
        x = float(z.real)
        for _ in range(5):
            slope = d1(x)
            if slope == 0:
                break
            step = series(x) / slope
            x -= step
            if abs(step) < 1e-12 * half:
                break
        if a <= x <= b and np.isfinite(x):
            out.append(x)
    out = sorted(set(np.round(out, 9)))
    return [float(v) for v in out]


def _choose(t, y, s, degree, basis, max_degree, domain, noise):
    """(degree, BIC scores, at_limit, noise model, cap) for the samples in use."""
    if not isinstance(degree, str):
        _check_enough(t, int(degree))
        model = estimate_noise(t, y, s, int(degree), basis=basis, domain_s=domain) if noise == "auto" else noise
        return int(degree), {}, False, model, None
    if noise == "auto":
        # rho from the residuals of the white-noise choice: a degree that absorbs the curve (on
        # correlated noise the white BIC over-fits, which the projection correction allows for)
        d0 = select_degree(t, y, s, basis=basis, max_degree=max_degree, domain_s=domain)[0]
        model = estimate_noise(t, y, s, d0, basis=basis, domain_s=domain)
    else:
        model = noise
    deg, scores, at_limit = select_degree(t, y, s, basis=basis, max_degree=max_degree, domain_s=domain,
                                          noise=model)
    cap = degree_cap(t, max_degree, model)
    if noise == "auto" and not model.white and (model.rho >= MAX_RHO or (at_limit and cap < d0)
                                                 or _variance_ratio(t, y, s, d0, deg, domain, basis, model)
                                                 > MAX_VARIANCE_RATIO):
        # AR(1) noise would leave fewer coefficients than the curve needs (or the correlation is at
        # its bound): correlated noise and unresolved curve cannot be told apart with these samples
        model = _replace(model, rho=0.0, n_eff=float(t.size), unresolved=True)
        deg, scores, at_limit = select_degree(t, y, s, basis=basis, max_degree=max_degree, domain_s=domain)
        cap = degree_cap(t, max_degree, model)
    return deg, scores, at_limit, model, cap


def _variance_ratio(t, y, s, d_white, d_ar1, domain, basis, model) -> float:
    """Variance factor of the AR(1) fit over that of the white-noise fit of the same samples.

    Both estimate the marginal noise variance when the AR(1) model holds (measured 1.1 at rho 0.6,
    1.3-2.2 at rho 0.9: the white over-fit absorbs some low-frequency noise); when the AR(1) fit
    has too few terms for the curve, its whitened residuals carry the curve (ratios of 10^3-10^10
    on high passes sampled every 10 s and a two-way range-rate pass at 1 mm/s)."""
    used = np.ones(t.size, bool)
    white = _solve(t, y, s, d_white, domain, basis, used)
    ar1 = _solve(t, y, s, d_ar1, domain, basis, used, model)
    return ar1.variance_factor / white.variance_factor if white.variance_factor > 0 else math.inf


def _studentized(t, s, fit: PolynomialFit, domain, basis):
    """Residuals over their own standard deviation (leverage-corrected), and their robust scale."""
    psi = design_matrix(t, fit.degree, domain, basis) / s[:, None]
    used = fit.used
    _, r = np.linalg.qr(psi[used])
    g = np.linalg.solve(r.T, psi.T).T          # psi R^-1: hat diagonal on the used rows
    h = np.sum(g * g, axis=1)
    z = fit.residual / s
    u = np.where(used, z / np.sqrt(np.maximum(1.0 - h, 1e-6)), z / np.sqrt(1.0 + h))
    uu = u[used]
    scale = MAD_TO_SIGMA * float(np.median(np.abs(uu - np.median(uu))))
    if not scale > 0.0:
        scale = float(np.sqrt(fit.chi2 / max(fit.dof, 1)))
    return u, scale


def _whiten(t_sorted, x, noise: NoiseModel | None):
    """Apply the inverse Cholesky factor of the AR(1) correlation (rows in time order)."""
    if noise is None or noise.white:
        return x
    a = noise.neighbour_correlation(t_sorted)
    out = np.array(x, dtype=float, copy=True)
    scale = 1.0 / np.sqrt(1.0 - a * a)
    if out.ndim == 1:
        out[1:] = (x[1:] - a * x[:-1]) * scale
    else:
        out[1:] = (x[1:] - a[:, None] * x[:-1]) * scale[:, None]
    return out


def _markov_sum(a, x):
    """``f_0 = x_0``, ``f_i = x_i + a_i f_(i-1)`` along axis 0: a parallel prefix scan, log2(n) steps."""
    f = np.array(x, dtype=float, copy=True)
    coef = np.concatenate([[0.0], np.asarray(a, float)])
    if f.ndim > 1:
        coef = coef.reshape((-1,) + (1,) * (f.ndim - 1))
    k = 1
    while k < f.shape[0]:
        # (A, X) after (A', X') = (A A', A X' + X): combine each element with the one k before
        f[k:] = f[k:] + coef[k:] * f[:-k]
        coef[k:] = coef[k:] * coef[:-k]
        k *= 2
    return f


def _ou_apply(a, x):
    """``C x`` for the Markov correlation ``C_ij = prod a_k`` between i and j (O(n p))."""
    forward = _markov_sum(a, x)
    backward = _markov_sum(a[::-1], x[::-1])[::-1]
    return forward + backward - x
