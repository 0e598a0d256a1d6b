"""The ``trackproc`` command: a Typer app whose commands live in sibling modules.

Only typer and the standard library are imported here and in the command modules at import
time; numpy, pandas, scipy and pyarrow are imported inside the commands, so that
``trackproc --help`` stays instant (see ``benchmarks/startup.py``).
"""

from __future__ import annotations

import logging
import os
import sys

import typer

from trackproc import __version__
from trackproc.errors import EXIT_INPUT

app = typer.Typer(
    name="trackproc",
    help="Satellite tracking passes in, orbits with honest error matrices out.",
    pretty_exceptions_enable=False,
    add_completion=False,
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
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only errors on stderr."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Debug messages on stderr."),
) -> None:
    """Satellite tracking passes in, orbits with honest error matrices out.

    Exit codes: 0 ok, 1 processing failure, 2 usage or invalid input,
    3 partial failure in batch.
    """
    level = logging.ERROR if quiet else logging.DEBUG if verbose else logging.INFO
    if os.environ.get("TRACKPROC_LOG_LEVEL"):
        level = os.environ["TRACKPROC_LOG_LEVEL"].upper()
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_OneLineFormatter("trackproc: %(levelname)s: %(message)s"))
    logging.basicConfig(level=level, handlers=[handler], force=True)
    logging.captureWarnings(True)   # library warnings (ERFA's "dubious year") as one escaped log line


class _OneLineFormatter(logging.Formatter):
    """One record, one line: control characters from file names, station names or options are
    escaped, so that no input can forge a log line."""

    def format(self, record: logging.LogRecord) -> str:
        from trackproc.cli.guard import one_line

        return one_line(super().format(record), limit=10_000)


def _register() -> None:
    # Each module adds its command(s) to ``app``; keep their top-level imports light.
    from trackproc.cli import commands  # noqa: F401


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point: runs the app, maps every failure to an exit code and one line
    on stderr (the guard of issue 14: no traceback, whatever the input).

    Called without ``argv`` (as the ``trackproc`` script), the process ends here by ``os._exit``
    once stdout, stderr and the log are flushed: the interpreter's own teardown of Arrow's C++
    threads aborted the process (exit 134, "terminate called without an active exception") in a
    few percent of runs after an input error. ``batch`` keeps the normal exit (its pool's
    finalizers must run).
    """
    if argv is None:
        code = _main(sys.argv[1:])
        if _command_name(_hoist_global_flags(sys.argv[1:])) != "batch" and not _has_children():
            _hard_exit(code)
        return code
    return _main(argv)


def _has_children() -> bool:
    mp = sys.modules.get("multiprocessing")
    try:
        return bool(mp is not None and mp.active_children())
    except Exception:  # noqa: BLE001 - be conservative: keep the normal exit
        return True


def _hard_exit(code: int) -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    logging.shutdown()
    os._exit(code)


def _main(argv: list[str]) -> int:
    from trackproc.cli import guard

    _register()
    argv = _hoist_global_flags(list(argv))
    command = _command_name(argv)
    stdout = sys.stdout
    restore = guard.install_signal_handlers()
    try:
        # A command with several outputs writes all of them or none; batch commits per input
        # (a killed run resumes from what is done), so it opts out.
        with guard.outputs_all_or_none(enabled=command != "batch") as outputs:
            result = app(args=argv, prog_name="trackproc", standalone_mode=False)
            code = result if isinstance(result, int) and not isinstance(result, bool) else 0
            outputs.commit_if(code == 0)
    except SystemExit as exit_:
        if sys.stdout is not stdout:
            # click met EPIPE on stdout, swapped in a pacifying wrapper and exits 1: the reader went away
            return _broken_pipe()
        code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        flushed = _flush_stdout()
        return flushed or code
    except BrokenPipeError:
        return _broken_pipe()
    except BaseException as exc:  # noqa: BLE001 - the one place every failure becomes one line
        _flush_stdout()
        message, code = guard.describe(exc, command)
        guard.print_error(message)
        return code
    finally:
        restore()
    return _flush_stdout() or code


def _command_name(argv: list[str]) -> str | None:
    """The subcommand named in ``argv`` (after the hoisted global flags), or None."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg
    return None


_GLOBAL_FLAGS = ("--quiet", "-q", "--verbose", "-v")


def _hoist_global_flags(argv: list[str]) -> list[str]:
    """Let ``--quiet``/``--verbose`` follow the command too (``trackproc ingest x.csv -q``):
    they are moved before it, where the root callback reads them (up to a ``--``)."""
    end = argv.index("--") if "--" in argv else len(argv)
    flags = [a for a in argv[:end] if a in _GLOBAL_FLAGS]
    rest = [a for a in argv[:end] if a not in _GLOBAL_FLAGS]
    return flags + rest + argv[end:]


def _flush_stdout() -> int:
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return _broken_pipe()
    return 0


def _broken_pipe() -> int:
    """The reader closed stdout early (``trackproc ... | head``): stop quietly, as Unix tools do."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 141


def run() -> None:  # pragma: no cover - thin wrapper for ``python -m trackproc``
    sys.exit(main())


__all__ = ["app", "main", "EXIT_INPUT"]
