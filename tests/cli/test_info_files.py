"""``trackproc info`` on every file kind trackproc reads or writes (issue 16): state JSON, TLE,
CCSDS OPM, OEM and TDM beside pass files and ephemerides; each summary checked against the file's
own content computed independently (numpy norms, the TLE's columns, the OEM's span/step, the TDM
samples that ingest reads)."""

import json
from pathlib import Path

import numpy as np
import pytest

from trackproc.cli.app import main

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_data"


def _info(args, capsys):
    assert main(["-q", "info", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_state_file(capsys):
    out = _info([SAMPLE / "stale.json"], capsys)
    doc = json.loads((SAMPLE / "stale.json").read_text())
    assert out["kind"].startswith("state")
    assert out["radius_km"] == pytest.approx(np.linalg.norm(doc["position_m"]) / 1e3, abs=1e-3)
    assert out["speed_m_s"] == pytest.approx(np.linalg.norm(doc["velocity_m_s"]), abs=1e-3)
    # vis-viva: a = 1 / (2/r - v^2/mu)
    r, v = np.linalg.norm(doc["position_m"]), np.linalg.norm(doc["velocity_m_s"])
    assert out["elements"]["a_m"] == pytest.approx(1 / (2 / r - v * v / 3.986004418e14), rel=1e-9)
    assert out["sigma"]["x"] == pytest.approx(10000.0) and out["covariance"] is True


def test_tle(capsys):
    out = _info([SAMPLE / "iss.tle"], capsys)
    line2 = (SAMPLE / "iss.tle").read_text().splitlines()[2].split()
    assert out["catalogue_number"] == "25544" and out["name"] == "ISS (ZARYA)"
    assert out["inclination_deg"] == float(line2[2]) and out["eccentricity"] == float("0." + line2[4])
    assert out["epoch"].startswith("2008-09-20T12:25:40")


def test_opm_and_oem_written_by_trackproc(tmp_path, capsys):
    opm, oem, state = tmp_path / "s.opm", tmp_path / "d.oem", tmp_path / "s.json"
    assert main(["-q", "estimate", str(SAMPLE / "multistation.parquet"), "--initial", str(SAMPLE / "truth.json"),
                 "--range-bias", "--opm", str(opm), "-o", str(state)]) == 0
    assert main(["-q", "propagate", str(SAMPLE / "truth.json"), "--span", "3600", "--step", "60", "--format", "oem",
                 "-o", str(oem)]) == 0
    capsys.readouterr()
    o = _info([opm], capsys)
    s = json.loads(state.read_text())
    assert o["kind"].startswith("CCSDS OPM")
    assert np.allclose(o["position_m"], s["position_m"], atol=1e-3)
    assert o["sigma"]["x"] == pytest.approx(s["sigma"][0], rel=1e-6)
    e = _info([oem], capsys)
    assert e["states"] == 61 and e["frame"] == "GCRF"
    assert e["start"].startswith("2026-03-20T09:30:00") and e["end"].startswith("2026-03-20T10:30:00")


def test_tdm(capsys):
    from trackproc.io.tdm import read_tdm

    path = ROOT / "tests" / "data" / "tdm" / "azel_tabs_doy.tdm"
    out = _info([path], capsys)
    frame = read_tdm(path.read_bytes(), str(path)).frame
    assert out["kind"].startswith("CCSDS TDM") and out["samples"] == len(frame)
    assert sum(sum(v.values()) for v in out["samples_per_station"].values()) == len(frame)


def test_text_form_reads_for_people(capsys):
    assert main(["-q", "info", str(SAMPLE / "stale.json")]) == 0
    text = capsys.readouterr().out
    assert "arg_latitude_deg" in text and "{" not in text
