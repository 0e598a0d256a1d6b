"""``trackproc filter --dmc`` and ``--bias-gm`` through the command line on the shipped three-station
set against the truth it was simulated from (sample_data/truth_at_start.json, J2: here the full
model with the zonal degree 2 only); the drag case and the Gauss–Markov references are in
tests/pipeline/test_filter_dmc.py."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
BIASES = {"range_bias:CPH": 120.0, "range_bias:KIR": 45.0, "range_bias:ZHY": -80.0}
BASE = ["filter", SAMPLE / "multistation.parquet", "--initial", SAMPLE / "stale.json", "--range-bias",
        "--apriori-sigma", "range_bias=1000", "--kinds", "range,range_rate"]


@pytest.mark.slow           # four sweeps of filter and smoother under the full model, ~1 s of CPU
def test_dmc_accelerations_are_estimated_states_with_sigmas(run_cli, tmp_path):
    out = tmp_path / "dmc.json"
    result = run_cli(BASE + ["--force", "full", "--gravity", "2x0", "--third-body", "none", "--no-relativity",
                             "--dmc", "1e-8,3600", "--smooth", "--iterations", "5", "-q", "-o", out])
    assert result.exit_code == 0, result.stderr
    state = json.loads(out.read_text())
    truth = json.loads((SAMPLE / "truth_at_start.json").read_text())
    values = dict(zip(state["parameters"], zip(state["values"], state["sigma"])))
    # the empirical accelerations are states; a Gauss-Markov state's sigma never exceeds its
    # steady-state sigma (started there; the data only reduce it), and the data reduced it
    for n in ("empirical_r", "empirical_t", "empirical_n"):
        v, s = values[n]
        assert 0.0 < s <= 1e-8 * (1 + 1e-9) and abs(v) < 4 * s
    assert values["empirical_t"][1] < 0.99e-8
    expected = dict(zip(truth["parameters"], truth["values"]), **BIASES)
    z = [(values[n][0] - x) / values[n][1] for n, x in expected.items()]
    assert np.max(np.abs(z)) < 4.0, dict(zip(expected, z))
    noise = state["filter"]["process_noise"]
    assert noise["dmc_sigma_rtn_m_s2"] == [1e-8] * 3 and noise["dmc_tau_s"] == 3600.0
    assert state["quality"]["verdict"] == "ok"


@pytest.mark.parametrize("extra,needle", [
    (["--dmc", "1e-8"], "--dmc"),                                         # not --force full
    (["--dmc", "1e-8,2,3"], "--dmc"),
    (["--force", "full", "--dmc", "0,3600"], "--dmc"),
    (["--bias-gm", "range_bias=1"], "--bias-gm"),
    (["--bias-gm", "nosuch=1,300"], "--bias-gm"),
    (["--bias-gm", "range_bias=1,300", "--bias-walk", "range_bias=0.01"], "--bias-gm"),
    (["--bias-reset-per-pass", "nosuch"], "--bias-reset-per-pass"),
])
def test_bad_process_noise_options_are_one_line_usage_errors(run_cli, tmp_path, extra, needle):
    out = tmp_path / "x.json"
    result = run_cli(BASE + extra + ["-o", out])
    assert result.exit_code == 2, result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in result.stderr, result.stderr
    assert not out.exists()
