"""DopTrack Delfi-C3 (../shared/realdata): does a refined or estimated orbit predict a pass better than the TLE?

Two tables (and a timing split of the first), each for the development passes (1-10 April 2020) and the hold-out (11-15 April,
never used while developing):

* ``refine`` (defaults: the noise model chosen per pass by REML, GLS): pass A refined from its
  own TLE, propagated (Taylor, J2) to the next pass B of the same day (< 4 h), Doppler RMS of B
  after B's own offset and drift, against the TLE's SGP4 prediction. Also the dynamics
  mismatch: the TLE's own state at A propagated with J2 instead of SGP4 (ratio to SGP4).
* ``estimate`` (defaults, --doppler-bias offset+drift, the TLE state with the refine default
  a-priori covariance, --apriori-initial): every pass of one evening but the last; the last
  pass is held back and predicted.

A pair counts as "not worse" when the ratio (ours / TLE) is <= 1.1. Usage:
``PYTHONPATH=src python benchmarks/doptrack_prediction.py [dev|holdout|both] [OSCILLATOR_NOISE]``
(a few minutes; the optional second argument is refine's ``--oscillator-noise``).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))  # test_refine_realdata

import numpy as np  # noqa: E402

from test_refine_realdata import (EOP, _load, _pairs, _predicted_rms, evenings,  # noqa: E402
                                  estimate_held_back, is_dev, timing_split)
from trackproc.io.tle import tle_state  # noqa: E402
from trackproc.pipeline.refine import RefineOptions, prepare, refine  # noqa: E402


def refine_table(dev: bool):
    rows, timing = [], []
    for a, b in _pairs():
        if is_dev(a) != dev:
            continue
        ta, tle = _load(a)
        tb, _ = _load(b)
        t0 = time.process_time()
        res = refine(ta, tle_state(tle, eop=EOP), None, RefineOptions(oscillator_noise=OSCILLATOR), EOP, source=a)
        cpu = time.process_time() - t0
        tle_hz = _predicted_rms(tb, res.state, tle)
        ours = _predicted_rms(tb, res.state)
        stale = prepare(ta, tle_state(tle, eop=EOP), None, RefineOptions(), EOP, source=a).initial
        j2 = _predicted_rms(tb, stale)
        d = res.state.diagnostics
        n = d.get("noise", {})
        refused = bool(d.get("refused"))
        # a refusal keeps the TLE's state: it counts as equal (as tests/pipeline/test_refine_realdata.py)
        rows.append((a, b, d["max_elevation_deg"], tle_hz, ours, 1.0 if refused else ours / tle_hz, j2 / tle_hz,
                     n.get("transmitter", "?") + "/" + n.get("model", "?"), n.get("effective_samples", np.nan), cpu,
                     "refused" if refused else res.quality.verdict))
        timing.append((a, timing_split(ta, res.state, tle)[2], *timing_split(tb, res.state, tle),
                       *timing_split(tb, res.state)))
    print(f"refine, {'development (1-10 April)' if dev else 'HOLD-OUT (11-15 April)'}")
    print(f"{'pass':>13} {'next':>13} {'elev':>5} {'TLE Hz':>7} {'ours Hz':>7} {'ratio':>6} {'J2/SGP4':>7} "
          f"{'model':>26} {'n_eff':>7} {'cpu s':>5} verdict")
    for r in rows:
        print(f"{r[0]:>13} {r[1]:>13} {r[2]:5.1f} {r[3]:7.2f} {r[4]:7.2f} {r[5]:6.2f} {r[6]:7.2f} {r[7]:>26} "
              f"{r[8]:7.1f} {r[9]:5.2f} {r[10]}")
    ratio = np.array([r[5] for r in rows])
    print(f"  {int((ratio <= 1.1).sum())} of {ratio.size} not worse than the TLE by > 10 %; median ratio "
          f"{np.median(ratio):.3f} (a refusal counts as 1); dynamics mismatch (TLE state, J2 vs SGP4) median "
          f"{np.median([r[6] for r in rows]):.3f}, max {max(r[6] for r in rows):.3f}")
    # How much of the next pass's error is timing: its RMS after the best time shift of each prediction
    # (an along-track error and the station's time tags look alike), and the pass's own shift.
    print("  timing: shift of the pass and of the next pass against the TLE, of the next pass against ours; "
          "RMS of the next pass after each prediction's best shift")
    print(f"  {'pass':>13} {'shift s':>7} {'next: TLE s':>11} {'ours s':>7} {'TLE Hz':>7} {'ours Hz':>7}")
    for a, s_a, _, tle_after, s_b, _, ours_after, s_ours in timing:
        print(f"  {a:>13} {s_a:7.2f} {s_b:11.2f} {s_ours:7.2f} {tle_after:7.2f} {ours_after:7.2f}")
    after = np.array([t[6] / t[3] for t in timing])
    s_a, s_b = np.array([t[1] for t in timing]), np.array([t[4] for t in timing])
    print(f"  after the shift ours/TLE: median {np.median(after):.3f}, range {after.min():.3f}-{after.max():.3f}; "
          f"the next pass's shift: median |TLE| {np.median(np.abs(s_b)):.2f} s, |ours| "
          f"{np.median(np.abs([t[7] for t in timing])):.2f} s; correlation of the two passes' shifts "
          f"{np.corrcoef(s_a, s_b)[0, 1]:.2f}\n")
    return ratio


def estimate_table(dev: bool):
    rows = []
    for group in evenings():
        if is_dev(group[0]) != dev:
            continue
        tle_hz, ours, res = estimate_held_back(group)
        noise = res.state.diagnostics.get("noise", {})
        rows.append((",".join(group[:-1]), group[-1], tle_hz, ours, ours / tle_hz,
                     ",".join(v["model"] for v in noise.values())))
    print(f"estimate with a held-back pass, {'development' if dev else 'HOLD-OUT'}")
    for r in rows:
        print(f"  fit {r[0]:>27}  held back {r[1]}: TLE {r[2]:6.2f} Hz, ours {r[3]:6.2f} Hz, ratio {r[4]:.2f} ({r[5]})")
    ratio = np.array([r[4] for r in rows])
    print(f"  {int((ratio <= 1.2).sum())} of {ratio.size} within 1.2x the TLE; median ratio {np.median(ratio):.3f}, "
          f"max {ratio.max():.3f}\n")
    return ratio


#: ``--oscillator-noise`` for the refine table (None: estimated per pass, the default)
OSCILLATOR = None

if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "both"
    if len(sys.argv) > 2:
        OSCILLATOR = float(sys.argv[2])
    for dev in ([True] if which == "dev" else [False] if which == "holdout" else [True, False]):
        refine_table(dev)
        estimate_table(dev)
