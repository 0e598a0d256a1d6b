"""``trackproc simulate``: determinism, exact noiseless values, noise statistics, biases,
the two-body propagation against Kepler, errors, and a real pipe into ingest and info."""

import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from test_reference import kepler_universal

from trackproc.constants import MU_EARTH
from trackproc.dynamics import geodesy, reference
from trackproc.dynamics import timescales as ts
from trackproc.io.passfile import read_pass_table
from trackproc.io.statefile import State, read_state
from trackproc.io.stations import Station
from trackproc.models import measurements as mm
from trackproc.pipeline.simulate import SimulateOptions, simulate

STATE = {"epoch": "2026-03-20T09:30:00.000Z", "frame": "GCRF",
         "position_m": [3774841.0, -1538034.0, 5924146.0], "velocity_m_s": [-4816.6, 3936.4, 4091.1]}
STATIONS = "station,lat_deg,lon_deg,height_m\nZHY,48.0,35.0,150\nKIR,67.857,20.964,400\nMAD,40.43,-4.25,830\n"
ST = {"ZHY": Station("ZHY", 48.0, 35.0, 150.0), "KIR": Station("KIR", 67.857, 20.964, 400.0),
      "MAD": Station("MAD", 40.43, -4.25, 830.0)}
INITIAL = State.from_vectors(STATE["epoch"], STATE["position_m"], STATE["velocity_m_s"])
EOP = ts.EarthOrientation.constant(0.1)
NOISELESS = dict(sigma_range_m=0, sigma_range_rate_m_s=0, sigma_doppler_hz=0, sigma_angle_deg=0)


@pytest.fixture
def files(write):
    return {"state": write("state.json", json.dumps(STATE)), "stations": write("stations.csv", STATIONS)}


def base_args(files, *extra):
    return ["simulate", "--state", files["state"], "--stations", files["stations"], "--duration", "3600",
            "--step", "10", "--dut1", "0.1", *extra]


# ----------------------------------------------------------------------------- CLI

def test_seeded_output_is_deterministic(run_cli, files, tmp_path):
    outs = []
    for name, seed in (("a", "7"), ("b", "7"), ("c", "8")):
        path = tmp_path / f"{name}.parquet"
        res = run_cli(base_args(files, "--seed", seed, "-o", path))
        assert res.exit_code == 0, res.stderr
        outs.append(path.read_bytes())
    assert outs[0] == outs[1]
    assert outs[0] != outs[2]


def test_pass_table_and_metadata(run_cli, files, tmp_path):
    path = tmp_path / "p.parquet"
    res = run_cli(base_args(files, "--seed", "1", "--range-bias", "ZHY=25", "--freq-offset-hz", "3",
                            "--truth", tmp_path / "truth.json", "-o", path))
    assert res.exit_code == 0, res.stderr
    table = read_pass_table(str(path))
    f = table.frame
    assert list(f.columns[:6]) == ["time", "station", "pass_id", "kind", "value", "sigma"]
    assert set(f["kind"]) == {"range", "range_rate", "doppler", "elevation", "azimuth"}
    assert f["pass_id"].str.match(r"^(ZHY|KIR|MAD)-\d{3}$").all()
    assert (f.sort_values(["station", "time", "kind"], kind="mergesort").index == f.index).all()
    el = f[f["kind"] == "elevation"]["value"]
    assert el.min() > np.radians(10.0) - 5 * np.radians(0.01)
    m = table.meta
    assert m["carrier_hz"] == 2.2e9 and m["doppler_mode"] == "one-way"
    assert m["force_model"] == "two-body+J2" and m["constants"]["j2"] > 0
    assert m["range_rate_model"] == "doppler"
    assert m["earth_orientation"].startswith("constant UT1-UTC = 0.1")
    sim = m["simulation"]
    assert sim["seed"] == 1 and sim["range_bias_m"] == {"ZHY": 25.0} and sim["frequency_offset_hz"] == 3.0
    assert sim["noise_sigma"]["range_m"] == 10.0
    assert set(m["stations"]) <= {"ZHY", "KIR", "MAD"}
    truth = read_state(str(tmp_path / "truth.json"))
    assert truth.epoch == np.datetime64("2026-03-20T09:30:00", "ns")
    assert truth.r_m.tolist() == STATE["position_m"]
    assert json.loads((tmp_path / "truth.json").read_text())["constants"]["mu_m3_s2"] == MU_EARTH


def test_bad_state_file_names_the_field(run_cli, files, write):
    bad = dict(STATE)
    del bad["position_m"]
    res = run_cli(base_args(dict(files, state=write("bad.json", json.dumps(bad)))))
    assert res.exit_code == 2
    assert "bad.json" in res.stderr and "position_m" in res.stderr and "Traceback" not in res.stderr
    res = run_cli(base_args(dict(files, state=write("frame.json", json.dumps(dict(STATE, frame="B1950"))))))
    assert res.exit_code == 2
    assert "column 'frame'" in res.stderr and "unknown frame" in res.stderr and "B1950" in res.stderr


@pytest.mark.parametrize("extra, words", [
    (["--range-bias", "XXX=3"], "unknown station"),
    (["--range-bias", "ZHY"], "STATION=METRES"),
    (["--kinds", "range,phase"], "--kinds"),
    (["--sigma-range-m", "-1"], "--sigma-range-m"),
    (["--step", "0"], "--step"),
    (["--start", "tomorrow"], "--start"),
])
def test_bad_options_exit_2(run_cli, files, extra, words):
    res = run_cli(base_args(files, *extra, "-o", "-"))
    assert res.exit_code == 2, res.stderr
    assert words in res.stderr


def test_state_and_tle_are_exclusive(run_cli, files):
    res = run_cli(base_args(files, "--tle", files["state"], "-o", "-"))
    assert res.exit_code == 2


def test_no_visible_pass_is_a_processing_error(run_cli, files):
    res = run_cli(["simulate", "--state", files["state"], "--stations", files["stations"], "--duration", "60",
                   "--step", "10", "--elevation-mask-deg", "85", "-o", "-"])
    assert res.exit_code == 1
    assert "no visible pass" in res.stderr and "85 deg" in res.stderr


def test_wide_csv_reads_back_through_ingest(run_cli, files, tmp_path):
    wide = tmp_path / "raw.csv"
    res = run_cli(base_args(files, "--seed", "3", "--wide", "-o", wide))
    assert res.exit_code == 0, res.stderr
    frame = pd.read_csv(wide)
    assert list(frame.columns) == ["time", "station", "range_m", "range_rate_m_s", "doppler_hz",
                                   "elevation_deg", "azimuth_deg"]
    assert frame["time"].str.endswith("Z").all()
    assert frame["elevation_deg"].min() > 9.9
    out = tmp_path / "in.parquet"
    res = run_cli(["ingest", wide, "--stations", files["stations"], "--carrier-hz", "2.2e9", "--mode", "one-way",
                   "-o", out])
    assert res.exit_code == 0, res.stderr
    assert len(read_pass_table(str(out)).frame) == 5 * len(frame)


def test_stdout_is_an_arrow_stream_and_csv_on_request(run_cli, files):
    from trackproc.io.passfile import parse_pass_table

    res = run_cli(base_args(files, "--seed", "1", "-o", "-"))
    assert res.exit_code == 0, res.stderr
    assert not res.stdout_bytes.startswith(b"PAR1")
    arrow = parse_pass_table(res.stdout_bytes, "<stdout>")
    res = run_cli(base_args(files, "--seed", "1", "--format", "csv", "-o", "-"))
    assert res.exit_code == 0 and res.stdout.startswith("# trackproc: {")
    csv = parse_pass_table(res.stdout_bytes, "<stdout>")
    # angles pass through degrees (rounded to 1e-12 deg) at the CSV edge: equal to 1e-13 relative
    assert np.allclose(csv.frame["value"].to_numpy(), arrow.frame["value"].to_numpy(), rtol=1e-13, atol=0)


def test_tle_input_and_two_way(run_cli, files, write, tmp_path):
    tle = write("iss.tle", "1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991\n"
                           "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482\n")
    path = tmp_path / "t.parquet"
    res = run_cli(["simulate", "--tle", tle, "--stations", files["stations"], "--duration", "86400", "--step", "30",
                   "--mode", "two-way", "--kinds", "range,doppler", "--seed", "2", "-o", path])
    assert res.exit_code == 0, res.stderr
    table = read_pass_table(str(path))
    assert table.meta["doppler_mode"] == "two-way" and set(table.frame["kind"]) == {"range", "doppler"}
    assert table.meta["simulation"]["initial_epoch"].startswith("2019-12-09T16:38:29.363")


def test_subprocess_pipe_into_ingest_and_info(files):
    env = dict(os.environ, TRACKPROC_LOG_LEVEL="ERROR")
    py = sys.executable
    cmd = (f"'{py}' -m trackproc simulate --state '{files['state']}' --stations '{files['stations']}' "
           f"--duration 3600 --step 10 --seed 1 --dut1 0.1 "
           f"| '{py}' -m trackproc ingest - | '{py}' -m trackproc info - --json")
    out = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    text = json.dumps(info)
    assert "ZHY" in text or "KIR" in text or "MAD" in text


# ----------------------------------------------------------------------------- pipeline

def test_noiseless_values_equal_the_measurement_models():
    options = SimulateOptions(duration_s=6000, step_s=20, force="two-body", seed=0, **NOISELESS)
    sim = simulate(INITIAL, ST, options, EOP)
    f = sim.frame
    assert np.array_equal(f["value"].to_numpy(), sim.truth_values)
    # recompute a sample of rows independently: closed-form Kepler orbit + the measurement models
    rows = f.iloc[:: max(1, len(f) // 40)]
    for _, row in rows.iterrows():
        t = np.datetime64(row["time"].tz_convert("UTC").tz_localize(None), "ns")
        j1, j2 = ts.datetime64_to_jd_utc(t)
        dt = float(ts.seconds_since((j1, j2), INITIAL.jd_utc))
        r, v = kepler_universal(INITIAL.r_m, INITIAL.v_m_s, dt)
        a, jk = reference.acceleration(r, MU_EARTH), reference.jerk(r, v, MU_EARTH)
        s = ST[row["station"]]
        lat, lon = np.radians(s.lat_deg), np.radians(s.lon_deg)
        st = mm.station_gcrf(geodesy.geodetic_to_itrf(lat, lon, s.height_m), j1, j2, EOP)
        o = mm.observables(r[None], v[None], a[None], jk[None], st.r, st.v, st.a, st.gcrf_to_itrf, lat, lon,
                           carrier_hz=2.2e9)
        expected = {"range": o.range_m, "range_rate": o.range_rate_m_s, "doppler": o.doppler_hz,
                    "elevation": o.elevation_rad, "azimuth": o.azimuth_rad}[row["kind"]][0]
        tol = {"range": 1e-3, "range_rate": 1e-6, "doppler": 1e-5, "elevation": 1e-9, "azimuth": 1e-9}[row["kind"]]
        assert abs(row["value"] - expected) < tol, row["kind"]
    # noiseless kinds keep a usable (positive) sigma
    assert (f["sigma"] > 0).all()


def test_noise_statistics_match_the_sigmas():
    options = SimulateOptions(duration_s=86400, step_s=10, seed=42)
    sim = simulate(INITIAL, ST, options, EOP)
    f = sim.frame
    resid = f["value"].to_numpy() - sim.truth_values
    az = (f["kind"] == "azimuth").to_numpy()
    resid[az] = np.angle(np.exp(1j * resid[az]))
    sig = options.noise_sigmas()
    for kind, sigma in sig.items():
        x = resid[(f["kind"] == kind).to_numpy()]
        n = x.size
        assert n > 1000
        assert abs(x.std(ddof=1) - sigma) < 3 * sigma / np.sqrt(2 * (n - 1)), kind
        assert abs(x.mean()) < 3 * sigma / np.sqrt(n), kind
        assert np.allclose(f[f["kind"] == kind]["sigma"], sigma)


def test_range_bias_and_frequency_offset_drift_are_applied():
    options = SimulateOptions(duration_s=86400, step_s=30, seed=1, range_bias_m={"ZHY": 25.0, "KIR": -4.0},
                              freq_offset_hz=12.5, freq_drift_hz_s=1e-3, **NOISELESS)
    sim = simulate(INITIAL, ST, options, EOP)
    f = sim.frame
    d = f["value"].to_numpy() - sim.truth_values
    for name, bias in (("ZHY", 25.0), ("KIR", -4.0), ("MAD", 0.0)):
        sel = ((f["kind"] == "range") & (f["station"] == name)).to_numpy()
        assert sel.any() and np.allclose(d[sel], bias, rtol=0, atol=1e-8)
    dop = (f["kind"] == "doppler").to_numpy()
    start = pd.Timestamp("2026-03-20T09:30:00Z")
    t = (f["time"][dop] - start).dt.total_seconds().to_numpy()
    assert np.allclose(d[dop], 12.5 + 1e-3 * t, rtol=0, atol=1e-9)
    for kind in ("range_rate", "elevation", "azimuth"):
        assert np.all(d[(f["kind"] == kind).to_numpy()] == 0.0)


def test_two_body_dop853_against_kepler_over_a_day_of_leo():
    options = SimulateOptions(duration_s=86400, step_s=10, force="two-body", seed=0)
    sim = simulate(INITIAL, ST, options, EOP)
    times = sim.grid["times"]
    j1, j2 = ts.datetime64_to_jd_utc(times)
    dt = ts.seconds_since((j1, j2), INITIAL.jd_utc)
    pick = np.r_[np.arange(0, times.size, 211), times.size - 1]
    err = max(np.linalg.norm(sim.grid["r_sat"][i] - kepler_universal(INITIAL.r_m, INITIAL.v_m_s, dt[i])[0])
              for i in pick)
    assert err < 1e-3          # DOP853 rtol 1e-13: ~1e-5 m after a day


def test_start_after_the_epoch_gives_the_propagated_truth():
    start = np.datetime64("2026-03-20T10:00:00", "ns")
    options = SimulateOptions(duration_s=7200, step_s=30, start=start, force="two-body", seed=0)
    sim = simulate(INITIAL, ST, options, EOP)
    assert sim.truth.epoch == start
    r, v = kepler_universal(INITIAL.r_m, INITIAL.v_m_s, 1800.0)
    assert np.linalg.norm(sim.truth.r_m - r) < 1e-4 and np.linalg.norm(sim.truth.v_m_s - v) < 1e-7
    assert sim.frame["time"].min() >= pd.Timestamp("2026-03-20T10:00:00Z")


def test_sphere_earth_moves_the_stations():
    wgs = simulate(INITIAL, ST, SimulateOptions(duration_s=3600, step_s=60, seed=0, **NOISELESS), EOP)
    sph = simulate(INITIAL, ST, SimulateOptions(duration_s=3600, step_s=60, seed=0, earth="sphere", **NOISELESS),
                   EOP)
    diff = np.abs(sph.grid["range_m"] - wgs.grid["range_m"])
    assert 100.0 < diff.max() < 30e3          # WGS-84 vs R = 6371 km at mid latitudes: kilometres
    assert "sphere" in sph.meta["simulation"]["earth"]


def test_passes_are_split_by_gaps_and_numbered_per_station():
    sim = simulate(INITIAL, ST, SimulateOptions(duration_s=86400, step_s=10, seed=0), EOP)
    f = sim.frame[sim.frame["kind"] == "elevation"]
    for name, group in f.groupby("station"):
        ids = group["pass_id"].unique()
        assert list(ids) == [f"{name}-{k:03d}" for k in range(1, len(ids) + 1)]
        for _, p in group.groupby("pass_id"):
            steps = p["time"].diff().dt.total_seconds().dropna()
            assert (steps == 10.0).all()

