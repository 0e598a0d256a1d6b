"""The ``trackproc`` command: a Typer app whose commands live in sibling modules.

Only typer and the standard library are imported here and in the command modules at import
time; numpy, pandas, scipy and pyarrow are imported inside the commands, so that
``trackproc --help`` stays instant (see ``benchmarks/startup.py``).
"""

from __future__ import annotations

import enum
import logging
import os
import re
import sys
import types
import typing
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
    warnings.showwarning = lambda message, category, *args, **kwargs: log.warning(str(message))
    log.debug("%s: started (pid %d)", ctx.invoked_subcommand, os.getpid())


class _OneLineFormatter(logging.Formatter):
    """One record, one line: control characters from file names, station names or options are
    escaped, so that no input can forge a log line."""

    def format(self, record: logging.LogRecord) -> str:
        from trackproc.cli.guard import one_line

        return one_line(super().format(record), limit=10_000)


def _register() -> None:
    # Each module adds its command(s) to ``app``; keep their top-level imports light.
    from trackproc.cli import commands  # noqa: F401
    _light_coercion()


class _LightCoercion:
    """Typer's runtime coercion of one parameter, without pydantic where the conversion is plain.

    Typer (0.2x) builds a pydantic TypeAdapter for every parameter it processes, including an
    option left at its default; importing pydantic for that is ~60 % of ``trackproc COMMAND
    --help`` and ~50 ms of every command (issue 19). Values whose conversion is unambiguous pass
    here with exactly the result typer's adapter gives (:func:`_plain_value`): None, a value
    already of the annotated type, a string for a ``str`` option, an enum member's exact value,
    a plain decimal number for a number option (within its min/max if it has them). Anything
    else (a bad value, a number out of its range, clamping, a custom parser, ...) goes to typer's own coercion, built on
    first use, so validation and messages stay typer's.
    """

    __slots__ = ("_param", "_build", "_full")

    def __init__(self, param, build):
        self._param, self._build, self._full = param, build, None

    def coerce(self, value, param, ctx):
        if value is None:
            return () if (param.multiple or param.nargs == -1) else None
        if _plain_default(self._param, value, ctx):
            return value
        plain = _plain_value(self._param.type_descriptor, value)
        if plain is not _NOT_PLAIN:
            return plain
        if self._full is None:
            self._full = self._build(self._param)
        return self._full.coerce(value, param=param, ctx=ctx)


def _plain_default(param, value, ctx) -> bool:
    """True for the command's own default (not a config file's) already of the annotated type:
    valid by construction, nothing to convert or check."""
    source = getattr(ctx, "get_parameter_source", lambda name: None)(param.name)
    return (getattr(source, "name", None) == "DEFAULT"
            and type(value) is param.type_descriptor.annotation)


_NOT_PLAIN = object()
#: Spellings whose value every parser agrees on (no "nan", "1_000", hex, surrounding blanks).
_DECIMAL = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d{1,3})?")
_INTEGER = re.compile(r"[+-]?\d{1,18}")


def _plain_value(descriptor, value):
    """``value`` converted as typer's adapter would, or ``_NOT_PLAIN`` when that needs typer."""
    info = descriptor.parameter_info
    if getattr(info, "parser", None) is not None or getattr(info, "click_type", None) is not None:
        return _NOT_PLAIN
    ann = descriptor.annotation
    if typing.get_origin(ann) in (typing.Union, types.UnionType):      # Optional[X]
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        if len(args) != 1:
            return _NOT_PLAIN
        ann = args[0]
    if typing.get_origin(ann) is list and isinstance(value, (list, tuple)):
        args = typing.get_args(ann)
        if len(args) != 1:
            return _NOT_PLAIN
        items = [_plain_leaf(args[0], info, item) for item in value]
        return _NOT_PLAIN if any(item is _NOT_PLAIN for item in items) else items
    return _plain_leaf(ann, info, value)


def _plain_leaf(ann, info, value):
    if ann is bool:
        return value if isinstance(value, bool) else _NOT_PLAIN
    if ann is str:
        return value if isinstance(value, str) else _NOT_PLAIN
    if isinstance(ann, type) and issubclass(ann, enum.Enum):
        if isinstance(value, ann):
            return value
        if isinstance(value, str):
            try:
                return ann(value)            # an exact member value: the member typer would give
            except ValueError:
                return _NOT_PLAIN
        return _NOT_PLAIN
    if ann in (int, float):
        if getattr(info, "clamp", False):
            return _NOT_PLAIN                # clamping: typer's adapter does it
        if type(value) is ann:
            number = value
        elif not isinstance(value, str):
            return _NOT_PLAIN
        elif ann is int:
            if not _INTEGER.fullmatch(value):
                return _NOT_PLAIN
            number = int(value)
        elif _DECIMAL.fullmatch(value) and float(value) - float(value) == 0.0:     # finite
            number = float(value)
        else:
            return _NOT_PLAIN
        lo, hi = getattr(info, "min", None), getattr(info, "max", None)
        if (lo is not None and not number >= lo) or (hi is not None and not number <= hi):
            return _NOT_PLAIN                # out of range: typer's adapter says so, in its words
        return number
    return _NOT_PLAIN


def _light_coercion() -> None:
    """Install :class:`_LightCoercion` on typer's parameter class (once; a typer without this
    hook keeps its own behaviour)."""
    core = sys.modules.get("typer.core")
    cls = getattr(core, "_TyperParameter", None)
    builder = getattr(core, "build_runtime_param", None)
    if (cls is None or builder is None or not hasattr(cls, "get_runtime_param")
            or getattr(cls.get_runtime_param, "_trackproc_light", False)):
        return

    def build(param):
        return builder(param.type_descriptor)

    def get_runtime_param(self):
        if getattr(self, "_runtime_param", None) is None:
            self._runtime_param = _LightCoercion(self, build)
        return self._runtime_param

    get_runtime_param._trackproc_light = True
    cls.get_runtime_param = get_runtime_param


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
