"""The ``quality`` verdict of a batch solution (:func:`estimate_quality`) and its per-pass checks:
each pass's share of the misfit and the whiteness of its residuals (:func:`pass_residuals`), a
pass that pulls the solution its own way (:func:`pass_consistency`: a score test of the pass
having its own state and biases), a level shift inside a pass (:func:`add_step`) and a pass
mostly edited away (:func:`add_edited_pass`). The a-priori gate that precedes them is in
:mod:`trackproc.pipeline.estimate.gates`."""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods import quality as qm
from trackproc.methods.estimation import decision as dm
from trackproc.pipeline.od.problem import Problem
from trackproc.pipeline.od.samples import groups
from trackproc.pipeline.timing import add_timing_reason


def pass_residuals(problem: Problem, sol) -> list:
    """Per pass and kind (station/pass kind), the kept normalised residuals in time order:
    ``{"pass", "n", "chi2", "whiteness"}`` (:func:`~trackproc.methods.quality.whiteness`)."""
    meas = problem.meas
    kept = ~np.asarray(sol.edited, bool)
    z = np.asarray(sol.normalized, float)
    passes = []
    for key, rows in groups(meas.station, meas.pass_id, meas.kind):
        idx = rows[kept[rows]]
        if not idx.size:
            continue
        idx = idx[np.argsort(problem.times[idx], kind="stable")]
        passes.append({"pass": f"{key[0]}/{key[1]} {key[2]}", "n": int(idx.size), "chi2": float(z[idx] @ z[idx]),
                       "whiteness": qm.whiteness(z[idx])})
    return passes


def _whitened(problem: Problem, sol):
    """The kept samples' indices, whitened Jacobian (``sol.jacobian / sigma``), whitened
    residuals (``sol.normalized``: a GLS solution's innovations) and the covariance; None when
    the solution carries no usable Jacobian."""
    kept = ~np.asarray(sol.edited, bool)
    sigma = np.asarray(problem.meas.sigma, float)
    jac = np.asarray(sol.jacobian, float)
    if jac.ndim != 2 or jac.shape[0] != kept.size:
        return None
    idx = np.flatnonzero(kept)
    jw = jac[idx] / sigma[idx, None]
    z = np.asarray(sol.normalized, float)[idx]
    if not (np.isfinite(jw).all() and np.isfinite(z).all()):
        return None
    return idx, jw, z, np.asarray(sol.covariance, float)


def add_step(q, problem: Problem, sol, noise_report: dict | None = None) -> None:
    """Reason ``step``: a level shift inside one pass and kind (a transmitter frequency step, a
    bias or time-tag jump) beyond what the orbit, the offsets and the drifts absorb:
    :func:`~trackproc.methods.quality.step_scan` on each white pass (a pass whose noise model has
    a random walk or AR(1) already allows for wander), ``suspect`` when the largest statistic is
    beyond the χ²(1) point at 0.001 / (all positions of all passes) (Bonferroni: at most 0.1 %
    false alarms, conservative since neighbouring positions are correlated). A step of 10 Hz in
    one of three 1.5 Hz VHF passes can move the state 5-6 sigma while the pass fits white and
    agrees with the others (its direction is its own)."""
    w = _whitened(problem, sol)
    if w is None:
        return
    idx, jw, z, cov = w
    meas = problem.meas
    station, pass_id, kind = meas.station[idx], meas.pass_id[idx], meas.kind[idx]
    times = np.asarray(meas.t_s, float)[idx]          # SI seconds from the solution epoch
    sigma = np.asarray(meas.sigma, float)[idx]
    correlated = {k for k, v in (noise_report or {}).items() if v.get("model", "white") != "white"}
    scans = []
    for key, rows in groups(station, pass_id, kind):
        if f"{key[0]}/{key[1]}" in correlated and key[2] in ("doppler", "range_rate"):
            continue
        if rows.size < 20:
            continue
        rows = rows[np.argsort(times[rows], kind="stable")]
        r = qm.step_scan(jw, z, cov, rows, 1.0 / sigma[rows])
        if r["candidates"]:
            scans.append((key, rows, r))
    total = sum(r["candidates"] for _, _, r in scans)
    if not scans:
        return
    alpha = (1.0 - qm.GATE_PROBABILITY) / total
    limit = qm.chi2_limit(1, 1.0 - alpha)
    key, rows, r = max(scans, key=lambda x: x[2]["statistic"])
    bad = r["statistic"] > limit
    at = float(times[rows[r["index"]]] - times[rows[0]])
    name = f"{key[0]}/{key[1]} {key[2]}"
    q.add("step", "suspect" if bad else "ok",
          (f"pass {name}: a level shift {at:.0f} s into the pass (chi2 {r['statistic']:.4g} over 1, limit {limit:.3g}: "
           f"99.9 % for the worst of {total} positions in {len(scans)} passes) that the orbit, offsets and drifts do "
           "not absorb: an oscillator step, a bias or time-tag jump; check it, or leave the pass out") if bad else
          (f"no level shift inside a pass (worst {name}: chi2 {r['statistic']:.3g} over 1, limit {limit:.3g})"),
          value=r["statistic"], limit=limit)


def pass_consistency(problem: Problem, sol, scale: float = 1.0) -> list:
    """Per pass (station/pass id, all its kinds, kept samples) and per station with more than
    one pass (all its passes), the score test of "this block has its own state and biases"
    (:func:`~trackproc.methods.quality.block_consistency`) on the whitened problem at ``sol``:
    ``{"block", "n", "statistic", "dof", "p"}``. A station's block finds what all its passes
    share (its coordinates, its clock), a pass's what only that pass has. The whitened rows are
    ``sol.jacobian / sigma`` and ``sol.normalized`` (a GLS solution's innovations: its
    correlated blocks are per pass, so a pass's whitened rows stay its own). The statistics are
    divided by ``scale`` (the caller's variance factor when above 1: the samples' sigmas scaled
    by the a-posteriori variance factor, as an F test)."""
    meas = problem.meas
    w = _whitened(problem, sol)
    if w is None:
        return []
    idx, jw, z, cov = w
    station, pass_id = meas.station[idx], meas.pass_id[idx]
    passes = groups(station, pass_id)
    keys = [key for key, _ in passes]
    blocks = [(f"{st}/{pid}", rows) for (st, pid), rows in passes]
    for (st,), rows in groups(station):
        count = sum(1 for k in keys if k[0] == st)
        if count > 1 and len(keys) > count:
            blocks.append((f"{st} (all {count} passes)", rows))
    out = []
    for name, rows in blocks:
        t = qm.block_consistency(jw, z, cov, rows)
        t["statistic"] /= scale
        if t["dof"] > 0:
            out.append({"block": name, "n": int(rows.size), **t, "p": qm.chi2_survival(t["statistic"], t["dof"])})
    return out


def add_pass_consistency(q, problem: Problem, sol) -> None:
    """Reason ``pass_consistency``: ``suspect`` when a pass (or a station's passes) disagrees
    with the others beyond the 99.9 % point for the worst of the m blocks tested (Bonferroni:
    p < 0.001/m, a false alarm on at most 0.1 % of consistent solutions); every such block is
    named, the least consistent first (when one station or pass is wrong, the solution it pulls
    can make others disagree too: the list says so). A pass that pulls the state its own way can
    fit white with a variance factor within its limit (the state absorbs it: a 20 Hz oscillator
    step in one of three VHF passes moved the state 10 sigma, verdict ok); the other passes then
    see that state as wrong, and this test compares the two."""
    tests = pass_consistency(problem, sol, scale=max(1.0, sol.variance_factor)
                             if math.isfinite(sol.variance_factor) else 1.0)
    if len(tests) < 2:
        return
    m = len(tests)
    alpha = (1.0 - qm.GATE_PROBABILITY) / m
    tests.sort(key=lambda t: t["p"])
    worst = tests[0]
    limit = qm.chi2_limit(worst["dof"], 1.0 - alpha)
    failing = [t for t in tests if t["p"] < alpha]
    if failing:
        listed = "; ".join(f"{t['block']} (chi2 {t['statistic']:.4g} over {t['dof']}, limit "
                           f"{qm.chi2_limit(t['dof'], 1.0 - alpha):.3g})" for t in failing[:4])
        more = f" and {len(failing) - 4} more" if len(failing) > 4 else ""
        message = (f"{len(failing)} of {m} passes/stations disagree with the rest, given their own state and biases "
                   f"they would fit better (99.9 % for the worst of {m}): {listed}{more}; "
                   + ("the first pulls the solution most: check it, or leave it out" if len(failing) == 1 else
                      "the first pulls the solution most, but with several a model error they share (forces, a "
                      "station's position or clock) is as likely as bad passes"))
    else:
        message = (f"every pass agrees with the others (worst {worst['block']}: chi2 {worst['statistic']:.3g} over "
                   f"{worst['dof']}, limit {limit:.3g})")
    q.add("pass_consistency", "suspect" if failing else "ok", message, value=worst["statistic"], limit=limit)


def add_edited_pass(q, problem: Problem, sol, clip: float | None) -> None:
    """Reason ``edited_pass``: a pass (station/pass id) that lost more than 10 % of its samples to
    the ``clip``-sigma editing, beyond chance: under the noise model a sample is edited with
    probability at most ``p0 = 2 Φ(-clip)``, and the pass's count is tested against Binomial(n, p0)
    at 0.001/m for the worst of m passes. A pass of another kind than its label (two-way Doppler
    read as one-way) is edited whole and the solution stays right, but silently without it."""
    if not clip:
        return
    meas = problem.meas
    edited = np.asarray(sol.edited, bool)
    if not edited.any():
        return
    passes = groups(meas.station, meas.pass_id)
    counts = [(st, pid, int(rows.size), int(edited[rows].sum())) for (st, pid), rows in passes]
    over = [c for c in counts if c[3] > 0.1 * c[2]]
    if not over:
        return
    # start-up: scipy.special (~30 ms of CPU) only for a pass more than 10 % edited
    from scipy.special import bdtrc, ndtr

    p0 = 2.0 * float(ndtr(-float(clip)))
    alpha = (1.0 - qm.GATE_PROBABILITY) / max(len(passes), 1)
    bad = []
    for st, pid, n, k in over:
        if float(bdtrc(k - 1, n, p0)) < alpha:     # P(K >= k)
            bad.append((k / n, f"{st}/{pid}", k, n))
    if bad:
        bad.sort(reverse=True)
        q.add("edited_pass", "suspect",
              "passes edited beyond chance (the solution goes without them): " +
              ", ".join(f"{name} {k} of {n} samples" for _, name, k, n in bad[:4]) +
              (f" and {len(bad) - 4} more" if len(bad) > 4 else "") +
              f" (> 10 % and beyond the 99.9 % point of Binomial(n, {p0:.2g}) for the worst of {len(passes)} passes): "
              "check their kind, mode, carrier or time tags", value=bad[0][0], limit=0.1)


def estimate_quality(problem: Problem, sol, adaptation: dict | None = None, clip: float | None = None,
                     noise_report: dict | None = None, timing: dict | None = None):
    """The :class:`~trackproc.methods.quality.Quality` of a batch solution: convergence, a-priori
    conflict (``rejected``: the covariance leans on an a-priori the data contradict), variance
    factor against its 99.9 % point, the pass that dominates the misfit (named), residual
    whiteness per pass (the worst named, Bonferroni over the passes), the passes that pull the
    solution their own way (:func:`pass_consistency`), a level shift inside a pass, passes and
    samples edited away, and the along-track move from an initial TLE against its accuracy
    (:func:`trackproc.pipeline.timing.tle_timing`)."""
    q = qm.Quality()
    if not sol.converged:
        q.add("not_converged", "rejected", f"the solver did not converge ({sol.message})")
    code = ((adaptation or {}).get("refused") or {}).get("code")
    if code == "kept":
        q.add("kept", "ok", f"the initial state is kept: {adaptation['refused']['reason']}",
              value=(adaptation.get("decision") or {}).get("probability_better"), limit=dm.REPLACE_PROBABILITY)
    elif code == "declined":
        a = adaptation
        q.add("declined", "suspect", a["refused"]["reason"], value=a["chi2_before"], limit=a["limit"])
    elif adaptation is not None and adaptation.get("refused"):
        a = adaptation
        q.add("refused", "suspect", f"the initial state is kept: {a['refused']['reason']}", value=a["refused"]["code"])
        q.add("apriori_conflict", "suspect", f"{a.get('test', 'a-priori')} chi2 {a['chi2_before']:.4g} over "
              f"{a['rows']} (limit {a['limit']:.3g}) of the refused solution", value=a["chi2_before"], limit=a["limit"])
    elif adaptation is not None:
        a = adaptation
        if a["resolved"]:
            q.add("apriori_conflict", "ok",
                  f"the data contradicted the state a-priori ({a.get('test', 'a-priori')} chi2 {a['chi2_before']:.4g} "
                  f"over {a['rows']}, limit {a['limit']:.3g}); its covariance was scaled by {a['factor']:.3g} "
                  f"(sigmas x{a['sigma_factor']:.3g}, maximum-likelihood variance component)"
                  + ("; the a-priori was stated, but the data determine the state without it and pass their own "
                     "tests: the stated accuracy was wrong" if a.get("stated") else ""),
                  value=a["chi2_before"], limit=a["limit"])
        else:           # (solve refuses such a solution: kept for a caller of adapt_apriori alone)
            q.add("apriori_conflict", "rejected",
                  f"the data contradict the state a-priori ({a.get('test', 'a-priori')} chi2 {a['chi2_before']:.4g} "
                  f"over {a['rows']}, limit {a['limit']:.3g}) and cannot carry a looser one", value=a["chi2_before"],
                  limit=a["limit"])
    elif sol.n_prior:
        qm.add_apriori_check(q, sol.chi2_prior, sol.n_prior, "constraints",
                             "the data and the a-priori disagree, the covariance that leans on the a-priori does not hold")
    if code is None and problem.decision is not None and problem.decision.get("action") == "replaced":
        q.add("replaced", "ok", problem.decision["reason"], value=problem.decision.get("probability_better"),
              limit=dm.REPLACE_PROBABILITY)
    vf_limit = qm.variance_factor_limit(sol.dof) if sol.dof > 0 else None
    if sol.dof > 0 and math.isfinite(sol.variance_factor):
        q.add("variance_factor", "ok" if sol.variance_factor <= vf_limit else "suspect",
              f"a-posteriori variance factor {sol.variance_factor:.4g} (99.9 % limit {vf_limit:.3g})",
              value=sol.variance_factor, limit=vf_limit)
    # per pass: its share of the misfit and the whiteness of its residuals (time order)
    passes = pass_residuals(problem, sol)
    total = sum(p["chi2"] for p in passes)
    if len(passes) > 1 and total > 0 and sol.dof > 0 and sol.variance_factor > vf_limit:
        worst = max(passes, key=lambda p: p["chi2"] / p["n"])
        share = worst["chi2"] / total
        if share > 0.5:
            q.add("dominant_pass", "suspect",
                  f"pass {worst['pass']} carries {100 * share:.0f} % of the misfit with {worst['n']} of "
                  f"{sum(p['n'] for p in passes)} samples (variance factor {worst['chi2'] / worst['n']:.3g}): "
                  "check it, or leave it out", value=share, limit=0.5)
    # the worst pass against the 99.9 % point for the worst of m (a fixed rho > 0.3 on the worst of
    # twelve short white passes made half of the consistent 3-station solutions suspect)
    qm.add_whiteness_family(q, passes)
    if not (adaptation is not None and adaptation.get("refused")):
        add_pass_consistency(q, problem, sol)     # (a refused solution's state is held, not fitted)
        add_step(q, problem, sol, noise_report)
    add_edited_pass(q, problem, sol, clip)
    add_timing_reason(q, timing, "the passes")
    if sol.n_edited > 0.1 * sol.n_measurements:
        q.add("edited", "suspect", f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)",
              value=int(sol.n_edited), limit=0.1 * sol.n_measurements)
    return q
