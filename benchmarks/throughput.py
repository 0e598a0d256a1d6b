"""Throughput side by side (issue 19), in one run, with the ratios the README quotes.

Run:  PYTHONPATH=src python benchmarks/throughput.py [--passes 500] [--serial-passes 100]
                                                     [--no-orekit] [--only help,propagation,refine,estimate,batch]

Sections (each figure the median of several runs; CPU seconds from ``time.process_time`` or,
for child processes, ``getrusage(RUSAGE_CHILDREN)``; wall time is printed too but is noisy on a
shared machine, CPU time is the figure to compare):

* ``help``: ``trackproc COMMAND --help`` for a few commands, a fresh process each (target <= 0.1 s);
* ``propagation``: one 600 s LEO pass (601 samples, two-body + J2, tol 1e-15) and one J2 day
  (1441 samples): the Taylor engine, numpy and compiled (numba, ``trackproc[fast]``), against
  heyoka (same tolerance; optional, ``trackproc[bench]``) and scipy DOP853 tuned to 1 mm (targets:
  a pass within 2x heyoka, a J2 day within 10x);
* ``refine``: a single-pass ``refine`` (default options) on DopTrack passes of the development
  period (1-10 April 2020, ../shared/realdata; never the hold-out), CPU per pass (issue 13: < 0.5 s);
* ``estimate``: the 3-station 24 h estimate of ``benchmarks/estimate.py`` end to end (a fresh
  process each) against Orekit's BatchLSEstimator on the same data (``--no-orekit`` to skip;
  target >= 25x);
* ``batch``: simulated one-second passes (``benchmarks/batch.py``), ingest -> smooth -> refine from
  ``sample_data/stale.json``: ``--serial-passes`` in this process (1 worker; CPU per pass, with the
  numpy paths and with the compiled kernels batch uses when numba is installed; with
  ``TRACKPROC_JIT`` set, that setting only), then all ``--passes`` really run with 1 worker (this
  process, warm) and with 2 worker
  processes (wall time from the start of the run to the summary, pool start-up included; the
  load average before the run is printed, the figure counts only on an idle machine; target:
  500 passes <= 30 s on an idle 2-core machine).

One BLAS thread per process, as ``trackproc`` itself runs. The defaults take about four minutes.
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import logging  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(HERE), str(ROOT / "tests"), str(ROOT / "tests" / "pipeline")]  # test_refine_realdata

SECTIONS = ("help", "propagation", "refine", "estimate", "batch")
RATIOS: list[tuple[str, str]] = []      # (what, figure) collected for the closing summary


def cpu_median(fn, repeat=7, inner=1):
    """Median CPU seconds of one call of ``fn`` (after one warm-up call)."""
    fn()
    out = []
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(inner):
            fn()
        out.append((time.process_time() - t0) / inner)
    return statistics.median(out)


def child_run(cmd):
    """(CPU s, wall s) of one child process: user + system from RUSAGE_CHILDREN."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def note(what, figure):
    RATIOS.append((what, figure))


# -- sections ------------------------------------------------------------------------------

def section_help(repeat=7):
    exe = Path(sys.executable).with_name("trackproc")
    exe = str(exe) if exe.exists() else shutil.which("trackproc") or "trackproc"
    print("\n== trackproc COMMAND --help (fresh process each; target <= 0.1 s) ==")
    bare = [child_run([sys.executable, "-c", "pass"]) for _ in range(repeat)]
    print(f"  bare python          CPU {statistics.median(c for c, _ in bare):.3f} s")
    worst = 0.0
    for args in (["--help"], ["refine", "--help"], ["estimate", "--help"], ["batch", "--help"]):
        runs = [child_run([exe, *args]) for _ in range(repeat)]
        cpu, wall = statistics.median(c for c, _ in runs), statistics.median(w for _, w in runs)
        worst = max(worst, cpu)
        print(f"  trackproc {' '.join(args):<17} CPU {cpu:.3f} s   wall {wall:.3f} s")
    note("`trackproc COMMAND --help`", f"{worst:.2f} s CPU (slowest command; target <= 0.1 s)")


def section_propagation(repeat=7):
    import numpy as np

    import propagation as pb
    from trackproc.dynamics import taylor

    try:
        import heyoka as hy
    except ImportError:
        hy = None
    engines = pb.engines()                       # numpy, and compiled when numba is importable
    print(f"\n== propagation, two-body + J2, tol {pb.TOL:g}, CPU per call, warm "
          f"(heyoka {'not installed' if hy is None else hy.__version__}; Taylor engines: "
          f"{', '.join(engines)}) ==")
    for label, span, n, target in (("600 s pass, 601 samples", pb.PASS_S, 601, 2.0),
                                   ("J2 day, 1441 samples", pb.DAY_S, 1441, 10.0)):
        t = np.linspace(0.0, span, n)
        inner = 20 if span < 1000 else 1
        res = taylor.propagate(pb.LEO, 0.0, span, tol=pb.TOL, engine="numpy")
        st = res.state(t)
        t_tay = {eng: cpu_median(lambda: taylor.propagate(pb.LEO, 0.0, span, tol=pb.TOL,
                                                          engine=eng).state(t), repeat, inner)
                 for eng in engines}
        line = f"  {label:<26} Taylor numpy {t_tay['numpy'] * 1e3:8.3f} ms"
        if "compiled" in t_tay:
            line += f", compiled {t_tay['compiled'] * 1e3:7.3f} ms"
        line += f" ({res.n_steps} steps)"
        ref = pb.dop853(pb.rhs_j2, pb.LEO, span, t, 1e-13, 1e-9).y.T
        rtol, _ = pb.tune_dop853(pb.rhs_j2, pb.LEO, span, t, ref)
        if rtol is not None:
            t_dop = cpu_median(lambda: pb.dop853(pb.rhs_j2, pb.LEO, span, t, rtol, rtol), 3)
            line += f"; DOP853 @1 mm {t_dop * 1e3:8.3f} ms (numpy Taylor {t_dop / t_tay['numpy']:.1f}x faster)"
            note(f"{label}: DOP853 (1 mm) / Taylor", "; ".join(
                f"{eng} {t_dop / t_tay[eng]:.1f}" for eng in engines))
        if hy is not None:
            ta = hy.taylor_adaptive(pb.heyoka_system("j2"), pb.LEO.tolist(), tol=pb.TOL)
            run = pb.heyoka_grid(ta, pb.LEO, t)
            out = run()
            t_hy = cpu_median(run, repeat, inner)
            ratios = "; ".join(f"{eng} {t_tay[eng] / t_hy:.1f}" for eng in engines)
            line += (f"; heyoka {t_hy * 1e3:7.3f} ms: Taylor/heyoka {ratios} (target <= {target:g}),"
                     f" |dr| {pb.pos_err(out[-1], st):.0e} m")
            note(f"{label}: Taylor / heyoka", f"{ratios} (target <= {target:g})")
        print(line)
        if span < 1000:                          # the pass with its STM: what refine asks for
            t_stm = {eng: cpu_median(lambda: taylor.propagate(pb.LEO, 0.0, span, tol=pb.TOL, stm=True,
                                                              engine=eng).stm(t), repeat, inner)
                     for eng in engines}
            line = f"  {label + ' + STM':<26} Taylor " + ", ".join(
                f"{eng} {t_stm[eng] * 1e3:8.3f} ms" for eng in engines)
            if hy is not None:
                tv = hy.taylor_adaptive(hy.var_ode_sys(pb.heyoka_system("j2"), hy.var_args.vars, order=1),
                                        pb.LEO.tolist(), tol=pb.TOL)
                t_hyv = cpu_median(pb.heyoka_grid(tv, tv.state.copy(), t), repeat, inner)
                ratios = "; ".join(f"{eng} {t_stm[eng] / t_hyv:.1f}" for eng in engines)
                line += f"; heyoka + var. eqs {t_hyv * 1e3:7.3f} ms: Taylor/heyoka {ratios}"
                note(f"{label} + STM: Taylor / heyoka", ratios)
            print(line)
    if "compiled" in engines:                    # cold: a fresh interpreter, kernels cached on disk
        leo = "[" + ", ".join(repr(float(x)) for x in pb.LEO) + "]"
        cold = {eng: pb._subprocess_seconds(pb._COLD.format(leo=leo, span=pb.DAY_S, n=1441, stm=False,
                                                            eng=eng), 3) for eng in engines}
        print(f"  J2 day, first call in a fresh process (CPU): numpy {cold['numpy'] * 1e3:.1f} ms, "
              f"compiled {cold['compiled'] * 1e3:.1f} ms (import numba + cached kernels); so `trackproc` "
              f"takes the compiled engine by itself only from {taylor.COMPILED_MIN_STEPS[False]} steps "
              f"(benchmarks/propagation.py --only jit)")
        note("J2 day, first call in a fresh process: numpy / compiled (CPU)",
             f"{cold['numpy'] * 1e3:.0f} ms / {cold['compiled'] * 1e3:.0f} ms")


def section_refine(repeat=3):
    import test_refine_realdata as rr
    from trackproc.io.tle import tle_state
    from trackproc.pipeline.refine import RefineOptions, refine

    stamps = ("202004011044", "202004021953", "202004072055", "202004092043")   # development passes
    print("\n== refine, one DopTrack pass (1-10 April 2020), default options, CPU per pass (issue 13: < 0.5 s) ==")
    cpus = []
    for stamp in stamps:
        try:
            table, tle = rr._load(stamp)
        except Exception as exc:  # noqa: BLE001 - real data absent: say so and go on
            print(f"  {stamp}: skipped ({exc})")
            continue
        st = tle_state(tle, eop=rr.EOP)
        cpu = cpu_median(lambda: refine(table, st, None, RefineOptions(), rr.EOP, source=stamp), repeat)
        cpus.append(cpu)
        print(f"  {stamp}  {len(table.frame):5d} samples  CPU {cpu:.3f} s")
    if cpus:
        note("refine, one DopTrack pass", f"median {statistics.median(cpus):.2f} s CPU, max {max(cpus):.2f} s "
                                          "(target < 0.5 s)")


def section_estimate(orekit: bool, runs=2):
    import estimate as eb

    print("\n== estimate, 3 stations, 24 h at 1 Hz (benchmarks/estimate.py), end to end in a fresh process ==")
    d = Path(tempfile.mkdtemp(prefix="trackproc-throughput-est-"))
    try:
        case = eb.make_case(d, 24.0)
        cmd = eb.trackproc_cmd(*eb.estimate_args(d, case, d / "trackproc.json"))
        child_run(cmd)                                                    # warm-up (file cache, .pyc)
        ours = [child_run(cmd) for _ in range(runs)]
        cpu, wall = statistics.median(c for c, _ in ours), statistics.median(w for _, w in ours)
        print(f"  trackproc estimate     {case['samples']} samples: CPU {cpu:.2f} s, wall {wall:.2f} s")
        if not orekit:
            return
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        try:
            theirs = eb.bench_orekit(d, case, 1, "gauss-newton")
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - Orekit/Java absent: say so
            print(f"  orekit: not run ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")
            return
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        ocpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        print(f"  Orekit {theirs['version']} BatchLSEstimator: CPU {ocpu:.2f} s, wall {theirs['wall_s']:.2f} s "
              f"(estimate() alone {theirs['estimate_s']:.2f} s wall)")
        print(f"  Orekit / trackproc: CPU {ocpu / cpu:.1f}x, wall {theirs['wall_s'] / wall:.1f}x "
              f"(Orekit's estimate() alone / trackproc end to end, wall: {theirs['estimate_s'] / wall:.1f}x)")
        note("estimate 24 h: Orekit BatchLSEstimator / trackproc", f"CPU {ocpu / cpu:.1f}x, wall "
             f"{theirs['wall_s'] / wall:.1f}x (target >= 25x)")
    finally:
        shutil.rmtree(d, ignore_errors=True)


def section_batch(passes: int, serial_passes: int):
    import batch as bb
    from trackproc.pipeline.batch import run_batch

    logging.getLogger("trackproc").setLevel(logging.ERROR)
    print("\n== batch: ingest -> smooth -> refine, simulated 1 s passes ==")
    d = Path(tempfile.mkdtemp(prefix="trackproc-throughput-batch-"))
    user_jit = os.environ.get("TRACKPROC_JIT")
    try:
        n = bb.make_passes(d, max(passes, serial_passes), 1.0)
        inbox = d / "inbox"
        # every distinct pass once before any repeat (make_passes repeats the day's passes as -01, -02, ...)
        names = sorted(inbox.iterdir(), key=lambda p: (p.stem.rsplit("-", 1)[-1], p.name))
        serial_dir = d / "serial-inbox"
        serial_dir.mkdir()
        for p in names[:serial_passes]:
            (serial_dir / p.name).write_bytes(p.read_bytes())
        flags = {"batch.steps": ["ingest", "smooth", "refine"],
                 "refine.initial": str(ROOT / "sample_data" / "stale.json")}

        def settings(src, out, workers):
            return bb.settings_for(d, d / out, **{**flags, "batch.workers": workers, "batch.inputs": [str(src)]})

        def serial(label, jit):
            # TRACKPROC_JIT=0: the numpy paths; unset: batch's own choice (the compiled kernels
            # when numba is installed)
            if jit is None:
                os.environ.pop("TRACKPROC_JIT", None)
            else:
                os.environ["TRACKPROC_JIT"] = jit
            run_batch(settings(serial_dir, f"warm-{label}", 1))        # imports, caches, kernels compiled/loaded
            t0, c0 = time.perf_counter(), time.process_time()
            res = run_batch(settings(serial_dir, f"out1-{label}", 1))
            wall1, cpu1 = time.perf_counter() - t0, time.process_time() - c0
            per_pass = cpu1 / serial_passes
            print(f"  1 worker (this process), {serial_passes} passes, {label:<22}: wall {wall1:.1f} s, CPU "
                  f"{per_pass:.3f} s per pass (exit {res.exit_code}); 500 passes at this rate: {500 * per_pass:.0f} s CPU")
            return per_pass

        if user_jit is None:
            per_numpy = serial("numpy (TRACKPROC_JIT=0)", "0")
            per_pass = serial("batch's choice", None)
            note("batch, ingest -> smooth -> refine, 1 worker", f"{per_numpy:.3f} s CPU per pass (numpy), "
                 f"{per_pass:.3f} s (with the compiled kernels batch chooses)")
        else:
            per_pass = serial(f"TRACKPROC_JIT={user_jit}", user_jit)
            note("batch, ingest -> smooth -> refine, 1 worker", f"{per_pass:.3f} s CPU per pass (TRACKPROC_JIT={user_jit})")
        if passes <= 0:
            return
        if user_jit is None:
            os.environ.pop("TRACKPROC_JIT", None)
        # every pass with 1 worker (this process, already warm), then with 2 worker processes
        t0 = time.perf_counter()
        res = run_batch(settings(inbox, "out-1worker", 1))
        wall1 = time.perf_counter() - t0
        print(f"  1 worker (this process), {n} passes: wall {wall1:.1f} s, {n / wall1:.1f} passes/s (exit {res.exit_code})")
        note(f"batch, {n} passes, 1 worker", f"{wall1:.1f} s wall")
        # the real run the issue asks for: every pass, 2 worker processes, wall time from the
        # start of the run (pool start-up: two interpreters importing numpy, scipy, pandas, and
        # loading the compiled kernels) to the summary; only meaningful on an idle machine
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        res = run_batch(settings(inbox, "out2", 2))
        wall2 = time.perf_counter() - t0
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        busy = load0[0] > 0.5
        load = " ".join(f"{x:.1f}" for x in load0)
        print(f"  2 worker processes, {n} passes: wall {wall2:.1f} s, {n / wall2:.1f} passes/s (exit {res.exit_code}); "
              f"load average before the run {load} on {cores} cores"
              + ("  (NOT idle: the wall time is not the idle machine's)" if busy else ""))
        if n == 500:
            figure = f"{wall2:.1f} s wall, measured"
        else:
            figure = f"{500 * wall2 / n:.0f} s wall, extrapolated from {n} passes"
        note("batch, 500 passes, 2 workers", figure + (" on a busy machine (load " + load + ")" if busy else
                                                      " on an idle machine") + " (target <= 30 s)")
    finally:
        if user_jit is None:
            os.environ.pop("TRACKPROC_JIT", None)
        else:
            os.environ["TRACKPROC_JIT"] = user_jit
        shutil.rmtree(d, ignore_errors=True)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--passes", type=int, default=500, help="passes for the 2-worker batch run (default 500; 0: no 2-worker run)")
    p.add_argument("--serial-passes", type=int, default=60, help="passes for the 1-worker run (default 60)")
    p.add_argument("--no-orekit", action="store_true", help="skip Orekit in the estimate section")
    p.add_argument("--only", default=",".join(SECTIONS), help="comma-separated sections: " + ", ".join(SECTIONS))
    args = p.parse_args(argv)
    want = [s.strip() for s in args.only.split(",") if s.strip()]
    unknown = set(want) - set(SECTIONS)
    if unknown:
        p.error(f"unknown section(s) {', '.join(sorted(unknown))}; expected {', '.join(SECTIONS)}")
    import numpy
    import scipy

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"python {sys.version.split()[0]}, numpy {numpy.__version__}, scipy {scipy.__version__}; "
          f"{cores} cores; load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    t_start = time.perf_counter()
    if "help" in want:
        section_help()
    if "propagation" in want:
        section_propagation()
    if "refine" in want:
        section_refine()
    if "estimate" in want:
        section_estimate(not args.no_orekit)
    if "batch" in want:
        section_batch(args.passes, args.serial_passes)
    print(f"\n== summary ({time.perf_counter() - t_start:.0f} s) ==")
    for what, figure in RATIOS:
        print(f"  {what:<58} {figure}")


if __name__ == "__main__":
    main()
