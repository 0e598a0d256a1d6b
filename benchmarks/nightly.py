"""The figures of the speed table (README "Performance"), measured side by side in one run, each a
whole process timed from outside (user + system CPU of the finished child, from the OS), and
every figure as a ratio to a yardstick run alternately with it in the same run:

* ``trackproc --help`` and every ``trackproc COMMAND --help`` against ``python -c pass``: the
  first run of each (rendered by typer) and the next ones (from the user cache);
* one ``refine`` of the sample pass against ``python -c 'import numpy, scipy.linalg, pandas,
  pyarrow.parquet'``, and the CPU of each of its imports and of the refinement (``time.process_time``
  between them, inside fresh processes);
* ``trackproc batch`` ingest -> smooth -> refine over a nightly workload: simulated days of six
  stations at 1 s, one-way Doppler + elevation, ``trackproc simulate``'s defaults otherwise, a
  new seed per day, days added until there are N passes (default 200): every pass is distinct
  data, not a copy. CPU per pass (the batch process and its workers), passes per second, and
  the 500-pass wall time at that rate, with 2 workers.

Run: python benchmarks/nightly.py [--passes 200] [--runs 5] [--workers 2] [--only help,refine,batch]

The load average before each section is printed with it: on a shared machine the absolute
seconds move with the load, the ratios (alternating runs) much less. Only the standard library
is used (``os.wait4`` for a child's CPU, /proc for a batch's workers), so anyone can rerun it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATIONS = ("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\nZHY,50.25,28.66,230\nKIR,67.857,20.964,400\n"
            "MAD,40.43,-4.25,800\nSVB,78.23,15.4,500\nHBK,-25.89,27.69,1500\n")
BARE_IMPORTS = "import numpy, scipy.linalg, pandas, pyarrow.parquet"
COMMANDS = ("ingest", "info", "simulate", "propagate", "smooth", "estimate", "refine", "accuracy", "requirements",
            "detect", "batch", "passes", "compare", "identify", "fit-tle")


def trackproc_exe() -> str:
    beside = Path(sys.executable).with_name("trackproc")          # the venv's console script
    return str(beside) if beside.exists() else shutil.which("trackproc") or "trackproc"


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def run_child(cmd, env=None) -> tuple[float, float, float]:
    """(CPU s = user + system, wall s, peak MiB) of one whole process, from the OS."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} exited {proc.returncode}")
    return usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024.0


def run_group(cmd, env=None, interval: float = 0.1) -> tuple[float, float]:
    """(CPU s, wall s) of a command and every process it starts, also those it does not wait for
    (a process pool's workers are the fork server's children: the OS never adds their CPU to the
    command's). Linux: each process of the command's session is read from /proc every
    ``interval`` s and its last reading kept (what a process spends after its last reading, at
    most ``interval`` each, is missed)."""
    tick = os.sysconf("SC_CLK_TCK")
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                            start_new_session=True)
    last: dict = {}
    while True:
        for entry in os.listdir("/proc"):
            if not entry.isdigit():
                continue
            try:
                with open(f"/proc/{entry}/stat", "rb") as fh:
                    fields = fh.read().rsplit(b")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == proc.pid:                  # session id: the command's session
                last[entry] = (int(fields[11]) + int(fields[12])) / tick     # utime + stime
        if proc.poll() is not None:
            break
        time.sleep(interval)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} exited {proc.returncode}")
    return sum(last.values()), wall


def paired(a, b, runs: int, env_a=None, env_b=None, before_a=None) -> dict:
    """Runs A and B in turn (A B A B ...), after one warm-up each; medians and the median of the
    pair-by-pair CPU ratios."""
    for cmd, env in ((a, env_a), (b, env_b)):
        run_child(cmd, env)
    ca, cb, wa, ratios = [], [], [], []
    for _ in range(runs):
        if before_a is not None:
            before_a()
        cpu_a, wall_a, _ = run_child(a, env_a)
        cpu_b, _, _ = run_child(b, env_b)
        ca.append(cpu_a), cb.append(cpu_b), wa.append(wall_a), ratios.append(cpu_a / cpu_b)
    return {"a": statistics.median(ca), "b": statistics.median(cb), "wall_a": statistics.median(wa),
            "ratio": statistics.median(ratios), "spread": (min(ratios), max(ratios))}


def bytecode_env(cache: Path | None = None) -> dict:
    """A user's environment: Python writes its bytecode; trackproc's cache in ``cache`` (or off)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["TRACKPROC_CACHE_DIR"] = str(cache) if cache is not None else "off"
    return env


def section_help(runs: int, work: Path) -> None:
    exe = trackproc_exe()
    bare = [sys.executable, "-c", "pass"]
    print(f"\n== --help against `python -c pass` (CPU, whole process; load {load()}) ==")
    worst = (0.0, "")
    for words in [[]] + [[c] for c in COMMANDS]:
        cmd = [exe, *words, "--help"]
        cache = work / "help-cache"
        cached = paired(cmd, bare, runs, env_a=bytecode_env(cache))
        first = paired(cmd, bare, max(runs // 2, 2), env_a=bytecode_env(cache),
                       before_a=lambda: shutil.rmtree(cache / "help", ignore_errors=True))
        name = " ".join(["trackproc", *words, "--help"])
        print(f"  {name:<32} cached {cached['a']:.3f} s = {cached['ratio']:4.1f}x   first run {first['a']:.3f} s = "
              f"{first['ratio']:4.1f}x   (python -c pass {cached['b']:.3f} s)")
        worst = max(worst, (cached["ratio"], name))
    print(f"  slowest cached help: {worst[1]} at {worst[0]:.1f}x `python -c pass` (target <= 5x)")


def sample_pass(work: Path) -> Path:
    exe = trackproc_exe()
    raw, smoothed = work / "pass.parquet", work / "smoothed.parquet"
    subprocess.run([exe, "-q", "ingest", str(ROOT / "sample_data" / "doppler_pass.csv"), "--stations",
                    str(ROOT / "sample_data" / "stations.csv"), "--carrier-hz", "2.2e9", "--mode", "one-way",
                    "-o", str(raw)], check=True)
    subprocess.run([exe, "-q", "smooth", str(raw), "-o", str(smoothed)], check=True)
    return smoothed


def section_refine(runs: int, work: Path) -> None:
    smoothed = sample_pass(work)
    cmd = [trackproc_exe(), "-q", "refine", str(smoothed), "--initial", str(ROOT / "sample_data" / "stale.json"),
           "--doppler-bias", "offset+drift", "-o", str(work / "refined.json")]
    print(f"\n== one refine (sample pass) against `python -c '{BARE_IMPORTS}'` (load {load()}) ==")
    res = paired(cmd, [sys.executable, "-c", BARE_IMPORTS], runs, env_a=bytecode_env(work / "cache"))
    print(f"  refine {res['a']:.3f} s CPU ({res['wall_a']:.3f} s wall), bare imports {res['b']:.3f} s: "
          f"{res['ratio']:.2f}x (pairs {res['spread'][0]:.2f}-{res['spread'][1]:.2f}; target <= 0.8x)")
    print("  where its CPU goes (in-process, one BLAS thread; medians, ms): " + refine_stages(cmd[1:], runs, work))


#: The imports of one refine in the order it needs them, then the command itself: each stage's CPU.
_STAGES = """import json, os, sys, time
clock = time.process_time
marks = [clock()]
from trackproc.cli import app
import trackproc.cli.root
marks.append(clock())
import numpy
app._defer_unused_numpy_modules()
marks.append(clock())
import pyarrow.parquet
marks.append(clock())
import scipy.linalg
marks.append(clock())
import trackproc.io.passfile, trackproc.pipeline.refine, trackproc.cli.refine_cmd
marks.append(clock())
code = app._main(json.loads(sys.argv[1]))
marks.append(clock())
print(json.dumps([code, [b - a for a, b in zip(marks, marks[1:])], "pandas" in sys.modules]))
"""
_STAGE_NAMES = ("Typer app", "numpy", "pyarrow.parquet", "scipy.linalg", "trackproc modules", "refine")


def refine_stages(args, runs: int, work: Path) -> str:
    """Median CPU of each stage of :data:`_STAGES` over ``runs`` fresh processes."""
    import json

    env = bytecode_env(work / "cache")
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(name, "1")                       # as the trackproc entry point sets them
    samples = []
    for _ in range(runs):
        out = subprocess.run([sys.executable, "-c", _STAGES, json.dumps(args)], capture_output=True, text=True,
                             env=env, check=True)
        code, stages, pandas = json.loads(out.stdout.strip().splitlines()[-1])
        if code != 0:
            raise RuntimeError(f"refine exited {code}: {out.stderr[-500:]}")
        samples.append(stages)
    medians = [statistics.median(column) for column in zip(*samples)]
    return (", ".join(f"{name} {1e3 * m:.0f}" for name, m in zip(_STAGE_NAMES, medians))
            + ("; pandas imported" if pandas else "; pandas not imported"))


def make_workload(directory: Path, passes: int) -> int:
    """Raw pass CSVs of simulated days (``trackproc simulate`` defaults, 1 s, one-way Doppler +
    elevation, seed = day number) until there are ``passes``; the last day's extra passes dropped."""
    from trackproc.io.statefile import read_state
    from trackproc.io.stations import parse_stations
    from trackproc.pipeline.simulate import SimulateOptions, simulate

    inbox = directory / "inbox"
    if inbox.is_dir() and len(list(inbox.glob("*.csv"))) == passes:        # --keep: reused
        return len({p.name.split("-")[0] for p in inbox.glob("*.csv")})
    inbox.mkdir(parents=True)
    (directory / "stations.csv").write_text(STATIONS)
    state = read_state(str(ROOT / "sample_data" / "truth.json"))
    stations = parse_stations(STATIONS.encode(), "stations")
    written, day = 0, 0
    while written < passes:
        day += 1
        sim = simulate(state, stations, SimulateOptions(duration_s=86400, step_s=1.0, kinds=("doppler", "elevation"),
                                                        seed=day))
        frame, wide = sim.frame, sim.wide()
        for station, pass_id in frame.groupby(["station", "pass_id"]).size().index:
            if written == passes:
                break
            times = frame.loc[(frame["station"] == station) & (frame["pass_id"] == pass_id), "time"].unique()
            sub = wide[(wide["station"] == station) & wide["time"].isin(times)]
            text = sub.assign(time=sub["time"].dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ")).to_csv(index=False)
            (inbox / f"day{day:02d}-{pass_id}.csv").write_text(text)
            written += 1
    return day


def batch_config(directory: Path, workers: int) -> Path:
    config = directory / f"nightly-{workers}.toml"
    config.write_text(f"""[batch]
inputs = ["inbox"]
steps = ["ingest", "smooth", "refine"]
workers = {workers}
force = true

[ingest]
stations = "stations.csv"
carrier_hz = 2.2e9
mode = "one-way"

[refine]
initial = "{ROOT / 'sample_data' / 'stale.json'}"
""")
    return config


def section_batch(passes: int, workers: int, work: Path, runs: int) -> None:
    t0 = time.perf_counter()
    days = make_workload(work, passes)
    print(f"\n== batch ingest -> smooth -> refine, {passes} passes of {days} simulated days (six stations, 1 s, "
          f"Doppler + elevation, seed = day), made in {time.perf_counter() - t0:.0f} s ==")
    exe = trackproc_exe()
    env = bytecode_env(work / "cache")
    for n_workers in sorted({1, workers}):
        config = batch_config(work, n_workers)
        cmd = [exe, "-q", "batch", str(config), "-o", str(work / f"out-{n_workers}")]
        run_group(cmd, env)                                           # warm: kernels, bytecode, caches
        cpus, walls = [], []
        for _ in range(runs):
            cpu, wall = run_group(cmd, env)
            cpus.append(cpu), walls.append(wall)
        cpu, wall = statistics.median(cpus), statistics.median(walls)
        print(f"  {n_workers} worker{'s' if n_workers > 1 else ' '} (load {load()}): {cpu / passes:.3f} s CPU a pass "
              f"(median of {runs}: {min(cpus) / passes:.3f}-{max(cpus) / passes:.3f}), {wall:.1f} s wall, "
              f"{passes / wall:.1f} passes/s; 500 passes at this rate: {500 * wall / passes:.0f} s wall "
              f"(target <= 0.06 s CPU a pass, 500 in <= 30 s on 2 workers)")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--passes", type=int, default=200)
    p.add_argument("--runs", type=int, default=5, help="timed runs of each figure (after a warm-up)")
    p.add_argument("--batch-runs", type=int, default=1, help="timed runs of each batch (after a warm-up)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--only", default="help,refine,batch")
    p.add_argument("--keep", metavar="DIR", help="work in DIR and keep it (the workload can be reused)")
    args = p.parse_args(argv)
    want = set(args.only.split(","))
    print(f"{os.cpu_count()} cores, load average {load()}, Python {sys.version.split()[0]}")
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="trackproc-nightly-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        if "help" in want:
            section_help(args.runs, work)
        if "refine" in want:
            section_refine(args.runs, work)
        if "batch" in want:
            section_batch(args.passes, args.workers, work / "batch", args.batch_runs)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
