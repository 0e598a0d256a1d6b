"""Start-up path (issue 19): ``trackproc COMMAND --help`` imports neither pydantic nor the numeric
stack, and typer's own coercion still runs for values that need converting."""

import subprocess
import sys

import pytest

from trackproc.cli.app import main

HEAVY = ("pydantic", "numpy", "scipy", "pandas", "pyarrow")


@pytest.mark.subprocess
@pytest.mark.parametrize("command", ["refine", "estimate", "batch", "ingest"])
def test_command_help_imports_nothing_heavy(command):
    probe = ("import io, sys; from trackproc.cli import app as a; out = sys.stdout; "
             f"sys.stdout = io.StringIO(); code = a._main([{command!r}, '--help']); "
             "text = sys.stdout.getvalue(); sys.stdout = out; "
             f"print(code, 'Usage:' in text, *[m for m in {HEAVY!r} if m in sys.modules])")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["0", "True"], res.stdout + res.stderr


def test_values_still_validated_by_typer(capsys):
    # a float below its minimum and a non-number: typer's (pydantic) coercion, exit 2, one line
    assert main(["refine", "p.csv", "--initial", "s.json", "--circular-tolerance", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--circular-tolerance" in err and "greater than or equal to 0" in err
    assert main(["refine", "p.csv", "--initial", "s.json", "--max-iterations", "abc"]) == 2
    assert "valid integer" in capsys.readouterr().err
