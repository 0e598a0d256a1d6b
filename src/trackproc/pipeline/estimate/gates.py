"""Noise model and consistency gates of an estimate: :func:`pass_noise` (per-pass REML, then
GLS), :func:`solve` (the weighted fit, then the correlated one), :func:`estimate_quality` (the
``quality`` verdict) and :func:`warnings_of` (the summary's warnings)."""

from __future__ import annotations

import math

import numpy as np

from trackproc.methods import noise as nz
from trackproc.methods import quality as qm
from trackproc.models import modifiers as md
from trackproc.pipeline.estimate.options import EstimateOptions
from trackproc.pipeline.estimate.problem import Problem


def solve(problem: Problem, opt: EstimateOptions):
    """The weighted least-squares fit, then (unless ``--noise white``) REML of each pass's noise
    on its residuals, GLS, REML again on the GLS residuals and GLS. Returns ``(solution, noise
    report or None)``."""
    sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol)
    noise_report = None
    if opt.noise != "white" or opt.oscillator_noise is not None:
        previous = None
        for _ in range(2):            # REML on the residuals, GLS, REML again on its residuals
            cov, noise_report = pass_noise(problem, sol, opt)
            if cov is None and previous is None:
                break                 # white: the weighted fit stands
            sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol,
                                noise=cov, edited=sol.edited, x0=sol.values)
            previous = cov
    return sol, noise_report


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


def estimate_quality(problem: Problem, sol):
    """The :class:`~trackproc.methods.quality.Quality` of a batch solution: convergence, a-priori
    conflict (``rejected``: the covariance leans on an a-priori the data contradict), variance
    factor against its 99.9 % point, the pass that dominates the misfit (named), residual
    whiteness per pass (the worst named), edited samples."""
    q = qm.Quality()
    if not sol.converged:
        q.add("not_converged", "rejected", f"the solver did not converge ({sol.message})")
    if sol.n_prior:
        limit = qm.chi2_limit(sol.n_prior)
        q.add("apriori_conflict", "ok" if sol.chi2_prior <= limit else "rejected",
              f"a-priori chi2 {sol.chi2_prior:.4g} over {sol.n_prior} constraints (99.9 % limit {limit:.3g})"
              + ("" if sol.chi2_prior <= limit else ": the data and the a-priori disagree, the covariance that leans "
                 "on the a-priori does not hold"), value=sol.chi2_prior, limit=limit)
    vf_limit = qm.variance_factor_limit(sol.dof) if sol.dof > 0 else None
    if sol.dof > 0 and math.isfinite(sol.variance_factor):
        q.add("variance_factor", "ok" if sol.variance_factor <= vf_limit else "suspect",
              f"a-posteriori variance factor {sol.variance_factor:.4g} (99.9 % limit {vf_limit:.3g})",
              value=sol.variance_factor, limit=vf_limit)
    # per pass: its share of the misfit and the whiteness of its residuals (time order)
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
        w = qm.whiteness(z[idx])
        passes.append({"pass": f"{key[0]}/{key[1]} {key[2]}", "n": int(idx.size), "chi2": float(z[idx] @ z[idx]),
                       "whiteness": w})
    total = sum(p["chi2"] for p in passes)
    if len(passes) > 1 and total > 0 and sol.dof > 0 and sol.variance_factor > vf_limit:
        worst = max(passes, key=lambda p: p["chi2"] / p["n"])
        share = worst["chi2"] / total
        if share > 0.5:
            q.add("dominant_pass", "suspect",
                  f"pass {worst['pass']} carries {100 * share:.0f} % of the misfit with {worst['n']} of "
                  f"{sum(p['n'] for p in passes)} samples (variance factor {worst['chi2'] / worst['n']:.3g}): "
                  "check it, or leave it out", value=share, limit=0.5)
    if passes:
        worst = max(passes, key=lambda p: (p["whiteness"]["lag1_autocorrelation"]
                                          if math.isfinite(p["whiteness"]["lag1_autocorrelation"]) else -1.0))
        if math.isfinite(worst["whiteness"]["lag1_autocorrelation"]):
            before = len(q.reasons)
            qm.add_whiteness(q, worst["whiteness"])
            if len(q.reasons) > before:
                q.reasons[-1]["message"] = f"pass {worst['pass']}: " + q.reasons[-1]["message"]
    if sol.n_edited > 0.1 * sol.n_measurements:
        q.add("edited", "suspect", f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)",
              value=int(sol.n_edited), limit=0.1 * sol.n_measurements)
    return q


def pass_noise(problem: Problem, sol, opt: EstimateOptions):
    """The noise model of every pass's Doppler and range-rate samples from the residuals of
    ``sol`` (:func:`trackproc.methods.noise.fit_noise`: REML with the pass's Jacobian columns as
    fixed effects; the random walk of the transmitter frequency only for one-way passes with a
    frequency offset, i.e. an :class:`~trackproc.models.modifiers.OscillatorWander` on its samples). Returns ``(PassCovariance or None when every pass is white, report)``;
    the report lists each pass's model and effective number of samples."""
    meas = problem.meas
    keep_all = ~np.asarray(sol.edited, bool)
    rr = np.isin(meas.kind, ["doppler", "range_rate"])
    blocks, report = [], {}
    wanders = [b for b in problem.modifiers if isinstance(b.modifier, md.OscillatorWander)]
    _, jac_all = problem.model(np.asarray(sol.values, float))     # (a GLS solution's own rows are whitened)
    for st, pid in sorted(set(zip(meas.station[rr], meas.pass_id[rr]))):
        rows = np.flatnonzero(rr & (meas.station == st) & (meas.pass_id == pid))
        keep = keep_all[rows]
        if keep.sum() < 20:
            continue
        t = meas.t_s[rows]
        jac = np.asarray(jac_all, float)[rows]
        wander = next((b.modifier for b in wanders if np.isin(rows, b.rows).all()), None)
        osc = wander is not None
        if opt.noise == "auto":
            models = nz.MODELS if osc else ("white", "ar1")
        elif opt.noise == "white":
            models = ("white",)
        else:
            models = (opt.noise,)
        nf = nz.fit_noise(t[keep], np.asarray(sol.residual, float)[rows][keep], jac[keep], models=models,
                          walk=wander.walk if osc else None, t0=float(t.min()))
        d = nf.as_dict()
        d.pop("candidates", None)
        report[f"{st}/{pid}"] = d
        if not nf.model.is_white:
            blocks.append((rows, nf.model, float(t.min())))
    if not blocks:
        return None, report
    return nz.PassCovariance(meas.sigma, meas.t_s, blocks), report
