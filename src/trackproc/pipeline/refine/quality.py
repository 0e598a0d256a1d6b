"""The quality verdict of a refinement (:func:`refine_quality`): the checks of docs/refine.md,
"Quality", as a :class:`~trackproc.methods.quality.Quality`.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods import quality as qm
from trackproc.methods.estimation import decision as dm
from trackproc.pipeline.refine.gates import refinement_apriori_test
from trackproc.pipeline.refine.options import CIRCULAR_TEST_P, LOW_PASS_DEG, TRAVERSE_TOLERANCE_S
from trackproc.pipeline.refine.problem import Refinement
from trackproc.pipeline.refine.steps import add_step_reason
from trackproc.pipeline.timing import add_timing_reason


def default_apriori(ref: Refinement) -> bool:
    """The state's a-priori is the default one (a stale state without covariance), not stated."""
    return ref.apriori_source == "default"


def add_decision(q, refusal: dict | None, decision: dict | None) -> None:
    """What became of the stale state (methods/estimation/decision.py): ``declined`` (the pass
    contradicts a stated a-priori: suspect), ``kept`` (the refined state would not predict better:
    ok, the stale state is the answer), ``replaced`` (ok), or ``refused`` (suspect: the pass's own
    noise model is in doubt, or it cannot carry a looser default a-priori)."""
    if refusal is not None and refusal.get("code") == "step":
        q.add("declined", "suspect", refusal["reason"], value=refusal["step"]["statistic"],
              limit=refusal["step"]["limit"])
    elif refusal is not None and refusal.get("code") == "second_signal":
        t = (decision or {}).get("apriori_test", {})
        q.add("declined", "suspect", refusal["reason"], value=t.get("statistic"), limit=t.get("limit"))
    elif refusal is not None and refusal.get("code") == "declined":
        q.add("declined", "suspect", refusal["reason"], value=(decision or {}).get("apriori_test", {}).get("statistic"),
              limit=(decision or {}).get("apriori_test", {}).get("limit"))
    elif refusal is not None and refusal.get("code") == "kept":
        q.add("kept", "ok", f"the stale state is kept: {refusal['reason']}",
              value=(decision or {}).get("probability_better"), limit=dm.REPLACE_PROBABILITY)
    elif refusal is not None:
        q.add("refused", "suspect", f"the stale state is kept: {refusal['reason']}", value=refusal.get("code"))
    elif decision is not None:
        q.add("replaced", "ok", decision["reason"], value=decision.get("probability_better"),
              limit=dm.REPLACE_PROBABILITY)


def refine_quality(ref: Refinement, sol, *, sigma_scale=1.0, adaptation=None, improvement=None, refusal=None,
                   t_model=None, max_el=None, consistency=None, timing=None, decision=None, step=None):
    """The :class:`~trackproc.methods.quality.Quality` of a refinement: a-priori conflict (and
    its adaptation), variance factor of the nominal sigmas, residual whiteness, traverse-epoch
    mismatch, low pass, circular-constraint conflict, edited samples, refusal, and the along-track
    move from a stale TLE against its accuracy (:func:`~trackproc.pipeline.timing.tle_timing`)."""
    q = qm.Quality()
    opt = ref.options
    add_decision(q, refusal, decision)
    add_step_reason(q, step)
    # a-priori conflict
    if adaptation is not None:
        a = adaptation
        t = a.get("test") or {"test": "a-priori share of chi2", "statistic": a["chi2_before"], "dof": a["rows"],
                              "limit": a["limit"]}
        said = f"{t['test']} chi2 {t['statistic']:.4g} over {t['dof']}, limit {t['limit']:.3g}"
        if a.get("resolved", True):
            # the default a-priori is this tool's guess for a state without covariance: adapting it is
            # routine. A stated covariance (the stale file's, --apriori-sigma) contradicted at 99.9 %
            # means that either it or the pass is wrong, and one pass cannot tell which: a time-tag
            # offset, a station error or the ionosphere move the orbit without leaving a trace in the
            # residuals (docs/refine.md, "Mis-modelled passes")
            stated = not default_apriori(ref)
            q.add("apriori_conflict", "suspect" if stated else "ok",
                  f"the pass contradicted the a-priori ({said}); its covariance was scaled by {a['factor']:.3g} "
                  f"(sigmas x{a['sigma_factor']:.3g}, maximum-likelihood variance component)"
                  + ("; the stated covariance or the pass is wrong (a systematic error an orbit absorbs: time "
                     "tags, station coordinates, ionosphere), one pass cannot tell which" if stated else ""),
                  value=t["statistic"], limit=t["limit"])
        else:
            q.add("apriori_conflict", "suspect" if refusal is not None else "rejected",
                  f"the pass contradicts the a-priori ({said}) and cannot carry a looser one "
                  f"({a.get('failure', 'the variance component did not settle')})",
                  value=t["statistic"], limit=t["limit"])
    elif sol.n_prior:
        t = refinement_apriori_test(ref, sol)
        if t is not None:
            # a refused refinement writes the stale state: the conflict is the rejected solution's
            q.add("apriori_conflict", "ok" if not t["conflict"] else "suspect" if refusal is not None else "rejected",
                  f"{t['test']} chi2 {t['statistic']:.4g} over {t['dof']} (limit {t['limit']:.3g}; the a-priori's "
                  f"share of chi2 {t['chi2']:.4g} over {t['rows']})"
                  + (" of the refused solution" if refusal is not None else ""), value=t["statistic"],
                  limit=t["limit"])
    # the variance factor of the nominal sigmas (reweighting hides it in the solution's own)
    if sol.dof > 0 and math.isfinite(sol.variance_factor):
        vf = float(sol.variance_factor) * sigma_scale ** 2
        limit = qm.variance_factor_limit(sol.dof)
        if opt.cost == "integral":
            q.add("variance_factor", "ok", f"variance factor {vf:.3g} of the curve (the integral cost's pseudo-sigmas "
                  "are not a test of the data)", value=vf, limit=None)
        else:
            q.add("variance_factor", "ok" if vf <= limit else "suspect",
                  f"a-posteriori variance factor {vf:.3g} with the samples' own sigmas (99.9 % limit {limit:.3g})"
                  + (f"; sigmas scaled by {sigma_scale:.3g} to their actual scatter" if sigma_scale > 1 else ""),
                  value=vf, limit=limit)
    # whiteness of the residuals
    if improvement is not None and "whiteness" in improvement:
        w = improvement["whiteness"]
    else:
        keep = ~np.asarray(sol.edited, bool)
        w = qm.whiteness(np.asarray(sol.normalized, float)[keep]) if opt.cost == "pointwise" else None
    if w is not None:
        qm.add_whiteness(q, w)
    if improvement is not None and refusal is None and "significant" in improvement:
        q.add("improvement", "ok",
              f"the pass {'tells' if improvement['significant'] else 'does not significantly tell'} the refined "
              f"state from the stale one (delta chi2 {improvement['delta_chi2']:.4g}, "
              f"{improvement['delta_chi2_effective']:.3g} after the residuals' correlation; 99.9 % point "
              f"{improvement['limit']:.3g})" + ("" if improvement["significant"] else
                                                 ": the a-priori carries most of the refined state"),
              value=improvement["delta_chi2_effective"], limit=improvement["limit"])
    # the epoch: the refined orbit's own traverse point
    if ref.curve.tca is not None or opt.traverse_epoch is not None:
        if t_model is None:
            q.add("traverse_mismatch", "suspect", "the refined orbit's range-rate does not vanish within 60 s of the "
                  "solution epoch", value=None, limit=TRAVERSE_TOLERANCE_S)
        else:
            q.add("traverse_mismatch", "ok" if abs(t_model) <= TRAVERSE_TOLERANCE_S else "suspect",
                  f"the refined orbit's own zero range-rate is {t_model:+.3g} s from the solution epoch",
                  value=abs(t_model), limit=TRAVERSE_TOLERANCE_S)
    if max_el is not None:
        q.add("low_pass", "ok" if max_el >= LOW_PASS_DEG else "suspect",
              f"highest elevation {max_el:.1f} deg" + (" (one low pass determines the orbit poorly)"
                                                       if max_el < LOW_PASS_DEG else ""),
              value=max_el, limit=LOW_PASS_DEG)
    if consistency is not None and "p_value" in consistency:
        bad = consistency["p_value"] < CIRCULAR_TEST_P
        q.add("circular_conflict", "suspect" if bad else "ok",
              f"circular-orbit constraints: delta chi2 {consistency['delta_chi2']:.4g} over 2, p = "
              f"{consistency['p_value']:.2g}", value=consistency["p_value"], limit=CIRCULAR_TEST_P)
    add_timing_reason(q, timing)
    if opt.cost == "pointwise" and sol.n_edited > 0.1 * sol.n_measurements:
        q.add("edited", "suspect", f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)",
              value=int(sol.n_edited), limit=0.1 * sol.n_measurements)
    return q
