"""``trackproc filter --noise``: each pass's noise model recorded in the state file, as
``estimate`` records it (``diagnostics.noise``), and the choice in ``filter.noise``."""

from __future__ import annotations

import json
from pathlib import Path

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"


def test_noise_auto_records_each_pass_model_and_white_records_none(run_cli, tmp_path):
    args = ["filter", SAMPLE / "multistation.parquet", "--initial", SAMPLE / "stale.json", "--kinds", "range_rate",
            "-q"]
    auto, white = tmp_path / "auto.json", tmp_path / "white.json"
    result = run_cli(args + ["-o", auto])                # auto is the default, as estimate's
    assert result.exit_code == 0, result.stderr
    state = json.loads(auto.read_text())
    assert state["filter"]["noise"] == "auto"
    models = state["diagnostics"]["noise"]
    assert len(models) == 14 and all(m["model"] in ("white", "ar1") for m in models.values()), models
    assert all(m["how"].startswith("REML") and m["samples"] >= 20 for m in models.values())
    result = run_cli(args + ["--noise", "white", "-o", white])
    assert result.exit_code == 0, result.stderr
    state = json.loads(white.read_text())
    assert state["filter"]["noise"] == "white" and "noise" not in state["diagnostics"]
    bad = run_cli(args + ["--noise", "pink", "-o", tmp_path / "x.json"])
    assert bad.exit_code == 2 and "--noise" in bad.stderr and "Traceback" not in bad.stderr
