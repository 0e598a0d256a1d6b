"""DopTrack Delfi-C3 (../shared/realdata): does a TLE fitted by ``fit-tle`` predict a pass better
than the TLE it started from? (issue 18's criterion; numbers in docs/fit-tle.md and the README)

Two protocols, each for the development passes (1-10 April 2020) and the hold-out (11-15 April,
never used while developing; evaluated twice, each time once at the end):

* ``held-back``: every pass of an evening (passes < 4 h apart) but the last fitted from the
  metadata TLE (the newest of those passes, defaults: offset+drift per pass, a-priori, B* fitted),
  the last pass (~95 min later) predicted.
* ``next``: every pass of an evening fitted, the first pass of the next group (the next
  morning or evening, < 24 h) predicted.

Both against the initial TLE's SGP4 prediction; "pred" is also compared with the TLE stored in
the predicted pass's own metadata (newer, when the station had updated it). RMS in Hz of the
predicted pass's Doppler after that pass's own offset and drift (``compare``); "fitted" is
the fit (written or refused), "written" what ``-o`` gets. Usage:
``PYTHONPATH=src python benchmarks/fit_tle_doptrack.py [dev|holdout|both|covariance|covariance-holdout|calibrate]``
(about a minute each; ``covariance``: :func:`covariance_rows`, the written covariance against the
prediction errors, development evenings; ``covariance-holdout`` the same on the hold-out, run
once at the end; ``calibrate``: :func:`calibrate`, the theory error's scale, development only,
about two minutes).
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


def _row(fit, target):
    tables = [(s, _load(s)[0]) for s in fit]
    initial = metadata_tle(tables)
    res = fit_tle(tables, [], OrbitInput(tle=initial, source="metadata"), FitTleOptions(), EOP)
    table = _load(target)[0]
    own = tle_from_pass_metadata(table)
    return {"fit": fit, "predicted": target, "tle_hz": round(_rms(table, initial), 2),
            "fitted_hz": round(_rms(table, _tle(res.summary)), 2), "written_hz": round(_rms(table, res.tle), 2),
            "own_tle_hz": round(_rms(table, own), 2), "quality": res.quality.verdict,
            "refused": (res.summary["refused"] or {}).get("code")}


def table(dev: bool):
    groups = [g for g in evenings() if is_dev(g[0]) == dev]
    allg = evenings()
    out = {"held-back": [], "next": []}
    for g in groups:
        out["held-back"].append(_row(g[:-1], g[-1]))
        k = allg.index(g)
        if k + 1 < len(allg):
            nxt = allg[k + 1][0]
            gap = (dt.datetime.strptime(nxt, "%Y%m%d%H%M") - dt.datetime.strptime(g[-1], "%Y%m%d%H%M"))
            if gap.total_seconds() < 86400 and is_dev(nxt) == dev:
                out["next"].append(_row(g, nxt))
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
    a = a - b @ np.linalg.lstsq(b, a, rcond=None)[0]          # offset and drift removed
    return float(np.sqrt(np.trace(a @ np.asarray(matrix) @ a.T) / len(t)))


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


def covariance_rows(dev: bool = True, model_error=None, protocols=("held-back", "next")):
    """Held-back and next-group passes: the fitted TLE's Doppler prediction error (the orbit's
    share, ``sqrt(rms^2 - noise^2)``, noise the RMS of a fit to that pass itself) against the
    spread its covariance predicts there (the written, prediction covariance and the one without
    SGP4's theory error); their ratio is the normalised error."""
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
        tables = [(s, _load(s)[0]) for s in fit]
        res = fit_tle(tables, [], OrbitInput(tle=metadata_tle(tables), source="metadata"), opts, EOP)
        held = _load(target)[0]
        own = fit_tle([(target, held)], [], OrbitInput(tle=metadata_tle([(target, held)]), source="metadata"),
                      FitTleOptions(refusal=False, model_error=0.0), EOP)       # the pass's own curve, by LS
        noise = own.summary["groups"][0]["rms"]
        fitted = _rms(held, _tle(res.summary))
        share = _curve_difference(held, _tle(res.summary), _tle(own.summary))
        own_sigma = doppler_spread(held, own.summary, own.summary["covariance_without_model_error"])
        me = res.summary["model_error"]
        rows.append({"protocol": protocol, "predicted": target, "fitted_passes": len(fit),
                     "noise_hz": round(noise, 2), "fitted_hz": round(fitted, 2), "orbit_share_hz": round(share, 2),
                     "own_fit_sigma_hz": round(own_sigma, 2),
                     "sigma_hz": round(float(np.hypot(doppler_spread(held, res.summary, res.summary["covariance"][
                         "matrix"]), own_sigma)), 2),
                     "sigma_without_model_error_hz": round(float(np.hypot(doppler_spread(
                         held, res.summary, res.summary["covariance_without_model_error"]), own_sigma)), 2),
                     "sigma_model_error_only_hz": round(doppler_spread(held, res.summary, me["element_covariance"]), 2),
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


def calibrate(scales=(1.0, 1.5, 2.0, 2.8, 4.0, 5.6)):
    """The model error's scale from the development evenings (held-back and next passes): the
    maximum of the Gaussian likelihood of each pass's orbit error ``e`` given the spread ``σ(s)``
    the covariance predicts, ``−Σ (log σ² + e²/σ²)``, over a grid of scales ``s``."""
    best = None
    for s in scales:
        rows = covariance_rows(True, model_error=s)
        e2 = np.array([r["orbit_share_hz"] ** 2 for r in rows])
        v = np.array([r["sigma_hz"] ** 2 for r in rows])
        nll = float(np.sum(np.log(v) + e2 / v))
        print(f"scale {s}: -2 log L {nll:.2f}", flush=True)
        if best is None or nll < best[1]:
            best = (s, nll)
    print(f"maximum-likelihood model-error scale (a-priori sigmas) over the development passes: {best[0]}")
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
