"""Prediction checks of a fitted TLE on the user's own passes (``--cross-validate``)."""

from __future__ import annotations

import math

import numpy as np

from trackproc.io.tle import satrec
from trackproc.methods import tle_fit as tf
from trackproc.pipeline.compare import CompareOptions, compare
from trackproc.pipeline.fit_tle.options import FitTleOptions
from trackproc.pipeline.orbit_source import OrbitInput


from dataclasses import replace


def cross_validation(tables, ephemerides, orbit, options: FitTleOptions, eop, stations, epoch) -> dict:
    """Prediction skill from the user's own data (``--cross-validate``): each pass file left out
    in turn, the TLE fitted to the others (same epoch and options) predicts it; per pass and kind
    of the left-out file, the RMS after its own offset and drift (``compare``) of that prediction
    and of the initial orbit's, and their ratio. Needs two or more pass files."""
    from trackproc.pipeline.fit_tle.run import fit_tle   # (run imports this module: the cycle of leave-one-out)


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
        own = fit_tle([(source, table)], [], orbit,
                      replace(sub, epoch=None, model_error=0.0, apriori_model="refine"), eop, stations)
        error = curve_difference(table, fitted.tle, own.tle, options, eop, stations)
        spread = prediction_spread(table, fitted, fitted.summary["covariance"]["matrix"], options, eop, stations)
        own_spread = prediction_spread(table, own, own.summary["covariance"]["matrix"], options, eop, stations)
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


def time_shifts(model, x, step, groups, rate, weights, design, observed, iterations: int = 4) -> dict:
    """Per pass and kind of Doppler or range-rate (``rate``, a row mask), the time shift (s) of
    the orbit ``x`` that best matches the samples ``observed``, and its 1-σ (the samples' ``1/σ``
    weights; the data's noise only): ``λ`` alone moved, that group's
    offset and drift columns of ``design`` refitted (profiled out), by Gauss-Newton (a pass's
    Doppler curve is far from linear in a shift of seconds), as time ``−δλ / (360° n)``:
    positive when the satellite passes later than ``x`` predicts. ``weights`` are 1/σ, 0 for
    edited rows. An along-track error of the orbit and a time-tag error of the station look the
    same here."""
    out = {}
    for g in sorted(set(groups[rate])):
        m = (groups == g) & rate & (weights > 0)
        if m.sum() < 3:
            continue
        w = weights[m]
        b = design[m][:, np.any(design[m] != 0.0, axis=0)] * w[:, None]

        def profiled(v):
            v = v * w
            return v - b @ np.linalg.lstsq(b, v, rcond=None)[0] if b.size else v

        dlam, info = 0.0, 0.0
        for _ in range(iterations):
            xx = np.array(x, float)
            xx[5] += dlam
            d = np.zeros(len(xx))
            d[5] = step
            col = profiled(((model(xx + d) - model(xx - d)) / (2.0 * step))[m])
            if not float(col @ col) > 0:
                break
            info = float(col @ col)
            inc = float(col @ profiled((observed - model(xx))[m])) / info
            dlam += inc
            if abs(inc) < 1e-3 * step:
                break
        to_s = 86400.0 / (360.0 * float(x[0]))
        out[g] = (float(-dlam * to_s), float(to_s / np.sqrt(info)) if info > 0 else float("inf"))
    return out


def trend_removed(frame, values, options):
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


def curve_difference(table, tle, reference, options, eop, stations) -> dict:
    """RMS per pass and kind of two TLEs' predicted curves' difference, offset and drift removed."""
    cmp = CompareOptions(remove="none", earth=options.earth, range_rate_model=options.range_rate_model)
    a, _ = compare(table, OrbitInput(tle=tle), cmp, eop, stations)
    b, _ = compare(table, OrbitInput(tle=reference), cmp, eop, stations)
    a = a.reset_index(drop=True)
    d = trend_removed(a, a["computed"].to_numpy() - b["computed"].to_numpy(), options)
    return {k: float(np.sqrt(np.mean(v ** 2))) for k, v in d.items()}


def prediction_spread(table, result, covariance, options, eop, stations) -> dict:
    """RMS per pass and kind of the spread an element covariance (7, 7) of ``result``'s fitted
    elements (written, not refused) predicts for ``table``'s samples, offset and drift removed: the linear map through
    SGP4's partials (central differences), ``sqrt(trace(Π A C Aᵀ Π) / n)``."""
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
    parts = [trend_removed(base, c, options) for c in cols]
    out = {}
    for key in parts[0]:
        a = np.stack([p[key] for p in parts], axis=1)
        out[key] = float(np.sqrt(max(np.trace(a @ cov @ a.T), 0.0) / a.shape[0]))
    return out
