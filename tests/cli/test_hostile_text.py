"""Hostile class: names from inputs and options never inject lines into KVN outputs or logs
(issue 14 item 4)."""

from __future__ import annotations

import json

import pytest

from hostile import DOPPLER_CSV, MULTI, STATIONS, TRUTH, assert_rejected

FORGERIES = ["SAT\nOBJECT_ID = FORGED", "SAT\rCENTER_NAME = MARS", "SAT\x00", "SAT\u2028X", "\t", "", "S" * 300]


@pytest.mark.parametrize("name", FORGERIES)
@pytest.mark.parametrize("flag", ["--object-name", "--object-id"])
def test_oem_names_cannot_forge_lines(run_cli, tmp_path, name, flag):
    out = tmp_path / "x.oem"
    result = run_cli(["propagate", TRUTH, "--span", "600", "--step", "60", "--dut1", "0", "--format", "oem",
                      flag, name, "-q", "-o", out])
    line = assert_rejected(result, 2, flag, outputs=[out], folder=tmp_path)
    assert "\n" not in line.rstrip("\n")


def test_tle_name_line_with_control_characters_is_refused_in_an_oem(run_cli, write, tmp_path):
    tle = write("sat.tle", "ISS\x1b[2J (ZARYA)\n"
                "1 25544U 98067A   20092.50000000  .00000700  00000-0  20000-4 0  9991\n"
                "2 25544  51.6440 230.0000 0005000  90.0000 270.0000 15.49000000 10000\n")
    out = tmp_path / "x.oem"
    result = run_cli(["propagate", tle, "--span", "600", "--step", "60", "--dut1", "0", "--format", "oem", "-q",
                      "-o", out])
    assert_rejected(result, 2, "OBJECT_NAME", outputs=[out])


@pytest.mark.parametrize("name", ["CPH\nKIR", "C\x00PH", "CPH\x1b[31m"])
def test_station_names_with_control_characters(run_cli, write, tmp_path, name):
    stations = write("st.csv", f'station,lat_deg,lon_deg,height_m\n"{name}",55.7,12.55,30\n')
    raw = write("r.csv", f'time,station,range_m\n2026-03-20T09:30:00Z,"{name}",1000000\n')
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", raw, "--stations", stations, "-q", "-o", out])
    assert_rejected(result, 2, "st.csv", "station", outputs=[out])


def test_nominal_station_with_a_newline(run_cli, write):
    nominal = write("n.json", json.dumps({"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3,
                                          "angle_deg": 48, "station": "KIR\nFORGED"}))
    result = run_cli(["detect", MULTI, "--nominal", nominal, "-q"])
    assert_rejected(result, 2, "n.json", "station")


def test_file_name_with_a_newline_cannot_forge_a_log_line(run_cli, tmp_path):
    raw = tmp_path / "pass\ntrackproc: INFO: all good.csv"
    raw.write_bytes(DOPPLER_CSV.read_bytes())
    out = tmp_path / "o.parquet"
    result = run_cli(["-v", "ingest", raw, "--stations", STATIONS, "--carrier-hz", "2.2e9", "--mode", "one-way",
                      "-o", out])     # -v: the INFO line that names the file is logged
    assert result.exit_code == 0, result.stderr
    lines = result.stderr.splitlines()
    assert lines and all(line.startswith("trackproc: ") for line in lines)
    assert not any(line.startswith("trackproc: INFO: all good") for line in lines)


def test_error_naming_a_file_with_a_newline_is_one_line(run_cli, tmp_path):
    raw = tmp_path / "bad\nFORGED: line.csv"
    raw.write_text("time,station,range_m\n2026-03-20T09:30:00Z,CPH,-1\n")
    result = run_cli(["ingest", raw, "--stations", STATIONS, "-q", "-o", tmp_path / "o.parquet"])
    line = assert_rejected(result, 2, "bad\\nFORGED", "row 2")
    assert "\\n" in line


def test_missing_file_with_escape_sequences_in_its_name(run_cli, tmp_path):
    result = run_cli(["info", str(tmp_path / "no\x1b[2Jsuch.parquet")])
    line = assert_rejected(result, 2, "file not found")
    assert "\x1b" not in line
