"""``trackproc fit-tle``: SGP4 mean elements fitted to passes and/or an ephemeris (issue 18 item 3).

Reference behaviour: STRF's ``rffit`` (Doppler curves -> TLE), with this project's honesty rules.

1. **Epoch.** The new TLE's epoch (default: the middle of the last pass) is rounded to what the
   epoch field holds (1e-8 day), so the elements fitted are those written.
2. **Initial elements at that epoch.** The initial orbit (a TLE by SGP4, a state by the J2
   integrator) is sampled every minute over one revolution either side of the epoch and a TLE at
   the epoch is fitted to those GCRF positions (:func:`trackproc.methods.tle_fit.solve`, B* kept):
   it reproduces the initial TLE's own prediction there (metres: same theory).
3. **A-priori.** refine's default element sigmas (:data:`trackproc.pipeline.refine.DEFAULT_APRIORI_ELEMENTS`:
   a 50 m, e 5e-5, i and Ω 1e-4 rad, argument of latitude 4e-4 rad) at the initial TLE's epoch,
   B* ``max(|B*|, 1e-4)``, carried to the new epoch by the along-track drift a mean-motion
   error causes (:func:`trackproc.methods.tle_fit.age_covariance`).
4. **Model.** Each sample predicted by SGP4 -> GCRF and the foundation measurement model
   (:func:`trackproc.pipeline.orbit_source.station_observables`: light time, one- or two-way,
   the model ``compare`` and ``simulate`` use); an ephemeris row gives three position samples.
   Per pass and kind of one-way Doppler or range-rate, the transmitter's offset and drift
   (``--doppler-bias``, default ``offset+drift``: DopTrack's oscillator drifts 0.3-0.7 Hz/s)
   are nuisance parameters, as ``compare`` fits them.
5. **Fit, editing, noise.** Levenberg-Marquardt on the elements and nuisance terms with the
   a-priori; samples beyond ``clip`` times their group's RMS are edited (three rounds). The
   file's sigmas are then scaled per pass and kind by the RMS of the normalised residuals (when
   above 1) and by the square root of their integrated autocorrelation time ``τ`` (a TLE's
   misfit is smooth in time: ``n`` samples hold ``n/τ`` independent ones;
   :func:`trackproc.pipeline.identify.integrated_autocorrelation_time`) and the fit is repeated
   (its covariance, ``covariance_without_model_error``, is the estimation error alone: see 7).
6. **Verdict** (as refine/estimate, :mod:`trackproc.methods.quality`): ``rejected`` when the
   solver does not converge, the data contradict the a-priori (its χ² beyond the 99.9 % point)
   or, without the a-priori, leave an element over 10x less determined than the default
   a-priori (``undetermined``; ``suspect`` beyond 1x),
   ``suspect`` when more than 10 % of the samples are edited or the written TLE (rounded to its
   fields) lies outside the fitted elements' 99.9 % confidence region (χ² up by more than
   the 99.9 % point of χ²(free elements)); ``ok``
   reasons say how the sigmas were scaled and whether the data improve significantly on the
   initial orbit (the likelihood-ratio test :func:`trackproc.methods.quality.improvement_test`).
7. **SGP4's theory error** (:func:`_model_error`): an analytical theory misses a LEO orbit by
   far more than the data's noise, differently at each pass; it is modelled as an independent
   per-pass perturbation of the elements (``--model-error`` times the default a-priori's sigmas,
   a random effect), the elements re-estimated by generalised least squares with it, and the
   written covariance is that of a prediction at a pass (estimation + the pass's own theory
   error). Its default scale is the maximum-likelihood one on the DopTrack development evenings.
8. **Refusal** (``refused``, suspect): one pass (its along-track drift cannot be told from its own
   theory error), or a fit whose predicted position error one day on is not below the initial
   orbit's (both with the theory error): the initial TLE is written unchanged (a state's orbit
   as a TLE at the epoch), with its covariance; ``refused.fitted_tle`` holds the fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import pandas as pd

from trackproc.errors import InputError, ProcessingError

KINDS = ("doppler", "range_rate", "range", "azimuth", "elevation")
DOPPLER_BIAS = ("none", "offset", "offset+drift")
#: B* a-priori 1-sigma floor (1/earth radii): B* of LEO objects varies by this much between TLEs.
BSTAR_SIGMA_FLOOR = 1e-4
#: Sampling of the initial orbit when the elements are moved to the new epoch (s), and its half-span (revolutions).
REEPOCH_STEP_S = 60.0
REEPOCH_HALF_SPAN_REV = 1.0
#: Share of edited samples above which the fit is suspect.
EDITED_LIMIT = 0.10
MU_WGS72 = 398600.8e9


@dataclass
class FitTleOptions:
    """Options of :func:`fit_tle` (defaults = the CLI's)."""

    epoch: Optional[np.datetime64] = None
    fit_bstar: bool = True
    doppler_bias: str = "offset+drift"
    kinds: Optional[list] = None
    earth: str = "wgs84"
    range_rate_model: str = "doppler"
    ephemeris_sigma_m: float = 100.0
    clip: float = 4.0
    max_iterations: int = 30
    satnum: Optional[str] = None
    apriori: bool = True
    cross_validate: bool = False
    #: SGP4's theory error at a pass, in a-priori sigmas; None: tle_fit.MODEL_ERROR_SCALE.
    model_error: Optional[float] = None
    #: Keep the initial TLE when the fit cannot be shown to predict better (``refused``).
    refusal: bool = True
    #: The prediction span (days after the epoch) at which fit and initial orbit are compared.
    prediction_span_days: float = 1.0


@dataclass
class FitTleResult:
    tle: object
    summary: dict
    quality: object
    residuals: pd.DataFrame
    warnings: list = field(default_factory=list)


@dataclass
class _Block:
    """Samples of one station (or one ephemeris) and how to predict them."""

    rows: np.ndarray            # indices into the stacked observation vector
    kind: np.ndarray
    predict: object             # satrec -> predicted values at these rows


def _utc(series) -> np.ndarray:
    return pd.DatetimeIndex(series).tz_convert("UTC").tz_localize(None).as_unit("ns").to_numpy()


def _observations(tables, ephemerides, options, eop, stations):
    """The stacked samples (a DataFrame: time, group, kind, value, sigma, source) and the blocks
    predicting them."""
    from trackproc.models.measurements import station_gcrf
    from trackproc.dynamics.timescales import datetime64_to_jd_utc
    from trackproc.pipeline.orbit_source import Sgp4Track, station_itrf, station_observables

    parts, blocks, offset = [], [], 0
    for source, table in tables:
        frame = table.frame
        if options.kinds:
            frame = frame[frame["kind"].isin(options.kinds)]
        frame = frame[frame["kind"].isin(KINDS)].reset_index(drop=True)
        if len(frame) == 0:
            raise InputError("no samples of a kind fit-tle uses", file=source, column="kind",
                             expected=", ".join(options.kinds or KINDS))
        known = dict(table.stations())
        known.update(stations or {})
        missing = sorted(set(frame["station"]) - set(known))
        if missing:
            raise InputError("station coordinates unknown", file=source, column="station", found=", ".join(missing),
                             expected="stations in the pass file's metadata or --stations STATIONS.csv")
        carrier = table.meta.get("carrier_hz")
        mode = table.meta.get("doppler_mode") or "one-way"
        if (frame["kind"] == "doppler").any() and not carrier:
            raise InputError("Doppler samples without a carrier frequency", file=source, column="carrier_hz",
                             expected="a pass file ingested with --carrier-hz")
        times = _utc(frame["time"])
        for name in sorted(set(frame["station"])):
            sel = np.flatnonzero(frame["station"].to_numpy() == name)
            st = known[name]
            track = Sgp4Track(times[sel], eop)
            view = station_gcrf(station_itrf(st, options.earth), *datetime64_to_jd_utc(times[sel]), eop)
            kinds = frame["kind"].to_numpy()[sel]

            def predict(sat, track=track, view=view, st=st, kinds=kinds, carrier=carrier, mode=mode):
                r, v, a, j = track.rvaj(sat)
                obs = station_observables(r, v, a, j, view, st, carrier_hz=carrier or 1.0, mode=mode,
                                          range_rate_model=options.range_rate_model)
                out = np.empty(kinds.size)
                for kind, values in (("range", obs.range_m), ("range_rate", obs.range_rate_m_s),
                                     ("doppler", obs.doppler_hz), ("elevation", obs.elevation_rad),
                                     ("azimuth", obs.azimuth_rad)):
                    m = kinds == kind
                    out[m] = values[m]
                return out

            blocks.append(_Block(rows=offset + np.arange(sel.size), kind=kinds, predict=predict))
            part = pd.DataFrame({"time": times[sel], "station": name, "pass_id": frame["pass_id"].to_numpy()[sel],
                                 "kind": kinds, "value": frame["value"].to_numpy(float)[sel],
                                 "sigma": frame["sigma"].to_numpy(float)[sel], "source": source,
                                 "one_way": mode == "one-way"})
            parts.append(part)
            offset += sel.size
    for source, eph in ephemerides:
        times = _utc(eph.frame["time"])
        xyz = eph.frame[["x_m", "y_m", "z_m"]].to_numpy(float)
        cols = [c for c in ("sigma_x_m", "sigma_y_m", "sigma_z_m") if c in eph.frame.columns]
        sig = (eph.frame[cols].to_numpy(float) if len(cols) == 3
               else np.full(xyz.shape, float(options.ephemeris_sigma_m)))
        if not np.all(np.isfinite(sig) & (sig > 0)):
            raise InputError("ephemeris sigmas must be positive", file=source, column="sigma_x_m",
                             expected="positive numbers, or no sigma columns (--ephemeris-sigma is used)")
        track = Sgp4Track(times, eop, derivatives=False)

        def predict(sat, track=track):
            return track.states(sat)[:, :3].reshape(-1)

        n = xyz.size
        blocks.append(_Block(rows=offset + np.arange(n), kind=np.repeat(np.array(["position"]), n), predict=predict))
        parts.append(pd.DataFrame({"time": np.repeat(times, 3), "station": "", "pass_id": source,
                                   "kind": np.tile(["x", "y", "z"], len(times)), "value": xyz.reshape(-1),
                                   "sigma": sig.reshape(-1), "source": source, "one_way": False}))
        offset += n
    if not parts:
        raise InputError("nothing to fit", expected="one or more pass files or --ephemeris files")
    obs = pd.concat(parts, ignore_index=True)
    obs["group"] = obs["source"].astype(str) + "|" + obs["pass_id"].astype(str) + "|" + obs["kind"].where(
        ~obs["kind"].isin(["x", "y", "z"]), "position")
    return obs, blocks


def _design(obs: pd.DataFrame, bias: str):
    """Offset (and drift, per s from the group's first sample) columns per pass and kind of
    one-way Doppler and range-rate; their names."""
    columns, names = [], []
    if bias == "none":
        return np.zeros((len(obs), 0)), names
    t_all = (obs["time"] - obs["time"].min()).dt.total_seconds().to_numpy() if len(obs) else np.zeros(0)
    rate = obs["kind"].isin(["doppler", "range_rate"]).to_numpy() & obs["one_way"].to_numpy(bool)
    for group in sorted(set(obs.loc[rate, "group"])):
        m = (obs["group"] == group).to_numpy()
        t = np.where(m, t_all - t_all[m].min(), 0.0)
        columns.append(m.astype(float))
        names.append(f"{group} offset")
        if bias == "offset+drift":
            columns.append(t)
            names.append(f"{group} drift")
    return (np.stack(columns, axis=1) if columns else np.zeros((len(obs), 0))), names


def default_epoch(tables, ephemerides) -> np.datetime64:
    """The middle of the last pass (the last pass id by its first sample), else of the ephemeris."""
    best = None
    for _, table in tables:
        f = table.frame
        for _, g in f.groupby("pass_id", sort=False):
            t = _utc(g["time"])
            if best is None or t.min() > best[0]:
                best = (t.min(), t.max())
    if best is None:
        t = np.concatenate([_utc(e.frame["time"]) for _, e in ephemerides])
        best = (t.min(), t.max())
    return best[0] + (best[1] - best[0]) // 2


def _reepoch(orbit, epoch, template_bstar, eop):
    """Elements at ``epoch`` reproducing the initial orbit there: fitted to its GCRF positions
    every :data:`REEPOCH_STEP_S` over :data:`REEPOCH_HALF_SPAN_REV` revolutions either side."""
    from trackproc.dynamics import kepler
    from trackproc.io.tle import satrec
    from trackproc.methods import tle_fit as tf
    from trackproc.pipeline.orbit_source import Satellite, Sgp4Track, teme_to_gcrf_maps

    force = "sgp4" if orbit.tle is not None else "j2"
    # the initial guess: the osculating elements (TEME) of the initial orbit at the epoch
    probe = Satellite(orbit, force, epoch, -1.0, 1.0, eop)
    x_gcrf = np.concatenate(probe.rvaj([0.0])[:2], axis=1)[0]
    from trackproc.dynamics.timescales import datetime64_to_jd_utc

    jd1, jd2 = datetime64_to_jd_utc(np.asarray([epoch], dtype="datetime64[ns]"))
    m = teme_to_gcrf_maps(jd1, jd2, eop)[0]
    x_teme = np.linalg.solve(m, x_gcrf)
    el = kepler.classical_elements(x_teme[:3], x_teme[3:], MU_WGS72)
    a = float(el["a_m"])
    if not 0.0 < a < 1e9:
        raise InputError("the initial orbit is not a bound Earth orbit", file=orbit.source, found=f"a = {a:.6g} m",
                         expected="a TLE or a state of an Earth satellite")
    period = 2 * math.pi * math.sqrt(a ** 3 / MU_WGS72)
    e, argp = float(el["e"]), el["argp_deg"]
    w = math.radians(argp) if argp is not None else 0.0
    lam = (argp + el["mean_anomaly_deg"]) if argp is not None and el["mean_anomaly_deg"] is not None \
        else float(el["arg_latitude_deg"])
    x0 = np.array([86400.0 / period, e * math.cos(w), e * math.sin(w), float(el["i_deg"]),
                   float(el["raan_deg"] or 0.0), lam, template_bstar])
    if orbit.tle is not None:        # SGP4's own mean elements at the epoch: a closer start
        sat = satrec(orbit.tle)
        sat.sgp4(float(jd1[0]), float(jd2[0]))
        x0[:6] = [sat.nm * tf.REV_DAY_PER_RAD_MIN, sat.em * math.cos(sat.om), sat.em * math.sin(sat.om),
                  sat.im / tf.DEG, sat.Om / tf.DEG, (sat.mm + sat.om) / tf.DEG]
    half = REEPOCH_HALF_SPAN_REV * period
    grid = np.arange(-half, half + REEPOCH_STEP_S / 2, REEPOCH_STEP_S)
    sampler = Satellite(orbit, force, epoch, float(grid[0]), float(grid[-1]), eop)
    truth = sampler.states(grid)[:, :3]
    track = Sgp4Track(sampler.times(grid), eop, derivatives=False)
    ep = tf.Epoch(0, float(jd1[0]), float(jd2[0]))
    sol = tf.solve(lambda x: track.states(tf.satrec_of(x, ep))[:, :3].reshape(-1), x0, truth.reshape(-1),
                   np.ones(truth.size), free=np.r_[np.ones(6, bool), False],
                   steps=np.array([1e-8, 1e-8, 1e-8, 1e-6, 1e-6, 1e-6, 1e-7]), max_iterations=40, tolerance=1e-6)
    if not sol.converged:
        raise ProcessingError(f"the initial orbit could not be expressed as a TLE at the epoch ({sol.message})")
    rms = float(np.sqrt(np.mean(np.sum(sol.residual.reshape(-1, 3) ** 2, axis=1))))
    return sol.x, rms, force


def _mean_elements(x, epoch):
    from trackproc.io.tle import MeanElements
    from trackproc.methods import tle_fit as tf

    c = tf.classical(x)
    return MeanElements(epoch=epoch, inclination_deg=c["inclination_deg"], raan_deg=c["raan_deg"],
                        eccentricity=c["eccentricity"], arg_perigee_deg=c["arg_perigee_deg"],
                        mean_anomaly_deg=c["mean_anomaly_deg"], mean_motion_rev_day=c["mean_motion_rev_day"],
                        bstar=c["bstar"])


def _model_error(options, sol, model, free, steps, obs, design, keep, sigma_eff, apriori_sigmas, prior, observed):
    """SGP4's theory error at each station pass (:func:`trackproc.methods.tle_fit.model_error_covariance`,
    ``options.model_error`` a-priori sigmas), a random effect: the elements by generalised least
    squares that weigh each pass by it (Gauss-Newton steps of
    :func:`~trackproc.methods.tle_fit.mixed_model_step` from the least-squares solution, the
    nuisance terms refitted at each), their estimation covariance, and the prediction covariance
    at a pass (that plus the pass's own theory error). Ephemeris rows carry none (a continuous
    arc, not passes). ``prior`` is ``(mean, covariance)`` or None."""
    from trackproc.methods import tle_fit as tf

    scale = tf.MODEL_ERROR_SCALE if options.model_error is None else float(options.model_error)
    q = tf.model_error_covariance(scale, apriori_sigmas)
    idx = np.flatnonzero(free)
    m = idx.size
    q_free = q[np.ix_(idx, idx)]
    c_fit = sol.covariance[:m, :m]
    station = (obs["station"] != "").to_numpy()
    passes = (obs["source"].astype(str) + "|" + obs["pass_id"].astype(str)).to_numpy()
    groups = [np.flatnonzero((passes == p) & station) for p in sorted(set(passes[station]))]
    other = np.flatnonzero(~station)                 # ephemeris rows: no theory error
    w = np.where(keep, 1.0 / sigma_eff, 0.0)
    if prior is not None:
        p_info = np.linalg.inv(np.asarray(prior[1], float)[np.ix_(idx, idx)])
    else:
        p_info = np.zeros((m, m))
    x, c_est, n_pass = sol.x.copy(), c_fit, 0
    if scale > 0 and groups:
        n_pass = len(groups)
        for _ in range(6):
            r = observed - model(x)
            if design.shape[1]:
                r = r - design @ np.linalg.lstsq(design * w[:, None], r * w, rcond=None)[0]
            jac = tf.jacobian(model, x, free, steps)
            infos = [tf.pass_information(jac[rows], w[rows], design[rows]) for rows in groups]
            grads = [jac[rows].T @ (w[rows] ** 2 * r[rows]) for rows in groups]
            o_info = p_info.copy()
            o_grad = p_info @ ((np.asarray(prior[0], float) - x)[idx]) if prior is not None else np.zeros(m)
            if other.size:
                o_info = o_info + tf.pass_information(jac[other], w[other], design[other])
                o_grad = o_grad + jac[other].T @ (w[other] ** 2 * r[other])
            step, c_est = tf.mixed_model_step(np.zeros(m), c_fit, infos, grads, q_free, o_info, o_grad)
            for _ in range(8):              # halved while SGP4 refuses the elements (far from linear)
                trial = x.copy()
                trial[idx] += step
                try:
                    model(trial)
                    break
                except (ValueError, ArithmeticError, ProcessingError):
                    step = step / 2.0
            else:
                break
            x = trial
            if np.max(np.abs(step) / np.sqrt(np.diag(c_est))) < 0.01:
                break

    def full(block):
        out = np.zeros((7, 7))
        out[np.ix_(idx, idx)] = block
        return out

    return {"scale": scale, "sigma": dict(zip(tf.ELEMENT_NAMES, np.sqrt(np.diag(q)).tolist())),
            "source": "--model-error" if options.model_error is not None else
            "default: calibrated on the DopTrack Delfi-C3 development evenings (docs/fit-tle.md)",
            "passes_with_it": n_pass, "element_covariance": q,
            "estimation_covariance": full(c_est), "covariance_without_model_error": full(c_fit),
            "prediction_covariance": full(c_est) + q, "x": x}


def fit_tle(tables: list, ephemerides: list, orbit, options: FitTleOptions, eop=None,
            stations: Optional[dict] = None) -> FitTleResult:
    """Fit a TLE to ``tables`` (``(source, PassTable)``) and ``ephemerides`` (``(source,
    Ephemeris)``) from ``orbit`` (:class:`~trackproc.pipeline.orbit_source.OrbitInput`)."""
    from trackproc.dynamics.timescales import datetime64_to_jd_utc
    from trackproc.io.statefile import format_epoch
    from trackproc.io.tle import MeanElements, format_tle, round_epoch, satrec, tle_epoch
    from trackproc.methods import quality as qm
    from trackproc.methods import tle_fit as tf
    from trackproc.models.observation import wrap_pi
    from trackproc.pipeline.identify import integrated_autocorrelation_time
    from trackproc.pipeline.refine import DEFAULT_APRIORI_ELEMENTS

    if options.doppler_bias not in DOPPLER_BIAS:
        raise InputError("unknown Doppler bias model", column="--doppler-bias", found=options.doppler_bias,
                         expected=", ".join(DOPPLER_BIAS))
    template = orbit.tle
    epoch = round_epoch(options.epoch if options.epoch is not None else default_epoch(tables, ephemerides))
    obs, blocks = _observations(tables, ephemerides, options, eop, stations)
    design, nuisance_names = _design(obs, options.doppler_bias)
    bstar0 = float(satrec(template).bstar) if template is not None else 0.0
    x_init, reepoch_rms, initial_force = _reepoch(orbit, epoch, bstar0, eop)
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
    prior_cov = tf.age_covariance(sig, age_days)
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
    model_error = _model_error(options, sol, model, free, steps, obs, design, keep, sigma_eff, sig,
                               (x_init, prior_cov) if options.apriori else None, observed)
    x_fit = model_error.pop("x")
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
    if not sol.converged:
        q.add("not_converged", "rejected", f"the solver did not converge ({sol.message})")
    if sol.n_prior:
        limit = qm.chi2_limit(sol.n_prior)
        q.add("apriori_conflict", "ok" if sol.chi2_prior <= limit else "rejected",
              f"a-priori chi2 {sol.chi2_prior:.4g} over {sol.n_prior} elements (99.9 % limit {limit:.3g})"
              + ("" if sol.chi2_prior <= limit else ": the data contradict the initial orbit's a-priori, the "
                 "covariance that leans on it does not hold"), value=sol.chi2_prior, limit=limit)
    # what the data leave undetermined (only possible without the a-priori): sigmas beyond the
    # default a-priori's, i.e. less than an initial TLE already knows
    loose = {name: float(sol.sigma[k] / math.sqrt(prior_cov[k, k]))
             for k, name in enumerate(tf.ELEMENT_NAMES) if free[k] and sol.sigma[k] > 1.01 * math.sqrt(prior_cov[k, k])}
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

    # per group summaries (the RMS the users quote: after the nuisance terms)
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
                entry[name.rsplit(" ", 1)[1] + "_sigma"] = float(math.sqrt(sol.covariance[int(free.sum()) + k,
                                                                                          int(free.sum()) + k]))
        entry.update(noise.get(g, {}))
        per_group.append(entry)
    cov = model_error.pop("prediction_covariance")
    # does the fit predict better than the initial TLE, both with SGP4's theory error? (refusal)
    a_fit = (MU_WGS72 / (2 * math.pi * float(x_fit[0]) / 86400.0) ** 2) ** (1 / 3)
    span = float(options.prediction_span_days)
    initial_cov = prior_cov + model_error["element_covariance"]
    var_fit = tf.position_variance(cov, float(x_fit[0]), a_fit, float(x_fit[3]), span)
    var_init = tf.position_variance(initial_cov, float(x_init[0]), a_fit, float(x_init[3]), span)
    station = (obs["station"] != "").to_numpy()
    n_passes = len(set((obs["source"].astype(str) + "|" + obs["pass_id"].astype(str))[station]))
    q.add("prediction", "ok", f"predicted position error {span:g} d after the epoch {math.sqrt(var_fit):.4g} m "
          f"(the initial orbit's {math.sqrt(var_init):.4g} m), SGP4's theory error included",
          value=math.sqrt(var_fit), limit=math.sqrt(var_init))
    refusal = None
    if options.refusal:
        if n_passes < 2 and not ephemerides:
            refusal = ("single_pass", "one pass cannot separate the along-track drift (mean motion) from that pass's "
                                      "own SGP4 error: the fit cannot be shown to predict better than the initial orbit")
        elif var_fit >= var_init:
            refusal = ("no_predictive_gain", f"the fit's predicted position error {span:g} d after the epoch "
                                             f"({math.sqrt(var_fit):.4g} m) is not below the initial orbit's "
                                             f"({math.sqrt(var_init):.4g} m)")
    if refusal is not None:
        q.add("refused", "suspect", f"the initial orbit is written unchanged: {refusal[1]} (--no-refusal writes "
                                    "the fit)", value=refusal[0])
        fitted_tle = tle
        tle = template if template is not None else format_tle(_mean_elements(x_init, epoch), None,
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
                       "initial_position_sigma_m": math.sqrt(var_init)},
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
        "estimation_covariance": model_error["estimation_covariance"].tolist(),
        "covariance_without_model_error": model_error["covariance_without_model_error"].tolist(),
        "classical": c,
        "initial_elements": dict(zip(tf.ELEMENT_NAMES, x_init.tolist())),
        "fixed": [] if options.fit_bstar else ["bstar"],
        "apriori": {"used": bool(options.apriori), "sigma_at_initial_epoch": dict(zip(tf.ELEMENT_NAMES, sig.tolist())),
                    "chi2": sol.chi2_prior, "elements": sol.n_prior},
        "chi2": {"initial": chi2_initial, "least_squares": chi2_ls, "fitted": chi2_fitted, "written": chi2_written},
        "samples": int(len(obs)), "edited": n_edited, "iterations": sol.iterations, "converged": sol.converged,
        "solver": sol.message,
        "doppler_bias": options.doppler_bias,
        "groups": per_group,
        "quality": q.as_dict(),
    }
    if cross is not None:
        summary["cross_validation"] = cross
    units = {"range": "m", "range_rate": "m/s", "doppler": "Hz", "elevation": "rad", "azimuth": "rad"}
    # the residual table of estimate/refine (io.residuals): computed = SGP4 + the nuisance terms,
    # sigma = the file's scaled as in the fit
    residuals = pd.DataFrame({"time": pd.to_datetime(obs["time"]).dt.tz_localize("UTC"), "station": obs["station"],
                              "pass_id": obs["pass_id"],
                              "kind": obs["kind"], "unit": obs["kind"].map(units).fillna("m"), "observed": observed,
                              "computed": observed - resid, "residual": resid,
                              "normalized_residual": resid / sigma_eff, "sigma": sigma_eff, "edited": ~keep})
    return FitTleResult(tle=tle, summary=summary, quality=q, residuals=residuals)


def cross_validation(tables, ephemerides, orbit, options: FitTleOptions, eop, stations, epoch) -> dict:
    """Prediction skill from the user's own data (``--cross-validate``): each pass file left out
    in turn, the TLE fitted to the others (same epoch and options) predicts it; per pass and kind
    of the left-out file, the RMS after its own offset and drift (``compare``) of that prediction
    and of the initial orbit's, and their ratio. Needs two or more pass files."""
    from dataclasses import replace

    from trackproc.pipeline.compare import CompareOptions, compare
    from trackproc.pipeline.orbit_source import OrbitInput

    if len(tables) < 2:
        return {"passes": [], "ratios": [], "note": "cross-validation needs two or more pass files: the fitted "
                                                    "TLE's prediction skill is unchecked"}
    sub = replace(options, cross_validate=False, epoch=epoch, refusal=False)
    cmp = CompareOptions(remove=options.doppler_bias, earth=options.earth, range_rate_model=options.range_rate_model)
    rows, ratios = [], []
    for k, (source, table) in enumerate(tables):
        others = tables[:k] + tables[k + 1:]
        fitted = fit_tle(others, ephemerides, orbit, sub, eop, stations)
        _, ours = compare(table, OrbitInput(tle=fitted.tle, source="fitted"), cmp, eop, stations)
        _, theirs = compare(table, orbit, cmp, eop, stations)
        # the covariance's check: the prediction's orbit error (its curve against that of a
        # least-squares fit to the left-out file itself) over the spread the covariance predicts
        own = fit_tle([(source, table)], [], orbit, replace(sub, epoch=None, model_error=0.0), eop, stations)
        error = _curve_difference(table, fitted.tle, own.tle, options, eop, stations)
        spread = _prediction_spread(table, fitted, fitted.summary["covariance"]["matrix"], options, eop, stations)
        own_spread = _prediction_spread(table, own, own.summary["covariance"]["matrix"], options, eop, stations)
        for a, b in zip(ours["passes"], theirs["passes"]):
            ratio = a["rms"] / b["rms"] if b["rms"] > 0 else float("nan")
            key = (str(a["pass_id"]), str(a["kind"]))
            sigma = math.hypot(spread.get(key, float("nan")), own_spread.get(key, float("nan")))
            z = error.get(key, float("nan")) / sigma if sigma > 0 else float("nan")
            rows.append({"left_out": source, "pass_id": a["pass_id"], "kind": a["kind"], "unit": a["unit"],
                         "rms_fitted_without_it": a["rms"], "rms_initial": b["rms"], "ratio": ratio,
                         "orbit_error": error.get(key), "predicted_sigma": sigma, "normalised_error": z})
            if math.isfinite(ratio):
                ratios.append(ratio)
    zs = [r["normalised_error"] for r in rows if math.isfinite(r["normalised_error"])]
    return {"passes": rows, "ratios": ratios,
            "rms_normalised_error": float(np.sqrt(np.mean(np.square(zs)))) if zs else None}


def _trend_removed(frame, values, options):
    """``values`` at the rows of a residual ``frame`` with each pass's and kind's offset and drift
    removed (``options.doppler_bias``, one-way Doppler and range-rate only, as the fit does),
    keyed by ``(pass_id, kind)``."""
    t_all = (frame["time"] - frame["time"].min()).dt.total_seconds().to_numpy()
    out = {}
    for (pid, kind), g in frame.groupby(["pass_id", "kind"], sort=False):
        rows = g.index.to_numpy()
        v = np.asarray(values, float)[rows]
        cols = {"none": 0, "offset": 1, "offset+drift": 2}[options.doppler_bias] if kind in ("doppler", "range_rate") \
            else 0
        if cols:
            t = t_all[rows] - t_all[rows].min()
            b = np.stack([np.ones_like(t), t][:cols], axis=1)
            v = v - b @ np.linalg.lstsq(b, v, rcond=None)[0]
        out[(str(pid), str(kind))] = v
    return out


def _curve_difference(table, tle, reference, options, eop, stations) -> dict:
    """RMS per pass and kind of two TLEs' predicted curves' difference, offset and drift removed."""
    from trackproc.pipeline.compare import CompareOptions, compare
    from trackproc.pipeline.orbit_source import OrbitInput

    cmp = CompareOptions(remove="none", earth=options.earth, range_rate_model=options.range_rate_model)
    a, _ = compare(table, OrbitInput(tle=tle), cmp, eop, stations)
    b, _ = compare(table, OrbitInput(tle=reference), cmp, eop, stations)
    a = a.reset_index(drop=True)
    d = _trend_removed(a, a["computed"].to_numpy() - b["computed"].to_numpy(), options)
    return {k: float(np.sqrt(np.mean(v ** 2))) for k, v in d.items()}


def _prediction_spread(table, result, covariance, options, eop, stations) -> dict:
    """RMS per pass and kind of the spread an element covariance (7, 7) of ``result``'s fitted
    elements (written, not refused) predicts for ``table``'s samples, offset and drift removed: the linear map through
    SGP4's partials (central differences), ``sqrt(trace(Π A C Aᵀ Π) / n)``."""
    from trackproc.io.tle import satrec
    from trackproc.methods import tle_fit as tf
    from trackproc.pipeline.compare import CompareOptions, compare
    from trackproc.pipeline.orbit_source import OrbitInput

    x = np.array(list(result.summary["fitted_elements"].values()))      # a fit not refused: its TLE's epoch
    sat = satrec(result.tle)
    ep = tf.Epoch(0, sat.jdsatepoch, sat.jdsatepochF)
    cov = np.asarray(covariance, float)
    cmp = CompareOptions(remove="none", earth=options.earth, range_rate_model=options.range_rate_model)

    def h(xx):
        r, _ = compare(table, OrbitInput(tle=tf.satrec_of(xx, ep)), cmp, eop, stations)
        return r.reset_index(drop=True)

    base = h(x)
    cols = []
    for k in range(7):
        step = 1e-3 * math.sqrt(max(cov[k, k], 0.0))
        if step <= 0:
            cols.append(np.zeros(len(base)))
            continue
        d = np.zeros(7)
        d[k] = step
        cols.append((h(x + d)["computed"].to_numpy() - h(x - d)["computed"].to_numpy()) / (2 * step))
    parts = [_trend_removed(base, c, options) for c in cols]
    out = {}
    for key in parts[0]:
        a = np.stack([p[key] for p in parts], axis=1)
        out[key] = float(np.sqrt(max(np.trace(a @ cov @ a.T), 0.0) / a.shape[0]))
    return out


def summary_text(result: FitTleResult) -> str:
    """The people's summary on stderr."""
    s = result.summary
    c = s["classical"]
    sig = s["sigma"]
    lines = [f"fit-tle: epoch {s['epoch']} ({s['initial_age_days']:+.2f} d from the initial), {s['samples']} samples, "
             f"{s['edited']} edited, {s['iterations']} iterations",
             f"  n {c['mean_motion_rev_day']:.8f} ± {sig['n_rev_per_day']:.2g} rev/day, e {c['eccentricity']:.7f}, "
             f"i {c['inclination_deg']:.4f} ± {sig['i_deg']:.2g} deg, RAAN {c['raan_deg']:.4f} ± "
             f"{sig['raan_deg']:.2g} deg, lambda ± {sig['lambda_deg']:.2g} deg, B* {c['bstar']:.4g} ± {sig['bstar']:.2g}"]
    shown = s["groups"] if len(s["groups"]) <= 12 else s["groups"][:10]
    for g in shown:
        unit = {"doppler": "Hz", "range_rate": "m/s", "range": "m", "azimuth": "rad", "elevation": "rad"}.get(
            g["kind"], "m")
        lines.append(f"  {g['group']}: RMS {g['rms']:.4g} {unit} (initial {g['rms_initial']:.4g}), "
                     f"{g['samples']} samples")
    if len(shown) < len(s["groups"]):
        lines.append(f"  ... {len(s['groups']) - len(shown)} more passes and kinds (--json or --summary FILE)")
    if s.get("refused"):
        lines.append(f"  refused ({s['refused']['code']}): the initial orbit is written; the fit is in the summary "
                     "(refused.fitted_tle)")
    p = s.get("prediction")
    if p:
        lines.append(f"  predicted position error {p['span_days']:g} d on: {p['position_sigma_m']:.4g} m "
                     f"(initial {p['initial_position_sigma_m']:.4g} m; SGP4's theory error included)")
    lines.append("  " + result.quality.text())
    return "\n".join(lines) + "\n"
