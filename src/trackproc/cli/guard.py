"""The top-level guard: every failure of a command becomes one line on stderr and an exit code.

``trackproc: error: <file>: <what>; expected <what>`` — never a traceback, a Click box or a
half-written output (issue 14). Exit codes follow :mod:`trackproc.errors`; a signal exits
128 + its number after every temporary output is removed. Standard library only (the CLI layer
stays light).
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import sys
from typing import Callable, Iterator

from trackproc.errors import EXIT_INPUT, EXIT_PROCESSING, Terminated, TrackprocError

#: The longest error line printed (a message quoting a huge cell or path is cut).
MAX_MESSAGE = 1000

_CONTROL = re.compile(r"[\x00-\x1f\x7f\u0085\u2028\u2029]")


def one_line(text: str, limit: int = MAX_MESSAGE) -> str:
    """``text`` with every control character escaped (a newline in a file or option name can
    never forge a second line), cut to ``limit`` characters."""
    text = _CONTROL.sub(lambda m: repr(m.group())[1:-1] if m.group() != "\x7f" else "\\x7f", str(text))
    if len(text) > limit:
        text = text[:limit] + f"... ({len(text)} characters)"
    return text


def print_error(message: str) -> None:
    try:
        print(f"trackproc: error: {one_line(message)}", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr closed: the exit code still tells
        pass


def describe(exc: BaseException, command: str | None) -> tuple[str, int]:
    """The one-line message and the exit code for any exception escaping a command."""
    from typer import _click

    if isinstance(exc, TrackprocError):
        return str(exc), exc.exit_code
    if isinstance(exc, Terminated):
        return f"terminated by {exc.name}; temporary outputs removed", 128 + exc.signum
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted; temporary outputs removed", 130
    if isinstance(exc, _click.exceptions.UsageError):
        path = exc.ctx.command_path if exc.ctx is not None else "trackproc"
        name = path.split(" ", 1)[1] + ": " if " " in path else ""
        if isinstance(exc, _click.exceptions.NoArgsIsHelpError):
            text = "a command or argument is missing"
        else:
            text = exc.format_message().strip().rstrip(".")
        return f"{name}{text}; see '{path} --help'", EXIT_INPUT
    if isinstance(exc, _click.exceptions.ClickException):
        return exc.format_message(), getattr(exc, "exit_code", EXIT_PROCESSING) or EXIT_PROCESSING
    if isinstance(exc, OSError):   # one that no reader or writer turned into an input/output error
        what = (exc.strerror or str(exc) or type(exc).__name__).lower()
        where = f"{exc.filename}: " if exc.filename is not None else ""
        return f"{where}{what}; expected a readable input and a writable output", EXIT_PROCESSING
    if isinstance(exc, MemoryError):
        return ("out of memory; expected an input within the size limits "
                "(TRACKPROC_MAX_INPUT_MB, see README 'Exit codes')"), EXIT_PROCESSING
    if isinstance(exc, RecursionError):
        return "input nested too deeply; expected at most a few levels of nesting", EXIT_INPUT
    where = f"{command}: " if command else ""
    detail = str(exc) or type(exc).__name__
    if os.environ.get("TRACKPROC_DEBUG"):
        import traceback

        traceback.print_exception(exc, file=sys.stderr)
    return f"{where}internal error ({type(exc).__name__}): {detail}", EXIT_PROCESSING


_INSTALLED_BY: int | None = None


def _raise_terminated(signum, frame):  # noqa: ARG001 - signal handler signature
    if os.getpid() != _INSTALLED_BY:
        # a forked worker (batch's pool) inherited the handler: die of the signal as before, so a
        # pool's terminate() stays silent
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    raise Terminated(signum)


def install_signal_handlers() -> Callable[[], None]:
    """SIGTERM, SIGINT and SIGHUP raise :class:`Terminated` in the main thread, so the ``with``
    blocks of open outputs remove their temporary files. Returns a function restoring the
    previous handlers (the CLI may run inside a test process)."""
    global _INSTALLED_BY
    _INSTALLED_BY = os.getpid()
    previous = {}
    for name in ("SIGTERM", "SIGINT", "SIGHUP"):
        signum = getattr(signal, name, None)
        if signum is None:
            continue
        try:
            previous[signum] = signal.signal(signum, _raise_terminated)
        except (ValueError, OSError):  # not the main thread
            pass

    def restore() -> None:
        for signum, handler in previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(signum, handler)

    return restore


@contextlib.contextmanager
def outputs_all_or_none(enabled: bool = True) -> Iterator[object]:
    """Every output file of the command is renamed into place at the end, or none is."""
    from trackproc.io.atomic import all_or_none

    with all_or_none(enabled=enabled) as txn:
        yield txn
