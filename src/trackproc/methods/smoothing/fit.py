"""The smoothing polynomial of one pass (implements seed 004 eq. 1, ``y_LSQ(t) = phi(t)^T C``): the
bases, the design matrix, the (generalized) weighted least-squares fit by QR with the AR(1)
whitening of :class:`NoiseModel`, and the fit's result :class:`PolynomialFit`. About 500 lines:
:class:`DesignRows` (one pass's design matrices and QR factors, shared by the degree search and the
fit) belongs with the fit whose matrices it holds, and the AR(1) products' numpy and compiled paths
(the same numbers) stay beside each other.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.polynomial import chebyshev as _cheb
from numpy.polynomial import legendre as _leg

from trackproc.errors import ProcessingError


#: Supported bases: (numpy series class, Vandermonde function, derivative function).
BASES = {
    "chebyshev": (np.polynomial.Chebyshev, _cheb.chebvander, _cheb.chebder),
    "legendre": (np.polynomial.Legendre, _leg.legvander, _leg.legder),
}


#: Largest AR(1) correlation of consecutive samples (keeps the whitening transform finite).
MAX_RHO = 0.99


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

    #: series made so far, by derivative order (the TCA search asks for the same ones many times)
    _series: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def series(self, deriv: int = 0):
        """The fitted curve (or its ``deriv``-th time derivative) as a numpy series in t_s (made
        once per order: treat it as read-only)."""
        made = self._series.get(deriv)
        if made is None:
            if deriv:
                # one order from the one below: numpy's m-th derivative is m first derivatives with
                # the same scale in turn (chebder / legder), so the same bits with one pass, not m
                below = self.series(deriv - 1)
                if type(below) is np.polynomial.Chebyshev and below.coef.size > 1:
                    made = type(below)(_chebder1(below.coef, below.mapparms()[1]), below.domain, below.window,
                                       below.symbol)
                else:
                    made = below.deriv(1)
            else:
                made = BASES[self.basis][0](self.coef, domain=list(self.domain_s))
            self._series[deriv] = made
        return made

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


def _chebder1(coef, scl) -> np.ndarray:
    """``numpy.polynomial.chebyshev.chebder(coef, 1, scl)`` of a 1-D series of 2 or more terms:
    numpy's recurrence for the derivative's coefficients (``c'_(j-1) = c'_(j+1) + 2 j c_j``), step by
    step in the same order in Python floats, so the same bits without numpy's per-element indexing."""
    c = [float(v) * scl for v in coef]
    n = len(c) - 1
    der = [0.0] * n
    for j in range(n, 2, -1):
        der[j - 1] = (2 * j) * c[j]
        c[j - 2] += (j * c[j]) / (j - 2)
    if n > 1:
        der[1] = 4 * c[2]
    der[0] = c[1]
    return np.array(der)


def design_matrix(t_s, degree: int, domain_s, basis: str = "chebyshev", deriv: int = 0) -> np.ndarray:
    """Basis functions (or their ``deriv``-th time derivatives) at ``t_s``: the matrix Psi of seed 004 eq. 1.

    Column k is ``d^m/dt^m P_k(x(t))`` with ``x = (2 t - (a + b)) / (b - a)`` on ``domain_s = (a, b)``.
    """
    _, vander, der = basis_functions(basis)
    a, b = float(domain_s[0]), float(domain_s[1])
    x = (2.0 * np.asarray(t_s, dtype=float) - (a + b)) / (b - a)
    if deriv == 0:
        return vander(x, degree)
    if deriv > degree:
        return np.zeros((x.size, degree + 1))
    # Coefficients of d^m P_k / dt^m, for each k (columns), in the same basis; dx/dt = 2/(b-a).
    kernels = _compiled() if basis == "chebyshev" else None
    if kernels is not None:     # numpy's chebder, compiled (the same bits)
        dcoef = kernels.cheb_der_rows(np.eye(degree + 1), deriv, 2.0 / (b - a))
    else:
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
    t, y, s = check_arrays(t_s, y, sigma)
    domain = pass_domain(t, domain_s)
    mask = np.ones(t.size, bool) if used is None else np.asarray(used, bool)
    check_enough(t[mask], int(degree))
    return solve_fit(t, y, s, int(degree), domain, basis, mask, noise or WHITE)


def basis_functions(basis: str):
    try:
        return BASES[basis]
    except KeyError:
        raise ValueError(f"unknown basis {basis!r}; expected one of {sorted(BASES)}") from None


def check_arrays(t_s, y, sigma):
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


def pass_domain(t, domain_s):
    if domain_s is None:
        a, b = float(t.min()), float(t.max())
    else:
        a, b = float(domain_s[0]), float(domain_s[1])
    if not b > a:
        raise SmoothingError("single_time", f"all {t.size} samples at one time: no curve can be fitted")
    return (a, b)


def distinct_count(t) -> int:
    """``np.unique(t).size``: for times in increasing order (a pass's, every step of the degree
    search) one comparison of neighbours instead of the sorted copy (the same count: equal
    neighbours are what ``unique`` merges)."""
    t = np.asarray(t)
    if t.ndim == 1 and t.size > 1:
        later, earlier = t[1:], t[:-1]
        if (later >= earlier).all():        # (False for a NaN: unique decides)
            return 1 + int(np.count_nonzero(later != earlier))
    return np.unique(t).size


def check_enough(t, degree: int, n_distinct: int | None = None) -> None:
    """Raise the :class:`SmoothingError` of a fit of ``degree`` to times ``t`` it cannot determine
    (``n_distinct``: the number of distinct times, when the caller has it)."""
    if n_distinct is None:
        n_distinct = distinct_count(t)
    if n_distinct < 2:
        raise SmoothingError("single_time", f"all {t.size} samples at one time: no curve can be fitted")
    if n_distinct < degree + 2:
        raise SmoothingError("too_few_points", f"{t.size} samples at {n_distinct} distinct times; degree "
                             f"{degree} needs at least {degree + 2} (degree + 1 coefficients and one "
                             "degree of freedom)")


def used_in_time_order(t, used) -> np.ndarray:
    """The indices of the samples ``used``, in time order (stable): the rows a fit whitens."""
    idx = np.flatnonzero(used)
    return idx[np.argsort(t[idx], kind="stable")]


def check_rank(r, degree: int) -> float:
    """The condition number of ``r``, the triangular factor of a degree-``degree`` fit; a
    ``rank_deficient`` :class:`SmoothingError` when it is beyond 1/(1000 eps) (the sample times do
    not determine the coefficients)."""
    sv = np.linalg.svd(r, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    if not cond < 1.0 / (np.finfo(float).eps * 1e3):
        raise SmoothingError("rank_deficient", f"degree {degree} is not determined by the sample times "
                             f"(condition number {cond:.3g})")
    return cond


def solve_fit(t, y, s, degree, domain, basis, used, noise: NoiseModel = WHITE, rows=None,
              _kept: bool = True) -> PolynomialFit:
    """QR solution of the whitened system for the samples ``used``; residuals for all samples.

    White noise: rows ``psi_i / sigma_i``; AR(1) noise: those rows, in time order, further
    whitened by the inverse Cholesky factor of the correlation (generalized least squares).
    ``rows``: a :class:`DesignRows` of these samples (t sorted), whose design matrices and white
    QR factors are shared with the other steps of :func:`smooth_pass` (the same bits), and which
    keeps its fits by (degree, samples, noise): a fit asked again is the one made (frozen).
    """
    if rows is not None and _kept:
        # the same fit asked again (the variance-ratio test's AR(1) fit is smooth_pass's fit)
        key = (degree, np.packbits(np.asarray(used, bool)).tobytes(), noise)
        made = rows.fits.get(key)
        if made is None:
            made = rows.fits[key] = solve_fit(t, y, s, degree, domain, basis, used, noise, rows, _kept=False)
        return made
    psi = design_matrix(t, degree, domain, basis) if rows is None else rows.design(degree)
    idx = used_in_time_order(t, used)
    tu = t[idx]
    yw = whiten(tu, y[idx] / s[idx], noise)
    if rows is not None and noise.white:
        a, q, r = rows.white_qr(degree, used)
    else:
        a = whiten(tu, psi[idx] / s[idx, None], noise)
        q, r = np.linalg.qr(a)
    cond = check_rank(r, degree)
    coef = solve_upper(r, q.T @ yw)
    r_inv = solve_upper(r, np.eye(degree + 1))
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


class DesignRows:
    """The design matrix of one pass's samples (times sorted) and the QR factors of its white
    weighted rows, made once and shared by the steps of one :func:`smooth_pass` iteration (degree
    search, noise estimate, fit, studentized residuals), which otherwise factor the same matrix
    up to three times.

    Same bits as building each afresh: the Chebyshev and Legendre Vandermonde recurrences fill
    column k from columns k-1 and k-2 only, so the first ``d + 1`` columns of a wider matrix are
    the degree-``d`` matrix; the division by sigma and the row selection are elementwise; and
    each matrix keeps the memory order of a fresh one (column-major, as the Vandermonde functions
    return it): a matrix-vector product takes another BLAS kernel, with other last bits, on the
    other order.
    """

    def __init__(self, t, y, s, domain, basis: str):
        self.t, self.y, self.s, self.domain, self.basis = t, y, s, domain, basis
        self._wide = None
        self._design: dict = {}
        self._qr: dict = {}
        self.fits: dict = {}        # solve_fit's results by (degree, samples in use, noise model)

    def design(self, degree: int) -> np.ndarray:
        """``design_matrix(t, degree, domain, basis)`` of every sample."""
        made = self._design.get(degree)
        if made is None:
            if self._wide is None or self._wide.shape[1] < degree + 1:
                self._wide = design_matrix(self.t, max(degree, DESIGN_ROWS_MIN_DEGREE), self.domain, self.basis)
            made = self._design[degree] = np.asfortranarray(self._wide[:, : degree + 1])
        return made

    def white_qr(self, degree: int, used) -> tuple:
        """``(a, q, r)``: ``a = psi[used] / sigma[used]`` at ``degree`` and ``np.linalg.qr(a)``."""
        used = np.asarray(used, bool)
        key = (degree, np.packbits(used).tobytes())
        made = self._qr.get(key)
        if made is None:
            idx = np.flatnonzero(used)
            a = self.design(degree)[idx] / self.s[idx, None]
            made = self._qr[key] = (a, *np.linalg.qr(a))
        return made


#: :class:`DesignRows` builds its widest matrix at least at this degree (the default search limit):
#: one Vandermonde evaluation serves the whole search.
DESIGN_ROWS_MIN_DEGREE = 30


def replace_fit(fit: PolynomialFit, **changes) -> PolynomialFit:
    return replace(fit, **changes)


def whiten(t_sorted, x, noise: NoiseModel | None):
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
    n = f.shape[0]
    term = np.empty_like(f)
    while k < n:
        # (A, X) after (A', X') = (A A', A X' + X): combine each element with the one k before
        # (the product into a scratch array first, then added in place: the same sums, fewer copies)
        np.multiply(coef[k:], f[:-k], out=term[k:])
        f[k:] += term[k:]
        coef[k:] = coef[k:] * coef[:-k]
        k *= 2
    return f


def ou_apply(a, x):
    """``C x`` for the Markov correlation ``C_ij = prod a_k`` between i and j (O(n p)).

    ``C`` is the covariance of ``u_0 = e_0``, ``u_i = a_i u_(i-1) + e_i`` with independent ``e_i`` of
    variance ``v_i`` (1, then ``1 - a_i^2``): ``D u = e`` with ``D`` unit lower bidiagonal (``-a_i``
    below the diagonal), so ``C = D^-1 V D^-T`` and its inverse ``D^T V^-1 D`` is tridiagonal (the
    Gauss-Markov precision matrix; Rue & Held 2005, sec. 1.3). Reversed in time, ``J C^-1 J =
    L (J V^-1 J) L^T`` with ``L = J D^T J`` unit lower bidiagonal (``-a`` reversed below the
    diagonal): the L D L^T factors LAPACK's ``dpttrs`` solves with (Golub & Van Loan 2013, sec.
    4.3.6), known without a factorisation. So ``C x`` is two first-order recurrences with a scaling
    between them, each as benign as the forward and backward sums ``f_i = x_i + a_i f_(i-1)`` of
    :func:`_markov_sum` (the same values to a few ulps at every ``a`` up to ``MAX_RHO``; a solve
    with the assembled tridiagonal matrix loses ``(1 + a) / (1 - a)``), 2-3 times faster.
    """
    a = np.asarray(a, float)
    if a.size:
        d = np.empty(a.size + 1)
        d[0] = 1.0
        d[1:] = 1.0 / (1.0 - a * a)
        kernels = _compiled() if x.ndim == 2 and x.dtype == np.float64 and x.flags.c_contiguous else None
        if kernels is not None:          # dpttrs's own operations, row by row (the same bits)
            out = np.empty_like(x)
            kernels.ou_solve(d, -a, x, out)
            return out
        out, info = _lapack("dpttrs")(d[::-1], -a[::-1], x[::-1])
        if info == 0:
            return out[::-1]
    forward = _markov_sum(a, x)
    backward = _markov_sum(a[::-1], x[::-1])[::-1]
    return forward + backward - x


def _compiled():
    """The smoothing's compiled kernels (:mod:`.compiled`, the same numbers as the paths they
    replace) when they pay, else None: ``TRACKPROC_JIT=0`` never; ``TRACKPROC_JIT=1`` (a batch's
    tasks) whenever numba is importable; unset, only when numba is loaded in this process already
    (a single command's few noise estimates save less than numba's import)."""
    from trackproc.dynamics import jit

    mode = jit.mode()
    if mode == "0" or (mode != "1" and "numba" not in sys.modules):
        return None
    if not _KERNELS:
        kernels = None
        if jit.enabled():
            try:
                from trackproc.methods.smoothing import compiled as kernels

                # compiled or loaded here, by one process at a time on a fresh cache
                with jit.compile_once([kernels.ou_solve, kernels.cheb_der_rows, kernels.polish_roots,
                                       kernels.cheb_values, kernels.cheb_value], "smoothing"):
                    kernels.ou_solve(np.ones(2), np.zeros(1), np.ones((2, 1)), np.empty((2, 1)))
                    kernels.cheb_der_rows(np.eye(3), 1, 1.0)
                    kernels.polish_roots(np.zeros(1), np.zeros(1), np.ones(3), np.ones(2), 0.0, 1.0, -1.0, 1.0)
                    kernels.cheb_values(np.ones(3), 0.0, 1.0, np.zeros(1))
                    kernels.cheb_value(np.ones(3), 0.0, 1.0, 0.0)
            except Exception:                      # noqa: BLE001 - numba unusable here: the numpy paths
                kernels = None
        _KERNELS.append(kernels)
    return _KERNELS[0]


_KERNELS: list = []


def solve_upper(r, b, transpose: bool = False) -> np.ndarray:
    """``R^-1 b`` (or ``R^-T b``) for the upper triangular ``r`` of a QR factorisation, by
    back (forward) substitution (LAPACK ``dtrtrs``): a third of the work of a general solve, which
    factors R again; ``numpy.linalg.solve`` when LAPACK reports a zero on the diagonal."""
    x, info = _lapack("dtrtrs")(r, b, lower=0, trans=1 if transpose else 0)
    if info != 0:
        return np.linalg.solve(r.T if transpose else r, b)
    return x


def _lapack(name: str):
    """A LAPACK routine of :mod:`trackproc.methods.lapack`, loaded at first use (a process that
    never fits needs none)."""
    made = _LAPACK.get(name)
    if made is None:
        from trackproc.methods.lapack import routines
        made = _LAPACK[name] = routines(name)[0]
    return made


_LAPACK: dict = {}
