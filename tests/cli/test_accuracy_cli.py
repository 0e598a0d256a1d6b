"""``trackproc accuracy``: the seed example, the three methods side by side, RTN and station
columns, the correlation file, outputs in every format, and errors (exit 2 naming the field)."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from trackproc.constants import MU_EARTH
from trackproc.methods import accuracy as ac

STATE = {"epoch": "2026-03-20T09:30:00.000Z", "frame": "GCRF",
         "position_m": [3774841.0, -1538034.0, 5924146.0], "velocity_m_s": [-4816.6, 3936.4, 4091.1]}
STATIONS = "station,lat_deg,lon_deg,height_m\nZHY,50.25,28.66,230\nKIR,67.857,20.964,400\n"


def _cov():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((6, 6))
    c = a @ a.T
    c = c / np.sqrt(np.outer(np.diag(c), np.diag(c)))
    s = np.array([80.0, 120.0, 60.0, 0.08, 0.05, 0.1])
    return c * np.outer(s, s)


@pytest.fixture
def files(write):
    with_cov = dict(STATE, parameters=["x", "y", "z", "vx", "vy", "vz", "range_bias:ZHY"])
    cov = np.zeros((7, 7))
    cov[:6, :6] = _cov()
    cov[6, 6] = 25.0
    with_cov["covariance"] = cov.tolist()
    return {"bare": write("bare.json", json.dumps(STATE)), "cov": write("cov.json", json.dumps(with_cov)),
            "stations": write("stations.csv", STATIONS)}


def _csv(path):
    return pd.read_csv(path, comment="#")


def _csv_meta(path):
    from trackproc.io.csvtext import parse_csv_metadata

    with open(path) as handle:
        first = handle.readline()
        assert first.startswith("# trackproc: ")
        return parse_csv_metadata([first[1:]] + [line[1:] for line in handle if line.startswith("#")])


# ----------------------------------------------------------------------------- seed example

def test_seed_example_table_and_plot(run_cli, tmp_path):
    out, png = tmp_path / "ex.csv", tmp_path / "ex.png"
    res = run_cli(["accuracy", "--seed-example", "--span", "3000", "--step", "100", "--plot", png, "-o", out])
    assert res.exit_code == 0, res.stderr
    f = _csv(out)
    n = math.sqrt(MU_EARTH / 7.0e6 ** 3)
    t = f["elapsed_s"].to_numpy()
    np.testing.assert_allclose(f["sigma_x_m"], np.sqrt(ac.seed000_variance_exact(t, 100.0, 0.1, n)), rtol=1e-14)
    assert np.abs(f["rel_err_var_x_spectral"]).max() < 1e-10
    # truncation: 4 discretes worse than 6, both growing with time (the paper's t = 100 s: ~1e-5, ~4e-9)
    row = f.set_index("elapsed_s")
    assert abs(row.loc[100.0, "rel_err_var_x_n4"]) == pytest.approx(1.12e-5, rel=0.01)
    assert abs(row.loc[100.0, "rel_err_var_x_n6"]) == pytest.approx(4.35e-9, rel=0.01)
    assert abs(row.loc[3000.0, "rel_err_var_x_n4"]) > 10 and abs(row.loc[3000.0, "rel_err_var_x_n6"]) > 0.1
    assert np.all(np.diff(f["velocity_share"].to_numpy()[t < 1450]) > 0)
    meta = _csv_meta(out)
    assert meta["discretes"] == [4, 6] and meta["spectral"]["discretes"] == 16
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_seed_example_json_other_parameters(run_cli, tmp_path):
    out = tmp_path / "ex.json"
    res = run_cli(["accuracy", "--seed-example", "--span", "1000", "--step", "500", "--radius-m", "4.2164e7",
                   "--sigma-position-m", "1000", "--sigma-velocity-m-s", "0.5", "--discretes", "3,8", "-o", out])
    assert res.exit_code == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["columns"][0] == "elapsed_s" and len(doc["rows"]) == 3
    assert "sigma_x_n3_m" in doc["rows"][0] and "rel_err_var_x_n8" in doc["rows"][0]
    assert doc["metadata"]["radius_m"] == 4.2164e7 and doc["rows"][0]["sigma_x_m"] == 1000.0


# ----------------------------------------------------------------------------- a state file

def test_three_methods_side_by_side(run_cli, files, tmp_path):
    """spectral = stm to round-off; Monte Carlo within 4 sd = 4 sqrt(2/(N-1)) of the variance."""
    out = tmp_path / "acc.parquet"
    n = 800
    res = run_cli(["accuracy", files["cov"], "--span", "7200", "--step", "600", "--method", "all",
                   "--monte-carlo", n, "--seed", "5", "--dut1", "0", "-o", out])
    assert res.exit_code == 0, res.stderr
    assert "spectral vs stm" in res.stderr and "monte carlo vs spectral" in res.stderr
    table = pq.read_table(out)
    meta = json.loads(table.schema.metadata[b"trackproc"])
    f = table.to_pandas()
    assert len(f) == 13 and str(f["time"].dt.tz) == "UTC"
    assert f["time"].iloc[0] == pd.Timestamp("2026-03-20T09:30:00Z")
    names = ["x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "radial_m", "along_m", "cross_m",
             "v_radial_m_s", "v_along_m_s", "v_cross_m_s"]
    for name in names:
        a, b, c = f[f"sigma_{name}"], f[f"stm_sigma_{name}"], f[f"mc_sigma_{name}"]
        np.testing.assert_allclose(a, b, rtol=1e-10)
        assert np.max(np.abs((c / a) ** 2 - 1)) < 4 * math.sqrt(2 / (n - 1))
    # the initial sigmas come from the 6 x 6 block of the file's 7 x 7 covariance
    np.testing.assert_allclose(f.loc[0, ["sigma_x_m", "sigma_y_m", "sigma_z_m"]].to_numpy(float),
                               [80.0, 120.0, 60.0], rtol=1e-12)
    assert meta["methods"] == ["spectral", "stm", "monte-carlo"]
    assert meta["monte_carlo"]["n_samples"] == n and meta["monte_carlo"]["seed"] == 5
    assert meta["checks"]["spectral_vs_stm_max_relative_sigma_difference"] < 1e-10
    assert meta["checks"]["monte_carlo_vs_linear_max_abs_z"] < 4
    assert meta["initial_covariance"]["source"].startswith("state file covariance")
    assert meta["force_model"] == "two-body+J2" and meta["constants"]["mu_m3_s2"] == MU_EARTH


def test_monte_carlo_is_seeded(run_cli, files, tmp_path):
    outs = []
    for name, seed in (("a", "7"), ("b", "7"), ("c", "8")):
        path = tmp_path / f"{name}.csv"
        res = run_cli(["accuracy", files["cov"], "--span", "600", "--step", "300", "--method", "monte-carlo",
                       "--monte-carlo", "50", "--seed", seed, "--force", "two-body", "-o", path])
        assert res.exit_code == 0, res.stderr
        outs.append(path.read_bytes())
    assert outs[0] == outs[1] and outs[0] != outs[2]
    f = _csv(tmp_path / "a.csv")
    assert "sigma_x_m" in f.columns and "mean_offset_position_m" in f.columns
    assert not any(c.startswith("mc_") for c in f.columns)


def test_sigma_options_rtn_and_station(run_cli, files, tmp_path):
    """--sigma-* on RTN axes: the t = 0 row gives them back; the range sigma at t = 0 of an
    isotropic position error is that error."""
    out = tmp_path / "rtn.csv"
    res = run_cli(["accuracy", files["bare"], "--span", "1200", "--step", "60", "--force", "two-body",
                   "--sigma-position-m", "10,200,30", "--sigma-velocity-m-s", "0.01,0.02,0.03",
                   "--sigma-frame", "rtn", "-o", out])
    assert res.exit_code == 0, res.stderr
    f = _csv(out)
    np.testing.assert_allclose(f.loc[0, ["sigma_radial_m", "sigma_along_m", "sigma_cross_m"]].to_numpy(float),
                               [10.0, 200.0, 30.0], rtol=1e-12)
    # velocity columns are rates of the RTN position errors: at t = 0 they mix in w x dr
    n = np.linalg.norm(np.cross(STATE["position_m"], STATE["velocity_m_s"])) / np.sum(np.square(STATE["position_m"]))
    expect = np.sqrt([0.01 ** 2 + (n * 200.0) ** 2, 0.02 ** 2 + (n * 10.0) ** 2, 0.03 ** 2])
    np.testing.assert_allclose(f.loc[0, ["sigma_v_radial_m_s", "sigma_v_along_m_s", "sigma_v_cross_m_s"]]
                               .to_numpy(float), expect, rtol=1e-9)

    out = tmp_path / "st.csv"
    res = run_cli(["accuracy", files["bare"], "--span", "1200", "--step", "60", "--sigma-position-m", "100",
                   "--sigma-velocity-m-s", "0.1", "--at-station", "ZHY", "--stations", files["stations"],
                   "--dut1", "0", "-o", out])
    assert res.exit_code == 0, res.stderr
    f = _csv(out)
    assert f.loc[0, "sigma_range_m"] == pytest.approx(100.0, rel=1e-12)
    assert {"range_m", "range_rate_m_s", "elevation_deg", "sigma_range_rate_m_s"} <= set(f.columns)
    assert f["range_m"].between(1e5, 2e7).all() and f["elevation_deg"].between(-90, 90).all()
    assert _csv_meta(out)["station"]["name"] == "ZHY"


def test_correlation_file_json_and_table(run_cli, files, tmp_path):
    out, corr = tmp_path / "a.csv", tmp_path / "r.json"
    res = run_cli(["accuracy", files["cov"], "--span", "3000", "--step", "600", "--correlation", corr, "-o", out])
    assert res.exit_code == 0, res.stderr
    f = _csv(out)
    doc = json.loads(corr.read_text())
    assert doc["metadata"]["correlation"]["method"] == "spectral"
    assert len(doc["times"]) == 6 and doc["times"][0] == "2026-03-20T09:30:00Z"
    for name, col in (("x_m2", "sigma_x_m"), ("along_m2", "sigma_along_m"), ("v_cross_m2_s2", "sigma_v_cross_m_s")):
        r = np.array(doc["covariance"][name])
        np.testing.assert_allclose(np.sqrt(np.diag(r)), f[col], rtol=1e-10)
        np.testing.assert_allclose(r, r.T, rtol=1e-12, atol=1e-12 * np.abs(r).max())
    c = np.array(doc["correlation"]["radial"])
    np.testing.assert_allclose(np.diag(c), 1.0, rtol=1e-12)
    assert np.all(np.abs(c) <= 1 + 1e-12)
    # the long table: one row per pair, and the same numbers
    corr_csv = tmp_path / "r.csv"
    res = run_cli(["accuracy", files["cov"], "--span", "3000", "--step", "600", "--method", "stm",
                   "--correlation", corr_csv, "-o", tmp_path / "b.csv"])
    assert res.exit_code == 0, res.stderr
    g = _csv(corr_csv)
    assert len(g) == 36 and {"time_1", "time_2", "cov_x_m2", "corr_x", "cov_vx_m2_s2"} <= set(g.columns)
    np.testing.assert_allclose(g["cov_x_m2"].to_numpy().reshape(6, 6), doc["covariance"]["x_m2"], rtol=1e-9)


def test_sigma_only_state_and_monte_carlo_beside_stm(run_cli, write, tmp_path):
    doc = dict(STATE, parameters=["x", "y", "z", "vx", "vy", "vz"], sigma=[30.0, 30.0, 30.0, 0.03, 0.03, 0.03])
    path = write("sig.json", json.dumps(doc))
    out = tmp_path / "s.csv"
    res = run_cli(["accuracy", path, "--span", "600", "--step", "300", "--method", "stm", "--monte-carlo", "300",
                   "--seed", "1", "-o", out])
    assert res.exit_code == 0, res.stderr
    f = _csv(out)
    assert f.loc[0, "sigma_z_m"] == pytest.approx(30.0, rel=1e-12)
    assert "mc_sigma_along_m" in f.columns and "mc_mean_offset_position_m" in f.columns
    assert not any(c.startswith("stm_") for c in f.columns)
    assert _csv_meta(out)["initial_covariance"]["source"].startswith("state file sigma")


def test_real_pipe(files, tmp_path):
    """A real process writing an Arrow stream into a pipe, read by another process."""
    import subprocess
    import sys
    from pathlib import Path

    exe = Path(sys.executable).with_name("trackproc")
    cmd = f"'{exe}' -q accuracy '{files['cov']}' --span 600 --step 300 --force two-body | " \
          f"'{sys.executable}' -c \"import sys, pyarrow as pa; t = pa.ipc.open_stream(sys.stdin.buffer).read_all(); " \
          f"print(t.num_rows, t.column_names[2])\""
    res = subprocess.run(cmd, shell=True, capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["3", "x_m"]


def test_stdout_arrow_stream(run_cli, files):
    import pyarrow as pa

    res = run_cli(["accuracy", files["cov"], "--span", "600", "--step", "300", "--force", "two-body", "-o", "-"])
    assert res.exit_code == 0, res.stderr
    table = pa.ipc.open_stream(io.BytesIO(res.stdout_bytes)).read_all()
    assert table.num_rows == 3 and "sigma_along_m" in table.column_names


# ----------------------------------------------------------------------------- errors

@pytest.mark.parametrize("args, fragments", [
    (["{bare}", "--span", "600", "--step", "60"], ["bare.json", "'covariance'", "--sigma-position-m"]),
    (["{bare}", "--span", "600", "--step", "60", "--sigma-position-m", "10"], ["--sigma-velocity-m-s"]),
    (["{cov}", "--span", "600", "--step", "60", "--at-station", "XXX", "--stations", "{stations}"],
     ["stations.csv", "'--at-station'", "XXX", "ZHY"]),
    (["{cov}", "--span", "600", "--step", "60", "--at-station", "ZHY"], ["--stations"]),
    (["{cov}", "--step", "60"], ["--span"]),
    (["{cov}", "--span", "-5", "--step", "60"], ["'--span'", "> 0"]),
    (["{cov}", "--span", "600", "--step", "60", "--monte-carlo", "1"], ["'--monte-carlo'"]),
    (["{cov}", "--span", "600", "--step", "60", "--sigma-position-m", "1,2", "--sigma-velocity-m-s", "1"],
     ["--sigma-position-m"]),
    (["{cov}", "--span", "86400", "--step", "60", "--correlation", "r.json"], ["'--correlation'", "at most 500"]),
    (["missing.json", "--span", "600", "--step", "60"], ["missing.json", "not found"]),
    (["{cov}", "--seed-example"], ["--seed-example takes no STATE"]),
    (["--seed-example", "--discretes", "0"], ["'--discretes'"]),
    ([], ["missing STATE.json"]),
])
def test_errors_exit_2(run_cli, files, tmp_path, args, fragments):
    args = [a.format(**files) if isinstance(a, str) else a for a in args]
    res = run_cli(["accuracy", *args, "-o", tmp_path / "out.csv"])
    assert res.exit_code == 2, (res.exit_code, res.stderr)
    for fragment in fragments:
        assert fragment in res.stderr, (fragment, res.stderr)
    assert not (tmp_path / "out.csv").exists()


def test_monte_carlo_correlation_agrees_with_the_stm(run_cli, files, tmp_path):
    """--correlation with Monte Carlo: the RTN covariance function of the draws (position and the
    rotating-frame velocity, as the linear methods) agrees with Phi P0 Phi^T within its sampling
    error (it used to crash applying the 6 x 6 RTN map to 3-vectors)."""
    docs = {}
    for method, extra in (("stm", []), ("monte-carlo", ["--monte-carlo", "4000", "--seed", "3"])):
        corr = tmp_path / f"{method}.json"
        res = run_cli(["accuracy", files["cov"], "--span", "3000", "--step", "600", "--method", method, *extra,
                       "--correlation", corr, "-o", tmp_path / f"{method}.csv"])
        assert res.exit_code == 0, res.stderr
        docs[method] = json.loads(corr.read_text())
    assert docs["monte-carlo"]["metadata"]["correlation"]["method"] == "monte-carlo"
    rel_sd = np.sqrt(2.0 / 3999)                                # sampling sd of a variance
    for name in ("radial_m2", "along_m2", "cross_m2", "v_radial_m2_s2", "v_along_m2_s2", "x_m2"):
        lin, mc = np.array(docs["stm"]["covariance"][name]), np.array(docs["monte-carlo"]["covariance"][name])
        np.testing.assert_allclose(np.diag(mc), np.diag(lin), rtol=5 * rel_sd, err_msg=name)
        scale = np.sqrt(np.outer(np.diag(lin), np.diag(lin)))
        assert np.max(np.abs(mc - lin) / scale) < 5 * rel_sd * np.sqrt(2), name
