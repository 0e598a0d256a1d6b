"""Accuracy of ``trackproc refine`` on the seed 004 Table 1 scenario, by Monte Carlo over the noise.

The truth of Table 1 is the traverse point of a pass over the station TRV (500 km left of the
ground track, highest elevation 55 deg; ``traverse_station``); the stale state of Table 1 with
its loose covariance (10 km, 5 m/s per axis) is the a-priori. For each measurement set below,
N noise draws are refined (pointwise cost, the CLI's defaults) and the errors at the traverse
epoch split, with the refinement's own observability report, into the part along the
directions the pass determines ("seen") and the part along those it cannot see ("unseen",
which only the a-priori bounds). Printed: RMS per component of the total, seen and unseen
errors against the paper's refined errors / 10, the mean reported sigma, and the largest
unseen error in units of its own reported sigma.

    python benchmarks/refine_accuracy.py            # 100 draws per set (about a minute)
    python benchmarks/refine_accuracy.py --draws 20
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "report"))  # test_refine

#: (label, kind, link mode, noise 1-sigma (Hz for Doppler, m/s for range-rate), bias model)
SETS = [
    ("one-way Doppler 0.1 Hz, offset estimated", "doppler", "one-way", 0.1, "offset"),
    ("one-way Doppler 0.03 Hz, offset estimated", "doppler", "one-way", 0.03, "offset"),
    ("one-way Doppler 0.01 Hz, offset estimated", "doppler", "one-way", 0.01, "offset"),
    ("two-way range-rate 1 mm/s (coherent S-band)", "range_rate", "two-way", 1e-3, "none"),
]


def run_set(kind, mode, sigma, bias, draws, seed=7):
    from test_refine import EOP, OFFSET_HZ, STALE, TRUTH, table, truth_at

    from trackproc.pipeline.refine import RefineOptions, finish, prepare, traverse_station
    from trackproc.pipeline.simulate import SimulateOptions, simulate

    station, _ = traverse_station(TRUTH, cross_track_m=500e3, eop=EOP)
    noise = {"sigma_doppler_hz": sigma, "freq_offset_hz": OFFSET_HZ} if kind == "doppler" else \
        {"sigma_range_rate_m_s": sigma}
    sim = simulate(TRUTH, {station.name: station},
                   SimulateOptions(duration_s=1800, step_s=1.0, start=np.datetime64("2026-03-20T09:15:00"),
                                   kinds=(kind,), mode=mode, seed=1, **noise), EOP)
    ref = prepare(table(sim), STALE, None, RefineOptions(doppler_bias=bias), EOP)
    truth = truth_at(ref.problem.epoch)
    noiseless = sim.truth_values + (OFFSET_HZ if kind == "doppler" else 0.0)
    rng = np.random.default_rng(seed)
    total, seen, unseen, sig, z_unseen, nees_seen, z_total = [], [], [], [], [], [], []
    for _ in range(draws):
        y = noiseless + rng.normal(size=noiseless.size) * sigma
        sol, _ = ref.solve(observed=y)          # simulated noise: no reweighting would happen
        res = finish(ref, sol)
        e = res.state.values[:6] - truth
        s_, u_ = res.observability.split(e)
        # coefficients along the report's directions: the posterior is diagonal in that basis
        obs = res.observability
        c = obs.dual @ e
        var = np.einsum("ij,jk,ik->i", obs.dual, res.state.covariance[:6, :6], obs.dual)
        weak = np.zeros(6, bool)
        weak[obs.unobservable] = True
        total.append(e)
        seen.append(s_)
        unseen.append(u_)
        sig.append(res.state.sigma[:6])
        z_unseen.append(float(np.sqrt(np.sum(c[weak] ** 2 / var[weak]))))
        nees_seen.append(float(np.sum(c[~weak] ** 2 / var[~weak])))
        z_total.append(float(np.max(np.abs(e) / res.state.sigma[:6])))
    dof = 6 - len(res.observability.unobservable)
    return tuple(np.array(a) for a in (total, seen, unseen, sig, z_unseen, nees_seen, z_total)) + (dof,)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=100)
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore")
    from test_refine import PAPER_POSITION_ERROR

    def rms(a):
        return np.sqrt(np.mean(a * a, axis=0))

    print(f"paper refined error / 10 (m): x {abs(PAPER_POSITION_ERROR[0]) / 10:.0f}, "
          f"y {abs(PAPER_POSITION_ERROR[1]) / 10:.0f}, z {abs(PAPER_POSITION_ERROR[2]) / 10:.1f}; "
          f"velocity: 0.01 .. 0.3 m/s")
    for label, kind, mode, sigma, bias in SETS:
        t0 = time.perf_counter()
        total, seen, unseen, sig, z_un, nees, z_tot, dof = run_set(kind, mode, sigma, bias, args.draws)
        print(f"\n{label} ({args.draws} draws, {time.perf_counter() - t0:.0f} s)")
        for name, a in (("total", total), ("seen", seen), ("unseen", unseen), ("sigma", sig)):
            r = rms(a) if name != "sigma" else a.mean(axis=0)
            print(f"  {name:7s} position x {r[0]:7.1f} y {r[1]:7.1f} z {r[2]:7.1f} m | "
                  f"velocity {r[3]:.3f} {r[4]:.3f} {r[5]:.3f} m/s")
        print(f"  unseen part / its sigma: largest {z_un.max():.2f}, median {np.median(z_un):.2f}; "
              f"NEES of the seen part: mean {nees.mean():.2f} ({dof} directions seen); "
              f"largest |component error|/sigma {z_tot.max():.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
