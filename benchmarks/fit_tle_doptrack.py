"""DopTrack Delfi-C3 (../shared/realdata): does a TLE fitted by ``fit-tle`` predict a pass better
than the TLE it started from? (issue 18's criterion; numbers in docs/fit-tle.md and the README)

Two protocols, each for the development passes (1-10 April 2020) and the hold-out (11-15 April,
never used while developing; evaluated three times, each time once at the end of a version):

* ``held-back``: every pass of an evening (passes < 4 h apart) but the last fitted from the
  metadata TLE (the newest of those passes, defaults: offset+drift per pass, a-priori, B* fitted),
  the last pass (~95 min later) predicted.
* ``next``: every pass of an evening fitted, the first pass of the next group (the next
  morning or evening, < 24 h) predicted.

Both against the initial TLE's SGP4 prediction; "pred" is also compared with the TLE stored in
the predicted pass's own metadata (newer, when the station had updated it). RMS in Hz of the
predicted pass's Doppler after that pass's own offset and drift (``compare``); "fitted" is
the fit (written or refused), "written" what ``-o`` gets. Usage:
``PYTHONPATH=src python benchmarks/fit_tle_doptrack.py [dev|holdout|both|covariance|covariance-holdout|calibrate|pairs|pairs-holdout|verdicts|verdicts-holdout|tle-apriori|timing|upstream-tca]``
(about a minute each; ``covariance``: :func:`covariance_rows`, the written covariance against the
prediction errors, development evenings; ``covariance-holdout`` the same on the hold-out, run
once at the end; ``calibrate``: :func:`calibrate`, the theory error's scale, development only,
about two minutes; ``pairs``: :func:`pairs`, every development run of passes against every later
pass within 30 h (68 pairs; :func:`honesty_rows` the same pairs' covariance check);
``verdicts``: :func:`verdicts`, every run of development passes fitted: verdicts, refusals and
the a-priori conflict test (``verdicts-holdout``, ``pairs-holdout``: the same on the hold-out, run
once at the end);
``tle-apriori``: :func:`tle_apriori`, the initial TLE's a-priori by TLE differencing;
``timing``: :func:`timing`, the passes' apparent time shifts against fresh TLEs;
``upstream-tca``: :func:`upstream_tca`, the DopTrack team's own TCA against the TLE's).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import sys
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))  # test_refine_realdata

import numpy as np  # noqa: E402

from test_refine_realdata import EOP, _load, evenings, is_dev  # noqa: E402
from trackproc.pipeline.compare import CompareOptions, compare  # noqa: E402
from trackproc.pipeline.fit_tle import FitTleOptions, fit_tle  # noqa: E402
from trackproc.pipeline.orbit_source import OrbitInput, metadata_tle, tle_from_pass_metadata  # noqa: E402


def _rms(table, tle):
    _, s = compare(table, OrbitInput(tle=tle), CompareOptions(), EOP)
    return s["passes"][0]["rms"]


def _fit(fit, options=None):
    tables = [(s, _load(s)[0]) for s in fit]
    initial = metadata_tle(tables)
    return initial, fit_tle(tables, [], OrbitInput(tle=initial, source="metadata"), options or FitTleOptions(), EOP)


def _row(fit, target, options=None, fitted=None):
    initial, res = fitted or _fit(fit, options)
    table = _load(target)[0]
    own = tle_from_pass_metadata(table)
    return {"fit": fit, "predicted": target, "tle_hz": round(_rms(table, initial), 2),
            "fitted_hz": round(_rms(table, _tle(res.summary)), 2), "written_hz": round(_rms(table, res.tle), 2),
            "own_tle_hz": round(_rms(table, own), 2), "quality": res.quality.verdict,
            "refused": (res.summary["refused"] or {}).get("code"),
            "p_better": round(res.summary["prediction"].get("probability_better", float("nan")), 3),
            "moved_m": round(res.summary["prediction"].get("change_m", float("nan")), 1)}


def _stamp_time(s):
    return dt.datetime.strptime(s, "%Y%m%d%H%M")


def visits(dev: bool = True):
    """Every run of consecutive passes < 4 h apart (single passes too) of the development days (or
    the hold-out): the fits of the extended development protocol."""
    from test_refine_realdata import BAD_PASSES, DOPTRACK, MAX_PAIR_GAP_S

    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    stamps = [s for s in stamps if s not in BAD_PASSES and is_dev(s) == dev]
    out, cur = [], []
    for s in stamps:
        if cur and (_stamp_time(s) - _stamp_time(cur[-1])).total_seconds() > MAX_PAIR_GAP_S:
            out.append(cur)
            cur = []
        cur.append(s)
    return out + [cur]


def pairs(options=None, dev: bool = True, horizon_h: float = 30.0, quiet: bool = False):
    """The extended development protocol (more pairs than ``held-back``/``next`` to decide on): every
    visit (one or more passes < 4 h apart), and every run of consecutive passes in it, fitted;
    every later pass of the same set within ``horizon_h`` hours of the last fitted pass
    predicted. Prints the counts of fitted <= initial, by horizon (< 4 h: the same evening;
    else next day) and by the number of passes fitted, and the refusals."""
    allp = [s for v in visits(dev) for s in v]
    rows = []
    for v in visits(dev):
        for fit in [v[i:j] for i in range(len(v)) for j in range(i + 1, len(v) + 1)]:
            targets = [s for s in allp
                       if 0 < (_stamp_time(s) - _stamp_time(fit[-1])).total_seconds() <= horizon_h * 3600]
            if not targets:
                continue
            fitted = _fit(fit, options)
            for target in targets:
                r = _row(fit, target, options, fitted)
                r["hours"] = round((_stamp_time(target) - _stamp_time(fit[-1])).total_seconds() / 3600, 1)
                rows.append(r)
                if not quiet:
                    print(json.dumps(r), flush=True)
    for name, sel in (("all", lambda r: True), ("< 4 h", lambda r: r["hours"] < 4),
                      (">= 4 h", lambda r: r["hours"] >= 4), ("1 pass fitted", lambda r: len(r["fit"]) == 1),
                      ("2+ passes fitted", lambda r: len(r["fit"]) > 1)):
        sub = [r for r in rows if sel(r)]
        if not sub:
            continue
        f = np.array([r["fitted_hz"] / r["tle_hz"] for r in sub])
        w = np.array([r["written_hz"] / r["tle_hz"] for r in sub])
        print(f"{name}: {len(sub)} pairs; fitted <= initial {(f <= 1).sum()}, median {np.median(f):.3f}, "
              f"geometric mean {np.exp(np.mean(np.log(f))):.3f}, worst {f.max():.2f}; written <= initial "
              f"{(w <= 1.0).sum()} (refused {sum(r['refused'] is not None for r in sub)}), worst {w.max():.2f}",
              flush=True)
    return rows


def verdicts(dev: bool = True, options=None):
    """Every run of consecutive passes of every visit (:func:`visits`) fitted with the defaults:
    the verdicts (exit 1 exactly when ``rejected``), the refusals, and the a-priori conflict
    test (``apriori.chi2``, under the fit's error model, against the 99.9 % point of
    χ²(elements)) beside the a-priori's share of the least-squares cost (``least_squares_share``:
    the check before issue 18's fix, which rejected a pass whose timing error is large against
    the TLE's a-priori although the theory error covers it)."""
    from trackproc.methods.quality import chi2_limit

    rows = []
    for v in visits(dev):
        for fit in [v[i:j] for i in range(len(v)) for j in range(i + 1, len(v) + 1)]:
            _, res = _fit(fit, options)
            a = res.summary["apriori"]
            limit = chi2_limit(a["elements"])
            others = [r["code"] for r in res.quality.as_dict()["reasons"]
                      if r["severity"] == "rejected" and r["code"] != "apriori_conflict"]
            row = {"fit": fit, "verdict": res.quality.verdict, "refused": (res.summary["refused"] or {}).get("code"),
                   "apriori_chi2": round(a["chi2"], 2), "directions": a["directions"],
                   "least_squares_share": round(a["least_squares_share"], 2), "limit": round(limit, 2),
                   "rejected_before": bool(a["least_squares_share"] > limit or others), "other_rejections": others}
            rows.append(row)
            print(json.dumps(row), flush=True)
    for name, sel in (("1 pass", lambda r: len(r["fit"]) == 1), ("2+ passes", lambda r: len(r["fit"]) > 1)):
        sub = [r for r in rows if sel(r)]
        if not sub:
            continue
        count = {k: sum(r["verdict"] == k for r in sub) for k in ("ok", "suspect", "rejected")}
        chi2 = np.array([r["apriori_chi2"] for r in sub])
        print(f"{'development' if dev else 'HOLD-OUT'} fits of {name}: {len(sub)}; verdicts {count}; rejected before "
              f"(least-squares a-priori share) {sum(r['rejected_before'] for r in sub)}; refused "
              f"{sum(r['refused'] is not None for r in sub)}; a-priori chi2 {chi2.min():.3g}-{chi2.max():.3g} "
              f"(median {np.median(chi2):.3g}, limit {sub[0]['limit']})", flush=True)
    return rows


def tle_apriori():
    """The a-priori of an initial TLE (methods/tle_fit.TLE_APRIORI) by TLE differencing: every
    older TLE of the development days' metadata (1-10 April) predicted by SGP4 against every newer
    one within 3.2 days, radial / along-track / cross-track RMS over 1.6 h about the newer epoch;
    RMS over the pairs by age class, and the along-track drift per day (least squares of the
    along-track RMS on age through the origin). No Doppler data enter."""
    import math

    from test_refine_realdata import DOPTRACK
    from trackproc.io.tle import satrec

    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    unique = {}
    for s in stamps:
        if is_dev(s):
            t = _load(s)[1]
            unique[t.line1] = t
    sats = sorted((satrec(t) for t in unique.values()), key=lambda x: x.jdsatepoch + x.jdsatepochF)

    def rtn(a, b, jd):
        _, ra, _ = a.sgp4(jd, 0.0)
        _, rb, vb = b.sgp4(jd, 0.0)
        r, v = np.array(rb), np.array(vb)
        d = (np.array(ra) - r) * 1e3
        u_r = r / np.linalg.norm(r)
        u_n = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
        return np.array([d @ u_r, d @ np.cross(u_n, u_r), d @ u_n])

    rows = []
    for k, a in enumerate(sats):
        for b in sats[k + 1:]:
            jd0 = b.jdsatepoch + b.jdsatepochF
            age = jd0 - (a.jdsatepoch + a.jdsatepochF)
            if age <= 3.2:
                d = np.array([rtn(a, b, jd0 + m / 1440.0) for m in np.arange(-48.0, 48.0, 2.0)])
                rows.append([age, *np.sqrt(np.mean(d ** 2, axis=0))])
    rows = np.array(rows)
    for lo, hi in ((0.0, 0.8), (0.8, 1.7), (1.7, 3.2)):
        m = (rows[:, 0] >= lo) & (rows[:, 0] < hi)
        print(f"age {lo}-{hi} d, {m.sum()} pairs: RMS radial {math.sqrt(np.mean(rows[m, 1] ** 2)):.0f} m, along-track "
              f"{math.sqrt(np.mean(rows[m, 2] ** 2)):.0f} m, cross-track {math.sqrt(np.mean(rows[m, 3] ** 2)):.0f} m")
    drift = float(np.sum(rows[:, 0] * rows[:, 2]) / np.sum(rows[:, 0] ** 2))
    from trackproc.methods.tle_fit import TLE_APRIORI

    print(f"along-track drift {drift:.0f} m/day over {len(rows)} pairs (TLE_APRIORI: {json.dumps(TLE_APRIORI)})")
    return rows


def timing(dev: bool = True):
    """Why one station's evening cannot improve these TLEs: per pass, the along-track time shift
    (s; λ alone moved, the pass's offset and drift refitted, Gauss-Newton) that best matches the
    pass with the development TLE nearest in epoch (most under half a day old, where TLE
    differencing puts the TLE's along-track error at 0.03-0.1 s). Development days only."""
    from test_refine_realdata import BAD_PASSES, DOPTRACK
    from trackproc.io.tle import satrec, tle_epoch
    from trackproc.methods import tle_fit as tf
    from trackproc.pipeline.fit_tle.observations import nuisance_design, observations

    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    stamps = [s for s in stamps if is_dev(s) == dev and s not in BAD_PASSES]
    tles = list({_load(s)[1].line1: _load(s)[1] for s in stamps}.values())
    shifts = []
    for s in stamps:
        table = _load(s)[0]
        t0 = np.datetime64(table.frame["time"].min().tz_convert("UTC").tz_localize(None), "ns")
        tle = min(tles, key=lambda t: abs((np.datetime64(tle_epoch(t), "ns") - t0) / np.timedelta64(1, "s")))
        obs, blocks = observations([(s, table)], [], FitTleOptions(), EOP, None)
        design, _ = nuisance_design(obs, "offset+drift")
        sat0 = satrec(tle)
        ep = tf.Epoch(0, sat0.jdsatepoch, sat0.jdsatepochF)
        x = tf.elements_of(sat0)
        z = obs["value"].to_numpy(float)

        def model(xx):
            out = np.empty(len(obs))
            for b in blocks:
                out[b.rows] = b.predict(tf.satrec_of(xx, ep))
            return out

        def rms(xx):
            r = z - model(xx)
            return float(np.sqrt(np.mean((r - design @ np.linalg.lstsq(design, r, rcond=None)[0]) ** 2)))

        rms0, lam0 = rms(x), x[5]
        for _ in range(6):
            d = np.zeros(7)
            d[5] = 1e-4
            col = (model(x + d) - model(x - d)) / 2e-4
            step = np.linalg.lstsq(np.column_stack([col, design]), z - model(x), rcond=None)[0][0]
            x[5] += step
        shift = -(x[5] - lam0) / (360.0 * x[0]) * 86400.0
        age = (t0 - np.datetime64(tle_epoch(tle), "ns")) / np.timedelta64(1, "s") / 86400.0
        shifts.append(shift)
        print(json.dumps({"pass": s, "tle_age_d": round(float(age), 2), "time_shift_s": round(float(shift), 2),
                          "rms_hz": round(rms0, 2), "rms_shifted_hz": round(rms(x), 2)}), flush=True)
    core = np.array([v for v in shifts if abs(v) < 2.0])
    print(f"{len(shifts)} passes; |shift| < 2 s: {core.size}, mean {core.mean():.2f} s, SD {core.std(ddof=1):.2f} s; "
          f"larger: {np.round([v for v in shifts if abs(v) >= 2.0], 1).tolist()}")
    return shifts


def upstream_tca(dev: bool = True):
    """An independent look at the passes' timing: the DopTrack team's own time of closest approach
    (the metadata's ``tracking.tca``, from their processing of the same recording) minus the
    time the pass's metadata TLE crosses zero Doppler at the station (interpolated between
    samples). Development days only."""
    import pandas as pd
    import yaml

    from test_refine_realdata import BAD_PASSES, DOPTRACK

    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))
    out = []
    for s in [s for s in stamps if is_dev(s) == dev and s not in BAD_PASSES]:
        table, tle = _load(s)
        doc = yaml.safe_load((DOPTRACK / "metadata" / f"Delfi-C3_32789_{s}.yml").read_text())
        tca = pd.Timestamp(doc["tracking"]["tca"]).tz_localize("UTC")
        r, _ = compare(table, OrbitInput(tle=tle), CompareOptions(remove="none"), EOP)
        r = r[r["kind"] == "doppler"]
        t = (r["time"] - tca).dt.total_seconds().to_numpy()
        d = r["computed"].to_numpy()
        if abs(np.median(d)) > 1e6:                        # received frequency, not the shift
            d = d - table.meta["carrier_hz"]
        k = np.flatnonzero(np.diff(np.sign(d)) != 0)
        if k.size:
            k = k[0]
            out.append(-(t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])))
            print(json.dumps({"pass": s, "upstream_tca_minus_tle_s": round(out[-1], 3)}), flush=True)
    v = np.array(out)
    print(f"{v.size} passes: median {np.median(v):.2f} s; {np.sum((v > -1.6) & (v <= 0))} between -1.6 and 0 s; "
          f"range {v.min():.1f} to {v.max():.1f} s")
    return v


def table(dev: bool, options=None):
    groups = [g for g in evenings() if is_dev(g[0]) == dev]
    allg = evenings()
    out = {"held-back": [], "next": []}
    for g in groups:
        out["held-back"].append(_row(g[:-1], g[-1], options))
        k = allg.index(g)
        if k + 1 < len(allg):
            nxt = allg[k + 1][0]
            gap = (dt.datetime.strptime(nxt, "%Y%m%d%H%M") - dt.datetime.strptime(g[-1], "%Y%m%d%H%M"))
            if gap.total_seconds() < 86400 and is_dev(nxt) == dev:
                out["next"].append(_row(g, nxt, options))
    for name, rows in out.items():
        print(f"## {'development (1-10 April)' if dev else 'HOLD-OUT (11-15 April)'}: {name}")
        for r in rows:
            print(json.dumps(r))
        if rows:
            ratio = np.array([r["fitted_hz"] / r["tle_hz"] for r in rows])
            print(f"ratio fitted/initial TLE: {np.round(ratio, 3).tolist()}; <= 1: {(ratio <= 1).sum()} of "
                  f"{ratio.size}; <= 1.1: {(ratio <= 1.1).sum()}; median {np.median(ratio):.3f}")
            written = np.array([r["written_hz"] / r["tle_hz"] for r in rows])
            print(f"ratio written/initial TLE (refused fits write the initial): {np.round(written, 3).tolist()}; "
                  f"refused {sum(r['refused'] is not None for r in rows)} of {len(rows)}")
    return out




def doppler_spread(table, summary, matrix) -> float:
    """The RMS Doppler spread (Hz) at a pass of the fitted TLE's SGP4 prediction under the element
    covariance ``matrix`` (7, 7), the pass's offset and drift removed: the linear map through
    SGP4's partials (central differences), ``sqrt(trace(Π A C Aᵀ Π) / n)``."""
    return spread(doppler_partials(table, summary), matrix)


def spread(a, matrix) -> float:
    """``sqrt(trace(A C Aᵀ) / n)`` for the partials ``a`` of :func:`doppler_partials` (several
    covariances of one fit share its partials: 15 SGP4 runs over the pass each)."""
    return float(np.sqrt(np.trace(a @ np.asarray(matrix) @ a.T) / a.shape[0]))


def doppler_partials(table, summary):
    """``Π A`` of :func:`doppler_spread`: the Doppler's partials (n, 7) at ``table``'s samples
    with respect to the fitted TLE's elements, offset and drift removed."""
    from trackproc.io.tle import satrec
    from trackproc.methods import tle_fit as tf

    x = np.array(list(summary["elements"].values()))
    sat = satrec(_tle(summary))
    ep = tf.Epoch(0, sat.jdsatepoch, sat.jdsatepochF)

    def h(xx):
        r, _ = compare(table, OrbitInput(tle=tf.satrec_of(xx, ep)), CompareOptions(remove="none"), EOP)
        return r["computed"].to_numpy(), r

    base, r = h(x)
    t = (r["time"] - r["time"].min()).dt.total_seconds().to_numpy()
    steps = np.array([1e-7, 1e-6, 1e-6, 1e-5, 1e-5, 1e-5, 1e-6])
    cols = []
    for k in range(7):
        d = np.zeros(7)
        d[k] = steps[k]
        cols.append((h(x + d)[0] - h(x - d)[0]) / (2 * steps[k]))
    a = np.stack(cols, axis=1)
    b = np.stack([np.ones_like(t), t], axis=1)
    return a - b @ np.linalg.lstsq(b, a, rcond=None)[0]          # offset and drift removed


def _curve_difference(table, tle, reference) -> float:
    """RMS (Hz) of the difference of two TLEs' Doppler curves at a pass, offset and drift removed:
    the prediction's orbit error when ``reference`` is fitted to that pass itself (its noise
    does not enter, only its estimation error)."""
    a, _ = compare(table, OrbitInput(tle=tle), CompareOptions(remove="none"), EOP)
    b, _ = compare(table, OrbitInput(tle=reference), CompareOptions(remove="none"), EOP)
    t = (a["time"] - a["time"].min()).dt.total_seconds().to_numpy()
    d = a["computed"].to_numpy() - b["computed"].to_numpy()
    m = np.stack([np.ones_like(t), t], axis=1)
    d = d - m @ np.linalg.lstsq(m, d, rcond=None)[0]
    return float(np.sqrt(np.mean(d ** 2)))


def _tle(summary):
    from trackproc.io.tle import parse_tle

    lines = (summary.get("refused") or {}).get("fitted_tle") or summary["tle"]
    return parse_tle("\n".join(lines))


def covariance_rows(dev: bool = True, model_error=None, protocols=("held-back", "next"), fits=None):
    """Held-back and next-group passes: the fitted TLE's Doppler prediction error (the orbit's
    share, ``sqrt(rms^2 - noise^2)``, noise the RMS of a fit to that pass itself) against the
    spread its covariance predicts there (the written, prediction covariance and the one without
    SGP4's theory error); their ratio is the normalised error.

    ``fits``: {tuple of fitted pass names: FitTleResult} made with the default options (refusal
    on) and ``model_error`` None, used instead of fitting again (tests/cli/test_fit_tle.py shares
    its held-back fits): a refused fit's summary keeps the fitted TLE and the two terms of its
    prediction covariance (``estimation_covariance`` + ``model_error.element_covariance``, the
    matrix ``--no-refusal`` writes, bit for bit), so the rows are the same; only ``verdict`` is
    then the refusing run's."""
    rows = []
    allg = evenings()
    pairs = []
    for g in [g for g in allg if is_dev(g[0]) == dev]:
        pairs.append(("held-back", g[:-1], g[-1]))
        k = allg.index(g)
        if k + 1 < len(allg):
            nxt = allg[k + 1][0]
            gap = dt.datetime.strptime(nxt, "%Y%m%d%H%M") - dt.datetime.strptime(g[-1], "%Y%m%d%H%M")
            if gap.total_seconds() < 86400 and is_dev(nxt) == dev:
                pairs.append(("next", g, nxt))
    opts = FitTleOptions(model_error=model_error, refusal=False)
    for protocol, fit, target in [p for p in pairs if p[0] in protocols]:
        if fits is not None and model_error is None and tuple(fit) in fits:
            res = fits[tuple(fit)]
        else:
            tables = [(s, _load(s)[0]) for s in fit]
            res = fit_tle(tables, [], OrbitInput(tle=metadata_tle(tables), source="metadata"), opts, EOP)
        held = _load(target)[0]
        own = fit_tle([(target, held)], [], OrbitInput(tle=metadata_tle([(target, held)]), source="metadata"),
                      FitTleOptions(refusal=False, model_error=0.0, apriori_model="refine"), EOP)   # its own curve
        noise = own.summary["groups"][0]["rms"]
        fitted = _rms(held, _tle(res.summary))
        share = _curve_difference(held, _tle(res.summary), _tle(own.summary))
        own_sigma = doppler_spread(held, own.summary, own.summary["covariance_without_model_error"])
        me = res.summary["model_error"]
        written = (np.array(res.summary["estimation_covariance"]) + np.array(me["element_covariance"])
                   if res.summary["refused"] else res.summary["covariance"]["matrix"])   # as --no-refusal writes it
        a = doppler_partials(held, res.summary)                 # the fit's three covariances share them
        rows.append({"protocol": protocol, "predicted": target, "fitted_passes": len(fit),
                     "noise_hz": round(noise, 2), "fitted_hz": round(fitted, 2), "orbit_share_hz": round(share, 2),
                     "own_fit_sigma_hz": round(own_sigma, 2),
                     "sigma_hz": round(float(np.hypot(spread(a, written), own_sigma)), 2),
                     "sigma_without_model_error_hz": round(float(np.hypot(spread(
                         a, res.summary["covariance_without_model_error"]), own_sigma)), 2),
                     "sigma_model_error_only_hz": round(spread(a, me["element_covariance"]), 2),
                     "verdict": res.quality.verdict})
        rows[-1]["normalised"] = round(rows[-1]["orbit_share_hz"] / rows[-1]["sigma_hz"], 2)
        print(json.dumps(rows[-1]), flush=True)
    for protocol in ("held-back", "next"):
        z = np.array([r["normalised"] for r in rows if r["protocol"] == protocol])
        z0 = np.array([r["orbit_share_hz"] / r["sigma_without_model_error_hz"] for r in rows
                       if r["protocol"] == protocol])
        if z.size:
            print(f"{protocol}: RMS normalised error {np.sqrt(np.mean(z ** 2)):.3g} over {z.size} "
                  f"(without the model error {np.sqrt(np.mean(z0 ** 2)):.3g})")
    return rows


_OWN = {}


def honesty_rows(options=None, dev: bool = True, horizon_h: float = 30.0):
    """The extended development pairs (:func:`pairs`): per pair, the orbit error of the fitted
    TLE's prediction and of the initial TLE's (each curve against a least-squares fit to the
    predicted pass itself, offset and drift removed) and the spread each one's covariance
    predicts there (fit: ``covariance``; initial: ``initial_covariance``, its a-priori + Q), plus
    the self-fit's own estimation spread."""
    from trackproc.io.tle import parse_tle

    options = options or FitTleOptions()
    allp = [s for v in visits(dev) for s in v]
    rows = []
    for v in visits(dev):
        for fit in [v[i:j] for i in range(len(v)) for j in range(i + 1, len(v) + 1)]:
            targets = [s for s in allp if 0 < (_stamp_time(s) - _stamp_time(fit[-1])).total_seconds() <= horizon_h * 3600]
            if not targets:
                continue
            initial, res = _fit(fit, FitTleOptions(**{**options.__dict__, "refusal": False}))
            summ = res.summary
            init_summary = {"elements": summ["initial_elements"], "tle": summ["tle"], "refused": None}
            for target in targets:
                held = _load(target)[0]
                if target not in _OWN:
                    own = fit_tle([(target, held)], [], OrbitInput(tle=metadata_tle([(target, held)]), source="metadata"),
                                  FitTleOptions(refusal=False, model_error=0.0, apriori_model="refine"), EOP)
                    _OWN[target] = (own, doppler_spread(held, own.summary, own.summary["covariance_without_model_error"]))
                own, own_sigma = _OWN[target]
                row = {"fit": fit, "predicted": target,
                       "hours": round((_stamp_time(target) - _stamp_time(fit[-1])).total_seconds() / 3600, 1),
                       "fitted_hz": round(_rms(held, _tle(summ)), 2), "tle_hz": round(_rms(held, initial), 2),
                       "e_fit": _curve_difference(held, _tle(summ), _tle(own.summary)),
                       "e_init": _curve_difference(held, initial, _tle(own.summary)),
                       "s_fit": float(np.hypot(doppler_spread(held, summ, summ["covariance"]["matrix"]), own_sigma)),
                       "s_init": float(np.hypot(doppler_spread(held, init_summary, summ["initial_covariance"]),
                                                own_sigma))}
                rows.append(row)
    z_fit = np.array([r["e_fit"] / r["s_fit"] for r in rows])
    z_init = np.array([r["e_init"] / r["s_init"] for r in rows])
    for name, sel in (("all", lambda r: True), ("< 4 h", lambda r: r["hours"] < 4), (">= 4 h", lambda r: r["hours"] >= 4)):
        m = np.array([sel(r) for r in rows])
        if m.any():
            ratio = np.array([r["fitted_hz"] / r["tle_hz"] for r in rows])[m]
            print(f"{name}: {m.sum()} pairs; RMS e/sigma fitted {np.sqrt(np.mean(z_fit[m] ** 2)):.2f}, initial "
                  f"{np.sqrt(np.mean(z_init[m] ** 2)):.2f}; RMS orbit error fitted "
                  f"{np.sqrt(np.mean([r['e_fit'] ** 2 for r, k in zip(rows, m) if k])):.2f} Hz, initial "
                  f"{np.sqrt(np.mean([r['e_init'] ** 2 for r, k in zip(rows, m) if k])):.2f} Hz; fitted <= initial "
                  f"{(ratio <= 1).sum()}, geometric mean ratio {np.exp(np.mean(np.log(ratio))):.3f}", flush=True)
    e2 = np.array([r["e_fit"] ** 2 for r in rows] + [r["e_init"] ** 2 for r in rows])
    v = np.array([r["s_fit"] ** 2 for r in rows] + [r["s_init"] ** 2 for r in rows])
    print(f"-2 log L (fitted and initial predictions) {np.sum(np.log(v) + e2 / v):.2f}", flush=True)
    return rows


def calibrate(scales=(2.0, 3.4, 5.0)):
    """The model error's scale from the development days: the maximum over a grid of scales ``s``
    of the Gaussian likelihood ``−Σ (log σ² + e²/σ²)`` of the orbit errors ``e`` of the fitted and
    the initial TLE's predictions on the 68 development pairs (:func:`honesty_rows`) given the
    spread ``σ(s)`` their covariances predict (about two minutes a scale). Measured: 781, 669,
    677 at 2, 3.4, 5 (docs/fit-tle.md "Covariance")."""
    best = None
    for s in scales:
        rows = honesty_rows(FitTleOptions(model_error=s))
        e2 = np.array([r["e_fit"] ** 2 for r in rows] + [r["e_init"] ** 2 for r in rows])
        v = np.array([r["s_fit"] ** 2 for r in rows] + [r["s_init"] ** 2 for r in rows])
        nll = float(np.sum(np.log(v) + e2 / v))
        print(f"scale {s}: -2 log L {nll:.2f}", flush=True)
        if best is None or nll < best[1]:
            best = (s, nll)
    print(f"maximum-likelihood model-error scale (a-priori sigmas) over the development pairs: {best[0]}")
    return best[0]


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "dev"
    if which in ("dev", "both"):
        table(True)
    if which in ("holdout", "both"):
        table(False)
    if which == "covariance":
        covariance_rows(True)
    if which == "covariance-holdout":
        covariance_rows(False)
    if which == "calibrate":
        calibrate()
    if which == "pairs":
        pairs()
    if which == "pairs-holdout":
        pairs(dev=False)
    if which == "verdicts":
        verdicts(True)
    if which == "verdicts-holdout":
        verdicts(False)
    if which == "tle-apriori":
        tle_apriori()
    if which == "timing":
        timing()
    if which == "upstream-tca":
        upstream_tca()
