"""Gross errors inside one pass (docs/refine.md, "Steps inside a pass"): a level shift of the
transmitter's frequency (an oscillator step) and a jump of the time tags, found by the score-test
step scan estimate uses (:func:`~trackproc.methods.quality.step_scan`) on the refinement's whitened
residuals (:func:`scan_steps`); a frequency step is then modelled (a
:class:`~trackproc.models.modifiers.DopplerStep` from the detected sample on), a time-tag jump or a
step the model does not remove declines the pass (:func:`declined_step`).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from trackproc.isotime import iso_utc
from trackproc.methods import quality as qm
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.models import modifiers as md
from trackproc.pipeline.od import UNITS
from trackproc.pipeline.refine.problem import Refinement

#: Fewest kept samples of a pass the scan looks at (estimate's per-pass minimum).
MIN_SAMPLES = 20
#: A step needs at least this share of the pass's samples on each side: fewer at one end are a
#: handful of edge samples (the first seconds of lock, low-elevation multipath), which the editing
#: handles, and which the orbit's own curvature and the drift mimic at the ends.
MIN_SIDE_FRACTION = 0.1


def _white(ref: Refinement, keep: np.ndarray, sigma_scale: float):
    """``v -> L⁻¹ v`` on the kept samples (``v`` full length, (N,) or (N, m)): the pass's noise
    model when it is correlated (as :func:`~trackproc.pipeline.refine.gates.stale_improvement`),
    the samples' sigmas otherwise, times ``1/sigma_scale``."""
    if ref.correlated():
        whiten = ref.noise.whitener(keep)
        return lambda v: whiten(v) / sigma_scale
    s = np.asarray(ref.problem.meas.sigma, float)[keep] * sigma_scale

    def white(v):
        v = np.asarray(v, float)[keep]
        return v / (s[:, None] if v.ndim == 2 else s)

    return white


def scan_steps(ref: Refinement, sol, kkt=None, sigma_scale: float = 1.0) -> Optional[dict]:
    """The step scans of a pointwise solution: a frequency level shift (the Doppler offset's
    partials from sample s on) and a time-tag jump (the modelled observable's rate ``ḣ`` from s
    on: samples tagged ``δ`` late from s on read ``h(t − δ) ≈ h − ḣ δ``), both on the residuals
    whitened by the pass's noise model, with the refinement's covariance (the a-priori included):
    what the orbit, the offset and the drift absorb is not counted. The family-wise limit is the
    χ²(1) point at 0.001 / (all candidate positions of both scans) (Bonferroni, as estimate's).
    Returns None (integral cost, too few samples) or the stronger signature's ``{"kind"
    ("frequency" or "time"), "significant", "statistic", "limit", "candidates", "time_utc", "t_s"
    (from the solution epoch), "seconds_into_pass", "size" (the one-step size: Hz, or the kind's
    unit without an offset; s for a time-tag jump), "unit"}`` with each signature's own under
    ``"frequency"`` and ``"time"``."""
    if ref.options.cost != "pointwise":
        return None
    keep = ~np.asarray(sol.edited, bool)
    if keep.sum() < MIN_SAMPLES:
        return None
    meas = ref.problem.meas
    npb = ref.n_problem
    white = _white(ref, keep, sigma_scale)
    # the model's own Jacobian (a GLS solution's holds its whitened rows times the sigmas)
    jac = np.asarray(ref.pointwise_model(sol.values)[1], float)[:, :npb]
    y = np.asarray(meas.observed, float)
    computed = np.asarray(sol.computed, float)
    jw = white(jac)
    z = white(y - computed)
    cov = np.asarray(ref.covariance(sol, kkt), float)[:npb, :npb]
    if not (np.isfinite(jw).all() and np.isfinite(z).all() and np.isfinite(cov).all()):
        return None
    idx = np.flatnonzero(keep)
    t = np.asarray(meas.t_s, float)[idx]
    rows = np.argsort(t, kind="stable")                   # positions among the kept samples, in time order
    offset = ref.modifier_drivers(md.DopplerOffset)
    coef_f = jac[idx, ref.problem.names.index(offset[0].name)] if offset else np.ones(idx.size)
    rate = np.zeros(idx.size)
    tt = t[rows]
    if np.ptp(tt) > 0:
        rate[rows] = np.gradient(computed[idx][rows], tt) if np.all(np.diff(tt) > 0) else 0.0
    coef_t = -rate                                       # d h(t − δ)/dδ at δ = 0

    def whiten_block(e_block):
        full = np.zeros((keep.size, e_block.shape[1]))
        full[idx[rows]] = e_block
        return white(full)[rows]

    scans = {}
    for name, coef in (("frequency", coef_f), ("time", coef_t)):
        if not np.any(coef):
            continue
        margin = max(3, int(np.ceil(MIN_SIDE_FRACTION * rows.size)))
        if ref.correlated():
            r = qm.step_scan(jw, z, cov, rows, coef[rows], margin=margin, whiten=whiten_block)
        else:
            r = qm.step_scan(jw, z, cov, rows, coef[rows] / (np.asarray(meas.sigma, float)[idx][rows] * sigma_scale),
                             margin=margin)
        if r["candidates"]:
            scans[name] = r
    if not scans:
        return None
    total = sum(r["candidates"] for r in scans.values())
    limit = qm.chi2_limit(1, 1.0 - (1.0 - qm.GATE_PROBABILITY) / total)
    units = {"time": "s", "frequency": "Hz" if offset and ref.kind == "doppler" else UNITS[ref.kind]}
    each = {}
    for k, v in scans.items():
        t_s = float(tt[v["index"]])
        each[k] = {"kind": k, "significant": bool(v["statistic"] > limit), "statistic": v["statistic"],
                   "limit": limit, "candidates": total, "t_s": t_s,
                   "time_utc": iso_utc(ref.problem.epoch + np.timedelta64(int(round(t_s * 1e9)), "ns")),
                   "seconds_into_pass": float(t_s - tt[0]), "size": v["estimate"], "unit": units[k]}
    kind = max(each, key=lambda k: each[k]["statistic"])
    return dict(each[kind], **{k: dict(v) for k, v in each.items()})


def as_kind(scan: dict, kind: str) -> Optional[dict]:
    """The scan of one signature (``frequency`` or ``time``) of :func:`scan_steps` (None: not scanned)."""
    return dict(scan[kind]) if kind in scan else None


def step_modifier(ref: Refinement, scan: dict) -> md.DopplerStep:
    """The :class:`~trackproc.models.modifiers.DopplerStep` of the pass from the detected sample on."""
    return md.DopplerStep(ref.pass_id, scan["t_s"])


def shifted(modifiers, seconds: float) -> tuple:
    """``modifiers`` for a solution epoch ``seconds`` later (a step's epoch is relative to it)."""
    out = []
    for m in modifiers:
        if isinstance(m, md.DopplerStep):
            m = md.DopplerStep(m.key, m.driver.epoch_s - seconds)
        out.append(m)
    return tuple(out)


def describe(scan: dict) -> str:
    """The shift in words: what, when (UTC) and how big."""
    if scan["kind"] == "time":
        what = f"a jump of the time tags by {scan['size']:+.3g} s"
    else:
        what = f"a frequency level shift of {scan['size']:+.4g} {scan['unit']}"
    return (f"{what} at {scan['time_utc']} ({scan['seconds_into_pass']:.0f} s into the pass; chi2 "
            f"{scan['statistic']:.4g} over 1, limit {scan['limit']:.3g}: 99.9 % for the worst of "
            f"{scan['candidates']} positions)")


def declined_step(ref: Refinement, scan: dict, modelled: Optional[dict] = None) -> dict:
    """The refusal record of a pass declined for a step it cannot model (code ``step``): the
    stale state kept with its own a-priori covariance, as for a stated a-priori the pass
    contradicts (:func:`~trackproc.methods.estimation.decision.declined`)."""
    if modelled is not None:
        why = (f"after modelling {describe(modelled)} the residuals still show {describe(scan)}: a step model "
               "does not explain the pass (a time-tag jump, a second signal)")
    elif scan["kind"] == "time":
        why = (f"the residuals show {describe(scan)}: one side of the pass is tagged wrongly and the pass "
               "cannot tell which")
    else:
        why = f"the residuals show {describe(scan)}, which the refinement cannot model"
    decision = dm.Decision("declined", f"declined: {why}; the stale state is kept with its own covariance",
                           source=ref.apriori_source or None,
                           test={"test": "step scan", "statistic": scan["statistic"], "dof": 1,
                                 "limit": scan["limit"], "conflict": True})
    return {"code": "step", "state_covariance": pr.state_prior_covariance(ref.priors), "reason": decision.reason,
            "decision": decision.as_dict(), "step": scan}


def add_step_reason(q, step: Optional[dict]) -> None:
    """Reason ``step`` of the verdict: none found (ok), a frequency step modelled (ok, with the
    fitted size), or a step that declined the pass (suspect)."""
    if not step:
        return
    scan = step.get("scan")
    if step.get("action") == "modelled":
        m = step["modelled"]
        fitted = step.get("fitted")
        q.add("step", "ok",
              f"{describe(m)} modelled from there on ({step['parameter']}"
              + (f" = {fitted[0]:+.4g} +- {fitted[1]:.2g} {m['unit']}" if fitted else "") + ")"
              + (f"; no further step (worst chi2 {scan['statistic']:.3g}, limit {scan['limit']:.3g})"
                 if scan else ""), value=m["statistic"], limit=m["limit"])
    elif step.get("action") == "declined":
        q.add("step", "suspect", f"{describe(scan)}: the pass is declined", value=scan["statistic"],
              limit=scan["limit"])
    elif scan is not None and scan["significant"]:
        q.add("step", "suspect", f"{describe(scan)} that the orbit, offset and drift do not absorb: an oscillator "
              "step, a bias or time-tag jump", value=scan["statistic"], limit=scan["limit"])
    elif scan is not None:
        q.add("step", "ok", f"no level shift or time-tag jump inside the pass (worst: {scan['kind']}, chi2 "
              f"{scan['statistic']:.3g} over 1, limit {scan['limit']:.3g})", value=scan["statistic"],
              limit=scan["limit"])


def refined_step(ref: Refinement, sol, cov) -> Optional[tuple]:
    """The fitted step (value, sigma) when the problem models one."""
    drivers = ref.modifier_drivers(md.DopplerStep)
    if not drivers:
        return None
    i = list(ref.names).index(drivers[0].name)
    return float(sol.values[i]), float(np.sqrt(max(cov[i, i], 0.0)))


__all__ = ["scan_steps", "step_modifier", "shifted", "declined_step", "add_step_reason", "refined_step"]
