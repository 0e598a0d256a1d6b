"""The degree of the smoothing polynomial (the profiled BIC over ``0..cap``, :func:`select_degree`,
:func:`degree_cap`) and the smoothing of a pass with it and K-sigma rejection on studentized
residuals (:func:`smooth_pass`).
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods.smoothing.correlation import estimate_noise
from trackproc.methods.smoothing.fit import (MAX_RHO, WHITE, DesignRows, NoiseModel, PolynomialFit, SmoothingError,
                                             check_arrays, check_enough, design_matrix, distinct_count, pass_domain,
                                             replace_fit,
                                             solve_fit, solve_upper, whiten)


#: Default upper bound of the degree search of ``degree="auto"``.
DEFAULT_MAX_DEGREE = 30
#: ``degree="auto"`` keeps at least this many effective samples per coefficient: d + 1 <= n_eff / 2.
MIN_EFFECTIVE_SAMPLES_PER_COEFFICIENT = 2.0
#: The rejection never flags more than this fraction of a pass.
MAX_REJECTED_FRACTION = 0.1


#: An AR(1) fit whose variance factor exceeds the white fit's by more than this leaves curve out.
MAX_VARIANCE_RATIO = 4.0


#: Iterations of the rejection loop before giving up (the last fit is kept, and said so).
MAX_CLIP_ITERATIONS = 30
#: 1 / Phi^-1(3/4): MAD -> standard deviation of a Gaussian.
MAD_TO_SIGMA = 1.482602218505602


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
    t, y, s = check_arrays(t_s, y, sigma)
    domain = pass_domain(t, domain_s)
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
        check_enough(t, int(degree))
    clipping = clip is not None and clip > 0
    max_rejected = int(np.floor(MAX_REJECTED_FRACTION * t.size))
    history: list[bytes] = []
    fit = None
    # sorted times (as the pipeline gives them): the design matrices and white QR factors made once
    # for all the steps below; otherwise each step builds its own (the same numbers)
    rows = DesignRows(t, y, s, domain, basis) if np.all(t[1:] >= t[:-1]) else None
    for iteration in range(1, MAX_CLIP_ITERATIONS + 1):
        if np.count_nonzero(used) < 2:
            raise SmoothingError("all_rejected", f"only {np.count_nonzero(used)} of {t.size} samples "
                                 "left after outlier rejection")
        try:
            deg, scores, at_limit, model, cap = _choose(t[used], y[used], s[used], degree, basis, max_degree,
                                                        domain, noise, rows, used)
        except SmoothingError as exc:
            if iteration > 1:
                raise SmoothingError("all_rejected", f"after outlier rejection: {exc}") from None
            raise
        fit = replace_fit(solve_fit(t, y, s, deg, domain, basis, used, model, rows), degree_scores=scores,
                       degree_at_limit=at_limit, degree_cap=cap)
        if not clipping:
            return fit
        u, scale = _studentized(t, s, fit, domain, basis, rows)
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
        fit = replace_fit(fit, iterations=iteration, robust_scale=scale, rejection_capped=capped,
                       n_over_threshold=n_over)
        if np.array_equal(new_used, used):
            return fit
        key = np.packbits(new_used).tobytes()
        if key in history:        # the rejected set cycles: stop, keep this fit, say so
            return replace_fit(fit, clip_converged=False)
        history.append(np.packbits(used).tobytes())
        used = new_used
    return replace_fit(fit, clip_converged=False)


def select_degree(t_s, y, sigma, *, basis: str = "chebyshev", max_degree: int = DEFAULT_MAX_DEGREE,
                  domain_s=None, noise: NoiseModel | None = None, design=None,
                  _checked: bool = False) -> tuple[int, dict, bool]:
    """Degree minimizing ``BIC(d) = n ln(chi2_d / n) + (d + 1) ln n`` over ``0..cap``.

    ``chi2_d`` is the weighted (for an AR(1) ``noise``: generalized) residual sum of squares. One QR
    factorization of the whitened ``[Psi  y]`` at the largest degree gives every nested fit:
    ``chi2_d = sum_(k > d) R[k, y]^2``, the squares of the last column's entries below row ``d``
    (the columns of a lower degree are the first ones; Golub & Van Loan 2013, sec. 5.3.3). The search stops at the smallest of ``max_degree``,
    ``n_distinct - 2`` (each candidate keeps a degree of freedom) and the effective-sample cap
    ``floor(n_eff / 2) - 1`` (:func:`degree_cap`). Returns (degree, {degree: BIC}, at_limit) where
    ``at_limit`` says the minimum is at the upper end of the search (more terms might help).
    ``design``: ``design(d)`` gives ``design_matrix`` of the (sorted) samples at degree ``d``, when
    the caller has it already. ``_checked``: the arrays are :func:`check_arrays`' output already
    (:func:`smooth_pass`'s samples in use).
    """
    t, y, s = (t_s, y, sigma) if _checked else check_arrays(t_s, y, sigma)
    domain = pass_domain(t, domain_s)
    dmax = degree_cap(t, max_degree, noise)
    order = np.argsort(t, kind="stable")
    t, y, s = t[order], y[order], s[order]
    psi = design_matrix(t, dmax, domain, basis) if design is None else design(dmax)
    aug = whiten(t, np.column_stack([psi, y]) / s[:, None], noise)
    # R of the QR of [A  y_w]: the last column's entries below row d are Q^T y_w's part the first
    # d + 1 columns do not reach, so chi2_d is the sum of their squares (Golub & Van Loan 2013,
    # sec. 5.3.3) -- no difference of large numbers, every degree from one factorisation
    r = np.linalg.qr(aug, mode="r")
    tail = np.cumsum(r[::-1, -1] ** 2)[::-1]          # tail[k] = sum_{j >= k} r[j, -1]^2
    n = t.size
    tiny = np.finfo(float).tiny
    chi2 = np.maximum(tail[1: dmax + 2], tiny)
    bic = n * np.log(chi2 / n) + np.arange(1, dmax + 2) * np.log(n)
    scores = {d: bic[d] for d in range(dmax + 1)}
    best = min(scores, key=scores.get)
    return best, scores, best == dmax


def degree_cap(t_s, max_degree: int = DEFAULT_MAX_DEGREE, noise: NoiseModel | None = None) -> int:
    """Largest degree ``degree="auto"`` may choose for samples at ``t_s``.

    The smallest of ``max_degree``, ``n_distinct - 2`` and ``floor(n_eff / 2) - 1`` (at least
    two effective samples per coefficient; ``n_eff`` from the AR(1) ``noise``, ``n`` for white).
    Raises :class:`SmoothingError` when not even a constant can be fitted and tested.
    """
    t = np.asarray(t_s, float)
    n_distinct = distinct_count(t)
    if n_distinct < 2:
        raise SmoothingError("single_time", f"all {t.size} samples at one time: no curve can be fitted")
    n_eff = (noise or WHITE).effective_samples(t) if noise is not None and not noise.white else float(t.size)
    by_samples = int(np.floor(n_eff / MIN_EFFECTIVE_SAMPLES_PER_COEFFICIENT + 1e-9)) - 1
    dmax = int(min(max_degree, n_distinct - 2, t.size - 2, max(by_samples, 0)))
    if dmax < 0:
        raise SmoothingError("too_few_points", f"{t.size} samples are too few to fit and test a curve")
    return dmax


def _choose(t, y, s, degree, basis, max_degree, domain, noise, rows=None, used=None):
    """(degree, BIC scores, at_limit, noise model, cap) for the samples in use (``rows``: the
    :class:`DesignRows` of all samples, ``used`` the mask of those in use, when sorted)."""
    design = white_q = None
    if rows is not None:
        idx = np.flatnonzero(used)

        def design(d):     # column-major, as design_matrix gives it
            return np.asfortranarray(rows.design(d)[idx])

        def white_q(d):
            return rows.white_qr(d, used)[1]
    if not isinstance(degree, str):
        check_enough(t, int(degree))
        model = (estimate_noise(t, y, s, int(degree), basis=basis, domain_s=domain,
                                white_q=white_q and white_q(int(degree)), _checked=True)
                 if noise == "auto" else noise)
        return int(degree), {}, False, model, None
    if noise == "auto":
        # rho from the residuals of the white-noise choice: a degree that absorbs the curve (on
        # correlated noise the white BIC over-fits, which the projection correction allows for)
        white = select_degree(t, y, s, basis=basis, max_degree=max_degree, domain_s=domain, design=design,
                              _checked=True)
        d0 = white[0]
        model = estimate_noise(t, y, s, d0, basis=basis, domain_s=domain, white_q=white_q and white_q(d0),
                               _checked=True)
    else:
        model = noise
    if noise == "auto" and model.white:     # the same search again (white noise whitens nothing)
        deg, scores, at_limit = white
    else:
        deg, scores, at_limit = select_degree(t, y, s, basis=basis, max_degree=max_degree, domain_s=domain,
                                              noise=model, design=design, _checked=True)
    cap = degree_cap(t, max_degree, model)
    if noise == "auto" and not model.white and (model.rho >= MAX_RHO or (at_limit and cap < d0)
                                                 or _variance_ratio(t, y, s, d0, deg, domain, basis, model,
                                                                    rows, used)
                                                 > MAX_VARIANCE_RATIO):
        # AR(1) noise would leave fewer coefficients than the curve needs (or the correlation is at
        # its bound): correlated noise and unresolved curve cannot be told apart with these samples
        model = replace_fit(model, rho=0.0, n_eff=float(t.size), unresolved=True)
        deg, scores, at_limit = white
        cap = degree_cap(t, max_degree, model)
    return deg, scores, at_limit, model, cap


def _variance_ratio(t, y, s, d_white, d_ar1, domain, basis, model, rows=None, used_all=None) -> float:
    """Variance factor of the AR(1) fit over that of the white-noise fit of the same samples.

    Both estimate the marginal noise variance when the AR(1) model holds (measured 1.1 at rho 0.6,
    1.3-2.2 at rho 0.9: the white over-fit absorbs some low-frequency noise); when the AR(1) fit
    has too few terms for the curve, its whitened residuals carry the curve (ratios of 10^3-10^10
    on high passes sampled every 10 s and a two-way range-rate pass at 1 mm/s)."""
    if rows is not None:      # the same samples through the shared rows (the same variance factors)
        t, y, s, used = rows.t, rows.y, rows.s, used_all
    else:
        used = np.ones(t.size, bool)
    white = solve_fit(t, y, s, d_white, domain, basis, used, rows=rows)
    ar1 = solve_fit(t, y, s, d_ar1, domain, basis, used, model, rows=rows)
    return ar1.variance_factor / white.variance_factor if white.variance_factor > 0 else math.inf


def _studentized(t, s, fit: PolynomialFit, domain, basis, rows=None):
    """Residuals over their own standard deviation (leverage-corrected), and their robust scale."""
    used = fit.used
    if rows is None:
        psi = design_matrix(t, fit.degree, domain, basis) / s[:, None]
        _, r = np.linalg.qr(psi[used])
    else:
        psi = rows.design(fit.degree) / s[:, None]
        r = rows.white_qr(fit.degree, used)[2]
    g = solve_upper(r, psi.T, transpose=True).T     # psi R^-1: hat diagonal on the used rows
    h = np.sum(g * g, axis=1)
    z = fit.residual / s
    u = np.where(used, z / np.sqrt(np.maximum(1.0 - h, 1e-6)), z / np.sqrt(1.0 + h))
    uu = u[used]
    scale = MAD_TO_SIGMA * float(np.median(np.abs(uu - np.median(uu))))
    if not scale > 0.0:
        scale = float(np.sqrt(fit.chi2 / max(fit.dof, 1)))
    return u, scale
