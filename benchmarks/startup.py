"""Time `trackproc --help` and `trackproc --version` (target: under 0.2 s), median of N runs.

Run: python benchmarks/startup.py [N]
"""

import shutil
import statistics
import subprocess
import sys
import time


def median_time(cmd, runs):
    samples = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def main():
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 7
    from pathlib import Path

    beside = Path(sys.executable).with_name("trackproc")  # the venv's console script
    exe = str(beside) if beside.exists() else shutil.which("trackproc") or "trackproc"
    base = median_time([sys.executable, "-c", "pass"], runs)
    for args in (["--help"], ["--version"], ["ingest", "--help"]):
        t = median_time([exe, *args], runs)
        print(f"trackproc {' '.join(args):<16} median {t * 1e3:7.1f} ms   (bare python {base * 1e3:.1f} ms, "
              f"ratio {t / base:.1f}x)")
    probe = subprocess.run([sys.executable, "-c", "import sys, trackproc.cli.app as a; a._register();"
                            "print(' '.join(m for m in ('numpy','pandas','scipy','pyarrow') if m in sys.modules))"],
                           capture_output=True, text=True, check=True)
    print("heavy modules imported by the CLI at start-up:", probe.stdout.strip() or "none")


if __name__ == "__main__":
    main()
