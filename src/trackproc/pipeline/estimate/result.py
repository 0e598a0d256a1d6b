"""The result of ``trackproc estimate``: :func:`estimate` (problem, fit, gates, reports) and
what it returns (:class:`EstimateResult`, with the residual table and the state file's records)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from trackproc.constants import MU_EARTH
from trackproc.dynamics.rtn import rtn_covariance
from trackproc.errors import ProcessingError, TrackprocError
from trackproc.methods import quality as qm
from trackproc.models import observation as ob
from trackproc.pipeline.estimate import gates
from trackproc.pipeline.estimate.quality import estimate_quality
from trackproc.pipeline.estimate import seed002 as s2
from trackproc.pipeline.od import Problem, build_problem, residual_frame, rms_table  # noqa: F401
from trackproc.pipeline.od.options import EstimateOptions
from trackproc.pipeline.od.residuals import DeferredField
from trackproc.pipeline.od.state import sigma_rtn, solution_state
from trackproc.pipeline.timing import time_tag_rate, timing_warning, tle_reference, tle_timing
from trackproc.io.passfile import PassTable


@dataclass
class EstimateResult:
    """Everything :func:`estimate` produces (the CLI writes it).

    ``state`` (:class:`~trackproc.io.statefile.State`, GCRF, every estimated parameter, its
    sigma, the full covariance and the diagnostics), ``solution`` (the solver's
    :class:`~trackproc.methods.least_squares.Solution`), ``problem``, ``residuals`` (one row per
    sample: :data:`RESIDUAL_COLUMNS`), ``rtn_covariance`` (6 × 6, m and m/s), ``comparison``
    (Doppler-only vs extended, or None), ``two_stage`` (:class:`~trackproc.methods.two_stage.TwoStage`
    or None) and ``two_stage_solution`` (its stage-2 solution), ``warnings``.
    """

    state: object
    solution: object
    problem: Problem
    residuals: pd.DataFrame = DeferredField()        # built when first read (pandas then)
    rtn_covariance: np.ndarray
    comparison: Optional[dict] = None
    two_stage: Optional[object] = None
    two_stage_solution: Optional[object] = None
    warnings: list = field(default_factory=list)
    quality: Optional[object] = None


#: Passes at most for which a failed estimate looks for the one pass without which it succeeds.
MAX_CULPRIT_PASSES = 12


def failure_culprit(exc: ProcessingError, tables, initial, stations, opt: EstimateOptions, eop) -> ProcessingError:
    """A failed estimate (no convergence, rank deficiency) of several passes: is one pass the
    cause? Each pass is left out in turn (at most :data:`MAX_CULPRIT_PASSES`); when exactly one
    left out lets the others converge to a consistent solution (variance factor within its 99.9 %
    point, not refused), the error names it (another object's pass, a wrong station or time
    tags). Returns the error to raise (``exc`` itself when no single pass is to blame)."""
    keys = sorted({(str(s), str(p)) for _, t in tables
                   for s, p in zip(t.frame["station"].astype(str), t.frame["pass_id"].astype(str))})
    if not 2 <= len(keys) <= MAX_CULPRIT_PASSES:
        return exc
    fine = []
    for station, pass_id in keys:
        rest = []
        for source, t in tables:
            keep = ~((t.frame["station"].astype(str) == station) & (t.frame["pass_id"].astype(str) == pass_id))
            if keep.any():
                rest.append((source, PassTable(t.frame[keep.to_numpy()].reset_index(drop=True), t.meta)))
        try:
            sol, adaptation, _ = gates.solve(build_problem(rest, initial, stations, opt, eop), opt)
        except TrackprocError:
            continue
        if (sol.dof > 0 and sol.variance_factor <= qm.variance_factor_limit(sol.dof)
                and not (adaptation or {}).get("refused")):
            fine.append(f"{station}/{pass_id}")
    if len(fine) != 1:
        return exc
    return ProcessingError(f"{exc}; without pass {fine[0]} the others converge and agree: check that pass "
                           "(another object's, a wrong station or time tags?), or leave it out",
                           {**exc.diagnostics, "culprit_pass": fine[0]})


def tle_timing_gate(problem: Problem, opt: EstimateOptions, initial, sol, adaptation):
    """An initial TLE moved along-track beyond its accuracy (:func:`trackproc.pipeline.timing.tle_timing`;
    a station's clock offset moves an estimate the same way): the solution's covariance then
    takes the shift. Returns ``(solution, timing report or None)``; nothing for a refused solution
    (the initial state is kept)."""
    if (adaptation or {}).get("refused"):
        return sol, None
    x0 = tle_reference(initial, problem.epoch, problem.eop)
    if x0 is None:
        return sol, None
    x = np.asarray(sol.values, float)
    force = opt.force if opt.force in ("two-body", "j2") else "j2"   # the rate's acceleration: J2 is enough
    timing = tle_timing(initial, problem.epoch, x0, x, sol.covariance,
                        lambda: time_tag_rate(x, problem.epoch, force, problem.frame, problem.eop), MU_EARTH)
    if timing is None:
        return sol, None
    cov = timing.pop("covariance")
    if timing["inflated"]:
        sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = np.nan_to_num(cov / np.outer(sigma, sigma))
        sol = replace(sol, covariance=cov, sigma=sigma, correlation=corr)
    return sol, timing


def estimate(tables, initial, stations=None, options: EstimateOptions | None = None, eop=None) -> EstimateResult:
    """Estimate the orbit state and the selected biases from pass tables (see the module docstring).

    Returns :class:`EstimateResult`; raises :class:`InputError` (exit 2) for invalid input and
    :class:`ProcessingError` (exit 1) when the estimation fails (too few data, rank deficiency,
    non-convergence), with diagnostics.
    """
    opt = options or EstimateOptions()
    problem = build_problem(tables, initial, stations, opt, eop)
    try:
        sol, adaptation, noise_report = gates.solve(problem, opt)
    except ProcessingError as exc:
        raise failure_culprit(exc, tables, initial, stations, opt, eop) from None
    # the estimator's own solution and covariance: what the quality tests take (for an initial state
    # kept by the replace/keep rule, the fit that was not taken)
    fitted = (adaptation or {}).pop("fitted_solution", None) or sol
    sol, timing = tle_timing_gate(problem, opt, initial, sol, adaptation)
    problem.params.set_values(sol.values)
    x = sol.values
    if problem.force_names:                 # the metadata name the estimated Cr, Cd, accelerations
        problem.force_model = problem.force_model_at(x)
    names = sol.names
    rtn = rtn_covariance(x[:3], x[3:6], sol.covariance[:6, :6])
    warnings = gates.warnings_of(sol)
    if timing is not None and timing["inflated"]:
        warnings.append(timing_warning(timing, "the passes"))
    fixed = {d.name: d.value for d in problem.params if not d.selected}
    drifts = {d.name: d.epoch_s for d in problem.params if d.epoch_s is not None}
    diagnostics = {
        "converged": bool(sol.converged), "message": sol.message, "iterations": int(sol.iterations),
        "damped_steps": int(sol.damped_steps), "cost": float(sol.chi2), "cost_history": sol.cost_history,
        "dof": int(sol.dof), "variance_factor": sol.variance_factor, "wrms": sol.wrms,
        "apriori_rows": sol.n_prior, "chi2_apriori": sol.chi2_prior,
        "condition_number": sol.condition_number,
        "measurements": sol.n_measurements, "edited": sol.n_edited, "clip_sigma": opt.clip,
        "rms": rms_table(problem, sol),
        "correlation": sol.correlation,
        "covariance_rtn": rtn, "sigma_rtn": sigma_rtn(rtn),
        "units": problem.params.units(),
    }
    if noise_report is not None:
        diagnostics["noise"] = noise_report
    if adaptation is not None:
        diagnostics["apriori_adaptation"] = adaptation
    diagnostics["tle_timing"] = timing
    diagnostics["decision"] = problem.decision
    quality = estimate_quality(problem, fitted, adaptation, clip=opt.clip, noise_report=noise_report, timing=timing)
    comparison = s2.compare(problem, fitted) if opt.compare_doppler_only else None
    two, sol2 = s2.two_stage(problem, fitted, opt) if opt.two_stage else (None, None)
    if comparison is not None:
        diagnostics["compare_doppler_only"] = comparison
    if two is not None:
        diagnostics["two_stage"] = s2.two_stage_dict(two, sol2)
    extra = {"estimation": {
        "method": "batch weighted least squares (Gauss-Newton by SVD, Levenberg-Marquardt damping)",
        "range_rate_model": problem.range_rate_model,
        "light_time": light_time_note(problem.meas),
        "propagator": ("DOP853 with variational equations" if problem.force_model is not None
                       else "Taylor (DT) with state transition matrix") + ", quasi-inertial frame of the solution epoch",
        "earth": opt.earth, "doppler_bias": opt.doppler_bias, "doppler_bias_per": opt.doppler_bias_per,
        "fixed_parameters": fixed, "drift_epochs_s": drifts,
        "apriori": {n: s for n, s, m in zip(names, problem.params.apriori()[2], problem.params.apriori()[0]) if m},
        "apriori_initial": problem.apriori_initial, "apriori_source": problem.apriori_source or None,
        "apriori_note": problem.apriori_note or None,
        **({"apriori_default": problem.apriori_note} if problem.apriori_note.startswith("the initial state has no")
           else {}),
        "sources": sorted({str(s) for s in problem.sources}),
    }, "quality": quality.as_dict()}
    if problem.force_model is not None and (problem.force_model.srp or problem.force_model.drag):
        # the spacecraft (with the estimated Cr/Cd) where --force full commands read it back, so that
        # the solution propagates with the forces it was fitted with
        extra["spacecraft"] = problem.force_model.spacecraft.as_dict()
    state = solution_state(problem, problem.epoch, x, names, sol.sigma, sol.covariance, opt.force, eop, diagnostics,
                           extra)
    return EstimateResult(state=state, solution=sol, problem=problem, residuals=residual_frame(problem, sol),
                          rtn_covariance=rtn, comparison=comparison, two_stage=two, two_stage_solution=sol2,
                          warnings=warnings, quality=quality)


def light_time_note(meas) -> str:
    """How the samples' light time was modelled (the state file's ``estimation`` record)."""
    if not meas.two_way.any():
        return "one-way, time tag at reception, range-rate > 0 receding"
    both = "one-way and " if (~meas.two_way & np.isin(meas.kind, ob.LINK_KINDS)).any() else ""
    return (f"{both}two-way (round trip to the same station, turnaround ratio 1: range = round trip / 2, "
            "range-rate = mean of both legs), time tag at reception, range-rate > 0 receding")
