"""DopTrack Delfi-C3 (../shared/realdata): does ``fit-tle`` from an OLD TLE (7 or more days before
the evening) over an evening's passes predict the NEXT DAY's passes better than that old TLE?
(issue 31 item 5; numbers in docs/fit-tle.md "From an old TLE")

* evenings: groups of two or more consecutive passes < 4 h apart (``test_refine_realdata.evenings``);
* old TLE: the newest catalogue TLE (of all the passes' metadata) whose epoch is at least
  ``doptrack_never_worse.STALE_DAYS`` (7) days before the evening's first pass;
* predicted: every pass more than 4 h and at most 30 h after the evening's last pass (the next
  day's); score: its Doppler RMS after its own offset and drift (``compare``, as
  ``fit_tle_doptrack``), from the TLE ``fit-tle`` writes (and the fit, written or refused) against
  the old TLE's.

Development: evening and predicted passes all within 1-10 April; the hold-out is every other pair
(a predicted pass on 11-15 April), evaluated once at the end. Usage:
``PYTHONPATH=src python benchmarks/fit_tle_stale.py [dev|holdout|both] [fresh]`` (``fresh``: the
newest metadata TLE of the evening instead, the refusal check; ``every``: every catalogue TLE 7-10
days older than the evening, one case each).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))

import numpy as np  # noqa: E402

_argv, sys.argv = sys.argv, sys.argv[:1]          # doptrack_never_worse reads its own arguments on import
from doptrack_never_worse import STALE_DAYS  # noqa: E402

sys.argv = _argv
from fit_tle_doptrack import _rms, _tle  # noqa: E402
from test_refine_realdata import (BAD_PASSES, DOPTRACK, EOP, MAX_PAIR_GAP_S, _load, evenings, is_dev,  # noqa: E402
                                  metadata_tle_of)
from trackproc.io.tle import tle_epoch  # noqa: E402
from trackproc.pipeline.fit_tle import FitTleOptions, fit_tle  # noqa: E402
from trackproc.pipeline.orbit_source import OrbitInput, metadata_tle  # noqa: E402

#: The predicted passes: more than this many hours after the evening's last pass ...
NEXT_MIN_H = MAX_PAIR_GAP_S / 3600.0
#: ... and at most this many.
NEXT_MAX_H = 30.0


def _time(stamp: str) -> dt.datetime:
    return dt.datetime.strptime(stamp, "%Y%m%d%H%M")


def _stamps():
    return sorted(p.stem.rsplit("_", 1)[-1] for p in (DOPTRACK / "data").glob("Delfi-C3_32789_*.csv"))


def catalogue():
    """Every distinct TLE of the passes' metadata, oldest first."""
    out = {}
    for s in _stamps():
        t = metadata_tle_of(s)
        out[t.line1] = t
    return sorted(out.values(), key=lambda t: tle_epoch(t))


def old_tle(evening, tles):
    """The newest TLE of ``tles`` at least :data:`STALE_DAYS` before the evening's first pass."""
    start = np.datetime64(_time(evening[0]), "ns")
    limit = start - np.timedelta64(int(STALE_DAYS * 86400), "s")
    older = [t for t in tles if np.datetime64(tle_epoch(t), "ns") <= limit]
    return older[-1] if older else None


def cases(dev: bool, fresh: bool = False, every: bool = False):
    """``(evening, old TLE, [next-day passes])`` of the development set (or the hold-out); ``every``:
    one case per catalogue TLE 7 to 10 days older than the evening (more pairs to study on)."""
    stamps = [s for s in _stamps() if s not in BAD_PASSES]
    tles = catalogue()
    out = []
    for ev in evenings():
        later = [s for s in stamps if NEXT_MIN_H * 3600 < (_time(s) - _time(ev[-1])).total_seconds()
                 <= NEXT_MAX_H * 3600]
        if not later:
            continue
        if (all(is_dev(s) for s in ev + later)) != dev:
            continue
        if every:
            start = np.datetime64(_time(ev[0]), "ns")
            for t in tles:
                age = (start - np.datetime64(tle_epoch(t), "ns")) / np.timedelta64(1, "D")
                if STALE_DAYS <= age <= STALE_DAYS + 3:
                    out.append((ev, t, later))
            continue
        tle = metadata_tle([(s, _load(s)[0]) for s in ev]) if fresh else old_tle(ev, tles)
        if tle is not None:
            out.append((ev, tle, later))
    return out


def run(dev: bool, fresh: bool = False, options=None, quiet: bool = False, cases_=None, every: bool = False):
    """Every case (``cases_``, default :func:`cases`) fitted (``options``, default the CLI's) and its
    next-day passes scored. Rows:
    evening, predicted pass, age of the old TLE at the evening (days), RMS of old / written /
    fitted (Hz), ratios, decision and probability."""
    rows = []
    for ev, tle, later in (cases(dev, fresh, every) if cases_ is None else cases_):
        tables = [(s, _load(s)[0]) for s in ev]
        t0 = time.process_time()
        res = fit_tle(tables, [], OrbitInput(tle=tle, source="old"), options or FitTleOptions(), EOP)
        cpu = time.process_time() - t0
        s = res.summary
        refused = (s["refused"] or {}).get("code")
        for target in later:
            table = _load(target)[0]
            old = _rms(table, tle)
            written = _rms(table, res.tle)
            fitted = _rms(table, _tle(s))
            rows.append({"evening": "+".join(x[-4:] for x in ev), "day": ev[0][:8], "predicted": target,
                         "age_days": s["initial_age_days"], "old_hz": old, "written_hz": written,
                         "fitted_hz": fitted, "ratio": written / old, "fitted_ratio": fitted / old,
                         "refused": refused, "p_better": s["prediction"]["probability_better"],
                         "verdict": res.quality.verdict, "cpu_s": cpu})
    title = (f"fit-tle from the {'fresh' if fresh else 'old (>= %g d)' % STALE_DAYS} TLE, evening -> next day's "
             f"passes, {'development (1-10 April)' if dev else 'HOLD-OUT (11-15 April)'}")
    if not quiet:
        print(title)
        print(f"{'evening':>16} {'predicted':>13} {'age d':>5} {'old Hz':>7} {'fit Hz':>7} {'ratio':>6} "
              f"{'fitted':>6} {'P(better)':>9} {'cpu s':>5} decision/verdict")
        for r in rows:
            print(f"{r['day'] + ' ' + r['evening']:>16} {r['predicted']:>13} {r['age_days']:5.2f} {r['old_hz']:7.2f} "
                  f"{r['written_hz']:7.2f} {r['ratio']:6.3f} {r['fitted_ratio']:6.3f} {r['p_better']:9.3f} "
                  f"{r['cpu_s']:5.1f} {'kept (' + r['refused'] + ')' if r['refused'] else 'replaced'}/{r['verdict']}")
        if rows:
            ratio = np.array([r["ratio"] for r in rows])
            fitted = np.array([r["fitted_ratio"] for r in rows])
            print(f"  written better than the old TLE in {int((ratio < 1).sum())} of {ratio.size} pairs, median ratio "
                  f"{np.median(ratio):.3f}, worse by > 10 %: {int((ratio > 1.1).sum())}, worst {ratio.max():.2f}; "
                  f"fits (written or not) median {np.median(fitted):.3f}; replaced in "
                  f"{len({(r['day'], r['evening'], r['age_days']) for r in rows if not r['refused']})} of "
                  f"{len({(r['day'], r['evening'], r['age_days']) for r in rows})} fits", flush=True)
    return rows


if __name__ == "__main__":
    which = sys.argv[1] if len(sys.argv) > 1 else "dev"
    fresh = len(sys.argv) > 2 and sys.argv[2] == "fresh"
    every = len(sys.argv) > 2 and sys.argv[2] == "every"
    for dev in {"dev": [True], "holdout": [False], "both": [True, False]}[which]:
        run(dev, fresh, every=every)
        print()
