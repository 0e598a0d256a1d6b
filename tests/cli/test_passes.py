"""``trackproc passes`` (issue 18 item 5) against independent brute-force scans: a TLE's passes
against 1-s elevations from the ``sgp4`` package + ERFA directly (tests/tle_reference.py, no
trackproc code), and the shipped sample state's passes against ``trackproc propagate
--at-station`` at 1-s steps (the image-domain spectra, another path than the foundation model
``passes`` uses)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tle_reference import ISS, sgp4_gcrf, station_view
from trackproc.io.ephemeris import read_ephemeris

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
C = 299792458.0
START = np.datetime64("2019-12-10T00:00:00", "ns")


def _crossings(t_s, el, mask):
    """Brute force: linear interpolation of the mask crossings of a fine elevation series, and the
    maximum elevation of each pass (complete passes only)."""
    up = el >= mask
    rises = np.flatnonzero(~up[:-1] & up[1:])
    sets = np.flatnonzero(up[:-1] & ~up[1:])
    passes = []
    for i in rises:
        later = sets[sets >= i]
        if not len(later):
            continue
        j = later[0]
        aos = t_s[i] + (mask - el[i]) / (el[i + 1] - el[i]) * (t_s[i + 1] - t_s[i])
        los = t_s[j] + (mask - el[j]) / (el[j + 1] - el[j]) * (t_s[j + 1] - t_s[j])
        passes.append((aos, los, el[i:j + 2].max()))
    return passes


def _seconds(values, start=START) -> np.ndarray:
    t = pd.to_datetime(pd.Series(values), utc=True).dt.tz_localize(None).to_numpy(dtype="datetime64[ns]")
    return (t - start) / np.timedelta64(1, "s")


@pytest.mark.slow   # a minute-by-minute SGP4 scan of a day: seconds
def test_tle_passes_match_a_brute_force_sgp4_erfa_scan(run_cli, write, tmp_path):
    tle = write("iss.tle", ISS)
    stations = write("st.csv", "station,lat_deg,lon_deg,height_m\nZHY,50.25,28.66,230\nCPH,55.7,12.55,30\n")
    out = tmp_path / "passes.csv"
    res = run_cli(["passes", tle, "--stations", stations, "--start", "2019-12-10T00:00:00Z", "--span", "1d",
                   "--min-elevation", "5", "--carrier-hz", "145.8e6", "--dut1", "-0.2", "-o", out])
    assert res.exit_code == 0, res.stderr
    table = pd.read_csv(out)
    t_s = np.arange(0.0, 86400.0 + 0.5, 1.0)
    times = START + (t_s * 1e9).astype("timedelta64[ns]")
    r, v = sgp4_gcrf(ISS, times, dut1=-0.2)
    checked = 0
    for name, lat, lon, h in (("ZHY", 50.25, 28.66, 230.0), ("CPH", 55.7, 12.55, 30.0)):
        el, az, rr = station_view(r, v, times, lat, lon, h, dut1=-0.2)
        ref = _crossings(t_s, el, 5.0)
        mine = table[(table["station"] == name) & table["complete"]]
        assert len(mine) == len(ref) >= 2, (name, len(mine), len(ref))
        aos, los = _seconds(mine["aos_time"]), _seconds(mine["los_time"])
        for k, (a_ref, l_ref, max_ref) in enumerate(ref):
            # light time (~5 ms) moves the elevation by ~1e-3 deg: a few hundredths of a second at the mask
            assert abs(aos[k] - a_ref) < 0.2 and abs(los[k] - l_ref) < 0.2, (name, k, aos[k] - a_ref, los[k] - l_ref)
            assert mine["max_elevation_deg"].iloc[k] >= max_ref - 1e-3
            assert mine["max_elevation_deg"].iloc[k] - max_ref < 0.02    # the 1-s scan's top is a lower bound
            i = int(round(aos[k]))
            assert abs(mine["aos_azimuth_deg"].iloc[k] - az[i]) < 0.5            # az changes ~0.2 deg/s at AOS
            assert abs(mine["aos_doppler_hz"].iloc[k] + 145.8e6 * rr[i] / C) < 300.0   # Doppler rate < 100 Hz/s
            tca = _seconds(mine["tca_time"].iloc[[k]])[0]
            i_tca = int(np.argmin(np.abs(rr[int(a_ref):int(l_ref)]))) + int(a_ref)
            assert abs(tca - i_tca) < 1.0
            checked += 1
    assert checked >= 4


@pytest.fixture(scope="module")
def sample_passes(run_cli_shared, tmp_path_factory) -> dict:
    """The sample state's passes over the three stations, 12 h: one run that each station's test reads."""
    out = tmp_path_factory.mktemp("passes") / "passes.json"
    res = run_cli_shared(["passes", SAMPLE / "truth.json", "--stations", SAMPLE / "stations.csv", "--span", "43200",
                          "--min-elevation", "10", "--dut1", "0", "-o", out])
    assert res.exit_code == 0, res.stderr
    return json.loads(out.read_text())


@pytest.mark.parametrize("station", ["CPH", "ZHY", "KIR"])
def test_sample_state_passes_match_propagate_at_station(run_cli, tmp_path, station, sample_passes):
    doc = sample_passes
    assert doc["meta"]["force_model"] == "j2" and doc["meta"]["min_elevation_deg"] == 10
    eph_path = tmp_path / "eph.parquet"
    res = run_cli(["propagate", SAMPLE / "truth.json", "--span", "43200", "--step", "1", "--at-station", station,
                   "--stations", SAMPLE / "stations.csv", "--dut1", "0", "-o", eph_path])
    assert res.exit_code == 0, res.stderr
    frame = read_ephemeris(str(eph_path)).frame
    start = np.datetime64("2026-03-20T09:30:00", "ns")
    t_s = _seconds(frame["time"], start)
    ref = _crossings(t_s, frame["elevation_deg"].to_numpy(), 10.0)
    mine = [p for p in doc["passes"] if p["station"] == station and p["complete"]]
    assert len(mine) == len(ref) >= 2
    for p, (a_ref, l_ref, max_ref) in zip(mine, ref):
        assert abs(_seconds([p["aos_time"]], start)[0] - a_ref) < 0.05
        assert abs(_seconds([p["los_time"]], start)[0] - l_ref) < 0.05
        assert -1e-6 < p["max_elevation_deg"] - max_ref < 0.02


def test_markdown_and_bad_input(run_cli, tmp_path):
    res = run_cli(["passes", SAMPLE / "truth.json", "--stations", SAMPLE / "stations.csv", "--span", "6h",
                   "--carrier-hz", "2.2e9", "--format", "md", "-o", "-", "--dut1", "0"])
    assert res.exit_code == 0, res.stderr
    assert res.stdout.splitlines()[2].startswith("| station | AOS (UTC)") and "Doppler" in res.stdout
    for args, needle in ((["--span", "2x"], "--span"), (["--span", "0"], "--span"),
                         (["--span", "1d", "--step", "0"], "--step"),
                         (["--span", "1d", "--force", "sgp4"], "SGP4 needs a TLE")):
        res = run_cli(["passes", SAMPLE / "truth.json", "--stations", SAMPLE / "stations.csv", *args, "-o",
                       tmp_path / "p.csv"])
        assert res.exit_code == 2 and needle in res.stderr and "Traceback" not in res.stderr, res.stderr
        assert len(res.stderr.strip().splitlines()) <= 2
    assert not (tmp_path / "p.csv").exists()


def test_docstring_examples_on_the_shipped_tle(run_cli, tmp_path):
    """The examples of ``passes --help`` and ``propagate --help`` on sample_data/iss.tle run."""
    out = tmp_path / "passes.csv"
    res = run_cli(["passes", SAMPLE / "iss.tle", "--stations", SAMPLE / "stations.csv", "--span", "2d",
                   "--carrier-hz", "145.87e6", "-o", out])
    assert res.exit_code == 0, res.stderr
    table = pd.read_csv(out)
    assert len(table) >= 6 and set(table["station"]) == {"CPH", "ZHY", "KIR"}
    # a 145.87 MHz LEO pass: |Doppler| at the horizon ~3.3 kHz, ~0 at closest approach
    assert table["aos_doppler_hz"].max() < 4e3 and table["aos_doppler_hz"].min() > 0
    assert table["tca_doppler_hz"].abs().max() < 1.0
    res = run_cli(["propagate", SAMPLE / "iss.tle", "--span", "86400", "--step", "10", "--at-station", "CPH",
                   "--stations", SAMPLE / "stations.csv", "--carrier-hz", "145.87e6", "--visible-only", "-o",
                   tmp_path / "predicted.csv"])
    assert res.exit_code == 0, res.stderr


@pytest.mark.realdata
def test_tca_of_doptrack_development_passes_against_the_measured_tca(run_cli, write, tmp_path):
    """Real data, development set (1-10 April): the TCA ``passes`` predicts from each pass's own
    metadata TLE (SGP4) against the upstream team's TCA measured from the recorded Doppler
    (``tracking.tca``, an independent reference). Measured on the 25 development passes: median
    0.67 s apart; all but two within 3 s (202004011959 is the README's known bad pass, 103 s;
    202004032256, a 13-degree pass, 12 s)."""
    import yaml

    from realdata import DOPTRACK

    files = sorted((DOPTRACK / "metadata").glob("Delfi-C3_32789_2020040*.yml")) + \
        sorted((DOPTRACK / "metadata").glob("Delfi-C3_32789_2020041[0]*.yml"))
    if not files:
        pytest.skip(f"real data not available: {DOPTRACK}")
    stations = write("st.csv", "station,lat_deg,lon_deg,height_m\nDopTrack,51.9989,4.3733585,95\n")
    diffs = []
    for path in files:
        doc = yaml.safe_load(path.read_text())
        tle = write("t.tle", doc["satellite"]["tle"]["line1"] + "\n" + doc["satellite"]["tle"]["line2"] + "\n")
        tca = np.datetime64(str(doc["tracking"]["tca"]).replace(" ", "T"), "ns")
        start = np.datetime_as_string(tca - np.timedelta64(15, "m"), "s") + "Z"
        out = tmp_path / "p.csv"
        res = run_cli(["passes", tle, "--stations", stations, "--start", start, "--span", "30m", "--dut1", "0",
                       "-o", out])
        assert res.exit_code == 0, res.stderr
        table = pd.read_csv(out)
        assert len(table) == 1, path.name
        diffs.append(_seconds(table["tca_time"], tca)[0])
    diffs = np.abs(diffs)
    assert len(diffs) >= 20
    assert np.median(diffs) < 1.5
    assert np.mean(diffs < 3.0) >= 0.85


def test_markdown_times_keep_hundredths_of_the_json(run_cli):
    """The Markdown table's AOS/TCA/LOS are the JSON's times rounded to 0.01 s (not cut to the second)."""
    args = ["passes", SAMPLE / "iss.tle", "--stations", SAMPLE / "stations.csv", "--span", "6h", "-o", "-"]
    doc = json.loads(run_cli([*args, "--format", "json"]).stdout)
    rows = [line.split("|")[1:-1] for line in run_cli([*args, "--format", "md"]).stdout.splitlines()
            if line.startswith("| ") and not line.startswith("| station")]
    assert len(rows) == len(doc["passes"]) >= 2
    for p, row in zip(doc["passes"], rows):
        for key, cell in (("aos_time", 1), ("tca_time", 3), ("los_time", 6)):
            shown = pd.Timestamp(row[cell].strip(), tz="UTC")
            assert abs((shown - pd.Timestamp(p[key])).total_seconds()) <= 0.005 + 1e-9
