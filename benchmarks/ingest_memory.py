"""Peak memory (max RSS) of `trackproc ingest` on a wide CSV of N rows, and of `info` on the
result: the measurement issue 14 item 5 asks for (target: 5e6 rows in < 1 GB).

Run: python benchmarks/ingest_memory.py [N ...]   (default 1e5 3e5 1e6; ~1 min in all)
Each N runs in its own process; the CSV is written to a temporary folder and removed.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def write_csv(path: Path, n: int) -> None:
    t0 = np.datetime64("2026-03-20T09:00:00", "ms")
    times = np.datetime_as_string(t0 + np.arange(n) * np.timedelta64(100, "ms"), unit="ms")
    rng = np.random.default_rng(1)
    ranges = 1.0e6 + rng.normal(0.0, 10.0, n)
    with open(path, "w") as handle:
        handle.write("time,station,range_m\n")
        for start in range(0, n, 100_000):
            stop = min(n, start + 100_000)
            handle.write("".join(f"{t}Z,CPH,{r:.3f}\n" for t, r in zip(times[start:stop], ranges[start:stop])))


def peak_rss_mb(cmd: list[str]) -> tuple[float, float, int]:
    """(peak RSS of the child in MB, wall seconds, exit code) of one command in a fresh process."""
    wrapper = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL); "
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, p.returncode)")
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", wrapper, *cmd], capture_output=True, text=True, check=True)
    kb, code = out.stdout.split()
    return int(kb) / 1024.0, time.perf_counter() - t0, int(code)


def main() -> None:
    sizes = [int(float(a)) for a in sys.argv[1:]] or [100_000, 300_000, 1_000_000]
    exe = str(Path(sys.executable).with_name("trackproc"))
    with tempfile.TemporaryDirectory() as folder:
        stations = Path(folder) / "st.csv"
        stations.write_text("station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\n")
        print(f"{'rows':>10} {'csv MB':>8} {'ingest MB':>10} {'x csv':>6} {'s':>6} {'info MB':>8}")
        for n in sizes:
            raw = Path(folder) / f"raw_{n}.csv"
            write_csv(raw, n)
            size = raw.stat().st_size / 1e6
            out = Path(folder) / f"pass_{n}.parquet"
            mb, wall, code = peak_rss_mb([exe, "ingest", str(raw), "--stations", str(stations), "-q", "-o", str(out)])
            info_mb, _, info_code = peak_rss_mb([exe, "info", str(out), "-q"]) if code == 0 else (float("nan"), 0, 1)
            print(f"{n:>10} {size:>8.1f} {mb:>10.0f} {mb / size:>6.1f} {wall:>6.1f} {info_mb:>8.0f}"
                  + ("" if code == 0 and info_code == 0 else f"  (exit {code}/{info_code})"))
            raw.unlink()
            if out.exists():
                os.unlink(out)


if __name__ == "__main__":
    main()
