"""Peak memory (max RSS) and time of large inputs: the measurement issue 14 item 5 asks for.

- ``ingest`` of a wide CSV and of a wide Parquet of N rows (target: 5e6 rows in < 1 GB), and
  ``info`` of the pass file it wrote;
- ``smooth`` of P small passes (one fit each) and the read-back of its P records
  (target: 10,000 passes written and read back; before, ~2,300 passed Arrow's footer limit).

Run: python benchmarks/ingest_memory.py [--rows 1e6,5e6] [--passes 10000]
(defaults as shown; ~3 min on a 2-core machine, most of it the 5e6-row CSV). Each command runs in
its own process; the files are written to a temporary folder and removed.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

EXE = str(Path(sys.executable).with_name("trackproc"))
T0 = np.datetime64("2026-03-20T09:00:00", "ms")


def write_csv(path: Path, n: int) -> None:
    rng = np.random.default_rng(1)
    with open(path, "w") as handle:
        handle.write("time,station,range_m\n")
        for start in range(0, n, 200_000):
            stop = min(n, start + 200_000)
            times = np.datetime_as_string(T0 + np.arange(start, stop) * np.timedelta64(100, "ms"), unit="ms")
            ranges = 1.0e6 + rng.normal(0.0, 10.0, stop - start)
            handle.write("".join(f"{t}Z,CPH,{r:.3f}\n" for t, r in zip(times, ranges)))


def write_parquet(path: Path, n: int) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    rng = np.random.default_rng(1)
    times = (T0 + np.arange(n) * np.timedelta64(100, "ms")).astype("datetime64[ms]")
    table = pa.table({"time": pa.array(times, pa.timestamp("ms", tz="UTC")),
                      "station": pa.array(np.full(n, "CPH", dtype=object), pa.string()),
                      "range_m": 1.0e6 + rng.normal(0.0, 10.0, n)})
    pq.write_table(table, path, compression="zstd")


def write_passes(path: Path, passes: int, samples: int = 8) -> None:
    """A canonical pass file of ``passes`` elevation passes of ``samples`` samples, 1 h apart."""
    import pandas as pd

    from trackproc.io.passfile import PassTable, base_meta, write_pass_table

    rng = np.random.default_rng(2)
    start = pd.Timestamp("2026-03-20T00:00:00Z")
    t = (np.arange(passes)[:, None] * 3600.0 + np.arange(samples)[None, :] * 10.0).ravel()
    frame = pd.DataFrame({
        "time": start + pd.to_timedelta(np.round(t * 1e9).astype(np.int64), unit="ns"),
        "station": "CPH",
        "pass_id": np.repeat([f"CPH-{i + 1:05d}" for i in range(passes)], samples),
        "kind": "elevation",
        "value": 0.3 + 0.01 * np.tile(np.arange(samples), passes) + rng.normal(0, 1e-4, t.size),
        "sigma": 1e-4,
    })
    meta = base_meta(stations={"CPH": {"lat_deg": 55.7, "lon_deg": 12.55, "height_m": 30.0}})
    write_pass_table(PassTable(frame, meta), str(path))


READ_RECORDS = ("import sys; from trackproc.io.passfile import read_pass_table; "
                "from trackproc.io.smoothing_record import smoothing_of, find_fit_record; "
                "t = read_pass_table(sys.argv[1]); recs = list(smoothing_of(t.meta)['fits']); "
                "assert len(recs) == int(sys.argv[2]), len(recs); "
                "assert find_fit_record(t.meta, 'CPH', recs[-1]['pass_id'], 'elevation') == recs[-1]")


def measure(cmd: list[str]) -> tuple[float, float, int, str]:
    """(peak RSS of the command in MB, wall seconds, exit code, last stderr line), in a fresh process."""
    wrapper = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, "
               "stderr=subprocess.PIPE, text=True); "
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, p.returncode); "
               "print((p.stderr.strip().splitlines() or [''])[-1])")
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", wrapper, *cmd], capture_output=True, text=True, check=True)
    first, _, last = out.stdout.partition("\n")
    kb, code = first.split()
    return int(kb) / 1024.0, time.perf_counter() - t0, int(code), last.strip()


def row(what: str, n: int, size_mb: float, result) -> None:
    mb, seconds, code, message = result
    note = "" if code == 0 else f"  exit {code}: {message}"
    print(f"{what:<28} {n:>10} {size_mb:>9.1f} {mb:>9.0f} {seconds:>8.1f}{note}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", default="1e6,5e6", help="comma-separated row counts")
    parser.add_argument("--passes", type=int, default=10_000)
    args = parser.parse_args()
    sizes = [int(float(a)) for a in args.rows.split(",") if a]
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        stations = work / "st.csv"
        stations.write_text("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\n")
        print(f"{'what':<28} {'rows/fits':>10} {'input MB':>9} {'peak MB':>9} {'seconds':>8}")
        for n in sizes:
            for fmt, writer in (("csv", write_csv), ("parquet", write_parquet)):
                raw = work / f"raw.{fmt}"
                writer(raw, n)
                out = work / "pass.parquet"
                size = raw.stat().st_size / 1e6
                row(f"ingest {fmt}", n, size, measure([EXE, "ingest", str(raw), "--stations", str(stations),
                                                       "-q", "-o", str(out)]))
                raw.unlink()
            if out.exists():
                row("info (the pass file)", n, out.stat().st_size / 1e6, measure([EXE, "info", str(out), "-q"]))
                out.unlink()
        if args.passes:
            passes, smoothed = work / "passes.parquet", work / "smoothed.parquet"
            write_passes(passes, args.passes)
            row("smooth (one fit a pass)", args.passes, passes.stat().st_size / 1e6,
                measure([EXE, "smooth", str(passes), "--degree", "2", "--clip", "0", "-q", "-o", str(smoothed)]))
            side = smoothed.with_name("smoothed.passes.parquet")
            size = (smoothed.stat().st_size + (side.stat().st_size if side.exists() else 0)) / 1e6
            row("read back every record", args.passes, size,
                measure([sys.executable, "-c", READ_RECORDS, str(smoothed), str(args.passes)]))
            row("info (the smoothed file)", args.passes, size, measure([EXE, "info", str(smoothed), "-q"]))


if __name__ == "__main__":
    main()
