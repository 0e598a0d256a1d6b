"""Durations with units (``90s``, ``45m``, ``1.5h``, ``2d``) on every option that takes one, read by
one function (``trackproc.types.checks.parse_duration``); a plain number keeps the option's unit."""

import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from trackproc.cli.app import main
from trackproc.errors import InputError
from trackproc.types.checks import parse_duration

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data"


@pytest.mark.parametrize("text, seconds", [("3600", 3600.0), ("90s", 90.0), ("45m", 2700.0), ("5min", 300.0),
                                           ("1.5h", 5400.0), ("2d", 172800.0), ("-1d", -86400.0), (".5h", 1800.0),
                                           ("1e3", 1000.0), (" 2 d ", 172800.0), (600, 600.0)])
def test_parse_duration(text, seconds):
    assert parse_duration(text, "--span") == seconds


def test_plain_number_in_the_options_own_unit():
    assert parse_duration("1.5", "--horizon", plain_unit_s=86400.0) == 1.5 * 86400.0
    assert parse_duration("12h", "--horizon", plain_unit_s=86400.0) == 12 * 3600.0


@pytest.mark.parametrize("text", ["1x", "abc", "", "h", "nan", "inf", "1e999", "1 day"])
def test_bad_duration_names_the_option(text):
    with pytest.raises(InputError) as caught:
        parse_duration(text, "--span")
    assert "option '--span'" in str(caught.value) and "column" not in str(caught.value)


def test_propagate_accepts_a_day_as_1d(tmp_path, capsys):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    assert main(["-q", "propagate", str(SAMPLE / "truth.json"), "--span", "1d", "--step", "1h", "-o", str(a)]) == 0
    assert main(["-q", "propagate", str(SAMPLE / "truth.json"), "--span", "86400", "--step", "3600", "-o", str(b)]) == 0
    ta, tb = pq.read_table(a), pq.read_table(b)
    assert ta.num_rows == 25 and ta.equals(tb)


@pytest.mark.parametrize("args", [
    ["simulate", "--state", str(SAMPLE / "truth.json"), "--stations", str(SAMPLE / "stations.csv"),
     "--duration", "10m", "--step", "1m"],
    ["accuracy", str(SAMPLE / "stale.json"), "--span", "1h", "--step", "30m", "--format", "csv"],
])
def test_units_on_simulate_and_accuracy(tmp_path, capsys, args):
    out = tmp_path / "out"
    assert main(["-q", *args, "-o", str(out)]) == 0


def test_usage_error_calls_the_option_an_option(run_cli):
    result = run_cli(["propagate", str(SAMPLE / "truth.json"), "--span", "1 week", "--step", "60"])
    assert result.exit_code == 2 and "option '--span'" in result.stderr and "column" not in result.stderr
