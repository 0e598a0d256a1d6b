"""A second signal inside one pass (docs/refine.md, "Steps inside a pass"): for part of a one-way
Doppler pass the receiver's tracker followed another emitter (another satellite, an interferer, a
harmonic), so a block of samples, or scattered samples, follow another curve. Found on the gated
solution's residuals against their robust scale (:func:`signal_runs`), named with their times
(:func:`find_second_signal`), edited out and the pass refined again with the same noise model
(:func:`refine_edited`); a pass that still shows one after that is declined (:func:`declined_signal`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Optional

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.isotime import iso_utc
from trackproc.methods.distributions import normal_quantile
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.models import modifiers as md
from trackproc.pipeline.od import UNITS
from trackproc.pipeline.refine.problem import Refinement

#: Probability that a clean pass has any sample flagged (the family-wise false-alarm rate; the
#: same 0.1 % as the refine gates). Bonferroni over the samples holds for correlated samples too
#: (a union bound on their Gaussian marginals); checked by Monte Carlo in
#: tests/pipeline/test_refine_second_signal.py.
FALSE_ALARM = 0.001
#: MAD -> sigma of a normal distribution (1 / Φ⁻¹(3/4)).
MAD_TO_SIGMA = 1.482602218505602
#: Flagged runs of the same sign this few samples apart are one run (a sample of the other signal
#: that noise pulls inside the limit does not split it) when the samples between are beyond
#: :data:`GAP_SIGMAS` on the same side.
MERGE_GAP = 2
GAP_SIGMAS = 2.0
#: At most this share of the pass can be another signal: beyond it, the robust scale and the
#: median belong to the other signal as much as to the satellite.
MAX_FRACTION = 0.4
#: Samples beyond this many robust sigmas are left out of the refit that finds the runs
#: (:func:`trimmed_residuals`; 0.006 % of a clean pass's samples).
FIT_SIGMAS = 4.0
#: Fewest samples left after editing (estimate's per-pass minimum).
MIN_LEFT = 20


def limit_sigmas(n: int, false_alarm: float = FALSE_ALARM) -> float:
    """``k`` such that any of ``n`` standard normal samples exceeds ``|k|`` with probability at most
    ``false_alarm`` (Bonferroni: each two-sided tail ``false_alarm / n``)."""
    return -normal_quantile(false_alarm / (2.0 * max(int(n), 1)))


def signal_runs(t, r, false_alarm: float = FALSE_ALARM) -> Optional[dict]:
    """Samples far from the rest: ``r`` (residuals over their sigmas, any order, times ``t``) centred
    on their median and scaled by their MAD (a robust sigma: up to half the samples may be another
    signal), flagged beyond :func:`limit_sigmas` of them, grouped into runs of consecutive samples in
    time (:data:`MERGE_GAP`). Returns None (no scale) or ``{"limit_sigmas", "false_alarm", "centre",
    "scale", "worst_sigmas", "flagged" (bool per sample, input order), "runs": [(first, last)
    positions in time order, ...], "order"}``."""
    r = np.asarray(r, float)
    t = np.asarray(t, float)
    ok = np.isfinite(r)
    if ok.sum() < MIN_LEFT:
        return None
    centre = float(np.median(r[ok]))
    scale = float(MAD_TO_SIGMA * np.median(np.abs(r[ok] - centre)))
    if not scale > 0:
        return None
    order = np.argsort(t, kind="stable")
    dev = np.where(ok, (r - centre) / scale, 0.0)[order]
    k = limit_sigmas(int(ok.sum()), false_alarm)
    hit = np.abs(dev) > k
    runs = []
    i = 0
    n = dev.size
    while i < n:
        if not hit[i]:
            i += 1
            continue
        j = i
        sign = np.sign(dev[i])
        while True:
            while j + 1 < n and hit[j + 1] and np.sign(dev[j + 1]) == sign:
                j += 1
            # the next flagged sample of the same sign, with only same-side samples between
            nxt = j + 1
            while nxt < n and nxt - j - 1 < MERGE_GAP and not hit[nxt] and sign * dev[nxt] > GAP_SIGMAS:
                nxt += 1
            if nxt < n and nxt > j + 1 and hit[nxt] and np.sign(dev[nxt]) == sign:
                j = nxt
                continue
            break
        runs.append((i, j))
        i = j + 1
    flagged_sorted = np.zeros(n, bool)
    for a, b in runs:
        flagged_sorted[a:b + 1] = True
    flagged = np.zeros(n, bool)
    flagged[order] = flagged_sorted
    return {"limit_sigmas": k, "false_alarm": false_alarm, "centre": centre, "scale": scale,
            "worst_sigmas": float(np.max(np.abs(dev))), "flagged": flagged, "runs": runs, "order": order}


def eligible(ref: Refinement) -> bool:
    """A one-way Doppler pass with a transmitter offset, pointwise cost, unconstrained: a receiver
    tracking a free-running transmitter is what locks onto another emitter."""
    opt = ref.options
    return (opt.cost == "pointwise" and not opt.circular and ref.kind == "doppler"
            and bool(ref.modifier_drivers(md.DopplerOffset)))


def find_second_signal(ref: Refinement, sol) -> Optional[dict]:
    """The runs of :func:`signal_runs` on a pointwise solution's residuals (every sample, the
    solver's edited ones included, over the samples' sigmas), named: ``{"found", "samples",
    "flagged", "limit_sigmas", "false_alarm", "scale" (the robust sigma, in the observable's unit),
    "worst_sigmas", "runs": [{"start_utc", "end_utc", "start_s", "end_s" (seconds into the pass),
    "samples", "median_offset" (from the pass's median residual), "unit"}], "times_ns" (the flagged
    samples' epochs, int ns, to edit them)}``; None when not applicable."""
    if not eligible(ref):
        return None
    meas = ref.problem.meas
    sigma = np.asarray(meas.sigma, float)
    t = np.asarray(meas.t_s, float)
    resid, found = white_residuals(ref, sol)
    if found is None:
        return None
    unit = UNITS[ref.kind] if ref.kind != "doppler" else "Hz"
    order = found["order"]
    ts, rs = t[order], resid[order]
    centre = float(np.nanmedian(resid))
    runs = []
    for a, b in found["runs"]:
        runs.append({"start_utc": iso_utc(ref.problem.epoch + np.timedelta64(int(round(ts[a] * 1e9)), "ns")),
                     "end_utc": iso_utc(ref.problem.epoch + np.timedelta64(int(round(ts[b] * 1e9)), "ns")),
                     "start_s": float(ts[a] - ts[0]), "end_s": float(ts[b] - ts[0]), "samples": int(b - a + 1),
                     "median_offset": float(np.median(rs[a:b + 1]) - centre), "unit": unit})
    flagged = found["flagged"]
    epoch_ns = ref.problem.epoch.astype("datetime64[ns]").astype(np.int64)
    return {"found": bool(runs), "samples": int(t.size), "flagged": int(flagged.sum()),
            "limit_sigmas": found["limit_sigmas"], "false_alarm": found["false_alarm"],
            "scale": float(found["scale"] * np.median(sigma)), "worst_sigmas": found["worst_sigmas"], "runs": runs,
            "times_ns": (epoch_ns + np.round(t[flagged] * 1e9).astype(np.int64)).tolist()}


def trimmed_residuals(a, b, rounds: int = 8) -> np.ndarray:
    """``b`` less its least-squares fit by the columns ``a``, the fit refitted without the samples
    beyond :data:`FIT_SIGMAS` robust sigmas (median, MAD) of the last residuals until that set
    settles (a trimmed least squares: a block of another signal on up to :data:`MAX_FRACTION` of the
    samples pulls a plain fit into residuals of tens of sigmas over the clean samples, which hide
    it). NaN where ``a`` or ``b`` is not finite."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    norm = np.linalg.norm(np.where(np.isfinite(a), a, 0.0), axis=0)
    a = a / np.where(norm > 0, norm, 1.0)
    ok = np.isfinite(b) & np.isfinite(a).all(axis=1)
    use = ok.copy()
    white = np.full(b.size, np.nan)
    for _ in range(rounds):
        if use.sum() <= a.shape[1] + MIN_LEFT:
            break
        step = np.linalg.lstsq(a[use], b[use], rcond=1e-10)[0]
        white[ok] = b[ok] - a[ok] @ step
        centre = np.median(white[ok])
        scale = MAD_TO_SIGMA * np.median(np.abs(white[ok] - centre))
        new = ok & (np.abs(white - centre) <= FIT_SIGMAS * scale)
        if np.array_equal(new, use):
            break
        use = new
    return white


def white_residuals(ref: Refinement, sol):
    """The residuals of the pass refitted with white noise from ``sol`` (one linear step on the
    model's columns — state, offset, drift — in the metric of the samples' sigmas, trimmed:
    :func:`trimmed_residuals`) and their :func:`signal_runs`. Why not the GLS residuals: under a
    random-walk noise model (which REML picks for a pass with a block in it) the GLS fit leaves
    residuals that wander by the block's size, and their whitened form shows a block only at its
    two edges. Returns ``(residuals in the observable's unit, runs)``."""
    meas = ref.problem.meas
    sigma = np.asarray(meas.sigma, float)
    r0 = np.asarray(meas.observed, float) - np.asarray(sol.computed, float)
    jac = np.asarray(ref.pointwise_model(sol.values)[1], float)[:, :ref.n_problem]
    white = trimmed_residuals(jac / sigma[:, None], r0 / sigma)
    return white * sigma, signal_runs(np.asarray(meas.t_s, float), white)


def describe(found: dict, most: int = 3) -> str:
    """The runs in words: how many samples, when (UTC, seconds into the pass), how far off."""
    runs = found["runs"]
    parts = [f"{r['start_utc']}..{r['end_utc']} ({r['start_s']:.0f}-{r['end_s']:.0f} s into the pass, "
             f"{r['samples']} samples, median {r['median_offset']:+.4g} {r['unit']})" for r in runs[:most]]
    more = f" and {len(runs) - most} more run(s)" if len(runs) > most else ""
    return (f"{found['flagged']} of {found['samples']} samples beyond {found['limit_sigmas']:.2f} robust sigmas "
            f"({found['scale']:.3g} Hz; {100 * found['false_alarm']:g} % false alarms on a clean pass) in "
            f"{len(runs)} run(s): " + "; ".join(parts) + more)


def without_samples(table, times_ns) -> object:
    """``table`` without the rows tagged at ``times_ns`` (int ns; matched within 1 ms)."""
    frame = table.frame
    tt = frame["time"]
    if getattr(tt.dt, "tz", None) is not None:
        tt = tt.dt.tz_convert("UTC").dt.tz_localize(None)
    rows = tt.to_numpy().astype("datetime64[ns]").astype(np.int64)
    cut = np.sort(np.asarray(times_ns, np.int64))
    pos = np.clip(np.searchsorted(cut, rows), 1, max(cut.size - 1, 1))
    near = np.minimum(np.abs(rows - cut[pos - 1]), np.abs(rows - cut[np.minimum(pos, cut.size - 1)]))
    drop = near <= 1_000_000
    return type(table)(frame.loc[~drop].reset_index(drop=True), table.meta)


def refine_edited(refine: Callable, table, initial, stations, opt, eop, source, ref: Refinement, found: dict):
    """The pass refined again without the samples of ``found`` (``refine`` with ``ref``'s noise model
    and transmitter model), annotated (:func:`annotate`); None when too few samples would be left or
    too many are flagged (the pass is then declined) or the refinement fails."""
    if found["flagged"] > MAX_FRACTION * found["samples"] or found["samples"] - found["flagged"] < MIN_LEFT:
        return None
    bias = "offset+drift" if ref.modifier_drivers(md.DopplerDrift) else opt.doppler_bias
    try:
        res = refine(without_samples(table, found["times_ns"]), initial, stations, replace(opt, doppler_bias=bias),
                     eop, source, _second_signal=found, _noise_of=ref)
    except ProcessingError:
        return None
    refused = res.state.diagnostics.get("refused") or {}
    again = res.state.diagnostics.get("second_signal")
    record = {"action": "declined" if refused.get("code") == "second_signal" else "edited",
              "edited": public(found), "after": (again or {}).get("check")}
    return annotate(res, record)


def public(found: Optional[dict]) -> Optional[dict]:
    return None if found is None else {k: v for k, v in found.items() if k != "times_ns"}


def declined_signal(ref: Refinement, found: dict, edited: Optional[dict] = None) -> dict:
    """The refusal record of a pass declined for a second signal it cannot be freed of (code
    ``second_signal``): the stale state kept with its own a-priori covariance, as other declines."""
    if edited is not None:
        why = (f"after editing {edited['flagged']} samples of a second signal the residuals still show "
               f"{describe(found)}")
    else:
        why = f"the residuals show {describe(found)}, too many to edit out"
    decision = dm.Decision("declined", f"declined: {why}; the stale state is kept with its own covariance",
                           source=ref.apriori_source or None,
                           test={"test": "second signal (robust residual scale)", "statistic": found["worst_sigmas"],
                                 "limit": found["limit_sigmas"], "conflict": True})
    return {"code": "second_signal", "state_covariance": pr.state_prior_covariance(ref.priors),
            "reason": decision.reason, "decision": decision.as_dict()}


def annotate(res, record: Optional[dict]):
    """``res`` with ``diagnostics.second_signal`` and the quality reason ``second_signal``: none found
    (ok), samples edited out and the re-solved pass clean (ok), or a second signal said or declined
    (suspect)."""
    if record is None:
        return res
    q = res.quality
    q.reasons[:] = [r for r in q.reasons if r["code"] != "second_signal"]
    action = record["action"]
    if action == "none":
        c = record["check"]
        q.add("second_signal", "ok", f"no sample beyond {c['limit_sigmas']:.2f} robust sigmas of the pass's "
              f"residuals (worst {c['worst_sigmas']:.2f}): no second signal", value=c["worst_sigmas"],
              limit=c["limit_sigmas"])
    elif action == "edited":
        e = record["edited"]
        q.add("second_signal", "ok", f"a second signal edited out, the rest of the pass refined again: {describe(e)}",
              value=e["worst_sigmas"], limit=e["limit_sigmas"])
        res.warnings.append(f"a second signal edited out: {describe(e)}")
    else:
        e = record.get("edited") or record.get("check")
        q.add("second_signal", "suspect", f"a second signal inside the pass: {describe(e)}"
              + (": the pass is declined" if action == "declined" else ""),
              value=e["worst_sigmas"], limit=e["limit_sigmas"])
    quality = q.as_dict()
    for state in (res.state, res.stale_epoch_state):
        state.diagnostics["second_signal"] = record
        state.extra["quality"] = quality
    return res


__all__ = ["signal_runs", "limit_sigmas", "find_second_signal", "refine_edited", "declined_signal", "annotate",
           "eligible"]
