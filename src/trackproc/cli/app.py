"""The ``trackproc`` command: the entry point of a Typer app (cli/root.py) whose commands live in
sibling modules.

Only the standard library is imported here (and ``pipeline/lazy_numpy.py``, which imports only it):
``trackproc --version`` and a ``--help`` already rendered once (cli/help_cache.py) are answered without typer; the command modules import only
typer and the standard library at import time, and numpy, pandas, scipy and pyarrow inside the
commands (see ``benchmarks/startup.py``). The names of cli/root.py (``app``, ``plain_help``, ...)
are also reachable here, imported when first used.
"""

from __future__ import annotations

import os
import sys

from trackproc import __version__
from trackproc.errors import EXIT_INPUT
# standard library only, shared with a batch's fork server (pipeline/batch/preload.py)
from trackproc.pipeline.lazy_numpy import UNUSED_NUMPY_MODULES as _UNUSED_NUMPY_MODULES  # noqa: F401 - tests
from trackproc.pipeline.lazy_numpy import defer_unused_numpy_modules as _defer_unused_numpy_modules


def __getattr__(name: str):
    # ``from trackproc.cli.app import app`` (the command modules, the tests): typer on first use
    if name.startswith("__"):
        raise AttributeError(name)
    from trackproc.cli import root

    try:
        return getattr(root, name)
    except AttributeError:
        raise AttributeError(f"module 'trackproc.cli.app' has no attribute {name!r}") from None


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
    if "logging" in sys.modules:
        sys.modules["logging"].shutdown()
    os._exit(code)


def _main(argv: list[str]) -> int:
    if argv in (["--version"], ["-V"]):
        return _write(f"trackproc {__version__}\n")
    from trackproc.cli import help_cache

    request = help_cache.request(argv)
    if request is None:
        return _run(argv)
    text = request.lookup()
    if text is not None:
        return _write(text)
    # rendered by typer into a buffer, then printed and kept for the next time
    stdout, sys.stdout = sys.stdout, help_cache.Capture()
    try:
        code = _run(argv)
    finally:
        text, sys.stdout = sys.stdout.getvalue(), stdout
    if code == 0 and text:
        request.store(text)
    return _write(text) or code


def _write(text: str) -> int:
    try:
        sys.stdout.write(text)
    except BrokenPipeError:
        return _broken_pipe()
    return _flush_stdout()


def _run(argv: list[str]) -> int:
    from trackproc.cli import guard
    from trackproc.cli.root import _click_group, _register, plain_help

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
            one = command if config_path() is None else None
            _register(one)
            root = plain_help(_click_group(one))
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


def _command_name(argv: list[str]) -> str | None:
    """The subcommand named in ``argv`` (after the hoisted global flags), or None."""
    for arg in argv:
        if arg == "--":
            return None
        if not arg.startswith("-"):
            return arg
    return None


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
