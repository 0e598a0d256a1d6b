"""The outputs of a solved refinement (:func:`finish`): the refined state at the traverse epoch and
at the stale epoch with the covariance, the constraints of seed 004 eq. 5, the observability
report, the residuals at the samples, the warnings and the diagnostics.

One responsibility, turning a solution into what refine writes; over 400 lines because it writes
that many things (the list above), assembled by :func:`finish`.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from trackproc.constants import force_model_constants
from trackproc.dynamics import propagator
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.rtn import rtn_covariance, rtn_jacobian
from trackproc.errors import ProcessingError
from trackproc.isotime import iso_utc
from trackproc.methods import refinement as rf
from trackproc.methods.quality import chi2_limit
from trackproc.models import modifiers as md
from trackproc.models.observables import range_rate_per_hz
from trackproc.pipeline.od import UNITS, residual_frame
from trackproc.pipeline.refine.options import CIRCULAR_TEST_P, LOW_PASS_DEG, RefineResult
from trackproc.types import State
from trackproc.pipeline.refine.problem import (Refinement, default_apriori_covariance, link_mode,
                                               state_prior_covariance)
from trackproc.pipeline.refine.quality import refine_quality
from trackproc.pipeline.refine.steps import refined_step
from trackproc.pipeline.refine.traverse import (eccentricity, max_elevation_deg, model_traverse, time_tag_covariance,
                                                time_tag_direction)
from trackproc.pipeline.timing import timing_warning, tle_timing


def finish(ref: Refinement, sol, kkt=None, sigma_scale: float = 1.0, consistency: dict | None = None,
           prior_centre=None, adaptation: dict | None = None, traverse_moves: list | None = None,
           improvement: dict | None = None, refusal: dict | None = None,
           decision: dict | None = None, step: dict | None = None) -> RefineResult:
    """Outputs of a solved :class:`Refinement` (states, covariance, report, residuals);
    ``consistency`` the :func:`circular_consistency` of a ``--circular`` solution;
    ``prior_centre`` the a-priori centre the solution was solved with (:meth:`Refinement.solve`);
    ``decision`` what became of the stale state (methods/estimation/decision.py: replaced, kept,
    declined), written to the diagnostics and the verdict; ``step`` a level shift found inside the
    pass (:mod:`trackproc.pipeline.refine.steps`: modelled, declined or said).

    Over 100 lines: the kept stale state, the residuals, the observability, the traverse report,
    the method and the states are steps of their own; what stays is the covariance written, which
    grows in order (profile, time-tag consider term, a TLE's timing), each step updating the
    sigmas, the observability's RTN sigmas, the note and the warnings, and the diagnostics built
    from all of it."""
    opt = ref.options
    problem = ref.problem
    warnings = list(ref.warnings)
    x = sol.values
    names = list(ref.names)
    npb = ref.n_problem
    cov = ref.covariance(sol, kkt)
    if refusal is not None:
        x, cov = _kept_stale_state(ref, sol, cov, refusal, improvement)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    units = problem.params.units() + (["m"] if opt.circular else [])

    samples = _sample_residuals(ref, sol, x, sigma_scale, refusal is not None)
    residuals = residual_frame(problem, samples)
    kept = ~samples.edited
    # Doppler residual (Hz) -> m/s: c/f one-way, c/(2f) two-way
    rr_factor = abs(range_rate_per_hz(ref.carrier_hz, link_mode(ref) == "two-way")) if ref.kind == "doppler" else 1.0
    res_kept = samples.residual[kept]
    rms = float(np.sqrt(np.mean(res_kept ** 2))) if res_kept.size else math.nan

    # constraints (eq. 5) at the solution
    constraints = constraint_report(ref, x, cov, sigma, kkt, consistency)

    obs = _observability(ref, sol, x, cov, sigma_scale)
    big = rtn_jacobian(x[:3], x[3:6], rotating=False)             # GCRF -> RTN for (r, v)
    covariance_note = "linear (the inverse of the whitened normal matrix at the solution)"
    if (opt.covariance == "profile" and opt.cost == "pointwise" and not opt.circular and obs.unobservable and ref.priors
            and refusal is None):
        # the estimate slides along a curved valley where the pass sees nothing: the linear
        # covariance misses that curvature along the best-determined combinations
        try:
            cov = ref.profile_covariance(sol, obs, sigma_scale, prior_centre)
            sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
            obs.posterior_sigma_rtn = np.sqrt(np.clip(np.diag(big @ cov[:6, :6] @ big.T), 0.0, None))
            covariance_note = (f"profile: linear, plus the curvature along the {len(obs.unobservable)} "
                               f"direction(s) the pass cannot see ({rf.PROFILE_NODES} Gauss-Hermite points each)")
        except ProcessingError as exc:
            warnings.append(f"the profile covariance could not be computed ({exc}); the linear one is reported")
    time_tags = None
    tt_sigma, tt_source = ref.time_tag_sigma()
    if tt_sigma > 0 and opt.cost == "pointwise" and not opt.circular:
        # a time-tag offset the pass cannot see (docs/refine.md, "Mis-modelled passes"): a consider term
        # of the refined state (a kept or declined stale state is written with its own covariance:
        # the term then only entered the decision, run.refine)
        extra_cov = time_tag_covariance(ref, np.asarray(sol.values, float) if refusal is not None else x,
                                        ref.covariance(sol, kkt), tt_sigma)
        if extra_cov is None:
            warnings.append("the time-tag uncertainty could not be added to the covariance (propagation failed)")
        elif refusal is not None:
            time_tags = {"sigma_s": tt_sigma, "source": tt_source, "applied": "in the decision only (the stale "
                         "state is written with its own covariance)",
                         "position_sigma_m": float(np.sqrt(np.trace(extra_cov[:3, :3]))),
                         "velocity_sigma_m_s": float(np.sqrt(np.trace(extra_cov[3:6, 3:6])))}
        else:
            cov = cov + extra_cov
            sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
            obs.posterior_sigma_rtn = np.sqrt(np.clip(np.diag(big @ cov[:6, :6] @ big.T), 0.0, None))
            covariance_note += (f"; plus a time-tag uncertainty of {tt_sigma:g} s (consider parameter, "
                                f"from the {tt_source})" if tt_source == "station table" else
                                f"; plus a time-tag uncertainty of {tt_sigma:g} s (consider parameter)")
            time_tags = {"sigma_s": tt_sigma, "source": tt_source,
                         "position_sigma_m": float(np.sqrt(np.trace(extra_cov[:3, :3]))),
                         "velocity_sigma_m_s": float(np.sqrt(np.trace(extra_cov[3:6, 3:6])))}
    # a pass whose timing contradicts its TLE: the covariance takes the shift as a possible
    # time-tag error (pipeline/timing.py)
    timing = (tle_timing(ref.initial, problem.epoch, ref.x0, x, cov, lambda: time_tag_direction(ref, x), ref.mu)
              if refusal is None else None)
    if timing is not None:
        cov = timing.pop("covariance")
    if timing is not None and timing["inflated"]:
        sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        obs.posterior_sigma_rtn = np.sqrt(np.clip(np.diag(big @ cov[:6, :6] @ big.T), 0.0, None))
        constraints = constraint_report(ref, x, cov, sigma, kkt, consistency)
        warnings.append(timing_warning(timing))
    # how far the pass moved the stale state, along what it sees and along what it cannot
    # (a large unseen part means the a-priori, not the data, put the state there)
    obs.correction_rtn = {part: dict(zip(rf.RTN_NAMES, (big @ d).tolist()))
                          for part, d in zip(("seen", "unseen"), obs.split(x[:6] - ref.x0[:6]))}
    if refusal is not None:
        refusal = dict(refusal)
        refusal.pop("state_covariance", None)
        refusal.pop("decision", None)
        refusal["refused_correction_rtn"] = {
            part: dict(zip(rf.RTN_NAMES, (big @ d).tolist()))
            for part, d in zip(("seen", "unseen"), obs.split(np.asarray(sol.values, float)[:6] - ref.x0[:6]))}

    # the state at the stale epoch
    rv_s, cov_s = at_stale_epoch(ref, x, cov)

    t_model = model_traverse(ref, x)
    traverse = _traverse_report(ref, t_model, traverse_moves)

    # warnings
    max_el = max_elevation_deg(ref, x)
    warnings += refine_warnings(ref, sol, obs, kkt, sigma_scale, consistency, max_el)

    if step is not None and step.get("action") == "modelled":
        step = dict(step, fitted=refined_step(ref, sol, cov))
    quality = refine_quality(ref, sol, sigma_scale=sigma_scale, adaptation=adaptation, improvement=improvement,
                             refusal=refusal, t_model=t_model, max_el=max_el, consistency=consistency,
                             timing=timing, decision=decision, step=step)
    if refusal is not None:
        warnings.append(f"the stale state is kept: {refusal['reason']}")
    apriori_note = ref.apriori_note
    if adaptation is not None and adaptation.get("factor", 1.0) > 1.0 and refusal is None:
        a = adaptation
        t = a.get("test") or {"statistic": a["chi2_before"], "dof": a["rows"], "limit": a["limit"]}
        warnings.append(f"the pass contradicted the a-priori (chi2 {t['statistic']:.4g} over {t['dof']}, 99.9 % limit "
                        f"{t['limit']:.3g}): its covariance was scaled by {a['factor']:.3g} (sigmas x"
                        f"{a['sigma_factor']:.3g}; maximum-likelihood variance component) and the pass refined again")
        apriori_note += f"; scaled by {a['factor']:.3g} (the pass contradicted it)"
    rtn = rtn_covariance(x[:3], x[3:6], cov[:6, :6])
    diagnostics = {
        "converged": bool(sol.converged), "message": sol.message, "iterations": int(sol.iterations),
        "damped_steps": int(sol.damped_steps), "cost": float(sol.chi2), "cost_history": sol.cost_history,
        "dof": int(sol.dof), "variance_factor": sol.variance_factor, "condition_number": sol.condition_number,
        "apriori_rows": sol.n_prior, "chi2_apriori": sol.chi2_prior,
        "samples": int(problem.meas.observed.size), "edited": int((~kept).sum()),
        "sigma_scale": sigma_scale, "max_elevation_deg": max_el,
        "residual_rms": {"value": rms, "unit": UNITS[ref.kind], "range_rate_m_s": rms * rr_factor},
        "apriori_adaptation": adaptation, "improvement": without_nuisance(improvement), "refused": refusal,
        "decision": decision,
        "tle_timing": timing,
        "traverse": traverse, "constraints": constraints, "observability": obs.as_dict(),
        "covariance_rtn": rtn,
        "sigma_rtn": dict(zip(rf.RTN_NAMES, np.sqrt(np.clip(np.diag(rtn), 0.0, None)).tolist())),
        "units": units, "warnings": warnings,
    }
    if step is not None:                              # a level shift inside the pass: modelled, declined or said
        diagnostics["step"] = step
    if time_tags is not None:                         # the time-tag consider term
        diagnostics["time_tag_consider"] = time_tags
    if ref.noise_report is not None:                  # the noise model of the pass (methods/noise.py)
        diagnostics["noise"] = ref.noise_report
    method = _method_report(ref, sol, apriori_note, covariance_note)
    state, stale_state = _states(ref, names, x, sigma, cov, rv_s, cov_s, method, diagnostics, quality)
    return RefineResult(state=state, stale_epoch_state=stale_state, solution=sol, problem=problem, curve=ref.curve,
                        residuals=residuals, observability=obs, constraints=constraints, covariance=cov, names=names,
                        warnings=warnings, quality=quality)


def _observability(ref: Refinement, sol, x, cov, sigma_scale: float):
    """What this pass sees of the state (:func:`~trackproc.methods.refinement.observability`), against
    the a-priori covariance (or the default one when the fit had none), with the notes on what
    ``--circular`` and the a-priori do to the unseen directions."""
    opt, problem = ref.options, ref.problem
    reference = state_prior_covariance(ref.priors)
    ref_name = "the a-priori covariance at the traverse epoch"
    if reference is None:
        reference = default_apriori_covariance(x[:6], ref.mu)
        ref_name = "the default a-priori covariance (not used in the fit)"
    _, _, sig_data, _, _ = ref.data()
    keep = ~sol.edited
    obs = rf.observability(sol.jacobian[keep][:, :ref.n_problem], np.asarray(sig_data)[keep] * sigma_scale,
                           problem.names, rtn_jacobian(x[:3], x[3:6], rotating=False), reference, cov[:6, :6],
                           other_scales=problem.params.scales()[6:], reference=ref_name,
                           station_axis=ref.station_axis, state=x[:6])
    if opt.circular and ref.tolerance() > 0:
        obs.notes.append(f"--circular with --circular-tolerance {ref.tolerance():g}: the constraints of eq. 5 hold "
                         "to the spread of an orbit circular to that eccentricity (soft), estimated with the state")
    elif opt.circular:
        obs.notes.append("--circular: the three constraints of eq. 5 fix three combinations of the state; "
                         "the covariance is zero across them (it is conditional on a circular orbit)")
    if ref.priors and opt.cost == "pointwise" and obs.unobservable:
        obs.notes.append("directions the pass cannot see keep the a-priori (stale) uncertainty")
    return obs


def _states(ref: Refinement, names, x, sigma, cov, rv_s, cov_s, method: dict, diagnostics: dict, quality):
    """The refined state at the traverse epoch and the same solution at the stale state's epoch."""
    opt, problem = ref.options, ref.problem
    stale_doc = {"epoch": iso_utc(ref.stale_epoch), "frame": "GCRF", "position_m": rv_s[:3].tolist(),
                 "velocity_m_s": rv_s[3:].tolist(), "parameters": names, "values": np.r_[rv_s, x[6:]].tolist(),
                 "sigma": np.sqrt(np.clip(np.diag(cov_s), 0.0, None)).tolist(), "covariance": cov_s.tolist()}
    values = x.copy()
    extra = {"refinement": method, "at_stale_epoch": stale_doc,
             "stale_state": {"epoch": iso_utc(ref.initial.epoch), "position_m": ref.initial.r_m.tolist(),
                             "velocity_m_s": ref.initial.v_m_s.tolist(),
                             "source": ref.initial.source or (ref.initial.extra or {}).get("source")}}
    eop_source = getattr(problem.eop, "source", None) or "none (UT1-UTC = 0, no polar motion)"
    extra["quality"] = quality.as_dict()
    state = State.from_vectors(problem.epoch, x[:3], x[3:6], parameters=names, values=values, sigma=sigma,
                               covariance=cov, force_model=opt.force, constants=force_model_constants(opt.force),
                               eop_source=eop_source, diagnostics=diagnostics, extra=extra)
    stale_state = State.from_vectors(ref.stale_epoch, rv_s[:3], rv_s[3:], parameters=names,
                                     values=np.r_[rv_s, x[6:]], sigma=np.sqrt(np.clip(np.diag(cov_s), 0.0, None)),
                                     covariance=cov_s, force_model=opt.force,
                                     constants=force_model_constants(opt.force), eop_source=eop_source,
                                     diagnostics=diagnostics,
                                     extra={"refinement": method, "at_traverse_epoch": iso_utc(problem.epoch),
                                            "quality": quality.as_dict()})
    return state, stale_state


def _kept_stale_state(ref: Refinement, sol, cov, refusal: dict, improvement: dict | None):
    """``(x, cov)`` when the pass cannot improve the stale state: the stale state with its a-priori
    covariance, the Doppler offset/drift fitted at it (:func:`stale_improvement`'s nuisance)."""
    npb = ref.n_problem
    x = np.asarray(sol.values, float).copy()
    x[:6] = ref.x0[:6]
    cov = np.zeros_like(np.asarray(cov, float))
    cov[:6, :6] = refusal["state_covariance"]
    nuisance = (improvement or {}).get("stale_nuisance") or {}
    if len(nuisance.get("values", [])) == npb - 6 and npb > 6:
        x[6:npb] = nuisance["values"]
        cov[6:npb, 6:npb] = np.asarray(nuisance["covariance"], float)
        cross = np.asarray(nuisance.get("state_cross", []), float)
        if cross.shape == (npb - 6, 6):
            cov[6:npb, :6] = cross
            cov[:6, 6:npb] = cross.T
    return x, cov


def _sample_residuals(ref: Refinement, sol, x, sigma_scale: float, refused: bool):
    """The residuals at the samples (both costs): the solution's own for the pointwise cost, else
    the model at ``x`` (the kept stale state, or the integral cost's solution)."""
    problem = ref.problem
    if not refused and ref.options.cost == "pointwise":
        return sol
    h, _ = problem.model(x[:ref.n_problem])
    r = problem.meas.observed - h
    if refused:
        return SimpleNamespace(computed=h, residual=r, normalized=r / (problem.meas.sigma * sigma_scale),
                               edited=np.asarray(sol.edited, bool))
    return SimpleNamespace(computed=h, residual=r, normalized=r / problem.meas.sigma, edited=np.zeros(r.size, bool))


def _traverse_report(ref: Refinement, t_model, traverse_moves) -> dict:
    """The traverse-point diagnostics: the solution epoch, how it was defined, and where the
    refined orbit's own zero range-rate falls (``t_model`` s from it)."""
    epoch = ref.problem.epoch
    return {"epoch": iso_utc(epoch), "definition": ref.traverse_how,
            "sigma_s": float(ref.curve.tca.sigma_s) if ref.curve.tca is not None else None,
            "curve": ref.curve.source,
            "refined_orbit_zero_range_rate_s": t_model,
            "moved_s": list(traverse_moves or []),
            "refined_orbit_zero_range_rate_utc": (iso_utc(epoch + np.timedelta64(int(round(t_model * 1e9)), "ns"))
                                                  if t_model is not None else None)}


def _method_report(ref: Refinement, sol, apriori_note: str, covariance_note: str) -> dict:
    """How the pass was refined (the ``refinement`` block of the state file)."""
    opt = ref.options
    method = {"cost": opt.cost, "circular": bool(opt.circular),
              "solver": ("Gauss-Newton with equality constraints, KKT by the null-space method (seed 004 eqs. 15-17)"
                         if opt.circular else "Gauss-Newton by QR/SVD with Levenberg-Marquardt damping"),
              "apriori": apriori_note, "covariance": covariance_note,
              "kind": ref.kind, "station": ref.station_name, "pass_id": ref.pass_id,
              "range_rate_model": ref.problem.range_rate_model, "force_model": opt.force, "earth": opt.earth,
              "doppler_bias": [d.name for d in ref.modifier_drivers(md.DopplerOffset, md.DopplerDrift)],
              "propagator": "Taylor (DT) with first-order sensitivity spectra, quasi-inertial frame of the traverse "
                            "epoch"}
    if opt.cost == "integral":
        method.update(integral_method(ref, sol))
    return method


def constraint_report(ref: Refinement, x, cov, sigma, kkt=None, consistency: dict | None = None) -> dict:
    """The circular-orbit constraints of seed 004 eq. 5 at the solution ``x`` (values, scales, ``r_ka``
    and its sigma; with ``kkt`` the multipliers and, under ``--circular``, ``consistency``)."""
    opt = ref.options
    names = list(ref.names)
    rka = float(x[-1]) if opt.circular else float(np.linalg.norm(x[:3]))
    x7 = np.r_[x[:6], rka]
    f, _ = rf.circular_constraints(x7, ref.mu)
    fscale = rf.constraint_scales(x7, ref.mu)
    constraints = {"names": list(rf.CONSTRAINT_NAMES), "units": ["m^2", "m^2/s^2", "m^2/s"],
                   "values": f.tolist(), "relative": (f / fscale).tolist(), "imposed": bool(opt.circular),
                   "r_ka_m": rka, "eccentricity": eccentricity(x[:3], x[3:6], ref.mu)}
    if kkt is not None:
        constraints.update({"multipliers": kkt.multipliers.tolist(),
                            "multipliers_note": "lambda of L = chi2 + lambda^T f (chi2: the whitened cost; "
                                                "seed 004 eq. 16), per unit of each constraint",
                            "stationarity": kkt.stationarity, "restoration_steps": kkt.restorations,
                            "free_directions": kkt.null_space_dim, "eccentricity_tolerance": ref.tolerance(),
                            "tolerance_note": "the covariance includes the constraints' own uncertainty for an orbit "
                                              "circular only to this eccentricity (0: conditional on an exactly "
                                              "circular orbit)"})
        if kkt.soft is not None:            # --circular-tolerance: the constraint values estimated with the state
            soft = np.flatnonzero(kkt.soft)
            constraints["soft"] = {"names": [rf.CONSTRAINT_NAMES[i] for i in soft],
                                   "values": kkt.target[soft].tolist(),
                                   "sigma": ref.soft_sigma(kkt).tolist(),
                                   "note": "f(x) = eps with eps ~ N(0, Sigma_eps) of an orbit circular to the "
                                           "tolerance; maximum a-posteriori estimate (soft constraints)"}
        i_rka = names.index("r_ka")
        constraints["r_ka_sigma_m"] = float(sigma[i_rka])
        if consistency is not None:
            constraints["consistency"] = consistency
    else:
        u = x[:3] / np.linalg.norm(x[:3])
        constraints["r_ka_sigma_m"] = float(np.sqrt(u @ cov[:3, :3] @ u))
    return constraints


def at_stale_epoch(ref: Refinement, x, cov) -> tuple[np.ndarray, np.ndarray]:
    """The refined state ``x`` and its covariance moved to the stale state's epoch by the STM."""
    opt = ref.options
    problem = ref.problem
    names = list(ref.names)
    dt = float(ts.seconds_since(ts.datetime64_to_jd_utc(ref.stale_epoch),
                                tuple(float(a) for a in ts.datetime64_to_jd_utc(problem.epoch))))
    if dt == 0.0:
        rv_s, cov_s = x[:6].copy(), cov.copy()
    else:
        traj = propagator.propagate(x[:3], x[3:6], problem.epoch, [dt], force=opt.force, stm=True,
                                    frame=problem.frame, eop=problem.eop).raise_for_outcome()
        rv_s = traj.state(dt)
        jac = np.eye(len(names))
        jac[:6, :6] = traj.stm(dt)
        cov_s = jac @ cov @ jac.T
        cov_s = 0.5 * (cov_s + cov_s.T)
    return rv_s, cov_s


def refine_warnings(ref: Refinement, sol, obs, kkt=None, sigma_scale: float = 1.0, consistency: dict | None = None,
                    max_el: float | None = None) -> list:
    """The warnings a solution earns (low pass, reweighting, circular-constraint conflict, variance
    factor, a-priori conflict, edited samples, unseen directions), in the order the report gives them."""
    opt = ref.options
    warnings = []
    if max_el is not None and max_el < LOW_PASS_DEG:
        warnings.append(f"a low pass (highest elevation {max_el:.1f} deg < {LOW_PASS_DEG:g}): one low pass "
                        "determines the orbit poorly and an onboard oscillator's wander is easily taken for orbit; "
                        "see docs/refine.md")
    if sigma_scale > 1.0:
        warnings.append(f"the samples scatter more than their sigmas say: sigmas scaled by {sigma_scale:.3g} "
                        "(sqrt of the variance factor, iterated) before weighing them against the a-priori")
    if consistency is not None and consistency.get("p_value", 1.0) < CIRCULAR_TEST_P:
        c = consistency
        warnings.append(f"the pass contradicts the circular-orbit constraints (delta chi2 = {c['delta_chi2']:.4g}, 2 "
                        f"degrees of freedom, p = {c['p_value']:.2g}; the unconstrained fit's eccentricity is "
                        f"{c['free_fit_eccentricity']:.2g}): the constrained state is biased and its covariance too "
                        "small; " + ("give --circular-tolerance (the eccentricity the orbit is circular to) or drop "
                                     "--circular" if ref.tolerance() == 0.0 else
                                     f"the orbit is not circular to {ref.tolerance():g}: give a larger "
                                     "--circular-tolerance or drop --circular"))
    if opt.circular and kkt is not None and ref.tolerance() == 0.0:
        warnings.append("--circular: the covariance is conditional on an exactly circular orbit; with J2 the "
                        "osculating eccentricity of a circular orbit swings by about 1e-3 (give --circular-tolerance)")
    if sol.dof > 0 and sol.variance_factor > 4.0 and opt.cost == "pointwise":
        warnings.append(f"a-posteriori variance factor {sol.variance_factor:.3g} (> 4): the sigmas of the data are too "
                        "small or the model misses something; the covariance is optimistic")
    if sol.n_prior:
        limit = chi2_limit(sol.n_prior, 0.999)
        if sol.chi2_prior > limit:
            warnings.append(f"the refined state departs from the stale state by chi2 = {sol.chi2_prior:.4g} over "
                            f"{sol.n_prior} a-priori constraints (99.9 % limit {limit:.3g}): the pass and the stale "
                            "state disagree; check the pass, or loosen the a-priori")
    if opt.cost == "pointwise" and sol.n_edited > 0.1 * sol.n_measurements:
        warnings.append(f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)")
    if opt.cost == "integral" and not ref.priors and obs.unobservable:
        warnings.append(f"{len(obs.unobservable)} state direction(s) are weakly determined by the pass alone "
                        "(see the observability report); consider --apriori")
    return warnings


def integral_method(ref: Refinement, sol) -> dict:
    """The integral cost's part of the method report (seed 004 eq. 14: quadrature, normalisation,
    gradient, covariance) and the smoothed curve it integrates."""
    opt = ref.options
    d = ref.integral
    w = d["weights"]
    res_nodes = d["observed"] - sol.computed
    integral = float(np.sum(w * res_nodes ** 2))
    return {
        "integral": {"equation": "I = integral over the pass of (Vr_LSQ - Vr(X, t))^2 dt (seed 004 eq. 14)",
                     "quadrature": f"composite Gauss-Legendre, {opt.quadrature_order} nodes per panel of at most "
                                   f"{opt.quadrature_panel_s:g} s", "nodes": int(w.size),
                     "intervals_s": d["intervals"], "I_m2_s": integral,
                     "rms_curve_difference_m_s": math.sqrt(integral / float(np.sum(w))),
                     "normalisation": "chi2 = I / (sigma_ref^2 * spacing)", "sigma_ref_m_s": d["sigma_ref"],
                     "spacing_s": d["spacing"],
                     "link": d["mode"],
                     "gradient": ("first-order 2-D DT sensitivities (seed 004 eqs. 19-21) through the range and "
                                  "range-rate spectra" if d["mode"] == "one-way" else
                                  "round-trip (two-way) range-rate partials through both light times times the "
                                  "Taylor engine's state transition matrix (first-order DT sensitivities)"),
                     "covariance": "the smoothing polynomial's scaled coefficient covariance propagated through "
                                   "the linearised estimator (sandwich)",
                     "sigma_formal": sol.sigma.tolist()},
        "curve": {"degree": int(ref.curve.fit.degree), "basis": ref.curve.fit.basis, "source": ref.curve.source}}


def without_nuisance(improvement):
    if improvement is None:
        return None
    return {k: v for k, v in improvement.items() if k != "stale_nuisance"}
