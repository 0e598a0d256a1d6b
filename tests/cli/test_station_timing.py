"""Station timing as a property of the station: the stations table's optional ``time_sigma_s``
column (checked like the other columns), used by ``refine`` as its time-tag consider parameter
unless ``--time-tag-sigma`` is given.

Independent reference for refine: the truth of the simulation (seed 004 Table 1 orbit, tests/report/
test_refine.py) over a pass whose time tags are 2 s late; with the station's stated 2 s the
refined state is within 2 sigma of the truth, as with ``--time-tag-sigma 2``
(tests/cli/test_refine_mismodel.py), and the consider term is the same.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from trackproc.errors import InputError
from trackproc.io.passfile import write_pass_table
from trackproc.io.stations import parse_stations
from trackproc.pipeline.refine import RefineOptions, refine
from trackproc.types import Station

from test_refine import EOP, EPOCH, STALE_RV, truth_at
from test_refine_mismodel import STALES, mismodelled


def _station_of(table) -> Station:
    (name, station), = table.stations().items()
    return station


def test_the_column_is_read_and_optional():
    data = (b"station,lat_deg,lon_deg,height_m,time_sigma_s\nA,40,116,50,0.5\nB,67.8,20.9,400,\n"
            b"C,10,10,0,0\n")
    st = parse_stations(data, "st.csv")
    assert st["A"].time_sigma_s == 0.5 and st["B"].time_sigma_s is None and st["C"].time_sigma_s == 0.0
    assert parse_stations(b"station,lat_deg,lon_deg,height_m\nA,40,116,50\n", "s.csv")["A"].time_sigma_s is None
    # round trip through the pass-file metadata (ingest writes it, refine and estimate read it back)
    assert Station.from_meta("A", st["A"].as_dict(), "m") == st["A"]
    assert "time_sigma_s" not in st["B"].as_dict()


@pytest.mark.parametrize("cell", ["-0.1", "nan", "inf", "soon"])
def test_a_bad_time_sigma_is_named(cell):
    data = f"station,lat_deg,lon_deg,height_m,time_sigma_s\nA,40,116,50,0.5\nB,67.8,20.9,400,{cell}\n".encode()
    with pytest.raises(InputError) as err:
        parse_stations(data, "st.csv")
    text = str(err.value)
    assert "\n" not in text and "st.csv" in text and "row 3" in text and "time_sigma_s" in text, text
    assert cell in text and ">= 0" in text


def test_bad_metadata_time_sigma_is_named():
    with pytest.raises(InputError) as err:
        Station.from_meta("A", {"lat_deg": 1.0, "lon_deg": 2.0, "height_m": 3.0, "time_sigma_s": -1}, "p.parquet")
    assert "stations.A.time_sigma_s" in str(err.value)


def test_refine_uses_the_station_time_sigma_and_the_option_wins():
    """Time tags 2 s late (37 sigma off without a consider term): the station's 2 s covers it as
    ``--time-tag-sigma 2`` does; ``--time-tag-sigma 0`` given explicitly turns it off."""
    table, _ = mismodelled("S55", "timetag2.0")
    station = replace(_station_of(table), time_sigma_s=2.0)
    stations = {station.name: station}
    res = refine(table, STALES["cov"], stations, RefineOptions(), EOP)
    z = (res.state.values[:6] - truth_at(res.state.epoch)) / res.state.sigma[:6]
    assert np.all(np.abs(z) < 2.0), z
    consider = res.state.diagnostics["time_tag_consider"]
    assert consider["source"] == "station table" and consider["sigma_s"] == 2.0
    given = refine(table, STALES["cov"], None, RefineOptions(time_tag_sigma_s=2.0), EOP)
    assert given.state.diagnostics["time_tag_consider"]["source"] == "--time-tag-sigma"
    np.testing.assert_allclose(consider["position_sigma_m"],
                               given.state.diagnostics["time_tag_consider"]["position_sigma_m"], rtol=1e-6)
    off = refine(table, STALES["cov"], stations, RefineOptions(time_tag_sigma_s=0.0), EOP)
    assert "time_tag_consider" not in off.state.diagnostics
    z_off = (off.state.values[:6] - truth_at(off.state.epoch)) / off.state.sigma[:6]
    assert np.max(np.abs(z_off)) > 4.0, z_off                   # the offset the consider term covers


def test_cli_refine_reads_time_sigma_from_the_stations_table(run_cli, tmp_path):
    table, _ = mismodelled("S55", "timetag2.0")
    st = _station_of(table)
    write_pass_table(table, str(tmp_path / "pass.parquet"))
    (tmp_path / "st.csv").write_text(f"station,lat_deg,lon_deg,height_m,time_sigma_s\n"
                                     f"{st.name},{st.lat_deg!r},{st.lon_deg!r},{st.height_m!r},2\n")
    (tmp_path / "stale.json").write_text(json.dumps({
        "epoch": EPOCH, "frame": "GCRF", "position_m": STALE_RV[:3].tolist(), "velocity_m_s": STALE_RV[3:].tolist(),
        "covariance": np.diag([1e8, 1e8, 1e8, 25.0, 25.0, 25.0]).tolist()}))
    out = tmp_path / "refined.json"
    args = ["refine", tmp_path / "pass.parquet", "--initial", tmp_path / "stale.json", "--dut1", "0",
            "--stations", tmp_path / "st.csv", "-o", out]
    r = run_cli(args)
    assert r.exit_code == 0, r.stderr
    doc = json.loads(out.read_text())
    assert doc["diagnostics"]["time_tag_consider"]["source"] == "station table"
    r = run_cli(args + ["--time-tag-sigma", "1"])
    assert r.exit_code == 0, r.stderr
    consider = json.loads(out.read_text())["diagnostics"]["time_tag_consider"]
    assert consider["sigma_s"] == 1.0 and consider["source"] == "--time-tag-sigma"
    (tmp_path / "bad.csv").write_text(f"station,lat_deg,lon_deg,height_m,time_sigma_s\n"
                                      f"{st.name},{st.lat_deg!r},{st.lon_deg!r},{st.height_m!r},-2\n")
    r = run_cli(args[:-4] + ["--stations", tmp_path / "bad.csv", "-o", out])
    assert r.exit_code == 2 and "bad.csv" in r.stderr and "time_sigma_s" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_cli_estimate_station_time_bias(run_cli, tmp_path):
    """``estimate --station-time-bias-station KIR`` on a day of 3 stations whose KIR tags are 0.5 s
    late (tests/pipeline/test_station_time_bias.py): the state file carries ``time_bias:KIR`` within
    3 sigma of 0.5 s; ``--station-time-bias`` for every station without an a-priori is a one-line
    input error (exit 2); with the stations table's ``time_sigma_s`` it runs."""
    from test_estimate import GUESS, STATIONS
    from test_station_time_bias import _day, _late

    table = _late(_day(), "KIR", 0.5)
    write_pass_table(table, str(tmp_path / "day.parquet"))
    (tmp_path / "guess.json").write_text(json.dumps({
        "epoch": "2026-03-20T09:30:00Z", "frame": "GCRF", "position_m": GUESS.r_m.tolist(),
        "velocity_m_s": GUESS.v_m_s.tolist()}))
    out = tmp_path / "est.json"
    base = ["estimate", tmp_path / "day.parquet", "--initial", tmp_path / "guess.json", "--dut1", "0.1", "-o", out]
    r = run_cli(base + ["--station-time-bias-station", "KIR"])
    assert r.exit_code == 0, r.stderr
    doc = json.loads(out.read_text())
    i = doc["parameters"].index("time_bias:KIR")
    assert abs(doc["values"][i] - 0.5) < 3 * doc["sigma"][i] and doc["sigma"][i] < 0.01, (doc["values"][i], doc["sigma"][i])
    out.unlink()
    r = run_cli(base + ["--station-time-bias"])
    assert r.exit_code == 2 and "common to every station" in r.stderr and not out.exists()
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    rows = "".join(f"{k},{v.lat_deg},{v.lon_deg},{v.height_m},1.0\n" for k, v in STATIONS.items())
    (tmp_path / "st.csv").write_text("station,lat_deg,lon_deg,height_m,time_sigma_s\n" + rows)
    r = run_cli(base + ["--station-time-bias", "--stations", tmp_path / "st.csv"])
    assert r.exit_code == 0, r.stderr
    assert [p for p in json.loads(out.read_text())["parameters"] if p.startswith("time_bias:")] == [
        "time_bias:KIR", "time_bias:MAD", "time_bias:ZHY"]
