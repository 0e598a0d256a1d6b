"""Hostile class: every output-side OS error is one line naming the path (issue 14 item 1), and a
command with several outputs writes all of them or none."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from hostile import MULTI, STATIONS, TRUTH, assert_no_temporaries, assert_rejected

SIM = ["simulate", "--state", TRUTH, "--stations", STATIONS, "--duration", "900", "--step", "30", "--dut1", "0",
       "--seed", "1", "-q"]


def _targets(tmp_path: Path):
    folder = tmp_path / "a_directory"
    folder.mkdir()
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    return {
        "directory": (str(folder), 2, "is a directory"),
        "under_a_file": (str(plain / "out.parquet"), 2, "not a directory"),
        "deep_under_a_file": (str(plain / "a" / "b" / "out.parquet"), 2, "not a directory"),
        "in_proc": ("/proc/trackproc-hostile/out.parquet", 2, "does not exist"),   # a missing directory: never created
        "dev_full": ("/dev/full", 1, "no space left"),
    }


@pytest.mark.parametrize("target", ["directory", "under_a_file", "deep_under_a_file", "in_proc", "dev_full"])
@pytest.mark.parametrize("command", ["simulate", "propagate", "ingest", "smooth"])
def test_unwritable_output_is_one_line(run_cli, tmp_path, target, command):
    if target == "dev_full" and not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    path, code, needle = _targets(tmp_path)[target]
    args = {
        "simulate": SIM,
        "propagate": ["propagate", TRUTH, "--span", "600", "--step", "60", "--dut1", "0", "-q"],
        "ingest": ["ingest", str(Path(TRUTH).parent / "doppler_pass.csv"), "--stations", STATIONS,
                   "--carrier-hz", "2.2e9", "--mode", "one-way", "-q"],
        "smooth": ["smooth", MULTI, "-q"],
    }[command]
    result = run_cli([*args, "-o", path])
    line = assert_rejected(result, code, needle, folder=tmp_path)
    assert path.split("/")[-1] in line or path in line


def test_read_only_directory(run_cli, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        if os.access(folder, os.W_OK):
            pytest.skip("running as root: a read-only directory is still writable")
        result = run_cli([*SIM, "-o", folder / "out.parquet"])
        assert_rejected(result, 1, "ro/out.parquet", "permission denied", outputs=[folder / "out.parquet"])
    finally:
        folder.chmod(0o700)


def test_second_output_failing_leaves_the_first_unwritten(run_cli, tmp_path):
    # simulate --truth is written first; the pass file then fails: neither may exist
    truth = tmp_path / "truth_out.json"
    folder = tmp_path / "is_a_dir"
    folder.mkdir()
    result = run_cli([*SIM, "--truth", truth, "-o", folder])
    assert_rejected(result, 2, "is_a_dir", outputs=[truth], folder=tmp_path)


def test_smooth_summary_failing_leaves_the_table_unwritten(run_cli, tmp_path):
    out = tmp_path / "smoothed.parquet"
    result = run_cli(["smooth", MULTI, "-q", "-o", out, "--summary", "/dev/full"])
    assert_rejected(result, 1, "/dev/full", outputs=[out], folder=tmp_path)


def test_accuracy_correlation_failing_leaves_nothing(run_cli, tmp_path):
    out = tmp_path / "acc.json"
    plain = tmp_path / "file"
    plain.write_text("")
    result = run_cli(["accuracy", TRUTH, "--span", "600", "--step", "300", "--dut1", "0", "-q", "-o", out,
                      "--sigma-position-m", "100", "--sigma-velocity-m-s", "0.1", "--correlation", plain / "c.csv"])
    assert_rejected(result, 2, "c.csv", outputs=[out], folder=tmp_path)


def test_overwrite_keeps_the_old_file_when_the_run_fails(run_cli, tmp_path):
    out = tmp_path / "out.parquet"
    out.write_bytes(b"old content")
    result = run_cli([*SIM, "--carrier-hz", "2.2", "-o", out])
    assert_rejected(result, 2, "--carrier-hz")
    assert out.read_bytes() == b"old content"
    assert_no_temporaries(tmp_path)


def test_estimate_opm_failing_leaves_the_state_unwritten(run_cli, tmp_path):
    out = tmp_path / "state.json"
    result = run_cli(["estimate", MULTI, "--initial", TRUTH, "--dut1", "0", "-q", "-o", out, "--opm", "/dev/full"])
    assert_rejected(result, 1, "/dev/full", outputs=[out], folder=tmp_path)
