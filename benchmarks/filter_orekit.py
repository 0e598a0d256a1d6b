"""``trackproc filter`` beside Orekit's ``KalmanEstimator`` (issue 27, "Side by side"): the simulated
3-station range + range-rate set of ``benchmarks/estimate.py`` / docs/estimate_orekit.md (ZHY, KIR,
MAD, 1 Hz, range 10 m, one-way range-rate 1 cm/s, range biases +100 / -80 / +120 m, two-body,
Orekit's one-way ``RangeRate`` = ``--range-rate-model instantaneous``, one finals2000A file),
filtered by both from the same first guess (0.96 km, 0.98 m/s off) with the same a-priori
(1 km, 1 m/s per axis, range biases 1 km), no process noise, no editing.

Printed: the two filtered states at the last measurement (state and the three range biases),
their difference in the filters' sigmas, the sigmas' ratio, and the CPU time (user + system) of
each as a child process, measured in this run (``resource.getrusage(RUSAGE_CHILDREN)``
around each), and their ratio. Timing is never asserted; the targets (within 1 sigma,
>= 10x less CPU) are printed beside the numbers.

Run:  python benchmarks/filter_orekit.py [--hours 24] [--step 1] [--keep DIR]
      (the Orekit child: python benchmarks/filter_orekit.py --child CONFIG.json OUT.json)
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))     # the Orekit set-up shared with benchmarks/estimate.py
import orekit_helpers as oh  # noqa: E402

SIGMA_POSITION_M, SIGMA_VELOCITY_M_S, SIGMA_BIAS_M = 1000.0, 1.0, 1000.0


def scaled_guess(scale: float) -> dict:
    """The shared first guess moved towards the truth: ``truth + scale (guess - truth)``."""
    import numpy as np

    return {**oh.GUESS, **{k: list(np.add(oh.TRUTH[k], scale * np.subtract(oh.GUESS[k], oh.TRUTH[k])))
                          for k in ("position_m", "velocity_m_s")}}


def orekit_kalman(config: dict) -> dict:
    """Orekit's extended ``KalmanEstimator`` over the pass file's range and range-rate samples
    (built by ``orekit_helpers._Setup.measurements``, a range ``Bias`` per station), the numerical
    two-body propagator of the BatchLS comparison, ``ConstantProcessNoise`` with the a-priori as
    its initial covariance and zero process noise; returns the last filtered state, biases and
    covariance (physical units, Cartesian GCRF)."""
    t_start = time.process_time()
    jvm_s, data = oh._start(config["eop"])
    try:
        from org.hipparchus.linear import MatrixUtils, QRDecomposer
        from org.orekit.estimation.sequential import ConstantProcessNoise, KalmanEstimatorBuilder
        from org.orekit.utils import ParameterDriversList

        setup = oh._Setup(config)
        frame = oh._read_passes([config["passes"]])
        frame = frame.sort_values("time", kind="stable").reset_index(drop=True)
        ms, _ = setup.measurements(frame, range_bias=True)
        orbit = setup.orbit(config["initial"])
        builder = oh._numerical_builder(setup, orbit, config)
        sp, sv = config["sigma_position_m"], config["sigma_velocity_m_s"]
        p0 = MatrixUtils.createRealDiagonalMatrix([sp ** 2] * 3 + [sv ** 2] * 3)
        q0 = MatrixUtils.createRealMatrix(6, 6)
        drivers = ParameterDriversList()
        seen = set()
        for m in ms:
            for d in m.getParametersDrivers():
                if d.isSelected() and str(d.getName()) not in seen:
                    seen.add(str(d.getName()))
                    drivers.add(d)
        nb = drivers.getNbParams()
        kb = KalmanEstimatorBuilder()
        kb.decomposer(QRDecomposer(1e-15))
        kb.addPropagationConfiguration(builder, ConstantProcessNoise(p0, q0))
        kb.estimatedMeasurementsParameters(drivers, ConstantProcessNoise(
            MatrixUtils.createRealDiagonalMatrix([SIGMA_BIAS_M ** 2] * nb), MatrixUtils.createRealMatrix(nb, nb)))
        kalman = kb.build()
        from java.util import ArrayList

        todo = ArrayList()
        for m in ms:
            todo.add(m)
        t0 = time.process_time()
        props = kalman.processMeasurements(todo)
        filter_cpu = time.process_time() - t0
        state = props[0].getInitialState()
        pv = state.getPVCoordinates(setup.gcrf)
        p, v = pv.getPosition(), pv.getVelocity()
        names = ["x", "y", "z", "vx", "vy", "vz"] + [str(d.getName()) for d in drivers.getDrivers()]
        values = [p.getX(), p.getY(), p.getZ(), v.getX(), v.getY(), v.getZ()] + [
            float(d.getValue()) for d in drivers.getDrivers()]
        cov = kalman.getPhysicalEstimatedCovarianceMatrix()
        n = cov.getRowDimension()
        return {"names": names, "values": values,
                "covariance": [[float(cov.getEntry(i, j)) for j in range(n)] for i in range(n)],
                "epoch": str(state.getDate()), "measurements": len(ms), "jvm_start_s": jvm_s,
                "filter_cpu_s": filter_cpu, "process_cpu_s": time.process_time() - t_start,
                "orekit_version": oh._orekit_version()}
    finally:
        shutil.rmtree(data, ignore_errors=True)


def child_cpu(cmd) -> tuple:
    """Run ``cmd``; return (CompletedProcess, CPU seconds user + system of that child and its
    children, wall seconds)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return proc, cpu, wall


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hours", type=float, default=24.0)
    p.add_argument("--step", type=float, default=1.0, help="sample step, s (1: ~24,000 samples in 24 h)")
    p.add_argument("--guess-scale", type=float, default=1.0,
                   help="first guess truth + F (shared guess - truth), a-priori state sigmas x F "
                        "(1: the shared guess, 0.96 km / 0.98 m/s off, a-priori 1 km / 1 m/s)")
    p.add_argument("--keep", metavar="DIR")
    p.add_argument("--child", nargs=2, metavar=("CONFIG", "OUT"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        cfg, out = a.child
        Path(out).write_text(json.dumps(orekit_kalman(json.loads(Path(cfg).read_text()))))
        return 0
    import numpy as np

    ok, why = oh.availability()
    if not ok:
        print(f"orekit: not installed ({why})")
        return 0
    d = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench-filter-orekit-"))
    d.mkdir(parents=True, exist_ok=True)
    try:
        eop, biased = oh.write_case_inputs(d)
        tp = [sys.executable, "-m", "trackproc"]
        proc, _, _ = child_cpu(tp + ["-q", "simulate", "--state", d / "truth.json", "--stations", d / "stations.csv",
                                     "--duration", f"{a.hours * 3600:g}", "--step", f"{a.step:g}",
                                     "--elevation-mask-deg", "7", "--eop", eop, "--kinds", "range,range_rate",
                                     "--seed", "11", *biased, *oh.MODEL, "-o", d / "passes.parquet"])
        if proc.returncode:
            raise SystemExit(proc.stderr)
        import pandas as pd

        n = len(pd.read_parquet(d / "passes.parquet"))
        guess = scaled_guess(a.guess_scale)
        sp, sv = SIGMA_POSITION_M * a.guess_scale, SIGMA_VELOCITY_M_S * a.guess_scale
        (d / "guess.json").write_text(json.dumps(guess))
        ours_cmd = tp + ["-q", "filter", d / "passes.parquet", "--initial", d / "guess.json", "--stations",
                         d / "stations.csv", "--eop", eop, "--range-bias", "--apriori-sigma",
                         f"position={sp:g}", "--apriori-sigma", f"velocity={sv:g}",
                         "--apriori-sigma", f"range_bias={SIGMA_BIAS_M:g}", "--edit-sigma", "0", *oh.MODEL,
                         "-o", d / "trackproc.json"]
        proc, ours_cpu, ours_wall = child_cpu(ours_cmd)
        if proc.returncode not in (0, 1):
            raise SystemExit(proc.stderr)
        ours = json.loads((d / "trackproc.json").read_text())
        config = {"eop": str(eop), "stations": str(d / "stations.csv"), "passes": str(d / "passes.parquet"),
                  "initial": guess, "integrator": {"position_tolerance_m": 1e-6},
                  "sigma_position_m": sp, "sigma_velocity_m_s": sv}
        (d / "orekit_kalman.json").write_text(json.dumps(config))
        proc, ore_cpu, ore_wall = child_cpu([sys.executable, Path(__file__).resolve(), "--child",
                                             d / "orekit_kalman.json", d / "orekit_result.json"])
        if proc.returncode:
            raise SystemExit(proc.stderr[-4000:])
        ore = json.loads((d / "orekit_result.json").read_text())
        names = ours["parameters"]
        idx = [ore["names"].index(nm) for nm in names]
        x, sig = np.array(ours["values"]), np.array(ours["sigma"])
        xo = np.array(ore["values"])[idx]
        sigo = np.sqrt(np.diag(np.array(ore["covariance"])))[idx]
        z = (x - xo) / np.maximum(sig, sigo)
        # the truth at the last measurement (two-body, trackproc's propagator) and the simulated biases
        from trackproc.dynamics import propagator
        from trackproc.dynamics import timescales as ts

        t0 = np.datetime64(oh.TRUTH["epoch"].rstrip("Z"), "ns")
        t1 = np.datetime64(ours["epoch"].rstrip("Z"), "ns")
        dt = float(ts.seconds_since(ts.datetime64_to_jd_utc(t1), ts.datetime64_to_jd_utc(t0)))
        traj = propagator.propagate(np.array(oh.TRUTH["position_m"]), np.array(oh.TRUTH["velocity_m_s"]), t0, [dt],
                                    force="two-body")
        truth = dict(zip(["x", "y", "z", "vx", "vy", "vz"], traj.state(dt)))
        truth.update({f"range_bias:{k}": v for k, v in oh.BIASES.items()})
        xt = np.array([truth[nm] for nm in names])
        print(f"== {n} range + range-rate samples over {a.hours:g} h at {a.step:g} s, 3 stations; filtered state "
              f"at the last measurement: trackproc {ours['epoch']}, Orekit {ore['epoch']} ==")
        print(f"first guess {a.guess_scale:g} x (0.96 km, 0.98 m/s) off, a-priori {sp:g} m / {sv:g} m/s")
        print(f"{'parameter':>16} {'trackproc':>18} {'sigma':>10} {'Orekit':>18} {'sigma':>10} {'diff/sigma':>10} "
              f"{'ours-truth/s':>12} {'Orekit-truth/s':>14}")
        for nm, a1, s1, a2, s2, zz, tt in zip(names, x, sig, xo, sigo, z, xt):
            print(f"{nm:>16} {a1:18.4f} {s1:10.4g} {a2:18.4f} {s2:10.4g} {zz:10.3g} {(a1 - tt) / s1:12.3g} "
                  f"{(a2 - tt) / s2:14.3g}")
        print(f"max |trackproc - Orekit| / sigma = {np.abs(z).max():.3g} (target <= 1); sigma ratio "
              f"{(sig / sigo).min():.4f}-{(sig / sigo).max():.4f}; trackproc verdict "
              f"{ours['quality']['verdict']} ({', '.join(r['code'] for r in ours['quality']['reasons'] if r['severity'] != 'ok')})")
        print(f"CPU (user + system, child processes, this run): trackproc filter {ours_cpu:.1f} s "
              f"(wall {ours_wall:.1f} s), Orekit KalmanEstimator {ore_cpu:.1f} s (wall {ore_wall:.1f} s; "
              f"processMeasurements alone {ore['filter_cpu_s']:.1f} s of the JVM thread, JVM start "
              f"{ore['jvm_start_s']:.1f} s); ratio {ore_cpu / ours_cpu:.1f}x (target >= 10x); Orekit "
              f"{ore['orekit_version']}")
        return 0
    finally:
        if not a.keep:
            shutil.rmtree(d, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
