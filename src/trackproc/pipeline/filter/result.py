"""The result of ``trackproc filter``: :func:`filter_passes` (problem, carried state, run, verdict,
outputs) and what it returns (:class:`FilterResult`: the state file, the innovation table, the
history of states; the tables themselves are built in :mod:`trackproc.pipeline.filter.history`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from trackproc.dynamics import propagator
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.rtn import rtn_covariance
from trackproc.errors import InputError, ProcessingError
from trackproc.io.statefile import State, format_epoch
from trackproc.methods import quality as qm
from trackproc.methods import sequential as sq
from trackproc.pipeline.filter import noise as fn
from trackproc.pipeline.filter import policy as fp
from trackproc.pipeline.filter import run as fr
from trackproc.pipeline.filter.history import (history_frame, history_oem, innovation_frame, sigma_rtn_frame,
                                               utc_of_step)
from trackproc.pipeline.filter.options import FilterOptions, check_filter_options
from trackproc.pipeline.od import Problem, build_problem
from trackproc.pipeline.od.state import sigma_rtn, solution_state

@dataclass
class FilterResult:
    """``state`` (the state file), ``problem``, ``sweep`` (:class:`~trackproc.pipeline.filter.run.Sweep`),
    ``innovations`` (one row per sample: :data:`~trackproc.pipeline.filter.history.INNOVATION_COLUMNS`, plus ``smoothed_residual``
    with the smoother), ``quality`` (:class:`~trackproc.methods.quality.Quality`), ``warnings``,
    ``skipped`` (passes older than a carried state's last measurement)."""

    state: State
    problem: Problem
    sweep: object
    innovations: pd.DataFrame
    quality: object
    warnings: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    iterations: list = field(default_factory=list)

    def history(self) -> pd.DataFrame:
        """Every filtered (and smoothed) state with its sigma and covariance (lower triangle), one
        row per step and solution (:func:`history_frame`)."""
        return history_frame(self.problem, self.sweep)

    def sigma_history(self) -> pd.DataFrame:
        """The 1-sigma position and velocity along radial, along-track, cross-track at every step
        and solution (:func:`sigma_rtn_frame`): the data of ``--plot``'s sigma panel."""
        return sigma_rtn_frame(self.problem, self.sweep)

    def history_oem(self, **oem_kwargs) -> str:
        """The history as CCSDS OEM KVN (:func:`history_oem`)."""
        return history_oem(self.problem, self.sweep, self.state, **oem_kwargs)


def carried_last_measurement(initial):
    """The last measurement time (UTC datetime64) a previous ``filter`` run's state carries, or None."""
    rec = (getattr(initial, "extra", None) or {}).get("filter")
    if not isinstance(rec, dict) or not rec.get("last_measurement"):
        return None
    from trackproc.io.statefile import parse_epoch

    return parse_epoch(str(rec["last_measurement"]), column="filter.last_measurement")


def declined_in_a_row(carried, decision) -> int:
    """How many runs in a row, this one included, declined the state they carried (0 when this
    run's decision is not ``declined``): a chain of nights that each decline the carried state is
    more likely held by an overconfident carried state than contradicted by every night's data."""
    if not decision or decision.get("action") != "declined":
        return 0
    rec = (getattr(carried, "extra", None) or {}).get("filter") if carried is not None else None
    before = rec.get("declined_in_a_row", 0) if isinstance(rec, dict) else 0
    return (int(before) if isinstance(before, (int, float)) and before >= 0 else 0) + 1


def skip_older(tables, last):
    """Drop the samples at or before ``last`` (a carried state's last measurement). Returns
    ``(tables, skipped pass names)``; a pass partly older keeps its newer samples."""
    from trackproc.io.passfile import PassTable

    out, skipped = [], []
    stamp = pd.Timestamp(last).tz_localize("UTC")
    for source, t in tables:
        f = t.frame
        keep = (f["time"] > stamp).to_numpy()
        old = f.loc[~keep, ["station", "pass_id"]].astype(str).drop_duplicates()
        newer = set(map(tuple, f.loc[keep, ["station", "pass_id"]].astype(str).to_numpy().tolist()))
        skipped += [f"{s}/{p}" for s, p in old.to_numpy().tolist() if (s, p) not in newer]
        if keep.any():
            out.append((source, PassTable(f[keep].reset_index(drop=True), t.meta)))
    return out, sorted(set(skipped))


def _extended_stm(traj, dt, n):
    top = traj.stm(np.array([dt]))[0]
    if traj.force_parameter_names:
        top = np.concatenate([top, traj.parameter_partials(np.array([dt]))[0]], -1)
    out = np.eye(n)
    out[:6, :top.shape[-1]] = top
    return out


def move(problem: Problem, opt: FilterOptions, x, p, epoch, to_epoch):
    """A state and its covariance from ``epoch`` to ``to_epoch`` (UTC datetime64) through the
    problem's force model and transition, with the process noise over the interval when forward
    (a prediction; the Gauss–Markov states decaying, :func:`~trackproc.pipeline.filter.run.gm_transition`);
    a backward move is the deterministic one (Gauss–Markov states held)."""
    dt = float(ts.seconds_since(ts.datetime64_to_jd_utc(to_epoch), ts.datetime64_to_jd_utc(epoch)))
    if dt == 0.0:
        return x, p
    n = x.size
    gm = fn.gauss_markov(problem, opt) if dt > 0 else {}
    xz = np.array(x, float)
    xz[sorted(gm)] = 0.0                  # propagated about the Gauss-Markov states' zero mean
    traj = propagator.propagate(x[:3], x[3:6], epoch, [dt], force=problem.force, stm=True, eop=problem.eop,
                                force_model=problem.force_model_at(xz)).raise_for_outcome()
    psi = _extended_stm(traj, dt, n)
    if gm:
        fn.gm_transition(psi, dt, gm)
    x2 = xz.copy()
    x2[:6] = traj.state(dt)
    x2 = x2 + psi @ (x - xz)
    p2 = psi @ p @ psi.T
    scales = problem.params.scales()
    q = fn.process_noise(problem, opt, dt, x, scales, gm) if dt > 0 else None
    if q is not None:
        p2 = p2 + q * np.outer(scales, scales)
    return x2, 0.5 * (p2 + p2.T)


def filter_quality(problem: Problem, sw, iterations: list, opt: FilterOptions):
    """The verdict: the normalised innovations squared over the run against χ²(kept samples)
    (:func:`~trackproc.methods.sequential.nis_test`, 99.9 % two-sided: above, the filter
    diverges or its noise models are optimistic; below, its process noise or the samples'
    sigmas are too large), the share of edited samples, the whiteness of each pass's normalised
    innovations, McReynolds' filter-smoother test with the smoother, and the iterations'
    convergence."""
    q = qm.Quality()
    kept = ~sw.edited
    z = sw.innovation / np.sqrt(sw.variance)
    chi2, dof = float(np.sum(z[kept] ** 2)), int(kept.sum())
    if dof:
        lo, hi = sq.nis_test(chi2, dof)
        said = f"normalised innovations squared {chi2:.5g} over {dof} samples (99.9 % band {lo:.5g}-{hi:.5g})"
        if chi2 > hi:
            q.add("innovations", "suspect", f"the filter diverges or its noise models are optimistic: {said}; "
                  "add process noise (--snc-accel) or check the data's sigmas", value=chi2 / dof, limit=hi / dof)
        elif chi2 < lo:
            q.add("innovations", "suspect", f"innovations smaller than their predicted variance: {said}; the "
                  "process noise or the samples' sigmas are too large", value=chi2 / dof, limit=lo / dof)
        else:
            q.add("innovations", "ok", f"innovations consistent: {said}", value=chi2 / dof, limit=hi / dof)
    n_edit = int(sw.edited.sum())
    if sw.edited.size and n_edit > 0.5 * sw.edited.size:
        q.add("edited", "rejected", f"{n_edit} of {sw.edited.size} samples edited beyond {opt.edit_sigma} sigma: "
              "the filter has diverged", value=n_edit / sw.edited.size, limit=0.5)
    elif sw.edited.size and n_edit > 0.1 * sw.edited.size:
        q.add("edited", "suspect", f"{n_edit} of {sw.edited.size} samples edited beyond {opt.edit_sigma} sigma",
              value=n_edit / sw.edited.size, limit=0.1)
    meas = problem.meas
    station, pass_id, kind = meas.station.astype(str), meas.pass_id.astype(str), meas.kind.astype(str)
    passes = []
    for key in sorted(set(zip(station, pass_id, kind))):
        idx = np.flatnonzero(kept & (station == key[0]) & (pass_id == key[1]) & (kind == key[2]))
        idx = idx[np.argsort(meas.t_s[idx], kind="stable")]
        if idx.size:
            passes.append({"pass": f"{key[0]}/{key[1]} {key[2]}", "whiteness": qm.whiteness(z[idx])})
    qm.add_whiteness_family(q, passes)
    if sw.x_s is not None and sw.t_s.size > 1:
        stat = sq.mcreynolds(sw.x_f, sw.p_f, sw.x_s, sw.p_s)
        finite = np.isfinite(stat)
        if finite.any():
            limit = qm.whiteness_family_limit(int(finite.sum()))
            worst = np.unravel_index(np.nanargmax(np.abs(stat)), stat.shape)
            value = float(abs(stat[worst]))
            name = problem.names[worst[1]]
            when = format_epoch(utc_of_step(problem, sw, int(worst[0])))
            said = (f"worst {name} at {when}: |smoothed - filtered| / sqrt(P_f - P_s) = {value:.3g}, limit "
                    f"{limit:.3g} (99.9 % for the worst of {int(finite.sum())})")
            q.add("filter_smoother", "suspect" if value > limit else "ok",
                  (f"the smoother disagrees with the filter beyond their covariances (McReynolds): {said}: "
                   "unmodelled dynamics or a bias the process noise does not cover") if value > limit else
                  f"filter and smoother consistent (McReynolds): {said}", value=value, limit=limit)
    if iterations and opt.iterations > 1 and len(iterations) == opt.iterations - 1 \
            and iterations[-1]["max_change_sigma"] > 0.01:
        q.add("iterations", "suspect", f"the iterated filter had not converged after {opt.iterations} sweeps "
              f"(last change {iterations[-1]['max_change_sigma']:.3g} sigma)",
              value=iterations[-1]["max_change_sigma"], limit=0.01)
    return q


def _output(problem: Problem, opt: FilterOptions, sw):
    """``(x, P, epoch)`` written from a sweep: the smoothed (with ``--smooth``) or filtered state of
    the last step at or before the output epoch, moved there through the force model."""
    which = "s" if opt.smooth else "f"
    if opt.output_epoch is None:
        k = sw.epoch_step if opt.smooth else sw.t_s.size - 1
        x, p = sw.absolute(which, k)
        return x, p, utc_of_step(problem, sw, k)
    out_epoch = np.datetime64(opt.output_epoch, "ns")
    t_out = float(ts.seconds_since(ts.datetime64_to_jd_utc(out_epoch), ts.datetime64_to_jd_utc(problem.epoch)))
    k = max(int(np.searchsorted(sw.t_s, t_out, side="right")) - 1, 0)
    x, p = sw.absolute(which, k)
    x, p = move(problem, opt, x, p, utc_of_step(problem, sw, k), out_epoch)
    return x, p, out_epoch


def run_record(problem: Problem, opt: FilterOptions, sw, iterations: list, noise, skipped: list, carried: bool,
               in_a_row: int) -> dict:
    """The state file's ``filter`` record of a run (docs/filter.md, "Output"): method, process
    noise, editing, counts, times, the NIS, skipped passes, whether a state was carried and the
    runs in a row that declined it."""
    kept = ~sw.edited
    z = sw.innovation / np.sqrt(sw.variance)
    last_time = problem.times.max()
    return {
        "method": "extended Kalman filter (Joseph form, sequential scalar updates), reference trajectory restarted "
                  "at each tracking segment" + (", Rauch-Tung-Striebel smoother" if opt.smooth else ""),
        "solution": "smoothed" if opt.smooth else "filtered",
        "process_noise": {"snc_accel_rtn_m_s2_sqrt_hz": [float(a) for a in opt.snc_accel],
                          "bias_walk_per_sqrt_s": {k2: float(v) for k2, v in opt.bias_walk.items()},
                          **({"dmc_sigma_rtn_m_s2": [float(a) for a in opt.dmc[:3]], "dmc_tau_s": float(opt.dmc[3])}
                             if opt.dmc is not None else {}),
                          **({"bias_gauss_markov": {k2: {"sigma": float(v[0]), "tau_s": float(v[1])}
                                                    for k2, v in opt.bias_gm.items()}} if opt.bias_gm else {}),
                          **({"bias_reset_per_pass": list(opt.bias_reset)} if opt.bias_reset else {}),
                          **({"pass_noise_walk_per_sqrt_s": dict(noise.walk)} if noise is not None and noise.walk else {})},
        "noise": opt.problem.noise,
        "edit_sigma": opt.edit_sigma, "segment_gap_s": opt.segment_gap_s,
        "updates": int(kept.sum()), "edited": int(sw.edited.sum()), "steps": int(sw.t_s.size),
        "segments": len(sw.segments), "sweeps": len(iterations) + 1, "iterations": iterations,
        "first_time": format_epoch(utc_of_step(problem, sw, 0)),
        "apriori_epoch": format_epoch(problem.epoch), "last_measurement": format_epoch(last_time),
        "nis": float(np.sum(z[kept] ** 2)), "nis_dof": int(kept.sum()),
        "skipped_passes": skipped, "carried_state": carried, "declined_in_a_row": in_a_row,
    }


def filter_passes(tables, initial, stations=None, options: FilterOptions | None = None, eop=None) -> FilterResult:
    """Filter (and smooth) the passes from the initial state (see :mod:`trackproc.pipeline.filter`).

    Raises :class:`InputError` (exit 2) for invalid input and :class:`ProcessingError` (exit 1)
    when nothing is left to filter or the reference trajectory fails."""
    opt = options or FilterOptions()
    check_filter_options(opt)
    warnings, skipped = [], []
    last = carried_last_measurement(initial)
    carried = None
    if last is not None:
        tables, skipped = skip_older(tables, last)
        if skipped:
            warnings.append(f"skipped {len(skipped)} pass(es) not newer than the carried state's last measurement "
                            f"{format_epoch(last)}: {', '.join(skipped)}")
        if not tables:
            raise ProcessingError(f"no samples after the carried state's last measurement {format_epoch(last)}")
        carried = initial
    popt = opt.problem
    epoch = popt.epoch
    apriori_initial = popt.apriori_initial
    if apriori_initial is None and initial.state_covariance is not None and not any(
            k in popt.apriori_sigma for k in ("x", "y", "z", "vx", "vy", "vz", "position", "velocity", "state")):
        apriori_initial = True
    from dataclasses import replace

    popt = replace(popt, epoch=epoch, apriori_initial=apriori_initial)
    problem = build_problem(tables, initial, stations, popt, eop)
    if carried is not None and np.datetime64(problem.epoch, "ns") != np.datetime64(initial.epoch, "ns"):
        carried = None
    noise = fr.fitted_noise(problem, opt, carried)

    def solve(state_scale: float = 1.0) -> fp.Candidate:
        # one run (its state a-priori scaled by ``state_scale``), its output and the output moved
        # back to the prior's epoch, where the a-priori test is made
        sw, iterations = fr.run(problem, opt, carried, noise, state_scale=state_scale)
        x, p, at = _output(problem, opt, sw)
        back_x, back_p = move(problem, opt, x, p, at, problem.epoch)
        return fp.Candidate(x, p, at, back_x, back_p, filter_quality(problem, sw, iterations, opt), sw, iterations)

    first = solve()
    out_epoch = first.epoch
    # the shared prior-and-decline policy (pipeline/filter/policy.py): the filter's start moved to
    # the output epoch by its own time update without data; the a-priori test where the prior is
    # stated, on the solution moved there (a loose prior's covariance is not mapped over the arc)
    start_x, start_p = fr.initial_covariance(problem, carried, fn.gauss_markov(problem, opt))
    prior_x, prior_p = move(problem, opt, start_x, start_p, problem.epoch, out_epoch)
    prior_back_p = move(problem, opt, prior_x, prior_p, out_epoch, problem.epoch)[1]
    outcome = fp.decide(problem, first, fp.PriorAt(prior_x, prior_p, start_x, prior_back_p), out_epoch, solve,
                        popt.horizon_days, popt.allow_keep)
    chosen = outcome.candidate
    sw, iterations, quality = chosen.sweep, chosen.iterations, chosen.quality
    fp.add_reasons(quality, outcome, problem.apriori_source)
    in_a_row = declined_in_a_row(initial, outcome.decision)
    if in_a_row > 1:
        for r in quality.reasons:
            if r["code"] == "declined":
                r["message"] += (f"; the carried state has now been declined {in_a_row} runs in a row: the carried "
                                 "state (an overconfident covariance), not each night's data, may be what is wrong: "
                                 "restart from a fresh orbit (--initial TLE) or carry it with process noise "
                                 "(--snc-accel)")
    x, p = outcome.x, outcome.p
    problem.decision = outcome.decision
    names = problem.names
    sigma = np.sqrt(np.clip(np.diag(p), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.nan_to_num(p / np.outer(sigma, sigma))
    rtn = rtn_covariance(x[:3], x[3:6], p[:6, :6])
    record = run_record(problem, opt, sw, iterations, noise, skipped, carried is not None, in_a_row)
    diagnostics = {"measurements": int(sw.edited.size), "edited": int(sw.edited.sum()), "correlation": corr,
                   "covariance_rtn": rtn,
                   "sigma_rtn": sigma_rtn(rtn),
                   "units": problem.params.units(), "decision": outcome.decision}
    if noise is not None:
        # each pass's model, as estimate records it; its AR(1) part is a Gauss-Markov state of the filter
        diagnostics["noise"] = noise.report
    extra = {"estimation": {"method": "sequential: " + record["method"], "range_rate_model": problem.range_rate_model,
                            "apriori_initial": problem.apriori_initial,
                            "apriori_source": problem.apriori_source or None,
                            "apriori_note": problem.apriori_note or None,
                            "sources": sorted({str(s) for s in problem.sources})},
             "filter": record, "quality": quality.as_dict()}
    state = solution_state(problem, out_epoch, x, names, sigma, p, popt.force, eop, diagnostics, extra)
    if quality.verdict != "ok":
        warnings.append(quality.text())
    return FilterResult(state=state, problem=problem, sweep=sw, innovations=innovation_frame(problem, sw),
                        quality=quality, warnings=warnings, skipped=skipped, iterations=iterations)



def summary_text(result: FilterResult) -> str:
    """The one-screen summary on stderr."""
    st, rec = result.state, result.state.extra["filter"]
    lines = [f"filter: {rec['updates']} updates ({rec['edited']} edited) over {rec['steps']} times in "
             f"{rec['segments']} segment(s), {rec['sweeps']} sweep(s); last measurement {rec['last_measurement']}",
             f"{rec['solution']} state at {format_epoch(st.epoch)} (GCRF):"]
    for name, v, s, u in zip(st.parameters, st.values, st.sigma, result.problem.params.units()):
        lines.append(f"  {name:<24} {v:>20.6f} +- {s:.4g} {u}")
    srtn = st.diagnostics["sigma_rtn"]
    lines.append(f"  sigma RTN {srtn['radial_m']:.4g} / {srtn['along_m']:.4g} / {srtn['cross_m']:.4g} m")
    lines.append(f"  normalised innovations squared {rec['nis']:.5g} over {rec['nis_dof']}")
    decision = (st.diagnostics or {}).get("decision")
    if decision:
        lines.append(f"  decision: {decision['reason']}")
    lines.extend(f"warning: {w}" for w in result.warnings)
    lines.append(result.quality.text())
    return "\n".join(lines) + "\n"
