"""Noise model and consistency gates of an estimate: :func:`pass_noise` (per-pass REML, then
GLS), :func:`solve` (the weighted fit, then the correlated one), :func:`estimate_quality` (the
``quality`` verdict) and :func:`warnings_of` (the summary's warnings)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.methods import noise as nz
from trackproc.methods.least_squares import Prior
from trackproc.methods import quality as qm
from trackproc.models import modifiers as md
from trackproc.pipeline.estimate.options import EstimateOptions
from trackproc.pipeline.estimate.problem import Problem


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
    chi2, rows = state_prior_chi2(problem.priors, sol.values)
    if not rows or chi2 <= qm.chi2_limit(rows) or state_prior_covariance(problem.priors) is None:
        return sol, None, noise_report
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
        return refuse(problem, opt, sol, used, chi2, rows, doubt, adaptation) + (noise_report,)
    return sol_a, adaptation, noise_report


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
    from scipy.linalg import eigh

    p = state_prior_covariance(priors)
    if p is None:
        return None
    lam = eigh(np.asarray(sol.covariance, float)[:6, :6], p, eigvals_only=True)
    worst = float(lam.max())
    if not worst > 0.5:
        return None
    return (f"with the a-priori loosened, the data weigh less than it in some direction of the state "
            f"(posterior/a-priori variance {worst:.2f} > 0.5): the solution there is the loosened a-priori's")


def _state_rows(p) -> np.ndarray:
    return np.flatnonzero(np.asarray(p.index, int) < 6)


def state_prior_chi2(priors, x) -> tuple[float, int]:
    """The state a-priori's share of χ² at ``x`` and its number of rows (x..vz rows of every prior)."""
    chi2, rows = 0.0, 0
    for p in priors:
        sel = _state_rows(p)
        if sel.size:
            r = np.asarray(x, float)[np.asarray(p.index, int)[sel]] - np.asarray(p.centre, float)[sel]
            chi2 += float(r @ np.linalg.solve(np.asarray(p.covariance, float)[np.ix_(sel, sel)], r))
            rows += sel.size
    return chi2, rows


def state_prior_covariance(priors):
    """The 6 × 6 a-priori covariance of x..vz (None unless all six have one)."""
    cov = np.full((6, 6), np.nan)
    for p in priors:
        sel = _state_rows(p)
        idx = np.asarray(p.index, int)[sel]
        cov[np.ix_(idx, idx)] = np.asarray(p.covariance, float)[np.ix_(sel, sel)]
    return None if np.isnan(np.diag(cov)).any() else np.nan_to_num(cov, nan=0.0)


def scaled_priors(priors, factor: float) -> list:
    """``priors`` with the state rows' covariance times ``factor`` (a prior on state and biases,
    always diagonal here, is split in two)."""
    out = []
    for p in priors:
        idx, cov = np.asarray(p.index, int), np.asarray(p.covariance, float)
        sel = _state_rows(p)
        rest = np.setdiff1d(np.arange(idx.size), sel)
        if sel.size:
            out.append(Prior(idx[sel], np.asarray(p.centre, float)[sel], cov[np.ix_(sel, sel)] * factor))
        if rest.size:
            out.append(Prior(idx[rest], np.asarray(p.centre, float)[rest], cov[np.ix_(rest, rest)]))
    return out


def refuse(problem: Problem, opt: EstimateOptions, sol, noise, chi2: float, rows: int, doubt: list,
           adaptation: dict | None = None):
    """Keep the initial state: the state at the a-priori centre with the a-priori covariance
    scaled by its variance component (the larger of the adapted one and one step on ``sol``,
    never below 1, so that it covers the conflict),
    the other parameters (biases) fitted with the state held there (their covariance is
    conditional on it: no cross-covariance with the state is written). Returns ``(solution,
    adaptation)`` with ``adaptation["refused"]`` saying why."""
    pcov = state_prior_covariance(problem.priors)
    red = qm.prior_redundancy(np.asarray(sol.covariance, float)[:6, :6], pcov)
    factor = max(1.0, (adaptation or {}).get("factor", 1.0), qm.prior_variance_component(chi2, red) or 1.0)
    centre = np.empty(6)
    for p in problem.priors:
        sel = _state_rows(p)
        centre[np.asarray(p.index, int)[sel]] = np.asarray(p.centre, float)[sel]
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
                              "chi2_before": chi2, "rows": rows, "limit": qm.chi2_limit(rows)})
    out.update({"factor": factor, "sigma_factor": math.sqrt(factor), "resolved": False,
                "refused": {"code": "apriori_conflict_doubtful_noise" if doubt else "apriori_conflict",
                            "covariance_factor": factor,
                            "reason": (f"the data contradict the initial state's a-priori (chi2 {chi2:.4g} over "
                                       f"{rows}, limit {qm.chi2_limit(rows):.3g}) but their noise model is in doubt: "
                                       f"{why}; "
                                       "neither the estimated state nor a loosened a-priori can be trusted"
                                       if doubt else
                                       f"the data contradict the initial state's a-priori (chi2 {chi2:.4g} over "
                                       f"{rows}) and {why}") + f"; the initial state is kept, its a-priori covariance "
                                                               f"scaled by {factor:.3g}"}})
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
    chi2, rows = state_prior_chi2(problem.priors, sol.values)
    if not rows or chi2 <= qm.chi2_limit(rows) or state_prior_covariance(problem.priors) is None:
        return sol, None
    limit = qm.chi2_limit(rows)
    start, factor, history, failure = chi2, 1.0, [], None
    priors = problem.priors
    for _ in range(MAX_APRIORI_ADAPT):
        red = qm.prior_redundancy(np.asarray(sol.covariance, float)[:6, :6], state_prior_covariance(priors))
        k_hat = qm.prior_variance_component(chi2, red)
        history.append({"factor": factor, "chi2": chi2, "redundancy": red, "component": k_hat})
        if k_hat is None or abs(k_hat - 1.0) < 0.1 or (k_hat < 1.0 and factor <= 1.0):
            break
        trial_factor = max(1.0, factor * k_hat)
        trial = scaled_priors(problem.priors, trial_factor)
        try:
            sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol,
                                priors=trial, noise=noise, edited=sol.edited, x0=sol.values)
        except ProcessingError as exc:
            failure = (f"with the a-priori scaled by {trial_factor:.3g} the estimation failed: "
                       f"{str(exc).split(' (')[0]}")
            break
        factor, priors = trial_factor, trial
        chi2, rows = state_prior_chi2(priors, sol.values)
    problem.priors = priors
    last = history[-1].get("component")
    resolved = failure is None and (chi2 <= limit or (last is not None and abs(last - 1.0) < 0.1))
    return sol, {"method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated",
                 "factor": factor, "sigma_factor": math.sqrt(factor), "chi2_before": start, "chi2_after": chi2,
                 "rows": rows, "limit": limit, "iterations": history, "resolved": bool(resolved),
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


def pass_residuals(problem: Problem, sol) -> list:
    """Per pass and kind (station/pass kind), the kept normalised residuals in time order:
    ``{"pass", "n", "chi2", "whiteness"}`` (:func:`~trackproc.methods.quality.whiteness`)."""
    meas = problem.meas
    kept = ~np.asarray(sol.edited, bool)
    z = np.asarray(sol.normalized, float)
    passes = []
    station, pass_id, kind = meas.station.astype(str), meas.pass_id.astype(str), meas.kind.astype(str)
    for key in sorted(set(zip(station, pass_id, kind))):
        rows = kept & (station == key[0]) & (pass_id == key[1]) & (kind == key[2])
        if not rows.any():
            continue
        idx = np.flatnonzero(rows)
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
    station, pass_id = meas.station.astype(str)[idx], meas.pass_id.astype(str)[idx]
    kind = meas.kind.astype(str)[idx]
    times = np.asarray(meas.t_s, float)[idx]          # SI seconds from the solution epoch
    sigma = np.asarray(meas.sigma, float)[idx]
    correlated = {k for k, v in (noise_report or {}).items() if v.get("model", "white") != "white"}
    scans = []
    for key in sorted(set(zip(station, pass_id, kind))):
        if f"{key[0]}/{key[1]}" in correlated and key[2] in ("doppler", "range_rate"):
            continue
        rows = np.flatnonzero((station == key[0]) & (pass_id == key[1]) & (kind == key[2]))
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
    station, pass_id = meas.station.astype(str)[idx], meas.pass_id.astype(str)[idx]
    keys = sorted(set(zip(station, pass_id)))
    blocks = [(f"{st}/{pid}", (station == st) & (pass_id == pid)) for st, pid in keys]
    for st in sorted(set(station)):
        count = sum(1 for k in keys if k[0] == st)
        if count > 1 and len(keys) > count:
            blocks.append((f"{st} (all {count} passes)", station == st))
    out = []
    for name, sel in blocks:
        rows = np.flatnonzero(sel)
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


def add_edited_pass(q, problem: Problem, sol, clip: float | None) -> None:
    """Reason ``edited_pass``: a pass (station/pass id) that lost more than 10 % of its samples to
    the ``clip``-sigma editing, beyond chance: under the noise model a sample is edited with
    probability at most ``p0 = 2 Φ(-clip)``, and the pass's count is tested against Binomial(n, p0)
    at 0.001/m for the worst of m passes. A pass of another kind than its label (two-way Doppler
    read as one-way) is edited whole and the solution stays right, but silently without it."""
    from scipy.special import bdtrc, ndtr

    if not clip:
        return
    meas = problem.meas
    edited = np.asarray(sol.edited, bool)
    station, pass_id = meas.station.astype(str), meas.pass_id.astype(str)
    keys = sorted(set(zip(station, pass_id)))
    p0 = 2.0 * float(ndtr(-float(clip)))
    alpha = (1.0 - qm.GATE_PROBABILITY) / max(len(keys), 1)
    bad = []
    for st, pid in keys:
        sel = (station == st) & (pass_id == pid)
        n, k = int(sel.sum()), int(edited[sel].sum())
        if k > 0.1 * n and float(bdtrc(k - 1, n, p0)) < alpha:     # P(K >= k)
            bad.append((k / n, f"{st}/{pid}", k, n))
    if bad:
        bad.sort(reverse=True)
        q.add("edited_pass", "suspect",
              "passes edited beyond chance (the solution goes without them): " +
              ", ".join(f"{name} {k} of {n} samples" for _, name, k, n in bad[:4]) +
              (f" and {len(bad) - 4} more" if len(bad) > 4 else "") +
              f" (> 10 % and beyond the 99.9 % point of Binomial(n, {p0:.2g}) for the worst of {len(keys)} passes): "
              "check their kind, mode, carrier or time tags", value=bad[0][0], limit=0.1)


def estimate_quality(problem: Problem, sol, adaptation: dict | None = None, clip: float | None = None,
                     noise_report: dict | None = None):
    """The :class:`~trackproc.methods.quality.Quality` of a batch solution: convergence, a-priori
    conflict (``rejected``: the covariance leans on an a-priori the data contradict), variance
    factor against its 99.9 % point, the pass that dominates the misfit (named), residual
    whiteness per pass (the worst named), edited samples."""
    q = qm.Quality()
    if not sol.converged:
        q.add("not_converged", "rejected", f"the solver did not converge ({sol.message})")
    if adaptation is not None and adaptation.get("refused"):
        a = adaptation
        q.add("refused", "suspect", f"the initial state is kept: {a['refused']['reason']}", value=a["refused"]["code"])
        q.add("apriori_conflict", "suspect", f"a-priori chi2 {a['chi2_before']:.4g} over {a['rows']} (limit "
              f"{a['limit']:.3g}) of the refused solution", value=a["chi2_before"], limit=a["limit"])
    elif adaptation is not None:
        a = adaptation
        if a["resolved"]:
            q.add("apriori_conflict", "ok",
                  f"the data contradicted the state a-priori (chi2 {a['chi2_before']:.4g} over {a['rows']}, limit "
                  f"{a['limit']:.3g}); its covariance was scaled by {a['factor']:.3g} "
                  f"(sigmas x{a['sigma_factor']:.3g}, maximum-likelihood variance component)",
                  value=a["chi2_before"], limit=a["limit"])
        else:           # (solve refuses such a solution: kept for a caller of adapt_apriori alone)
            q.add("apriori_conflict", "rejected",
                  f"the data contradict the state a-priori (chi2 {a['chi2_before']:.4g} over {a['rows']}, limit "
                  f"{a['limit']:.3g}) and cannot carry a looser one", value=a["chi2_before"], limit=a["limit"])
    elif sol.n_prior:
        qm.add_apriori_check(q, sol.chi2_prior, sol.n_prior, "constraints",
                             "the data and the a-priori disagree, the covariance that leans on the a-priori does not hold")
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
    if sol.n_edited > 0.1 * sol.n_measurements:
        q.add("edited", "suspect", f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)",
              value=int(sol.n_edited), limit=0.1 * sol.n_measurements)
    return q


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
    for st, pid in sorted(set(zip(meas.station[rr], meas.pass_id[rr]))):
        rows = np.flatnonzero(rr & (meas.station == st) & (meas.pass_id == pid))
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
