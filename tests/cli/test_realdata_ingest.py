"""Validation on real measurements in ../shared/realdata (skipped when that folder is absent).

DopTrack (TU Delft, Delfi-C3 one-way Doppler, 44 passes, April 2020) and the Eutelsat W3B
launch-phase angles and ranges from the Orekit test resources (5 stations).
"""

from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
import pandas as pd
import pytest

from trackproc.constants import C_LIGHT
from trackproc.io.passfile import read_pass_table, write_pass_table
from trackproc.io.tabular import read_raw
from trackproc.pipeline.ingest import ingest
from realdata import SHARED, DOPTRACK, W3B, requires, w3b_stations_csv


pytestmark = requires(SHARED)


@pytest.fixture(scope="module")
def doptrack_table(tmp_path_factory):
    """All DopTrack passes ingested in one run (stations from the YAML sidecars)."""
    files = sorted((DOPTRACK / "data").glob("*.csv"))
    out = tmp_path_factory.mktemp("doptrack") / "doptrack.parquet"
    result = ingest([read_raw(str(f)) for f in files])
    write_pass_table(result.table, str(out), "parquet")
    assert result.dropped == {}
    return files, read_pass_table(str(out)), out


def test_doptrack_every_file_is_one_pass(doptrack_table):
    files, table, _ = doptrack_table
    frame = table.frame
    assert len(files) == 44
    assert frame["pass_id"].nunique() == len(files)
    assert set(frame["pass_id"]) == {f.stem for f in files}
    assert set(frame["station"]) == {"DopTrack"} and set(frame["kind"]) == {"doppler"}
    for path in files:
        lines = [l for l in path.read_text().splitlines() if l.strip() and not l.startswith("#")]
        samples = frame[frame["pass_id"] == path.stem]
        assert len(samples) == len(lines)
        assert 200 <= len(samples) <= 1400
        duration = (samples["time"].max() - samples["time"].min()).total_seconds()
        assert 60 < duration < 20 * 60, path.name                     # minutes, a LEO pass


def test_doptrack_metadata_and_values(doptrack_table):
    files, table, _ = doptrack_table
    meta = table.meta
    assert meta["carrier_hz"] == 145.870e6 and meta["doppler_mode"] == "one-way"
    station = meta["stations"]["DopTrack"]
    assert station["lat_deg"] == pytest.approx(51.9989) and station["height_m"] == 95.0
    frame = table.frame
    assert frame["time"].min() >= pd.Timestamp("2020-04-01T00:00Z")
    assert frame["time"].max() < pd.Timestamp("2020-04-16T00:00Z")
    # Doppler of a 550 km LEO at 145.87 MHz is within about +-3.6 kHz, plus a ~1 kHz offset
    assert np.abs(frame["value"]).max() < 6e3
    assert (frame["sigma"] == 1.0).all()
    assert len(meta["doptrack"]) == len(files)


def test_doptrack_values_match_the_upstream_range_rate(doptrack_table):
    """Our Doppler (received - 145.87 MHz) reproduces the file's own rangerate = -c (f - fca)/fca."""
    files, table, _ = doptrack_table
    path = files[0]
    upstream = np.loadtxt(path, delimiter=",", comments="#")
    fca = table.meta["doptrack"][str(path)]["fca_hz"]
    doppler = table.frame[table.frame["pass_id"] == path.stem]["value"].to_numpy()
    received = doppler + table.meta["carrier_hz"]
    np.testing.assert_allclose(-C_LIGHT * (received - fca) / fca, upstream[:, 2], rtol=0, atol=1e-6)
    epoch = pd.Timestamp(table.meta["doptrack"][str(path)]["epoch"])
    first = table.frame[table.frame["pass_id"] == path.stem]["time"].iloc[0]
    assert (first - epoch).total_seconds() == pytest.approx(upstream[0, 0], abs=1e-9)


def test_doptrack_info_summary(doptrack_table, run_cli):
    _, _, out = doptrack_table
    result = run_cli(["info", out, "--json"])
    assert result.exit_code == 0
    info = json.loads(result.stdout)
    assert len(info["passes"]) == 44 and info["stations"][0]["name"] == "DopTrack"
    assert all(60 < p["duration_s"] < 1200 for p in info["passes"])


def test_w3b_aer_ingest_and_summary(run_cli, tmp_path):
    stations = w3b_stations_csv(tmp_path / "w3b_stations.csv")
    out = tmp_path / "w3b.parquet"
    result = run_cli(["ingest", W3B / "W3B.aer", "--stations", stations, "--sigma-range-m", "20",
                      "--sigma-angle-deg", "0.02", "-o", out])
    assert result.exit_code == 0, result.stderr
    table = read_pass_table(str(out))
    frame = table.frame
    expected = Counter()
    for line in (W3B / "W3B.aer").read_text().splitlines():
        fields = line.split()
        if fields and not fields[0].startswith("#"):
            for kind in ({"AZ_EL": ("azimuth", "elevation"), "RANGE": ("range",)}[fields[1]]):
                expected[(fields[2], kind)] += 1
    assert Counter(zip(frame["station"], frame["kind"])) == expected
    assert sorted(frame["station"].unique()) == ["CastleRock", "Fucino", "Kumsan", "Pretoria", "Uralla"]
    assert table.meta["stations"]["Fucino"]["range_bias_m"] == pytest.approx(13468.956)
    elevation = np.degrees(frame.query("kind == 'elevation'")["value"])
    assert elevation.min() > 0 and elevation.max() < 90
    azimuth = np.degrees(frame.query("kind == 'azimuth'")["value"])
    assert azimuth.min() >= 0 and azimuth.max() < 360
    ranges = frame.query("kind == 'range'")
    assert 5e6 < ranges["value"].min() and ranges["value"].max() < 4.1e7        # GTO, metres
    assert (ranges["sigma"] == 20.0).all()
    assert frame.query("kind == 'elevation'")["sigma"].iloc[0] == pytest.approx(math.radians(0.02))
    info = run_cli(["info", out, "--json"])
    summary = json.loads(info.stdout)
    assert len(summary["stations"]) == 5 and summary["samples"] == 860
    assert all(p["max_elevation_deg"] is None or 0 < p["max_elevation_deg"] < 90 for p in summary["passes"])
    assert summary["start"].startswith("2010-11-02T03:00:13") and summary["end"].startswith("2010-11-02T18:47")
