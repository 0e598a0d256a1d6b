"""Noise model and consistency gates of an estimate: :func:`pass_noise` (per-pass REML, then
GLS), :func:`solve` (the weighted fit, then the correlated one; the a-priori gate) and
:func:`warnings_of` (the summary's warnings). The ``quality`` verdict: :mod:`trackproc.pipeline.estimate.quality`."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.methods import noise as nz
from trackproc.methods import quality as qm
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.methods.estimation.prior import (scaled_priors, state_prior_centre, state_prior_chi2,  # noqa: F401
                                               state_prior_covariance)
from trackproc.models import modifiers as md
from trackproc.pipeline.od.options import EstimateOptions
from trackproc.pipeline.od import decision as od_decision
from trackproc.pipeline.od.problem import Problem
from trackproc.pipeline.estimate.quality import pass_residuals
from trackproc.pipeline.od.samples import groups


#: Iterations of the a-priori variance-component adaptation at most (as refine's).
MAX_APRIORI_ADAPT = 6


def solve(problem: Problem, opt: EstimateOptions):
    """The weighted least-squares fit, then (unless ``--noise white``) REML of each pass's noise
    on its residuals, GLS, REML again on the GLS residuals and GLS; then the a-priori gate
    (:func:`adapt_apriori`, or :func:`refuse`). Returns ``(solution, adaptation or None, noise report or None)``."""
    sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol)
    noise_report = None
    used = None
    if opt.noise != "white" or opt.oscillator_noise is not None:
        previous = None
        for _ in range(2):            # REML on the residuals, GLS, REML again on its residuals
            # the weighted fit's Jacobian is the model's at its solution; a GLS solution's is whitened
            cov, noise_report = pass_noise(problem, sol, opt, jacobian=sol.jacobian if previous is None else None)
            if cov is None and previous is None:
                break                 # white: the weighted fit stands
            sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol,
                                noise=cov, edited=sol.edited, x0=sol.values)
            previous = used = cov
    test = pr.apriori_test(problem.priors, sol.values, sol.covariance)
    if test is None or not test["conflict"] or state_prior_covariance(problem.priors) is None:
        return keep_or_replace(problem, opt, sol, used) + (noise_report,)
    # The a-priori is scaled by the data; but a conflict is evidence against the a-priori only if
    # the data's own noise model holds on the adapted solution: residuals still correlated in
    # time, or a variance factor beyond its limit, overstate the data's information just as much,
    # and a loosened a-priori would then let the passes move the state by their own systematic
    # errors (measured on the DopTrack development evenings: 3.2-3.4x worse than the TLE on the
    # held-back pass). Then the initial state is kept (refine's gate, pipeline/refine.py).
    original = problem.priors
    sol_a, adaptation = adapt_apriori(problem, opt, sol, used)
    doubt = doubtful_noise(problem, sol_a)
    if not doubt and adaptation["resolved"]:
        loss = knowledge_lost(problem.priors, sol_a)
        if loss is not None:
            adaptation["resolved"] = False
            adaptation["failure"] = loss
    if doubt or not adaptation["resolved"]:
        problem.priors = original
        if problem.apriori_source == "stated":
            # a stated a-priori (a TLE's, a state file's covariance, --apriori-sigma) contradicted by data
            # that cannot vouch for themselves (their noise model fails, or they do not determine the
            # state without it) is kept as it is: its accuracy is known, the data are the likely
            # culprit (methods/estimation/decision.py); it is never loosened to let them move the orbit
            decision = dm.declined("the initial state's stated a-priori", test)
            why = "; ".join(doubt) if doubt else adaptation.get("failure") or "the data cannot carry a looser one"
            decision.reason += f" ({why})"
            return hold(problem, opt, sol, used, test, "declined", decision.reason,
                        decision.as_dict()) + (noise_report,)
        return refuse(problem, opt, sol, used, test, doubt, adaptation) + (noise_report,)
    if problem.apriori_source == "stated":
        # data that determine the state without the a-priori and pass their own tests contradict a
        # stated one: the a-priori is the culprit; it is scaled, and the verdict says it was stated
        adaptation["stated"] = True
    sol_k, kept = keep_or_replace(problem, opt, sol_a, used)
    if kept is not None:
        kept.update({k: v for k, v in adaptation.items() if k not in kept})
        return sol_k, kept, noise_report
    adaptation["decision"] = problem.decision
    return sol_a, adaptation, noise_report


def keep_or_replace(problem: Problem, opt: EstimateOptions, sol, noise=None):
    """The replace/keep rule (methods/estimation/decision.py) on a solution with a full state
    a-priori: the solution replaces the initial state only when it predicts the position better
    with probability >= 0.9 somewhere over ``opt.horizon_days``. Returns ``(solution, None)`` when
    it does (``problem.decision`` says why) or there is nothing to decide, else the initial state
    held (:func:`hold`, code ``kept``) and its record."""
    problem.decision = None
    if state_prior_covariance(problem.priors) is None or not opt.allow_keep:
        return sol, None
    npb = len(problem.names)
    made = od_decision.by_prediction(problem, np.asarray(sol.values, float)[:npb],
                                     np.asarray(sol.covariance, float)[:npb, :npb], problem.priors, opt.horizon_days,
                                     problem.apriori_source or None)
    if made is None:
        return sol, None
    problem.decision = made.as_dict()
    if not made.keeps_prior:
        return sol, None
    test = pr.apriori_test(problem.priors, sol.values, sol.covariance)
    kept, out = hold(problem, opt, sol, noise, test, "kept", made.reason, made.as_dict())
    out["fitted_solution"] = sol        # the data's checks are the fit's (the kept state is not a fit)
    return kept, out


def hold(problem: Problem, opt: EstimateOptions, sol, noise, test: dict, code: str, reason: str, decision: dict):
    """Keep the initial state with its a-priori covariance as given (``declined`` or ``kept``:
    methods/estimation/decision.py), the other parameters fitted with the state held there
    (:func:`refuse`'s way, unscaled). Returns ``(solution, record)``."""
    kept, out = refuse(problem, opt, sol, noise, test, [], None, scale=False)
    out["refused"] = {"code": code, "reason": reason, "covariance_factor": 1.0}
    out["decision"] = decision
    problem.decision = decision
    return kept, out


def knowledge_lost(priors, sol) -> str | None:
    """Why an adapted solution rests on its loosened a-priori rather than on the data (None when
    it does not): in some direction of the state the data weigh less than the scaled a-priori,
    i.e. the largest generalised eigenvalue of ``C_post v = λ P v`` (``P`` the scaled a-priori
    covariance; ``λ = 1 / (1 + d)`` with ``d`` the data's information there relative to the
    a-priori's) is above 1/2. The variance component that loosens the a-priori is estimated from
    the directions the data see; where they see little (one low pass), the loosened a-priori is
    all the solution has, and the data move the state there by their own systematic errors: the
    initial state is kept instead (DopTrack 12 April 2020, one pass: the adapted solution
    predicted the next pass 6.4 times worse than the TLE, with verdict ok)."""
    p = state_prior_covariance(priors)
    if p is None:
        return None
    worst = pr.prior_dominance(np.asarray(sol.covariance, float)[:6, :6], p)
    if not worst > 0.5:
        return None
    return (f"with the a-priori loosened, the data weigh less than it in some direction of the state "
            f"(posterior/a-priori variance {worst:.2f} > 0.5): the solution there is the loosened a-priori's")


def refuse(problem: Problem, opt: EstimateOptions, sol, noise, test: dict, doubt: list,
           adaptation: dict | None = None, scale: bool = True):
    """Keep the initial state: the state at the a-priori centre with the a-priori covariance
    scaled by its variance component, one step on ``sol`` (the conflict as the data first show
    it; never below 1, so that it covers the conflict: the iterated component of an adaptation
    that is not trusted can run away — the doubtful data pull further as the a-priori loosens —
    34 000 on a DopTrack hold-out pass, a 500 km sigma for a kept TLE),
    the other parameters (biases) fitted with the state held there (their covariance is
    conditional on it: no cross-covariance with the state is written). Returns ``(solution,
    adaptation)`` with ``adaptation["refused"]`` saying why; ``test``: the conflict
    (:func:`trackproc.methods.estimation.prior.apriori_test`)."""
    chi2 = test["chi2"]
    said = f"{test['test']} chi2 {test['statistic']:.4g} over {test['dof']}, limit {test['limit']:.3g}"
    pcov = state_prior_covariance(problem.priors)
    red = qm.prior_redundancy(np.asarray(sol.covariance, float)[:6, :6], pcov)
    factor = max(1.0, qm.prior_variance_component(chi2, red) or 1.0) if scale else 1.0
    centre = state_prior_centre(problem.priors)
    x0 = np.asarray(sol.values, float).copy()
    x0[:6] = centre
    pinned = scaled_priors(problem.priors, 1e-10)      # the state held at the a-priori centre (sigmas x 1e-5)
    held = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol, priors=pinned,
                         noise=noise, edited=sol.edited, x0=x0)
    values = np.asarray(held.values, float).copy()
    values[:6] = centre
    cov = np.asarray(held.covariance, float).copy()
    cov[:6, :] = 0.0
    cov[:, :6] = 0.0
    cov[:6, :6] = pcov * factor
    sigma = np.sqrt(np.diag(cov))
    kept = replace(held, values=values, covariance=cov, sigma=sigma, correlation=cov / np.outer(sigma, sigma))
    problem.priors = scaled_priors(problem.priors, factor)
    why = ("; ".join(doubt) + ", with the a-priori scaled by the data" if doubt else
           f"the data cannot carry a looser a-priori ({(adaptation or {}).get('failure') or 'not resolved'})")
    out = dict(adaptation or {"method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner)",
                              "chi2_before": test["statistic"], "rows": test["dof"], "limit": test["limit"],
                              "test": test["test"]})
    out.update({"factor": factor, "sigma_factor": math.sqrt(factor), "resolved": False,
                "refused": {"code": "apriori_conflict_doubtful_noise" if doubt else "apriori_conflict",
                            "covariance_factor": factor,
                            "reason": (f"the data contradict the initial state's a-priori ({said}) but their noise "
                                       f"model is in doubt: {why}; "
                                       "neither the estimated state nor a loosened a-priori can be trusted"
                                       if doubt else
                                       f"the data contradict the initial state's a-priori ({said}) and {why}")
                            + f"; the initial state is kept, its a-priori covariance scaled by {factor:.3g}"}})
    return kept, out


def adapt_apriori(problem: Problem, opt: EstimateOptions, sol, noise=None):
    """The a-priori gate: when the state a-priori's share of χ² exceeds the 99.9 % point of
    χ²(rows), its covariance is scaled by its maximum-likelihood variance component
    (Helmert/Förstner, :func:`~trackproc.methods.quality.prior_variance_component`, iterated to
    a fixed point, never below 1) and the problem solved again (with the same noise model): an
    initial state further off than its a-priori says is weighed by how far off the data show it
    to be, and the covariance covers that (refine's gate, :func:`trackproc.pipeline.refine.solve_adapted`).
    ``problem.priors`` become the scaled ones. Returns ``(solution, adaptation dict or None)``;
    the adaptation is ``resolved`` False when the data cannot carry a looser a-priori."""
    test = pr.apriori_test(problem.priors, sol.values, sol.covariance)
    if test is None or not test["conflict"] or state_prior_covariance(problem.priors) is None:
        return sol, None
    chi2 = test["chi2"]             # the a-priori's share of chi2: the variance component's input
    factor, history, failure = 1.0, [], None
    priors = problem.priors
    for _ in range(MAX_APRIORI_ADAPT):
        red = qm.prior_redundancy(np.asarray(sol.covariance, float)[:6, :6], state_prior_covariance(priors))
        k_hat, trial_factor = pr.adapt_step(chi2, red, factor)
        history.append({"factor": factor, "chi2": chi2, "redundancy": red, "component": k_hat})
        if trial_factor is None:
            break
        trial = scaled_priors(problem.priors, trial_factor)
        try:
            sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol,
                                priors=trial, noise=noise, edited=sol.edited, x0=sol.values)
        except ProcessingError as exc:
            failure = (f"with the a-priori scaled by {trial_factor:.3g} the estimation failed: "
                       f"{str(exc).split(' (')[0]}")
            break
        factor, priors = trial_factor, trial
        chi2, _ = state_prior_chi2(priors, sol.values)
    problem.priors = priors
    last = history[-1].get("component")
    after = pr.apriori_test(priors, sol.values, sol.covariance)
    resolved = failure is None and (not after["conflict"] or (last is not None and abs(last - 1.0) < 0.1))
    # chi2_before/rows/limit: the test that fired (chi2_after: the same test with the scaled a-priori)
    return sol, {"method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated",
                 "factor": factor, "sigma_factor": math.sqrt(factor), "test": test["test"],
                 "chi2_before": test["statistic"], "chi2_after": after["statistic"], "rows": test["dof"],
                 "limit": test["limit"], "iterations": history, "resolved": bool(resolved),
                 **({"failure": failure} if failure else {})}


def warnings_of(sol) -> list:
    """The summary's warnings: variance factor, a-priori conflict, edited samples."""
    warnings = []
    if sol.dof > 0 and sol.variance_factor > 4.0:
        warnings.append(f"a-posteriori variance factor {sol.variance_factor:.3g} (> 4): the sigmas of the data "
                        "are too small or the model misses something; the covariance is optimistic")
    if sol.n_prior:
        limit = qm.chi2_limit(sol.n_prior)
        if sol.chi2_prior > limit:
            warnings.append(f"the solution departs from the a-priori values by chi2 = {sol.chi2_prior:.4g} over "
                            f"{sol.n_prior} constraints (99.9 % limit {limit:.3g}): the data and the a-priori "
                            "(initial state, biases) disagree; check for a bad pass")
    if sol.n_edited > 0.1 * sol.n_measurements:
        warnings.append(f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)")
    return warnings


def doubtful_noise(problem: Problem, sol) -> list:
    """Why the data's noise model is in doubt on ``sol`` (empty when it holds): the variance
    factor beyond its 99.9 % point, or residuals correlated in time beyond the 99.9 % point for
    the worst of the m passes (Bonferroni: the lag-1 autocorrelation's ``ρ √n`` or the runs
    test's ``|z|`` above ``Φ⁻¹(1 - 0.001/(2m))``, so that white passes are not doubted by chance:
    on short white passes ρ > 0.3 happens one time in ten)."""
    out = []
    if sol.dof > 0 and math.isfinite(sol.variance_factor):
        limit = qm.variance_factor_limit(sol.dof)
        if sol.variance_factor > limit:
            out.append(f"a-posteriori variance factor {sol.variance_factor:.4g} (99.9 % limit {limit:.3g})")
    passes = [p for p in pass_residuals(problem, sol) if math.isfinite(p["whiteness"]["lag1_autocorrelation"])]
    if passes:
        crit = qm.whiteness_family_limit(len(passes))
        worst = max(passes, key=lambda p: qm.whiteness_score(p["whiteness"]))
        if qm.whiteness_score(worst["whiteness"]) > crit:
            w = worst["whiteness"]
            out.append(f"pass {worst['pass']}: residuals correlated in time (lag-1 autocorrelation "
                       f"{w['lag1_autocorrelation']:.2f} over {w['n']} samples, runs-test z {w['runs_z']:.1f}; "
                       f"limit {crit:.2f} for the worst of {len(passes)} passes)")
    return out


def pass_noise(problem: Problem, sol, opt: EstimateOptions, jacobian=None):
    """The noise model of every pass's Doppler and range-rate samples from the residuals of
    ``sol`` (:func:`trackproc.methods.noise.fit_noise`: REML with the pass's Jacobian columns as
    fixed effects; the random walk of the transmitter frequency only for one-way passes with a
    frequency offset, i.e. an :class:`~trackproc.models.modifiers.OscillatorWander` on its
    samples). ``jacobian``: the model's (unwhitened) Jacobian at ``sol.values`` when the caller
    has it, else evaluated here. Returns ``(PassCovariance or None when every pass is white,
    report)``; the report lists each pass's model and effective number of samples."""
    meas = problem.meas
    keep_all = ~np.asarray(sol.edited, bool)
    rr = np.isin(meas.kind, ["doppler", "range_rate"])
    blocks, report = [], {}
    wanders = [b for b in problem.modifiers if isinstance(b.modifier, md.OscillatorWander)]
    jac_all = problem.model(np.asarray(sol.values, float))[1] if jacobian is None else jacobian
    rr_rows = np.flatnonzero(rr)
    for (st, pid), sub in groups(meas.station[rr_rows], meas.pass_id[rr_rows]):
        rows = rr_rows[sub]
        keep = keep_all[rows]
        if keep.sum() < 20:
            continue
        t = meas.t_s[rows]
        jac = np.asarray(jac_all, float)[rows]
        wander = next((b.modifier for b in wanders if np.isin(rows, b.rows).all()), None)
        osc = wander is not None
        nf = nz.fit_noise(t[keep], np.asarray(sol.residual, float)[rows][keep], jac[keep],
                          models=nz.candidate_models(opt.noise, osc),
                          walk=wander.walk if osc else None, t0=float(t.min()))
        d = nf.as_dict()
        d.pop("candidates", None)
        report[f"{st}/{pid}"] = d
        if not nf.model.is_white:
            blocks.append((rows, nf.model, float(t.min())))
    if not blocks:
        return None, report
    return nz.PassCovariance(meas.sigma, meas.t_s, blocks), report
