"""``trackproc batch``: every refined or estimated solution's ``quality`` verdict in the summary
(issue 13: "every solution (state file, OPM comment, batch summary) carries a machine-readable
quality verdict"), and ``--strict`` for cron. Data: the ISS pass simulated from its TLE, on time
and with its time tags 1 s late (tests/cli/test_tle_timing.py: the late one contradicts the TLE's
stated accuracy, ``suspect``, reason ``declined``)."""

from __future__ import annotations

import csv
import json
import shutil

from test_tle_timing import iss_pass  # noqa: F401  (the fixture)


def _batch(run_cli, iss_pass, tmp_path, name, *extra):  # noqa: F811
    inbox = tmp_path / "inbox"
    if not inbox.exists():
        inbox.mkdir()
        for f in ("p.parquet", "late.parquet"):
            shutil.copy(iss_pass / f, inbox / f)
    out = tmp_path / name
    run = run_cli(["batch", "-i", inbox, "-o", out, "--steps", "refine", "--refine-initial", iss_pass / "iss.tle",
                   "--workers", "1", *extra])
    return run, json.loads((out / "summary.json").read_text()), out


def test_the_summary_carries_each_solutions_verdict_and_strict_counts_suspect_as_failed(run_cli, iss_pass,  # noqa: F811
                                                                                        tmp_path):
    run, summary, out = _batch(run_cli, iss_pass, tmp_path, "plain")
    assert run.exit_code == 0, run.stderr
    records = {r["name"]: r for r in summary["inputs"]}
    assert records["p"]["numbers"]["quality"] == "ok"
    assert records["late"]["numbers"]["quality"] == "suspect"
    assert records["late"]["numbers"]["quality_reasons"].startswith("declined")
    assert records["late"]["numbers"]["decision"] == "declined"
    assert records["p"]["numbers"]["decision"] in ("replaced", "kept")
    assert records["late"]["details"]["refine"]["quality"]["verdict"] == "suspect"
    assert summary["counts"]["quality_suspect"] == 1 and summary["counts"]["quality_counted_as_failed"] == 0
    rows = {r["input"]: r for r in csv.DictReader((out / "summary.csv").open())}
    assert rows["late"]["quality"] == "suspect" and rows["p"]["quality"] == "ok"
    assert "late: ok" in run.stderr and "quality suspect (declined" in run.stderr
    assert rows["late"]["decision"] == "declined"
    # --strict: the suspect solution counts against the run (exit 3: the other one is ok), its
    # refined state written all the same
    run, summary, out = _batch(run_cli, iss_pass, tmp_path, "strict", "--strict")
    assert run.exit_code == 3, run.stderr
    assert summary["exit_code"] == 3 and summary["counts"]["quality_counted_as_failed"] == 1
    assert (out / "passes" / "late.refined.json").exists()
    assert "counted as failed by their quality verdict" in run.stderr
