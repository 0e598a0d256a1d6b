"""The Typer app of ``trackproc`` and its root callback: imported when a command runs or its
help is rendered (cli/app.py keeps the entry point light: a cached ``--help`` needs neither
typer nor logging)."""

from __future__ import annotations

import logging
import os
import sys
import warnings

import typer

from trackproc import __version__

app = typer.Typer(
    name="trackproc",
    help="Satellite tracking passes in, orbits with honest error matrices out.",
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    add_completion=True,
    no_args_is_help=True,
    context_settings={"help_option_names": ["-h", "--help"]},
)

log = logging.getLogger("trackproc")


def _version(value: bool) -> None:
    if value:
        typer.echo(f"trackproc {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    version: bool = typer.Option(False, "--version", "-V", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only errors on stderr."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Progress and debug messages on stderr."),
    no_metadata: bool = typer.Option(False, "--no-metadata",
                                     help="CSV outputs without the '# trackproc: {...}' metadata block (plain "
                                          "CSV for spreadsheets; also TRACKPROC_CSV_METADATA=0)."),
) -> None:
    """Satellite tracking passes in, orbits with honest error matrices out.

    Exit codes: 0 ok, 1 processing failure, 2 usage or invalid input,
    3 partial failure in batch.
    """
    if no_metadata:
        os.environ["TRACKPROC_CSV_METADATA"] = "0"   # read by the CSV writers (io.tabular.csv_metadata_line)
    # Quiet by default: warnings, errors and the commands' own summaries. batch keeps its per-input
    # INFO lines (the cron log is its record of what was done).
    default = logging.INFO if ctx.invoked_subcommand == "batch" else logging.WARNING
    level = logging.ERROR if quiet else logging.DEBUG if verbose else default
    if os.environ.get("TRACKPROC_LOG_LEVEL"):
        level = os.environ["TRACKPROC_LOG_LEVEL"].upper()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLineFormatter("trackproc: %(levelname)s: %(message)s"))
    logging.basicConfig(level=level, handlers=[handler], force=True)
    # warnings of the lower layers (e.g. dates beyond the EOP table) as one log line each
    _WARNED.clear()
    warnings.showwarning = _show_warning
    log.debug("%s: started (pid %d)", ctx.invoked_subcommand, os.getpid())


_WARNED: set = set()
#: ERFA's "dubious year" (UTC before 1960 or far beyond the leap-second table), in our words.
DUBIOUS_YEAR = ("a date before 1960 or far in the future: UTC is not defined there and the leap-second table "
                "does not reach it (ERFA's 'dubious year'); times are uncertain by seconds")


def _show_warning(message, category, *args, **kwargs) -> None:
    """A lower layer's warning as one log line, each text once per run; ERFA's raw
    "dubious year" warnings (one per function) become one line in our words."""
    text = str(message)
    if "dubious year" in text:
        text = DUBIOUS_YEAR
    if text in _WARNED:
        return
    _WARNED.add(text)
    log.warning("%s", text)


class _OneLineFormatter(logging.Formatter):
    """One record, one line: control characters from file names, station names or options are
    escaped, so that no input can forge a log line."""

    def format(self, record: logging.LogRecord) -> str:
        from trackproc.cli.guard import one_line

        return one_line(super().format(record), limit=10_000)


#: The module of each command (cli/commands.py imports them all).
COMMAND_MODULES = {"ingest": "ingest_cmd", "info": "info_cmd", "simulate": "simulate_cmd",
                   "propagate": "propagate_cmd", "smooth": "smooth_cmd", "estimate": "estimate_cmd",
                   "refine": "refine_cmd", "accuracy": "accuracy_cmd", "requirements": "requirements_cmd",
                   "detect": "detect_cmd", "batch": "batch_cmd", "passes": "passes_cmd", "compare": "compare_cmd",
                   "identify": "identify_cmd", "fit-tle": "fit_tle_cmd", "filter": "filter_cmd", "help": "help_cmd",
                   "import-orekit": "import_orekit_cmd"}


def _register(command: str | None = None) -> None:
    """Add the commands to ``app`` (each module adds its own; keep their top-level imports light):
    only ``command``'s module when it names one (the other fourteen cost ~13 ms of CPU in every
    run), else all of them."""
    import importlib

    from trackproc.cli import coercion

    if command in COMMAND_MODULES:
        importlib.import_module(f"trackproc.cli.{COMMAND_MODULES[command]}")
    else:
        from trackproc.cli import commands  # noqa: F401
    coercion.install()


def _click_group(command: str | None):
    """The click group of the app; with only ``command`` in it when that names a command (typer
    builds every command's parameters, ~12 ms of each run, for one of them)."""
    registered = app.registered_commands
    if command not in {c.name for c in registered}:
        return typer.main.get_command(app)     # the top-level help, completion, an unknown name
    app.registered_commands = [c for c in registered if c.name == command]
    try:
        return typer.main.get_command(app)
    finally:
        app.registered_commands = registered


#: Typer's own type labels (``<float>``) -> the metavars a Unix reader expects.
_METAVARS = {"str": "TEXT", "float": "FLOAT", "int": "INTEGER", "bool": "BOOLEAN", "path": "PATH",
             "float range": "FLOAT", "int range": "INTEGER", "datetime": "TIME",
             "list[str]": "TEXT", "list[float]": "FLOAT", "list[int]": "INTEGER"}


def plain_help(command):
    """Help that reads in a pipe and at any width (issue 16): readable metavars (``FLOAT``,
    ``[a|b]`` for choices, never a Python type), arguments shown by name alone, and the indented
    shell examples of a docstring kept verbatim (click's ``\\b`` paragraphs) instead of rewrapped
    mid-command. Plain click formatting (no boxes) is set on the app itself."""
    for param in getattr(command, "params", []):
        kind = getattr(param, "param_type_name", "")
        if kind == "argument":
            param.display_type_rich = lambda ctx: None
        elif (kind == "option" and not getattr(param, "is_flag", False) and param.metavar is None
              and hasattr(param, "display_type")):
            # the command's own context class: typer vendors click (no click import here)
            label = param.display_type(command.context_class(command)).strip("<>")
            param.metavar = _METAVARS.get(label) or (f"[{label}]" if "|" in label else label.upper() or None)
    if getattr(command, "help", None):
        command.help = _keep_examples(command.help)
    for sub in getattr(command, "commands", {}).values():
        plain_help(sub)
    return command


def _keep_examples(text: str) -> str:
    """Mark each indented paragraph of a docstring (a shell example) with click's ``\\b`` so it is
    printed as written."""
    import inspect

    out = []
    for para in inspect.cleandoc(text).split("\n\n"):
        lines = para.split("\n")
        if lines[0] != "\b" and all(l.startswith("    ") for l in lines if l.strip()):
            para = "\b\n" + para
        out.append(para)
    return "\n\n".join(out)
