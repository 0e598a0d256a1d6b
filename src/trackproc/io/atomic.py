"""Atomic outputs and the ``-`` convention for stdin/stdout.

Every file trackproc writes goes through :func:`write_bytes` / :func:`open_atomic`: the
content is written to a temporary file in the destination directory and renamed over the
target only when complete, so a failure never leaves a half-written file behind.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path
from typing import BinaryIO, Iterator

STDIO = "-"


def is_stdio(path: str | os.PathLike | None) -> bool:
    return path is not None and str(path) == STDIO


@contextlib.contextmanager
def open_atomic(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """Binary file handle that becomes ``path`` only if the block completes.

    ``path == "-"`` yields stdout's binary buffer (nothing to rename).
    """
    if is_stdio(path):
        out = _WholeWrites(sys.stdout.buffer)
        yield out
        out.flush()
        return
    target = Path(path)
    if target.exists() and not target.is_file():
        # a device, FIFO or /dev/stdout: there is nothing to replace atomically (and renaming
        # over /dev/null would destroy it): write straight through
        with open(target, "wb") as handle:
            yield handle
        return
    directory = target.parent if str(target.parent) else Path(".")
    directory.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        with os.fdopen(fd, "wb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


class _WholeWrites:
    """stdout whose ``write`` writes everything or raises: a pipe whose reader went away can make
    a buffered write return a short count without an error, which would end the run with exit 0
    and a silently truncated output."""

    def __init__(self, raw: BinaryIO):
        self._raw = raw

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        total = len(view)
        while view:
            n = self._raw.write(view)
            if not n:
                raise BrokenPipeError("stdout accepted no more data")
            view = view[n:]
        return total

    def flush(self) -> None:
        self._raw.flush()

    def __getattr__(self, name):
        return getattr(self._raw, name)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    with open_atomic(path) as handle:
        handle.write(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


def read_input_bytes(path: str | os.PathLike) -> bytes:
    """All bytes of a file, or of stdin for ``-`` (Parquet needs the whole buffer)."""
    from trackproc.errors import InputError

    if is_stdio(path):
        return sys.stdin.buffer.read()
    try:
        return Path(path).read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", file=str(path)) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", file=str(path)) from None
    except PermissionError:
        raise InputError("permission denied", file=str(path)) from None
