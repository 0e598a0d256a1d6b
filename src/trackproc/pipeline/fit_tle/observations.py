"""The samples a TLE is fitted to (passes and ephemerides, stacked, with the SGP4 prediction
of each block), the nuisance design (offset/drift per one-way group), the epoch and the
initial elements moved to it (steps 1, 2 and 4 of :mod:`trackproc.pipeline.fit_tle`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from trackproc.dynamics import kepler
from trackproc.dynamics.timescales import datetime64_to_jd_utc
from trackproc.errors import InputError, ProcessingError
from trackproc.io.tle import MeanElements, satrec
from trackproc.io.validate import ORBIT_RADIUS_RANGE_M, stated_carrier
from trackproc.methods import tle_fit as tf
from trackproc.models.measurements import KIND_FIELDS, station_gcrf
from trackproc.pipeline.fit_tle.options import KINDS, MU_WGS72, REEPOCH_HALF_SPAN_REV, REEPOCH_STEP_S
from trackproc.pipeline.orbit_source import (Satellite, Sgp4Track, station_itrf, station_observables,
                                             teme_to_gcrf_maps)


@dataclass
class Block:
    """Samples of one station (or one ephemeris) and how to predict them."""

    rows: np.ndarray            # indices into the stacked observation vector
    kind: np.ndarray
    predict: object             # satrec -> predicted values at these rows


def utc_times(series) -> np.ndarray:
    return pd.DatetimeIndex(series).tz_convert("UTC").tz_localize(None).as_unit("ns").to_numpy()


def observations(tables, ephemerides, options, eop, stations):
    """The stacked samples (a DataFrame: time, group, kind, value, sigma, source) and the blocks
    predicting them."""
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
        carrier = stated_carrier(table.meta, file=source, needed=bool((frame["kind"] == "doppler").any()),
                                 missing=None)
        mode = table.meta.get("doppler_mode") or "one-way"
        times = utc_times(frame["time"])
        for name in sorted(set(frame["station"])):
            sel = np.flatnonzero(frame["station"].to_numpy() == name)
            st = known[name]
            track = Sgp4Track(times[sel], eop)
            view = station_gcrf(station_itrf(st, options.earth), *datetime64_to_jd_utc(times[sel]), eop)
            kinds = frame["kind"].to_numpy()[sel]
            # each kind's rows, found once: the model is evaluated many times at these samples
            where = [(field, np.flatnonzero(kinds == kind)) for kind, field in KIND_FIELDS.items()]
            where = [(field, idx) for field, idx in where if idx.size]

            def predict(sat, track=track, view=view, st=st, where=where, size=kinds.size, carrier=carrier,
                        mode=mode):
                r, v, a, j = track.rvaj(sat)
                obs = station_observables(r, v, a, j, view, st, carrier_hz=carrier or 1.0, mode=mode,
                                          range_rate_model=options.range_rate_model)
                out = np.empty(size)
                for field, idx in where:
                    out[idx] = getattr(obs, field)[idx]
                return out

            blocks.append(Block(rows=offset + np.arange(sel.size), kind=kinds, predict=predict))
            part = pd.DataFrame({"time": times[sel], "station": name, "pass_id": frame["pass_id"].to_numpy()[sel],
                                 "kind": kinds, "value": frame["value"].to_numpy(float)[sel],
                                 "sigma": frame["sigma"].to_numpy(float)[sel], "source": source,
                                 "one_way": mode == "one-way"})
            parts.append(part)
            offset += sel.size
    for source, eph in ephemerides:
        times = utc_times(eph.frame["time"])
        xyz = eph.frame[["x_m", "y_m", "z_m"]].to_numpy(float)
        cols = [c for c in ("sigma_x_m", "sigma_y_m", "sigma_z_m") if c in eph.frame.columns]
        sig = (eph.frame[cols].to_numpy(float) if len(cols) == 3
               else np.full(xyz.shape, float(options.ephemeris_sigma_m)))
        if not np.all(np.isfinite(sig) & (sig > 0)):
            raise InputError("ephemeris sigmas must be positive", file=source, column="sigma_x_m",
                             expected="positive numbers, or no sigma columns (--ephemeris-sigma is used)")
        radius = np.linalg.norm(xyz, axis=1)
        low, high = ORBIT_RADIUS_RANGE_M
        bad = np.flatnonzero(~(np.isfinite(xyz).all(axis=1) & (radius >= low) & (radius <= high)))
        if bad.size:
            k = int(bad[0])
            column = next((c for c, v in zip(("x_m", "y_m", "z_m"), xyz[k]) if not np.isfinite(v)), "x_m/y_m/z_m")
            raise InputError("invalid ephemeris position", file=source, column=column,
                             found=f"record {k + 1}: {xyz[k].tolist()}", expected=f"finite positions in metres, |r| between {low:g} and {high:g} m")
        track = Sgp4Track(times, eop, derivatives=False)

        def predict(sat, track=track):
            return track.states(sat)[:, :3].reshape(-1)

        n = xyz.size
        blocks.append(Block(rows=offset + np.arange(n), kind=np.repeat(np.array(["position"]), n), predict=predict))
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


def nuisance_design(obs: pd.DataFrame, bias: str):
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
            t = utc_times(g["time"])
            if best is None or t.min() > best[0]:
                best = (t.min(), t.max())
    if best is None:
        t = np.concatenate([utc_times(e.frame["time"]) for _, e in ephemerides])
        best = (t.min(), t.max())
    return best[0] + (best[1] - best[0]) // 2


def reepoch(orbit, epoch, template_bstar, eop):
    """Elements at ``epoch`` reproducing the initial orbit there: fitted to its GCRF positions
    every :data:`REEPOCH_STEP_S` over :data:`REEPOCH_HALF_SPAN_REV` revolutions either side."""
    force = "sgp4" if orbit.tle is not None else "j2"
    # the initial guess: the osculating elements (TEME) of the initial orbit at the epoch
    probe = Satellite(orbit, force, epoch, -1.0, 1.0, eop)
    x_gcrf = np.concatenate(probe.rvaj([0.0])[:2], axis=1)[0]

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


def mean_elements(x, epoch):
    c = tf.classical(x)
    return MeanElements(epoch=epoch, inclination_deg=c["inclination_deg"], raan_deg=c["raan_deg"],
                        eccentricity=c["eccentricity"], arg_perigee_deg=c["arg_perigee_deg"],
                        mean_anomaly_deg=c["mean_anomaly_deg"], mean_motion_rev_day=c["mean_motion_rev_day"],
                        bstar=c["bstar"])
