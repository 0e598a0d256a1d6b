"""The stderr summaries people and scripts read (issue 16): angles in degrees, the orbital elements
beside the Cartesian state, and ``--json`` for scripts (the same numbers as the state file)."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_data"
MU = 3.986004418e14


@pytest.fixture(scope="module")
def estimate_runs(tmp_path_factory):
    from typer.testing import CliRunner

    from trackproc.cli.app import main

    d = tmp_path_factory.mktemp("sum")
    args = ["estimate", str(SAMPLE / "multistation.parquet"), "--initial", str(SAMPLE / "truth.json"), "--range-bias",
            "--angle-bias"]
    out = {}
    for name, extra in (("text", []), ("json", ["--json"])):
        with CliRunner().isolation() as (_, err, _):
            assert main(args + extra + ["-o", str(d / f"{name}.json")]) == 0
            out[name] = (err.getvalue().decode(), json.loads((d / f"{name}.json").read_text()))
    return out


def test_text_summary_in_degrees_with_elements(estimate_runs):
    text, state = estimate_runs["text"]
    assert "az_bias:CPH" in text and not re.search(r"\brad\b", text), text
    m = re.search(r"elements \(osculating, GCRF\): a ([0-9.]+) m, e ([0-9.]+), i ([0-9.]+) deg", text)
    r, v = np.linalg.norm(state["position_m"]), np.linalg.norm(state["velocity_m_s"])
    assert float(m.group(1)) == pytest.approx(1 / (2 / r - v * v / MU), abs=0.1)          # vis-viva
    h = np.cross(state["position_m"], state["velocity_m_s"])
    assert float(m.group(3)) == pytest.approx(np.degrees(np.arccos(h[2] / np.linalg.norm(h))), abs=1e-4)


def test_json_summary_matches_the_state_file(estimate_runs):
    text, state = estimate_runs["json"]
    doc = json.loads(text.strip().splitlines()[-1])
    assert doc["command"] == "estimate" and doc["quality"]["verdict"] == state["quality"]["verdict"]
    for name, value, sigma in zip(state["parameters"], state["values"], state["sigma"]):
        assert doc["parameters"][name]["value"] == pytest.approx(value, rel=1e-15)
        assert doc["parameters"][name]["sigma"] == pytest.approx(sigma, rel=1e-15)
    assert doc["elements"]["a_m"] == pytest.approx(state["elements"]["a_m"], rel=1e-15)


def test_accuracy_and_detect_json_summaries(tmp_path):
    from typer.testing import CliRunner

    from trackproc.cli.app import main

    with CliRunner().isolation() as (_, err, _):
        assert main(["accuracy", str(SAMPLE / "stale.json"), "--span", "3600", "--step", "600", "--method", "all",
                     "--json", "-o", str(tmp_path / "a.parquet")]) == 0
        doc = json.loads(err.getvalue().decode().strip().splitlines()[-1])
    assert doc["command"] == "accuracy" and "spectral_vs_stm_max_relative_sigma_difference" in doc["checks"]
    passfile = tmp_path / "b.parquet"
    with CliRunner().isolation() as (_, err, _):
        assert main(["-q", "simulate", "--ballistic", str(SAMPLE / "nominal.json"), "--stations",
                     str(SAMPLE / "stations.csv"), "--hypothesis", "h1", "--step", "2", "--elevation-mask-deg", "0",
                     "--seed", "1", "-o", str(passfile)]) == 0
    with CliRunner().isolation() as (_, err, _):
        assert main(["detect", str(passfile), "--nominal", str(SAMPLE / "nominal.json"), "--json",
                     "-o", str(tmp_path / "d.json")]) == 0
        line = json.loads(err.getvalue().decode().strip().splitlines()[-1])
    result = json.loads((tmp_path / "d.json").read_text())
    assert line["decision"] == result["decision"] == "H1" and line["S"] == result["statistic"]["S"]
