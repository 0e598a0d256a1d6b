"""The least-squares problem shared by the unconstrained and the constrained solvers: the whitened
SVD, the a-priori rows, the whitened problem with editing (:class:`Problem`) and the damped
Gauss-Newton iterations (:func:`iterate`; seed 002 eqs. 4-8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from trackproc.errors import ProcessingError

from trackproc.methods.least_squares.types import Options, Prior, Solution


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
    r = _tall_r(jacobian_w, rhs)
    u, s, vt = np.linalg.svd(r[:n, :n])
    return u.T @ r[:n, n], s, vt


_DGEQRF: list = []


def _tall_r(jacobian_w: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``R`` (n, n + 1) of the Householder QR of the tall ``[J | b]``: LAPACK's dgeqrf, the routine
    ``np.linalg.qr(..., mode="r")`` calls (the same R bit for bit, tests/methods/test_tall_r.py), on
    the augmented matrix made in Fortran order, without numpy's wrapper (~20 µs a call, each
    linearisation of every solve)."""
    if not _DGEQRF:
        from trackproc.methods.lapack import routines   # start-up: scipy's LAPACK wrapper, ~3 ms, when solving

        _DGEQRF.extend(routines("dgeqrf"))
    m, n = jacobian_w.shape
    aug = np.empty((m, n + 1), order="F")
    aug[:, :n] = jacobian_w
    aug[:, n] = rhs
    qr, _, _, info = _DGEQRF[0](aug, overwrite_a=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqrf failed (info {info})")
    # np.triu's own operation (``where(tri(n, n + 1, -1), 0, R)``) with its mask made once a size
    mask = _BELOW.get(n)
    if mask is None:
        mask = _BELOW[n] = np.tri(n, n + 1, k=-1, dtype=bool)
    return np.where(mask, _ZERO, qr[:n, :])


_BELOW: dict = {}                # n -> the (n, n + 1) mask below the diagonal
_ZERO = np.zeros(1)


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


#: :func:`prior_rows`' whitened rows and factors by the priors' indices and covariances, the parameter
#: count and the scales: a pass's solves (the profile covariance's 4 per direction) share them.
_PRIOR_ROWS: dict = {}
_PRIOR_ROWS_MAX = 64


def prior_rows(priors: Sequence[Prior], n: int, scales: np.ndarray):
    """Whitening of the priors: rows ``W E S`` and the factor W (with W Wᵀ = covariance⁻¹)."""
    key = (n, np.asarray(scales, float).tobytes()) + tuple(
        (np.asarray(p.index, int).tobytes(), np.atleast_2d(np.asarray(p.covariance, float)).tobytes(),
         np.shape(p.covariance)) for p in priors)
    kept = _PRIOR_ROWS.get(key)
    if kept is None:
        a, factors = _prior_rows(priors, n, scales)
        if len(_PRIOR_ROWS) >= _PRIOR_ROWS_MAX:
            _PRIOR_ROWS.clear()
        kept = _PRIOR_ROWS[key] = (a, [w for w, _ in factors])
    a, ws = kept
    return a.copy(), [(w.copy(), p) for w, p in zip(ws, priors)]


def _prior_rows(priors: Sequence[Prior], n: int, scales: np.ndarray):
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


@dataclass
class Run:
    """Where :func:`iterate` stopped: the last accepted point (``x, h, jac, r``), the editing
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


class Problem:
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
        keep = ~mask
        # nothing edited: the whole arrays, the same contiguous values without the selections' copies
        z = r / self.sig if keep.all() else r[keep] / self.sig[keep]
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
        if keep.all() and jac.flags.c_contiguous:
            sig = self.sig                      # every row: the same C-ordered values without the copies
        else:
            sig, jac, r = self.sig[keep], jac[keep], r[keep]
        a = jac / sig[:, None] * self.scales[None, :]
        b = r / sig
        if self.n_prior:
            a = np.vstack([a, self.prior_a])
            b = np.concatenate([b, self.prior_rhs(x)])
        if not np.isfinite(a).all():
            raise ProcessingError("the Jacobian has non-finite entries", {"iteration": it})
        return a, b

    def solution(self, names, run: Run, cov_scaled, s, *, free: int, constrained: bool = False) -> Solution:
        """The :class:`Solution` at the end of ``run``, with ``K_out = S cov_scaled S`` (seed 002 eq. 9) and
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


def iterate(prob: Problem, opt: Options, x, h, jac, r, mask, *, stable: bool, linearise, trial, check,
             tag: str = "") -> Run:
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
        # np.sum / np.max as the ufuncs' reduce: the same reductions without numpy's wrappers
        sig_q = np.sqrt(np.add.reduce((vt / s[:, None]) ** 2, axis=0))     # formal sigma of q
        q_gn = vt.T @ (ub / s)
        gn_sig = float(np.maximum.reduce(np.abs(q_gn) / sig_q))
        if stable and gn_sig < opt.step_tol:          # at the minimum already: no evaluation needed
            return Run(x, h, jac, r, mask, cost, history, damped, True,
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
            if not np.isfinite(h_new).all():
                continue
            r_new = prob.residuals(h_new)
            c_new = prob.cost(r_new, x_new, mask)
            if c_new <= cost * (1.0 + 1e-12) + 1e-300:
                accepted = (x_new, h_new, jac_new, r_new, c_new, q)
                damped += attempt > 0
                break
        if accepted is None:
            if gn_sig < opt.step_tol:         # already at the minimum to round-off
                return Run(x, h, jac, r, mask, cost, history, damped, True,
                            "converged (no step reduces the cost further)", it, s, vt)
            raise ProcessingError(
                f"no step reduces the cost after {opt.max_damping_tries} damped tries at iteration {it} "
                f"(cost {cost:.6g}); the initial state may be too far off",
                {"iteration": it, "cost": cost, "cost_history": history})
        x, h, jac, r, c_new, q = accepted
        step_sig = float(np.maximum.reduce(np.abs(q) / sig_q))
        rel = abs(cost - c_new) / max(c_new, 1e-300)
        new_mask = prob.edit(r, mask)
        check(new_mask)
        stable = bool(np.array_equal(new_mask, mask))
        mask = new_mask
        # the same editing: the accepted point's cost is the one just computed, by the same sums
        cost = c_new if stable else prob.cost(r, x, mask)
        history.append(cost)
        if stable and (step_sig < opt.step_tol or rel < opt.cost_rtol):
            message = (f"converged: step {step_sig:.2g} sigma{tag}" if step_sig < opt.step_tol
                       else f"converged: relative cost change {rel:.2g}{tag}")
            return Run(x, h, jac, r, mask, cost, history, damped, True, message, it, s, vt)
    return Run(x, h, jac, r, mask, cost, history, damped, False, "", it, s, vt)
