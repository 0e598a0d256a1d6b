"""The fit itself (steps 3, 5, 6 and 8 of :mod:`trackproc.pipeline.fit_tle`): one procedure whose
verdict, refusal and summary read the same intermediate results."""

from __future__ import annotations

import math
from typing import Optional

import numpy as np
import pandas as pd

from trackproc.dynamics.timescales import datetime64_to_jd_utc
from trackproc.errors import InputError, ProcessingError
from trackproc.io.statefile import format_epoch
from trackproc.io.tle import MeanElements, format_tle, round_epoch, satrec, tle_epoch
from trackproc.methods import quality as qm
from trackproc.methods import tle_fit as tf
from trackproc.models.observation import wrap_pi
from trackproc.pipeline.fit_tle.checks import cross_validation, time_shifts
from trackproc.pipeline.fit_tle.model_error import model_error_fit
from trackproc.pipeline.fit_tle.observations import default_epoch, mean_elements, nuisance_design, observations, reepoch
from trackproc.pipeline.fit_tle.options import (APRIORI_MODELS, BSTAR_SIGMA_FLOOR, DOPPLER_BIAS, EDITED_LIMIT,
                                                MU_WGS72, REFUSAL_PROBABILITY, FitTleOptions, FitTleResult)
from trackproc.pipeline.identify import integrated_autocorrelation_time
from trackproc.methods.estimation.prior import DEFAULT_APRIORI_ELEMENTS


def fit_tle(tables: list, ephemerides: list, orbit, options: FitTleOptions, eop=None,
            stations: Optional[dict] = None) -> FitTleResult:
    """Fit a TLE to ``tables`` (``(source, PassTable)``) and ``ephemerides`` (``(source,
    Ephemeris)``) from ``orbit`` (:class:`~trackproc.pipeline.orbit_source.OrbitInput`).

    Over 100 lines: the option checks, the per-group summaries and the residual table are steps of
    their own; the rest (a-priori, fit, theory error, verdict, refusal, summary) reads and extends
    one set of some thirty values and the closures ``model``/``run`` over them, which further
    functions would only pass around."""
    _check_options(options)
    template = orbit.tle
    epoch = round_epoch(options.epoch if options.epoch is not None else default_epoch(tables, ephemerides))
    obs, blocks = observations(tables, ephemerides, options, eop, stations)
    design, nuisance_names = nuisance_design(obs, options.doppler_bias)
    bstar0 = float(satrec(template).bstar) if template is not None else 0.0
    x_init, reepoch_rms, initial_force = reepoch(orbit, epoch, bstar0, eop)
    jd1, jd2 = datetime64_to_jd_utc(np.asarray([epoch], dtype="datetime64[ns]"))
    satnum_text = (options.satnum or (template.satnum if template is not None else "99999")).strip()
    ep = tf.Epoch(int(satnum_text) if satnum_text.isdigit() else 0, float(jd1[0]), float(jd2[0]))

    # a-priori: refine's default element sigmas at the initial epoch, carried to the new epoch
    n0 = float(x_init[0])
    a0 = (MU_WGS72 / (2 * math.pi * n0 / 86400.0) ** 2) ** (1 / 3)
    d = DEFAULT_APRIORI_ELEMENTS
    sig = tf.element_sigmas(d["a_m"], d["ex"], d["ey"], d["i_rad"], d["raan_rad"], d["u_rad"],
                            max(abs(bstar0), BSTAR_SIGMA_FLOOR), n0, a0)
    initial_epoch = tle_epoch(template) if template is not None else orbit.state.epoch
    age_days = float((epoch - np.datetime64(initial_epoch, "ns")) / np.timedelta64(1, "s")) / 86400.0
    # a TLE's own accuracy (TLE differencing) unless asked for refine's; the default a-priori's
    # sigmas stay the unit of the theory error (Q), the partials' steps and the undetermined check
    # (beyond the ages it was measured at a TLE's error grows faster than the model: refine's)
    too_old = template is not None and abs(age_days) > tf.TLE_APRIORI_MAX_AGE_DAYS
    use_tle = template is not None and options.apriori_model == "tle" and not too_old
    prior_sig = tf.tle_element_sigmas(**tf.TLE_APRIORI, bstar=sig[6], n_rev_day=n0, semi_major_m=a0,
                                      inclination_deg=float(x_init[3])) if use_tle else sig
    prior_cov = tf.age_covariance(prior_sig, age_days)
    default_cov = tf.age_covariance(sig, age_days)
    free = np.r_[np.ones(6, bool), bool(options.fit_bstar)]
    steps = tf.STEP_FRACTION * sig
    observed = obs["value"].to_numpy(float)
    sigma_file = obs["sigma"].to_numpy(float)
    is_az = (obs["kind"] == "azimuth").to_numpy()
    groups = obs["group"].to_numpy()

    def model(x):
        sat = tf.satrec_of(x, ep)
        out = np.empty(len(obs))
        for block in blocks:
            out[block.rows] = block.predict(sat)
        # azimuth: the prediction on the observation's side of the ±π cut
        out[is_az] = observed[is_az] - wrap_pi(observed[is_az] - out[is_az])
        return out

    def run(x0, sigma, keep):
        try:
            return tf.solve(model, x0, observed, sigma, free=free, prior_mean=x_init if options.apriori else None,
                            prior_cov=prior_cov if options.apriori else None, design=design, steps=steps, keep=keep,
                            max_iterations=options.max_iterations)
        except (ValueError, ProcessingError, np.linalg.LinAlgError) as exc:
            hint = "" if options.apriori else " (without --no-apriori the initial orbit constrains what the data do not)"
            raise ProcessingError(f"the fit failed: {exc}{hint}") from None

    keep = np.ones(len(obs), bool)
    sol = run(x_init, sigma_file, keep)
    for _ in range(3):                       # editing: beyond clip x the group's RMS (normalised)
        z = sol.residual / sigma_file
        new_keep = np.ones(len(obs), bool)
        for g in set(groups):
            m = groups == g
            rms = math.sqrt(float(np.mean(z[m & keep] ** 2))) if (m & keep).any() else 0.0
            new_keep[m] = np.abs(z[m]) <= options.clip * max(rms, 1.0)
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
        sol = run(sol.x, sigma_file, keep)
    # noise: the file's sigmas scaled per group by the normalised RMS (when > 1) and sqrt(tau)
    z = sol.residual / sigma_file
    scale = np.ones(len(obs))
    noise = {}
    order = np.argsort(obs["time"].to_numpy(), kind="stable")
    for g in sorted(set(groups)):
        m = (groups == g) & keep
        idx = order[m[order]]
        if idx.size == 0:
            continue
        rms = math.sqrt(float(np.mean(z[idx] ** 2)))
        tau = integrated_autocorrelation_time([z[idx]])
        s = math.sqrt(max(rms, 1.0) ** 2 * tau)
        scale[groups == g] = s
        noise[g] = {"samples": int(idx.size), "rms_over_file_sigma": rms, "autocorrelation_time_samples": tau,
                    "sigma_scale": s}
    sigma_eff = sigma_file * scale
    sol = run(sol.x, sigma_eff, keep)
    # SGP4's own theory error at each pass (a random effect, docs/fit-tle.md "Covariance"): the
    # elements by generalised least squares with it, their covariance, and at a predicted pass
    model_error = model_error_fit(options, sol, model, free, steps, obs, design, keep, sigma_eff, sig,
                               (x_init, prior_cov) if options.apriori else None, observed)
    x_fit = model_error.pop("x")
    conflict = model_error.pop("apriori_conflict")
    try:
        model(x_fit)
    except (ValueError, ArithmeticError, ProcessingError):
        raise ProcessingError("the fit failed: the elements weighed for SGP4's theory error are not an orbit SGP4 "
                              "accepts") from None

    # the TLE as written (fields rounded) and how it fits
    c = tf.classical(x_fit)
    rev0 = int(template.line2[63:68]) if template is not None and template.line2[63:68].strip() else 0
    revolution = rev0 + int(math.floor(n0 * age_days)) if template is not None else 0
    elements = MeanElements(epoch=epoch, inclination_deg=c["inclination_deg"], raan_deg=c["raan_deg"],
                            eccentricity=c["eccentricity"], arg_perigee_deg=c["arg_perigee_deg"],
                            mean_anomaly_deg=c["mean_anomaly_deg"], mean_motion_rev_day=c["mean_motion_rev_day"],
                            bstar=c["bstar"])
    try:
        tle = format_tle(elements, template, satnum=options.satnum, revolution=max(revolution, 0))
    except ValueError as exc:
        raise ProcessingError(f"the fitted elements cannot be written as a TLE: {exc}") from None
    written = tf.elements_of(satrec(tle))

    def chi2_with_nuisance(x):
        """χ² (final weights, kept samples) of elements ``x`` with the nuisance terms refitted."""
        r = observed - model(x)
        w = np.where(keep, 1.0 / sigma_eff, 0.0)
        if design.shape[1]:
            cc = np.linalg.lstsq(design * w[:, None], r * w, rcond=None)[0]
            r = r - design @ cc
        rw = r * w
        return float(rw @ rw), r

    chi2_written, _ = chi2_with_nuisance(written)
    chi2_fitted, resid = chi2_with_nuisance(x_fit)
    chi2_initial, r_initial = chi2_with_nuisance(x_init)

    # the verdict
    q = qm.Quality()
    if options.apriori and options.apriori_model == "tle" and too_old:
        q.add("apriori_model", "ok", f"the initial TLE is {abs(age_days):.3g} days from the epoch, beyond the "
              f"{tf.TLE_APRIORI_MAX_AGE_DAYS:g} days its measured accuracy covers (TLE differencing: its error grows "
              "faster after): refine's looser default a-priori is used", value=abs(age_days),
              limit=tf.TLE_APRIORI_MAX_AGE_DAYS)
    if not sol.converged:
        q.add("not_converged", "rejected", f"the solver did not converge ({sol.message})")
    if conflict is not None and not conflict["directions"]:
        q.add("undetermined", "rejected", "the data determine none of the elements' directions (0 directions seen): "
              "the fit says nothing about the orbit", value=0)
    if conflict is not None:
        # the score test of the a-priori under the fit's own error model (the theory error at each
        # pass included): methods/tle_theory_error.apriori_conflict_chi2; its limit the 99.9 % point of
        # chi2(free elements), conservative when the data see fewer directions
        qm.add_apriori_check(q, conflict["chi2"], sol.n_prior,
                             f"elements (the data see {conflict['directions']} directions)",
                             "the data contradict the initial orbit's a-priori even with SGP4's theory error at each "
                             "pass: the covariance that leans on it does not hold")
    # what the data leave undetermined (only possible without the a-priori): sigmas beyond the
    # default a-priori's, i.e. less than an initial TLE already knows
    loose = {name: float(sol.sigma[k] / math.sqrt(default_cov[k, k])) for k, name in enumerate(tf.ELEMENT_NAMES)
             if free[k] and sol.sigma[k] > 1.01 * math.sqrt(default_cov[k, k])}
    if loose:
        worst_ratio = max(loose.values())
        q.add("undetermined", "rejected" if worst_ratio > 10.0 else "suspect",
              "the data leave " + ", ".join(f"{k} ({v:.3g}x)" for k, v in sorted(loose.items())) + " less well "
              "determined than the default a-priori of an initial TLE: give more passes, or keep the a-priori",
              value=worst_ratio, limit=1.0)
    worst = max(noise.values(), key=lambda v: v["sigma_scale"]) if noise else None
    if worst is not None:
        q.add("noise", "ok", f"file sigmas scaled per pass and kind by up to {worst['sigma_scale']:.3g} (residual "
              f"RMS {worst['rms_over_file_sigma']:.3g} sigma, autocorrelation time "
              f"{worst['autocorrelation_time_samples']:.3g} samples) before the covariance is taken",
              value=worst["sigma_scale"])
    n_edited = int((~keep).sum())
    if n_edited > EDITED_LIMIT * len(obs):
        q.add("edited", "suspect", f"{n_edited} of {len(obs)} samples edited (> 10 %)", value=n_edited,
              limit=EDITED_LIMIT * len(obs))
    # the likelihood-ratio test of the least-squares elements (the weights of the data alone)
    chi2_ls, _ = chi2_with_nuisance(sol.x)
    gain = qm.improvement_test(chi2_initial, chi2_ls, int(free.sum()))
    q.add("improvement", "ok",
          (f"the data move the elements significantly from the initial orbit (chi2 {chi2_initial:.4g} -> "
           f"{chi2_ls:.4g}, limit of the drop {gain['limit']:.3g})") if gain["significant"] else
          (f"the data cannot tell the fitted TLE from the initial orbit (chi2 {chi2_initial:.4g} -> {chi2_ls:.4g}, "
           f"a drop below the 99.9 % point {gain['limit']:.3g}): it is not demonstrably better"),
          value=gain["delta_chi2"], limit=gain["limit"])
    rounding = chi2_written - chi2_fitted
    # the written (rounded) elements inside the fitted elements' 99.9 % confidence region?
    rounding_limit = qm.chi2_limit(int(free.sum()))
    q.add("rounding", "ok" if rounding <= rounding_limit else "suspect",
          f"the written TLE (fields rounded) changes chi2 by {rounding:.3g} (99.9 % limit {rounding_limit:.3g})"
          + ("" if rounding <= rounding_limit else ": the TLE format cannot hold elements as precise as the data "
             "determine them"), value=rounding, limit=rounding_limit)

    # the passes' timing against the initial orbit: what a fit would read as along-track error
    rate = (obs["kind"].isin(["doppler", "range_rate"]) & (obs["station"] != "")).to_numpy()
    shifts = time_shifts(model, x_init, float(steps[5]), groups, rate, np.where(keep, 1.0 / sigma_eff, 0.0), design,
                         observed) if rate.any() else {}
    if shifts:
        v = np.array([t for t, _ in shifts.values()])
        along_s = math.sqrt(prior_cov[5, 5]) / (360.0 * float(x_init[0])) * 86400.0
        half_rev_s = 86400.0 / float(x_init[0]) / 2.0
        worst_shift = float(np.max(np.abs(v))) if np.all(np.isfinite(v)) else math.inf
        if worst_shift > half_rev_s:
            # beyond half a revolution a time shift has no meaning: not this orbit's passes (another
            # object's TLE, wrong station or time tags)
            q.add("timing_mismatch", "rejected", f"a pass's apparent time shift against the initial orbit is "
                  f"{worst_shift:.4g} s, beyond half a revolution ({half_rev_s:.4g} s): the passes do not belong to "
                  "this orbit (another object's TLE? wrong station or time tags?)", value=worst_shift,
                  limit=half_rev_s)
        q.add("timing", "ok", f"the passes' apparent time shifts against the initial orbit (Doppler and range-rate; "
              f"an along-track error of the orbit and the station's time tags look alike): mean {v.mean():.3g} s, "
              f"RMS {np.sqrt(np.mean(v ** 2)):.3g} s over {v.size}; the initial orbit's along-track sigma at the epoch "
              f"is {along_s:.3g} s (docs/fit-tle.md 'A-priori')", value=float(np.sqrt(np.mean(v ** 2))), limit=along_s)
    # per group summaries (the RMS the users quote: after the nuisance terms)
    per_group = _group_summaries(obs, keep, r_initial, resid, nuisance_names, sol, int(free.sum()), shifts, noise)
    cov = model_error.pop("prediction_covariance")
    # does the fit predict better than the initial TLE, both with SGP4's theory error? (refusal)
    a_fit = (MU_WGS72 / (2 * math.pi * float(x_fit[0]) / 86400.0) ** 2) ** (1 / 3)
    span = float(options.prediction_span_days)
    initial_cov = prior_cov + model_error["element_covariance"]
    var_fit = tf.position_variance(cov, float(x_fit[0]), a_fit, float(x_fit[3]), span)
    var_init = tf.position_variance(initial_cov, float(x_init[0]), a_fit, float(x_init[3]), span)
    station = (obs["station"] != "").to_numpy()
    n_passes = len(set((obs["source"].astype(str) + "|" + obs["pass_id"].astype(str))[station]))
    # the chance that the fitted elements predict the position at the horizon better than the
    # initial orbit's, given how far the fit moves that prediction against the fitted elements'
    # own error there (estimation, with the theory error at the fitted passes; the predicted
    # pass's own theory error is the same for both element sets and is left out)
    p_better, moved, moved_sigma = tf.probability_better(x_fit - x_init, model_error["estimation_covariance"],
                                                         float(x_fit[0]), a_fit, float(x_fit[3]), span)
    q.add("prediction", "ok", f"predicted position error {span:g} d after the epoch {math.sqrt(var_fit):.4g} m "
          f"(the initial orbit's {math.sqrt(var_init):.4g} m), SGP4's theory error included; the fit moves that "
          f"prediction by {moved:.4g} m (the fitted elements' error there {moved_sigma:.4g} m 1-sigma): better than "
          f"the initial orbit's with probability {p_better:.3g}", value=math.sqrt(var_fit), limit=math.sqrt(var_init))
    refusal = None
    if options.refusal:
        if n_passes < 2 and not ephemerides:
            refusal = ("single_pass", "one pass cannot separate the along-track drift (mean motion) from that pass's "
                                      "own SGP4 error: the fit cannot be shown to predict better than the initial orbit")
        elif p_better < REFUSAL_PROBABILITY:
            refusal = ("no_predictive_gain", f"the fit moves the predicted position {span:g} d after the epoch by "
                                             f"{moved:.4g} m, against the fitted elements' own {moved_sigma:.4g} m "
                                             f"error there: it predicts better than the initial orbit with probability "
                                             f"{p_better:.3g} only (< {REFUSAL_PROBABILITY:g})")
    if refusal is not None:
        q.add("refused", "suspect", f"the initial orbit is written unchanged: {refusal[1]} (--no-refusal writes "
                                    "the fit)", value=refusal[0])
        fitted_tle = tle
        tle = template if template is not None else format_tle(mean_elements(x_init, epoch), None,
                                                                satnum=options.satnum)
        cov = initial_cov
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    cross = cross_validation(tables, ephemerides, orbit, options, eop, stations, epoch) \
        if options.cross_validate else None
    if cross is not None:
        if cross["ratios"]:
            median = float(np.median(cross["ratios"]))
            q.add("cross_validation", "ok" if median <= 1.0 else "suspect",
                  f"each pass file left out in turn and predicted by a TLE fitted to the others: RMS ratio to the "
                  f"initial orbit's prediction, median {median:.3g} over {len(cross['ratios'])}"
                  + ("" if median <= 1.0 else ": the fitted TLE predicts left-out passes worse than the initial "
                     "orbit"), value=median, limit=1.0)
        else:
            q.add("cross_validation", "ok", cross["note"])
        z = cross.get("rms_normalised_error")
        if z is not None:
            q.add("cross_validation_covariance", "ok" if z <= 2.0 else "suspect",
                  f"left-out passes' orbit errors over the sigma the covariance predicts, RMS {z:.3g}"
                  + (" (consistent: <= 2)" if z <= 2.0 else ": the covariance does not cover the prediction errors "
                     f"on these passes; raise --model-error (about {z:.2g}x)"), value=z, limit=2.0)
    summary = {
        "generator": "trackproc fit-tle",
        "initial": orbit.source,
        "initial_force_model": initial_force,
        "epoch": format_epoch(epoch),
        "initial_age_days": age_days,
        "reepoch_rms_m": reepoch_rms,
        "tle": [tle.line1, tle.line2],
        "name": tle.name,
        "elements": dict(zip(tf.ELEMENT_NAMES, (x_fit if refusal is None else x_init).tolist())),
        "fitted_elements": dict(zip(tf.ELEMENT_NAMES, x_fit.tolist())),
        "least_squares_elements": dict(zip(tf.ELEMENT_NAMES, sol.x.tolist())),
        "refused": None if refusal is None else {"code": refusal[0], "reason": refusal[1],
                                                 "fitted_tle": [fitted_tle.line1, fitted_tle.line2]},
        "prediction": {"span_days": span, "position_sigma_m": math.sqrt(var_fit),
                       "initial_position_sigma_m": math.sqrt(var_init), "change_m": moved,
                       "change_sigma_m": moved_sigma, "probability_better": p_better},
        "sigma": dict(zip(tf.ELEMENT_NAMES, sigma.tolist())),
        "covariance": {"parameters": list(tf.ELEMENT_NAMES), "matrix": cov.tolist(),
                       "note": "n rev/day, ex, ey, angles deg, B* 1/earth radii; the file sigmas scaled per pass "
                               "and kind (noise) before it is taken",
                       "scope": "the error of this TLE's SGP4 prediction at a pass, as element errors at the "
                                "epoch (map it to a pass through SGP4's partials): the estimation error with "
                                "SGP4's theory error at the fitted passes (model_error, estimation_covariance) "
                                "plus that error at the predicted pass (model_error.element_covariance). "
                                "Its scale (model_error) is calibrated on DopTrack Delfi-C3 passes and checked "
                                "up to ~1 day ahead (docs/fit-tle.md)"},
        "model_error": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in model_error.items()
                        if k not in ("estimation_covariance", "covariance_without_model_error")},
        "initial_covariance": initial_cov.tolist(),
        "estimation_covariance": model_error["estimation_covariance"].tolist(),
        "covariance_without_model_error": model_error["covariance_without_model_error"].tolist(),
        "classical": c,
        "initial_elements": dict(zip(tf.ELEMENT_NAMES, x_init.tolist())),
        "fixed": [] if options.fit_bstar else ["bstar"],
        "apriori": {"used": bool(options.apriori), "model": "tle" if use_tle else "refine",
                    "sigma_at_initial_epoch": dict(zip(tf.ELEMENT_NAMES, prior_sig.tolist())),
                    "chi2": None if conflict is None else conflict["chi2"], "elements": sol.n_prior,
                    "directions": None if conflict is None else conflict["directions"],
                    "chi2_definition": "the a-priori conflict test (quality reason apriori_conflict): the data's "
                                       "gradient at the initial elements against its covariance under the fit's "
                                       "error model (SGP4's theory error at each pass included), "
                                       "b^T (A + A P A)^+ b, chi2(directions) when consistent "
                                       "(methods/tle_theory_error.apriori_conflict_chi2)",
                    "least_squares_share": sol.chi2_prior},
        "chi2": {"initial": chi2_initial, "least_squares": chi2_ls, "fitted": chi2_fitted, "written": chi2_written},
        "samples": int(len(obs)), "edited": n_edited, "iterations": sol.iterations, "converged": sol.converged,
        "solver": sol.message,
        "doppler_bias": options.doppler_bias,
        "groups": per_group,
        "quality": q.as_dict(),
    }
    if cross is not None:
        summary["cross_validation"] = cross
    return FitTleResult(tle=tle, summary=summary, quality=q,
                        residuals=_residual_table(obs, observed, resid, sigma_eff, keep))


def _check_options(options: FitTleOptions) -> None:
    """The options fit_tle checks itself (the CLI's choices reach it as text)."""
    if options.doppler_bias not in DOPPLER_BIAS:
        raise InputError("unknown Doppler bias model", column="--doppler-bias", found=options.doppler_bias,
                         expected=", ".join(DOPPLER_BIAS))
    if options.apriori_model not in APRIORI_MODELS:
        raise InputError("unknown a-priori model", column="--apriori-model", found=options.apriori_model,
                         expected=", ".join(APRIORI_MODELS))
    if not options.prediction_span_days > 0:
        raise InputError("the prediction horizon must be positive", column="--horizon",
                         found=f"{options.prediction_span_days:g}", expected="days > 0")


def _group_summaries(obs, keep, r_initial, resid, nuisance_names, sol, n_free: int, shifts: dict,
                     noise: dict) -> list:
    """Per group of samples: counts, the RMS before and after the fit (after the nuisance terms:
    the RMS users quote), the group's nuisance terms and their sigmas, its apparent time shift
    against the initial orbit and its noise scaling."""
    groups = obs["group"].to_numpy()
    per_group = []
    for g in sorted(set(groups)):
        m = groups == g
        mk = m & keep
        entry = {"group": g, "kind": str(obs["kind"][m].iloc[0]), "samples": int(m.sum()),
                 "edited": int((m & ~keep).sum()),
                 "rms_initial": float(np.sqrt(np.mean(r_initial[mk] ** 2))) if mk.any() else None,
                 "rms": float(np.sqrt(np.mean(resid[mk] ** 2))) if mk.any() else None}
        for k, name in enumerate(nuisance_names):
            if name.startswith(g + " "):
                entry[name.rsplit(" ", 1)[1]] = float(sol.nuisance[k])
                entry[name.rsplit(" ", 1)[1] + "_sigma"] = float(math.sqrt(sol.covariance[n_free + k, n_free + k]))
        if g in shifts:
            entry["time_shift_initial_s"], entry["time_shift_initial_sigma_s"] = shifts[g]
        entry.update(noise.get(g, {}))
        per_group.append(entry)
    return per_group


def _residual_table(obs, observed, resid, sigma_eff, keep) -> pd.DataFrame:
    """The residual table of estimate and refine (io.residuals): computed = SGP4 + the nuisance
    terms, sigma = the file's scaled as in the fit."""
    units = {"range": "m", "range_rate": "m/s", "doppler": "Hz", "elevation": "rad", "azimuth": "rad"}
    return pd.DataFrame({"time": pd.to_datetime(obs["time"]).dt.tz_localize("UTC"), "station": obs["station"],
                         "pass_id": obs["pass_id"],
                         "kind": obs["kind"], "unit": obs["kind"].map(units).fillna("m"), "observed": observed,
                         "computed": observed - resid, "residual": resid,
                         "normalized_residual": resid / sigma_eff, "sigma": sigma_eff, "edited": ~keep})
