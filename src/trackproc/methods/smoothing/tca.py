"""The time of closest approach of a smoothed pass (:func:`closest_approach`: the zero of the
range-rate, or the inflection of a one-way Doppler S-curve) and its spread over neighbouring
degrees (:func:`tca_degree_spread`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polyutils as pu

from trackproc.methods.smoothing.fit import (WHITE, PolynomialFit, SmoothingError, _chebder1, _compiled, check_arrays,
                                             check_enough, check_rank, design_matrix, distinct_count, replace_fit,
                                             solve_upper, used_in_time_order, whiten)


#: A TCA whose spread over neighbouring degrees exceeds this many formal sigmas is ``uncertain``.
TCA_SPREAD_RATIO = 3.0


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
    order, definition, t_star, gp, n_candidates = _tca_time(fit, kind, doppler_mode)
    slope = float(gp(t_star))
    phi_m = design_matrix([t_star], fit.degree, fit.domain_s, fit.basis, order)[0]
    phi_0 = design_matrix([t_star], fit.degree, fit.domain_s, fit.basis, 0)[0]
    dt_dc = -phi_m / slope
    dv_dc = phi_0 + float(fit(t_star, 1)) * dt_dc
    jac = np.vstack([dt_dc, dv_dc])
    cov_u = jac @ fit.cov_unscaled @ jac.T
    return ClosestApproach(definition=definition, order=order, t_s=float(t_star), value=float(fit(t_star)),
                           cov=cov_u * fit.variance_factor, cov_unscaled=cov_u, slope=slope,
                           n_candidates=n_candidates)


def _tca_time(fit: PolynomialFit, kind: str, doppler_mode: str):
    """``(order, definition, t*, the derivative series at order + 1, candidates)`` of
    :func:`closest_approach` (the time alone: :func:`tca_degree_spread` needs no covariance)."""
    order, sign, definition = _definition(kind, doppler_mode)
    g = fit.series(order)
    gp = fit.series(order + 1)
    candidates = _real_roots(g, fit.domain_s, gp)
    gp_at = _scalar(gp)
    good = [r for r in candidates if sign * gp_at(r) > 0]
    if not good:
        what = {0: "zero", 1: "minimum", 2: "inflection point"}[order]
        found = f" ({len(candidates)} of the wrong sense)" if candidates else ""
        raise SmoothingError("no_tca", f"no {what} of the fitted {kind.replace('_', '-')} inside the pass"
                             f"{found}: closest approach not observed")
    if order == 2:      # Doppler S-curve: steepest descent = most negative f'
        t_star = min(good, key=_scalar(fit.series(1)))
    elif order == 1:    # range: the lowest minimum
        t_star = min(good, key=_scalar(fit.series(0)))
    else:               # steepest crossing
        t_star = max(good, key=lambda r: abs(gp_at(r)))
    return order, definition, t_star, gp, len(candidates)


def _definition(kind: str, doppler_mode: str):
    """``(order, sign, definition)``: the TCA is a root of the curve's ``order``-th derivative where
    the next derivative has the sign ``sign``."""
    if kind == "range_rate":
        return 0, +1, "zero of the fitted range-rate (negative to positive)"
    if kind == "range":
        return 1, +1, "minimum of the fitted range (zero of its derivative)"
    if kind == "doppler" and doppler_mode == "two-way":
        return 0, -1, "zero of the fitted two-way Doppler (positive to negative)"
    if kind == "doppler":
        return 2, +1, ("inflection point of the fitted one-way Doppler S-curve "
                       "(zero of the second derivative, steepest descent)")
    raise ValueError(f"no closest approach is defined for kind {kind!r}")


def _cheb_tca(coef, base, domain, kind: str, doppler_mode: str) -> tuple[float, float]:
    """``(t*, curve at t*)`` of :func:`_tca_time` for the Chebyshev coefficients ``coef`` on
    ``domain``, the domain of the series ``base`` (a fit of another degree on the same pass), from coefficient
    arrays: the derivatives by :func:`_chebder1` with ``base``'s scale, the roots by ``chebroots``
    mapped as ``Chebyshev.roots`` maps them, the values by :func:`_cheb_scalar` -- the operations of
    the series path in the same order (the same bits) without building a numpy series per
    derivative. Raises :class:`SmoothingError` (``no_tca``) where :func:`_tca_time` would."""
    order, sign, _ = _definition(kind, doppler_mode)
    off, scl = base.mapparms()
    kernels = _compiled()
    coefs = [np.array(coef, dtype=float)]
    for _ in range(order + 1):
        coefs.append(_chebder1(coefs[-1], scl) if kernels is None else
                     kernels.cheb_der_rows(coefs[-1].reshape(-1, 1), 1, float(scl)).reshape(-1))
    # window -> domain as pu.mapdomain(roots, base.window, base.domain) maps them: its own
    # mapparms, then off + scl * x (the same operations, without its argument checks)
    w_off, w_scl = pu.mapparms(base.window, base.domain)
    roots = w_off + w_scl * _cheb_roots(coefs[order])
    if kernels is not None:     # the same operations compiled (compiled.polish_roots, cheb_values)
        return _cheb_tca_compiled(kernels, roots, coefs, float(off), float(scl), domain, order, sign)
    value = [_cheb_scalar(c, off, scl) for c in coefs]
    candidates = _polish(roots, value[order], value[order + 1], domain)
    good = [r for r in candidates if sign * value[order + 1](r) > 0]
    if not good:
        raise SmoothingError("no_tca", "no closest approach")
    if order == 2:
        t_star = min(good, key=value[1])
    elif order == 1:
        t_star = min(good, key=value[0])
    else:
        t_star = max(good, key=lambda r: abs(value[1](r)))
    return t_star, value[0](t_star)


def _cheb_tca_compiled(kernels, roots, coefs, off, scl, domain, order, sign) -> tuple[float, float]:
    """:func:`_cheb_tca`'s polish and choice among the roots by the compiled kernels: the same
    Newton steps and values (:func:`_cheb_scalar`'s operations), the same rounding, order and
    choice (the first of equal keys, as ``min`` / ``max`` take it)."""
    roots = np.asarray(roots)
    zr = np.ascontiguousarray(roots.real, dtype=float)
    zi = np.ascontiguousarray(roots.imag, dtype=float)
    a, b = float(domain[0]), float(domain[1])
    out = kernels.polish_roots(zr, zi, coefs[order], coefs[order + 1], off, scl, a, b)
    out = out[~np.isnan(out)]
    candidates = np.array([float(v) for v in sorted(set(np.round(out, 9)))], dtype=float)
    if candidates.size:
        good = candidates[sign * kernels.cheb_values(coefs[order + 1], off, scl, candidates) > 0]
    else:
        good = candidates
    if not good.size:
        raise SmoothingError("no_tca", "no closest approach")
    keys = kernels.cheb_values(coefs[0 if order == 1 else 1], off, scl, good).tolist()
    at = range(len(keys))
    # Python's min / max over the keys, as _cheb_tca takes them (NaN included)
    best = max(at, key=lambda i: abs(keys[i])) if order == 0 else min(at, key=keys.__getitem__)
    t_star = float(good[best])
    return t_star, float(kernels.cheb_value(coefs[0], off, scl, t_star))


def _cheb_roots(coef) -> np.ndarray:
    """``numpy.polynomial.chebyshev.chebroots(coef)`` of a 1-D float series, the same bits: the
    eigenvalues (``numpy.linalg.eigvals``) of the same rotated scaled companion matrix
    (``chebcompanion``; Barnett 1975, the colleague matrix), made from a kept matrix of its constant
    entries for each size instead of numpy's per-call construction (its argument checks, the
    trimming copy and the scale vector are most of a call below degree ~12), then sorted."""
    c = np.asarray(coef, dtype=float)
    k = c.size
    while k > 1 and c[k - 1] == 0:       # as_series' trim of trailing zeros
        k -= 1
    if k < 2:
        return np.array([], dtype=float)
    if k == 2:
        return np.array([-c[0] / c[1]])
    n = k - 1
    kept = _COMPANION.get(n)
    if kept is None:
        mat = np.zeros((n, n))
        top = mat.reshape(-1)[1::n + 1]
        bot = mat.reshape(-1)[n::n + 1]
        top[0] = np.sqrt(.5)
        top[1:] = 1 / 2
        bot[...] = top
        scl = np.array([1.] + [np.sqrt(.5)] * (n - 1))
        kept = _COMPANION[n] = (mat, scl / scl[-1])
    mat = kept[0].copy()
    mat[:, -1] -= (c[: n] / c[n]) * kept[1] * .5
    r = np.linalg.eigvals(mat[::-1, ::-1])
    r.sort()
    return r


#: ``n -> (the constant part of chebcompanion's n x n matrix, its column scale over the last)``.
_COMPANION: dict = {}


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
                      width: int | None = None, t_star: float | None = None) -> tuple[float, float, int]:
    """Sensitivity of the TCA to the choice of degree: a model-error indicator.

    Refits the samples ``fit`` used with degrees ``fit.degree - width .. fit.degree + width`` (default
    width: :func:`degree_spread_width`) and
    returns the standard deviation of t* and of the curve value at t* over those that give a
    closest approach, and how many did (NaN when fewer than 3). The coefficient covariance cannot
    show this error: it assumes the polynomial of the chosen degree is the true curve.
    ``t_star``: ``fit``'s own TCA (:func:`closest_approach`'s ``t_s``), when the caller has it.
    """
    t, yy, s = check_arrays(t_s, y, sigma)
    if width is None:
        width = degree_spread_width(fit.degree)
    times, values = [], []
    degrees = range(max(0, fit.degree - width), fit.degree + width + 1)
    nested = _nested_coefficients(t, yy, s, fit, degrees[-1])
    base = fit.series(0)
    # Chebyshev degrees whose derivative series down to the root's all have two or more terms (the
    # series path's _chebder1 steps): from coefficient arrays
    light = _definition(kind, doppler_mode)[0] + 1 if type(base) is np.polynomial.Chebyshev else 0
    for d in degrees:
        try:
            if d == fit.degree:
                t_d = _tca_time(fit, kind, doppler_mode)[2] if t_star is None else t_star
                v_d = fit(t_d)
            elif light and d >= light:
                t_d, v_d = _cheb_tca(nested(d), base, fit.domain_s, kind, doppler_mode)
            else:
                other = replace_fit(fit, degree=d, coef=nested(d))
                t_d = _tca_time(other, kind, doppler_mode)[2]      # closest_approach's t*, no covariance
                v_d = other(t_d)
        except SmoothingError:
            continue
        times.append(float(t_d))
        values.append(float(v_d))
    if len(times) < 3:
        return float("nan"), float("nan"), len(times)
    return float(np.std(times, ddof=1)), float(np.std(values, ddof=1)), len(times)


def _nested_coefficients(t, y, s, fit: PolynomialFit, top: int):
    """``coef(d)``: the coefficients of :func:`fit_polynomial` of degree ``d`` <= ``top`` on the
    samples, domain, basis and noise of ``fit`` (raises :class:`SmoothingError` where it would), all
    from one QR of the whitened ``[Psi_top  y]``.

    The fits are nested: the basis columns of degree ``d`` are the first ``d + 1`` of ``top``'s, and
    the whitening acts on rows, so the leading ``(d + 1) x (d + 1)`` block of R is the R of the
    smaller fit and the last column's first ``d + 1`` entries are its ``Q^T y`` (Householder QR,
    Golub & Van Loan 2013, sec. 5.3): the same least-squares solution, to rounding, without a
    factorisation for each degree.
    """
    idx = used_in_time_order(t, np.asarray(fit.used, bool))
    tu = t[idx]
    noise = fit.noise or WHITE
    aug = np.column_stack([design_matrix(tu, top, fit.domain_s, fit.basis), y[idx]]) / s[idx, None]
    r = np.linalg.qr(whiten(tu, aug, noise), mode="r")
    n_distinct = distinct_count(tu)
    # R_d's columns are the first d + 1 of R_top's (zero below row d), so its condition number is
    # at most R_top's (singular values interlace when columns are removed: Golub & Van Loan 2013,
    # cor. 8.6.3): one SVD decides for every degree when R_top is well inside solve_fit's limit
    try:
        all_ranked = check_rank(r[: top + 1, : top + 1], top) < 0.5 / (np.finfo(float).eps * 1e3)
    except SmoothingError:
        all_ranked = False

    def coef(d: int) -> np.ndarray:
        check_enough(tu, d, n_distinct)
        rd = r[: d + 1, : d + 1]
        if not all_ranked:
            check_rank(rd, d)                                 # solve_fit's rank test
        return solve_upper(rd, r[: d + 1, -1])

    return coef


def _real_roots(series, domain, d1=None) -> list[float]:
    """Real roots of a numpy series inside [a, b], polished by Newton steps; ``d1`` its
    derivative when the caller has it already (the same series as ``series.deriv()``)."""
    if series.degree() < 1:
        return []
    return _polish(series.roots(), _scalar(series), _scalar(series.deriv() if d1 is None else d1), domain)


def _polish(roots, value, d1, domain) -> list[float]:
    """The roots (complex, of a series whose value and derivative at a float are ``value`` and
    ``d1``) that are real to 1e-3 of the half-width of ``domain``, after up to 5 Newton steps, inside it."""
    a, b = domain
    half = 0.5 * (b - a)
    out = []
    for z in roots:
        if abs(z.imag) > 1e-3 * half:
            continue
        x = float(z.real)
        for _ in range(5):
            slope = d1(x)
            if slope == 0:
                break
            step = value(x) / slope
            x -= step
            if abs(step) < 1e-12 * half:
                break
        if a <= x <= b and np.isfinite(x):
            out.append(x)
    out = sorted(set(np.round(out, 9)))
    return [float(v) for v in out]


def _scalar(series):
    """``x -> series(x)`` for one float ``x``: for a Chebyshev series numpy's own operations in
    Python floats, in the same order (the domain map ``off + scl x``, then ``chebval``'s Clenshaw
    recurrence), so the same value to the last bit without numpy's per-call overhead (the root
    polish and the choice among roots call it some 20 times per fit); other bases: the series."""
    if type(series) is not np.polynomial.Chebyshev:
        return series
    return _cheb_scalar(series.coef, *series.mapparms())


def _cheb_scalar(coef, off, scl):
    """:func:`_scalar` of the Chebyshev series ``coef`` whose domain map is ``off + scl x``."""
    off, scl = float(off), float(scl)
    c = [float(v) for v in coef]
    if len(c) == 1:
        return lambda x: c[0] + 0 * (off + scl * x)

    def value(x):
        x = off + scl * x
        if len(c) == 2:
            return c[0] + c[1] * x
        x2 = 2 * x
        c0, c1 = c[-2], c[-1]
        for i in range(3, len(c) + 1):
            c0, c1 = c[-i] - c1, c0 + c1 * x2
        return c0 + c1 * x

    return value
