"""The shell recipes in cli/ run as written (they are what users copy into their scripts). Their
``trackproc`` is a fork of one server that imported trackproc once (tests/conftest.py
``forked_trackproc``): real pipes, files and exit codes."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from trackproc.io.passfile import read_pass_table

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")


def env(bin_dir: Path):
    e = dict(os.environ)
    e["PATH"] = os.pathsep.join([str(bin_dir), str(Path(sys.executable).parent), e.get("PATH", "")])
    return e


def test_pipeline_recipe(tmp_path, forked_trackproc):
    out = tmp_path / "out"
    run = subprocess.run(["bash", str(ROOT / "cli" / "pipeline.sh"), str(out)], capture_output=True,
                         text=True, env=env(forked_trackproc), timeout=300)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    by_file = read_pass_table(out / "smoothed.parquet").frame
    by_pipe = read_pass_table(out / "smoothed_piped.parquet").frame
    assert len(by_file) == 650 and by_file["flag"].sum() == 0
    assert by_file[["value", "smoothed", "residual"]].equals(by_pipe[["value", "smoothed", "residual"]])
    assert (out / "smooth.json").stat().st_size > 0
    assert "KIR-007" in run.stdout  # info of the shipped multi-station set
    # the estimate from the refined state (README's smooth -> refine -> estimate chain, the
    # refined covariance as a-priori) lands on the truth within its own error matrix
    import json

    import numpy as np

    sol = json.loads((out / "solution.json").read_text())
    truth = json.loads((ROOT / "sample_data" / "truth_at_start.json").read_text())
    err = np.array(sol["position_m"] + sol["velocity_m_s"]) - np.array(truth["position_m"] + truth["velocity_m_s"])
    cov = np.array(sol["covariance"])[:6, :6]
    assert float(err @ np.linalg.solve(cov, err)) < 22.5  # chi2(6) at 0.999
    biases = dict(zip(sol["parameters"], sol["values"]))
    assert abs(biases["range_bias:CPH"] - 120) < 3 and abs(biases["range_bias:ZHY"] + 80) < 3
    # ... and the error matrix tight, not only covering: position sigma below one range's noise (5 m), each
    # bias sigma within [1, 2) x its sigma with the orbit known, 1/sqrt(sum 1/sigma^2) of the station's ranges
    import pandas as pd

    sigma = dict(zip(sol["parameters"], sol["sigma"]))
    passes = pd.read_parquet(ROOT / "sample_data" / "multistation.parquet")
    ranges = passes[passes["kind"] == "range"]
    assert max(sol["sigma"][:3]) < ranges["sigma"].min(), sol["sigma"][:3]
    for station in ("CPH", "ZHY", "KIR"):
        known = 1.0 / np.sqrt(np.sum(ranges.loc[ranges["station"] == station, "sigma"].to_numpy() ** -2.0))
        assert 1.0 <= sigma[f"range_bias:{station}"] / known < 2.0, (station, sigma[f"range_bias:{station}"], known)
    assert (out / "solution.oem").read_text().startswith("CCSDS_OEM_VERS")
    # the one-pass refinement: within its error matrix of the truth (the same state at 09:30), two
    # directions reported as not seen, and the Doppler drift of sample_data/make.sh recovered
    ref = json.loads((out / "refined.json").read_text())
    truth0 = json.loads((ROOT / "sample_data" / "truth.json").read_text())
    err = np.array(ref["position_m"] + ref["velocity_m_s"]) - np.array(truth0["position_m"] + truth0["velocity_m_s"])
    assert ref["epoch"] == "2026-03-20T09:30:00.000Z"
    assert np.all(np.abs(err) < 3 * np.array(ref["sigma"][:6])), err / np.array(ref["sigma"][:6])
    # ... and a sigma the pass supports: refine's a-priori is stale.json's covariance and data only add
    # information (a posterior is never wider than its prior); two directions are unseen, so not much narrower
    prior = np.array(json.loads((ROOT / "sample_data" / "stale.json").read_text())["sigma"][:6])
    assert np.all(np.array(ref["sigma"][:6]) <= prior), ref["sigma"][:6]
    assert len(ref["diagnostics"]["observability"]["unobservable"]) >= 1
    values = dict(zip(ref["parameters"], ref["values"]))
    assert abs(values["doppler_drift:CPH-001"] - 0.02) < 0.012 and abs(values["doppler_offset:CPH-001"] - 150) < 4
    assert (out / "refine_residuals.csv").stat().st_size > 0


def test_cron_recipe_reports_partial_failure_and_skips_done_files(tmp_path, forked_trackproc):
    inbox, outbox = tmp_path / "inbox", tmp_path / "outbox"
    inbox.mkdir()
    shutil.copy(ROOT / "sample_data" / "doppler_pass.csv", inbox / "a.csv")
    lines = (ROOT / "sample_data" / "doppler_pass.csv").read_text().splitlines()
    (inbox / "b.csv").write_text("\n".join(lines[:300]) + "\n")
    (inbox / "bad.csv").write_text("time,station,doppler_hz\nnot-a-time,CPH,12.0\n")
    cmd = ["bash", str(ROOT / "cli" / "cron_ingest.sh"), str(inbox), str(outbox),
           str(ROOT / "sample_data" / "stations.csv")]
    first = subprocess.run(cmd, capture_output=True, text=True, env=env(forked_trackproc), timeout=300)
    assert first.returncode == 3, first.stderr
    assert "FAILED" in first.stderr and "bad.csv" in first.stderr and "row 2" in first.stderr
    assert (outbox / "a.smoothed.parquet").exists() and (outbox / "b.smoothed.parquet").exists()
    assert not (outbox / "bad.smoothed.parquet").exists()
    second = subprocess.run(cmd, capture_output=True, text=True, env=env(forked_trackproc), timeout=300)
    assert second.returncode == 1  # only the bad file was tried again, and it failed again
    assert "0 ok, 1 failed" in second.stderr
