"""A pass file stands for its TLE and its stations (issue 29): ``passes PASS``, ``--stations PASS``,
``metadata:PASS`` in ``propagate``, ``compare`` and ``refine``. Each is checked against the same
command given a TLE and a stations CSV written here from independent sources (the DopTrack YAML
read with PyYAML, sample_data/stations.csv), and the DopTrack pass's TCA against the upstream
team's measured TCA."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from realdata import DOPTRACK

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
#: A clean, high (88 deg) development pass.
DOPTRACK_PASS = "Delfi-C3_32789_202004022126"


def test_a_pass_file_as_stations_is_its_stations(run_cli):
    """``--stations PASS`` (Parquet) gives the schedule the stations CSV it was ingested with gives."""
    args = ["passes", SAMPLE / "iss.tle", "--span", "6h", "--format", "json", "-o", "-"]
    from_csv = json.loads(run_cli([*args, "--stations", SAMPLE / "stations.csv"]).stdout)["passes"]
    res = run_cli([*args, "--stations", SAMPLE / "multistation.parquet"])
    assert res.exit_code == 0, res.stderr
    from_pass = json.loads(res.stdout)["passes"]
    assert len(from_pass) == len(from_csv) >= 3
    assert from_pass == from_csv
    res = run_cli([*args, "--stations", f"metadata:{SAMPLE / 'multistation.parquet'}"])
    assert json.loads(res.stdout)["passes"] == from_csv


def test_a_pass_file_without_stations_or_tle_is_said_plainly(run_cli, tmp_path):
    from trackproc.io.passfile import read_pass_table, write_pass_table

    table = read_pass_table(str(SAMPLE / "multistation.parquet"))
    table.meta.pop("stations")
    bare = tmp_path / "bare.parquet"
    write_pass_table(table, str(bare))
    res = run_cli(["passes", SAMPLE / "iss.tle", "--stations", bare, "--span", "6h", "-o", "-"])
    assert res.exit_code == 2
    assert res.stderr.startswith(f"trackproc: error: {bare}, column 'stations': no stations in the pass file's metadata")
    assert "UTF-8" not in res.stderr and len(res.stderr.strip().splitlines()) == 1
    res = run_cli(["passes", SAMPLE / "multistation.parquet", "--span", "6h", "-o", "-"])
    assert res.exit_code == 2 and "no TLE in the pass file's metadata" in res.stderr
    res = run_cli(["passes", SAMPLE / "iss.tle", "--span", "6h", "-o", "-"])
    assert res.exit_code == 2 and "--stations" in res.stderr and "Traceback" not in res.stderr


@pytest.fixture(scope="module")
def doptrack(tmp_path_factory):
    """The DopTrack pass ingested, and its TLE and station written from the YAML read independently."""
    yaml = pytest.importorskip("yaml")
    raw = DOPTRACK / "data" / f"{DOPTRACK_PASS}.csv"
    if not raw.is_file():
        pytest.skip(f"real data not available: {DOPTRACK}")
    doc = yaml.safe_load((DOPTRACK / "metadata" / f"{DOPTRACK_PASS}.yml").read_text())
    where = tmp_path_factory.mktemp("doptrack")
    tle = where / "pass.tle"
    tle.write_text(doc["satellite"]["tle"]["line1"] + "\n" + doc["satellite"]["tle"]["line2"] + "\n")
    pos = doc["station"]["position"]
    stations = where / "st.csv"
    stations.write_text("station,lat_deg,lon_deg,height_m\n"
                        f"DopTrack,{pos['latitude']},{pos['longitude']},{pos['altitude']}\n")
    return {"raw": raw, "tle": tle, "stations": stations, "dir": where,
            "tca": np.datetime64(str(doc["tracking"]["tca"]).replace(" ", "T"), "ns")}


@pytest.mark.realdata
def test_passes_of_a_doptrack_pass_file_alone(run_cli, doptrack):
    """``passes PASS.parquet --span 2d``: station and TLE from the pass's metadata, the same table as
    the TLE and station of the YAML; the recorded pass is in it, its TCA 0.55 s from the measured
    one (the transmitter's drift moves the measured TCA by up to a second or two)."""
    pass_file = doptrack["dir"] / "pass.parquet"
    assert run_cli(["ingest", doptrack["raw"], "-o", pass_file]).exit_code == 0
    res = run_cli(["passes", pass_file, "--span", "2d", "--format", "json", "-o", "-"])
    assert res.exit_code == 0, res.stderr
    alone = json.loads(res.stdout)["passes"]
    by_hand = json.loads(run_cli(["passes", doptrack["tle"], "--stations", doptrack["stations"], "--span", "2d",
                                  "--format", "json", "-o", "-"]).stdout)["passes"]
    assert len(alone) == len(by_hand) >= 8
    for a, b in zip(alone, by_hand):
        assert a["station"] == b["station"] == "DopTrack"
        assert abs(pd.Timestamp(a["tca_time"]) - pd.Timestamp(b["tca_time"])).total_seconds() < 1e-3
    tca = pd.Series([pd.Timestamp(p["tca_time"]) for p in alone]).dt.tz_localize(None)
    gap = np.min(np.abs((tca.to_numpy(dtype="datetime64[ns]") - doptrack["tca"]) / np.timedelta64(1, "s")))
    assert gap < 3.0


@pytest.mark.realdata
def test_propagate_and_compare_with_metadata_of_a_doptrack_pass(run_cli, doptrack):
    """``propagate metadata:PASS --at-station`` needs no stations table and predicts what the YAML's
    TLE and station predict; ``compare PASS metadata:PASS`` equals ``compare PASS metadata``."""
    pass_file = doptrack["dir"] / "pass2.parquet"
    assert run_cli(["ingest", doptrack["raw"], "-o", pass_file]).exit_code == 0
    out1, out2 = doptrack["dir"] / "a.csv", doptrack["dir"] / "b.csv"
    common = ["--span", "2d", "--step", "60", "--at-station", "DopTrack", "--carrier-hz", "145.87e6", "--visible-only"]
    res = run_cli(["propagate", f"metadata:{pass_file}", *common, "-o", out1])
    assert res.exit_code == 0, res.stderr
    res = run_cli(["propagate", doptrack["tle"], *common, "--stations", doptrack["stations"], "-o", out2])
    assert res.exit_code == 0, res.stderr
    a, b = pd.read_csv(out1, comment="#"), pd.read_csv(out2, comment="#")
    assert len(a) == len(b) > 50
    np.testing.assert_allclose(a["doppler_hz"], b["doppler_hz"], atol=1e-6)
    one = run_cli(["compare", pass_file, "metadata"])
    two = run_cli(["compare", pass_file, f"metadata:{pass_file}"])
    assert one.exit_code == two.exit_code == 0, two.stderr
    rms = [json.loads(r.stderr[r.stderr.index("{"):r.stderr.rindex("}") + 1])["passes"][0]["rms"] for r in (one, two)]
    assert rms[0] == rms[1] < 20.0
