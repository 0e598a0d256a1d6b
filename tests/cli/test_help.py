"""Help that reads in a pipe (issue 16): at 80 columns no option name is cut, no box characters,
no Python types as metavars, and the shell examples are printed as written (never wrapped)."""

import re
from pathlib import Path

import pytest

from trackproc.cli.app import main

COMMANDS = ["ingest", "info", "simulate", "propagate", "smooth", "estimate", "refine", "accuracy",
            "requirements", "detect", "batch", "passes", "compare", "identify", "fit-tle", "filter", "help"]


def _help(args, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    assert main(args + ["--help"]) == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("command", [[]] + [[c] for c in COMMANDS])
def test_help_is_plain_at_80_columns(command, capsys, monkeypatch):
    text = _help(command, capsys, monkeypatch)
    assert "…" not in text
    assert not re.search("[\u2500-\u257f]", text), "box-drawing characters in help"
    # readable metavars: never a Python type label such as <str>, <float>, <list[str]>, <bool>
    assert not re.search(r"<(str|float|int|bool|path|list\[\w+\]|\w+ range)>", text), text
    if command:
        # every option of the command is listed with its full name
        from typer.main import get_command

        from trackproc.cli.app import _register, app
        _register()
        cmd = get_command(app).commands[command[0]]
        for param in cmd.params:
            for opt in getattr(param, "opts", []):
                if opt.startswith("--") and not param.hidden:
                    assert opt in text, f"{opt} missing from {command[0]} --help"


@pytest.mark.parametrize("command", COMMANDS)
def test_help_examples_are_not_wrapped(command, capsys, monkeypatch):
    from typer.main import get_command

    from trackproc.cli.app import _register, app
    _register()
    doc = get_command(app).commands[command].help or ""
    text = _help([command], capsys, monkeypatch)
    for line in doc.splitlines():
        if line.strip().startswith("trackproc "):
            assert line.strip() in text, f"example line rewrapped in {command} --help: {line.strip()}"


def test_version_short_flag(capsys):
    assert main(["-V"]) == 0
    assert capsys.readouterr().out.startswith("trackproc ")


def test_manual_page_is_current():
    """docs/trackproc.1 is generated from the same help (python -m trackproc.cli.manpage): a change
    of an option or a docstring without regenerating it fails here."""
    from pathlib import Path

    from trackproc.cli.manpage import manpage

    shipped = (Path(__file__).resolve().parents[2] / "docs" / "trackproc.1").read_text()
    assert manpage() == shipped, "regenerate: python -m trackproc.cli.manpage > docs/trackproc.1"
    assert '.SS "trackproc refine"' in shipped and ".SH EXIT STATUS" in shipped


def test_help_command_prints_what_cmd_help_prints(capsys, monkeypatch):
    """``trackproc help CMD`` is ``trackproc CMD --help``, word for word; ``--man`` the shipped page."""
    monkeypatch.setenv("COLUMNS", "80")
    for command in ("estimate", "passes", "info"):
        assert main(["help", command]) == 0
        via_help = capsys.readouterr().out
        assert main([command, "--help"]) == 0
        assert via_help == capsys.readouterr().out
    assert main(["help", "--man"]) == 0
    assert capsys.readouterr().out == (Path(__file__).resolve().parents[2] / "docs" / "trackproc.1").read_text()


def test_help_for_an_unknown_command_names_the_nearest(run_cli):
    result = run_cli(["help", "estmate"])
    assert result.exit_code == 2 and "did you mean estimate?" in result.stderr and "Traceback" not in result.stderr
