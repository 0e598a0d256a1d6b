"""``trackproc help [CMD]``: a command's full help (what ``trackproc CMD --help`` prints), or the
whole manual page (``--man``: roff, for ``man -l -``), wherever trackproc is installed."""

from __future__ import annotations

from typing import Optional

import typer

from trackproc.cli.app import app


@app.command("help")
def help_command(
    command: Optional[str] = typer.Argument(None, metavar="[CMD]", help="The command to explain; none: the list."),
    man: bool = typer.Option(False, "--man", help="The whole manual page (roff): trackproc help --man | man -l -"),
) -> None:
    """Print a command's full help (its options, examples and exit codes, as CMD --help shows them),
    the list of commands, or with --man the whole manual page trackproc(1) in roff, which needs no
    installation under share/man: read it with man ./trackproc.1 or trackproc help --man | man -l -.

    Examples:

        trackproc help estimate

        trackproc help --man > trackproc.1
    """
    import difflib
    import sys

    from trackproc.cli import commands  # noqa: F401  (every command: the start-up registers only this one)
    from trackproc.cli.app import plain_help

    if man:
        from trackproc.cli.manpage import manpage

        sys.stdout.write(manpage())
        return
    root = plain_help(typer.main.get_command(app))
    names = ["-h", "--help"]                       # the app's own help options, as CMD --help shows them
    ctx = root.context_class(root, info_name="trackproc", help_option_names=names)
    if command is None:
        sys.stdout.write(root.get_help(ctx) + "\n")
        return
    sub = root.commands.get(command)
    if sub is None:
        known = sorted(root.commands)
        near = difflib.get_close_matches(command, known, n=1)
        hint = f" (did you mean {near[0]}?)" if near else ""
        raise typer.BadParameter(f"no command {command!r}{hint}; commands: {', '.join(known)}", param_hint="CMD")
    sys.stdout.write(sub.get_help(sub.context_class(sub, info_name=command, parent=ctx, help_option_names=names))
                     + "\n")
