"""Hostile class: usage errors and bad option values are one line on stderr, exit 2 (issue 14)."""

from __future__ import annotations

import pytest

from hostile import STATIONS, TRUTH, assert_rejected

SIM = ["simulate", "--state", TRUTH, "--stations", STATIONS, "--duration", "600", "--step", "10"]


@pytest.mark.parametrize("args, needles", [
    (["ingest", "--no-such-flag", "x.csv"], ["ingest", "--no-such-flag"]),
    (["ingest"], ["ingest", "INPUT"]),
    (["info"], ["info"]),
    (["no-such-command"], ["no-such-command"]),
    (["propagate", TRUTH, "--span", "abc", "--step", "60"], ["--span"]),
    (["propagate", TRUTH, "--span", "600", "--step", "60", "--force", "n-body"], ["--force"]),
    (["smooth", "x.parquet", "--degree"], ["--degree"]),
    ([*SIM, "--seed", "-1"], ["--seed"]),
    ([*SIM, "--seed", "1e3"], ["--seed"]),
    ([*SIM, "--seed", str(2 ** 70)], ["--seed"]),
    ([*SIM, "--mode", "three-way"], ["--mode"]),
    ([*SIM, "--dut1", "nan"], ["--dut1", "nan"]),
    ([*SIM, "--dut1", "inf"], ["--dut1"]),
    ([*SIM, "--dut1", "1.5"], ["--dut1"]),
    ([*SIM, "--dut1", "abc"], ["--dut1"]),
    ([*SIM, "--step", "0"], ["--step"]),
    ([*SIM, "--duration", "-5"], ["--duration"]),
    (["accuracy", TRUTH, "--span", "600", "--step", "60", "--seed", "-3"], ["--seed"]),
    (["requirements", "--no-such"], ["requirements"]),
    (["detect"], ["detect"]),
])
def test_usage_error_is_one_line_exit_2(run_cli, tmp_path, args, needles):
    out = tmp_path / "out.parquet"
    result = run_cli([*args, "-q", "-o", out] if args and args[0] == "simulate" else [*args])
    assert_rejected(result, 2, *needles, outputs=[out], folder=tmp_path)


def test_bare_command_shows_help_and_one_error_line_on_stderr(run_cli):
    result = run_cli([])
    assert result.exit_code == 2
    assert "Traceback" not in result.stderr
    assert sum(line.startswith("trackproc: error:") for line in result.stderr.splitlines()) == 1


@pytest.mark.parametrize("exc, code, needle", [
    (RuntimeError("unexpected\nsecond line"), 1, "internal error (RuntimeError): unexpected\\nsecond line"),
    (MemoryError(), 1, "out of memory"),
    (RecursionError("deep"), 2, "nested too deeply"),
    (OSError(5, "Input/output error", "/mnt/x"), 1, "/mnt/x: input/output error"),
])
def test_unexpected_exception_is_one_line(run_cli, monkeypatch, exc, code, needle):
    """The guard's last resort: whatever escapes a command is one escaped line and an exit code."""
    from hostile import MULTI
    from trackproc.pipeline import info

    def boom(*args, **kwargs):
        raise exc

    monkeypatch.setattr(info, "summarize", boom)
    result = run_cli(["info", MULTI, "-q"])
    assert_rejected(result, code, needle)
