"""Seed 002's reports on an estimate: the comparison without the ranges (eqs. 9, 15,
:func:`compare`) and the two-stage method (eqs. 17-22, :func:`two_stage`)."""

from __future__ import annotations

import math

import numpy as np

from trackproc.errors import InputError, ProcessingError
from trackproc.methods import two_stage as tsm
from trackproc.methods.least_squares import Prior
from trackproc.models import modifiers as md
from trackproc.models import parameters as pm
from trackproc.pipeline.od.options import EstimateOptions
from trackproc.pipeline.od.problem import Problem


def range_bias_drivers(problem: Problem) -> list:
    """The drivers of the problem's :class:`~trackproc.models.modifiers.RangeBias` modifiers."""
    return [d for b in problem.modifiers if isinstance(b.modifier, md.RangeBias)
            for d in b.modifier.parameter_drivers()]


def motion_columns(problem: Problem, names):
    """Columns of ``names`` that are not range biases (the motion parameters of seed 002)."""
    biases = {d.name for d in range_bias_drivers(problem)}
    return [i for i, n in enumerate(names) if n not in biases]


def compare(problem: Problem, sol) -> dict:
    """Solve without the ranges (and range biases) and compare the motion blocks.

    Implements seed 002 eqs. 9 and 15 (the theorem on the motion block of the extended error matrix)."""

    names = sol.names
    mcol = motion_columns(problem, names)
    motion = [names[i] for i in mcol]
    rows = problem.meas.kind != "range"
    out = {"parameters": motion, "extended_sigma": sol.sigma[mcol].tolist()}
    if rows.all() or not rows.any():
        out["doppler_only"] = "not computed: the data have no ranges, or only ranges"
        return out
    sub = subproblem(problem, rows, keep_range_bias=False)
    try:
        sol1 = sub.solve(max_iterations=20, clip=None)
    except ProcessingError as exc:
        out["doppler_only"] = f"not observable without the ranges: {exc}"
        return out
    idx = [sol1.names.index(n) for n in motion]
    kx = sol.covariance[np.ix_(mcol, mcol)]
    # the Doppler-only error matrix (A1ᵀ K⁻¹ A1)⁻¹ on the extended solution's Jacobian (same A1,
    # as in seed 002 eqs. 9 and 15), so that the two blocks differ only by what the ranges add
    a1 = rows & ~sol.edited
    k1 = with_priors(tsm.covariance(sol.jacobian[a1][:, mcol], problem.meas.sigma[a1] ** 2), problem.priors, mcol)
    # eigenvalues of K1^-1/2 (K1 - Kx) K1^-1/2: 0 = the ranges add nothing in that direction
    # (seed 002 eq. 15, one range per offset), 1 = they determine it completely
    l_inv = np.linalg.inv(np.linalg.cholesky(k1))
    w = np.linalg.eigvalsh(l_inv @ (k1 - kx) @ l_inv.T)
    out.update({"doppler_only_sigma": np.sqrt(np.diag(k1)).tolist(),
                "doppler_only_solved_sigma": sol1.sigma[idx].tolist(),
                "doppler_only_values": sol1.values[idx].tolist(), "extended_values": sol.values[mcol].tolist(),
                "doppler_only_covariance": k1, "extended_covariance": kx,
                "relative_reduction_min": float(w.min()), "relative_reduction_max": float(w.max()),
                "ranges": int((~rows).sum())})
    return out


def subproblem(problem: Problem, rows, keep_range_bias: bool) -> Problem:
    """The problem restricted to ``rows`` (and without range-bias drivers unless kept)."""
    meas = problem.meas.subset(np.flatnonzero(rows))
    biases = {d.name for d in range_bias_drivers(problem)}
    params = pm.ParameterSet()
    for d in problem.params:
        if d.name in biases and not keep_range_bias:
            continue
        params.add(pm.ParameterDriver(d.name, d.unit, d.value, d.scale, apriori_sigma=d.apriori_sigma,
                                      apriori_value=d.apriori_value if d.apriori_value is not None else d.reference,
                                      selected=d.selected, bounds=d.bounds, epoch_s=d.epoch_s,
                                      description=d.description))
    modifiers = [b.modifier.bind(meas) for b in problem.modifiers
                 if keep_range_bias or not isinstance(b.modifier, md.RangeBias)]
    mask, centre, sigma = params.apriori()
    priors = [Prior.diagonal(np.flatnonzero(mask), centre[mask], sigma[mask])] if mask.any() else []
    for p in problem.priors:          # a full initial-state prior stays on x..vz
        if p.covariance.shape[0] == 6 and np.array_equal(p.index, np.arange(6)) and not mask[:6].any():
            priors.append(p)
    return Problem(meas=meas, params=params, epoch=problem.epoch, frame=problem.frame, force=problem.force,
                   range_rate_model=problem.range_rate_model, modifiers=modifiers, priors=priors,
                   times=problem.times[rows], sources=problem.sources[rows], eop=problem.eop,
                   force_model=problem.force_model, force_names=problem.force_names)


def two_stage(problem: Problem, sol, opt: EstimateOptions):
    """Implements seed 002 eqs. 17-22: stage 1 per-pass offsets from the orbit without ranges, accumulated
    per station (Π); stage 2 with the bias-corrected ranges (error matrix D + E Π Eᵀ)."""
    meas = problem.meas
    is_range = meas.kind == "range"
    names = sol.names
    owners = {d.name: b.modifier for b in problem.modifiers if isinstance(b.modifier, md.RangeBias)
              for d in b.modifier.parameter_drivers()}
    bias_names = [n for n in names if n in owners]
    if not bias_names or not is_range.any() or is_range.all():
        raise InputError("--two-stage needs ranges with --range-bias and other (Doppler, range-rate, angle) data",
                         column="--two-stage")
    # stage 0: the orbit from the data without ranges
    sub = subproblem(problem, ~is_range, keep_range_bias=False)
    sol1 = sub.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol)
    motion = sol1.names
    k1 = sol1.covariance
    # stage 1: per-pass offsets against that orbit
    x_full = np.array([sol1.values[motion.index(n)] if n in motion else 0.0 for n in names])
    h, jac = problem.model(x_full)
    mcol = [names.index(n) for n in motion]
    rows = np.flatnonzero(is_range)
    w = 1.0 / meas.sigma[rows] ** 2
    res = meas.observed[rows] - h[rows]
    passes = sorted(set(meas.pass_id[rows]))
    est, var, a_pass, pass_station, table = [], [], [], [], []
    for p in passes:
        sel = meas.pass_id[rows] == p
        wp = w[sel]
        est.append(float(np.sum(wp * res[sel]) / wp.sum()))
        var.append(1.0 / wp.sum())
        a_pass.append((wp[:, None] * jac[rows[sel]][:, mcol]).sum(0) / wp.sum())
        station = meas.station[rows[sel]][0]
        pass_station.append(station)
        table.append({"pass_id": p, "station": station, "n": int(sel.sum()), "offset_m": est[-1],
                      "noise_sigma_m": math.sqrt(var[-1])})
    a_pass = np.array(a_pass)
    c_pass = np.diag(var) + a_pass @ k1 @ a_pass.T
    stations = [owners[n].key for n in bias_names]
    means, pi, _ = tsm.accumulate(est, c_pass, pass_station, stations)
    for row, s in zip(table, pass_station):
        row["orbit_sigma_m"] = float(np.sqrt(a_pass[table.index(row)] @ k1 @ a_pass[table.index(row)]))
    # stage 2: ranges corrected by the accumulated offsets, error matrix D + E Π Eᵀ (as a prior on the offsets)
    bidx = np.array([names.index(n) for n in bias_names])
    priors = [p for p in problem.priors if not np.isin(p.index, bidx).any()]
    priors.append(Prior(bidx, means, pi))
    x0 = x_full.copy()
    x0[bidx] = means
    sol2 = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol, x0=x0,
                         priors=priors)
    k_prime = sol2.covariance[np.ix_(mcol, mcol)]
    # K from the A1 rows, and ΔK by the inversion lemma, all from stage 2's Jacobian
    jac2 = sol2.jacobian
    keep = ~sol2.edited
    a1_rows = keep & ~is_range
    a2_rows = keep & is_range
    k = tsm.covariance(jac2[a1_rows][:, mcol], meas.sigma[a1_rows] ** 2)
    kwith_priors = with_priors(k, problem.priors, mcol)
    e = jac2[a2_rows][:, bidx]
    a2c, eye = tsm.compress(jac2[a2_rows][:, mcol], meas.sigma[a2_rows] ** 2, e, pi)
    k_lemma, dk, _ = tsm.two_stage_update(kwith_priors, a2c, eye)
    err = float(np.abs(k_prime - k_lemma).max() / np.abs(kwith_priors).max())
    return tsm.TwoStage(names=motion, k=kwith_priors, k_prime=k_prime, delta_k=dk, stations=stations, biases=means,
                        pi=pi, passes=table, identity_error=err,
                        delta_k_min_eigenvalue=float(np.linalg.eigvalsh(dk).min())), sol2


def with_priors(k, priors, mcol):
    """K including the a-priori constraints on the motion parameters (information added)."""
    if not priors:
        return k
    info = np.linalg.inv(k)
    pos = {c: i for i, c in enumerate(mcol)}
    for p in priors:
        if all(int(i) in pos for i in p.index):
            idx = [pos[int(i)] for i in p.index]
            info[np.ix_(idx, idx)] += np.linalg.inv(p.covariance)
    out = np.linalg.inv(info)
    return 0.5 * (out + out.T)


def two_stage_dict(two, sol2) -> dict:
    return {"parameters": two.names, "K": two.k, "K_prime": two.k_prime, "delta_K": two.delta_k,
            "sigma_K": np.sqrt(np.diag(two.k)).tolist(), "sigma_K_prime": np.sqrt(np.diag(two.k_prime)).tolist(),
            "stations": two.stations, "stage1_offsets_m": two.biases.tolist(), "Pi": two.pi,
            "passes": two.passes, "identity_error": two.identity_error,
            "delta_K_min_eigenvalue": two.delta_k_min_eigenvalue,
            "stage2_values": dict(zip(sol2.names, sol2.values.tolist())),
            "stage2_sigma": dict(zip(sol2.names, sol2.sigma.tolist()))}
