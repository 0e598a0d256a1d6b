"""DopTrack Delfi-C3 (../shared/realdata): does a TLE fitted by ``fit-tle`` predict a pass better
than the TLE it started from? (issue 18's criterion; numbers in docs/fit-tle.md and the README)

Two protocols, each for the development passes (1-10 April 2020) and the hold-out (11-15 April,
never used while developing):

* ``held-back``: every pass of an evening (passes < 4 h apart) but the last fitted from the
  metadata TLE (the newest of those passes, defaults: offset+drift per pass, a-priori, B* fitted),
  the last pass (~95 min later) predicted.
* ``next``: every pass of an evening fitted, the first pass of the next group (the next
  morning or evening, < 24 h) predicted.

Both against the initial TLE's SGP4 prediction; "pred" is also compared with the TLE stored in
the predicted pass's own metadata (newer, when the station had updated it). RMS in Hz of the
predicted pass's Doppler after that pass's own offset and drift (``compare``). Usage:
``PYTHONPATH=src python benchmarks/fit_tle_doptrack.py [dev|holdout|both|covariance]`` (about a
minute; ``covariance``: :func:`covariance_check`, development evenings only).
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
            "fitted_hz": round(_rms(table, res.tle), 2), "own_tle_hz": round(_rms(table, own), 2),
            "quality": res.quality.verdict}


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
    return out




def covariance_check():
    """Development evenings only: does the fitted elements' covariance cover the prediction error
    of the held-back pass? Its Doppler spread there (20 draws from the covariance, each pass's
    offset and drift removed) against the orbit's share of the prediction RMS,
    ``sqrt(rms_fitted^2 - noise^2)``, the noise being the RMS of a fit to that pass itself."""
    from trackproc.io.tle import satrec
    from trackproc.methods import tle_fit as tf
    from trackproc.pipeline.compare import fit_trend

    for g in [g for g in evenings() if is_dev(g[0])]:
        tables = [(s, _load(s)[0]) for s in g[:-1]]
        res = fit_tle(tables, [], OrbitInput(tle=metadata_tle(tables), source="metadata"), FitTleOptions(), EOP)
        held = _load(g[-1])[0]
        own = fit_tle([(g[-1], held)], [], OrbitInput(tle=metadata_tle([(g[-1], held)]), source="metadata"),
                      FitTleOptions(), EOP)
        noise = own.summary["groups"][0]["rms"]
        x = np.array(list(res.summary["elements"].values()))
        chol = np.linalg.cholesky(np.array(res.summary["covariance"]["matrix"]) + 1e-30 * np.eye(7))
        sat = satrec(res.tle)
        ep = tf.Epoch(0, sat.jdsatepoch, sat.jdsatepochF)
        base, _ = compare(held, OrbitInput(tle=tf.satrec_of(x, ep)), CompareOptions(remove="none"), EOP)
        t = (base["time"] - base["time"].min()).dt.total_seconds().to_numpy()
        rng = np.random.default_rng(0)
        spread = []
        for _ in range(20):
            r, _ = compare(held, OrbitInput(tle=tf.satrec_of(x + chol @ rng.normal(size=7), ep)),
                           CompareOptions(remove="none"), EOP)
            _, after = fit_trend(t, r["computed"].to_numpy() - base["computed"].to_numpy(),
                                 base["sigma"].to_numpy(), "offset+drift")
            spread.append(float(np.mean(after ** 2)))
        fitted = _rms(held, res.tle)
        print(json.dumps({"predicted": g[-1], "noise_hz": round(noise, 2), "fitted_hz": round(fitted, 2),
                          "orbit_share_hz": round(float(np.sqrt(max(fitted ** 2 - noise ** 2, 0.0))), 2),
                          "covariance_hz": round(float(np.sqrt(np.mean(spread))), 2)}))


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "dev"
    if which in ("dev", "both"):
        table(True)
    if which in ("holdout", "both"):
        table(False)
    if which == "covariance":
        covariance_check()
