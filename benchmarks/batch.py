"""Passes per second of ``trackproc batch`` (ingest -> smooth): 1 worker, 2 worker processes, and
a local Dask cluster (2 worker processes) reached over loopback TCP, on simulated passes.

Run: python benchmarks/batch.py [--passes N] [--step S] [--repeat R]

A directory of N raw passes (wide CSV, one-way Doppler and elevation, one sample every S s,
defaults 120 and 1 s) is made from one simulated day seen by six stations (its passes longer than
4 minutes, repeated under new names up to N); every run redoes all of them (``force``)
into its own output directory, and the median of R runs is kept. The wall time includes
starting the process pool (forkserver) and connecting to the cluster, not starting the
cluster itself. The outputs of the three ways are checked to be byte-identical. Needs
``trackproc[dask]`` for the cluster (skipped, with a note, without it).
"""

from __future__ import annotations

import os

# as `trackproc batch` does before numpy is loaded: one BLAS thread per process (see
# trackproc.pipeline.batch.single_thread_blas); the pool's and the cluster's workers do the same
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_name] = "1"

import argparse  # noqa: E402
import hashlib  # noqa: E402
import logging  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

STATIONS = ("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\nZHY,50.25,28.66,230\nKIR,67.857,20.964,400\n"
            "MAD,40.43,-4.25,800\nSVB,78.23,15.4,500\nHBK,-25.89,27.69,1500\n")
ROOT = Path(__file__).resolve().parents[1]


def make_passes(directory: Path, n: int, step_s: float) -> int:
    """Write ``n`` pass CSVs into ``directory/inbox`` and the stations table beside it: the passes
    of one simulated day longer than 4 minutes, repeated under new names until there are ``n``."""
    from trackproc.io.stations import parse_stations
    from trackproc.io.statefile import read_state
    from trackproc.pipeline.simulate import SimulateOptions, simulate

    inbox = directory / "inbox"
    inbox.mkdir(parents=True)
    (directory / "stations.csv").write_text(STATIONS)
    sim = simulate(read_state(str(ROOT / "sample_data" / "truth.json")), parse_stations(STATIONS.encode(), "st"),
                   SimulateOptions(duration_s=86400, step_s=step_s, kinds=("doppler", "elevation"), seed=1,
                                   sigma_doppler_hz=0.5))
    frame, wide = sim.frame, sim.wide()
    sizes = frame.groupby(["station", "pass_id"]).size()
    keys = [k for k in sizes.index if sizes[k] >= 2 * 240 / step_s]
    texts = []
    for station, pass_id in keys:
        times = frame.loc[(frame["station"] == station) & (frame["pass_id"] == pass_id), "time"].unique()
        sub = wide[(wide["station"] == station) & wide["time"].isin(times)]
        texts.append((pass_id, sub.assign(time=sub["time"].dt.strftime("%Y-%m-%dT%H:%M:%SZ")).to_csv(index=False)))
    for i in range(n):
        pass_id, text = texts[i % len(texts)]
        (inbox / f"{pass_id}-{i // len(texts) + 1:02d}.csv").write_text(text)
    return n


def settings_for(directory: Path, output: Path, **flags):
    from trackproc.pipeline.batch.config import resolve

    base = {"batch.inputs": [str(directory / "inbox")], "batch.output": str(output), "batch.force": True,
            "ingest.stations": str(directory / "stations.csv"), "ingest.carrier_hz": 2.2e9,
            "ingest.mode": "one-way"}
    base.update(flags)
    return resolve(None, base, environ={})


def timed(directory: Path, name: str, repeat: int, **flags) -> tuple:
    from trackproc.pipeline.batch import run_batch

    times = []
    output = directory / f"out-{name}"
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = run_batch(settings_for(directory, output, **flags))
        times.append(time.perf_counter() - t0)
        assert result.exit_code == 0, result.counts
    return statistics.median(times), output


def digest(out: Path) -> str:
    h = hashlib.sha256()
    for p in sorted((out / "passes").rglob("*")):
        if p.is_file() and not p.name.endswith(".batch.json"):
            h.update(p.name.encode() + p.read_bytes())
    return h.hexdigest()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--passes", type=int, default=120)
    parser.add_argument("--step", type=float, default=1.0, help="sample step of the passes, s")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    logging.getLogger("trackproc").setLevel(logging.ERROR)  # the suspect-fit warnings of short passes
    directory = Path(tempfile.mkdtemp(prefix="trackproc-bench-batch-"))
    try:
        t0 = time.perf_counter()
        n = make_passes(directory, args.passes, args.step)
        samples = sum(sum(1 for _ in open(p)) - 1 for p in (directory / "inbox").iterdir())
        print(f"{n} simulated passes, {samples} rows ({2 * samples} samples: Doppler + elevation), "
              f"one every {args.step:g} s; made in {time.perf_counter() - t0:.1f} s")
        rows = []
        t1, out1 = timed(directory, "serial", args.repeat, **{"batch.workers": 1})
        rows.append(("1 worker (this process)", t1, out1))
        t2, out2 = timed(directory, "pool2", args.repeat, **{"batch.workers": 2})
        rows.append(("2 worker processes", t2, out2))
        try:
            from distributed import LocalCluster
        except ImportError:
            LocalCluster = None
            print("Dask distributed not installed (pip install 'trackproc[dask]'): cluster run skipped")
        if LocalCluster is not None:
            with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                              dashboard_address=None) as cluster:
                t3, out3 = timed(directory, "dask", args.repeat, **{"batch.scheduler": cluster.scheduler_address})
            rows.append(("Dask LocalCluster, 2 workers, loopback", t3, out3))
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        load = " ".join(f"{x:.1f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "?"
        print(f"cores available: {cores}; load average now (1, 5, 15 min): {load}")
        print(f"{'how':<42} {'median wall s':>13} {'passes/s':>9} {'vs 1 worker':>12}")
        for label, seconds, _ in rows:
            print(f"{label:<42} {seconds:13.2f} {n / seconds:9.1f} {t1 / seconds:11.2f}x")
        same = len({digest(out) for _, _, out in rows}) == 1
        print("outputs byte-identical across the runs:", same)
    finally:
        shutil.rmtree(directory, ignore_errors=True)


if __name__ == "__main__":
    main()
