"""``trackproc ingest``: layouts, units, passes, formats, determinism, pipes."""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from trackproc.cli.app import app
from trackproc.io.passfile import (COLUMNS, PassTable, base_meta, parse_pass_table, read_pass_table,
                                   write_pass_table)
from trackproc.io.stations import read_stations
from trackproc.io.tabular import read_raw
from trackproc.pipeline.ingest import IngestOptions, assign_pass_ids, ingest

WIDE = """time,station,range_rate_m_s,elevation_deg,range_km,sigma_range_rate_m_s
2026-03-20T09:30:00Z,ZHY,-5000.5,10.0,1200.5,0.05
2026-03-20T09:30:10Z,ZHY,-4900.25,12.5,1190,
2026-03-20T11:30:20+02:00,ZHY,-4800,15,,
2026-03-20T09:30:05,KIR,100,,,
"""


def test_wide_csv_to_parquet_units_and_order(run_cli, write, stations_csv, tmp_path):
    raw = write("raw.csv", WIDE)
    out = tmp_path / "pass.parquet"
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", out])
    assert result.exit_code == 0, result.stderr
    assert out.read_bytes()[:4] == b"PAR1"
    table = read_pass_table(str(out))
    frame = table.frame
    assert list(frame.columns) == list(COLUMNS)
    assert str(frame["time"].dtype) == "datetime64[ns, UTC]"
    assert frame["value"].dtype == np.float64 and frame["sigma"].dtype == np.float64
    # sorted by station, then time, then kind
    assert list(frame["station"]) == ["KIR"] + ["ZHY"] * 8
    zhy = frame[frame.station == "ZHY"]
    assert zhy["time"].is_monotonic_increasing
    first = zhy[zhy.time == pd.Timestamp("2026-03-20T09:30:00Z")].set_index("kind")
    assert first.loc["elevation", "value"] == pytest.approx(math.radians(10.0), rel=1e-15)
    assert first.loc["elevation", "sigma"] == pytest.approx(math.radians(0.01))   # default 0.01 deg
    assert first.loc["range", "value"] == pytest.approx(1200.5e3)                # km -> m
    assert first.loc["range", "sigma"] == 10.0                                   # default, m
    assert first.loc["range_rate", "sigma"] == 0.05                              # given
    # +02:00 offset converted to UTC
    assert pd.Timestamp("2026-03-20T09:30:20Z") in set(zhy["time"])
    meta = table.meta
    assert meta["schema_version"] == 1 and meta["time_scale"] == "UTC"
    assert meta["units"]["elevation"] == "rad" and meta["units"]["range"] == "m"
    assert meta["stations"]["ZHY"] == {"lat_deg": 40.0, "lon_deg": 116.0, "height_m": 50.0}
    assert meta["sources"] == [str(raw)]
    assert "received - nominal" in meta["doppler_sign_convention"]


def test_long_duplicate_spellings_are_duplicates(write, stations_csv, run_cli):
    raw = write("long.csv", "time,station,kind,value\n"
                            "2026-03-20T09:30:00Z,ZHY,elevation_deg,45\n"
                            "2026-03-20T09:30:00Z,ZHY,elevation,0.5\n")
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", raw.with_suffix(".parquet")])
    assert result.exit_code == 2
    assert "row 3" in result.stderr and "duplicated timestamp" in result.stderr


def test_long_layout_units_and_sigma_scaling(write, stations_csv):
    raw = write("long.csv", "time,station,kind,value,sigma\n"
                            "2026-03-20T09:30:00Z,ZHY,elevation_deg,45,0.1\n"
                            "2026-03-20T09:30:01Z,ZHY,range_km,1000,0.002\n"
                            "2026-03-20T09:30:02Z,ZHY,range,5,\n"
                            "2026-03-20T09:30:03Z,ZHY,Doppler_Hz,-1234.5,\n")
    result = ingest([read_raw(str(raw))], read_stations(str(stations_csv)),
                    IngestOptions(carrier_hz=2.2e9, doppler_mode="two-way", sigma_doppler_hz=3.0))
    frame = result.table.frame.set_index("kind")
    assert frame.loc["elevation", "value"] == pytest.approx(math.pi / 4)
    assert frame.loc["elevation", "sigma"] == pytest.approx(math.radians(0.1))
    assert frame.loc["range", "value"].tolist() == [1e6, 5.0]
    assert frame.loc["range", "sigma"].tolist() == pytest.approx([2.0, 10.0])
    assert frame.loc["doppler", "sigma"] == 3.0
    assert result.table.meta["carrier_hz"] == 2.2e9
    assert result.table.meta["doppler_mode"] == "two-way"


def _times(*seconds):
    start = pd.Timestamp("2026-03-20T09:00:00Z")
    return [(start + pd.Timedelta(seconds=s)).isoformat().replace("+00:00", "Z") for s in seconds]


def test_passes_split_by_gap_and_numbered_by_start(write, stations_csv, run_cli, tmp_path):
    lines = ["time,station,range_m"]
    lines += [f"{t},ZHY,1000" for t in _times(0, 10, 20, 400, 410, 2000)]
    lines += [f"{t},KIR,1000" for t in _times(5, 15)]
    raw = write("gaps.csv", "\n".join(lines) + "\n")
    out = tmp_path / "p.parquet"
    assert run_cli(["ingest", raw, "--stations", stations_csv, "-o", out]).exit_code == 0
    frame = read_pass_table(str(out)).frame
    zhy = frame[frame.station == "ZHY"]
    assert zhy["pass_id"].tolist() == ["ZHY-001"] * 3 + ["ZHY-002"] * 2 + ["ZHY-003"]
    assert set(frame[frame.station == "KIR"]["pass_id"]) == {"KIR-001"}
    assert run_cli(["ingest", raw, "--stations", stations_csv, "--max-gap", "1000", "-o", out]).exit_code == 0
    zhy = read_pass_table(str(out)).frame.query("station == 'ZHY'")
    assert zhy["pass_id"].tolist() == ["ZHY-001"] * 5 + ["ZHY-002"]


def test_given_pass_ids_are_kept():
    frame = pd.DataFrame({
        "time": pd.to_datetime(_times(0, 10, 1000, 2000), utc=True),
        "station": ["A"] * 4, "pass_id": ["A-001", "", "", "mine"],
    })
    # the generated ids skip the one the input already uses
    assert assign_pass_ids(frame, 300.0).tolist() == ["A-001", "A-002", "A-003", "mine"]


def test_multiple_inputs_merge(write, stations_csv, run_cli, tmp_path):
    a = write("a.csv", "time,station,range_m\n" + "".join(f"{t},ZHY,1\n" for t in _times(0, 10)))
    b = write("b.csv", "time,station,kind,value\n" + "".join(f"{t},KIR,range_m,2\n" for t in _times(5)))
    out = tmp_path / "ab.parquet"
    assert run_cli(["ingest", a, b, "--stations", stations_csv, "-o", out]).exit_code == 0
    table = read_pass_table(str(out))
    assert len(table.frame) == 3
    assert table.meta["sources"] == [str(a), str(b)]
    assert sorted(table.meta["stations"]) == ["KIR", "ZHY"]


@pytest.mark.parametrize("fmt, suffix", [("parquet", ".parquet"), ("arrow", ".arrow"), ("csv", ".csv")])
def test_deterministic_output(write, stations_csv, run_cli, tmp_path, fmt, suffix):
    raw = write("raw.csv", WIDE)
    one, two = tmp_path / ("one" + suffix), tmp_path / ("two" + suffix)
    for out in (one, two):
        assert run_cli(["ingest", raw, "--stations", stations_csv, "--format", fmt, "-o", out]).exit_code == 0
    assert one.read_bytes() == two.read_bytes()


def test_stdout_default_is_arrow_stream_and_round_trips_through_stdin(write, stations_csv, run_cli):
    raw = write("raw.csv", WIDE)
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", "-"])
    assert result.exit_code == 0, result.stderr
    assert result.stdout_bytes[:4] == b"\xff\xff\xff\xff"
    stream = result.stdout_bytes
    info = run_cli(["info", "-", "--json"], input=stream)
    assert info.exit_code == 0, info.stderr
    assert json.loads(info.stdout)["samples"] == 9
    again = run_cli(["ingest", "-", "-o", "-"], input=stream)      # canonical in -> same samples
    assert again.exit_code == 0, again.stderr
    before = parse_pass_table(stream, "a").frame
    after = parse_pass_table(again.stdout_bytes, "b").frame
    pd.testing.assert_frame_equal(before, after)


def test_parquet_via_stdin_and_csv_round_trip(write, stations_csv, run_cli, tmp_path):
    raw = write("raw.csv", WIDE)
    parquet, csv_out = tmp_path / "p.parquet", tmp_path / "p.csv"
    assert run_cli(["ingest", raw, "--stations", stations_csv, "-o", parquet]).exit_code == 0
    info = run_cli(["info", "-"], input=parquet.read_bytes())
    assert info.exit_code == 0 and "ZHY-001" in info.stdout
    assert run_cli(["ingest", "-", "-o", csv_out], input=parquet.read_bytes()).exit_code == 0
    text = csv_out.read_text()
    assert text.startswith("# trackproc: {")
    assert "2026-03-20T09:30:00Z,ZHY,ZHY-001,elevation_deg,10.0," in text   # degrees at the CSV edge
    # CSV (with its metadata line) ingested again: identical samples and stations
    back = tmp_path / "back.parquet"
    assert run_cli(["ingest", csv_out, "-o", back]).exit_code == 0
    pd.testing.assert_frame_equal(read_pass_table(str(parquet)).frame, read_pass_table(str(back)).frame)
    assert read_pass_table(str(back)).meta["stations"] == read_pass_table(str(parquet)).meta["stations"]


def test_parquet_and_arrow_file_inputs_of_wide_layout(write, stations_csv, run_cli, tmp_path):
    table = pa.table({
        "time": pa.array(pd.to_datetime(_times(0, 1, 2)).tz_localize(None).to_numpy(), pa.timestamp("ms")),
        "station": ["ZHY", "ZHY", "ZHY"],
        "elevation_deg": [10.0, None, 30.0],
        "azimuth_deg": [100.0, 101.0, 102.0],
    })
    buf = io.BytesIO()
    pq.write_table(table, buf)
    pfile = write("wide.parquet", buf.getvalue())
    sink = pa.BufferOutputStream()
    with pa.ipc.new_file(sink, table.schema) as writer:
        writer.write_table(table)
    afile = write("wide.arrow", sink.getvalue().to_pybytes())
    for path in (pfile, afile):
        out = tmp_path / (path.stem + "_out.parquet")
        result = run_cli(["ingest", path, "--stations", stations_csv, "-o", out])
        assert result.exit_code == 0, result.stderr
        frame = read_pass_table(str(out)).frame
        assert (frame.kind == "elevation").sum() == 2 and (frame.kind == "azimuth").sum() == 3
        assert frame.query("kind == 'azimuth'")["value"].iloc[0] == pytest.approx(math.radians(100))


def test_doppler_settings_stored_and_shown(write, stations_csv, run_cli, tmp_path):
    raw = write("dop.csv", "time,station,doppler_hz\n" + "".join(f"{t},ZHY,-1500.5\n" for t in _times(0, 1)))
    out = tmp_path / "d.parquet"
    result = run_cli(["ingest", raw, "--stations", stations_csv, "--carrier-hz", "2.2e9",
                      "--mode", "two-way", "-o", out])
    assert result.exit_code == 0, result.stderr
    meta = read_pass_table(str(out)).meta
    assert (meta["carrier_hz"], meta["doppler_mode"]) == (2.2e9, "two-way")
    info = run_cli(["info", out])
    assert "2200000000.0 Hz" in info.stdout and "two-way" in info.stdout


def test_drop_invalid_reports_counts_on_stderr_and_in_metadata(write, stations_csv, run_cli, tmp_path):
    t = _times(0, 1, 2, 3, 4, 5)
    raw = write("bad.csv", "time,station,range_m,elevation_deg\n"
                           f"{t[0]},ZHY,1,10\n"
                           f"{t[1]},ZHY,nan,95\n"          # non-finite value + elevation out of range
                           f"not-a-time,ZHY,3,\n"
                           f"{t[3]},XXX,4,\n"
                           f"{t[0]},ZHY,5,\n"              # duplicated range at t0
                           f"{t[5]},ZHY,abc,20\n")          # wrong type range, elevation fine
    out = tmp_path / "kept.parquet"
    result = run_cli(["ingest", raw, "--stations", stations_csv, "--drop-invalid", "-o", out])
    assert result.exit_code == 0, result.stderr
    assert "dropped 6 invalid samples" in result.stderr
    for reason in ("non-finite value 1", "elevation out of range 1", "unparseable time 1",
                   "unknown station 1", "duplicated timestamp 1", "wrong column type 1"):
        assert reason in result.stderr
    table = read_pass_table(str(out))
    assert len(table.frame) == 3        # t0 range + t0 elevation + t5 elevation
    assert sum(table.meta["dropped_rows"].values()) == 6


def test_stations_optional_when_inputs_define_them(write, run_cli, tmp_path):
    stations = write("st.csv", "station,lat_deg,lon_deg,height_m,range_bias_m\nZHY,40,116,50,12.5\n")
    raw = write("raw.csv", "time,station,range_m\n" + "".join(f"{t},ZHY,1\n" for t in _times(0, 1)))
    first = tmp_path / "first.parquet"
    assert run_cli(["ingest", raw, "--stations", stations, "-o", first]).exit_code == 0
    assert read_pass_table(str(first)).meta["stations"]["ZHY"]["range_bias_m"] == 12.5
    again = tmp_path / "again.parquet"
    result = run_cli(["ingest", first, "-o", again])          # no --stations: carried in metadata
    assert result.exit_code == 0, result.stderr
    assert read_pass_table(str(again)).stations()["ZHY"].range_bias_m == 12.5


def test_pass_table_keeps_extra_columns(tmp_path):
    frame = pd.DataFrame({
        "time": pd.to_datetime(_times(0, 1), utc=True).as_unit("ns"), "station": ["A", "A"],
        "pass_id": ["A-001"] * 2, "kind": ["range"] * 2, "value": [1.0, 2.0], "sigma": [1.0, 1.0],
        "smoothed": [1.1, 1.9], "flag": [False, True],
    })
    table = PassTable(frame, base_meta(stations={"A": {"lat_deg": 0.0, "lon_deg": 0.0, "height_m": 0.0}}))
    for fmt in ("parquet", "arrow", "csv"):
        path = tmp_path / f"x.{fmt}"
        write_pass_table(table, str(path), fmt)
        back = read_pass_table(str(path))
        assert back.frame["smoothed"].tolist() == [1.1, 1.9]
        assert back.frame["flag"].tolist() == [False, True]
        assert back.frame["time"].tolist() == frame["time"].tolist()
        assert back.meta["stations"]["A"]["height_m"] == 0.0


def test_doptrack_adapter(write, run_cli, tmp_path):
    data = write("dt/data/Sat_1_202001010000.csv",
                 "# time,frequency,rangerate\n1.0,145871000.0,-7000\n1.5,145870998.0,-6990\n")
    yml = ("satellite:\n  name: Delfi-C3\n  noradid: '32789'\nstation:\n  name: Delft\n"
           "  position: {altitude: 95, latitude: 51.9989, longitude: 4.3733585}\n"
           "tracking:\n  epoch: 2020-01-01 00:00:00.25\n  fca: 145870500.0\n  tca: 2020-01-01 00:05:00\n")
    write("dt/metadata/Sat_1_202001010000.yml", yml)
    out = tmp_path / "dt.parquet"
    result = run_cli(["ingest", data, "-o", out])          # stations from the sidecar
    assert result.exit_code == 0, result.stderr
    table = read_pass_table(str(out))
    frame = table.frame
    assert frame["kind"].unique().tolist() == ["doppler"]
    assert frame["value"].tolist() == [1000.0, 998.0]              # received - 145.870 MHz
    assert frame["time"].iloc[0] == pd.Timestamp("2020-01-01T00:00:01.25Z")
    assert frame["pass_id"].unique().tolist() == ["Sat_1_202001010000"]
    assert table.meta["carrier_hz"] == 145.870e6 and table.meta["doppler_mode"] == "one-way"
    assert table.meta["stations"]["Delft"]["height_m"] == 95.0
    assert table.meta["doptrack"][str(data)]["fca_hz"] == 145870500.0
    # --carrier-hz overrides; a sidecar in the same folder and --sidecar are found too
    write("flat/Sat_1_202001010000.yml", yml.replace("Delfi-C3", "Other"))
    flat = write("flat/Sat_1_202001010000.csv", data.read_bytes())
    result = run_cli(["ingest", flat, "--carrier-hz", "145871000", "-o", out])
    assert result.exit_code == 0, result.stderr
    assert read_pass_table(str(out)).frame["value"].tolist() == [0.0, -2.0]
    result = run_cli(["ingest", "-", "--layout", "doptrack", "--sidecar",
                      tmp_path / "dt/metadata/Sat_1_202001010000.yml", "-o", out], input=data.read_bytes())
    assert result.exit_code == 0, result.stderr


def test_orekit_aer_adapter(write, run_cli, tmp_path):
    aer = write("w.aer", "# comment\n\n"
                         "2010-11-02T03:00:13.3851   RANGE   ZHY   38014.9488\n"
                         "2010-11-02T03:00:50.5716   AZ_EL   ZHY   211.1446   43.4099\n")
    out = tmp_path / "w.parquet"
    stations = write("s.csv", "station,lat_deg,lon_deg,height_m\nZHY,40,116,50\n")
    result = run_cli(["ingest", aer, "--stations", stations, "-o", out])
    assert result.exit_code == 0, result.stderr
    frame = read_pass_table(str(out)).frame.set_index("kind")
    assert frame.loc["range", "value"] == pytest.approx(38014948.8)
    assert frame.loc["azimuth", "value"] == pytest.approx(math.radians(211.1446))
    assert frame.loc["elevation", "value"] == pytest.approx(math.radians(43.4099))
    # detected by content too (stdin has no suffix)
    assert run_cli(["ingest", "-", "--stations", stations, "-o", out], input=aer.read_bytes()).exit_code == 0


def test_typer_cli_runner_help():
    result = CliRunner().invoke(app, ["ingest", "--help"])
    assert result.exit_code == 0
    for option in ("--stations", "--carrier-hz", "--mode", "--max-gap", "--layout", "--drop-invalid",
                   "--format", "--sidecar"):
        assert option in result.output


# --------------------------------------------------------------------------- real pipes


def _trackproc() -> list[str]:
    script = Path(sys.executable).parent / "trackproc"
    return [str(script)] if script.exists() else [sys.executable, "-m", "trackproc"]


@pytest.mark.skipif(shutil.which("sh") is None, reason="needs a POSIX shell")
def test_real_pipe_ingest_to_info(write, stations_csv, tmp_path):
    raw = write("x.csv", WIDE)
    exe = " ".join(f"'{p}'" for p in _trackproc())
    proc = subprocess.run(f"{exe} ingest '{raw}' --stations '{stations_csv}' -o - | {exe} info -",
                          shell=True, capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "ZHY-001" in proc.stdout and "KIR-001" in proc.stdout
    assert "Traceback" not in proc.stderr


@pytest.mark.skipif(shutil.which("head") is None, reason="needs head")
@pytest.mark.parametrize("command", ["ingest", "info"])
def test_real_pipe_closed_early_is_quiet(write, stations_csv, tmp_path, command):
    # enough rows that the output exceeds the pipe buffer
    rows = "".join(f"2026-03-20T09:{m:02d}:{s:02d}Z,ZHY,{m * 60 + s},10\n" for m in range(60) for s in range(60))
    raw = write("big.csv", "time,station,range_m,elevation_deg\n" + rows)
    exe = " ".join(f"'{p}'" for p in _trackproc())
    if command == "ingest":
        line = f"{exe} ingest '{raw}' --stations '{stations_csv}' --max-gap 1 -o - | head -c 10"
    else:
        line = (f"{exe} ingest '{raw}' --stations '{stations_csv}' --max-gap 0.5 -o p.parquet "
                f"&& {exe} info p.parquet | head -c 10")
    proc = subprocess.run(["sh", "-c", line], capture_output=True, cwd=tmp_path, timeout=120,
                          env={**os.environ, "TRACKPROC_LOG_LEVEL": "ERROR"})
    assert proc.returncode == 0
    assert len(proc.stdout) == 10
    assert b"Traceback" not in proc.stderr and b"Error" not in proc.stderr, proc.stderr


TDM_SAMPLE = Path(__file__).resolve().parents[1] / "data" / "tdm" / "oneway_doppler.tdm"


@pytest.mark.skipif(not TDM_SAMPLE.exists(), reason="CCSDS TDM sample not present")
def test_ccsds_tdm_is_dispatched_by_its_first_keyword(write, run_cli, tmp_path):
    stations = write("s.csv", "station,lat_deg,lon_deg,height_m\nDSS-25,35.3,243.1,960\n")
    out = tmp_path / "t.parquet"
    # through stdin: detected by CCSDS_TDM_VERS, not by the suffix
    result = run_cli(["ingest", "-", "--stations", stations, "-o", out], input=TDM_SAMPLE.read_bytes())
    assert result.exit_code == 0, result.stderr
    table = read_pass_table(str(out))
    assert "doppler" in set(table.frame["kind"]) and table.meta["doppler_mode"] == "one-way"
    assert table.meta["inputs"]["<stdin>"]["format"] == "CCSDS TDM (KVN)"
