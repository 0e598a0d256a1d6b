"""Batch weighted least squares: Gauss-Newton on the whitened system, solved by SVD.

Seed 002 eqs. 4-8: ``Δq = (Aᵀ K⁻¹ A)⁻¹ Aᵀ K⁻¹ Δr``, iterated (Gauss-Newton), and eq. 9: the
error matrix ``K_out = (Aᵀ K⁻¹ A)⁻¹``. Here that is computed without ever forming or inverting
the normal matrix: the residuals and the Jacobian are *whitened* (divided by the measurement
sigmas, so ``K = I``), the columns scaled by the parameters' scales (``x = x_ref + S ξ``), any
a-priori constraints appended as extra whitened rows, and the system ``J ξ ≈ b`` is solved by
the thin SVD ``J = U Σ Vᵀ``:

    step        ξ = V Σ⁻¹ Uᵀ b
    covariance  K_out = S V Σ⁻² Vᵀ S           (= (Aᵀ K⁻¹ A + prior)⁻¹, eq. 9)

which loses no precision to squaring the condition number (the normal matrix would).

Levenberg-Marquardt damping: when the Gauss-Newton step does not reduce the cost, the
damped step ``ξ(λ) = V diag(σᵢ / (σᵢ² + λ)) Uᵀ b`` (the minimiser of ``|J ξ - b|² + λ|ξ|²``,
from the same SVD) is tried with λ growing tenfold until the cost falls.

Convergence: after an accepted step, when the step is below ``step_tol`` formal sigmas in
every parameter, or the relative change of the cost is below ``cost_rtol`` — and the set of
edited samples did not change.

Residual editing (k-sigma, iterated): after every iteration, a sample is edited (excluded,
flagged, still reported) when ``|r/σ| > k · max(1, WRMS)`` with WRMS the RMS of the normalized
residuals of the samples kept in the previous iteration; every sample is re-tested each time,
so a sample edited while the orbit was poor comes back.

Failures raise :class:`~trackproc.errors.ProcessingError` with diagnostics: too few
measurements, rank deficiency (naming the unobservable combinations: the right singular
vectors of the negligible singular values, in parameter names), non-convergence, and a
model that fails (non-finite values).

Pure numpy; the model is a callable ``model(x) -> (computed (N,), jacobian (N, n))``. The problem
(:class:`_Problem`) and the iterations (:func:`_iterate`) also serve the constrained solver
:func:`trackproc.methods.refinement.solve_kkt`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import numpy as np

from trackproc.errors import ProcessingError

__all__ = ["Options", "Prior", "Solution", "solve", "solve_gls", "whitened_svd", "combination_text"]


@dataclass
class Options:
    """Settings of :func:`solve`.

    ``max_iterations``: Gauss-Newton iterations (each may try several damped steps);
    ``step_tol``: converged when every step component is below this many formal sigmas;
    ``cost_rtol``: or when the relative cost change is below this;
    ``clip``: k of the k-sigma editing (None or 0: no editing);
    ``rank_rtol``: a singular value below ``rank_rtol * max`` (of the whitened, scaled
    Jacobian) is a rank deficiency; ``max_damping_tries``: damped steps tried per iteration.
    """

    max_iterations: int = 20
    step_tol: float = 1e-3
    cost_rtol: float = 1e-9
    clip: Optional[float] = 4.0
    rank_rtol: float = 1e-9
    max_damping_tries: int = 12
    initial_damping: float = 1e-4


@dataclass(frozen=True)
class Prior:
    """An a-priori constraint ``x[index] ~ N(centre, covariance)`` (index into the parameters)."""

    index: np.ndarray
    centre: np.ndarray
    covariance: np.ndarray

    @classmethod
    def diagonal(cls, index, centre, sigma) -> "Prior":
        sigma = np.asarray(sigma, float)
        return cls(np.asarray(index, int), np.asarray(centre, float), np.diag(sigma ** 2))


@dataclass
class Solution:
    """Result of :func:`solve`.

    Parameters: ``names``, ``values``, physical ``covariance`` (eq. 9, including any a-priori
    information), ``sigma``, ``correlation``, ``covariance_scaled`` (of ξ = (x - x_ref)/scale:
    Orekit's "normalized" covariance), ``scales``.

    Statistics: ``chi2`` (sum of squared normalized residuals of the kept samples plus the
    a-priori terms), ``dof`` (kept samples + a-priori rows - parameters), ``variance_factor``
    (a-posteriori variance factor = chi2/dof, the reduced χ²; NaN when dof = 0),
    ``condition_number`` (of the whitened, scaled Jacobian), ``singular_values``.

    Samples (all N, edited ones included): ``computed``, ``residual`` (observed - computed,
    azimuth wrapped), ``normalized`` (residual/sigma), ``edited`` (bool), ``jacobian`` (N, n)
    at the solution.

    Run: ``iterations``, ``converged``, ``cost_history``, ``damped_steps``, ``message``.
    A-priori: ``n_prior`` constraint rows and their share of chi2, ``chi2_prior`` (a large value
    means the data pulled the solution far from the a-priori values).
    """

    names: list
    values: np.ndarray
    covariance: np.ndarray
    sigma: np.ndarray
    correlation: np.ndarray
    covariance_scaled: np.ndarray
    scales: np.ndarray
    chi2: float
    dof: int
    variance_factor: float
    condition_number: float
    singular_values: np.ndarray
    computed: np.ndarray
    residual: np.ndarray
    normalized: np.ndarray
    edited: np.ndarray
    jacobian: np.ndarray
    iterations: int
    converged: bool
    cost_history: list = field(default_factory=list)
    damped_steps: int = 0
    message: str = ""
    chi2_prior: float = 0.0
    n_prior: int = 0

    @property
    def n_measurements(self) -> int:
        return int(self.edited.size)

    @property
    def n_edited(self) -> int:
        return int(self.edited.sum())

    @property
    def wrms(self) -> float:
        """RMS of the normalized residuals of the kept samples."""
        z = self.normalized[~self.edited]
        return float(np.sqrt(np.mean(z * z))) if z.size else math.nan

    def block(self, names: Sequence[str]) -> np.ndarray:
        """Covariance block of the named parameters."""
        idx = [self.names.index(n) for n in names]
        return self.covariance[np.ix_(idx, idx)]


# ----------------------------------------------------------------------------- linear algebra

def whitened_svd(jacobian_w: np.ndarray, rhs: np.ndarray):
    """SVD of a whitened Jacobian (rows: samples; columns: scaled parameters) and ``Uᵀ b``.

    The tall system is first reduced by a Householder QR of the augmented matrix ``[J | b]``
    (``R``, ``c = Qᵀ b`` exactly, no normal matrix), then the small ``R`` is decomposed:
    ``J = Q R = (Q U_R) Σ Vᵀ``, so ``Uᵀ b = U_Rᵀ c``. Returns ``(Uᵀ b, Σ, Vᵀ)``.
    """
    n = jacobian_w.shape[1]
    if jacobian_w.shape[0] <= n:
        u, s, vt = np.linalg.svd(jacobian_w, full_matrices=False)
        return u.T @ rhs, s, vt
    r = np.linalg.qr(np.column_stack([jacobian_w, rhs]), mode="r")
    u, s, vt = np.linalg.svd(r[:n, :n])
    return u.T @ r[:n, n], s, vt


def combination_text(vector: np.ndarray, names: Sequence[str], threshold: float = 0.1) -> str:
    """A unit vector over the (scaled) parameters as text, e.g. ``+0.71 x -0.71 range_bias:KIR``."""
    v = np.asarray(vector, float)
    v = v / np.linalg.norm(v)
    k = int(np.argmax(np.abs(v)))
    if v[k] < 0:
        v = -v
    order = np.argsort(-np.abs(v))
    terms = [f"{v[i]:+.2f} {names[i]}" for i in order if abs(v[i]) >= threshold]
    return " ".join(terms)


def prior_rows(priors: Sequence[Prior], n: int, scales: np.ndarray):
    """Whitening of the priors: rows ``W E S`` and the factor W (with W Wᵀ = covariance⁻¹)."""
    rows, factors = [], []
    for p in priors:
        cov = np.atleast_2d(np.asarray(p.covariance, float))
        chol = np.linalg.cholesky(cov)                     # cov = L Lᵀ; rows L⁻¹
        w = np.linalg.solve(chol, np.eye(cov.shape[0]))
        e = np.zeros((len(p.index), n))
        e[np.arange(len(p.index)), p.index] = 1.0
        rows.append(w @ e * scales[None, :])
        factors.append((w, p))
    a = np.vstack(rows) if rows else np.zeros((0, n))
    return a, factors


def prior_rhs(factors, x: np.ndarray) -> np.ndarray:
    parts = [w @ (p.centre - x[p.index]) for w, p in factors]
    return np.concatenate(parts) if parts else np.zeros(0)


# ----------------------------------------------------------------------------- the problem, shared

@dataclass
class _Run:
    """Where :func:`_iterate` stopped: the last accepted point (``x, h, jac, r``), the editing
    ``mask`` and ``cost`` there, and the bookkeeping; ``s, vt`` of the last linearisation."""

    x: np.ndarray
    h: np.ndarray
    jac: np.ndarray
    r: np.ndarray
    mask: np.ndarray
    cost: float
    history: list
    damped: int
    converged: bool
    message: str
    iterations: int
    s: Optional[np.ndarray] = None
    vt: Optional[np.ndarray] = None


class _Problem:
    """The whitened problem ``Σ ((y - h(x))/σ)² + prior terms`` (seed 002 eqs. 4-8), shared by
    :func:`solve` and :func:`trackproc.methods.refinement.solve_kkt`: residuals, model calls,
    cost, k-sigma editing and the whitened system.

    ``n`` parameters; ``clip`` the k of the editing (None or 0: none); ``fixed_out`` (N,) bool:
    samples edited from the start and never re-admitted (default: none). Other arguments as in
    :func:`solve`.
    """

    def __init__(self, model, n: int, observed, sigma, *, scales=None, priors: Sequence[Prior] = (),
                 periodic=None, clip: Optional[float] = None, fixed_out=None):
        self.model = model
        self.n = n
        self.y = np.asarray(observed, float)
        self.sig = np.asarray(sigma, float)
        self.nobs = self.y.size
        if self.sig.shape != self.y.shape or not np.all(np.isfinite(self.sig) & (self.sig > 0)):
            raise ValueError("sigma must be positive and finite, one per measurement")
        self.scales = np.ones(n) if scales is None else np.asarray(scales, float)
        self.periodic = np.zeros(self.nobs, bool) if periodic is None else np.asarray(periodic, bool)
        self.fixed_out = np.zeros(self.nobs, bool) if fixed_out is None else np.asarray(fixed_out, bool).copy()
        self.prior_a, self.prior_factors = prior_rows(priors, n, self.scales)
        self.n_prior = self.prior_a.shape[0]
        self.clip = clip if clip else None

    def residuals(self, h):
        """``y - h``, wrapped to [-π, π) where periodic."""
        r = self.y - h
        if self.periodic.any():
            r = np.where(self.periodic, np.mod(r + np.pi, 2 * np.pi) - np.pi, r)
        return r

    def evaluate(self, x):
        """``model(x)`` as float arrays of the expected shapes (ValueError otherwise)."""
        h, jac = self.model(x)
        h = np.asarray(h, float)
        jac = np.asarray(jac, float)
        nobs, n = self.nobs, self.n
        if h.shape != (nobs,) or jac.shape != (nobs, n):
            raise ValueError(f"model returned shapes {h.shape}, {jac.shape}; expected ({nobs},), ({nobs}, {n})")
        return h, jac

    def start(self, x, prepare=None):
        """``(x, h, J)`` at the initial values, after ``prepare(x)`` if given; a failure is a ProcessingError."""
        try:
            if prepare is not None:
                x = prepare(x)
            h, jac = self.evaluate(x)
        except (ArithmeticError, ValueError) as exc:
            raise ProcessingError(f"the model cannot be evaluated at the initial values: {exc}") from None
        return x, h, jac

    def step(self, x, xi, retract=None):
        """The point a scaled step ξ leads to: ``x + S ξ``, or ``retract(x, S ξ)``."""
        return x + self.scales * xi if retract is None else retract(x, self.scales * xi)

    def prior_rhs(self, x):
        """The whitened a-priori residuals at ``x``."""
        return prior_rhs(self.prior_factors, x)

    def cost(self, r, x, mask):
        """χ²: squared normalized residuals of the kept samples plus the a-priori terms."""
        z = r[~mask] / self.sig[~mask]
        pr = self.prior_rhs(x)
        return float(z @ z + pr @ pr)

    def edit(self, r, mask_prev):
        """k-sigma editing: ``fixed_out`` or ``|r/σ| > k · max(1, WRMS of the samples kept in mask_prev)``."""
        if self.clip is None:
            return self.fixed_out.copy()
        z = np.abs(r / self.sig)
        kept = z[~mask_prev]
        wrms = float(np.sqrt(np.mean(kept * kept))) if kept.size else 1.0
        return self.fixed_out | (z > self.clip * max(1.0, wrms))

    def system(self, jac, r, x, mask, it):
        """The whitened, scaled system ``J ξ ≈ b``: kept samples, then the a-priori rows."""
        keep = ~mask
        a = jac[keep] / self.sig[keep, None] * self.scales[None, :]
        b = r[keep] / self.sig[keep]
        if self.n_prior:
            a = np.vstack([a, self.prior_a])
            b = np.concatenate([b, self.prior_rhs(x)])
        if not np.all(np.isfinite(a)):
            raise ProcessingError("the Jacobian has non-finite entries", {"iteration": it})
        return a, b

    def solution(self, names, run: _Run, cov_scaled, s, *, free: int, constrained: bool = False) -> Solution:
        """The :class:`Solution` at the end of ``run``, with ``K_out = S cov_scaled S`` (eq. 9) and
        ``free`` parameters in the degrees of freedom; ``constrained``: the covariance may be
        singular (zero sigmas, zero correlations there)."""
        scales = self.scales
        cov = cov_scaled * np.outer(scales, scales)
        cov = 0.5 * (cov + cov.T)
        if constrained:
            sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
            with np.errstate(invalid="ignore", divide="ignore"):
                corr = np.where(np.outer(sd, sd) > 0, cov / np.outer(sd, sd), 0.0)
        else:
            sd = np.sqrt(np.diag(cov))
            corr = cov / np.outer(sd, sd)
        dof = int((~run.mask).sum()) + self.n_prior - free
        chi2 = run.cost
        return Solution(names=names, values=run.x, covariance=cov, sigma=sd, correlation=corr,
                        covariance_scaled=cov_scaled, scales=scales, chi2=chi2, dof=dof,
                        variance_factor=chi2 / dof if dof > 0 else math.nan, condition_number=float(s[0] / s[-1]),
                        singular_values=s, computed=run.h, residual=run.r, normalized=run.r / self.sig,
                        edited=run.mask, jacobian=run.jac, iterations=run.iterations, converged=True,
                        cost_history=run.history, damped_steps=run.damped, message=run.message,
                        chi2_prior=float(np.sum(self.prior_rhs(run.x) ** 2)), n_prior=int(self.n_prior))


def _iterate(prob: _Problem, opt: Options, x, h, jac, r, mask, *, stable: bool, linearise, trial, check,
             tag: str = "") -> _Run:
    """Damped Gauss-Newton with k-sigma editing and the stopping rules of the module docstring,
    from the point ``x`` (model values ``h``, Jacobian ``jac``, residuals ``r``, editing ``mask``,
    ``stable`` if that editing is settled). Shared by :func:`solve` and
    :func:`trackproc.methods.refinement.solve_kkt`.

    ``linearise(jac, r, x, mask, it) -> (Uᵀ b, Σ, Vᵀ, to_step)``: the SVD of the whitened system
    of the free step ``q`` and the map ``q -> ξ`` (the scaled step); ``trial(x, ξ) -> x_new``, or
    None for a refused point; ``check(mask)`` raises when too few samples are kept; ``tag`` ends
    the convergence messages. Non-convergence is returned (``converged`` False), not raised.
    """
    cost = prob.cost(r, x, mask)
    history = [cost]
    damped = 0
    s = vt = None
    it = 0
    for it in range(1, opt.max_iterations + 1):
        ub, s, vt, to_step = linearise(jac, r, x, mask, it)
        sig_q = np.sqrt(np.sum((vt / s[:, None]) ** 2, axis=0))     # formal sigma of q
        q_gn = vt.T @ (ub / s)
        gn_sig = float(np.max(np.abs(q_gn) / sig_q))
        if stable and gn_sig < opt.step_tol:          # at the minimum already: no evaluation needed
            return _Run(x, h, jac, r, mask, cost, history, damped, True,
                        f"converged: Gauss-Newton step {gn_sig:.2g} sigma{tag}", it, s, vt)
        accepted = None
        for attempt in range(opt.max_damping_tries + 1):
            if attempt == 0:
                q = q_gn
            else:
                lam = opt.initial_damping * s[0] ** 2 * 10.0 ** (attempt - 1)
                q = vt.T @ (ub * s / (s * s + lam))
            x_new = trial(x, to_step(q))
            if x_new is None:
                continue
            try:
                h_new, jac_new = prob.evaluate(x_new)
            except (ArithmeticError, ProcessingError, ValueError):
                continue
            if not np.all(np.isfinite(h_new)):
                continue
            r_new = prob.residuals(h_new)
            c_new = prob.cost(r_new, x_new, mask)
            if c_new <= cost * (1.0 + 1e-12) + 1e-300:
                accepted = (x_new, h_new, jac_new, r_new, c_new, q)
                damped += attempt > 0
                break
        if accepted is None:
            if gn_sig < opt.step_tol:         # already at the minimum to round-off
                return _Run(x, h, jac, r, mask, cost, history, damped, True,
                            "converged (no step reduces the cost further)", it, s, vt)
            raise ProcessingError(
                f"no step reduces the cost after {opt.max_damping_tries} damped tries at iteration {it} "
                f"(cost {cost:.6g}); the initial state may be too far off",
                {"iteration": it, "cost": cost, "cost_history": history})
        x, h, jac, r, c_new, q = accepted
        step_sig = float(np.max(np.abs(q) / sig_q))
        rel = abs(cost - c_new) / max(c_new, 1e-300)
        new_mask = prob.edit(r, mask)
        check(new_mask)
        stable = bool(np.array_equal(new_mask, mask))
        mask = new_mask
        cost = prob.cost(r, x, mask)
        history.append(cost)
        if stable and (step_sig < opt.step_tol or rel < opt.cost_rtol):
            message = (f"converged: step {step_sig:.2g} sigma{tag}" if step_sig < opt.step_tol
                       else f"converged: relative cost change {rel:.2g}{tag}")
            return _Run(x, h, jac, r, mask, cost, history, damped, True, message, it, s, vt)
    return _Run(x, h, jac, r, mask, cost, history, damped, False, "", it, s, vt)


# ----------------------------------------------------------------------------- the solver

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
    prob = _Problem(model, n, observed, sigma, scales=scales, priors=priors, periodic=periodic, clip=opt.clip,
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

    def factor(jac, r, xv, mask, it):
        ub, s, vt = whitened_svd(*prob.system(jac, r, xv, mask, it))
        if s.size < n or s[-1] <= opt.rank_rtol * s[0]:
            _raise_rank(s, vt, names, scales, opt.rank_rtol, it)
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
    run = _iterate(prob, opt, x, h, jac, r, mask, stable=stable, linearise=linearise,
                   trial=lambda xv, xi: np.clip(prob.step(xv, xi, retract), lo, hi), check=check_counts)
    if not run.converged:
        s, history = run.s, run.history
        weakest = combination_text(run.vt[-1], names)
        raise ProcessingError(
            f"did not converge in {opt.max_iterations} iterations (cost {history[-2]:.6g} -> {history[-1]:.6g}; "
            f"condition number {s[0] / s[-1]:.3g}, weakest combination {weakest}); "
            "try --max-iterations, a better --initial state, or a-priori sigmas",
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


# ----------------------------------------------------------------------------- correlated samples

def solve_gls(model: Callable[[np.ndarray], tuple], x0, observed, covariance, fit, *, clip: Optional[float] = 4.0,
              sigma_scale: float = 1.0, edited=None, max_editing_rounds: int = 4):
    """Generalised least squares: the samples' covariance ``covariance`` (a
    :class:`trackproc.methods.noise.PassCovariance`) is not diagonal. Seed 002 eqs. 4-9 with a
    full ``K``: the kept samples are whitened (``L⁻¹ y``, ``L⁻¹ h(x)``, ``L⁻¹ J``, ``K = L Lᵀ``
    times ``sigma_scale²``), which makes them independent of unit sigma, and solved by
    ``fit(model_w, y_w, start) -> (Solution, extra)`` (:func:`solve`, or a constrained solver).
    The k-sigma editing (``clip``) is made on the innovations ``L⁻¹ r`` of every sample (the
    standardised one-step prediction errors; an outlier stands out at its own sample), the
    whitening refactored on the kept samples, until the edited set settles.

    Returns ``(Solution, extra)``: the solution of the last whitened fit with the samples' own
    ``computed``/``residual``, ``normalized`` = the innovations, ``edited``, and ``jacobian``
    whose kept rows are the whitened rows times the samples' sigma (so that dividing by the
    sigmas, as diagnostics do, gives the whitened Jacobian).
    """
    from dataclasses import replace as dc_replace

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
    return dc_replace(sol_w, computed=h, residual=r, normalized=z, edited=mask.copy(), jacobian=jac_rep), extra
