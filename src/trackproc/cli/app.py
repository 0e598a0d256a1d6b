"""The ``trackproc`` command: a Typer app whose commands live in sibling modules.

Only typer and the standard library are imported here and in the command modules at import
time; numpy, pandas, scipy and pyarrow are imported inside the commands, so that
``trackproc --help`` stays instant (see ``benchmarks/startup.py``).
"""

from __future__ import annotations

import logging
import os
import sys
import warnings

import typer

from trackproc import __version__
from trackproc.errors import EXIT_INPUT

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
                                     help="CSV outputs without the '# trackproc: {...}' first line (plain "
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


def _register() -> None:
    # Each module adds its command(s) to ``app``; keep their top-level imports light.
    from trackproc.cli import coercion, commands  # noqa: F401
    coercion.install()


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point: runs the app, maps every failure to an exit code and one line
    on stderr (the guard of issue 14: no traceback, whatever the input).

    Called without ``argv`` (as the ``trackproc`` script), the process ends here by ``os._exit``
    once stdout, stderr and the log are flushed: the interpreter's own teardown of Arrow's C++
    threads aborted the process (exit 134, "terminate called without an active exception") in a
    few percent of runs after an input error (and a serial ``batch`` stopped by SIGTERM: exit 134
    for 143). A process that made a process pool (``batch`` with workers: its semaphores are
    unlinked by the pool's finalizers) or still has children keeps the normal exit.
    """
    if argv is None:
        _one_blas_thread()
        code = _main(sys.argv[1:])
        if "multiprocessing.synchronize" not in sys.modules and not _has_children():
            _hard_exit(code)
        return code
    return _main(argv)


#: BLAS thread variables: one thread unless the user says otherwise.
_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _one_blas_thread() -> None:
    """One BLAS thread per process unless the environment says otherwise, set before numpy loads:
    trackproc's matrices are small (a pass: ~1000 x 10), and a multi-threaded BLAS on a loaded
    2-core machine made the noise model's Choleskys ~25x and smoothing's QR ~200x slower (measured
    while developing issue 13); batch sets the same per worker."""
    if "numpy" not in sys.modules:
        for name in _BLAS_THREADS:
            os.environ.setdefault(name, "1")


#: numpy submodules no trackproc command uses, which scipy imports only to copy their names
_UNUSED_NUMPY_MODULES = ("numpy.f2py", "numpy.testing")


def _defer_unused_numpy_modules() -> None:
    """Make :data:`_UNUSED_NUMPY_MODULES` lazy modules (``importlib.util.LazyLoader``: loaded
    on first attribute access) before scipy loads. scipy >= 1.15 copies numpy's namespace when
    it starts (``scipy._lib.array_api_compat.clone_module``: ``hasattr(numpy, name)`` for every
    name), which imports them: ~45 ms of CPU in every command that uses scipy (issue 19). Any
    failure leaves numpy as it is."""
    if any(name in sys.modules for name in _UNUSED_NUMPY_MODULES) or "scipy" in sys.modules:
        return
    try:
        import importlib.util

        import numpy

        for name in _UNUSED_NUMPY_MODULES:
            spec = importlib.util.find_spec(name)
            if spec is None or spec.loader is None:
                continue
            spec.loader = importlib.util.LazyLoader(spec.loader)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
            setattr(numpy, name.rpartition(".")[2], module)
    except Exception:  # noqa: BLE001 - only a start-up saving: never a reason to fail
        pass


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
    if command is not None and not any(a in ("--help", "-h") for a in argv):
        _defer_unused_numpy_modules()
    stdout = sys.stdout
    restore = guard.install_signal_handlers()
    try:
        # A command with several outputs writes all of them or none; batch commits per input
        # (a killed run resumes from what is done), so it opts out.
        with guard.outputs_all_or_none(enabled=command != "batch") as outputs:
            from trackproc.cli.config import config_path, default_map
            from trackproc.cli.progress import ticker

            # a config file is checked against every command's options: then all of them
            root = plain_help(_click_group(command if config_path() is None else None))
            with ticker(command, enabled=not any(a in ("-q", "--quiet") for a in argv)):
                result = root(args=argv, prog_name="trackproc", standalone_mode=False,
                              default_map=default_map(root))
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


def _command_name(argv: list[str]) -> str | None:
    """The subcommand named in ``argv`` (after the hoisted global flags), or None."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg
    return None


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


_GLOBAL_FLAGS = ("--quiet", "-q", "--verbose", "-v", "--no-metadata")


def _hoist_global_flags(argv: list[str]) -> list[str]:
    """Let ``--quiet``/``--verbose``/``--no-metadata`` follow the command too (``trackproc ingest x.csv -q``):
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
