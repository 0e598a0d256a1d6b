"""Every bad input of ``trackproc ingest`` / ``info``: exit code 2, one line naming file, row, column."""

from __future__ import annotations

import io

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from trackproc.errors import InputError
from trackproc.io.stations import parse_stations

HEAD = "time,station,range_m,elevation_deg,sigma_range_m\n"
T0, T1, T2 = "2026-03-20T09:30:00Z", "2026-03-20T09:30:01Z", "2026-03-20T09:30:02Z"


def _csv(*rows: str) -> str:
    return HEAD + "".join(r + "\n" for r in rows)


# name, input CSV text, extra args, expected row, expected column, words in the message
CASES = [
    ("empty file", "", [], 1, None, ["empty input"]),
    ("header only", HEAD, [], 2, None, ["empty input", "no data rows"]),
    ("all cells empty", _csv(f"{T0},ZHY,,,"), [], 2, "range_m, elevation_deg", ["empty input"]),
    ("unparseable time", _csv(f"{T0},ZHY,1,,", "2026-13-45T00:00:00Z,ZHY,2,,"), [], 3, "time",
     ["unparseable time", "'2026-13-45T00:00:00Z'", "ISO 8601"]),
    ("empty time", _csv(f"{T0},ZHY,1,,", ",ZHY,2,,"), [], 3, "time", ["unparseable time"]),
    ("wrong column type", _csv(f"{T0},ZHY,1,,", f"{T1},ZHY,12 m,,"), [], 3, "range_m",
     ["wrong column type", "'12 m'", "a number"]),
    ("wrong sigma type", _csv(f"{T0},ZHY,1,,x"), [], 2, "sigma_range_m", ["wrong column type", "'x'"]),
    ("NaN value", _csv(f"{T0},ZHY,1,,", f"{T1},ZHY,NaN,,"), [], 3, "range_m", ["non-finite value", "nan"]),
    ("Inf value", _csv(f"{T0},ZHY,1,,", f"{T1},ZHY,1,-inf,"), [], 3, "elevation_deg",
     ["non-finite value", "-inf"]),
    ("NaN sigma", _csv(f"{T0},ZHY,1,,nan"), [], 2, "sigma_range_m", ["non-finite sigma"]),
    ("Inf sigma", _csv(f"{T0},ZHY,1,,", f"{T1},ZHY,1,,inf"), [], 3, "sigma_range_m", ["non-finite sigma"]),
    ("negative sigma", _csv(f"{T0},ZHY,1,,2", f"{T1},ZHY,1,,-0.5"), [], 3, "sigma_range_m",
     ["non-positive sigma", "-0.5", "sigma > 0"]),
    ("zero sigma", _csv(f"{T0},ZHY,1,,0"), [], 2, "sigma_range_m", ["non-positive sigma", "sigma > 0"]),
    ("elevation above 90 deg", _csv(f"{T0},ZHY,,45,", f"{T1},ZHY,,90.5,"), [], 3, "elevation_deg",
     ["elevation out of range", "90.5", "[-90, 90] deg"]),
    ("elevation below -90 deg", _csv(f"{T0},ZHY,,-91,"), [], 2, "elevation_deg", ["-91.0"]),
    ("duplicated timestamp", _csv(f"{T0},ZHY,1,,", f"{T1},ZHY,2,,", f"{T0},ZHY,3,,"), [], 4, "range_m",
     ["duplicated timestamp", "first at", "row 2"]),
    ("unknown station", _csv(f"{T0},ZHY,1,,", f"{T1},ZHX,1,,"), [], 3, "station",
     ["unknown station", "'ZHX'", "KIR, ZHY"]),
    ("missing station column", "time,range_m\n" + f"{T0},1\n", [], 1, "station",
     ["missing required column"]),
    ("missing time column", "station,range_m\nZHY,1\n", [], 1, "time", ["missing required column"]),
    ("no measurement column", "time,station,elevation\n" + f"{T0},ZHY,1\n", [], 1, "(none)",
     ["no measurement column", "elevation_deg"]),
    ("long layout missing value", "time,station,kind\n" + f"{T0},ZHY,range_m\n", ["--layout", "long"], 1,
     "value", ["missing required column"]),
    ("long layout unknown kind", "time,station,kind,value\n" + f"{T0},ZHY,range_m,1\n{T1},ZHY,altitude,1\n",
     [], 3, "kind", ["unknown kind", "'altitude'"]),
    ("wrong number of fields", _csv(f"{T0},ZHY,1,,", f"{T1},ZHY,1"), [], 3, None, ["wrong number of fields"]),
    ("Doppler without carrier", "time,station,doppler_hz\n" + f"{T0},ZHY,-100\n", ["--mode", "one-way"], 2,
     "--carrier-hz", ["nominal carrier"]),
    ("Doppler without mode", "time,station,doppler_hz\n" + f"{T0},ZHY,-100\n", ["--carrier-hz", "2.2e9"], 2,
     "--mode", ["one-way or --mode two-way"]),
]


@pytest.mark.parametrize("name, text, extra, row, column, words", CASES, ids=[c[0] for c in CASES])
def test_bad_input_exit_2_names_file_row_column(run_cli, write, stations_csv, tmp_path, name, text, extra,
                                                 row, column, words):
    raw = write("in.csv", text)
    out = tmp_path / "out.parquet"
    result = run_cli(["ingest", raw, "--stations", stations_csv, *extra, "-o", out])
    assert result.exit_code == 2, result.stderr
    message = result.stderr.strip().splitlines()[-1]
    assert message.startswith(f"trackproc: error: {raw}, row {row}")
    if column is not None:
        label = "option" if column.startswith("-") else "column"     # errors.py: an option is called one
        assert f"{label} '{column}'" in message
    for word in words:
        assert word in message
    assert "Traceback" not in result.stderr
    assert not out.exists()          # nothing half-written


def test_unknown_station_without_any_stations_table(run_cli, write, tmp_path):
    raw = write("in.csv", _csv(f"{T0},ZHY,1,,"))
    result = run_cli(["ingest", raw, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2
    assert f"{raw}, row 2, column 'station'" in result.stderr and "--stations" in result.stderr


def test_duplicate_across_files_names_both(run_cli, write, stations_csv, tmp_path):
    a = write("a.csv", _csv(f"{T0},ZHY,1,,"))
    b = write("b.csv", _csv(f"{T1},ZHY,1,,", f"{T0},ZHY,2,,"))
    result = run_cli(["ingest", a, b, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2
    assert f"{b}, row 3, column 'range_m'" in result.stderr and f"first at {a} row 2" in result.stderr


def test_elevation_in_radians_reported_in_radians(run_cli, write, stations_csv, tmp_path):
    raw = write("long.csv", f"time,station,kind,value\n{T0},ZHY,elevation,1.6\n")
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2
    assert "row 2, column 'value'" in result.stderr and "1.6" in result.stderr and "rad" in result.stderr


def test_parquet_wrong_time_type_and_record_rows(run_cli, write, stations_csv, tmp_path):
    buf = io.BytesIO()
    pq.write_table(pa.table({"time": [1, 2], "station": ["ZHY", "ZHY"], "range_m": [1.0, 2.0]}), buf)
    raw = write("bad.parquet", buf.getvalue())
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2
    assert f"{raw}, row 1, column 'time': wrong column type; found 'int64'" in result.stderr
    buf = io.BytesIO()
    pq.write_table(pa.table({"time": [T0, T1, T2], "station": ["ZHY"] * 3, "range_m": [1.0, float("nan"), 2.0]}),
                   buf)
    raw = write("nan.parquet", buf.getvalue())
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2
    assert f"{raw}, row 2, column 'range_m': non-finite value" in result.stderr   # record index


def test_value_column_of_text_type_in_parquet(run_cli, write, stations_csv, tmp_path):
    buf = io.BytesIO()
    pq.write_table(pa.table({"time": [T0], "station": ["ZHY"], "range_m": [True]}), buf)
    raw = write("b.parquet", buf.getvalue())
    result = run_cli(["ingest", raw, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "column 'range_m': wrong column type; found 'bool'" in result.stderr


def test_missing_input_file(run_cli, tmp_path):
    missing = tmp_path / "nope.csv"
    result = run_cli(["ingest", missing, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and f"{missing}: file not found" in result.stderr


def test_corrupt_parquet(run_cli, write, tmp_path):
    raw = write("bad.parquet", b"PAR1 not really")
    result = run_cli(["ingest", raw, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and str(raw) in result.stderr and "Traceback" not in result.stderr


def test_not_utf8(run_cli, write, tmp_path):
    raw = write("bin.csv", b"time,station\n\x00\xff\xfe")
    result = run_cli(["ingest", raw, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and f"{raw}, row 2: not UTF-8 text" in result.stderr


def test_bad_options(run_cli, write, stations_csv, tmp_path):
    raw = write("in.csv", _csv(f"{T0},ZHY,1,,"))
    for args, word in ((["--max-gap", "0"], "--max-gap"), (["--sigma-range-m", "-1"], "--sigma-range-m"),
                       (["--mode", "three-way"], "--mode")):
        result = run_cli(["ingest", raw, "--stations", stations_csv, *args, "-o", tmp_path / "o.parquet"])
        assert result.exit_code == 2 and word in result.stderr, result.stderr


def test_conflicting_carrier_between_input_and_option(run_cli, write, stations_csv, tmp_path):
    raw = write("d.csv", "time,station,doppler_hz\n" + f"{T0},ZHY,-100\n")
    first = tmp_path / "d.parquet"
    assert run_cli(["ingest", raw, "--stations", stations_csv, "--carrier-hz", "2.2e9", "--mode", "one-way",
                    "-o", first]).exit_code == 0
    result = run_cli(["ingest", first, "--carrier-hz", "2.3e9", "-o", tmp_path / "e.parquet"])
    assert result.exit_code == 2 and "conflicting carrier_hz" in result.stderr and str(first) in result.stderr


def test_doptrack_errors(run_cli, write, tmp_path):
    data = write("dt/data/P.csv", "# time,frequency,rangerate\n1.0,145871000.0,0\n2.0,oops,0\n")
    result = run_cli(["ingest", data, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "needs its YAML sidecar" in result.stderr and "--sidecar" in result.stderr
    write("dt/metadata/P.yml", "satellite: {name: Unknown}\nstation: {name: S, position: "
                               "{latitude: 1, longitude: 2, altitude: 3}}\ntracking: {epoch: 2020-01-01 00:00:00}\n")
    result = run_cli(["ingest", data, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "--carrier-hz" in result.stderr
    result = run_cli(["ingest", data, "--carrier-hz", "145.87e6", "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and f"{data}, row 3, column 'frequency': wrong column type" in result.stderr
    write("dt/metadata/P.yml", "satellite: {name: Delfi-C3}\nstation: {name: S}\n")
    result = run_cli(["ingest", data, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "column 'tracking.epoch'" in result.stderr
    write("dt/metadata/P.yml", "satellite: [unclosed\n")
    result = run_cli(["ingest", data, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "invalid YAML" in result.stderr and "Traceback" not in result.stderr


def test_aer_errors(run_cli, write, stations_csv, tmp_path):
    aer = write("x.aer", "2010-11-02T03:00:13   RANGE   ZHY   38014.9\n"
                         "2010-11-02T03:00:14   RANGE_RATE   ZHY   1.0\n")
    result = run_cli(["ingest", aer, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and f"{aer}, row 2, column 'TYPE': unsupported measurement type" in result.stderr
    aer = write("y.aer", "2010-11-02T03:00:13   AZ_EL   ZHY   38014.9\n")
    result = run_cli(["ingest", aer, "--stations", stations_csv, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and "row 1" in result.stderr and "wrong number of values" in result.stderr


def test_info_on_a_non_pass_file(run_cli, write):
    """A raw CSV (before ingest) is a kind info knows: it says what it is and what to run on it; an
    empty stdin is refused."""
    raw = write("raw.csv", _csv(f"{T0},ZHY,1,,"))
    result = run_cli(["info", raw])
    assert result.exit_code == 0, result.stderr
    assert "trackproc ingest" in result.stdout
    assert run_cli(["info", "-"], input=b"").exit_code == 2


def test_stdin_twice_is_a_usage_error(run_cli):
    assert run_cli(["ingest", "-", "-", "-o", "x.parquet"]).exit_code == 2


# --------------------------------------------------------------------------- stations table


@pytest.mark.parametrize("text, row, column, words", [
    ("station,lat_deg,lon_deg,height_m\nA,95,0,0\n", 2, "lat_deg", ["[-90, 90]", "'95'"]),
    ("station,lat_deg,lon_deg,height_m\nA,0,0,0\nB,0,360,0\n", 3, "lon_deg", ["[-180, 360)"]),
    ("station,lat_deg,lon_deg,height_m\nA,0,0,nan\n", 2, "height_m", ["finite"]),
    ("station,lat_deg,lon_deg,height_m\nA,0,0,x\n", 2, "height_m", ["'x'"]),
    ("station,lat_deg,lon_deg,height_m\nA,0,0,0\nA,1,1,1\n", 3, "station", ["duplicate station", "row 2"]),
    ("station,lat_deg,height_m\nA,0,0\n", 1, "lon_deg", ["missing required column"]),
    ("station,lat_deg,lon_deg,height_m\n", 2, None, ["empty stations table"]),
    ("station,lat_deg,lon_deg,height_m,range_bias_m\nA,0,0,0,inf\n", 2, "range_bias_m", ["finite"]),
])
def test_stations_table_errors(text, row, column, words):
    with pytest.raises(InputError) as info:
        parse_stations(text.encode(), "st.csv")
    err = info.value
    assert (err.file, err.row, err.column) == ("st.csv", row, column)
    for word in words:
        assert word in str(err)


def test_stations_table_error_through_cli(run_cli, write, tmp_path):
    stations = write("st.csv", "# comment\nstation,lat_deg,lon_deg,height_m\nZHY,91,0,0\n")
    raw = write("in.csv", _csv(f"{T0},ZHY,1,,"))
    result = run_cli(["ingest", raw, "--stations", stations, "-o", tmp_path / "o.parquet"])
    assert result.exit_code == 2 and f"{stations}, row 3, column 'lat_deg'" in result.stderr


def test_stations_table_parses_bias_and_comments():
    stations = parse_stations(b"# WGS-84\nStation, lat_deg, lon_deg, height_m, range_bias_m\n"
                              b"A, 1.5, -70, 10,\nB, -2, 350, 0, 12.5\n", "st.csv")
    assert stations["A"].lat_deg == 1.5 and stations["A"].range_bias_m is None
    assert stations["B"].lon_deg == 350.0 and stations["B"].as_dict()["range_bias_m"] == 12.5
