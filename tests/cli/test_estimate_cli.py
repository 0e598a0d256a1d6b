"""``trackproc estimate`` at the command line: outputs (state file, OPM, residuals, plot,
summary), a real pipe from simulate, and exit codes 2 (bad input) and 1 (processing failure)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from trackproc.io.opm import COVARIANCE_KEYS, parse_opm
from trackproc.io.statefile import read_state

STATE = {"epoch": "2026-03-20T09:30:00.000Z", "frame": "GCRF",
         "position_m": [3774841.0, -1538034.0, 5924146.0], "velocity_m_s": [-4816.6, 3936.4, 4091.1]}
GUESS = {**STATE, "position_m": [3775441.0, -1538534.0, 5924706.0], "velocity_m_s": [-4816.0, 3935.9, 4091.7]}
STATIONS = "station,lat_deg,lon_deg,height_m\nZHY,48.0,35.0,150\nKIR,67.857,20.964,400\nMAD,40.43,-4.25,830\n"
BIASES = ("ZHY=100", "KIR=-80", "MAD=120")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Simulated passes (3 stations, 6 h, range + Doppler, biases, 20 Hz offset), truth and guess."""
    from trackproc.cli import app as cli_app

    d = tmp_path_factory.mktemp("est")
    (d / "state.json").write_text(json.dumps(STATE))
    (d / "guess.json").write_text(json.dumps(GUESS))
    (d / "stations.csv").write_text(STATIONS)
    args = ["simulate", "--state", d / "state.json", "--stations", d / "stations.csv", "--duration", "21600",
            "--step", "30", "--dut1", "0.1", "--seed", "5", "--kinds", "range,doppler", "--freq-offset-hz", "20",
            "--truth", d / "truth.json", "-o", d / "passes.parquet"]
    for b in BIASES:
        args += ["--range-bias", b]
    assert cli_app.main([str(a) for a in args]) == 0
    return d


def _bias_sigma_orbit_known(d, station: str, name: str = "passes.parquet") -> float:
    """Sigma of a station's range bias if the orbit were known: 1/sqrt(sum 1/sigma^2) of its ranges."""
    frame = pd.read_parquet(d / name)
    ranges = frame[(frame["station"] == station) & (frame["kind"] == "range")]
    return float(1.0 / np.sqrt(np.sum(ranges["sigma"].to_numpy() ** -2.0)))


def test_estimate_writes_state_opm_residuals_plot_and_summary(run_cli, files, tmp_path):
    out, opm, res_csv, res_pq, png = (tmp_path / n for n in ("sol.json", "sol.opm", "res.csv", "res.parquet",
                                                               "res.png"))
    result = run_cli(["estimate", files / "passes.parquet", "--initial", files / "guess.json", "--range-bias",
                      "--doppler-bias", "offset", "--dut1", "0.1", "--opm", opm, "--residuals", res_csv,
                      "--plot", png, "-o", out])
    assert result.exit_code == 0, result.stderr
    assert "range_bias:KIR" in result.stderr and "variance factor" in result.stderr
    state = read_state(str(out))
    doc = json.loads(out.read_text())
    assert doc["parameters"][:6] == ["x", "y", "z", "vx", "vy", "vz"]
    assert {"range_bias:KIR", "range_bias:MAD", "range_bias:ZHY"} <= set(doc["parameters"])
    assert len(doc["covariance"]) == len(doc["parameters"]) == len(doc["sigma"])
    diag = doc["diagnostics"]
    assert diag["converged"] is True and diag["iterations"] >= 1
    assert set(diag["rms"]) == {"ZHY", "KIR", "MAD"} and "doppler" in diag["rms"]["KIR"]
    assert {"variance_factor", "condition_number", "correlation", "covariance_rtn", "sigma_rtn"} <= set(diag)
    assert doc["force_model"] == "two-body+J2" and doc["estimation"]["range_rate_model"] == "doppler"
    truth = read_state(str(files / "truth.json"))
    err = state.rv - truth.rv
    assert np.all(np.abs(err) < 3 * state.sigma[:6])
    for b in BIASES:
        name, value = b.split("=")
        i = state.parameters.index(f"range_bias:{name}")
        assert abs(state.values[i] - float(value)) < 3 * state.sigma[i]
    # ... and tight, not only covering: position sigma below one range's noise (10 m), velocity sigma below
    # one Doppler sample's (0.1 Hz = 1.4 cm/s), each bias sigma within [1, 2) x its bound with the orbit known
    assert np.all(state.sigma[:3] < 10.0) and np.all(state.sigma[3:6] < 0.1 * 299792458.0 / 2.2e9), state.sigma
    for b in BIASES:
        name = b.split("=")[0]
        ratio = state.sigma[state.parameters.index(f"range_bias:{name}")] / _bias_sigma_orbit_known(files, name)
        assert 1.0 <= ratio < 2.0, (name, ratio)

    parsed = parse_opm(opm.read_text())
    np.testing.assert_allclose(parsed["r_m"], state.r_m, rtol=1e-15)
    np.testing.assert_allclose(parsed["covariance"], state.state_covariance, rtol=1e-14)
    text = opm.read_text()
    keys = [line.split("=")[0].strip() for line in text.splitlines() if line.startswith("C") and "_" in line
            and not line.startswith(("CCSDS", "CREATION", "CENTER", "COMMENT", "COV_REF"))]
    assert keys == [k for k, _, _ in COVARIANCE_KEYS]                 # lower triangle, row by row
    assert "REF_FRAME = GCRF" in text and "TIME_SYSTEM = UTC" in text and "[km/s]" in text
    assert "COMMENT range_bias:KIR = " in text

    res = pd.read_csv(res_csv, comment="#")
    assert list(res.columns) == ["time", "station", "pass_id", "kind", "unit", "observed", "computed", "residual",
                                 "normalized_residual", "sigma", "edited"]
    assert res["edited"].dtype == bool and res["time"].str.endswith("Z").all()
    np.testing.assert_allclose(res["observed"] - res["computed"], res["residual"], atol=1e-6)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    assert run_cli(["estimate", files / "passes.parquet", "--initial", files / "guess.json", "--range-bias",
                    "--doppler-bias", "offset", "--dut1", "0.1", "--residuals", res_pq, "-o", out]).exit_code == 0
    table = pd.read_parquet(res_pq)
    assert len(table) == len(res) and str(table["time"].dt.tz) == "UTC"


def test_compare_and_two_stage_reports(run_cli, files, tmp_path):
    out = tmp_path / "sol.json"
    result = run_cli(["estimate", files / "passes.parquet", "--initial", files / "state.json", "--range-bias",
                      "--doppler-bias", "offset", "--dut1", "0.1", "--compare-doppler-only", "--two-stage",
                      "-o", out])
    assert result.exit_code == 0, result.stderr
    assert "seed 002 comparison" in result.stderr and "two-stage" in result.stderr
    diag = json.loads(out.read_text())["diagnostics"]
    assert diag["two_stage"]["identity_error"] < 1e-9
    assert diag["compare_doppler_only"]["relative_reduction_min"] > -1e-6
    assert diag["compare_doppler_only"]["relative_reduction_max"] > 0.1


def test_real_pipe_simulate_into_estimate(files, tmp_path):
    env = {**os.environ, "TRACKPROC_LOG_LEVEL": "ERROR"}
    sim = [sys.executable, "-m", "trackproc", "simulate", "--state", str(files / "state.json"), "--stations",
           str(files / "stations.csv"), "--duration", "21600", "--step", "60", "--dut1", "0.1", "--seed", "1",
           "--kinds", "range,range_rate", "--range-bias", "KIR=50", "-o", "-"]
    est = [sys.executable, "-m", "trackproc", "estimate", "-", "--initial", str(files / "state.json"),
           "--range-bias", "--dut1", "0.1", "-o", "-"]
    p1 = subprocess.Popen(sim, stdout=subprocess.PIPE, env=env)
    p2 = subprocess.run(est, stdin=p1.stdout, capture_output=True, env=env, timeout=120)
    p1.stdout.close()
    assert p1.wait() == 0 and p2.returncode == 0, p2.stderr.decode()
    doc = json.loads(p2.stdout)
    assert "range_bias:KIR" in doc["parameters"] and doc["diagnostics"]["converged"]


@pytest.mark.parametrize("args, needle", [
    (["missing.parquet", "--initial", "{state}"], "missing.parquet"),
    (["{passes}", "--initial", "{dir}/nope.json"], "nope.json"),
    (["{passes}", "--initial", "{state}", "--doppler-bias", "sometimes"], "--doppler-bias"),
    (["{passes}", "--initial", "{state}", "--apriori-sigma", "x:10"], "--apriori-sigma"),
    (["{passes}", "--initial", "{state}", "--apriori-sigma", "clock=10"], "--apriori-sigma"),
    (["{passes}", "--initial", "{state}", "--kinds", "phase"], "--kinds"),
    (["{passes}", "--initial", "{state}", "--range-bias-station", "XYZ"], "--range-bias"),
    (["{passes}", "--initial", "{state}", "--range-bias", "--range-bias-station", "KIR"], "--range-bias"),
    (["{passes}", "--initial", "{state}", "--stations", "{dir}/badst.csv"], "badst.csv"),
    (["{passes}", "--initial", "{dir}/bad.json"], "bad.json"),
    (["{passes}", "--initial", "{state}", "--plot", "-"], "--plot"),
])
def test_bad_inputs_exit_2_naming_the_file_or_field(run_cli, files, tmp_path, args, needle):
    (files / "bad.json").write_text('{"epoch": "2026-03-20T09:30:00Z", "frame": "GCRF", "position_m": [1, 2]}')
    (files / "badst.csv").write_text("station,lat_deg,lon_deg,height_m\nKIR,95.0,20.9,400\n")
    fill = {"passes": str(files / "passes.parquet"), "state": str(files / "state.json"), "dir": str(files)}
    argv = ["estimate"] + [a.format(**fill) for a in args] + ["--dut1", "0.1", "-o", str(tmp_path / "o.json")]
    result = run_cli(argv)
    assert result.exit_code == 2, result.stderr
    assert needle in result.stderr
    assert not (tmp_path / "o.json").exists()


def test_unknown_station_exit_2(run_cli, files, tmp_path):
    from trackproc.io.passfile import read_pass_table, write_pass_table

    table = read_pass_table(str(files / "passes.parquet"))
    table.frame["station"] = table.frame["station"].replace("MAD", "XXX")
    write_pass_table(table, str(tmp_path / "p.parquet"))
    result = run_cli(["estimate", tmp_path / "p.parquet", "--initial", files / "state.json", "--dut1", "0.1",
                      "-o", tmp_path / "o.json"])
    assert result.exit_code == 2
    assert "p.parquet" in result.stderr and "'station'" in result.stderr and "XXX" in result.stderr


def test_non_convergence_exit_1_and_nothing_written(run_cli, files, tmp_path):
    out = tmp_path / "o.json"
    result = run_cli(["estimate", files / "passes.parquet", "--initial", files / "guess.json", "--range-bias",
                      "--doppler-bias", "offset", "--dut1", "0.1", "--max-iterations", "1", "-o", out])
    assert result.exit_code == 1
    assert "did not converge in 1 iterations" in result.stderr
    assert not out.exists()


def test_rank_deficiency_exit_1_names_the_combination(run_cli, files, tmp_path):
    """A pass left with a single Doppler sample cannot observe its own drift."""
    from trackproc.io.passfile import read_pass_table, write_pass_table

    table = read_pass_table(str(files / "passes.parquet"))
    f = table.frame
    pid = sorted(f["pass_id"].unique())[0]
    drop = f[(f["pass_id"] == pid) & (f["kind"] == "doppler")].index[1:]
    table.frame = f.drop(index=drop).reset_index(drop=True)
    write_pass_table(table, str(tmp_path / "p.parquet"))
    out = tmp_path / "o.json"
    result = run_cli(["estimate", tmp_path / "p.parquet", "--initial", files / "state.json", "--range-bias",
                      "--doppler-bias", "offset+drift", "--dut1", "0.1", "-o", out])
    assert result.exit_code == 1, result.stderr
    assert "rank-deficient" in result.stderr and f"doppler_drift:{pid}" in result.stderr
    assert not out.exists()


def test_plot_without_matplotlib_exit_2(run_cli, files, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    result = run_cli(["estimate", files / "passes.parquet", "--initial", files / "state.json", "--dut1", "0.1",
                      "--plot", tmp_path / "p.png", "-o", tmp_path / "o.json"])
    assert result.exit_code == 2 and "matplotlib" in result.stderr


def test_initial_state_from_a_tle(run_cli, files, tmp_path):
    """--initial TLE: SGP4 (TEME -> GCRF) at the TLE epoch, or at the first sample with --epoch first."""
    tle = tmp_path / "iss.tle"
    tle.write_text("1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991\n"
                   "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482\n")
    passes = tmp_path / "iss.parquet"
    res = run_cli(["simulate", "--tle", tle, "--stations", files / "stations.csv", "--duration", "43200",
                   "--step", "30", "--kinds", "range,range_rate", "--range-bias", "MAD=60", "--seed", "4",
                   "--dut1", "0.1", "-o", passes])
    assert res.exit_code == 0, res.stderr
    for extra in ([], ["--epoch", "first"]):
        out = tmp_path / "sol.json"
        res = run_cli(["estimate", passes, "--initial", tle, "--range-bias", "--dut1", "0.1", *extra, "-o", out])
        assert res.exit_code == 0, res.stderr
        state = read_state(str(out))
        i = state.parameters.index("range_bias:MAD")
        assert abs(state.values[i] - 60.0) < 3 * state.sigma[i]
        assert 1.0 <= state.sigma[i] / _bias_sigma_orbit_known(tmp_path, "MAD", "iss.parquet") < 2.0
    first = pd.read_parquet(passes)["time"].min()
    assert state.epoch == first.tz_convert("UTC").tz_localize(None).to_datetime64()
