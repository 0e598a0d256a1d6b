"""Full-force propagation of a LEO day at 1 mm: trackproc (DOP853 + dense polynomials; its numpy
path and its numba-compiled one) against plain scipy ``solve_ivp(DOP853)`` on the same right-hand
side and Orekit 13's NumericalPropagator with the same forces, side by side in one run.

Run: python benchmarks/forces.py [--degree 20] [--repeat 3] [--no-orekit]

Case: 500 km sun-synchronous orbit (tests/io/test_forces_orekit.py's LEO), 2020-04-05, 24 h, EIGEN-6S
DEGxDEG + Sun + Moon + relativity, states every hour. Each tool's accuracy is measured against
its own converged run (trackproc and scipy: rtol 3e-14; Orekit: 1e-8 m position tolerance), and
the loosest tolerance of a ladder that keeps every hourly position within 1 mm of it is timed
(median of --repeat runs; Orekit's runs in one warm JVM, so no start-up or JIT in its time;
trackproc compiled likewise after its first run, whose extra cost of loading numba and the cached
kernels is printed apart; --stm adds the 6x6 STM to trackproc's runs, as an estimation needs). The
two models differ by ~3 mm after the day (ERFA vs DE-440 Sun and Moon); that is not in these
numbers, which are each tool's cost of its own 1 mm. CPU seconds (process time) for the Python
runs, wall seconds inside the JVM for Orekit; a loaded machine inflates both.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "io"))  # test_forces_orekit
EPOCH = "2020-04-05T00:00:00"
LADDER_RTOL = (1e-10, 3e-11, 1e-11, 3e-12, 1e-12)
LADDER_OREKIT_M = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)


def _case():
    from test_forces_orekit import LEO

    return LEO


def _model(degree, eop):
    from trackproc.dynamics.forces import ForceModel
    from trackproc.io.icgem import load_field

    return ForceModel(load_field(degree=degree, date=EPOCH), third_bodies=("sun", "moon"), relativity=True, eop=eop)


def _timed(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return statistics.median(times), out


def trackproc_run(model, orbit, t, rtol, eop, compiled=False, stm=False):
    import os

    from trackproc.dynamics.propagator import propagate

    os.environ["TRACKPROC_JIT"] = "1" if compiled else "0"
    traj = propagate(orbit[0], orbit[1], np.datetime64(EPOCH), t, force=model, eop=eop, tol=rtol, stm=stm)
    return traj.state(t), traj.n_steps


def scipy_run(model, orbit, t, rtol, eop):
    """solve_ivp(DOP853) on the same acceleration (Environment), t_eval at the hours."""
    from scipy.integrate import solve_ivp

    from trackproc.dynamics import timescales as ts
    from trackproc.dynamics.propagator import reference_frame

    jd = tuple(float(x) for x in ts.datetime64_to_jd_utc(np.datetime64(EPOCH, "ns")))
    q = reference_frame(*jd, eop).q
    env = model.environment(jd, q, 0.0, float(t.max()))
    y0 = np.concatenate([q @ np.asarray(orbit[0]), q @ np.asarray(orbit[1])])

    def f(tt, y):
        return np.concatenate([y[3:], env.acceleration(tt, y[:3], y[3:])[0]])

    sol = solve_ivp(f, (0.0, float(t.max())), y0, method="DOP853", rtol=rtol, atol=[1e-6] * 3 + [1e-9] * 3,
                    t_eval=t)
    x = sol.y.T
    return np.concatenate([x[:, :3] @ q, x[:, 3:] @ q], 1), sol.nfev


def _loosest(run, reference, ladder, label):
    for tol in ladder:
        states = run(tol)
        err = np.linalg.norm(states[:, :3] - reference[:, :3], axis=1).max()
        print(f"  {label} {tol:g}: max |dr| {err * 1e3:.3f} mm")
        if err <= 1e-3:
            return tol, err
    return ladder[-1], err


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--degree", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-orekit", action="store_true")
    ap.add_argument("--stm", action="store_true", help="trackproc with the STM (variational equations)")
    args = ap.parse_args(argv)
    import orekit_helpers as oh

    work = Path(tempfile.mkdtemp(prefix="bench_forces_"))
    eop_file = oh.write_linear_finals2000a(work / "finals2000A.txt", 58940, 10, -0.2, -3e-4, 0.05, 1e-4, 0.4, 2e-4)
    from trackproc.io.eop import read_finals2000a

    eop = read_finals2000a(str(eop_file))
    orbit = _case()
    t = 3600.0 * np.arange(1, 25)
    model = _model(args.degree, eop)
    print(f"LEO day, EIGEN-6S {args.degree}x{args.degree} + Sun + Moon + relativity, 1 mm target")
    from trackproc.dynamics import jit

    stm = args.stm
    rows = []
    if jit.enabled():
        t0 = time.process_time()
        ref, _ = trackproc_run(model, orbit, t, 3e-14, eop, compiled=True)
        print(f"  first compiled run (loading numba and the cached kernels included): "
              f"{time.process_time() - t0:.2f} s CPU")
        tol, err = _loosest(lambda r: trackproc_run(model, orbit, t, r, eop, True, stm)[0], ref, LADDER_RTOL,
                            "trackproc compiled rtol")
        sec, (_, steps) = _timed(lambda: trackproc_run(model, orbit, t, tol, eop, True, stm), args.repeat)
        rows.append(("trackproc compiled (numba)" + (" + STM" if stm else ""), f"rtol {tol:g}", err, sec,
                     f"{steps} steps"))
    else:
        print("  trackproc compiled skipped: numba not importable or TRACKPROC_JIT=0")
    ref_n, _ = trackproc_run(model, orbit, t, 3e-14, eop)
    tol, err = _loosest(lambda r: trackproc_run(model, orbit, t, r, eop, False, stm)[0], ref_n, LADDER_RTOL,
                        "trackproc numpy rtol")
    sec, (_, steps) = _timed(lambda: trackproc_run(model, orbit, t, tol, eop, False, stm), args.repeat)
    rows.append(("trackproc numpy (DOP853 + dense polynomials)" + (" + STM" if stm else ""), f"rtol {tol:g}",
                 err, sec, f"{steps} steps"))
    if len(rows) == 2:
        gap = np.linalg.norm(ref[:, :3] - ref_n[:, :3], axis=1).max()
        print(f"  compiled vs numpy (converged runs): {gap * 1e6:.1f} um after the day")
    else:
        ref = ref_n
    ref_s, _ = scipy_run(model, orbit, t, 3e-14, eop)
    tol, err = _loosest(lambda r: scipy_run(model, orbit, t, r, eop)[0], ref_s, LADDER_RTOL, "scipy rtol")
    sec, (_, nfev) = _timed(lambda: scipy_run(model, orbit, t, tol, eop), args.repeat)
    rows.append(("scipy solve_ivp DOP853, same RHS", f"rtol {tol:g}", err, sec, f"{nfev} evaluations"))
    ok, why = oh.availability()
    if args.no_orekit or not ok:
        print(f"Orekit skipped: {why or '--no-orekit'}")
    else:
        import orekit_forces

        cases = [{"state": {"epoch": EPOCH, "position_m": orbit[0], "velocity_m_s": orbit[1]}, "times_s": list(t),
                  "degree": args.degree, "order": args.degree, "third_bodies": ["sun", "moon"], "relativity": True,
                  "position_tolerance_m": p, "max_step_s": 300.0, "repeat": args.repeat + 1}
                 for p in (1e-8,) + LADDER_OREKIT_M]
        res = orekit_forces.run_subprocess({"eop": str(eop_file), "cases": cases}, work)["cases"]
        oref = np.array(res[0]["states"])
        for p, r in zip(LADDER_OREKIT_M, res[1:]):
            err = np.linalg.norm(np.array(r["states"])[:, :3] - oref[:, :3], axis=1).max()
            print(f"  Orekit position tolerance {p:g} m: max |dr| {err * 1e3:.3f} mm")
            if err <= 1e-3:
                rows.append(("Orekit 13 NumericalPropagator (warm JVM)", f"{p:g} m", err,
                             statistics.median(r["run_s"][1:]), "wall"))
                break
        gap = np.linalg.norm(ref[:, :3] - oref[:, :3], axis=1).max()
        print(f"  model difference trackproc vs Orekit (converged runs): {gap * 1e3:.1f} mm after the day")
    base = rows[0][3]
    print(f"\n{'':50s} {'tolerance':>12s} {'error':>9s} {'seconds':>8s} {'ratio':>6s}")
    for name, tol, err, sec, note in rows:
        print(f"{name:50s} {tol:>12s} {err * 1e3:7.3f}mm {sec:8.3f} {sec / base:6.2f}  {note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
