"""CPU of one model evaluation (``models.observation.evaluate``, what a refinement calls per trial
point) and of one measurement-spectra ``predict`` (the traverse search), on a batch's real calls.

A ``trackproc batch`` configuration (e.g. the nightly workload of ``benchmarks/nightly.py``, or a
10-pass subset of it) is run once in this process with both functions wrapped to record their
arguments; then every recorded call is replayed ``--repeat`` times, each on a trajectory whose kept
work (derivative spectra, the last times' split and powers) is forgotten first, as a refinement's
new trial point has it. Prints the CPU (``time.process_time``) per call of each replay round and a
digest of every output (values, partials, light-time geometry; predictions): two source trees give
the same numbers bit for bit when their digests agree.

Run (from the directory of the configuration; one thread of BLAS, as a batch worker has):

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src python benchmarks/model_evaluations.py nightly.toml --repeat 5

Alternate the trees compared (A B A B) and quote the load: the absolute figures move with it.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import tempfile
import time

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")


def _forget(traj) -> None:
    """Drop what a trajectory (and its runs) keeps between calls."""
    inner = getattr(traj, "traj", traj)
    inner = getattr(inner, "traj", inner)
    for run in inner.runs:
        for name, val in list(vars(run).items()):
            if name.startswith("_") and isinstance(val, (dict, list)):
                val.clear()
    for name in [n for n in vars(inner) if n.startswith("_")]:
        del inner.__dict__[name]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("config", help="a trackproc batch configuration (TOML)")
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args(argv)

    import numpy as np

    import trackproc.dynamics.measurement_spectra as ms
    from trackproc.cli.app import main as cli
    from trackproc.models import observation as ob

    calls = {"evaluate": [], "predict": []}
    real = {"evaluate": ob.evaluate, "predict": ms.predict}

    def recorder(name):
        def wrapped(*a, **k):
            calls[name].append((a, dict(k)))
            return real[name](*a, **k)
        return wrapped

    ob.evaluate, ms.predict = recorder("evaluate"), recorder("predict")
    out = tempfile.mkdtemp(prefix="model-evaluations-")
    try:
        cli(["-q", "batch", args.config, "-o", out])
    except SystemExit:
        pass
    finally:
        ob.evaluate, ms.predict = real["evaluate"], real["predict"]
        shutil.rmtree(out, ignore_errors=True)

    digest = hashlib.sha256()

    def add(*arrays):
        for a in arrays:
            if a is not None:
                digest.update(np.ascontiguousarray(a).tobytes())

    for name, fn in real.items():
        rounds = []
        for rep in range(args.repeat):
            total = 0.0
            for a, k in calls[name]:
                _forget(a[1] if name == "evaluate" else a[0])
                start = time.process_time()
                res = fn(*a, **k)
                total += time.process_time() - start
                if rep == 0 and name == "evaluate":
                    geo = res[2]
                    add(res[0], res[1], geo.tau_s, geo.state, geo.state_dot if k.get("partials", True) else None,
                        geo.u, geo.rho_m)
                elif rep == 0:
                    add(res.range_m, res.range_rate_m_s, res.azimuth_rad, res.elevation_rad, res.d_range_d_state,
                        res.d_range_rate_d_state)
            rounds.append(1e3 * total / max(len(calls[name]), 1))
        print(f"{name}: {len(calls[name])} calls; CPU ms a call, min {min(rounds):.3f}, median "
              f"{sorted(rounds)[len(rounds) // 2]:.3f} (rounds: {' '.join(f'{r:.3f}' for r in rounds)})")
    print(f"digest {digest.hexdigest()[:16]}")


if __name__ == "__main__":
    main()
