"""The consistency gates of a refinement (docs/refine.md, "Quality"): the data reweighted by their
scatter (:func:`solve_weighted`), the a-priori scaled by its variance component when the pass
contradicts it (:func:`solve_adapted`), the improvement test against the stale state
(:func:`stale_improvement`), the refusal of a pass that cannot improve it (:func:`solve_gated`, its
result a :class:`Gated`)
and the likelihood-ratio test of the circular-orbit constraints (:func:`circular_consistency`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Optional

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.methods import quality as qm
from trackproc.methods.distributions import chi2_survival_2
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.pipeline.refine.options import MAX_ADAPT_ITERATIONS, MAX_APRIORI_ADAPT, MAX_REWEIGHT, REWEIGHT_THRESHOLD
from trackproc.pipeline.refine.problem import Refinement, with_noise_of  # noqa: F401  (re-exported)
from trackproc.pipeline.refine.traverse import eccentricity, time_tag_covariance


def may_refuse(ref: Refinement) -> bool:
    """Refusal applies to the pointwise cost with a stale a-priori on the whole state, unconstrained."""
    opt = ref.options
    return (opt.allow_refusal and opt.cost == "pointwise" and not opt.circular
            and pr.state_prior_covariance(ref.priors) is not None)


@dataclass(frozen=True)
class Gated:
    """What the gates made of a pass (:func:`solve_gated`): the refinement with the a-priori used,
    its solution, KKT result (or None) and sigma scale; the a-priori's adaptation
    (:func:`solve_adapted`, or None), the improvement test (:func:`stale_improvement`, or None);
    ``refusal`` None, or ``{"reason", "code", "state_covariance", ...}`` when the stale state is kept."""

    ref: Refinement
    sol: Any
    kkt: Any
    scale: float
    adaptation: Optional[dict]
    improvement: Optional[dict]
    refusal: Optional[dict]

    @property
    def solved(self) -> tuple:
        """``(ref, sol, kkt, scale)``: the solution in the form the solvers take as ``first``."""
        return self.ref, self.sol, self.kkt, self.scale


@dataclass(frozen=True)
class Adapted:
    """A solution with the a-priori adapted to the pass (:func:`solve_adapted`): the refinement
    with the a-priori used, its solution, KKT result (or None) and sigma scale, and the
    adaptation record (None when the a-priori was used as given)."""

    ref: Refinement
    sol: Any
    kkt: Any
    scale: float
    adaptation: Optional[dict]


def correlated_conflict_reason(test: dict, whiteness: dict, factor: float, inflation: float) -> str:
    """The reason given when a pass contradicts the a-priori on residuals correlated in time."""
    return (f"the pass contradicts the stale state's a-priori ({test['test']} chi2 "
            f"{test['statistic']:.4g} over {test['dof']}, limit {test['limit']:.3g}) but its residuals "
            "are correlated in time (lag-1 "
            f"{whiteness['lag1_autocorrelation']:.2f}, runs-test z {whiteness['runs_z']:.1f}): the data's noise model "
            "is as doubtful as the a-priori, so neither the refined state nor a loosened a-priori "
            "can be trusted; the stale covariance is scaled by "
            f"{factor:.3g} (its variance component with the data's information deflated by "
            f"{inflation:.3g})")


def solve_gated(ref: Refinement, start_factor: float = 1.0, first=None) -> Gated:
    """Solve with the gates: the improvement test (reported), then the a-priori: a conflict on
    residuals still correlated after the pass's noise model is refused (the data's noise model is
    as doubtful as the a-priori), otherwise the a-priori is adapted (a conflict the pass cannot
    carry is refused). ``ref`` carries the pass's noise
    model (:func:`solve_noise`; the solves are then GLS and the tests read whitened residuals);
    ``first`` ``(sol, kkt, scale)`` a solution of ``ref`` already made. Returns :class:`Gated`."""
    may = may_refuse(ref)
    original = pr.state_prior_covariance(ref.priors) if may else None
    work = with_scaled_priors(ref, start_factor) if start_factor != 1.0 else ref
    if first is None or start_factor != 1.0:
        first = solve_weighted(work)
    improvement = stale_improvement(work, first[0], first[2]) if work.priors else None
    stated = may and ref.apriori_source == "stated" and start_factor == 1.0
    # the a-priori test of the first solution, once (with a station's time-tag sigma it propagates
    # the orbit): the gates below and solve_adapted read the same one
    test = (refinement_apriori_test(work, first[0], first[1])
            if stated or (may and improvement is not None) else None)
    if stated:
        # a stated a-priori (a TLE's, a state file's covariance, --apriori-sigma) that the pass
        # contradicts is kept as it is: its accuracy is known, so the pass is the likely culprit
        # (methods/estimation/decision.py); it is never loosened to let the pass move the orbit
        if test is not None and test["conflict"]:
            decision = dm.declined("the stale state's stated a-priori", test)
            return Gated(work, first[0], first[1], first[2], None, improvement, {
                "code": "declined", "state_covariance": original, "reason": decision.reason,
                "decision": decision.as_dict()})
    # A pass that does not significantly tell the refined state from the stale one is no reason to
    # keep the stale state: the posterior already weighs the pass by its information (measured on
    # the DopTrack development pairs: refusing those kept 4 of 7 states whose refinement predicted
    # the next pass 9-35 % better). The test is reported (quality reason ``improvement``).
    if may and improvement is not None:
        # an a-priori conflict is evidence against the a-priori only if the data's own noise model
        # holds: time-correlated residuals overstate the data's information just as much, and
        # loosening the a-priori would then let the pass move the state by its own systematic
        # errors (docs/refine.md, "Quality")
        w = improvement["whiteness"]
        correlated = (w["lag1_autocorrelation"] > qm.WHITENESS_RHO
                      or (np.isfinite(w["runs_z"]) and abs(w["runs_z"]) > qm.RUNS_Z))
        if test is not None and test["conflict"] and correlated:
            chi2 = test["chi2"]
            # the kept covariance: the a-priori scaled by its variance component with the data's
            # information deflated by the correlation (never below the a-priori as given)
            pcov = pr.state_prior_covariance(work.priors)
            red = qm.prior_redundancy(np.asarray(work.covariance(first[0], first[1]), float)[:6, :6], pcov)
            comp = qm.prior_variance_component(chi2 / improvement["inflation"], red) or 1.0
            factor = max(1.0, comp)
            return Gated(work, first[0], first[1], first[2], None, improvement, {
                "code": "apriori_conflict_correlated", "state_covariance": original * factor,
                "covariance_factor": factor,
                "reason": correlated_conflict_reason(test, w, factor, improvement["inflation"])})
    adapted = solve_adapted(ref, start_factor, first=(work,) + tuple(first), first_test=test)
    work, sol, kkt, scale, adaptation = adapted.ref, adapted.sol, adapted.kkt, adapted.scale, adapted.adaptation
    if adaptation is not None:
        improvement = stale_improvement(work, sol, scale) if work.priors else improvement
        if may and not adaptation.get("resolved", True):
            return Gated(work, sol, kkt, scale, adaptation, improvement, {
                "code": "apriori_conflict", "state_covariance": original,
                "reason": "the pass contradicts the stale state's a-priori and cannot carry a looser one "
                          "(apriori_conflict); the stale covariance is kept as given"})
    return Gated(work, sol, kkt, scale, adaptation, improvement, None)


def circular_consistency(free: Refinement, constrained, sigma_scale: float = 1.0) -> dict:
    """Do the data contradict the circular-orbit constraints (seed 004 eq. 5)? The likelihood-ratio
    test: ``Δχ² = χ²(constrained) - χ²(free)`` is χ² with 2 degrees of freedom when the orbit is
    circular — three constraints, less the free radius ``r_ka`` that absorbs ``|r|² = r_ka²``
    (checked by Monte Carlo in the tests; with a fixed a-priori centre it is smaller on average,
    so the test errs towards silence). ``free`` is the same refinement without the constraints,
    solved here from the constrained solution with the same data sigmas."""
    try:
        sol, _ = free.solve(sigma_scale=sigma_scale, x0=np.asarray(constrained.values, float)[:len(free.names)])
    except ProcessingError as exc:
        return {"test": "likelihood ratio", "status": f"the unconstrained fit failed: {exc}"}
    delta = float(constrained.chi2 - sol.chi2)
    out = {"test": "likelihood ratio", "delta_chi2": delta, "dof": 2,
           "p_value": chi2_survival_2(delta),
           "free_fit_eccentricity": eccentricity(sol.values[:3], sol.values[3:6], free.mu),
           "edited_constrained_free": [int(constrained.n_edited), int(sol.n_edited)]}
    if constrained.n_edited != sol.n_edited:
        out["note"] = "the two fits edited different samples: the test is approximate"
    return out


def stale_improvement(ref: Refinement, sol, sigma_scale: float = 1.0, n_seen: int = 6) -> Optional[dict]:
    """:func:`~trackproc.methods.quality.improvement_test` of a pointwise solution: the data's χ²
    at the stale state (at the solution epoch, the Doppler offset/drift refitted — they enter
    linearly) against the refined state's, on the same samples and sigmas, deflated by the
    correlation of the refined residuals (:func:`~trackproc.methods.quality.whiteness`), with
    ``n_seen`` (the state directions the pass sees) degrees of freedom. None for the integral cost."""
    if ref.options.cost != "pointwise":
        return None
    _, y, sigma, _, _ = ref.data()
    keep = ~np.asarray(sol.edited, bool)
    s = np.asarray(sigma, float)[keep] * sigma_scale
    if ref.correlated():
        # GLS: the residuals whitened by the pass's noise model (independent, unit sigma)
        whiten = ref.noise.whitener(keep)

        def white(v):
            return whiten(v) / sigma_scale
    else:
        def white(v):
            v = np.asarray(v, float)[keep]
            return v / (s[:, None] if v.ndim == 2 else s)
    npb = ref.n_problem
    x = np.asarray(sol.values, float)[:npb].copy()
    x[:6] = ref.x0[:6]
    h, jac = ref.problem.model_near(x)        # the first solve's start, its offsets moved (linear)
    r = white(np.asarray(y, float) - h)
    bias, bias_cov, cross = np.zeros(0), np.zeros((0, 0)), np.zeros((0, 6))
    if npb > 6:
        a = white(np.asarray(jac, float)[:, 6:npb])
        db = np.linalg.lstsq(a, r, rcond=None)[0]
        r = r - a @ db
        bias, bias_cov = x[6:npb] + db, np.linalg.pinv(a.T @ a)
        pcov = pr.state_prior_covariance(ref.priors)
        if pcov is not None:
            # the offsets fitted with the state held at the stale one inherit its error e: they move by
            # -A⁺ J_x e (A, J_x the whitened columns of the offsets and of the state), so their
            # covariance adds A⁺ J_x P J_xᵀ A⁺ᵀ and they correlate with the state by -A⁺ J_x P
            k = np.linalg.pinv(a) @ white(np.asarray(jac, float)[:, :6])
            bias_cov = bias_cov + k @ pcov @ k.T
            cross = -k @ pcov
    chi2_stale = float(r @ r)
    computed = np.asarray(sol.computed, float)
    rr = white(np.asarray(y, float) - computed) if ref.correlated() else np.asarray(sol.residual, float)[keep] / s
    w = qm.whiteness(rr)
    out = qm.improvement_test(chi2_stale, float(rr @ rr), max(n_seen, 1), qm.correlation_inflation(
        w["lag1_autocorrelation"]))
    out["whiteness"] = w
    out["stale_nuisance"] = {"values": bias.tolist(), "covariance": bias_cov.tolist(), "state_cross": cross.tolist()}
    return out


#: the last :func:`refinement_apriori_test`: ``((ref, sol, kkt), result)``, the objects kept so
#: that their identity stands for their contents (the gates test the first solution, the quality
#: report tests the same one again)
_LAST_TEST: list = [((), None)]


def refinement_apriori_test(ref: Refinement, sol, kkt=None) -> Optional[dict]:
    """:func:`_apriori_test` of ``(ref, sol, kkt)``, the last call's result again (a copy) when these
    are the same objects."""
    key, made = _LAST_TEST[0]
    if len(key) == 3 and key[0] is ref and key[1] is sol and key[2] is kkt:
        return None if made is None else dict(made)
    made = _apriori_test(ref, sol, kkt)
    _LAST_TEST[0] = ((ref, sol, kkt), made)
    return None if made is None else dict(made)


def _apriori_test(ref: Refinement, sol, kkt=None) -> Optional[dict]:
    """:func:`trackproc.methods.estimation.prior.apriori_test` of a refinement: the innovation of the
    a-priori for the pointwise cost without ``circular``; the a-priori's share of χ² otherwise (the
    integral cost's covariance is a sandwich, ``circular``'s singular across the constraints). The
    station's time-tag uncertainty (a consider term, :func:`time_tag_covariance`) is part of what
    the correction may be: a pass whose tags are off by their stated sigma does not contradict the
    a-priori."""
    innovation = ref.options.cost == "pointwise" and not ref.options.circular
    if not innovation or pr.state_prior_covariance(ref.priors) is None:
        return pr.apriori_test(ref.priors, sol.values)
    cov = ref.covariance(sol, kkt)
    tt_sigma, _ = ref.time_tag_sigma()
    consider = time_tag_covariance(ref, sol.values, cov, tt_sigma) if tt_sigma > 0 else None
    return pr.apriori_test(ref.priors, sol.values, cov, consider_cov=consider)


def with_scaled_priors(ref: Refinement, factor: float) -> Refinement:
    """``ref`` with the covariance of its state a-priori multiplied by ``factor``."""
    return replace(ref, priors=pr.scaled_priors(ref.priors, factor))


def solve_adapted(ref: Refinement, start_factor: float = 1.0, x0=None, first=None,
                  first_test: Optional[dict] = None) -> Adapted:
    """:func:`solve_weighted`, then, when the a-priori test rejects (the state's a-priori share of
    χ² above the 99.9 % point of χ²(rows)), the a-priori covariance is scaled by its
    maximum-likelihood variance component (Helmert/Förstner:
    :func:`~trackproc.methods.quality.prior_variance_component`, iterated to a fixed point,
    never below 1) and the problem solved again: a stale state further off than its a-priori says
    is weighed by how far off the data show it to be, and the covariance covers that.
    ``start_factor`` starts from an already scaled a-priori; ``first`` ``(work, sol, kkt, scale)``
    a solution already made with it, ``first_test`` its :func:`refinement_apriori_test` when already
    made. Returns :class:`Adapted`."""
    if first is not None:
        work, sol, kkt, scale = first
    else:
        work = with_scaled_priors(ref, start_factor) if start_factor != 1.0 else ref
        sol, kkt, scale = solve_weighted(work, x0=x0)
    if not pr.has_state_prior(ref.priors):
        return Adapted(work, sol, kkt, scale, None)
    test = first_test if first is not None and first_test is not None else refinement_apriori_test(work, sol, kkt)
    chi2, rows = test["chi2"], test["rows"]
    if not test["conflict"] and start_factor == 1.0:
        return Adapted(work, sol, kkt, scale, None)
    start = {"chi2": chi2, "rows": rows, "limit": qm.chi2_limit(rows), "test": test}
    factor = start_factor
    history = []
    kept = (work, sol, kkt, scale)
    for _ in range(MAX_APRIORI_ADAPT):
        pcov = pr.state_prior_covariance(work.priors)
        red = (qm.prior_redundancy(np.asarray(work.covariance(sol, kkt), float)[:6, :6], pcov)
               if pcov is not None else math.nan)
        k_hat, following = pr.adapt_step(chi2, red, factor)
        history.append({"factor": factor, "chi2": chi2, "redundancy": red, "component": k_hat})
        if following is None:
            break
        factor = following
        try:
            trial = with_scaled_priors(ref, factor)
            # from the previous solution a consistent scale converges in a few iterations
            quick = replace(trial, options=replace(ref.options, max_iterations=min(ref.options.max_iterations,
                                                                                     MAX_ADAPT_ITERATIONS)))
            sol, kkt, scale = solve_weighted(quick, x0=sol.values)
            work = trial
        except ProcessingError as exc:
            # the pass alone cannot carry a looser a-priori: keep the last solution, say so
            work, sol, kkt, scale = kept
            history.append({"factor": factor, "failed": str(exc)})
            factor = history[-2]["factor"] if len(history) > 1 else start_factor
            chi2, rows = pr.state_prior_chi2(work.priors, sol.values)
            return Adapted(work, sol, kkt, scale, {
                "method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated",
                "factor": factor, "sigma_factor": math.sqrt(factor), "chi2_before": start["chi2"], "chi2_after": chi2,
                "rows": rows, "limit": start["limit"], "iterations": history, "resolved": False,
                "test": pr.test_report(start["test"]),
                "failure": f"with the a-priori scaled by {history[-1]['factor']:.3g} the refinement failed: "
                           f"{str(exc).split(' (')[0]}"})
        kept = (work, sol, kkt, scale)
        chi2, rows = pr.state_prior_chi2(work.priors, sol.values)
    after = refinement_apriori_test(work, sol, kkt)
    adaptation = {"method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated",
                  "factor": factor, "sigma_factor": math.sqrt(factor), "chi2_before": start["chi2"],
                  "chi2_after": chi2, "rows": rows, "limit": start["limit"], "iterations": history,
                  "test": pr.test_report(start["test"]), "test_after": pr.test_report(after),
                  "resolved": bool(not after["conflict"] or (history and history[-1].get("component") is not None
                                                             and abs(history[-1]["component"] - 1.0) < 0.1))}
    return Adapted(work, sol, kkt, scale, adaptation)


def solve_weighted(ref: Refinement, observed=None, prior_centre=None, x0=None):
    """:meth:`Refinement.solve`, repeated with the sample sigmas scaled by √(variance factor) while
    that exceeds :data:`REWEIGHT_THRESHOLD` (pointwise with ``reweight``). Returns
    ``(Solution, KKTResult or None, sigma scale)``. ``observed``, ``prior_centre``, ``x0`` as in
    :meth:`Refinement.solve` (Monte Carlo)."""
    scale = 1.0
    for _ in range(MAX_REWEIGHT):
        sol, kkt = ref.solve(observed=observed, prior_centre=prior_centre, sigma_scale=scale, x0=x0)
        vf = sol.variance_factor
        if not (ref.options.reweight and ref.options.cost == "pointwise" and math.isfinite(vf)
                and vf > REWEIGHT_THRESHOLD):
            break
        scale *= math.sqrt(vf)
        x0 = sol.values
    return sol, kkt, scale
