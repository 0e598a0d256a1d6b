"""``refine`` on mis-modelled passes: the table of docs/refine.md, "Mis-modelled passes".

For each pass (S55: S-band 0.1 Hz, 55 deg; V55: VHF 1.5 Hz with drift, 55 deg; V16: the same at
16 deg), each error its models do not know (tests/cli/test_refine_mismodel.py, ``mismodelled``) and
the stale state of seed 004 Table 1 with its covariance (``cov``) and without (``nocov``, the default
a-priori), over a few noise draws: the largest |error|/sigma over x..vz at the solution epoch, the
verdicts and the reasons that were not ``ok``, refusals, failures (exit 1), and whether every draw
covers or says so.

    PYTHONPATH=src python benchmarks/refine_mismodel.py [--seeds 1,2,3] [--geometries S55,V55,V16]

About 1-2 min on one core (0.1-0.4 s per refinement).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "cli"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "report"))  # test_refine

from test_refine_mismodel import GEOMETRIES, covers_or_says_so, outcome  # noqa: E402

SCENARIOS = ["clean", "timetag0.2", "timetag0.5", "timetag2", "station_n200", "station_n1k", "station_e1k",
             "station_u100", "carrier+3k", "twoway_as_oneway", "thermal20", "sine5", "gap90", "first_half", "pass60",
             "tone10pct", "bursts", "iono"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--geometries", default=",".join(GEOMETRIES))
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    warnings.simplefilter("ignore")
    print(f"{'pass':4s} {'scenario':17s} {'stale':5s} {'max|z|':>7s}  verdicts (not-ok reasons)  covers or says so")
    for geometry in args.geometries.split(","):
        for scenario in args.scenarios.split(","):
            for stale in ("cov", "nocov"):
                outs = [outcome(geometry, scenario, stale, seed) for seed in seeds]
                z = max((o["max_z"] for o in outs if "max_z" in o), default=float("nan"))
                said = []
                for o in outs:
                    if "failed" in o:
                        said.append("exit 1")
                    else:
                        bad = ",".join(r for r in o["reasons"] if r != "refused")
                        said.append(("refused " if o["refused"] else "") + o["verdict"] + (f" ({bad})" if bad else ""))
                ok = sum(covers_or_says_so(o) for o in outs)
                print(f"{geometry:4s} {scenario:17s} {stale:5s} {z:7.2f}  {'; '.join(sorted(set(said)))}  "
                      f"{ok}/{len(outs)}", flush=True)


if __name__ == "__main__":
    main()
