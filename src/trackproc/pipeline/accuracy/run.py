""":func:`accuracy`: the nominal orbit and its spectra, the moments by each method (steps 2-3), the table.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from trackproc.dynamics import geodesy, taylor
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.propagator import propagate_state
from trackproc.errors import InputError
from trackproc.methods import accuracy as ac
from trackproc.models.observables import azel
from trackproc.pipeline.simulate import time_grid
from trackproc.pipeline.accuracy.columns import consistency_checks, correlation_matrices, result_meta, sigma_frame
from trackproc.pipeline.accuracy.options import (MC_CHUNK, AccuracyOptions, AccuracyResult, check_options,
                                                 initial_covariance)


def accuracy(state, options: AccuracyOptions, stations: Optional[dict] = None, eop=None,
             stations_source: Optional[str] = None) -> AccuracyResult:
    """Mean, sigma and (on request) the covariance function of the orbit predicted from ``state``.

    Parameters
    ----------
    state : :class:`~trackproc.io.statefile.State` (GCRF) with a covariance, or use the sigma options.
    options : :class:`AccuracyOptions`.
    stations : name -> station (``lat_deg``, ``lon_deg``, ``height_m``), needed with ``at_station``.
    eop : :class:`~trackproc.dynamics.timescales.EarthOrientation` or None.
    stations_source : the stations file name, for error messages.
    """
    check_options(options)
    if options.at_station is not None:
        if not stations or options.at_station not in stations:
            raise InputError("unknown station", file=stations_source, column="--at-station", found=options.at_station,
                             expected="a station of the stations table: " + ", ".join(sorted(stations or {})))
    cov0, cov_label = initial_covariance(state, options)
    times = time_grid(state.epoch, options.span_s, options.step_s)
    t = np.maximum(ts.seconds_since(ts.datetime64_to_jd_utc(times), state.jd_utc), 0.0)   # SI s (leap s)
    traj = propagate_state(state, float(t.max(initial=0.0)), force=options.force, eop=eop, stm=True,
                           force_model=options.force_model)
    traj.raise_for_outcome()
    nominal = traj.state(t)                        # (M, 6) GCRF
    big_q = traj.rotation                          # GCRF -> quasi-inertial
    cov0_q = big_q @ cov0 @ big_q.T

    covs, factors = {}, {}
    for method in options.methods:
        if method == "spectral":
            p_q = ac.spectral_covariance(traj, t, cov0_q)
            covs[method] = big_q.T @ p_q @ big_q
            if options.correlation:
                factors[method] = big_q.T @ ac.spectral_factors(traj, t, cov0_q)
        elif method == "stm":
            phi = traj.stm(t)
            covs[method] = ac.stm_covariance(phi, cov0)
            if options.correlation:
                factors[method] = phi @ ac.normalizing_factor(cov0)

    track = None
    if options.at_station is not None:
        track = station_track(stations[options.at_station], times, nominal, options.earth, eop)

    mc = None
    if "monte-carlo" in options.methods:
        mc = monte_carlo(traj, state, cov0, t, nominal, options, track)
        covs["monte-carlo"] = mc["cov"]

    rtn = {m: ac.to_rtn(c, nominal[:, :3], nominal[:, 3:]) for m, c in covs.items()}
    obs = {}
    if track is not None:
        for m, c in covs.items():
            obs[m] = ac.observable_covariance(track["jacobian"], c)
        if mc is not None:
            obs["monte-carlo"] = mc["obs_cov"]

    frame = sigma_frame(times, t, nominal, covs, rtn, obs, track, options, mc)
    checks = consistency_checks(covs, rtn, options.n_samples)
    correlation = None
    if options.correlation:
        first = options.methods[0]
        correlation = correlation_matrices(first, factors.get(first), mc, nominal)
    meta = result_meta(state, options, traj, cov0, cov_label, checks, eop, track, mc)
    return AccuracyResult(frame=frame, meta=meta, times=times, elapsed_s=t, nominal=nominal, covariance=covs,
                          covariance_rtn=rtn, observables=obs, initial_covariance=cov0, correlation=correlation,
                          station_track=track)


def station_track(station, times, nominal, earth, eop) -> dict:
    """Station in GCRF at the grid times, nominal range / range-rate / elevation and partials."""
    lat, lon, r_itrf = geodesy.station_itrf(station, earth)
    jd1, jd2 = ts.datetime64_to_jd_utc(times)
    st = geodesy.station_gcrf(r_itrf, jd1, jd2, eop)
    d = nominal[:, :3] - st.r
    rng = np.linalg.norm(d, axis=-1)
    rr = np.sum(d * (nominal[:, 3:] - st.v), axis=-1) / rng
    _, el = azel(d, st.gcrf_to_itrf, lat, lon)
    return {"name": station.name if hasattr(station, "name") else None, "r": st.r, "v": st.v,
            "range_m": rng, "range_rate_m_s": rr, "elevation_rad": el,
            "jacobian": ac.range_range_rate_jacobian(nominal[:, :3], nominal[:, 3:], st.r, st.v),
            "station": station}


def monte_carlo(traj, state, cov0, t, nominal, options, track) -> dict:
    """N draws of N(x0, P0) propagated in the façade's frame by the engine's batch mode.

    Moments accumulate about the nominal orbit (deviations of metres, not positions of
    thousands of kilometres, so the sums lose nothing), chunk by chunk.
    """
    n = options.n_samples
    q = traj.frame.q
    big_q = traj.rotation
    draws = ac.sample_initial_states(state.rv, cov0, n, options.seed)          # (N, 6) GCRF
    m = t.size
    s1 = np.zeros((m, 6))
    s2 = np.zeros((m, 6, 6))
    o1 = np.zeros((m, 2))
    o2 = np.zeros((m, 2, 2))
    corr = {} if options.correlation else None
    rot = None
    if options.correlation:
        rot = ac.rtn_jacobian(nominal[:, :3], nominal[:, 3:])
        corr = {"s1": np.zeros((m, 12)), "s2": np.zeros((12, m, m))}
    for a in range(0, n, MC_CHUNK):
        chunk = draws[a:a + MC_CHUNK] @ big_q.T                              # quasi-inertial
        run = taylor.propagate(chunk, 0.0, traj.t_max_s, force=traj.force, mu_m3_s2=traj.mu_m3_s2, j2=traj.j2,
                               re_m=traj.re_m, tol=traj.tol).raise_for_outcome()
        x = run.state(t)                                                      # (B, M, 6)
        x = np.concatenate([x[..., :3] @ q, x[..., 3:] @ q], axis=-1)         # GCRF
        d = x - nominal[None]
        s1 += d.sum(0)
        s2 += np.einsum("bmi,bmj->mij", d, d)
        if track is not None:
            dr = x[..., :3] - track["r"][None]
            rng = np.linalg.norm(dr, axis=-1)
            rr = np.sum(dr * (x[..., 3:] - track["v"][None]), axis=-1) / rng
            do = np.stack([rng - track["range_m"][None], rr - track["range_rate_m_s"][None]], -1)
            o1 += do.sum(0)
            o2 += np.einsum("bmi,bmj->mij", do, do)
        if corr is not None:
            d_rtn = np.einsum("mij,bmj->bmi", rot, d)                          # the 6 x 6 RTN map, as to_rtn
            dd = np.concatenate([d, d_rtn], axis=-1)                          # (B, M, 12)
            corr["s1"] += dd.sum(0)
            for c in range(12):                                               # BLAS: (M x B)(B x M)
                dc = np.ascontiguousarray(dd[:, :, c])
                corr["s2"][c] += dc.T @ dc
    mean_dev = s1 / n
    cov = (s2 - n * np.einsum("mi,mj->mij", mean_dev, mean_dev)) / (n - 1)
    out = {"n": n, "seed": options.seed, "cov": 0.5 * (cov + np.swapaxes(cov, -1, -2)), "mean_dev": mean_dev}
    if track is not None:
        om = o1 / n
        out["obs_cov"] = (o2 - n * np.einsum("mi,mj->mij", om, om)) / (n - 1)
        out["obs_mean_dev"] = om
    if corr is not None:
        cm = corr["s1"] / n                                                   # (M, 12)
        out["cross"] = (corr["s2"] - n * np.einsum("mc,kc->cmk", cm, cm)) / (n - 1)
    return out
