"""DopTrack Delfi-C3 (../shared/realdata): is a refined orbit ever worse than the TLE the user had?

For every pair (pass A, the same evening's next pass B), ``refine`` A with its defaults from

* ``fresh``: A's own TLE (hours old, from A's metadata), and
* ``stale``: the TLE of the latest pass at least 7 days before A (7-8 days older than the pass),

then predict B (Taylor, J2) and score B's Doppler RMS after B's own offset and drift against the
same TLE's SGP4 prediction of B. A decision that keeps the TLE (``kept``, ``declined``, ``refused``)
counts as the TLE's answer (ratio 1). Also the covariance realism of each written state (a kept or
declined TLE with its stated accuracy): B's time offset against its prediction (fitted as a time
shift) over the sigma its covariance predicts for it, B's own time-tag sigma beside it (``z``; its
RMS should be about 1).

Development: 1-10 April 2020; hold-out: 11-15 April (never used while developing). Usage:
``PYTHONPATH=src python benchmarks/doptrack_never_worse.py [dev|holdout|both] [fresh|stale|both] [HORIZON_DAYS]
[STALE_DAYS] [REPLACE_PROBABILITY|-] [TIME_SIGMA_S|-] [evening|day]`` (refine's ``--horizon``, default 1;
the stale TLE's minimum age, default 7; the replace rule's probability, default the code's; the
station's time-tag sigma, default the station's own (io/doptrack.py); ``day`` pairs each pass with
the next pass of the same set within 30 h instead of the same evening's, more pairs for a stale TLE).
"""

from __future__ import annotations

import datetime as dt
import math
import os
import sys
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))

import numpy as np  # noqa: E402

from test_refine_realdata import BAD_PASSES, EOP, _load, _pairs, _predicted_rms, is_dev, timing_split  # noqa: E402
from trackproc.dynamics import propagator  # noqa: E402
from trackproc.dynamics.rtn import rtn_jacobian  # noqa: E402
from trackproc.io.tle import tle_state  # noqa: E402
from trackproc.pipeline.refine import RefineOptions, refine  # noqa: E402

STALE_DAYS = 7.0


def _stamp_time(stamp: str) -> dt.datetime:
    return dt.datetime.strptime(stamp, "%Y%m%d%H%M")


def stale_tle_for(stamp: str, stamps: list):
    """The TLE of the latest pass at least :data:`STALE_DAYS` before ``stamp`` (None if none)."""
    t = _stamp_time(stamp)
    older = [s for s in stamps if (t - _stamp_time(s)).total_seconds() >= STALE_DAYS * 86400.0]
    return _load(max(older))[1] if older else None


def _day_pairs(stamps: list) -> list:
    """Each good pass and the next one within 30 h (the issue's pairs are the same evening's)."""
    good = [s for s in stamps if s not in BAD_PASSES]
    return [(a, b) for a, b in zip(good[:-1], good[1:])
            if (_stamp_time(b) - _stamp_time(a)).total_seconds() <= 30 * 3600.0]


def time_offset_z(table_b, state, time_sigma_s=None):
    """B's time offset against the prediction of ``state`` (s, fit-tle's sign) over the sigma the
    state's covariance gives the along-track position at B's middle (divided by the speed), with B's
    own time-tag sigma (``time_sigma_s``: the station's, when stated) beside it: B's offset is the
    prediction's error plus B's own time-tag error."""
    _, _, shift = timing_split(table_b, state)
    t_mid = table_b.frame["time"].iloc[len(table_b.frame) // 2]
    t_s = float((np.datetime64(t_mid.tz_convert("UTC").tz_localize(None), "ns") - np.datetime64(state.epoch, "ns"))
                / np.timedelta64(1, "s"))
    traj = propagator.propagate(state.r_m, state.v_m_s, state.epoch, [0.0, t_s], force="j2", eop=EOP, stm=True)
    phi = np.asarray(traj.stm(np.array([t_s])), float).reshape(6, 6)
    x = np.asarray(traj.state(np.array([t_s])), float).reshape(6)
    along = rtn_jacobian(x[:3], x[3:6], rotating=False)[1]
    cov = phi @ np.asarray(state.covariance, float)[:6, :6] @ phi.T
    sigma_s = math.sqrt(max(float(along @ cov @ along), 0.0) / float(x[3:6] @ x[3:6]) + (time_sigma_s or 0.0) ** 2)
    return shift / sigma_s if sigma_s > 0 else math.nan, shift, sigma_s


def pass_pairs(dev: bool, pairs: str) -> tuple:
    """``(stamps, [(a, b), ...])``: every pass's stamp, and the pairs (``evening`` or ``day``) of
    the development (``dev``) or hold-out set."""
    stamps = sorted(p.stem.rsplit("_", 1)[-1] for p in
                    (Path(__file__).resolve().parents[2] / "shared" / "realdata" / "doptrack-delfic3" / "data")
                    .glob("Delfi-C3_32789_*.csv"))
    chosen = [(a, b) for a, b in (_day_pairs(stamps) if pairs == "day" else _pairs())
              if is_dev(a) == dev and is_dev(b) == dev]
    return stamps, chosen


def table(dev: bool, which: str):
    stamps, pairs = pass_pairs(dev, PAIRS)
    rows = []
    for a, b in pairs:
        ta, fresh = _load(a)
        tb, _ = _load(b)
        tle = fresh if which == "fresh" else stale_tle_for(a, stamps)
        if tle is None:
            continue
        t0 = time.process_time()
        try:
            res = refine(ta, tle_state(tle, eop=EOP), None,
                         RefineOptions(horizon_days=HORIZON, time_tag_sigma_s=TIME_SIGMA), EOP, source=a)
        except Exception as exc:      # a failure keeps the TLE as well: say it
            rows.append((a, b, math.nan, math.nan, 1.0, f"failed: {type(exc).__name__}", math.nan, 0.0))
            continue
        cpu = time.process_time() - t0
        tle_hz = _predicted_rms(tb, res.state, tle)
        ours = _predicted_rms(tb, res.state)
        d = res.state.diagnostics
        action = (d.get("decision") or {}).get("action") or ("refused" if d.get("refused") else "replaced")
        keeps = bool(d.get("refused"))
        b_sigma = TIME_SIGMA if TIME_SIGMA is not None else (d.get("time_tag_consider") or {}).get("sigma_s")  # the station's
        # every written state has a covariance (a kept or declined TLE: its stated accuracy)
        z = time_offset_z(tb, res.state, b_sigma)[0] if res.state.covariance is not None else math.nan
        rows.append((a, b, tle_hz, ours, 1.0 if keeps else ours / tle_hz, f"{action}/{res.quality.verdict}", z, cpu))
    title = f"refine from the {which} TLE, {'development (1-10 April)' if dev else 'HOLD-OUT (11-15 April)'}"
    print(title)
    if not rows:
        print(f"  no pair has a TLE at least {STALE_DAYS:g} days older than its pass")
        return rows
    print(f"{'pass':>13} {'next':>13} {'TLE Hz':>7} {'ours Hz':>7} {'ratio':>6} {'z':>6} {'cpu s':>5} decision/verdict")
    for r in rows:
        print(f"{r[0]:>13} {r[1]:>13} {r[2]:7.2f} {r[3]:7.2f} {r[4]:6.2f} {r[6]:6.2f} {r[7]:5.2f} {r[5]}")
    ratio = np.array([r[4] for r in rows])
    zs = np.array([r[6] for r in rows if math.isfinite(r[6]) and r[5].startswith("replaced")])
    z_all = np.array([r[6] for r in rows if math.isfinite(r[6])])
    print(f"  {int((ratio <= 1.1).sum())} of {ratio.size} within 1.10x of the TLE, {int((ratio > 2).sum())} beyond 2x, "
          f"{int((ratio < 1.0).sum())} better; median ratio {np.median(ratio):.3f}; worse by > 10 %: "
          f"{int((ratio > 1.1).sum())}; replaced {zs.size}, RMS z {math.sqrt(np.mean(zs ** 2)) if zs.size else math.nan:.2f}, "
          f"RMS z of every written state {math.sqrt(np.mean(z_all ** 2)) if z_all.size else math.nan:.2f} ({z_all.size}); "
          f"CPU median {np.median([r[7] for r in rows]):.2f} s, max {max(r[7] for r in rows):.2f} s")
    return rows


HORIZON = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
#: the station's time-tag sigma (s; refine's --time-tag-sigma, a stations table's time_sigma_s): None = none
TIME_SIGMA = float(sys.argv[6]) if len(sys.argv) > 6 and sys.argv[6] != "-" else None
PAIRS = sys.argv[7] if len(sys.argv) > 7 else "evening"
if len(sys.argv) > 5 and sys.argv[5] != "-":          # the replace threshold (methods/estimation/decision.py), for studies
    from trackproc.methods.estimation import decision as _dm

    _dm.REPLACE_PROBABILITY = float(sys.argv[5])
STALE_DAYS = float(sys.argv[4]) if len(sys.argv) > 4 else STALE_DAYS

if __name__ == "__main__":
    sets = {"dev": [True], "holdout": [False], "both": [True, False]}[sys.argv[1] if len(sys.argv) > 1 else "dev"]
    kinds = {"fresh": ["fresh"], "stale": ["stale"], "both": ["fresh", "stale"]}[sys.argv[2] if len(sys.argv) > 2
                                                                                  else "both"]
    for k in kinds:
        for dev in sets:
            table(dev, k)
            print()
