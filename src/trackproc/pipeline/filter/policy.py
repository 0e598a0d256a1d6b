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

from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from trackproc.methods import quality as qm
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.methods.least_squares import Prior
from trackproc.pipeline.od import Problem
from trackproc.pipeline.od import decision as od_decision


@dataclass
class Outcome:
    """The written ``x``, ``p`` (the solution, or the prior held) and what was decided: the
    ``decision`` record (:meth:`~trackproc.methods.estimation.decision.Decision.as_dict`, None when
    there was nothing to decide) and the a-priori ``test``."""

    x: np.ndarray
    p: np.ndarray
    decision: Optional[dict] = None
    test: Optional[dict] = None


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


def decide(problem: Problem, x, p, prior_x, prior_p, out_epoch, horizon_days: float = dm.HORIZON_DAYS,
           allow_keep: bool = True, tested=None) -> Outcome:
    """The policy on the filter's output ``(x, p)`` at ``out_epoch`` against its prior
    ``(prior_x, prior_p)`` moved to the same epoch (module docstring). ``tested``: the a-priori
    test's operands where the prior is stated, ``(solution x, P, prior x, P)`` at its epoch (the
    solution moved back, the prior's covariance with the process noise to the output epoch moved
    back), linearly the same test as at the output epoch; None: at the output epoch.
    ``problem.apriori_source`` says whether the prior is stated; ``allow_keep`` False: the
    replace-or-keep rule off (as ``estimate``'s option)."""
    x = np.asarray(x, float)
    p = np.asarray(p, float)
    priors = _state_prior(prior_x, prior_p)
    if tested is None:
        test = pr.apriori_test(priors, x, p)
    else:
        test = pr.apriori_test(_state_prior(tested[2], tested[3]), np.asarray(tested[0], float),
                               np.asarray(tested[1], float))
    source = problem.apriori_source or None
    if test is not None and test["conflict"] and source == "stated":
        made = dm.declined("the filter's stated prior (the initial state's a-priori at the output epoch)", test)
        hx, hp = hold(x, p, prior_x, prior_p)
        return Outcome(hx, hp, made.as_dict(), test)
    if not allow_keep:
        return Outcome(x, p, None, test)
    at_output = replace(problem, epoch=np.datetime64(out_epoch, "ns"), frame=None)
    made = od_decision.by_prediction(at_output, x, p, priors, horizon_days, source)
    if made is None:
        return Outcome(x, p, None, test)
    if made.keeps_prior:
        hx, hp = hold(x, p, prior_x, prior_p)
        return Outcome(hx, hp, made.as_dict(), test)
    return Outcome(x, p, made.as_dict(), test)


def add_reasons(q: qm.Quality, outcome: Outcome, source: Optional[str]) -> None:
    """The decision in the verdict, with estimate's codes: ``declined`` (suspect), ``kept`` (ok),
    ``replaced`` (ok); a conflict with a default (not stated) prior: ``apriori_conflict`` (suspect,
    the filter's solution stands)."""
    d, test = outcome.decision, outcome.test
    if d is not None and d["action"] == "declined":
        q.add("declined", "suspect", d["reason"], value=test["statistic"], limit=test["limit"])
        return
    if test is not None and test["conflict"]:
        q.add("apriori_conflict", "suspect",
              f"the data contradict the state a-priori ({test['test']} chi2 {test['statistic']:.4g} over "
              f"{test['dof']}, limit {test['limit']:.3g}); it has no stated accuracy ({source or 'none'}), so the "
              "filter's solution stands (the filter does not adapt an a-priori)",
              value=test["statistic"], limit=test["limit"])
    if d is None:
        return
    if d["action"] == "kept":
        q.add("kept", "ok", f"the initial state is kept: {d['reason']}", value=d.get("probability_better"),
              limit=dm.REPLACE_PROBABILITY)
    else:
        q.add("replaced", "ok", d["reason"], value=d.get("probability_better"), limit=dm.REPLACE_PROBABILITY)
