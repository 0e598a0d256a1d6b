"""The ``trackproc(1)`` manual page, generated from the commands' own help (issue 16).

``python -m trackproc.cli.manpage > docs/trackproc.1`` writes it; ``tests/cli/test_help.py`` checks the
shipped page is current, so the page and ``--help`` never disagree. Read it with
``man docs/trackproc.1`` (or install it under ``share/man/man1``).
"""

from __future__ import annotations

import inspect


def _roff(text: str) -> str:
    """Text safe for roff: backslashes as ``\\e``, a leading dot or quote escaped."""
    lines = []
    for line in text.replace("\\", "\\e").splitlines():
        if line.startswith((".", "'")):
            line = "\\&" + line
        lines.append(line)
    return "\n".join(lines)


def _paragraphs(help_text: str) -> str:
    """Help paragraphs as roff: indented ones (shell examples) verbatim, the others filled."""
    out = []
    for para in inspect.cleandoc(help_text or "").split("\n\n"):
        lines = [line for line in para.splitlines() if line.strip() != "\b"]
        if not lines:
            continue
        if all(line.startswith("    ") for line in lines if line.strip()):
            out.append(".PP\n.nf\n.RS 4\n" + _roff(inspect.cleandoc("\n".join(lines))) + "\n.RE\n.fi")
        else:
            out.append(".PP\n" + _roff(" ".join(line.strip() for line in lines)))
    return "\n".join(out)


def _options(command, ctx) -> list[str]:
    parts = []
    for param in command.get_params(ctx):
        record = param.get_help_record(ctx)
        if record:
            parts += [".TP", f"\\fB{_roff(record[0])}\\fR", _roff(record[1])]
    return parts


def manpage() -> str:
    """The page, from the same command tree (and the same plain help) as ``trackproc --help``."""
    from typer.main import get_command

    from trackproc import __version__
    from trackproc.cli.app import _register, app, plain_help

    _register()
    root = plain_help(get_command(app))
    ctx = root.context_class(root, info_name="trackproc")   # typer vendors click: its own classes
    parts = [f'.TH TRACKPROC 1 "" "trackproc {__version__}" "User Commands"',
             ".SH NAME", "trackproc \\- satellite tracking passes in, orbits with honest error matrices out",
             ".SH SYNOPSIS", ".B trackproc", "[\\fIOPTIONS\\fR] \\fICOMMAND\\fR [\\fIARGS\\fR]...",
             ".SH DESCRIPTION", _paragraphs(root.help or ""), ".SH OPTIONS", *_options(root, ctx),
             ".SH COMMANDS"]
    for name, cmd in root.commands.items():
        sub = cmd.context_class(cmd, info_name=name, parent=ctx)
        usage = " ".join(cmd.collect_usage_pieces(sub))
        parts += [f'.SS "trackproc {name}"', ".PP", f"\\fBtrackproc {name}\\fR {_roff(usage)}",
                  _paragraphs((cmd.help or "").partition("\f")[0]), *_options(cmd, sub)]
    parts += [".SH EXIT STATUS",
              "0 success; 1 processing failure (or a solution whose quality verdict is rejected, or suspect "
              "with \\-\\-strict); 2 usage error or invalid input; 3 partial failure in batch; 128+N ended by "
              "signal N; 141 stdout closed by the reader.",
              ".SH FILES", "~/.config/trackproc/config.toml (or $TRACKPROC_CONFIG): defaults for every command.",
              ".SH SEE ALSO", "The README and docs/ of the trackproc repository."]
    return "\n".join(parts) + "\n"


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.stdout.write(manpage())
