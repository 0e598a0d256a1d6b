"""DopTrack Delfi-C3 (../shared/realdata), ``trackproc filter`` sequentially over an evening: every
pass but the last filtered from the first pass's TLE with the transmitter's offset a random walk
(``--oscillator-noise``), the held-back last pass predicted from the last filtered state; the
score is that pass's Doppler RMS after its own offset and drift against the TLE's prediction
(``tests/pipeline/test_filter_doptrack.filter_held_back``, on the score of
``benchmarks/doptrack_prediction.py``'s estimate table). Target: ratio <= 1.2.

Usage: ``PYTHONPATH=src python benchmarks/doptrack_filter.py [--noise auto|white] [dev|holdout] [OSCILLATOR_NOISE ...]``
(development days 1-10 April; the hold-out 11-15 April is run once, at the end).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))

import numpy as np  # noqa: E402

from test_filter_doptrack import NOISE, OSCILLATOR_NOISE, filter_held_back  # noqa: E402
from test_refine_realdata import evenings, is_dev  # noqa: E402


def table(dev: bool, oscillator_noise: float, noise: str = NOISE):
    rows = []
    for group in evenings():
        if is_dev(group[0]) != dev:
            continue
        t0 = time.process_time()
        tle_hz, ours, res = filter_held_back(group, oscillator_noise, noise=noise)
        f = res.state.extra["filter"]
        models = ",".join(v["model"] for v in (res.state.diagnostics or {}).get("noise", {}).values()) or "-"
        d = (res.state.diagnostics or {}).get("decision") or {}
        said = d.get("action", "-") + (f" {d['probability_better']:.2f}" if d.get("probability_better") is not None
                                       else "")
        rows.append((",".join(group[:-1]), group[-1], tle_hz, ours, ours / tle_hz, res.quality.verdict,
                     ",".join(r["code"] for r in res.quality.reasons if r["severity"] != "ok"),
                     time.process_time() - t0, f["edited"] / max(f["edited"] + f["updates"], 1), models, said))
    print(f"filter, --noise {noise}, oscillator noise {oscillator_noise:g} Hz/sqrt(s), {'development (1-10 April)' if dev else 'HOLD-OUT (11-15 April)'}")
    for r in rows:
        print(f"  fit {r[0]:>27}  held back {r[1]}: TLE {r[2]:6.2f} Hz, ours {r[3]:6.2f} Hz, ratio {r[4]:.2f} "
              f"({r[5]} {r[6]}; decision {r[10]}; edited {r[8]:.0%}; noise {r[9]}; {r[7]:.1f} s CPU)")
    ratio = np.array([r[4] for r in rows])
    print(f"  {int((ratio <= 1.2).sum())} of {ratio.size} within 1.2x the TLE; median ratio {np.median(ratio):.3f}, "
          f"max {ratio.max():.3f}\n")
    return ratio


if __name__ == "__main__":
    args = sys.argv[1:]
    noise = NOISE
    if "--noise" in args:
        i = args.index("--noise")
        noise = args[i + 1]
        del args[i:i + 2]
    which = args[0] if args else "dev"
    values = [float(v) for v in args[1:]] or [OSCILLATOR_NOISE]
    for value in values:
        table(which != "holdout", value, noise)
