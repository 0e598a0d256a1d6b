"""``trackproc detect`` and ``trackproc simulate --ballistic`` (pipeline/detect.py, pipeline/ballistic_sim.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trackproc.io.passfile import PassTable, read_pass_table, write_pass_table
from trackproc.io.stations import Station
from trackproc.pipeline.ballistic_sim import BallisticOptions, simulate_ballistic
from trackproc.pipeline.detect import detect, parse_nominal

NOMINAL = {"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48, "station": "KIR",
           "tau_s": 30}
STATIONS = {"KIR": Station("KIR", 67.8, 20.9, 400.0)}
STATIONS_CSV = "station,lat_deg,lon_deg,height_m\nKIR,67.8,20.9,400\n"


def _nominal(**changes):
    doc = dict(NOMINAL, **changes)
    return parse_nominal(json.dumps(doc), "nominal.json")


def _sim(nominal, hypothesis="h0", sigma_deg=0.2, seed=1, step=2.0):
    result = simulate_ballistic(nominal, STATIONS, BallisticOptions(
        hypothesis=hypothesis, step_s=step, sigma_angle_deg=sigma_deg, seed=seed, elevation_mask_deg=0.0))
    return PassTable(result.frame, result.meta), result


def test_detect_model_values_are_the_simulated_truth():
    nominal = _nominal()
    for hyp, key in (("h0", "a"), ("h1", "b")):
        table, sim = _sim(nominal, hyp, sigma_deg=0.0)
        out = detect(table, nominal)
        # only samples before T - τ are used; the simulated truth there equals a (H0) or b (H1)
        np.testing.assert_allclose(out.samples[key], sim.truth_values[: out.statistic.n], rtol=0, atol=1e-12)
        assert out.document["samples"]["not_used_after_T_minus_tau"] == len(table.frame) - out.statistic.n
        assert out.document["decision"] == hyp.upper()


def test_detect_end_to_end_monte_carlo_decisions_and_moments():
    """40 simulated noisy passes per hypothesis through simulate_ballistic -> detect (γ ≈ 3.5):
    the equal-error rule errs at the rate 1 - Φ(γ/2) within binomial bounds; E[S|H1] = C_n."""
    from scipy.stats import binom

    from trackproc.methods.detection import equal_error

    nominal = _nominal()
    errors, s1 = 0, []
    for seed in range(40):
        for hyp in ("h0", "h1"):
            table, _ = _sim(nominal, hyp, sigma_deg=0.2, seed=seed, step=3.0)
            doc = detect(table, nominal).document
            errors += doc["decision"] != hyp.upper()
            if hyp == "h1":
                s1.append(doc["statistic"]["S"])
    gamma = doc["gamma"]
    assert 3.0 < gamma < 4.0
    assert doc["equal_error_probability"] == pytest.approx(equal_error(gamma))
    assert errors <= binom.ppf(0.9999, 80, equal_error(gamma))
    assert np.mean(s1) == pytest.approx(doc["statistic"]["mean_h1"], abs=4 * doc["statistic"]["std"] / np.sqrt(40))


def test_cli_simulate_ballistic_then_detect(run_cli, write, tmp_path):
    stations = write("st.csv", STATIONS_CSV)
    nominal = write("nominal.json", json.dumps(NOMINAL))
    pass_file = tmp_path / "pass.parquet"
    result = run_cli(["simulate", "--ballistic", nominal, "--stations", stations, "--hypothesis", "h1",
                      "--step", "1", "--elevation-mask-deg", "0", "--sigma-angle-deg", "0.05", "--seed", "3",
                      "-o", pass_file])
    assert result.exit_code == 0, result.stderr
    table = read_pass_table(str(pass_file))
    assert set(table.frame["kind"]) == {"elevation"}
    assert table.meta["simulation"]["hypothesis"] == "h1"
    assert table.meta["stations"]["KIR"]["lat_deg"] == 67.8
    out = tmp_path / "result.json"
    result = run_cli(["detect", pass_file, "--nominal", nominal, "--false-alarm", "0.001", "-o", out])
    assert result.exit_code == 0, result.stderr
    doc = json.loads(out.read_text())
    assert doc["decision"] == "H1" and doc["displaced"] is True
    assert doc["criterion"] == "false-alarm" and doc["false_alarm_probability"] == 0.001
    st = doc["statistic"]
    assert st["mean_h0"] == 0.0 and st["variance"] == pytest.approx(doc["sigma_rad"] ** 2 * st["mean_h1"])
    assert doc["gamma"] == pytest.approx(np.sqrt(st["mean_h1"]) / doc["sigma_rad"])
    assert doc["samples"]["by_kind"] == {"elevation": doc["samples"]["used"]}
    assert doc["samples"]["last_s_from_impact"] <= -30.0
    # the displacement and the criterion from the command line
    result = run_cli(["detect", pass_file, "--nominal", nominal, "--displacement-m", "-500", "--equal-error"])
    doc = json.loads(result.stdout)
    assert doc["displacement_m"] == -500.0 and doc["decision"] == "H0"


def test_cli_detect_3d_with_azimuth_reports_the_planar_error(run_cli, write, tmp_path):
    stations = write("st.csv", STATIONS_CSV)
    nominal = write("nominal.json", json.dumps(dict(NOMINAL, model="3d", direction="against")))
    pass_file = tmp_path / "pass3d.parquet"
    result = run_cli(["simulate", "--ballistic", nominal, "--stations", stations, "--step", "4",
                      "--elevation-mask-deg", "0", "--sigma-angle-deg", "0.2", "--seed", "5", "-o", pass_file])
    assert result.exit_code == 0, result.stderr
    assert set(read_pass_table(str(pass_file)).frame["kind"]) == {"elevation", "azimuth"}
    result = run_cli(["detect", pass_file, "--nominal", nominal, "--dut1", "0"])
    assert result.exit_code == 0, result.stderr
    doc = json.loads(result.stdout)
    assert doc["decision"] == "H0" and doc["model"] == "3d"
    assert set(doc["samples"]["by_kind"]) == {"elevation", "azimuth"}
    cmp = doc["planar_comparison"]
    assert cmp["available"] and cmp["max_abs_elevation_error_h0_rad"] < 3e-4
    assert abs(cmp["relative_gamma_error"]) < 1e-4


@pytest.mark.parametrize("doc, field", [
    ({"velocity_kms": 3, "angle_deg": 48}, "impact_time"),
    ({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3}, "angle_deg"),
    ({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 100}, "angle_deg"),
    ({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48, "speed": 1}, "speed"),
    ({"impact_time": "yesterday", "velocity_kms": 3, "angle_deg": 48}, "impact_time"),
    ({"impact_time": "2026-03-20T10:00:00Z", "p_m": 2e6, "e": 0.1}, "e"),
    ({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48, "model": "3d"}, "direction"),
    ({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48, "direction": "up"}, "direction"),
    ({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48, "station": "XXX"}, "station"),
])
def test_cli_detect_bad_nominal_exit_2_names_file_and_field(run_cli, write, tmp_path, doc, field):
    table, _ = _sim(_nominal(), sigma_deg=0.1)
    pass_file = tmp_path / "p.parquet"
    write_pass_table(table, str(pass_file))
    nominal = write("bad_nominal.json", json.dumps(doc))
    result = run_cli(["detect", pass_file, "--nominal", nominal])
    assert result.exit_code == 2, result.stderr
    assert "bad_nominal.json" in result.stderr and f"'{field}'" in result.stderr


def test_cli_detect_bad_inputs_exit_2(run_cli, write, tmp_path):
    table, _ = _sim(_nominal(), sigma_deg=0.1)
    pass_file = tmp_path / "p.csv"
    write_pass_table(table, str(pass_file), "csv")
    nominal = write("nominal.json", json.dumps(NOMINAL))
    result = run_cli(["detect", pass_file, "--nominal", write("broken.json", "{not json")])
    assert result.exit_code == 2 and "broken.json" in result.stderr and "not valid JSON" in result.stderr
    result = run_cli(["detect", tmp_path / "missing.parquet", "--nominal", nominal])
    assert result.exit_code == 2 and "missing.parquet" in result.stderr
    result = run_cli(["detect", pass_file, "--nominal", nominal, "--false-alarm", "1.5"])
    assert result.exit_code == 2 and "--false-alarm" in result.stderr
    result = run_cli(["detect", pass_file, "--nominal", nominal, "--false-alarm", "0.01", "--equal-error"])
    assert result.exit_code == 2
    # a pass that ends before the nominal impact minus tau: no usable sample
    late = write("late.json", json.dumps(dict(NOMINAL, impact_time="2026-03-20T09:00:00Z")))
    result = run_cli(["detect", pass_file, "--nominal", late])
    assert result.exit_code == 2 and "p.csv" in result.stderr and "'time'" in result.stderr
    # a pass without elevations
    frame = table.frame.assign(kind="range")
    write_pass_table(PassTable(frame, table.meta), str(tmp_path / "r.csv"), "csv")
    result = run_cli(["detect", tmp_path / "r.csv", "--nominal", nominal])
    assert result.exit_code == 2 and "r.csv" in result.stderr and "'kind'" in result.stderr


def test_cli_simulate_ballistic_bad_options_exit_2(run_cli, write):
    stations = write("st.csv", STATIONS_CSV)
    nominal = write("nominal.json", json.dumps(NOMINAL))
    result = run_cli(["simulate", "--ballistic", nominal, "--stations", stations, "--hypothesis", "h2", "-o", "-"])
    assert result.exit_code == 2 and "--hypothesis" in result.stderr
    result = run_cli(["simulate", "--ballistic", nominal, "--stations", stations, "--duration", "100", "-o", "-"])
    assert result.exit_code == 2 and "--duration" in result.stderr
    result = run_cli(["simulate", "--stations", stations, "--state", nominal, "-o", "-"])
    assert result.exit_code == 2 and "--duration" in result.stderr
    other = write("other.json", json.dumps(dict(NOMINAL, station="ZZZ")))
    result = run_cli(["simulate", "--ballistic", other, "--stations", stations, "-o", "-"])
    assert result.exit_code == 2 and "other.json" in result.stderr and "'station'" in result.stderr
