"""DopTrack Delfi-C3 (../shared/realdata): how much better than an old TLE can ANY orbit predict a pass?

The never-worse issue asks a refined orbit to predict the next pass better than a TLE 7-8 days
older than the refined pass (median ratio <= 0.95). On some days an old TLE already predicts at
the level of the pass's own time-tag error, and then no orbit can do much better. This measures
that room, for the same pairs as ``benchmarks/doptrack_never_worse.py`` (pass A, its next pass B;
the TLE of the latest pass at least 7 days before A):

* ``old``: B's Doppler RMS after B's own offset and drift, predicted by the old TLE (SGP4);
* ``bound``: the same after also the best time shift of that prediction (an along-track
  correction of the old TLE; it also removes B's own time-tag error, which no orbit can, so it is
  an optimistic bound for any orbit whose error is mostly along-track, as a week-old TLE's is);
* ``fresh``: the same predicted by B's own TLE (hours old); ``old-fresh``: B's best time shift
  against the old TLE less that against its own TLE, the old TLE's along-track error in seconds
  (B's own time-tag error cancels; a fresh TLE is good to ~0.05 s);
* ``taken``: the old TLE's prediction of B shifted by the time shift pass A itself shows against
  the old TLE (first order, through B's Doppler rate): an orbit that takes all of A's timing as
  an along-track correction, the most a single pass can move a TLE along its track. It gains on
  B only when A's and B's timing errors are common (an along-track error of the old TLE), and
  loses when they are each pass's own (the station's time tags).

A median of ``bound / old`` above 0.95 says the issue's target cannot be met on those pairs by
any along-track correction, however good; ``taken/old`` above 1 in most pairs says that moving
the TLE by pass A's own timing loses. No refinement is run: nothing here is tuned.

``nextday`` asks the same of ``fit-tle`` from an old TLE over an evening (the cases of
``benchmarks/fit_tle_stale.py``: an evening of passes < 4 h apart, the newest catalogue TLE at
least 7 days older, every pass 4-30 h later predicted): ``taken`` then shifts the old TLE's
prediction of each next-day pass by the mean of the evening's own shifts against it (the along-track
phase an evening measures; first order, no drift).

Usage: ``PYTHONPATH=src python benchmarks/doptrack_bound.py [dev|holdout|both] [evening|day|nextday]``
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

# (doptrack_never_worse puts tests/ on the path and holds the pairs, the loader and the scores)
from doptrack_never_worse import (EOP, _load, _predicted_rms, pass_pairs, stale_tle_for,  # noqa: E402
                                  timing_split)
from test_refine_realdata import _predicted_residuals, _rate, _rms_after_own_offset_drift  # noqa: E402
from trackproc.io.tle import tle_state  # noqa: E402


def _scores(b: str, state, old, shift_a: float) -> tuple:
    """Pass ``b`` predicted by the ``old`` TLE (``state`` its state): ``(old Hz, bound Hz, shift s,
    fresh Hz, A shift s, taken Hz, old-fresh s)``, ``shift_a`` the shift taken (module docstring)."""
    tb, fresh_b = _load(b)
    rms, after, shift = timing_split(tb, state, old)
    fresh_state = tle_state(fresh_b, eop=EOP)
    fresh = _predicted_rms(tb, fresh_state, fresh_b)
    old_error = shift - timing_split(tb, fresh_state, fresh_b)[2]
    return rms, after, shift, fresh, shift_a, _taken(tb, state, old, shift_a), old_error


def _taken(table, state, tle, shift_s: float) -> float:
    """The RMS (Hz) of ``table``'s Doppler after its own offset and drift, predicted by ``tle`` with
    the prediction shifted by ``shift_s`` (fit-tle's sign: the residual's fitted rate coefficient is
    -shift, so a shift s removes -s * rate)."""
    t_s, residual, computed = _predicted_residuals(table, state, tle)
    return _rms_after_own_offset_drift(t_s, residual + shift_s * _rate(t_s, computed))


def rows(dev: bool, pairs: str) -> list:
    """``(pass A, pass B, *scores of B)`` for the pairs (``evening`` or ``day``), A's own shift taken."""
    stamps, chosen = pass_pairs(dev, pairs)
    out = []
    for a, b in chosen:
        old = stale_tle_for(a, stamps)
        if old is None:
            continue
        state = tle_state(old, eop=EOP)
        out.append((a, b, *_scores(b, state, old, timing_split(_load(a)[0], state, old)[2])))
    return out


def evening_rows(dev: bool) -> list:
    """``(evening, next-day pass, *scores)`` for fit-tle's cases, the mean of the evening's shifts
    against the old TLE taken."""
    from fit_tle_stale import cases

    out = []
    for evening, old, later in cases(dev):
        state = tle_state(old, eop=EOP)
        mean_shift = float(np.mean([timing_split(_load(s)[0], state, old)[2] for s in evening]))
        label = f"{evening[0][:8]} {'+'.join(s[-4:] for s in evening)}"
        out.extend((label, b, *_scores(b, state, old, mean_shift)) for b in later)
    return out


def main() -> None:
    sets = {"dev": [True], "holdout": [False], "both": [True, False]}[sys.argv[1] if len(sys.argv) > 1 else "dev"]
    pairs = sys.argv[2] if len(sys.argv) > 2 else "evening"
    for dev in sets:
        got = evening_rows(dev) if pairs == "nextday" else rows(dev, pairs)
        print(f"old TLE (>= 7 days) predicting the next pass, {pairs} pairs, "
              f"{'development (1-10 April)' if dev else 'HOLD-OUT (11-15 April)'}")
        print(f"{'evening' if pairs == 'nextday' else 'pass':>13} {'next':>13} {'old Hz':>7} {'bound Hz':>8} "
              f"{'shift s':>7} {'fresh Hz':>8} {'bound/old':>9} {'A shift s':>9} {'taken Hz':>8} {'taken/old':>9} "
              f"{'old-fresh s':>11}")
        for a, b, rms, after, shift, fresh, shift_a, taken, old_error in got:
            print(f"{a:>13} {b:>13} {rms:7.2f} {after:8.2f} {shift:7.2f} {fresh:8.2f} {after / rms:9.2f} "
                  f"{shift_a:9.2f} {taken:8.2f} {taken / rms:9.2f} {old_error:11.2f}")
        if got:
            ratio = np.array([r[3] / r[2] for r in got])
            fresh_ratio = np.array([r[5] / r[2] for r in got])
            taken_ratio = np.array([r[7] / r[2] for r in got])
            print(f"  {len(got)} pairs: bound/old median {np.median(ratio):.3f} ({int((ratio <= 0.95).sum())} at or "
                  f"below 0.95); fresh/old median {np.median(fresh_ratio):.3f} ({int((fresh_ratio < 1).sum())} "
                  f"better); |shift| median {np.median(np.abs([r[4] for r in got])):.2f} s; taken/old median "
                  f"{np.median(taken_ratio):.3f} ({int((taken_ratio < 1).sum())} better, "
                  f"{int((taken_ratio > 1.1).sum())} worse by more than 10 %); |old-fresh| median "
                  f"{np.median(np.abs([r[8] for r in got])):.2f} s")
        print()


if __name__ == "__main__":
    main()
