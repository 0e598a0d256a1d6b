"""``trackproc estimate`` under mis-modelled passes (issue 13: "no confident wrong answer"): the
scenario table of ``mismodel_scenarios.py`` — simulated passes with a known truth and one error
the estimate does not model — checked "covers or says so": every state component and estimated
bias within 4 sigma of the truth, or a verdict ``suspect``/``rejected`` (exit 1 with
``--strict``), and when a pass or station is named first, the right one. The clean sets are
``ok`` (their false-alarm rate, measured over 60 draws each, is in docs/estimate.md).

Scenarios undetectable in principle are not tested for coverage: a one-station VHF evening whose
time tags are 0.5 s late (the same Doppler as the orbit 3.7 km along-track) or whose station is
1 km off (the orbit shifted by about as much) fits white and consistent, and only the 1 km
a-priori could tell (docs/estimate.md, "Mis-modelled passes"). A 3 kHz carrier error (1.4e-6 in scale) and a two-way pass labelled one-way (its
Doppler edited whole) leave the solution covering the truth.
"""

from __future__ import annotations

import pytest

import mismodel_scenarios as ms
from trackproc.cli import app as cli_app


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    ms.RUNNER = cli_app.main            # simulate and estimate through the real entry point
    return ms.Sets(tmp_path_factory.mktemp("mismodel"), 1)


def _check(row, culprit_named: bool = True):
    assert ms.covers_or_says_so(row), row
    if row["verdict"] == "(failed)":
        assert row["exit"] == 1, row                 # a processing failure, nothing written
    elif row["verdict"] in ("suspect", "rejected"):
        assert row["exit"] == 1, row                 # --strict
        if culprit_named and row["named"] is not None:
            assert row["named"], row                 # the first block named is the culprit
    else:
        assert row["exit"] == 0, row


@pytest.mark.parametrize("name", ["clean", "vhf_clean"])
def test_consistent_passes_are_ok_and_cover_the_truth(sets, name):
    row = ms.run(sets, name)
    assert row["verdict"] == "ok" and row["exit"] == 0, row
    assert max(row["z_state"], row["z_bias"]) < 4.0, row


@pytest.mark.parametrize("name, culprit", [
    ("station_300", "KIR"),             # one station 300 m off: the station is named first
    ("timetag_0.5", "KIR"),             # one station's time tags 0.5 s late
    ("bias_jump", "KIR/KIR-002"),       # a 50 m range bias step in one pass
    ("other_satellite", "KIR/KIR-002"),  # a pass of a satellite 30 s behind
    ("range_step_20", "KIR/KIR-002"),    # +20 m on the second half of one pass's ranges (10 m noise)
    ("rr_station_300", "KIR"),          # the same with range-rate instead of Doppler
    ("rr_bias_jump_15", "KIR/KIR-002"),  # +15 m on one pass: ok with a bias 4.1-4.3 sigma off before
])
def test_a_wrong_station_or_pass_is_said_and_named(sets, name, culprit):
    row = ms.run(sets, name)
    _check(row)
    assert row["verdict"] == "suspect" and culprit in row["first_named"], row
    if name == "range_step_20":
        step = [r for r in row["doc"]["quality"]["reasons"] if r["code"] == "step"][0]
        assert step["severity"] == "suspect" and "KIR/KIR-002 range" in step["message"], step


def test_an_oscillator_step_absorbed_by_the_state_is_found_by_pass_consistency(sets):
    """A 20 Hz thermal step (60 s time constant) mid-way through the second of three VHF passes:
    in some draws the state absorbs it (the pass then fits white, variance factor within its
    limit) and the state is 10 sigma off with verdict ok before the pass-consistency test;
    seed 3 is one of them. Now: suspect, that pass named."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        s3 = ms.Sets(Path(tmp), 3)
        row = ms.run(s3, "vhf_oscillator_step")
        _check(row)
        assert row["verdict"] == "suspect" and "pass_consistency" in row["reasons"], row
        assert "DLF/DLF-002" in row["first_named"], row


def test_a_two_way_pass_labelled_one_way_is_edited_and_said(sets):
    row = ms.run(sets, "two_way_as_one_way")
    _check(row)
    assert max(row["z_state"], row["z_bias"]) < 4.0, row     # the solution goes without it...
    assert "edited_pass" in row["reasons"] and "KIR/KIR-002" in row["first_named"], row   # ...and says so


@pytest.mark.parametrize("name", ["bias_not_estimated", "carrier_3khz", "vhf_timetag_2", "vhf_carrier_3khz"])
def test_other_mismodellings_cover_or_say_so(sets, name):
    _check(ms.run(sets, name))


@pytest.mark.parametrize("name", ["drag_1", "vhf_other_satellite", "vhf_oscillator_step"])
def test_unmodelled_drag_and_another_satellite_cover_or_say_so(sets, name, run_cli, tmp_path):
    row = ms.run(sets, name)
    _check(row, culprit_named=name != "drag_1")
    if name == "drag_1":                      # drag and SRP over a day with --force j2: 19 sigma, said
        assert row["verdict"] == "suspect" and "variance_factor" in row["reasons"], row
    if name == "vhf_other_satellite":         # 225 km along-track from the others: no convergence, exit 1
        assert row["verdict"] == "(failed)" and row["exit"] == 1, row
        # ... and the error names the pass without which the others converge
        sc = ms.scenario(sets, name)
        res = run_cli(["estimate", *sc["files"], "--initial", sc["initial"], "--stations", sc["stations"],
                       *sc["options"], "-o", tmp_path / "x.json"])
        assert res.exit_code == 1, res.stderr
        assert f"without pass DLF/{sc['culprit']} the others converge and agree" in res.stderr, res.stderr


def test_a_long_dense_set_does_not_crash_the_noise_model(run_cli, tmp_path):
    """12 h of range and Doppler every 2 s from 3 stations, no range bias, estimated with
    `--doppler-bias offset`: REML's simplex stepped to a log-variance whose exp overflowed
    (``internal error (OverflowError)``, exit 1) before the cap in methods/noise.py; now it
    converges, covers the truth and is ok."""
    import json

    import numpy as np

    d = tmp_path
    (d / "state.json").write_text(json.dumps(ms.STATE))
    (d / "guess.json").write_text(json.dumps(ms.GUESS))
    (d / "stations.csv").write_text(ms._stations_csv(ms.STATIONS))
    assert run_cli(["simulate", "--state", d / "state.json", "--stations", d / "stations.csv", "--duration", "43200",
                    "--step", "2", "--seed", "3", "--kinds", "range,doppler", "--dut1", "0.1",
                    "-o", d / "p.parquet"]).exit_code == 0
    r = run_cli(["estimate", d / "p.parquet", "--initial", d / "guess.json", "--stations", d / "stations.csv",
                 "--doppler-bias", "offset", "--dut1", "0.1", "-o", d / "sol.json"])
    assert r.exit_code == 0 and "Traceback" not in r.stderr, r.stderr
    doc = json.loads((d / "sol.json").read_text())
    err = np.asarray(doc["values"][:6]) - np.r_[ms.STATE["position_m"], ms.STATE["velocity_m_s"]]
    assert np.all(np.abs(err) < 4 * np.asarray(doc["sigma"][:6])), err / np.asarray(doc["sigma"][:6])
    assert doc["quality"]["verdict"] == "ok", doc["quality"]
