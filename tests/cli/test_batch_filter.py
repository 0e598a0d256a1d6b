"""The ``filter`` step of ``trackproc batch`` carries the filter's state from one run (night) to
the next: two nights of the shipped three-station set (range + range-rate, range biases) run as
two batch runs equal one ``trackproc filter`` over both nights' passes (zero process noise, no
editing: the filter is linear in its updates between reference restarts), and the second run
starts from the first one's ``OUTPUT/filter/state.json`` (skipping nothing new)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from trackproc.io.passfile import PassTable, read_pass_table, write_pass_table

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"
SETTINGS = ["--steps", "filter", "--workers", "1", "--filter-initial", str(SAMPLE / "stale.json"),
            "--stations", str(SAMPLE / "stations.csv"), "--filter-range-bias", "--filter-apriori-sigma",
            "range_bias=1000", "--filter-kinds", "range,range_rate", "--filter-edit-sigma", "0",
            "--filter-force-model", "j2"]


def _guess(path: Path) -> Path:
    """The truth moved within a 100 m / 0.1 m/s covariance that the state file states (a consistent
    prior: night 1's filtered state is then consistent too, and night 2 replaces it; from the 10 km
    stale state one sweep leaves night 1 overconfident, NEES 40 against the truth, and night 2
    contradicts it: docs/filter.md, "Prior and decision")."""
    from trackproc.io.statefile import read_state, state_json
    from trackproc.types.state import State

    truth = read_state(str(SAMPLE / "truth_at_start.json"), None)
    sig = np.array([100.0] * 3 + [0.1] * 3)
    rv = truth.rv + np.random.default_rng(1).standard_normal(6) * sig
    path.write_text(state_json(State.from_vectors(truth.epoch, rv[:3], rv[3:], values=rv, sigma=sig,
                                                  covariance=np.diag(sig ** 2))))
    return path


def _split(inbox: Path) -> tuple:
    """One pass file per pass of the shipped set; (night-1 names, night-2 names) cut 5 h in."""
    table = read_pass_table(str(SAMPLE / "multistation.parquet"))
    frame = table.frame
    cut = frame["time"].min() + np.timedelta64(5, "h")
    nights = ([], [])
    for (station, pass_id), sub in frame.groupby(["station", "pass_id"], sort=True):
        name = f"{station}-{pass_id}".replace("/", "-")
        write_pass_table(PassTable(sub.reset_index(drop=True), table.meta), str(inbox / f"{name}.parquet"))
        nights[int(sub["time"].min() >= cut)].append(name)
    return nights


def test_two_nights_in_two_batch_runs_equal_one_filter_run(tmp_path, run_cli):
    night1_dir, all_dir, out = tmp_path / "n1", tmp_path / "all", tmp_path / "out"
    all_dir.mkdir()
    night1, night2 = _split(all_dir)
    assert night1 and night2
    initial = _guess(tmp_path / "initial.json")
    settings = [str(initial) if s == str(SAMPLE / "stale.json") else s for s in SETTINGS]
    night1_dir.mkdir()
    for name in night1:
        (night1_dir / f"{name}.parquet").write_bytes((all_dir / f"{name}.parquet").read_bytes())
    first = run_cli(["batch", "-i", night1_dir, "-o", out, *settings])
    assert first.exit_code == 0, first.stderr
    state1 = json.loads((out / "filter" / "state.json").read_text())
    assert state1["filter"]["carried_state"] is False
    second = run_cli(["batch", "-i", all_dir, "-o", out, *settings])
    assert second.exit_code == 0, second.stderr
    state2 = json.loads((out / "filter" / "state.json").read_text())
    rec = state2["filter"]
    assert rec["carried_state"] is True
    # the passes night 1 filtered are skipped, night 2's all used
    assert sorted(rec["skipped_passes"]) == sorted(
        f"{n.split('-', 1)[0]}/{n.split('-', 1)[1]}" for n in night1)
    assert rec["updates"] > 0
    dated = sorted(p.name for p in (out / "filter").glob("*.json") if p.name != "state.json")
    assert len(dated) == 2                      # one output per night
    # the reference: one filter over both nights' passes
    one = tmp_path / "one.json"
    res = run_cli(["filter", *sorted(all_dir.glob("*.parquet")), "--initial", initial,
                   "--stations", SAMPLE / "stations.csv", "--range-bias", "--apriori-sigma", "range_bias=1000",
                   "--kinds", "range,range_rate", "--edit-sigma", "0", "--force", "j2", "-q", "-o", one])
    assert res.exit_code == 0, res.stderr
    ref = json.loads(one.read_text())
    for state in (state1, state2, ref):
        assert state["diagnostics"]["decision"]["action"] == "replaced", state["diagnostics"]["decision"]
    assert ref["epoch"] == state2["epoch"] and ref["parameters"] == state2["parameters"]
    z = (np.asarray(state2["values"]) - np.asarray(ref["values"])) / np.asarray(ref["sigma"])
    # measured 0.0042 sigma, sigmas 1e-8 relative (docs/filter.md: the extended filter's
    # linearisation points differ between the two runs)
    assert np.max(np.abs(z)) < 0.01, dict(zip(ref["parameters"], z))
    np.testing.assert_allclose(state2["sigma"], ref["sigma"], rtol=1e-4)
    # a third run with nothing new: the carried state is kept as it is
    before = (out / "filter" / "state.json").read_bytes()
    third = run_cli(["batch", "-i", all_dir, "-o", out, *settings])
    assert third.exit_code == 0, third.stderr
    assert (out / "filter" / "state.json").read_bytes() == before
    assert "no pass newer than the carried state" in third.stderr


def test_failed_filter_step_exits_1_and_keeps_no_state(tmp_path, run_cli):
    """A filter step that fails (--filter-kinds doppler: the passes hold none) is a failed
    unit of the run: exit 3 beside ok inputs, no state file written."""
    inbox, out = tmp_path / "in", tmp_path / "out"
    inbox.mkdir()
    _split(inbox)
    settings = [s if s != "range,range_rate" else "doppler" for s in SETTINGS]
    res = run_cli(["batch", "-i", inbox, "-o", out, *settings])
    assert res.exit_code == 3, res.stderr
    assert "filter: failed" in res.stderr
    assert not (out / "filter" / "state.json").exists()


def test_report_lists_the_filter_run_without_a_figure_error(tmp_path, run_cli):
    """report.html has the filter's row (its state file linked) and no "figures left out"."""
    inbox, out = tmp_path / "in", tmp_path / "out"
    inbox.mkdir()
    _split(inbox)
    res = run_cli(["batch", "-i", inbox, "-o", out, *SETTINGS])
    assert res.exit_code == 0, res.stderr
    html = (out / "report.html").read_text()
    assert "filter over 14 input(s), state carried" in html
    assert "Figures left out" not in html and "figures left out" not in res.stderr
    (record,) = json.loads((out / "summary.json").read_text())["estimates"]
    assert record["task"] == "filter" and record["status"] == "ok"
    # one sweep from the 10 km first guess: suspect by its innovations (docs/filter.md), not rejected
    assert record["numbers"]["quality"] == "suspect" and "innovations" in record["numbers"]["quality_reasons"]
    assert record["numbers"]["sigma_along_m"] > 0


def test_a_corrupt_carried_state_fails_the_filter_alone_and_is_left_as_it_was(tmp_path, run_cli):
    """A carried state that is not a state file: the filter step fails with the file named, the
    inputs stay ok (exit 3), and the file is not replaced."""
    inbox, out = tmp_path / "in", tmp_path / "out"
    inbox.mkdir()
    _split(inbox)
    (out / "filter").mkdir(parents=True)
    (out / "filter" / "state.json").write_text("{not json")
    res = run_cli(["batch", "-i", inbox, "-o", out, *SETTINGS])
    assert res.exit_code == 3, res.stderr
    (line,) = [ln for ln in res.stderr.splitlines() if "filter: failed" in ln]
    assert "state.json" in line and "Traceback" not in res.stderr
    assert (out / "filter" / "state.json").read_text() == "{not json"
    assert not [p for p in (out / "filter").glob("*.json") if p.name != "state.json"]
