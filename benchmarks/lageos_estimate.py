"""A 3-day LAGEOS-like arc estimated with the full force model (issue 17 item 6): ``trackproc
estimate`` against Orekit 13's ``BatchLSEstimator`` on the same simulated laser ranges, the same
forces, side by side in one run.

Run:  python benchmarks/lageos_estimate.py [--days 3] [--step 120] [--numpy] [--no-orekit] [--keep DIR]

The case: ``trackproc simulate --force full`` of a LAGEOS-like orbit (a 12,162 km, e 0.0138,
109.8 deg; tests/io/test_forces_orekit.py's LAGEOS) from six SLR stations (Yarragadee, Graz,
Greenbelt, Herstmonceux, Matera, Hartebeesthoek; 20 deg mask) every --step s over --days days:
two-way ranges with 1 cm noise, no troposphere, no biases. Force model of both sides: EIGEN-6S
20x20 (tide-free, its own GM and radius), Sun and Moon point masses, cannon-ball SRP with the
conical shadow of the Earth (LAGEOS: 405.38 kg, 0.2827 m², Cr 1.13), the Schwarzschild term.
Estimated by both: the state and Cr, from a first guess 100 m and 5 cm/s off and Cr 1.0.
trackproc: ``estimate --force full ... --estimate-force cr --clip 0``, Gauss-Newton; Orekit:
NumericalPropagatorBuilder (DormandPrince853, 1e-6 m position tolerance, 300 s maximum step)
with the same force models (HolmesFeatherstone, ThirdBodyAttraction on DE-440, Relativity,
SolarRadiationPressure with the ellipsoid's occultation), Cr driver selected, Gauss-Newton/QR.

Printed: wall time and CPU of each child process (trackproc: a fresh interpreter end to end,
with numba's cached kernels when installed, and with ``--numpy`` once more with ``TRACKPROC_JIT=0``; Orekit: the
JVM start, the set-up and ``estimate()`` apart), peak resident memory (``os.wait4``),
iterations, and the difference of the two solutions in metres and in trackproc's sigmas. The
two models differ by design in small things (ERFA vs DE-440 Sun and Moon, the shadow of the
ellipsoid), a few centimetres over three days (tests/io/test_forces_orekit.py); that difference,
not the estimators, sets how close the two answers can be. Timing is never asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "io"))  # test_forces_orekit
import orekit_helpers as oh  # noqa: E402

EPOCH = "2020-04-05T00:00:00"
STATIONS = ("station,lat_deg,lon_deg,height_m\nYARL,-29.0464,115.3467,244\nGRZL,47.0671,15.4933,539\n"
            "GODL,39.0206,-76.8277,19\nHERL,50.8674,0.3361,75\nMATM,40.6486,16.7046,536\nHRAL,-25.8897,27.6861,1406\n")
SC = {"mass_kg": 405.38, "srp_area_m2": 0.2827, "cr": 1.13}
CR_GUESS = 1.0
FORCE = ["--force", "full", "--gravity", "20", "--third-body", "sun,moon", "--srp", "--relativity",
         "--mass-kg", str(SC["mass_kg"]), "--srp-area-m2", str(SC["srp_area_m2"])]


def _truth():
    from test_forces_orekit import LAGEOS

    return np.asarray(LAGEOS[0], float), np.asarray(LAGEOS[1], float)


def make_case(d: Path, days: float, step: float) -> dict:
    eop = oh.write_linear_finals2000a(d / "finals2000A.txt", 58940, 10, -0.2, -3e-4, 0.05, 1e-4, 0.4, 2e-4)
    r, v = _truth()
    state = {"epoch": EPOCH, "frame": "GCRF", "position_m": list(r), "velocity_m_s": list(v)}
    (d / "truth.json").write_text(json.dumps(state))
    rng = np.random.default_rng(5)
    dr = rng.normal(size=3)
    dv = rng.normal(size=3)
    guess = {**state, "position_m": list(r + 100.0 * dr / np.linalg.norm(dr)),
             "velocity_m_s": list(v + 0.05 * dv / np.linalg.norm(dv))}
    (d / "guess.json").write_text(json.dumps(guess))
    (d / "stations.csv").write_text(STATIONS)
    child = oh.run_measured([sys.executable, "-m", "trackproc", "-q", "simulate", "--state", d / "truth.json",
                             "--stations", d / "stations.csv", "--duration", f"{days * 86400:g}", "--step",
                             f"{step:g}", "--elevation-mask-deg", "20", "--eop", eop, "--kinds", "range",
                             "--mode", "two-way", "--sigma-range-m", "0.01", "--seed", "3", *FORCE, "--cr",
                             str(SC["cr"]), "-o", d / "ranges.parquet"])
    if child["returncode"] != 0:
        raise SystemExit(f"trackproc simulate failed:\n{child['stderr']}")
    import pandas as pd

    frame = pd.read_parquet(d / "ranges.parquet")
    return {"eop": eop, "passes": d / "ranges.parquet", "samples": len(frame),
            "passes_n": frame["pass_id"].nunique(), "simulate_s": child["wall_s"], "guess": guess, "truth": state}


def run_trackproc(d: Path, case: dict, jit: bool) -> dict:
    cmd = [sys.executable, "-m", "trackproc", "estimate", case["passes"], "--initial", d / "guess.json",
           "--stations", d / "stations.csv", "--eop", case["eop"], *FORCE, "--cr", str(CR_GUESS),
           "--estimate-force", "cr", "--troposphere", "none", "--clip", "0", "--json", "-o", d / "trackproc.json"]
    old = os.environ.get("TRACKPROC_JIT")
    os.environ["TRACKPROC_JIT"] = "1" if jit else "0"              # the child inherits it
    try:
        t0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        child = oh.run_measured(cmd, timeout_s=1200)
        t1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    finally:
        os.environ.pop("TRACKPROC_JIT")
        if old is not None:
            os.environ["TRACKPROC_JIT"] = old
    if child["returncode"] != 0:
        raise SystemExit(f"trackproc estimate failed ({child['returncode']}):\n{child['stderr'][-3000:]}")
    summary = json.loads(child["stderr"].strip().splitlines()[-1])
    return {"wall_s": child["wall_s"], "cpu_s": (t1.ru_utime + t1.ru_stime) - (t0.ru_utime + t0.ru_stime),
            "maxrss_mb": child["maxrss_mb"], "summary": summary,
            "result": json.loads((d / "trackproc.json").read_text())}


# ------------------------------------------------------------------------------ Orekit (child)
def orekit_estimate(config: dict) -> dict:
    """In a child process: Orekit's BatchLSEstimator with the full force model (see the module doc)."""
    t_start = time.perf_counter()
    jvm_s, data = oh._start(config["eop"], full_force=True)
    try:
        return _orekit_estimate(config, jvm_s, t_start)
    finally:
        shutil.rmtree(data, ignore_errors=True)


def _orekit_estimate(config, jvm_s, t_start):
    from org.hipparchus.linear import QRDecomposer
    from org.hipparchus.optim.nonlinear.vector.leastsquares import GaussNewtonOptimizer
    from org.orekit.bodies import CelestialBodyFactory
    from org.orekit.estimation.leastsquares import BatchLSEstimator
    from org.orekit.forces.gravity import HolmesFeatherstoneAttractionModel, Relativity, ThirdBodyAttraction
    from org.orekit.forces.gravity.potential import GravityFieldFactory
    from org.orekit.forces.radiation import IsotropicRadiationSingleCoefficient, SolarRadiationPressure
    from org.orekit.orbits import PositionAngleType
    from org.orekit.propagation.conversion import DormandPrince853IntegratorBuilder, NumericalPropagatorBuilder

    provider = GravityFieldFactory.getNormalizedProvider(20, 20)
    setup = oh._Setup({**config, "mu": provider.getMu()})
    t0 = time.perf_counter()
    frame = oh._read_passes([config["passes"]])
    ms, _ = setup.measurements(frame, range_bias=False)
    orbit = setup.orbit(config["initial"])
    builder = NumericalPropagatorBuilder(orbit, DormandPrince853IntegratorBuilder(1e-3, 300.0, 1e-6),
                                         PositionAngleType.MEAN, 1.0)
    builder.setMass(float(config["mass_kg"]))
    builder.addForceModel(HolmesFeatherstoneAttractionModel(setup.itrf, provider))
    builder.addForceModel(ThirdBodyAttraction(CelestialBodyFactory.getSun()))
    builder.addForceModel(ThirdBodyAttraction(CelestialBodyFactory.getMoon()))
    builder.addForceModel(Relativity(provider.getMu()))
    builder.addForceModel(SolarRadiationPressure(CelestialBodyFactory.getSun(), setup.earth,
                                                 IsotropicRadiationSingleCoefficient(float(config["area_m2"]),
                                                                                     float(config["cr"]))))
    for driver in builder.getPropagationParametersDrivers().getDrivers():
        if "reflection" in str(driver.getName()):
            driver.setSelected(True)
    estimator = BatchLSEstimator(GaussNewtonOptimizer(QRDecomposer(1e-11), False), [builder])
    estimator.setParametersConvergenceThreshold(1e-3)
    estimator.setMaxIterations(20)
    estimator.setMaxEvaluations(40)
    for m in ms:
        estimator.addMeasurement(m)
    setup_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    props = estimator.estimate()
    estimate_s = time.perf_counter() - t0
    pv = props[0].getInitialState().getOrbit().getPVCoordinates(setup.gcrf)
    p, v = pv.getPosition(), pv.getVelocity()
    prop_drivers = list(estimator.getPropagatorParametersDrivers(True).getDrivers())
    cov = estimator.getPhysicalCovariances(1e-14)
    n = cov.getRowDimension()
    return {"state": [p.getX(), p.getY(), p.getZ(), v.getX(), v.getY(), v.getZ()],
            "cr": float(prop_drivers[0].getValue()) if prop_drivers else None,
            "covariance": [[float(cov.getEntry(i, j)) for j in range(n)] for i in range(n)],
            "iterations": int(estimator.getIterationsCount()), "evaluations": int(estimator.getEvaluationsCount()),
            "rms": float(estimator.getOptimum().getRMS()), "measurements": len(ms), "jvm_start_s": jvm_s,
            "setup_s": setup_s, "estimate_s": estimate_s, "total_s": time.perf_counter() - t_start,
            "cpu_s": time.process_time(), "orekit_version": oh._orekit_version()}


def run_orekit(d: Path, case: dict) -> dict:
    config = {"eop": str(case["eop"]), "stations": str(d / "stations.csv"), "passes": str(case["passes"]),
              "initial": case["guess"], "mass_kg": SC["mass_kg"], "area_m2": SC["srp_area_m2"], "cr": CR_GUESS}
    cfg, out = d / "orekit_config.json", d / "orekit_result.json"
    cfg.write_text(json.dumps(config))
    t0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    child = oh.run_measured([sys.executable, Path(__file__).resolve(), "--orekit-child", cfg, out], 1800)
    t1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if child["returncode"] != 0:
        raise SystemExit(f"Orekit estimation failed:\n{child['stderr'][-4000:]}")
    res = json.loads(out.read_text())
    res.update(wall_s=child["wall_s"], maxrss_mb=child["maxrss_mb"],
               child_cpu_s=(t1.ru_utime + t1.ru_stime) - (t0.ru_utime + t0.ru_stime))
    return res


def _ours(result: dict):
    """trackproc's solution: GCRF state (6,), Cr, sigmas of the state and Cr."""
    names = result["parameters"]
    vals = dict(zip(names, result["values"]))
    sig = dict(zip(names, result["sigma"]))
    keys = ["x", "y", "z", "vx", "vy", "vz"]
    return (np.array([vals[k] for k in keys]), vals.get("cr"), np.array([sig[k] for k in keys]), sig.get("cr"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--days", type=float, default=3.0)
    p.add_argument("--step", type=float, default=120.0, help="seconds between simulated normal points")
    p.add_argument("--no-orekit", action="store_true")
    p.add_argument("--numpy", action="store_true", help="also the TRACKPROC_JIT=0 run (~3 more minutes)")
    p.add_argument("--keep", metavar="DIR")
    p.add_argument("--orekit-child", nargs=2, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.orekit_child:
        cfg, out = a.orekit_child
        Path(out).write_text(json.dumps(orekit_estimate(json.loads(Path(cfg).read_text()))))
        return 0
    d = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench-lageos-"))
    d.mkdir(parents=True, exist_ok=True)
    try:
        case = make_case(d, a.days, a.step)
        print(f"== LAGEOS-like, {a.days:g} days, 6 SLR stations: {case['samples']} two-way ranges (1 cm) in "
              f"{case['passes_n']} passes; EIGEN-6S 20x20 + Sun + Moon + SRP + relativity; state + Cr "
              f"(simulated in {case['simulate_s']:.1f} s) ==")
        truth = np.array(case["truth"]["position_m"] + case["truth"]["velocity_m_s"])
        rows = []
        runs = [("trackproc estimate (numba kernels)", True)] + ([("trackproc estimate (TRACKPROC_JIT=0)", False)]
                                                                  if a.numpy else [])
        tp = None
        for label, jit in runs:
            r = run_trackproc(d, case, jit)
            x, cr, sig, sig_cr = _ours(r["result"])
            tp = tp or (x, cr, sig, sig_cr)
            diag = r["result"]["diagnostics"]
            it = f"{diag['iterations']} iterations, {diag.get('damped_steps', 0)} damped"
            print(f"{label:40s} wall {r['wall_s']:6.1f} s  CPU {r['cpu_s']:6.1f} s  peak RSS {r['maxrss_mb']:5.0f} MB"
                  f"  {it}")
            print(f"  |r - truth| {np.linalg.norm(x[:3] - truth[:3]) * 100:.2f} cm (sigma "
                  f"{np.linalg.norm(sig[:3]) * 100:.2f} cm), Cr {cr:.5f} +- {sig_cr:.5f} (truth {SC['cr']})")
            rows.append((label, r["wall_s"], r["cpu_s"], r["maxrss_mb"]))
        if a.no_orekit:
            print("orekit: skipped (--no-orekit)")
            return 0
        ok, why = oh.availability()
        if not ok:
            print(f"orekit: not installed ({why})")
            return 0
        o = run_orekit(d, case)
        xo = np.array(o["state"])
        print(f"{'Orekit ' + o['orekit_version'] + ' BatchLSEstimator':40s} wall {o['wall_s']:6.1f} s  CPU "
              f"{o['child_cpu_s']:6.1f} s  peak RSS {o['maxrss_mb']:5.0f} MB  {o['iterations']} iterations "
              f"({o['evaluations']} evaluations)")
        print(f"  JVM start {o['jvm_start_s']:.1f} s, set-up {o['setup_s']:.1f} s, estimate() {o['estimate_s']:.1f} s;"
              f" |r - truth| {np.linalg.norm(xo[:3] - truth[:3]) * 100:.2f} cm, Cr {o['cr']:.5f}")
        x, cr, sig, sig_cr = tp
        dz = np.abs(x - xo) / sig
        print(f"trackproc - Orekit: |dr| {np.linalg.norm(x[:3] - xo[:3]) * 100:.2f} cm, |dv| "
              f"{np.linalg.norm(x[3:] - xo[3:]) * 1e3:.3f} mm/s, max {dz.max():.2f} sigma; dCr {cr - o['cr']:+.5f} "
              f"({(cr - o['cr']) / sig_cr:+.2f} sigma)")
        base = rows[0]
        print(f"ratios Orekit / trackproc (numba): wall {o['wall_s'] / base[1]:.1f}x, CPU "
              f"{o['child_cpu_s'] / base[2]:.1f}x, peak memory {o['maxrss_mb'] / base[3]:.1f}x")
        return 0
    finally:
        if not a.keep:
            shutil.rmtree(d, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
