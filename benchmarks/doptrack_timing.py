"""DopTrack's station timing: each good pass's time shift against its own fresh TLE (SGP4; a fresh
TLE is good to ~0.05 s along-track), its formal sigma, and the station's time-tag sigma by maximum
likelihood (``tests/pipeline/test_refine_realdata.station_time_sigma``), about zero (what an orbit
fitted to the tags absorbs) and about the median (the scatter from pass to pass).

The stated sigma in ``io/doptrack.py`` (``KNOWN_STATION_TIME_SIGMA_S``) comes from the development
days. Usage: ``PYTHONPATH=src python benchmarks/doptrack_timing.py [dev|holdout]``.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))

import numpy as np  # noqa: E402

from test_refine_realdata import doptrack_time_shifts, station_time_sigma  # noqa: E402

if __name__ == "__main__":
    dev = (sys.argv[1] if len(sys.argv) > 1 else "dev") == "dev"
    rows = doptrack_time_shifts(dev)
    for stamp, shift, formal in rows:
        print(f"{stamp}  shift {shift:+7.3f} s  formal {formal:6.3f} s")
    shifts, formal = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    for name, centre in (("about zero", 0.0), ("about the median", float(np.median(shifts)))):
        sigma, keep = station_time_sigma(shifts, formal, centre)
        print(f"{'development' if dev else 'HOLD-OUT'} {name} ({centre:+.3f} s): time-tag sigma {sigma:.3f} s "
              f"from {int(keep.sum())} of {keep.size} passes")
