"""The filter's output under the shared prior-and-decline policy (docs/design.md, "Prior and
decision"; :mod:`trackproc.methods.estimation.decision`): the written state replaces the stated
prior only when the data do not contradict it and it is expected to predict better.

Both tests are the shared ones, at the output epoch:

1. the a-priori test (:func:`trackproc.methods.estimation.prior.apriori_test`, the innovation of
   the a-priori against ``P − C``; no consider term, as ``estimate``) of the written solution
   against the prior *at the output epoch*: the filter's start (its state a-priori, or a carried
   state) moved there by the filter's own time update without data (:func:`~.result.move`: the
   force model's transition, plus the process noise over the interval when forward). That is
   what the prior predicts there under the filter's model, so the test compares like with like:
   with process noise the solution's covariance is the same prediction updated by the data. The
   test is evaluated at the prior's own epoch, on the solution moved back there and the prior
   with that process noise moved back (``P₀ + Φ⁻¹QΦ⁻ᵀ``): linearly the same statistic, but a
   loose prior's covariance is not mapped over the arc, where its linearisation fails (the
   shipped 10 km / 5 m/s stale state over 12 h: 32.2 over 6 at the output epoch against 0.80 at
   its epoch, estimate's 0.80). A stated prior contradicted by the data is **declined** (a
   default one, with no stated accuracy, is not: the filter's solution stands and the verdict
   says so);
2. the replace-or-keep rule (:func:`trackproc.pipeline.od.decision.by_prediction`) of the move
   from that prior over ``--horizon`` days after the output epoch.

A declined or kept prior is written in place of the solution: its state and covariance at the
output epoch; the other parameters (biases, force parameters) fitted with the state held there,
i.e. the filter's Gaussian posterior conditioned on the state being the prior's (``b + G (s₀ − s)``,
``G = P_bs P_ss⁻¹``), carrying the prior state's uncertainty through ``G`` (``P_b|s + G P₀ Gᵀ`` and
the cross-covariance ``G P₀``), as refine's kept state does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Optional

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.methods import quality as qm
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.methods.least_squares import Prior
from trackproc.pipeline.od import Problem
from trackproc.pipeline.od import decision as od_decision


#: Re-runs of the filter with the state a-priori scaled by its variance component at most (as
#: estimate's ``MAX_APRIORI_ADAPT``).
MAX_APRIORI_ADAPT = 6
#: Verdict codes of the filter that put the data's own noise model in doubt (estimate's variance
#: factor and residual correlation): the innovation test and the innovations' whiteness.
DOUBT_CODES = ("innovations", "whiteness")


@dataclass
class Candidate:
    """One run's answer: the written ``x``, ``p`` at ``epoch``; the same moved back to the prior's
    epoch (``back_x``, ``back_p``: the a-priori test's operands); its verdict ``quality``, its
    ``sweep`` and ``iterations``."""

    x: np.ndarray
    p: np.ndarray
    epoch: object
    back_x: np.ndarray
    back_p: np.ndarray
    quality: object
    sweep: object = None
    iterations: list = field(default_factory=list)


@dataclass
class PriorAt:
    """The prior at the output epoch (``x``, ``p``: the filter's start moved there by its time
    update, with the process noise) and at its own epoch (``x0``; ``p0``: its covariance with that
    process noise moved back, ``P₀ + Φ⁻¹QΦ⁻ᵀ``)."""

    x: np.ndarray
    p: np.ndarray
    x0: np.ndarray
    p0: np.ndarray


@dataclass
class Outcome:
    """The written ``x``, ``p`` (the chosen run's solution, or the prior held) and what was decided:
    the ``decision`` record (:meth:`~trackproc.methods.estimation.decision.Decision.as_dict`, None
    when there was nothing to decide), the a-priori ``test`` of the first run, the chosen
    ``candidate`` run and the ``adaptation`` when the a-priori was scaled."""

    x: np.ndarray
    p: np.ndarray
    candidate: Candidate
    decision: Optional[dict] = None
    test: Optional[dict] = None
    adaptation: Optional[dict] = None


def hold(x, p, prior_x, prior_p) -> tuple[np.ndarray, np.ndarray]:
    """The prior's state ``prior_x[:6]`` with its covariance ``prior_p[:6, :6]``; the other
    parameters of the posterior ``(x, p)`` conditioned on the state being the prior's, with the
    prior state's uncertainty carried through the gain (module docstring)."""
    x = np.asarray(x, float)
    p = np.asarray(p, float)
    s0 = np.asarray(prior_x, float)[:6]
    p0 = np.asarray(prior_p, float)[:6, :6]
    gain = np.linalg.solve(p[:6, :6], p[:6, 6:]).T                 # G = P_bs P_ss^-1, (n-6, 6)
    out_x = x.copy()
    out_x[:6] = s0
    out_x[6:] = x[6:] + gain @ (s0 - x[:6])
    out_p = np.empty_like(p)
    out_p[:6, :6] = p0
    out_p[6:, :6] = gain @ p0
    out_p[:6, 6:] = out_p[6:, :6].T
    out_p[6:, 6:] = p[6:, 6:] - gain @ p[:6, 6:] + gain @ p0 @ gain.T
    return out_x, 0.5 * (out_p + out_p.T)


def _state_prior(x, p) -> list:
    return [Prior(np.arange(6), np.asarray(x, float)[:6], np.asarray(p, float)[:6, :6])]


def adapt(first: Candidate, prior: PriorAt, test: dict, rerun: Callable[[float], Candidate]):
    """Estimate's a-priori gate in sequential form: the state a-priori's covariance scaled by its
    maximum-likelihood variance component (Helmert/Förstner, ``σ²_p = vᵀPv / r_p``, Koch 1999 eq.
    3.291; :func:`~trackproc.methods.quality.prior_variance_component`), the filter run again from
    it, iterated to a fixed point (never below 1). Returns ``(run, adaptation)``; ``resolved``
    False when the data cannot carry a looser a-priori: still in conflict, a failed run, their own
    noise model in doubt on the adapted run (:data:`DOUBT_CODES`), or leaning on the loosened
    a-priori in some direction (:func:`~trackproc.methods.estimation.prior.prior_dominance` above
    1/2) — then the stated prior is declined, as estimate's."""
    cand, factor, chi2, history, failure = first, 1.0, test["chi2"], [], None
    for _ in range(MAX_APRIORI_ADAPT):
        red = qm.prior_redundancy(np.asarray(cand.back_p, float)[:6, :6], prior.p0[:6, :6] * factor)
        k_hat, trial = pr.adapt_step(chi2, red, factor)
        history.append({"factor": factor, "chi2": chi2, "redundancy": red, "component": k_hat})
        if trial is None:
            break
        try:
            cand = rerun(trial)
        except (ProcessingError, np.linalg.LinAlgError) as exc:
            failure = f"with the a-priori scaled by {trial:.3g} the filter failed: {str(exc).split(' (')[0]}"
            break
        factor = trial
        chi2 = pr.state_prior_chi2(_state_prior(prior.x0, prior.p0 * factor), cand.back_x)[0]
    scaled = prior.p0[:6, :6] * factor
    after = pr.apriori_test(_state_prior(prior.x0, scaled), cand.back_x, cand.back_p)
    last = history[-1].get("component")
    resolved = failure is None and (not after["conflict"] or (last is not None and abs(last - 1.0) < 0.1))
    doubt = [r["message"] for r in cand.quality.reasons if r["code"] in DOUBT_CODES and r["severity"] != "ok"]
    if resolved and not doubt:
        share = pr.prior_dominance(np.asarray(cand.back_p, float)[:6, :6], scaled)
        if share > 0.5:
            resolved = False
            failure = (f"with the a-priori loosened, the data weigh less than it in some direction of the state "
                       f"(posterior/a-priori variance {share:.2f} > 0.5): the solution there is the loosened "
                       "a-priori's")
    return cand, {"method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated, "
                            "the filter run again from it",
                  "factor": factor, "sigma_factor": math.sqrt(factor), "test": test["test"],
                  "chi2_before": test["statistic"], "chi2_after": after["statistic"], "rows": test["dof"],
                  "limit": test["limit"], "iterations": history, "resolved": bool(resolved and not doubt),
                  "doubt": doubt, **({"failure": failure} if failure else {})}


def decide(problem: Problem, first: Candidate, prior: PriorAt, out_epoch, rerun: Callable[[float], Candidate],
           horizon_days: float = dm.HORIZON_DAYS, allow_keep: bool = True) -> Outcome:
    """The policy (module docstring) on the filter's run ``first`` against its ``prior``, as
    estimate's (``pipeline/estimate/gates.solve``): a stated prior the data contradict is scaled
    (:func:`adapt`, runs through ``rerun(scale)``); if the data then cannot vouch for themselves
    it is declined (written as it is), else the adapted run stands (the stated accuracy was
    wrong); then replaced or kept by prediction over ``horizon_days`` (``allow_keep`` False: not).
    ``problem.apriori_source`` says whether the prior is stated."""
    test = pr.apriori_test(_state_prior(prior.x0, prior.p0), first.back_x, first.back_p)
    source = problem.apriori_source or None
    cand, adaptation = first, None
    if test is not None and test["conflict"]:
        cand, adaptation = adapt(first, prior, test, rerun)
        if not adaptation["resolved"] and source != "stated":
            cand = first          # a default a-priori the data cannot carry: the first run stands, said suspect
        elif not adaptation["resolved"]:
            made = dm.declined("the filter's stated prior (the initial state's a-priori)", test)
            why = "; ".join(adaptation["doubt"]) or adaptation.get("failure") or "the data cannot carry a looser one"
            made.reason += f" ({why})"
            hx, hp = hold(first.x, first.p, prior.x, prior.p)
            return Outcome(hx, hp, first, made.as_dict(), test, adaptation)
        else:
            adaptation["stated"] = source == "stated"
    if not allow_keep:
        return Outcome(cand.x, cand.p, cand, None, test, adaptation)
    at_output = replace(problem, epoch=np.datetime64(out_epoch, "ns"), frame=None)
    made = od_decision.by_prediction(at_output, cand.x, cand.p, _state_prior(prior.x, prior.p), horizon_days, source)
    if made is None:
        return Outcome(cand.x, cand.p, cand, None, test, adaptation)
    if made.keeps_prior:
        hx, hp = hold(cand.x, cand.p, prior.x, prior.p)
        return Outcome(hx, hp, cand, made.as_dict(), test, adaptation)
    return Outcome(cand.x, cand.p, cand, made.as_dict(), test, adaptation)


def add_reasons(q: qm.Quality, outcome: Outcome, source: Optional[str]) -> None:
    """The decision in the verdict, with estimate's codes: ``declined`` (suspect), ``kept`` (ok),
    ``replaced`` (ok), and ``apriori_conflict`` when the a-priori was scaled (ok: the data carried
    it; suspect: a default a-priori they could not carry, the first run's solution stands).

    When the prior is written (declined or kept), the run's own failures (a diverged filter, its
    samples edited away) say why the data were not used, not that the written state is wrong:
    they are at most ``suspect``, and the exit status is the policy's (0; 1 with ``--strict``)."""
    d, test, a = outcome.decision, outcome.test, outcome.adaptation
    if d is not None and d["action"] in ("declined", "kept"):
        for r in q.reasons:
            if r["severity"] == "rejected":
                r["severity"] = "suspect"
                r["message"] += " (the filter's run; the prior is written, not this run's state)"
    if d is not None and d["action"] == "declined":
        q.add("declined", "suspect", d["reason"], value=test["statistic"], limit=test["limit"])
        return
    said = f"{test['test']} chi2 {test['statistic']:.4g} over {test['dof']}, limit {test['limit']:.3g}" if test else ""
    if a is not None and a["resolved"]:
        q.add("apriori_conflict", "ok",
              f"the data contradicted the state a-priori ({said}); its covariance was scaled by {a['factor']:.3g} "
              f"(sigmas x{a['sigma_factor']:.3g}, maximum-likelihood variance component) and the filter run again"
              + ("; the a-priori was stated, but the data determine the state without it and pass their own "
                 "tests: the stated accuracy was wrong" if a.get("stated") else ""),
              value=test["statistic"], limit=test["limit"])
    elif test is not None and test["conflict"]:
        why = "; ".join((a or {}).get("doubt") or []) or (a or {}).get("failure") or "no full a-priori to scale"
        q.add("apriori_conflict", "suspect",
              f"the data contradict the state a-priori ({said}) and cannot carry a looser one ({why}); it has no "
              f"stated accuracy ({source or 'none'}), so the filter's first solution stands",
              value=test["statistic"], limit=test["limit"])
    if d is None:
        return
    if d["action"] == "kept":
        q.add("kept", "ok", f"the initial state is kept: {d['reason']}", value=d.get("probability_better"),
              limit=dm.REPLACE_PROBABILITY)
    else:
        q.add("replaced", "ok", d["reason"], value=d.get("probability_better"), limit=dm.REPLACE_PROBABILITY)
