"""CPU time of a single-pass ``refine`` on DopTrack passes (../shared/realdata), by option.

Issue 13 budget: 0.5 s of CPU per single-pass refine. Columns: the default (noise model by REML,
GLS, profile covariance), ``--noise white``, ``--covariance linear``, both, and the REML model
choice alone (:func:`trackproc.pipeline.refine.noise_model` on a converged fit). BLAS is kept to
one thread (a multi-threaded BLAS on a shared machine makes a 300 x 300 Cholesky 25x slower).
Usage: ``PYTHONPATH=src python benchmarks/refine_speed.py [STAMP ...]`` (about a minute).
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

from test_refine_realdata import EOP, _load  # noqa: E402
from trackproc.io.tle import tle_state  # noqa: E402
from trackproc.pipeline.refine import RefineOptions, noise_model, prepare, refine, solve_weighted  # noqa: E402

STAMPS = ("202004011044", "202004021953", "202004072055", "202004092043")


def cpu(fn):
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def main(stamps):
    print(f"{'pass':>13} {'samples':>7} {'default':>8} {'white':>8} {'linear':>8} {'white+lin':>9} {'REML':>6}  (CPU s)")
    for stamp in stamps:
        table, tle = _load(stamp)
        st = tle_state(tle, eop=EOP)
        refine(table, st, None, RefineOptions(), EOP, source=stamp)          # warm caches and imports
        row = [cpu(lambda o=o: refine(table, st, None, o, EOP, source=stamp))
               for o in (RefineOptions(), RefineOptions(noise="white"), RefineOptions(covariance="linear"),
                         RefineOptions(noise="white", covariance="linear"))]
        ref = prepare(table, st, None, RefineOptions(doppler_bias="offset+drift"), EOP, source=stamp)
        sol, _, scale = solve_weighted(ref)
        row.append(cpu(lambda: noise_model(ref, sol, scale)))
        print(f"{stamp:>13} {len(table.frame):7d} " + " ".join(f"{v:8.2f}" for v in row[:3]) + f" {row[3]:9.2f} "
              f"{row[4]:6.2f}")


if __name__ == "__main__":
    main(sys.argv[1:] or STAMPS)
