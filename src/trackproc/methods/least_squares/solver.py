"""The weighted least-squares solver (:func:`solve`) and its generalised form for correlated samples
(:func:`solve_gls`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Optional, Sequence

import numpy as np

from trackproc.errors import ProcessingError

from trackproc.methods.least_squares.iteration import Problem, combination_text, iterate, whitened_svd
from trackproc.methods.least_squares.types import Options, Prior, Solution


def solve(model: Callable[[np.ndarray], tuple], x0, observed, sigma, *, names: Sequence[str],
          scales=None, priors: Sequence[Prior] = (), periodic=None, bounds=None,
          options: Options | None = None, edited=None, retract=None) -> Solution:
    """Minimise ``Σ ((y - h(x))/σ)² + prior terms`` over ``x`` by damped Gauss-Newton.

    Parameters
    ----------
    model : callable
        ``model(x) -> (h (N,), H (N, n))``, computed values and their Jacobian at ``x``. It may
        raise ``ArithmeticError`` or :class:`ProcessingError` at a trial point (treated as an
        infinite cost, i.e. the step is damped).
    x0 : (n,) starting values (also the reference of the scaling).
    observed, sigma : (N,) measurements and their 1-sigma (> 0).
    names : parameter names (for diagnostics).
    scales : (n,) positive column scales (default 1).
    priors : a-priori constraints (:class:`Prior`).
    periodic : (N,) bool, residuals wrapped to [-π, π) (azimuth).
    bounds : ((n,), (n,)) lower and upper bounds (steps are clipped into them).
    edited : (N,) bool, samples excluded from the start (never re-admitted).
    retract : callable, optional
        ``retract(x, dx) -> x_new``: how a step is applied (default ``x + dx``), e.g. along a
        curved family of nearly equivalent solutions (to first order it must equal ``x + dx``).

    Returns :class:`Solution`; raises :class:`ProcessingError` (see the module docstring).
    Implements seed 002 eqs. 4-9.
    """
    opt = options or Options()
    x = np.asarray(x0, float).copy()
    n = x.size
    names = list(names)
    prob = Problem(model, n, observed, sigma, scales=scales, priors=priors, periodic=periodic, clip=opt.clip,
                    fixed_out=edited)
    scales = prob.scales
    lo, hi = (np.full(n, -np.inf), np.full(n, np.inf)) if bounds is None else (np.asarray(bounds[0], float),
                                                                                np.asarray(bounds[1], float))

    def check_counts(mask):
        kept = int((~mask).sum())
        if kept + prob.n_prior < n or kept == 0:
            raise ProcessingError(
                f"too few measurements: {kept} kept ({int(mask.sum())} edited) and {prob.n_prior} a-priori "
                f"constraints for {n} parameters",
                {"measurements": prob.nobs, "kept": kept, "edited": int(mask.sum()), "parameters": n,
                 "apriori_rows": prob.n_prior})

    last = [((), None)]

    def factor(jac, r, xv, mask, it):
        # a run that stops at the Gauss-Newton test returns the point it last factored: the error
        # matrices below then reuse that SVD (the same arrays, so the same numbers)
        if len(last[0][0]) == 4 and all(u is v for u, v in zip(last[0][0], (jac, r, xv, mask))):
            return last[0][1]
        ub, s, vt = whitened_svd(*prob.system(jac, r, xv, mask, it))
        if s.size < n or s[-1] <= opt.rank_rtol * s[0]:
            _raise_rank(s, vt, names, scales, opt.rank_rtol, it)
        last[0] = ((jac, r, xv, mask), (ub, s, vt))
        return ub, s, vt

    def linearise(jac, r, xv, mask, it):
        return (*factor(jac, r, xv, mask, it), lambda xi: xi)      # the free step is the whole step

    x, h, jac = prob.start(x)
    if not np.all(np.isfinite(h)):
        raise ProcessingError("the model gives non-finite values at the initial values",
                              {"non_finite": int((~np.isfinite(h)).sum())})
    r = prob.residuals(h)
    mask = prob.fixed_out.copy()
    check_counts(mask)
    # first editing pass against the initial orbit (generous: WRMS of everything)
    mask = prob.edit(r, mask)
    stable = bool(np.array_equal(mask, prob.fixed_out))
    check_counts(mask)
    run = iterate(prob, opt, x, h, jac, r, mask, stable=stable, linearise=linearise,
                   trial=lambda xv, xi: np.clip(prob.step(xv, xi, retract), lo, hi), check=check_counts)
    if not run.converged:
        s, history = run.s, run.history
        weakest = combination_text(run.vt[-1], names)
        raise ProcessingError(
            f"did not converge in {opt.max_iterations} iterations (cost {history[-2]:.6g} -> {history[-1]:.6g}; "
            f"condition number {s[0] / s[-1]:.3g}, weakest combination {weakest}); "
            "try --max-iterations, a better --initial state, or an a-priori (estimate: --apriori-initial, "
            "--apriori-sigma; one station's passes leave some directions of an orbit free)",
            {"iterations": run.iterations, "cost_history": history, "edited": int(run.mask.sum()),
             "condition_number": float(s[0] / s[-1]), "weakest_combination": weakest})

    # error matrices at the solution (the Jacobian of the last accepted point)
    _, s, vt = factor(run.jac, run.r, run.x, run.mask, run.iterations)
    return prob.solution(names, run, (vt.T / s ** 2) @ vt, s, free=n)


def _raise_rank(s, vt, names, scales, rtol, it):
    """Rank deficiency: name the combinations of the negligible singular values."""
    n = len(names)
    smax = s[0] if s.size else 0.0
    weak = [i for i in range(n) if i >= s.size or s[i] <= rtol * smax]
    combos = []
    for i in weak:
        if i < vt.shape[0]:
            combos.append(combination_text(vt[i], names))
    if s.size < n:
        text = f"only {s.size} independent rows for {n} parameters"
    else:
        text = "; ".join(combos)
    raise ProcessingError(
        f"rank-deficient problem (condition number {smax / s[-1] if s.size and s[-1] > 0 else math.inf:.3g}): "
        f"unobservable combination(s) of the scaled parameters: {text}; add data, fix or drop a parameter, "
        "or give it an a-priori sigma",
        {"iteration": it, "singular_values": s.tolist(), "unobservable": combos})


def solve_gls(model: Callable[[np.ndarray], tuple], x0, observed, covariance, fit, *, clip: Optional[float] = 4.0,
              sigma_scale: float = 1.0, edited=None, max_editing_rounds: int = 4, values=None):
    """Generalised least squares: the samples' covariance ``covariance`` (a
    :class:`trackproc.methods.noise.PassCovariance`) is not diagonal. Seed 002 eqs. 4-9 with a
    full ``K``: the kept samples are whitened (``L⁻¹ y``, ``L⁻¹ h(x)``, ``L⁻¹ J``, ``K = L Lᵀ``
    times ``sigma_scale²``), which makes them independent of unit sigma, and solved by
    ``fit(model_w, y_w, start) -> (Solution, extra)`` (:func:`solve`, or a constrained solver);
    ``model_w.values(x)`` is its values alone, from ``values(x)`` (``model(x)``'s values without
    the Jacobian, the same numbers) when given.
    The k-sigma editing (``clip``) is made on the innovations ``L⁻¹ r`` of every sample (the
    standardised one-step prediction errors; an outlier stands out at its own sample), the
    whitening refactored on the kept samples, until the edited set settles.

    Returns ``(Solution, extra)``: the solution of the last whitened fit with the samples' own
    ``computed``/``residual``, ``normalized`` = the innovations, ``edited``, and ``jacobian``
    whose kept rows are the whitened rows times the samples' sigma (so that dividing by the
    sigmas, as diagnostics do, gives the whitened Jacobian).
    """
    y = np.asarray(observed, float)
    sigma = np.asarray(covariance.sigma, float)
    n = y.size
    mask = np.zeros(n, bool) if edited is None else np.asarray(edited, bool).copy()
    start = np.asarray(x0, float)
    k = 1.0 / sigma_scale
    for _ in range(max_editing_rounds):
        keep = ~mask
        w = covariance.whitener(keep)

        def model_w(x, w=w):
            h_, jac_ = model(x)
            return w(h_) * k, w(jac_) * k

        def values_w(x, w=w):
            return w(model(x)[0] if values is None else values(x)) * k

        model_w.values = values_w

        sol_w, extra = fit(model_w, w(y) * k, start)
        h, jac = model(sol_w.values)
        r = y - h
        z = covariance.innovations(r) * k
        if not clip:
            break
        wrms = float(np.sqrt(np.mean(z[keep] ** 2)))
        new = np.abs(z) > clip * max(1.0, wrms)
        if np.array_equal(new, mask) or int(new.sum()) > 0.5 * n:
            break
        mask, start = new, sol_w.values
    jac_rep = np.array(jac, float)
    jac_rep[keep] = sol_w.jacobian * (sigma[keep] * sigma_scale)[:, None]
    return replace(sol_w, computed=h, residual=r, normalized=z, edited=mask.copy(), jacobian=jac_rep), extra
