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


# --------------------------------------------------------------------------- every other kind
# Each summary is checked against the file's own lines read here with the standard library
# (csv, json, gzip, line prefixes), not with trackproc's readers.

import csv  # noqa: E402
import gzip  # noqa: E402
import math  # noqa: E402
from datetime import datetime, timedelta, timezone  # noqa: E402

from realdata import DOPTRACK, REALDATA, W3B  # noqa: E402

LAGEOS = REALDATA / "orekit-lageos2"
DOPTRACK_PASS = "Delfi-C3_32789_202004011044"


def _real(path):
    return [pytest.mark.realdata, pytest.mark.skipif(not path.is_dir(), reason=f"real data not available: {path}")]


def _apply(marks):
    def wrap(fn):
        for mark in marks:
            fn = mark(fn)
        return fn
    return wrap


def test_raw_pass_csv_before_ingest(capsys):
    out = _info([SAMPLE / "doppler_pass.csv"], capsys)
    rows = list(csv.DictReader((SAMPLE / "doppler_pass.csv").open()))
    assert out["kind"].startswith("raw pass table") and out["samples"] == len(rows)
    assert out["samples_per_kind"] == {"doppler": len(rows)} and out["units"] == {"doppler": "Hz"}
    assert out["start"].startswith(rows[0]["time"][:19]) and out["end"].startswith(rows[-1]["time"][:19])
    assert out["samples_per_station"] == {"CPH": len(rows)}


def test_stations_table(capsys):
    out = _info([SAMPLE / "stations.csv"], capsys)
    rows = list(csv.DictReader((SAMPLE / "stations.csv").open()))
    assert out["stations"] == len(rows)
    assert out["positions"][rows[0]["station"]]["lat_deg"] == float(rows[0]["lat_deg"])


def test_tle_catalogue_and_bstar_as_a_number(capsys):
    out = _info([SAMPLE / "catalogue.tle"], capsys)
    lines = (SAMPLE / "catalogue.tle").read_text().splitlines()
    assert out["tles"] == sum(line.startswith("1 ") for line in lines) == len(out["satellites"])
    one = _info([SAMPLE / "iss.tle"], capsys)
    assert one["bstar"] == pytest.approx(-0.11606e-4, rel=1e-12)   # "-11606-4": -.11606 x 10^-4
    assert main(["-q", "info", str(SAMPLE / "iss.tle")]) == 0
    assert "-1.1606e-05" in capsys.readouterr().out


def test_detect_nominal(capsys):
    out = _info([SAMPLE / "nominal.json"], capsys)
    doc = json.loads((SAMPLE / "nominal.json").read_text())
    assert out["kind"].startswith("detect nominal")
    assert out["velocity_m_s"] == pytest.approx(doc["velocity_kms"] * 1e3) and out["angle_deg"] == pytest.approx(48)
    assert out["station"] == doc["station"]


def test_smooth_and_batch_summaries_and_residuals(tmp_path, capsys):
    pass_file, smooth = tmp_path / "p.parquet", tmp_path / "smooth.json"
    assert main(["-q", "ingest", str(SAMPLE / "doppler_pass.csv"), "--stations", str(SAMPLE / "stations.csv"),
                 "--carrier-hz", "2.2e9", "--mode", "one-way", "-o", str(pass_file)]) == 0
    assert main(["-q", "smooth", str(pass_file), "--summary", str(smooth), "-o", str(tmp_path / "s.parquet")]) == 0
    residuals = tmp_path / "res.csv"
    assert main(["-q", "estimate", str(SAMPLE / "multistation.parquet"), "--initial", str(SAMPLE / "truth.json"),
                 "--range-bias", "--residuals", str(residuals), "-o", str(tmp_path / "sol.json")]) == 0
    assert main(["-q", "batch", str(SAMPLE / "nightly.toml"), "-o", str(tmp_path / "b")]) == 0
    capsys.readouterr()

    doc = json.loads(smooth.read_text())
    out = _info([smooth], capsys)
    assert out["kind"].startswith("smooth summary") and len(out["fits"]) == len(doc["fits"])
    (fit,) = out["fits"].values()
    assert fit["fca_hz"] == doc["fits"][0]["fca_hz"] and fit["samples"] == 650

    batch = json.loads((tmp_path / "b" / "summary.json").read_text())
    out = _info([tmp_path / "b" / "summary.json"], capsys)
    assert out["kind"].startswith("batch summary") and out["inputs_by_status"] == {"ok": len(batch["inputs"])}
    rows = list(csv.DictReader(line for line in (tmp_path / "b" / "summary.csv").open() if not line.startswith("#")))
    out = _info([tmp_path / "b" / "summary.csv"], capsys)
    assert out["rows"] == len(rows) and out["status"] == {"ok": len(rows)}

    rows = list(csv.DictReader(line for line in residuals.open() if not line.startswith("#")))
    out = _info([residuals], capsys)
    assert out["samples"] == len(rows)
    cph = [float(r["residual"]) for r in rows if r["station"] == "CPH" and r["kind"] == "range"
           and r["edited"] != "true"]
    entry = out["per_station_and_kind"]["CPH range"]
    assert entry["rms"] == pytest.approx(math.sqrt(sum(x * x for x in cph) / len(cph)), rel=1e-12)
    assert entry["unit"] == "m" and 0.5 < entry["normalized_rms"] < 2


@pytest.mark.parametrize("fmt", ["csv", "md"])
def test_requirements_tables(tmp_path, capsys, fmt):
    path = tmp_path / f"req.{fmt}"
    assert main(["-q", "requirements", "--format", fmt, "-o", str(path)]) == 0
    capsys.readouterr()
    out = _info([path], capsys)
    assert out["kind"].startswith("requirements table")
    if fmt == "csv":
        g = [float(r["g"]) for r in csv.DictReader(line for line in path.open() if not line.startswith("#"))]
        assert out["rows"] == len(g) == 75 and out["g_rad_s05"] == [min(g), max(g)]
    else:
        assert out["rows"] == 15 and out["columns"][-1] == "V = 5 km/s"


def test_gzipped_gravity_field_by_path_and_stdin(run_cli):
    from trackproc.io.icgem import default_field_path

    path = default_field_path()
    head = gzip.open(path, "rt", encoding="latin-1").read(20000)
    header = dict(line.split()[:2] for line in head.split("begin_of_head")[1].split("end_of_head")[0].splitlines()
                  if len(line.split()) >= 2)
    out = json.loads(run_cli(["info", path, "--json"]).stdout)
    assert out["degree"] == int(header["max_degree"]) and out["gm_m3_s2"] == float(header["earth_gravity_constant"])
    piped = json.loads(run_cli(["info", "-", "--json"], input=path.read_bytes()).stdout)
    assert piped["degree"] == out["degree"] and piped["file"] == "<stdin>"


@pytest.mark.parametrize("content", [b"[section]\nkey = 1\n", b"<?xml version='1.0'?><a/>",
                                     b'{"hello": 1}', b"a,b\n1,2\n"])
def test_unknown_file_lists_the_kinds(run_cli, write, content):
    from hostile import assert_rejected

    result = run_cli(["info", write("thing.in", content), "-q"])
    assert_rejected(result, 2, "thing.in", "not a file trackproc knows", "ILRS CRD", "SINEX")


def test_text_has_units_and_no_python_dicts(tmp_path, capsys):
    state = tmp_path / "sol.json"
    assert main(["-q", "estimate", str(SAMPLE / "multistation.parquet"), "--initial", str(SAMPLE / "truth.json"),
                 "--range-bias", "-o", str(state)]) == 0
    capsys.readouterr()
    assert main(["-q", "info", str(state)]) == 0
    text = capsys.readouterr().out
    sigma_x = json.loads(state.read_text())["sigma"][0]
    assert f"x                         {sigma_x:.4g} m\n" in text
    assert " m/s\n" in text and "{" not in text and "'verdict'" not in text
    assert "variance_factor ok: a-posteriori variance factor" in text


@_apply(_real(REALDATA / "orekit-lageos2"))
def test_crd_cpf_and_sinex(capsys):
    npt = LAGEOS / "lageos2_20160214.npt"
    out = _info([npt], capsys)
    lines = [line.split() for line in npt.read_text().splitlines() if line.split()]
    assert out["kind"].startswith("ILRS CRD") and out["samples"] == sum(f[0] == "11" for f in lines) == 95
    assert set(out["samples_per_station"]) == {f[2] for f in lines if f[0].lower() == "h2"}
    assert out["units"] == {"range": "m"} and len(out["sessions"]) == sum(f[0].lower() == "h4" for f in lines)

    cpf = LAGEOS / "lageos2_cpf_160213_5441.sgf"
    out = _info([cpf], capsys)
    records = [line.split() for line in cpf.read_text().splitlines() if line.startswith("10 ")]
    assert out["positions"] == len(records) and out["step_s"] == 300.0
    r = math.dist((0, 0, 0), [float(x) for x in records[0][5:8]]) / 1e3
    assert out["radius_km"][0] <= r <= out["radius_km"][1]

    snx = LAGEOS / "SLRF2014_POS+VEL_2030.0_200428.snx"
    out = _info([snx], capsys)
    codes = {line.split()[2] for line in snx.read_text(encoding="latin-1").splitlines()
             if len(line.split()) > 2 and line.split()[1] == "STAX"}
    assert out["kind"].startswith("SINEX") and out["sites_with_coordinates"] == len(codes)
    ecc = _info([LAGEOS / "ecc_une.snx"], capsys)
    assert ecc["sites_with_eccentricities"] > 100 and ecc["sites_with_coordinates"] == 0


@_apply(_real(W3B))
def test_orekit_aer(capsys):
    out = _info([W3B / "W3B.aer"], capsys)
    fields = [line.split() for line in (W3B / "W3B.aer").read_text().splitlines()
              if line.strip() and not line.startswith("#")]
    azel = sum(f[1] == "AZ_EL" for f in fields)
    assert out["samples_per_kind"] == {"azimuth": azel, "elevation": azel, "range": sum(f[1] == "RANGE" for f in fields)}
    assert out["units"]["range"] == "m"


@_apply(_real(DOPTRACK))
def test_doptrack_csv_and_yaml(capsys):
    data = DOPTRACK / "data" / f"{DOPTRACK_PASS}.csv"
    yml = DOPTRACK / "metadata" / f"{DOPTRACK_PASS}.yml"
    out = _info([data], capsys)
    rows = [line for line in data.read_text().splitlines() if line.strip() and not line.startswith("#")]
    assert out["kind"].startswith("DopTrack") and out["samples"] == len(rows) and out["satellite"] == "Delfi-C3"
    side = _info([yml], capsys)
    assert side["kind"].startswith("DopTrack YAML") and side["tca"] == out["tca"]
    line1 = next(line for line in yml.read_text().splitlines() if "line1:" in line).split("line1:")[1].split()
    year, day = 2000 + int(line1[3][:2]), float(line1[3][2:])
    epoch = datetime(year, 1, 1, tzinfo=timezone.utc) + timedelta(days=day - 1)
    assert side["tle_epoch"].startswith(epoch.strftime("%Y-%m-%dT%H:%M:%S"))
