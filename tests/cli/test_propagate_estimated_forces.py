"""A solution of ``estimate --force full`` propagates with the forces it was fitted with: the
empirical accelerations in its ``constants`` (cli/force_options.empirical_from_state) and the
spacecraft with Cr/Cd in its ``spacecraft`` block (written whenever SRP or drag was on) are read
back by every ``--force full`` command."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from trackproc.io.ephemeris import read_ephemeris

STATE = {"epoch": "2020-04-05T00:00:00Z", "frame": "GCRF", "position_m": [6878137.0, 0.0, 0.0],
         "velocity_m_s": [0.0, -927.7425636, 7555.8568340]}
FULL = ["--force", "full", "--gravity", "4", "--dut1", "0"]


@pytest.mark.slow
def test_compare_and_propagate_of_a_solution_reproduce_the_fit(run_cli, write, stations_csv, tmp_path):
    """Ranges and range-rates simulated with the full model (4x4, Sun, Moon), estimated with a
    constant GCRF acceleration: ``compare`` of the solution on the same passes gives estimate's
    own post-fit residuals (measured 5e-6 m, 2e-7 m/s; 3.1 m and 0.037 m/s when the accelerations
    were not read back), and ``propagate`` names and uses them."""
    truth = write("truth.json", json.dumps(STATE))
    sim, fit, res_e, res_c = (tmp_path / n for n in ("sim.parquet", "fit.json", "res.csv", "cmp.csv"))
    r = run_cli(["simulate", "--state", truth, "--stations", stations_csv, "--duration", "21600", "--step", "20",
                 "--kinds", "range,range_rate", "--sigma-range-m", "2", "--sigma-range-rate-m-s", "0.002", "--seed", "7",
                 "-o", sim, *FULL])
    assert r.exit_code == 0, r.stderr
    r = run_cli(["estimate", sim, "--initial", truth, "--stations", stations_csv, "--estimate-force", "empirical-xyz",
                 "--residuals", res_e, "-o", fit, *FULL])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(fit.read_text())
    emp = doc["constants"]["empirical_gcrf_m_s2"]
    assert emp == doc["values"][6:9] and max(map(abs, emp)) > 1e-8
    r = run_cli(["compare", sim, fit, "--remove", "none", "-o", res_c, *FULL])
    assert r.exit_code == 0, r.stderr
    both = pd.read_csv(res_e, comment="#").merge(pd.read_csv(res_c, comment="#"), on=["time", "station", "kind"],
                                                  suffixes=("_e", "_c"))
    assert len(both) == 128
    for kind, tol in (("range", 1e-4), ("range_rate", 1e-6)):
        rows = both[both.kind == kind]
        assert np.abs(rows.residual_e - rows.residual_c).max() < tol, kind

    eph = tmp_path / "eph.csv"
    r = run_cli(["propagate", fit, "--span", "3600", "--step", "600", "-o", eph, *FULL])
    assert r.exit_code == 0, r.stderr
    meta = read_ephemeris(str(eph)).meta
    assert "empirical" in meta["force_model"] and meta["constants"]["empirical_gcrf_m_s2"] == emp

    # fitted with radiation pressure, nothing estimated: the spacecraft travels with the solution
    srp = ["--srp", "--mass-kg", "100", "--srp-area-m2", "1", "--cr", "1.4"]
    r = run_cli(["estimate", sim, "--initial", truth, "--stations", stations_csv, "--residuals", res_e, "-o", fit,
                 *FULL, *srp])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(fit.read_text())
    assert doc["spacecraft"] == doc["constants"]["spacecraft"] and doc["spacecraft"]["cr"] == 1.4
    r = run_cli(["compare", sim, fit, "--remove", "none", "-o", res_c, *FULL])
    assert r.exit_code == 0, r.stderr
    both = pd.read_csv(res_e, comment="#").merge(pd.read_csv(res_c, comment="#"), on=["time", "station", "kind"],
                                                  suffixes=("_e", "_c"))
    assert np.abs(both.residual_e - both.residual_c)[both.kind == "range"].max() < 1e-4


def test_malformed_empirical_constants_are_a_one_line_error(run_cli, write, tmp_path):
    bad = write("bad.json", json.dumps({**STATE, "force_model": "full",
                                        "constants": {"empirical_rtn_m_s2": [1e-8, "x", 0.0]}}))
    r = run_cli(["propagate", bad, "--span", "600", "--step", "300", "-o", tmp_path / "e.csv", *FULL])
    assert r.exit_code == 2
    assert "constants.empirical_rtn_m_s2" in r.stderr and len(r.stderr.strip().splitlines()) == 1
