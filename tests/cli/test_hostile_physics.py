"""Hostile class: physically impossible inputs (issue 14 item 3, issue 13 item 5) are input errors
naming the file, row and field; real passes still go through."""

from __future__ import annotations

import json

import pytest

from hostile import DOPPLER_CSV, MULTI, STATIONS, TDM_DIR, TRUTH, assert_rejected, state_doc

ST = "station,lat_deg,lon_deg,height_m\nCPH,55.7,12.55,30\n"


def _ingest(run_cli, tmp_path, raw, *extra):
    out = tmp_path / "o.parquet"
    return run_cli(["ingest", raw, "--stations", tmp_path / "st.csv", "-q", "-o", out, *extra]), out


@pytest.fixture
def st(write):
    return write("st.csv", ST)


@pytest.mark.parametrize("header, value, needles", [
    ("range_m", "-5", ["range_m", "negative range"]),
    ("range_km", "-0.001", ["range_km", "negative range"]),
    ("azimuth_deg", "720", ["azimuth_deg", "azimuth"]),
    ("azimuth_deg", "-200", ["azimuth_deg", "azimuth"]),
    ("elevation_deg", "97.2", ["elevation_deg", "elevation"]),
    ("range_rate_m_s", "20000", ["range_rate_m_s", "range-rate"]),
    ("range_rate_m_s", "-13000", ["range_rate_m_s", "range-rate"]),
    ("range_m", "nan", ["range_m"]),
    ("range_m", "inf", ["range_m"]),
])
def test_impossible_sample(run_cli, write, tmp_path, st, header, value, needles):
    raw = write("r.csv", f"time,station,{header}\n2026-03-20T09:30:00Z,CPH,1\n2026-03-20T09:30:01Z,CPH,{value}\n")
    result, out = _ingest(run_cli, tmp_path, raw)
    assert_rejected(result, 2, "r.csv", "row 3", *needles, outputs=[out])


@pytest.mark.parametrize("row, needle", [
    ("CPH,55.7,12.55,-7000000", "height_m"),
    ("CPH,55.7,12.55,7000000", "height_m"),
    ("CPH,95,12.55,30", "lat_deg"),
    ("CPH,55.7,400,30", "lon_deg"),
    ("CPH,nan,12.55,30", "lat_deg"),
    ("CPH,55.7,12.55,", "height_m"),
])
def test_impossible_station(run_cli, write, tmp_path, row, needle):
    stations = write("bad_st.csv", "station,lat_deg,lon_deg,height_m\n" + row + "\n")
    raw = write("r.csv", "time,station,range_m\n2026-03-20T09:30:00Z,CPH,1000000\n")
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", raw, "--stations", stations, "-q", "-o", out])
    assert_rejected(result, 2, "bad_st.csv", "row 2", needle, outputs=[out])


@pytest.mark.parametrize("change, needle", [
    ({"velocity_m_s": [-4.8166, 3.9364, 4.0911]}, "velocity_m_s"),            # km/s given as m/s
    ({"position_m": [3774.841, -1538.034, 5924.146]}, "position_m"),          # km given as m
    ({"position_m": [3774841.0, -1538034.0, 3924146.0]}, "position_m"),       # below the surface
    ({"velocity_m_s": [-48166.0, 39364.0, 40911.0]}, "velocity_m_s"),         # hyperbolic
    ({"position_m": [3.7e12, 0.0, 0.0]}, "position_m"),                       # interplanetary
    ({"position_m": [3774841.0, "x", 5924146.0]}, "position_m"),
    ({"velocity_m_s": [1.0, 2.0]}, "velocity_m_s"),
    ({"epoch": 20260320}, "epoch"),
    ({"frame": ["GCRF"]}, "frame"),
])
def test_impossible_state(run_cli, write, tmp_path, change, needle):
    state = write("s.json", state_doc(**change))
    out = tmp_path / "o.parquet"
    result = run_cli(["propagate", state, "--span", "600", "--step", "60", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "s.json", needle, outputs=[out])


def test_state_in_km_s_rejected_by_simulate_and_estimate(run_cli, write, tmp_path):
    state = write("s.json", state_doc(velocity_m_s=[-4.8166, 3.9364, 4.0911]))
    for args in (["simulate", "--state", state, "--stations", STATIONS, "--duration", "600", "--step", "10"],
                 ["estimate", MULTI, "--initial", state]):
        out = tmp_path / "o.parquet"
        result = run_cli([*args, "--dut1", "0", "-q", "-o", out])
        assert_rejected(result, 2, "s.json", "velocity_m_s", outputs=[out])


@pytest.mark.parametrize("carrier", ["2.2", "2200", "0.5e6", "5e12", "nan", "-2.2e9"])
def test_carrier_in_the_wrong_unit_ingest(run_cli, tmp_path, st, carrier):
    result, out = _ingest(run_cli, tmp_path, DOPPLER_CSV, "--carrier-hz", carrier, "--mode", "one-way")
    assert_rejected(result, 2, "--carrier-hz", outputs=[out])


@pytest.mark.parametrize("command", ["simulate", "propagate"])
def test_carrier_in_the_wrong_unit_other_commands(run_cli, tmp_path, command):
    args = (["simulate", "--state", TRUTH, "--stations", STATIONS, "--duration", "600", "--step", "10"]
            if command == "simulate" else
            ["propagate", TRUTH, "--span", "600", "--step", "60", "--at-station", "CPH", "--stations", STATIONS])
    out = tmp_path / "o.parquet"
    result = run_cli([*args, "--carrier-hz", "2.2", "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "--carrier-hz", "2.2", outputs=[out])


def _pass_with_meta(tmp_path, **meta_changes):
    """The sample Doppler pass ingested, its metadata then edited as a hostile user would."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from trackproc.pipeline.ingest import IngestOptions, ingest
    from trackproc.io.stations import read_stations
    from trackproc.io.tabular import read_raw

    raw = read_raw(str(DOPPLER_CSV))
    result = ingest([raw], read_stations(str(STATIONS)), IngestOptions(carrier_hz=2.2e9, doppler_mode="one-way"))
    meta = dict(result.table.meta)
    for key, value in meta_changes.items():
        if value is KeyError:
            meta.pop(key, None)
        else:
            meta[key] = value
    table = pa.Table.from_pandas(result.table.frame, preserve_index=False)
    table = table.replace_schema_metadata({"trackproc": json.dumps(meta)})
    path = tmp_path / "edited.parquet"
    pq.write_table(table, path)
    return path


@pytest.mark.parametrize("changes, needle", [
    ({"carrier_hz": 2.2}, "carrier"),
    ({"carrier_hz": "abc"}, "carrier_hz"),
    ({"carrier_hz": [2.2e9]}, "carrier_hz"),
    ({"doppler_mode": "three-way"}, "doppler_mode"),
    ({"stations": {"CPH": {"lon_deg": 12.55, "height_m": 30.0}}}, "lat_deg"),
    ({"stations": {"CPH": {"lat_deg": "north", "lon_deg": 12.55, "height_m": 30.0}}}, "lat_deg"),
    ({"stations": {"CPH": {"lat_deg": 55.7, "lon_deg": 12.55, "height_m": -7.0e6}}}, "height_m"),
    ({"stations": {"CPH\nFORGED": {"lat_deg": 55.7, "lon_deg": 12.55, "height_m": 30.0}}}, "control"),
    ({"stations": [1, 2, 3]}, "stations"),
])
@pytest.mark.parametrize("command", ["smooth", "refine", "info"])
def test_hostile_pass_metadata(run_cli, tmp_path, changes, needle, command):
    path = _pass_with_meta(tmp_path, **changes)
    out = tmp_path / "o.parquet"
    args = {"smooth": ["smooth", path, "-o", out], "info": ["info", path],
            "refine": ["refine", path, "--initial", TRUTH, "--dut1", "0", "-o", out]}[command]
    result = run_cli([*args, "-q"])
    assert_rejected(result, 2, "edited.parquet", needle, outputs=[out])


def test_nan_in_a_pass_file_names_the_row(run_cli, write, tmp_path):
    pass_csv = write("p.csv", "time,station,pass_id,kind,value,sigma\n"
                              "2026-03-20T09:30:00Z,CPH,CPH-001,range,1000000,10\n"
                              "2026-03-20T09:30:01Z,CPH,CPH-001,range,nan,10\n")
    result = run_cli(["smooth", pass_csv, "-q", "-o", tmp_path / "o.parquet"])
    assert_rejected(result, 2, "p.csv", "row 3", "value")


def test_zero_sigma_in_a_pass_file_names_the_row(run_cli, write, tmp_path):
    pass_csv = write("p.csv", "time,station,pass_id,kind,value,sigma\n"
                              "2026-03-20T09:30:00Z,CPH,CPH-001,range,1000000,0\n")
    result = run_cli(["info", pass_csv, "-q"])
    assert_rejected(result, 2, "p.csv", "row 2", "sigma")


@pytest.mark.parametrize("typo, needle", [("RANGEE", "RANGE"), ("RECEIVE_FREQ1", "RECEIVE_FREQ_1"),
                                          ("DOPPLER_INSTANTANEUS", "DOPPLER_INSTANTANEOUS"),
                                          ("ANGLE_l", "ANGLE_")])
def test_tdm_keyword_typo_is_not_dropped_silently(run_cli, write, tmp_path, typo, needle):
    text = (TDM_DIR / "oneway_doppler.tdm").read_text()
    text = text.replace("RECEIVE_FREQ_1 = 2005-159T17:41:01", f"{typo} = 2005-159T17:41:01", 1)
    tdm = write("t.tdm", text)
    out = tmp_path / "o.parquet"
    result = run_cli(["ingest", tdm, "--stations", STATIONS, "-q", "-o", out])
    assert_rejected(result, 2, "t.tdm", typo.upper(), needle, outputs=[out])


def test_tdm_metadata_keyword_typo(run_cli, write, tmp_path):
    text = (TDM_DIR / "oneway_doppler.tdm").read_text().replace("INTEGRATION_REF = START", "INTEGRATION_REFF = START", 1)
    result = run_cli(["ingest", write("t.tdm", text), "--stations", STATIONS, "-q", "-o", tmp_path / "o.parquet"])
    assert_rejected(result, 2, "t.tdm", "INTEGRATION_REFF", "INTEGRATION_REF")


def test_estimate_same_file_twice(run_cli, tmp_path):
    out = tmp_path / "o.json"
    result = run_cli(["estimate", MULTI, MULTI, "--initial", TRUTH, "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "multistation.parquet", "twice", outputs=[out])


def test_estimate_same_samples_in_a_copy(run_cli, tmp_path):
    copy = tmp_path / "copy.parquet"
    copy.write_bytes(MULTI.read_bytes())
    out = tmp_path / "o.json"
    result = run_cli(["estimate", MULTI, copy, "--initial", TRUTH, "--dut1", "0", "-q", "-o", out])
    assert_rejected(result, 2, "copy.parquet", "two inputs", outputs=[out])


def test_ingest_same_file_twice(run_cli, tmp_path, st):
    result, out = _ingest(run_cli, tmp_path, DOPPLER_CSV, DOPPLER_CSV, "--carrier-hz", "2.2e9", "--mode", "one-way")
    assert_rejected(result, 2, "doppler_pass.csv", "duplicate", outputs=[out])


def test_plausible_doppler_and_state_still_accepted(run_cli, tmp_path, st):
    """The limits must not reject a real pass: the sample one-way Doppler at 2.2 GHz goes through."""
    result, out = _ingest(run_cli, tmp_path, DOPPLER_CSV, "--carrier-hz", "2.2e9", "--mode", "one-way")
    assert result.exit_code == 0, result.stderr
    assert out.exists()
