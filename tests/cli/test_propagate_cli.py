"""``trackproc propagate``: the ephemeris against the simulator's reference propagator, the pass
predictor against ``trackproc simulate``'s noiseless measurements, STM and covariance against
central finite differences, CCSDS OEM read back, errors and exit codes, and a real pipe."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from trackproc.constants import C_LIGHT
from trackproc.dynamics import frames, propagator, reference
from trackproc.dynamics import timescales as ts
from trackproc.io.ephemeris import COV_COLUMNS, STM_COLUMNS, read_ephemeris
from trackproc.io.passfile import read_pass_table

STATE = {"epoch": "2026-03-20T09:30:00.000Z", "frame": "GCRF",
         "position_m": [3774841.0, -1538034.0, 5924146.0], "velocity_m_s": [-4816.6, 3936.4, 4091.1]}
R0, V0 = np.array(STATE["position_m"]), np.array(STATE["velocity_m_s"])
EPOCH = np.datetime64("2026-03-20T09:30:00", "ns")
JD = tuple(float(x) for x in ts.datetime64_to_jd_utc(EPOCH))
STATIONS = "station,lat_deg,lon_deg,height_m\nZHY,48.0,35.0,150\nKIR,67.857,20.964,400\nMAD,40.43,-4.25,830\n"
P0 = np.diag([400.0, 900.0, 100.0, 1e-2, 4e-2, 1e-3])
P0[0, 4] = P0[4, 0] = 0.5
P0[2, 3] = P0[3, 2] = -0.1
ISS = ("ISS (ZARYA)\n"
       "1 25544U 98067A   19343.69339541  .00001764  00000-0  38792-4 0  9991\n"
       "2 25544  51.6439 211.2001 0007417  17.6667  85.6398 15.50103472202482\n")
NOISELESS = ["--sigma-range-m", "0", "--sigma-range-rate-m-s", "0", "--sigma-doppler-hz", "0",
             "--sigma-angle-deg", "0"]


@pytest.fixture
def files(write):
    cov_state = dict(STATE, parameters=["x", "y", "z", "vx", "vy", "vz"], covariance=P0.tolist())
    return {"state": write("state.json", json.dumps(STATE)), "stations": write("stations.csv", STATIONS),
            "cov": write("cov.json", json.dumps(cov_state)), "tle": write("iss.tle", ISS)}


def _run_ok(run_cli, args):
    res = run_cli(args)
    assert res.exit_code == 0, res.stderr
    return res


def _flat(text: str) -> str:
    """stderr without Rich's box drawing and line wrapping."""
    return " ".join(re.sub(r"[\u2500-\u257f]", " ", text).split())


def _times(frame) -> np.ndarray:
    return pd.DatetimeIndex(frame["time"]).tz_convert("UTC").tz_localize(None).as_unit("ns").to_numpy()


# ----------------------------------------------------------------------------- the ephemeris

def test_day_of_j2_against_the_simulator_reference_dop853(run_cli, files, tmp_path):
    out = tmp_path / "day.parquet"
    _run_ok(run_cli, ["propagate", files["state"], "--span", "86400", "--step", "1800", "--dut1", "0.1", "-o", out])
    eph = read_ephemeris(str(out))
    f = eph.frame
    assert list(f.columns) == ["time", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s"]
    assert len(f) == 49 and _times(f)[0] == EPOCH
    t = np.arange(49) * 1800.0
    q = frames.QuasiInertialFrame.at(*JD, ts.EarthOrientation.constant(0.1)).q
    r, v = reference.propagate_gcrf(R0, V0, t, q, "j2")
    s = eph.states
    assert np.linalg.norm(s[:, :3] - r, axis=1).max() < 1e-3
    assert np.linalg.norm(s[:, 3:] - v, axis=1).max() < 1e-6
    assert np.array_equal(s[0], np.r_[R0, V0])
    m = eph.meta
    assert m["force_model"] == "two-body+J2" and m["constants"]["j2"] > 0 and m["constants"]["mu_m3_s2"] > 0
    assert m["earth_orientation"].startswith("constant UT1-UTC = 0.1") and m["frame"] == "GCRF"
    assert m["propagator"]["tol"] == 1e-15 and m["propagator"]["steps"] >= 1


def test_negative_span_goes_backwards_in_time_order(run_cli, files, tmp_path):
    out = tmp_path / "back.csv"
    _run_ok(run_cli, ["propagate", files["state"], "--span", "-600", "--step", "60", "--force", "two-body",
                      "--dut1", "0", "-o", out])
    eph = read_ephemeris(str(out))
    times = _times(eph.frame)
    assert times[0] == EPOCH - np.timedelta64(600, "s") and times[-1] == EPOCH and len(times) == 11
    assert np.all(np.diff(times.astype(np.int64)) > 0)
    q = frames.QuasiInertialFrame.at(*JD).q
    r, _ = reference.propagate_gcrf(R0, V0, np.arange(-600.0, 1.0, 60.0), q, "two-body")
    assert np.abs(eph.states[:, :3] - r).max() < 1e-5
    assert eph.meta["force_model"] == "two-body" and "j2" not in eph.meta["constants"]


def test_start_option_and_tle_input_to_oem(run_cli, files, tmp_path):
    out = tmp_path / "iss.oem"
    _run_ok(run_cli, ["propagate", files["tle"], "--start", "2019-12-09T17:00:00Z", "--span", "120", "--step", "60",
                      "--dut1", "-0.2", "-o", out])
    oem = parse_oem(out.read_text())
    assert oem["meta"]["OBJECT_NAME"] == "ISS (ZARYA)" and oem["meta"]["OBJECT_ID"] == "1998-067A"
    assert oem["meta"]["START_TIME"] == "2019-12-09T17:00:00.000" and len(oem["lines"]) == 3


def test_stm_columns_against_central_finite_differences(run_cli, files, tmp_path):
    out = tmp_path / "stm.parquet"
    _run_ok(run_cli, ["propagate", files["state"], "--span", "5400", "--step", "2700", "--stm", "--dut1", "0.1",
                      "-o", out])
    eph = read_ephemeris(str(out))
    assert list(eph.frame.columns[7:]) == list(STM_COLUMNS)
    phi = eph.matrix("stm")
    fd = _fd_stm(np.array([0.0, 2700.0, 5400.0]))
    assert np.allclose(phi[0], np.eye(6), atol=1e-14)
    rel = np.linalg.norm(phi - fd, axis=1) / np.linalg.norm(fd, axis=1)
    assert rel.max() < 1e-6


def _fd_stm(t):
    frame = propagator.reference_frame(*JD, ts.EarthOrientation.constant(0.1))
    x0 = np.r_[R0, V0]
    h = np.array([1.0] * 3 + [1e-3] * 3)
    fd = np.zeros((t.size, 6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h[k]
        plus = propagator.propagate((x0 + e)[:3], (x0 + e)[3:], EPOCH, t, frame=frame).state(t)
        minus = propagator.propagate((x0 - e)[:3], (x0 - e)[3:], EPOCH, t, frame=frame).state(t)
        fd[:, :, k] = (plus - minus) / (2 * h[k])
    return fd


def test_propagated_covariance_equals_phi_p_phit_from_finite_differences(run_cli, files, tmp_path):
    out = tmp_path / "cov.parquet"
    _run_ok(run_cli, ["propagate", files["cov"], "--span", "5400", "--step", "2700", "--dut1", "0.1", "-o", out])
    eph = read_ephemeris(str(out))
    cols = list(eph.frame.columns)
    assert cols[7:13] == ["sigma_x_m", "sigma_y_m", "sigma_z_m", "sigma_vx_m_s", "sigma_vy_m_s", "sigma_vz_m_s"]
    assert cols[13:] == list(COV_COLUMNS)
    cov = eph.matrix("cov")
    fd = _fd_stm(np.array([0.0, 2700.0, 5400.0]))
    expected = fd @ P0 @ np.swapaxes(fd, 1, 2)
    scale = np.sqrt(np.einsum("nii->ni", expected))
    assert np.abs((cov - expected) / (scale[:, :, None] * scale[:, None, :])).max() < 1e-6
    assert np.allclose(eph.frame["sigma_x_m"], np.sqrt(cov[:, 0, 0]))
    assert np.allclose(cov[0], P0, rtol=1e-12, atol=1e-15)
    assert "Phi" in eph.meta["covariance"]["propagation"]


# ----------------------------------------------------------------------------- CCSDS OEM

def parse_oem(text: str) -> dict:
    """A tiny CCSDS OEM KVN reader: header, one META block, data lines, covariance blocks."""
    header, meta, lines, covs = {}, {}, [], []
    section = "header"
    cov = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("COMMENT"):
            continue
        if line in ("META_START", "META_STOP", "COVARIANCE_START", "COVARIANCE_STOP"):
            section = {"META_START": "meta", "META_STOP": "data", "COVARIANCE_START": "cov",
                       "COVARIANCE_STOP": "done"}[line]
            continue
        if section in ("header", "meta"):
            key, _, value = line.partition("=")
            (header if section == "header" else meta)[key.strip()] = value.strip()
        elif section == "data":
            parts = line.split()
            assert len(parts) == 7, line
            lines.append((np.datetime64(parts[0], "ns"), [float(p) for p in parts[1:]]))
        elif section == "cov":
            if line.startswith("EPOCH"):
                cov = {"epoch": np.datetime64(line.split("=")[1].strip(), "ns"), "rows": []}
                covs.append(cov)
            elif line.startswith("COV_REF_FRAME"):
                cov["frame"] = line.split("=")[1].strip()
            else:
                cov["rows"].append([float(p) for p in line.split()])
    for c in covs:
        m = np.zeros((6, 6))
        for i, row in enumerate(c["rows"]):
            assert len(row) == i + 1
            m[i, :i + 1] = row
        c["matrix"] = m + np.tril(m, -1).T
    return {"header": header, "meta": meta, "lines": lines, "covariances": covs}


def test_oem_parses_back_to_the_same_numbers(run_cli, files, tmp_path, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1767225600")          # 2026-01-01: reproducible
    table, oem_path = tmp_path / "e.parquet", tmp_path / "e.oem"
    args = ["propagate", files["cov"], "--span", "3600", "--step", "600", "--dut1", "0.1"]
    _run_ok(run_cli, args + ["-o", table])
    _run_ok(run_cli, args + ["--object-name", "SEED 004", "--object-id", "2026-001A", "-o", oem_path])
    text = oem_path.read_text()
    oem = parse_oem(text)
    assert oem["header"]["CCSDS_OEM_VERS"] == "2.0" and oem["header"]["ORIGINATOR"] == "TRACKPROC"
    assert oem["header"]["CREATION_DATE"] == "2026-01-01T00:00:00.000"
    meta = oem["meta"]
    assert meta == {"OBJECT_NAME": "SEED 004", "OBJECT_ID": "2026-001A", "CENTER_NAME": "EARTH",
                    "REF_FRAME": "GCRF", "TIME_SYSTEM": "UTC", "START_TIME": "2026-03-20T09:30:00.000",
                    "STOP_TIME": "2026-03-20T10:30:00.000"}
    eph = read_ephemeris(str(table))
    times = _times(eph.frame)
    assert [t for t, _ in oem["lines"]] == list(times)
    km = np.array([row for _, row in oem["lines"]])
    assert np.allclose(km * 1000.0, eph.states, rtol=1e-15, atol=0)
    assert len(oem["covariances"]) == 7
    cov = eph.matrix("cov")
    for c, t, m in zip(oem["covariances"], times, cov):
        assert c["epoch"] == t and c["frame"] == "GCRF"
        assert np.allclose(c["matrix"] * 1e6, m, rtol=1e-15, atol=0)
    # same input, same bytes (with SOURCE_DATE_EPOCH)
    _run_ok(run_cli, args + ["--object-name", "SEED 004", "--object-id", "2026-001A", "-o", tmp_path / "f.oem"])
    assert (tmp_path / "f.oem").read_text() == text


# ----------------------------------------------------------------------------- the pass predictor

@pytest.mark.parametrize("model", ["doppler", "instantaneous"])
def test_at_station_equals_simulated_noiseless_measurements(run_cli, files, tmp_path, model):
    passes = tmp_path / "passes.parquet"
    _run_ok(run_cli, ["simulate", "--state", files["state"], "--stations", files["stations"], "--duration", "7200",
                      "--step", "10", "--dut1", "0.1", "--seed", "1", "--range-rate-model", model, *NOISELESS,
                      "-o", passes])
    table = read_pass_table(str(passes))
    checked = 0
    for name in sorted(table.frame["station"].unique()):
        out = tmp_path / f"pred_{name}.parquet"
        # the station's coordinates come from the pass file's metadata (no --stations)
        _run_ok(run_cli, ["propagate", files["state"], "--at", passes, "--at-station", name, "--carrier-hz", "2.2e9",
                          "--range-rate-model", model, "--dut1", "0.1", "-o", out])
        pred = read_ephemeris(str(out))
        assert pred.meta["station"]["name"] == name and pred.meta["range_rate_model"] == model
        f = pred.frame.set_index("time")
        sim = table.frame[table.frame["station"] == name]
        for kind, column, scale, tol in (("range", "range_m", 1.0, 1e-3),
                                         ("range_rate", "range_rate_m_s", 1.0, 1e-6),
                                         ("doppler", "doppler_hz", 1.0, 1e-5),
                                         ("elevation", "elevation_deg", np.pi / 180, 1e-7),
                                         ("azimuth", "azimuth_deg", np.pi / 180, 1e-7)):
            rows = sim[sim["kind"] == kind]
            predicted = f.loc[pd.DatetimeIndex(rows["time"]), column].to_numpy() * scale
            diff = predicted - rows["value"].to_numpy()
            if kind == "azimuth":
                diff = np.angle(np.exp(1j * diff))
            assert np.abs(diff).max() < tol, (name, kind, np.abs(diff).max())
            checked += len(rows)
        assert np.allclose(f["doppler_hz"], -2.2e9 * f["range_rate_m_s"] / C_LIGHT, rtol=1e-15)
    assert checked > 500


def _finals(mjds, dut1, xp, yp) -> str:
    """IERS finals2000A rows (fixed columns: MJD 8-15, PM-x 19-27, PM-y 38-46, UT1-UTC 59-68)."""
    rows = []
    for m, d, x, y in zip(mjds, dut1, xp, yp):
        line = [" "] * 80
        for start, text in ((7, f"{m:8.2f}"), (18, f"{x:9.6f}"), (37, f"{y:9.6f}"), (58, f"{d:10.7f}")):
            line[start:start + len(text)] = text
        rows.append("".join(line))
    return "\n".join(rows) + "\n"


def test_at_station_with_an_eop_file(run_cli, files, write, tmp_path):
    # UT1-UTC with a 1.5 ms length-of-day excess and 0.3 arcsec of polar motion
    mjd = np.arange(61117.0, 61124.0)
    eop = write("finals.all", _finals(mjd, 0.1 - 0.0015 * np.arange(7), [0.15] * 7, [0.3] * 7))
    passes = tmp_path / "passes.parquet"
    _run_ok(run_cli, ["simulate", "--state", files["state"], "--stations", files["stations"], "--duration", "86400",
                      "--step", "30", "--eop", eop, *NOISELESS, "-o", passes])
    out = tmp_path / "pred.parquet"
    _run_ok(run_cli, ["propagate", files["state"], "--at", passes, "--at-station", "KIR", "--eop", eop, "-o", out])
    pred = read_ephemeris(str(out))
    assert pred.meta["earth_orientation"] == "IERS finals2000A finals.all"
    f = pred.frame.set_index("time")
    sim = read_pass_table(str(passes)).frame
    sim = sim[sim["station"] == "KIR"]
    for kind, column, scale, tol in (("range", "range_m", 1.0, 1e-3), ("range_rate", "range_rate_m_s", 1.0, 1e-6),
                                     ("elevation", "elevation_deg", np.pi / 180, 1e-7)):
        rows = sim[sim["kind"] == kind]
        diff = f.loc[pd.DatetimeIndex(rows["time"]), column].to_numpy() * scale - rows["value"].to_numpy()
        assert np.abs(diff).max() < tol, (kind, np.abs(diff).max())


def test_pass_predictor_grid_visible_only_and_sigmas(run_cli, files, tmp_path):
    out = tmp_path / "pred.csv"
    _run_ok(run_cli, ["propagate", files["cov"], "--span", "7200", "--step", "20", "--at-station", "ZHY",
                      "--stations", files["stations"], "--carrier-hz", "2.2e9", "--visible-only",
                      "--elevation-mask-deg", "5", "--dut1", "0.1", "-o", out])
    eph = read_ephemeris(str(out))
    f = eph.frame
    assert len(f) > 10 and (f["elevation_deg"] >= 5.0).all()
    for column in ("range_m", "range_rate_m_s", "doppler_hz", "azimuth_deg", "light_time_s", "sigma_range_m",
                   "sigma_range_rate_m_s", "sigma_doppler_hz"):
        assert column in f.columns
    assert (f["sigma_range_m"] > 0).all() and (f["sigma_range_rate_m_s"] > 0).all()
    assert np.allclose(f["light_time_s"], f["range_m"] / C_LIGHT, rtol=1e-12)
    assert eph.meta["elevation_mask_deg"] == 5.0 and eph.meta["units"]["doppler_hz"] == "Hz"
    # no pass above 89 deg in ten minutes: a processing failure (exit 1), nothing written
    bad = tmp_path / "none.csv"
    res = run_cli(["propagate", files["state"], "--span", "600", "--step", "60", "--at-station", "MAD",
                   "--stations", files["stations"], "--visible-only", "--elevation-mask-deg", "89", "--dut1", "0.1",
                   "-o", bad])
    assert res.exit_code == 1 and "no visible pass" in res.stderr and not bad.exists()


# ----------------------------------------------------------------------------- errors

@pytest.mark.parametrize("extra,message", [
    (["--span", "600", "--step", "10", "--at", "x.parquet"], "not both"),
    ([], "--span S and --step S"),
    (["--span", "600"], "--span S and --step S"),
    (["--span", "600", "--step", "0"], "--step"),
    (["--span", "nan", "--step", "10"], "--span"),
    (["--span", "600", "--step", "10", "--carrier-hz", "2e9"], "--carrier-hz needs --at-station"),
    (["--span", "600", "--step", "10", "--visible-only"], "--visible-only needs --at-station"),
    (["--span", "600", "--step", "10", "--at-station", "ZHY"], "--at-station needs --stations"),
    (["--span", "600", "--step", "10", "--at-station", "XXX", "--stations", "STATIONS"], "unknown station"),
    (["--span", "600", "--step", "10", "--stm", "--format", "oem"], "OEM holds states"),
    (["--span", "600", "--step", "10", "--tol", "0.5"], "--tol"),
    (["--span", "600", "--step", "10", "--force", "j4"], "--force"),
    (["--span", "600", "--step", "10", "--eop", "finals.all", "--dut1", "0.1"], "either --eop or --dut1"),
    (["--span", "600", "--step", "10", "--at-station", "ZHY", "--stations", "STATIONS", "--carrier-hz", "-1"],
     "--carrier-hz"),
])
def test_usage_errors_exit_2(run_cli, files, tmp_path, extra, message):
    args = [a if a != "STATIONS" else files["stations"] for a in extra]
    res = run_cli(["propagate", files["state"], *args, "-o", tmp_path / "o.parquet"])
    assert res.exit_code == 2, res.stderr
    assert message in _flat(res.stderr)
    assert not (tmp_path / "o.parquet").exists()


def test_bad_state_file_exit_2_and_orbit_into_the_earth_exit_1(run_cli, files, write, tmp_path):
    bad = write("bad.json", json.dumps(dict(STATE, velocity_m_s=[1.0, 2.0])))
    res = run_cli(["propagate", bad, "--span", "600", "--step", "10", "-o", tmp_path / "o.parquet"])
    assert res.exit_code == 2 and "velocity_m_s" in res.stderr
    # an ellipse with perigee 4300 km from the centre: it goes through the Earth
    falling = write("falling.json",
                    json.dumps(dict(STATE, position_m=[6.5e6, 0.0, 0.0], velocity_m_s=[0.0, 7000.0, 0.0])))
    res = run_cli(["propagate", falling, "--span", "3600", "--step", "60", "--dut1", "0", "-o", tmp_path / "o.parquet"])
    assert res.exit_code == 1 and "enters the Earth" in res.stderr
    # straight through the centre: the Taylor series blow up, the propagation outcome is not success
    radial = write("radial.json",
                   json.dumps(dict(STATE, position_m=[6.5e6, 0.0, 0.0], velocity_m_s=[0.0, 1000.0, 0.0])))
    res = run_cli(["propagate", radial, "--span", "3600", "--step", "60", "--dut1", "0", "-o", tmp_path / "o.parquet"])
    assert res.exit_code == 1 and "propagation stopped (non_finite)" in res.stderr
    assert not (tmp_path / "o.parquet").exists()


def test_subprocess_pipe_arrow_stream(files):
    env = dict(os.environ, TRACKPROC_LOG_LEVEL="ERROR")
    py = sys.executable
    reader = ("import sys, pyarrow as pa; t = pa.ipc.open_stream(sys.stdin.buffer).read_all(); "
              "print(t.num_rows, ','.join(t.column_names), t.schema.field('time').type)")
    cmd = (f"'{py}' -m trackproc propagate '{files['state']}' --span 600 --step 10 --dut1 0.1 -o - "
           f"| '{py}' -c \"{reader}\"")
    out = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    rows, columns, ttype = out.stdout.split(maxsplit=2)
    assert rows == "61" and columns == "time,x_m,y_m,z_m,vx_m_s,vy_m_s,vz_m_s" and ttype.startswith("timestamp[ns")


def test_arrow_stream_to_stdout_in_process(run_cli, files):
    res = run_cli(["propagate", files["state"], "--span", "60", "--step", "30", "--dut1", "0.1", "-o", "-"])
    assert res.exit_code == 0, res.stderr
    table = pa.ipc.open_stream(pa.BufferReader(res.stdout_bytes)).read_all()
    assert table.num_rows == 3
    meta = json.loads(table.schema.metadata[b"trackproc"])
    assert meta["content"] == "ephemeris" and meta["time_scale"] == "UTC"
