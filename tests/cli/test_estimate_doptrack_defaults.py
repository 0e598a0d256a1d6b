"""``trackproc estimate`` with its DEFAULTS on a DopTrack evening, as a new user runs it (issue 13:
"estimate over an evening's passes predicts a held-back pass no worse than 1.2x the TLE").

``trackproc ingest`` each pass, ``trackproc estimate`` every pass of the evening but the last with
``--initial metadata`` and nothing else (``--dut1`` aside); ``trackproc compare`` then predicts the
held-back pass from the solution and from the TLE (offset and drift removed, as no orbit predicts
them). The defaults that make this work: an offset and drift for each one-way Doppler pass (the
transmitter's oscillator: kHz off at VHF), the TLE's a-priori (one station's passes cannot fix a
whole orbit: without it the solve does not converge), and the TLE evaluated by SGP4 at the first
sample. Development evenings only (1-10 April; the hold-out is reported in docs/estimate.md).
"""

from __future__ import annotations

import json

import pytest

from realdata import DOPTRACK, requires
from test_refine_realdata import evenings, is_dev

pytestmark = requires(DOPTRACK) + [pytest.mark.slow]


def _ingest(run_cli, tmp_path, stamp):
    out = tmp_path / f"{stamp}.parquet"
    res = run_cli(["ingest", DOPTRACK / "data" / f"Delfi-C3_32789_{stamp}.csv", "-q", "-o", out])
    assert res.exit_code == 0, res.stderr
    return out


def _rms(run_cli, tmp_path, pass_file, orbit):
    summary = tmp_path / "compare.json"
    res = run_cli(["compare", pass_file, orbit, "--dut1", "-0.2", "--remove", "offset+drift", "--summary", summary,
                   "-q", "-o", tmp_path / "compare.csv"])
    assert res.exit_code == 0, res.stderr
    return json.loads(summary.read_text())["passes"][0]["rms"]


def test_estimate_with_its_defaults_predicts_each_held_back_pass_within_1_2x_the_tle(run_cli, tmp_path):
    rows = []
    for group in evenings():
        if not is_dev(group[0]):
            continue
        files = [_ingest(run_cli, tmp_path, s) for s in group]
        out = tmp_path / "solution.json"
        res = run_cli(["estimate", *files[:-1], "--initial", "metadata", "--dut1", "-0.2", "-q", "-o", out])
        assert res.exit_code == 0, (group, res.stderr)
        doc = json.loads(out.read_text())
        assert any(p.startswith("doppler_drift:") for p in doc["parameters"]), doc["parameters"]
        assert doc["estimation"]["doppler_bias"] == "auto"
        ours, tle = _rms(run_cli, tmp_path, files[-1], out), _rms(run_cli, tmp_path, files[-1], "metadata")
        rows.append((group, round(tle, 2), round(ours, 2), doc["quality"]["verdict"]))
    print("DopTrack held-back pass (Hz), TLE vs estimate with its defaults:", rows)
    assert len(rows) >= 6
    assert all(o <= 1.2 * t for _, t, o, _ in rows), rows
