"""Assemble a :class:`~trackproc.pipeline.refine.problem.Refinement` from a pass and a stale state
(:func:`prepare`): the options checked, the pass chosen and smoothed, the traverse epoch, the
stale state (a TLE by SGP4 there), the a-priori, the estimator's problem
(:func:`trackproc.pipeline.estimate.build_problem`), the station in the image domain, and for the
integral cost the quadrature of seed 004 eq. 14 (:func:`integral_setup`).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from trackproc.dynamics import geodesy, propagator
from trackproc.dynamics import measurement_spectra as ms
from trackproc.dynamics import timescales as ts
from trackproc.errors import InputError, ProcessingError
from trackproc.io import smoothing_record
from trackproc.io.tle import parse_tle, tle_state
from trackproc.io.validate import stated_carrier
from trackproc.isotime import iso_utc_offset
from trackproc.methods import refinement as rf
from trackproc.methods.least_squares import Prior
from trackproc.models import observation as ob
from trackproc.models.observables import range_rate_per_hz
from trackproc.models import parameters as pm
from trackproc.pipeline.od import EstimateOptions, build_problem
from trackproc.types import PassTable
from trackproc.vocabulary import TAYLOR_FORCES
from trackproc.methods.estimation.prior import (DEFAULT_APRIORI_ELEMENTS, default_apriori_text,  # noqa: F401
                                               tle_along_sigma_m, tle_apriori_covariance)
from trackproc.pipeline.timing import tle_age_days
from trackproc.pipeline.refine.options import (COSTS, DOPPLER_BIAS, NOISE_MODELS,
                                               RefineOptions, SmoothedCurve)
from trackproc.io.tle import is_tle_state
from trackproc.pipeline.refine.problem import Refinement, default_apriori_covariance, link_mode
from trackproc.pipeline.refine.selection import curve_traverse_epoch, select_pass, smoothed_curve


def check_options(opt: RefineOptions) -> None:
    """:class:`InputError` (exit 2) for an option :func:`prepare` cannot take (cost, noise model,
    oscillator noise, covariance, Doppler bias, force model, quadrature settings)."""
    if opt.cost not in COSTS:
        raise InputError("unknown cost", column="--cost", found=opt.cost, expected=" or ".join(COSTS))
    if opt.noise not in NOISE_MODELS:
        raise InputError("unknown noise model", column="--noise", found=opt.noise, expected=", ".join(NOISE_MODELS))
    if opt.oscillator_noise is not None and not (math.isfinite(opt.oscillator_noise) and opt.oscillator_noise > 0):
        raise InputError("the oscillator noise must be positive", column="--oscillator-noise",
                         found=opt.oscillator_noise, expected="a random-walk intensity > 0 in Hz per sqrt(s)")
    if opt.covariance not in ("linear", "profile"):
        raise InputError("unknown covariance", column="--covariance", found=opt.covariance,
                         expected="linear or profile")
    if opt.doppler_bias not in (None,) + DOPPLER_BIAS:
        raise InputError("unknown Doppler bias model", column="--doppler-bias", found=opt.doppler_bias,
                         expected=" or ".join(DOPPLER_BIAS))
    if opt.force not in TAYLOR_FORCES:   # refine's image-domain model runs on the Taylor engine
        raise InputError("unknown force model", column="--force", found=opt.force, expected="two-body or j2")
    if not (opt.quadrature_order >= 2 and opt.quadrature_panel_s > 0 and opt.max_gap_s > 0):
        raise InputError("bad quadrature settings", column="--quadrature-order",
                         found=(opt.quadrature_order, opt.quadrature_panel_s, opt.max_gap_s),
                         expected="order >= 2, panel > 0 s, gap > 0 s")


def apriori_choice(opt: RefineOptions, initial) -> tuple[dict, bool, str, str]:
    """Which a-priori the refinement takes: ``(apriori_sigma, apriori_initial, note, source)``:
    ``--apriori-sigma``, else the stale state's covariance, else a TLE's accuracy at its age
    (:func:`~trackproc.methods.estimation.prior.tle_apriori_covariance`; these three are *stated*),
    else the documented default element sigmas (:data:`DEFAULT_APRIORI_ELEMENTS`, source
    ``default``); none for ``--no-apriori`` (the integral cost's default; source ``""``).
    ``source`` ``"tle"`` asks :func:`prepare` for the TLE's a-priori (a stated one)."""
    use_apriori = opt.apriori if opt.apriori is not None else (opt.cost == "pointwise")
    apriori_sigma, apriori_initial, note, source = {}, False, "none (the pass alone)", ""
    if use_apriori:
        if opt.apriori_sigma:
            apriori_sigma, note, source = dict(opt.apriori_sigma), "--apriori-sigma", "stated"
        elif initial.state_covariance is not None:
            apriori_initial, source = True, "stated"
            note = "the stale state's covariance, moved to the traverse epoch by the STM"
        elif is_tle_state(initial):
            source = "tle"
            note = "the TLE's accuracy at its age (TLE differencing)"
        else:
            source = "default"
            note = "default (the stale state has no covariance): " + default_apriori_text()
    elif opt.apriori_sigma:
        raise InputError("--apriori-sigma with --no-apriori", column="--apriori-sigma",
                         expected="one of the two")
    return apriori_sigma, apriori_initial, note, source


def _station_model(problem, st, station: str, opt: RefineOptions, eop, like: Optional[Refinement]):
    """The :class:`~trackproc.dynamics.measurement_spectra.StationModel` of ``station`` (``st``) over the
    pass's samples (±60 s) at ``problem``'s epoch: ``like``'s when it is of the same site, epoch,
    Earth model and samples (:func:`prepare`'s re-solves), else built."""
    t_meas = problem.meas.t_s
    if (like is not None and like.station_name == station and like.problem.epoch == problem.epoch
            and like.problem.eop is eop and like.options.earth == opt.earth
            and np.array_equal(like.problem.meas.t_s, t_meas)):
        return like.station_model
    lat, lon, r_itrf = geodesy.station_itrf(st, opt.earth)
    epoch_jd = tuple(float(a) for a in ts.datetime64_to_jd_utc(problem.epoch))
    return ms.StationModel.build(r_itrf, lat, lon, epoch_jd, problem.frame.q, float(t_meas.min()) - 60.0,
                                 float(t_meas.max()) + 60.0, eop=eop)


def prepare(table: PassTable, initial, stations=None, options: RefineOptions | None = None, eop=None,
            source: str = "<pass>", curve: Optional[SmoothedCurve] = None, like: Optional[Refinement] = None
            ) -> Refinement:
    """Assemble a :class:`Refinement` (see the module docstring); :class:`InputError` for bad input.
    ``curve``: the pass's smoothed curve when already made (:func:`refine`'s re-solves); ``like``:
    the refinement of the same pass, stations and Earth model prepared before (those re-solves):
    its stations' geometry at the samples, and its station model at the same epoch, are reused."""
    opt = options or RefineOptions()
    check_options(opt)
    warnings: list = []
    sub, kind, station, pass_id = select_pass(table, opt, source)
    meta = sub.meta
    if opt.cost == "pointwise" and smoothing_record.output_of(meta) == "grid":
        raise InputError("a smoothed grid is a curve, not samples", file=source, column="smoothing",
                         found="output = grid",
                         expected="the samples (smooth without --grid), or --cost integral")
    carrier = stated_carrier(meta, file=source, needed=kind == "doppler")
    # a coherent two-way link returns the ground station's own frequency: no transmitter offset
    one_way = (meta.get("doppler_mode") or "one-way") == "one-way"
    bias = opt.doppler_bias if opt.doppler_bias is not None else ("offset" if kind == "doppler" and one_way else "none")
    if bias != "none" and kind == "range_rate" and not carrier > 0:
        raise InputError("a Doppler offset on range-rate samples needs the carrier frequency", file=source,
                         column="carrier_hz", found=meta.get("carrier_hz"),
                         expected="carrier_hz in the metadata, or --doppler-bias none")
    sig = np.asarray(sub.column("sigma"), float)
    if not np.all(np.isfinite(sig) & (sig > 0)):
        i = int(np.flatnonzero(~(np.isfinite(sig) & (sig > 0)))[0])
        raise InputError(f"invalid sigma at {iso_utc_offset(sub.column('time')[i])} (sample {i + 1} of the "
                         "pass)", file=source, column="sigma", found=sig[i], expected="a positive number")
    if sub.n_rows < 8:
        raise ProcessingError(f"too few samples in the pass: {sub.n_rows} (at least 8 are needed)")

    curve = curve if curve is not None else smoothed_curve(sub, kind, station, pass_id, source)
    t_traverse, how = curve_traverse_epoch(curve, warnings, opt.traverse_epoch)

    # the stale state: a TLE is evaluated by SGP4 at the traverse epoch
    if is_tle_state(initial):
        lines = initial.extra["tle"]
        tle = parse_tle("\n".join(([initial.extra["tle_name"]] if initial.extra.get("tle_name") else []) + list(lines)),
                        initial.source or "<tle>")
        initial = tle_state(tle, at=t_traverse, eop=eop)
        warnings.append("the TLE is evaluated by SGP4 at the traverse epoch: the stale epoch is the traverse epoch")
    stale_epoch = np.datetime64(initial.epoch, "ns")

    apriori_sigma, apriori_initial, note, source = apriori_choice(opt, initial)
    est = EstimateOptions(doppler_bias=None if bias == "none" else bias, doppler_bias_per="pass",
                          apriori_sigma=apriori_sigma, apriori_initial=apriori_initial, force=opt.force,
                          earth=opt.earth, range_rate_model=opt.range_rate_model, max_iterations=opt.max_iterations,
                          clip=opt.clip, epoch=t_traverse, kinds=[kind], modifiers=opt.modifiers,
                          oscillator_noise=opt.oscillator_noise)
    problem = build_problem([(source, sub)], initial, stations, est, eop,
                            like=like.problem if like is not None else None)
    mu = propagator.force_parameters(opt.force)[0]
    if source == "default":
        rv0 = problem.x0[:6]
        problem.priors.append(Prior(np.arange(6), rv0.copy(), default_apriori_covariance(rv0, mu)))
    elif source == "tle":
        # a TLE's accuracy is known (TLE differencing): a stated a-priori, looser with the TLE's age
        rv0 = problem.x0[:6]
        age = tle_age_days(initial, t_traverse) or 0.0
        problem.priors.append(Prior(np.arange(6), rv0.copy(), tle_apriori_covariance(rv0, mu, age)))
        note = (f"the TLE's accuracy {age:.2g} days from its epoch (TLE differencing: along-track "
                f"{tle_along_sigma_m(age):.0f} m)")
        source = "stated"

    names = list(problem.names)
    x0 = problem.x0.copy()
    scales = problem.params.scales()
    if opt.circular:                 # the constraints' own driver, r_ka (seed 004 eq. 5), after the problem's
        rka = pm.orbit_radius(float(np.linalg.norm(x0[:3])), scale=float(scales[0]))
        names.append(rka.name)
        x0 = np.r_[x0, rka.reference]
        scales = np.r_[scales, rka.scale]

    # the station in the image domain (seed 004 eqs. 7-10), for the integral and the model traverse time
    known = dict(stations or {})
    for n_, s_ in sub.stations().items():
        known.setdefault(n_, s_)
    st = known[station]
    station_model = _station_model(problem, st, station, opt, eop, like)

    # the station's geocentric axis at the traverse epoch (GCRF): the single-pass rotation family
    r_st0, _ = station_model.state(np.array([0.0]))
    axis = problem.frame.q.T @ r_st0[0]
    ref = Refinement(options=opt, problem=problem, curve=curve, kind=kind, station_name=station, pass_id=pass_id,
                     initial=initial, stale_epoch=stale_epoch, traverse_how=how, names=names, x0=x0, scales=scales,
                     priors=list(problem.priors), apriori_note=note, apriori_source=source,
                     station_model=station_model, mu=mu,
                     carrier_hz=carrier, station_axis=axis / np.linalg.norm(axis), warnings=warnings,
                     station_time_sigma_s=getattr(st, "time_sigma_s", None))
    if opt.cost == "integral":
        ref.integral = integral_setup(ref, sub)
    return ref


def integral_setup(ref: Refinement, table: PassTable) -> dict:
    """Gauss-Legendre nodes on the covered parts of the pass, the curve there (range-rate), the
    pseudo-sigmas, the bias coefficients and the basis (for the sandwich covariance). Implements
    seed 004 eq. 14 (the integral cost, by quadrature on the smoothed curve)."""
    opt = ref.options
    curve = ref.curve
    intervals = rf.covered_intervals(curve.used_t_s, opt.max_gap_s)
    if not intervals:
        raise ProcessingError("the smoothed pass has no interval without gaps to integrate over")
    t_poly, w = rf.gauss_legendre(intervals, order=opt.quadrature_order, panel_s=opt.quadrature_panel_s)
    # node times: polynomial time (s from the curve's epoch) -> s from the traverse epoch (SI)
    jd_c = ts.datetime64_to_jd_utc(curve.epoch)
    jd_e = tuple(float(a) for a in ts.datetime64_to_jd_utc(ref.problem.epoch))
    offset = float(ts.seconds_since(jd_c, jd_e))
    t_nodes = t_poly + offset
    # Doppler -> range-rate: -c Δf/f one-way, -c Δf/(2f) two-way (seed 004: Vr = c/(2 f0) f_D)
    mode = link_mode(ref)
    to_rr = range_rate_per_hz(ref.carrier_hz, mode == "two-way") if ref.kind == "doppler" else 1.0
    observed = to_rr * curve.fit(t_poly)
    design = to_rr * curve.fit.design(t_poly)
    sig = np.asarray(table.column("sigma"), float) * abs(to_rr)
    n_used = curve.used_t_s.size
    covered = float(sum(b - a for a, b in intervals))
    spacing = covered / max(n_used - len(intervals), 1)
    sigma_ref = float(np.sqrt(np.mean(sig * sig)))
    vf_curve = float(curve.fit.variance_factor)
    if opt.reweight and math.isfinite(vf_curve) and vf_curve > 1.0:
        sigma_ref *= math.sqrt(vf_curve)           # the samples' actual scatter about the curve
    sigma_nodes = rf.pseudo_sigma(w, sigma_ref, spacing)
    bias_cols = node_bias_columns(ref, t_nodes, mode)
    model = rf.IntegralModel(ref.problem.epoch, ref.problem.frame, ref.station_model, t_nodes, bias_cols,
                             force=opt.force, eop=ref.problem.eop, range_rate_model=ref.problem.range_rate_model,
                             n_extra=1 if opt.circular else 0, mode=mode)
    return {"model": model, "observed": observed, "sigma": sigma_nodes, "weights": w, "t_nodes": t_nodes,
            "t_poly": t_poly, "design": design, "coefficient_covariance": curve.fit.cov_scaled,
            "intervals": intervals, "sigma_ref": sigma_ref, "spacing": spacing, "to_range_rate": to_rr,
            "mode": mode}


def node_bias_columns(ref: Refinement, t_nodes, mode: str) -> list:
    """The partials of the curve's range-rate at the nodes with respect to the problem's
    non-state drivers, in their order: each measurement modifier of the problem bound to the
    nodes as range-rate samples of the pass's station, pass and link (a Doppler offset becomes
    ``-c/f`` one-way, ``-c/(2f)`` two-way; a drift that times ``t - t0``), as the estimator's own
    model does on samples. :class:`ProcessingError` for a driver no modifier sets at the nodes."""
    k = t_nodes.size
    nodes = ob.MeasurementSet(t_s=np.asarray(t_nodes, float), kind=["range_rate"] * k, station=[ref.station_name] * k,
                              pass_id=[ref.pass_id] * k, observed=np.zeros(k), sigma=np.ones(k), r_st=np.zeros((k, 3)),
                              v_st=np.zeros((k, 3)), carrier_hz=ref.carrier_hz, mode=mode)
    columns = {}
    for bound in ref.problem.modifiers:
        mod = bound.modifier
        if not mod.parameter_drivers():
            continue                                   # a known correction or the oscillator's wander
        try:
            at_nodes = mod.bind(nodes)
        except ValueError:
            continue                                   # acts on no node: reported below if estimated
        for j, name in enumerate(at_nodes.names):
            columns[name] = at_nodes.coefficients(j)
    out = []
    for name in ref.problem.names[6:]:
        if name not in columns:
            raise ProcessingError(f"parameter {name} has no meaning for the integral cost")
        out.append(columns[name])
    return out
