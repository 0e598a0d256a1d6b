"""Gauss-Newton with equality constraints, the KKT system by the null-space method (seed 004 eqs. 15-17),
and the same constraints held only to a given covariance (:func:`solve_soft_kkt`).

Soft constraints. Seed 004 imposes ``f(x) = 0`` exactly. When the constraints hold only to
``f(x) = ε``, ``ε ~ N(0, Σ_ε)`` (a circular orbit that is circular only to an eccentricity), the
correct estimate is the maximum a-posteriori one, ``min χ²(x) + εᵀ Σ_ε⁻¹ ε`` subject to
``f(x) = ε``: the data decide the combinations of ε they see, the prior the others. It is found
on the hard solver: for fixed ε the KKT solution gives the profiled cost's gradient ``-λ`` and
half-Hessian ``G = Dᵀ J_wᵀ J_w D`` (D = dx̂/dε, J_w the whitened data and a-priori rows), and
Newton steps on ε, ``δε = (G + Σ_ε⁻¹)⁻¹ (λ/2 - Σ_ε⁻¹ ε)``, converge in a few solves. Its covariance is the Laplace
one, ``K(x | ε) + D C_ε Dᵀ`` with ``C_ε = (G + Σ_ε⁻¹)⁻¹``. Adding ``D Σ_ε Dᵀ`` to the hard
solution's covariance instead (the error of the estimate that forces ``ε = 0``) is honest for
that estimate but ignores what the data say about ε: on the seed 004 Table 1 pass it is 10 to 20
times the soft estimate's (tests/pipeline/test_refine_circular_tolerance.py). ``Σ_ε = 0`` is seed 004's
hard case, solved by :func:`solve_kkt` alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, Optional, Sequence

import numpy as np

from trackproc.errors import ProcessingError

from trackproc.methods.least_squares import Options, Problem, Solution, combination_text, iterate, whitened_svd


#: Feasibility reached by the restoration steps (relative to each constraint's scale).
FEASIBILITY_RTOL = 1e-14
MAX_RESTORE = 30


@dataclass
class KKTResult:
    """A solution under equality constraints (:func:`solve_kkt`).

    ``solution`` (a :class:`~trackproc.methods.least_squares.Solution`; its covariance is the
    constrained one, singular across the constraint surface), ``multipliers`` λ of
    ``L = χ² + λᵀ f`` (seed 004 eq. 16; units: cost per unit of each constraint),
    ``constraints`` f at the solution, ``relative`` f divided by :func:`constraint_scales`,
    ``stationarity`` the free Gauss-Newton step left at the solution, in formal sigmas (0 at a
    KKT point: ``∇χ² + Aᵀλ = 0``),
    ``restorations`` minimum-norm Newton steps taken to stay feasible, ``sensitivity`` (n, m)
    ``dx̂/dε``: how the solution moves if the constraints were ``f = ε`` instead of 0 (for the
    soft constraints, :func:`solve_soft_kkt`);
    ``curvature`` (m, m) ``G = Dᵀ J_wᵀ J_w D``: half the Hessian of the profiled cost with respect to ε.

    From :func:`solve_soft_kkt` (soft constraints): ``soft`` (m,) bool, the constraints held to a
    covariance; ``target`` ε (m,) the constraint values at the solution; ``target_covariance``
    ``C_ε`` (k, k) of the soft ones; ``conditional_covariance`` (n, n) the covariance for ε fixed.
    The solution's covariance is then ``K(x | ε) + D C_ε Dᵀ`` and its χ² includes ``εᵀ Σ_ε⁻¹ ε``.
    """

    solution: Solution
    multipliers: np.ndarray
    constraints: np.ndarray
    relative: np.ndarray
    stationarity: float
    restorations: int = 0
    null_space_dim: int = 0
    sensitivity: Optional[np.ndarray] = None
    curvature: Optional[np.ndarray] = None
    soft: Optional[np.ndarray] = None
    target: Optional[np.ndarray] = None
    target_covariance: Optional[np.ndarray] = None
    conditional_covariance: Optional[np.ndarray] = None

    def joint(self):
        """The soft solution as a problem in ``(x, ε_soft)``: ``(covariance_scaled, jacobian,
        scales)`` of the joint parameters (ε in physical units, scale 1), for a covariance that
        propagates the data (:func:`~trackproc.methods.refinement.sandwich_covariance`)."""
        sol = self.solution
        sc = np.asarray(sol.scales, float)
        d = np.asarray(self.sensitivity, float)[:, self.soft] / sc[:, None]       # dξ/dε_soft (scaled)
        c = np.asarray(self.target_covariance, float)
        k_cond = np.asarray(self.conditional_covariance, float) / np.outer(sc, sc)
        top = np.hstack([k_cond + d @ c @ d.T, d @ c])
        cov = np.vstack([top, np.hstack([c @ d.T, c])])
        jac = np.hstack([np.asarray(sol.jacobian, float), np.zeros((sol.jacobian.shape[0], c.shape[0]))])
        return 0.5 * (cov + cov.T), jac, np.r_[sc, np.ones(c.shape[0])]


def null_space(a_scaled):
    """``Y`` (n, m), ``Z`` (n, n - m), ``R`` (m, m) with ``A_sᵀ = Y R`` (QR of the constraint Jacobian)."""
    m = a_scaled.shape[0]
    q, r = np.linalg.qr(a_scaled.T, mode="complete")
    rr = r[:m, :m]
    if (np.abs(np.diag(rr)) <= 1e-13 * max(np.abs(np.diag(rr)).max(), 1e-300)).any():
        raise ProcessingError("the constraints are degenerate at this point (their Jacobian is rank deficient)")
    return q[:, :m], q[:, m:], rr


def solve_kkt(model: Callable[[np.ndarray], tuple], x0, observed, sigma, *, names: Sequence[str],
              constraints: Callable[[np.ndarray], tuple], constraint_scale: Callable[[np.ndarray], np.ndarray],
              scales=None, priors=(), periodic=None, options: Options | None = None, retract=None,
              diagnostics: bool = True) -> KKTResult:
    """Minimise ``Σ ((y - h(x))/σ)² + prior terms`` subject to ``f(x) = 0`` (seed 004 eqs. 15-17).

    Gauss-Newton on the KKT system of each linearised step, solved by the null-space method
    (module docstring); every iterate is restored onto ``f = 0`` by minimum-norm Newton steps;
    Levenberg-Marquardt damping of the free step; the k-sigma editing, stopping rules and failure
    reports are those of :func:`trackproc.methods.least_squares.solve` (the same problem and iterations).

    ``constraints(x) -> (f (m,), A (m, n))``; ``constraint_scale(x) -> (m,)`` positive scales
    making ``f`` relative (feasible when every ``|f| / scale < 1e-14``); ``retract`` as in
    :func:`~trackproc.methods.least_squares.solve` (applied before the restoration).
    ``diagnostics`` False: the solution alone (``multipliers``, ``sensitivity`` and ``curvature``
    None, ``stationarity`` NaN; for a caller that needs only the point and its covariance).
    Raises :class:`ProcessingError` on failure.

    Over 100 lines with this docstring; its code is under 100.
    """
    opt = options or Options()
    x = np.asarray(x0, float).copy()
    n = x.size
    names = list(names)
    prob = Problem(model, n, observed, sigma, scales=scales, priors=priors, periodic=periodic, clip=opt.clip)
    scales = prob.scales
    restorations = 0

    def restore(xv):
        nonlocal restorations
        best = (math.inf, xv)
        for _ in range(MAX_RESTORE):
            f, a = constraints(xv)
            scale = constraint_scale(xv)
            if (np.abs(f) <= FEASIBILITY_RTOL * scale).all():
                return xv
            # a constraint evaluated at rounding level (e.g. a linear one at |x| ~ 7e6 m) never
            # reaches 1e-14: once a step no longer reduces it, more steps only stir the last bits
            rel = float(np.maximum.reduce(np.abs(f) / scale))
            if rel >= best[0] and best[0] < 1e-10:
                return best[1]
            if rel < best[0]:
                best = (rel, xv)
            step = np.linalg.lstsq(a * scales[None, :], -f, rcond=None)[0]
            xv = xv + scales * step
            restorations += 1
        f, _ = constraints(xv)
        rel = np.abs(f) / constraint_scale(xv)
        if (rel < 1e-10).all():
            return xv
        raise ArithmeticError(f"cannot satisfy the constraints (relative residual {rel.max():.3g})")

    factorised = {}              # null_space by the constraint Jacobian (a linear constraint's is the same throughout)
    last = [((None,) * 4, None)]  # the last linearisation, by its arrays (the run may stop at that point)

    def reduced(jac, r, xv, mask, it):
        if all(u is v for u, v in zip(last[0][0], (jac, r, xv, mask))):
            return last[0][1]
        f, ac = constraints(xv)
        a_s = ac * scales[None, :]
        yb, zb, rr = factorised.get(a_s.tobytes()) or factorised.setdefault(a_s.tobytes(), null_space(a_s))
        p = -np.linalg.solve(rr.T, f)
        a, b = prob.system(jac, r, xv, mask, it)
        ub, s, vt = whitened_svd(a @ zb, b - a @ (yb @ p))
        if s.size < zb.shape[1] or s[-1] <= opt.rank_rtol * s[0]:
            weak = combination_text(zb @ vt[-1], names) if s.size else ""
            raise ProcessingError(
                f"rank-deficient problem under the constraints (condition number "
                f"{s[0] / s[-1] if s.size and s[-1] > 0 else math.inf:.3g}); unobservable combination of the "
                f"scaled parameters: {weak}", {"iteration": it, "singular_values": s.tolist()})
        last[0] = ((jac, r, xv, mask), (yb, zb, rr, p, ub, s, vt, a, b, f, ac))
        return last[0][1]

    def linearise(jac, r, xv, mask, it):
        yb, zb, _, p, ub, s, vt = reduced(jac, r, xv, mask, it)[:7]
        return ub, s, vt, lambda q: yb @ p + zb @ q                 # δ = Y p + Z q

    def trial(xv, xi):
        try:
            return restore(prob.step(xv, xi, retract))
        except (ArithmeticError, ProcessingError, ValueError):
            return None

    def check_counts(mask):
        if int((~mask).sum()) + prob.n_prior < n - 3:
            raise ProcessingError(f"too few measurements: {int((~mask).sum())} kept for {n} parameters")

    x, h, jac = prob.start(x, prepare=restore)
    if not np.isfinite(h).all():
        raise ProcessingError("the model gives non-finite values at the initial values")
    r = prob.residuals(h)
    mask = prob.edit(r, np.zeros(prob.nobs, bool))
    run = iterate(prob, opt, x, h, jac, r, mask, stable=not mask.any(), linearise=linearise, trial=trial,
                   check=check_counts, tag=" (constrained)")
    if not run.converged:
        history = run.history
        raise ProcessingError(
            f"did not converge in {opt.max_iterations} iterations under the constraints (cost {history[-2]:.6g} -> "
            f"{history[-1]:.6g}); try --max-iterations, a better --initial state, or drop --circular",
            {"iterations": run.iterations, "cost_history": history})

    # covariance, multipliers and stationarity at the solution
    x = run.x
    yb, zb, rr, _, ub, s, vt, a, b, f, ac = reduced(run.jac, run.r, x, run.mask, run.iterations)
    inner = (vt.T / s ** 2) @ vt
    sol = prob.solution(names, run, zb @ inner @ zb.T, s, free=n - f.size, constrained=True)
    common = dict(solution=sol, constraints=f, relative=f / constraint_scale(x), restorations=restorations,
                  null_space_dim=int(zb.shape[1]))
    if not diagnostics:
        return KKTResult(multipliers=None, stationarity=math.nan, **common)
    lam, stationarity, sens, curvature = _diagnostics(a, b, ac * scales[None, :], yb, zb, rr, ub, s, vt, inner)
    return KKTResult(multipliers=lam, stationarity=stationarity, sensitivity=sens * scales[:, None],
                     curvature=curvature, **common)


def _diagnostics(a, b, a_scaled, yb, zb, rr, ub, s, vt, inner):
    """At a KKT solution of :func:`solve_kkt` (whitened system ``a ξ ≈ b``, scaled constraint Jacobian
    ``a_scaled``, its null-space split and the reduced SVD): the multipliers λ of ``Aᵀλ = -∇χ²`` (seed
    004 eq. 16), the stationarity, the sensitivity ``dξ/dε`` (scaled) and the curvature ``G``."""
    grad = -2.0 * a.T @ b                                    # ∇χ² in the scaled parameters
    lam = np.linalg.lstsq(a_scaled.T, -grad, rcond=None)[0]
    # stationarity: the free Gauss-Newton step left at the solution, in formal sigmas
    sig_q = np.sqrt(np.add.reduce((vt / s[:, None]) ** 2, axis=0))
    stationarity = float(np.maximum.reduce(np.abs(vt.T @ (ub / s)) / sig_q))
    # dξ/dε: the constraint step Y R⁻ᵀ δε, minus the free directions' readjustment
    a_y = yb @ np.linalg.inv(rr.T)
    sens = a_y - zb @ (inner @ (zb.T @ (a.T @ (a @ a_y))))
    ad = a @ sens
    return lam, stationarity, sens, ad.T @ ad

#: Newton steps on the soft constraint values ε stop below this fraction of their posterior sigma.
SOFT_STEP_TOL = 0.01
MAX_SOFT_STEPS = 8


def solve_soft_kkt(model: Callable[[np.ndarray], tuple], x0, observed, sigma, *, names: Sequence[str],
                   constraints: Callable[[np.ndarray], tuple], constraint_scale: Callable[[np.ndarray], np.ndarray],
                   constraint_covariance: Callable[[np.ndarray], np.ndarray], scales=None, priors=(), periodic=None,
                   options: Options | None = None, retract=None) -> KKTResult:
    """Minimise ``χ²(x) + εᵀ Σ_ε⁻¹ ε`` subject to ``f(x) = ε`` (module docstring: soft constraints).
    Implements seed 004 eqs. 15-17 generalised to constraints that hold to a covariance.

    ``constraint_covariance(x) -> Σ_ε`` (m, m): the covariance of the constraint values (a zero
    row and column: that constraint is hard). Other arguments as in :func:`solve_kkt`, whose
    solutions at fixed ε are converged to 1e-6 sigma (the multipliers are the profiled cost's
    gradient). Returns a :class:`KKTResult` with the soft fields; with ``Σ_ε = 0`` the result of
    :func:`solve_kkt`. Raises :class:`ProcessingError` on failure.
    """
    opt = options or Options()
    tight = replace(opt, step_tol=min(opt.step_tol, 1e-6))
    x = np.asarray(x0, float).copy()
    cov0 = np.asarray(constraint_covariance(x), float)
    soft = np.diag(cov0) > 0
    if not soft.any():
        return solve_kkt(model, x, observed, sigma, names=names, constraints=constraints,
                         constraint_scale=constraint_scale, scales=scales, priors=priors, periodic=periodic,
                         options=opt, retract=retract)
    eps = np.zeros(cov0.shape[0])

    def solve_at(xv, target):
        def shifted(xx):
            f, a = constraints(xx)
            return f - target, a

        common = dict(names=names, constraints=shifted, constraint_scale=constraint_scale, scales=scales,
                      priors=priors, periodic=periodic, retract=retract)
        try:
            return solve_kkt(model, xv, observed, sigma, options=tight, **common)
        except ProcessingError:      # round-off stops short of the tight tolerance: the caller's will do
            return solve_kkt(model, xv, observed, sigma, options=opt, **common)

    def posterior(kk):
        """``(Σ_ε⁻¹, C_ε)`` of the soft constraints at the solution ``kk``."""
        s_inv = np.linalg.inv(np.asarray(constraint_covariance(kk.solution.values), float)[np.ix_(soft, soft)])
        c = np.linalg.inv(kk.curvature[np.ix_(soft, soft)] + s_inv)
        return s_inv, 0.5 * (c + c.T)

    k = solve_at(x, eps.copy())
    for _ in range(MAX_SOFT_STEPS):
        s_inv, c_eps = posterior(k)
        step = c_eps @ (k.multipliers[soft] / 2.0 - s_inv @ eps[soft])        # Newton on the profiled cost
        eps[soft] += step
        k = solve_at(k.solution.values + k.sensitivity[:, soft] @ step, eps.copy())
        if np.all(np.abs(step) <= SOFT_STEP_TOL * np.sqrt(np.diag(c_eps))):
            break
    else:
        raise ProcessingError(f"the soft constraints did not settle in {MAX_SOFT_STEPS} steps (last step "
                              f"{np.max(np.abs(step) / np.sqrt(np.diag(c_eps))):.3g} sigma)")
    s_inv, c_eps = posterior(k)
    sol = k.solution
    d = k.sensitivity[:, soft]
    cov = sol.covariance + d @ c_eps @ d.T
    cov = 0.5 * (cov + cov.T)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.where(np.outer(sd, sd) > 0, cov / np.outer(sd, sd), 0.0)
    sc = np.asarray(sol.scales, float)
    chi2 = float(sol.chi2 + eps[soft] @ s_inv @ eps[soft])
    sol = replace(sol, covariance=cov, sigma=sd, correlation=corr, covariance_scaled=cov / np.outer(sc, sc),
                  chi2=chi2, variance_factor=chi2 / sol.dof if sol.dof > 0 else math.nan)
    return replace(k, solution=sol, soft=soft, target=eps, target_covariance=c_eps,
                   conditional_covariance=k.solution.covariance)
