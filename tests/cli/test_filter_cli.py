"""``trackproc filter`` through the command line: the docs' example on the shipped three-station set
against the truth it was simulated from (``sample_data/truth_at_start.json`` and the range biases
of ``sample_data/make.sh``). The filter's own references (estimate's batch solution, a manoeuvre,
a carried state) are in tests/pipeline/test_filter.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
#: the range biases sample_data/make.sh simulated (m)
BIASES = {"range_bias:CPH": 120.0, "range_bias:KIR": 45.0, "range_bias:ZHY": -80.0}


def test_smoothed_state_and_biases_cover_the_simulated_truth(run_cli, tmp_path):
    out = tmp_path / "smoothed.json"
    result = run_cli(["filter", SAMPLE / "multistation.parquet", "--initial", SAMPLE / "stale.json",
                      "--range-bias", "--apriori-sigma", "range_bias=1000", "--kinds", "range,range_rate",
                      "--smooth", "--iterations", "5", "-q", "-o", out])
    assert result.exit_code == 0, result.stderr
    state = json.loads(out.read_text())
    truth = json.loads((SAMPLE / "truth_at_start.json").read_text())
    assert state["epoch"] == truth["epoch"]                        # smoothed back to the first time
    expected = dict(zip(truth["parameters"], truth["values"]), **BIASES)
    assert set(state["parameters"]) == set(expected)
    z = [(v - expected[n]) / s for n, v, s in zip(state["parameters"], state["values"], state["sigma"])]
    assert np.max(np.abs(z)) < 4.0, dict(zip(state["parameters"], z))
    # the stale first guess was 10 km away: the data moved it
    stale = json.loads((SAMPLE / "stale.json").read_text())
    assert np.linalg.norm(np.subtract(stale["position_m"], truth["position_m"])) > 1000.0
