"""Hostile class: times the nanosecond representation cannot hold (years before 1678 or after 2261)
are input errors naming the file, row and field, never a silent wrap (2300 -> 1715) or a crash."""

from __future__ import annotations

import datetime as dt
import subprocess
import sys

import pytest

from hostile import STATIONS, TDM_DIR, assert_rejected, state_doc

TDM = (TDM_DIR / "oneway_doppler.tdm").read_text()


@pytest.mark.parametrize("year", ["2300", "2262", "1600", "1677", "9999"])
def test_state_epoch_outside_the_span(run_cli, write, tmp_path, year):
    state = write("s.json", state_doc(epoch=f"{year}-03-20T09:30:00Z"))
    out = tmp_path / "o.parquet"
    result = run_cli(["propagate", state, "--span", "600", "--step", "60", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "s.json", "epoch", year, outputs=[out])


@pytest.mark.parametrize("year", ["2300", "1500"])
def test_tdm_epoch_outside_the_span(run_cli, write, tmp_path, year):
    tdm = write("t.tdm", TDM.replace("2005-159T17:41:01 -371.1568", f"{year}-159T17:41:01 -371.1568"))
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", tdm, "--stations", STATIONS, "-q", "-o", out])
    line = assert_rejected(result, 2, "t.tdm", "RECEIVE_FREQ_1", year, outputs=[out])
    assert "row" in line


@pytest.mark.parametrize("stamp", ["2300-01-01T00:00:00Z", "1600-01-01T00:00:00Z", "3000-12-31T23:59:59.5Z",
                                   "+12026-01-01T00:00:00Z"])
def test_csv_time_outside_the_span(run_cli, write, tmp_path, stamp):
    raw = write("r.csv", f"time,station,range_m\n2026-03-20T09:30:00Z,CPH,1000000\n{stamp},CPH,1000000\n")
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", raw, "--stations", STATIONS, "-q", "-o", out])
    assert_rejected(result, 2, "r.csv", "row 3", "time", outputs=[out])


@pytest.mark.parametrize("unit", ["s", "ms", "us"])
def test_parquet_timestamps_in_year_3000(run_cli, tmp_path, unit):
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "y3000.parquet"
    times = [dt.datetime(2026, 3, 20, 9, 30), dt.datetime(3000, 1, 1)]
    pq.write_table(pa.table({"time": pa.array(times, pa.timestamp(unit, tz="UTC")), "station": ["CPH", "CPH"],
                             "range_m": [1.0e6, 1.0e6]}), path)
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", path, "--stations", STATIONS, "-q", "-o", out])
    assert_rejected(result, 2, "y3000.parquet", "row 2", "time", outputs=[out])


def test_parquet_year_3000_never_aborts(tmp_path):
    """The script itself (not in-process): an input error must exit 2 every time, never 134."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "y3000.parquet"
    pq.write_table(pa.table({"time": pa.array([dt.datetime(3000, 1, 1)], pa.timestamp("us", tz="UTC")),
                             "station": ["CPH"], "range_m": [1.0e6]}), path)
    codes = set()
    for _ in range(12):
        run = subprocess.run([sys.executable, "-c", "import sys; from trackproc.cli.app import main; sys.exit(main())",
                              "ingest", str(path), "--stations", str(STATIONS), "-q", "-o", str(tmp_path / "o.parquet")],
                             capture_output=True, text=True)
        codes.add(run.returncode)
        assert "Traceback" not in run.stderr and "terminate" not in run.stderr
    assert codes == {2}


def test_sidecar_free_simulate_start_in_2300(run_cli, tmp_path):
    from hostile import TRUTH

    out = tmp_path / "o.parquet"
    result = run_cli(["simulate", "--state", TRUTH, "--stations", STATIONS, "--start", "2300-01-01T00:00:00Z",
                      "--duration", "600", "--step", "10", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "--start", "2300", outputs=[out])


def test_nominal_impact_time_in_2300(run_cli, write, tmp_path):
    nominal = write("n.json", '{"impact_time": "2300-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 48}')
    from hostile import MULTI

    result = run_cli(["detect", MULTI, "--nominal", nominal, "-q"])
    assert_rejected(result, 2, "n.json", "impact_time", "2300")
