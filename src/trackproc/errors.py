"""Error types and the exit-code table shared by every command.

=====  ==========================================================
code   meaning
=====  ==========================================================
0      success
1      processing failure (non-convergence, rank deficiency, ...)
2      usage error or invalid input (file, row, column named)
3      partial failure in batch (some inputs failed, others done)
=====  ==========================================================
"""

from __future__ import annotations

import errno
import signal

EXIT_OK = 0
EXIT_PROCESSING = 1
EXIT_INPUT = 2
EXIT_PARTIAL = 3


class TrackprocError(Exception):
    """Base class: a failure that the CLI reports in one line and turns into an exit code."""

    exit_code = EXIT_PROCESSING


class InputError(TrackprocError):
    """Invalid input. Names the file, the 1-based row (as a spreadsheet shows it; the
    header is row 1 in a CSV with a header), the column, what was found and what was expected.
    """

    exit_code = EXIT_INPUT

    def __init__(self, message: str = "", *, file: str | None = None, row: int | None = None,
                 column: str | None = None, found: object = None, expected: str | None = None):
        self.file, self.row, self.column = file, row, column
        self.found, self.expected, self.detail = found, expected, message
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.file is not None:
            where.append(str(self.file))
        if self.row is not None:
            where.append(f"row {self.row}")
        if self.column is not None:     # a command-line option ("--span") is not a column of a file
            where.append(f"{'option' if str(self.column).startswith('-') else 'column'} '{self.column}'")
        parts = [": ".join([", ".join(where)] if where else [])]
        text = self.detail
        if self.found is not None:
            text += ("; " if text else "") + f"found {_shorten(repr(self.found))}"
        if self.expected is not None:
            text += ("; " if text else "") + f"expected {self.expected}"
        return (parts[0] + ": " + text) if where else text


def _shorten(text: str, limit: int = 240) -> str:
    """A found value as shown in a one-line message: a 200 kB cell is cut, its length said."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


class ProcessingError(TrackprocError):
    """A computation failed on valid input (non-convergence, rank deficiency, too few data)."""

    exit_code = EXIT_PROCESSING

    def __init__(self, message: str, diagnostics: dict | None = None):
        self.diagnostics = diagnostics or {}
        super().__init__(message)


class OutputError(TrackprocError):
    """An output could not be written (a directory, under a file, a full or read-only disk).

    Exit 2 when the path itself cannot be a file (the user named a directory, or a path under a
    file); exit 1 when the system refused (no space, read-only, permission, I/O error).
    """

    exit_code = EXIT_PROCESSING

    def __init__(self, path: str, exc: OSError):
        self.path, self.errno = str(path), exc.errno
        usage = {errno.EISDIR, errno.ENOTDIR, errno.ENAMETOOLONG, errno.EEXIST, errno.EINVAL}
        self.exit_code = EXIT_INPUT if exc.errno in usage else EXIT_PROCESSING
        what = (exc.strerror or type(exc).__name__).lower()
        super().__init__(f"{self.path}: cannot write output: {what}; "
                         "expected a writable file path (nothing was written)")


class Terminated(BaseException):
    """SIGTERM/SIGINT/SIGHUP arrived: unwinds like KeyboardInterrupt, so that every open output
    removes its temporary file, then the CLI exits 128 + signal number."""

    def __init__(self, signum: int):
        self.signum = signum
        try:
            self.name = signal.Signals(signum).name
        except ValueError:
            self.name = f"signal {signum}"
        super().__init__(self.name)
