"""Atomic outputs and the ``-`` convention for stdin/stdout.

Every file trackproc writes goes through :func:`write_bytes` / :func:`open_atomic`: the
content is written to a temporary file in the destination directory and renamed over the
target only when complete, so a failure never leaves a half-written file behind. Each file's data
is fsynced before its rename, so that after a crash or power loss a visible file is complete (the
batch trusts a manifest's outputs by their size, and writes the manifest after them); one sync
per run instead would save no CPU of the machine (the page writeback is then done by the kernel's
flusher instead) and would lose that order.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import sys
from pathlib import Path
from typing import BinaryIO, Iterator

from trackproc.errors import InputError, OutputError

STDIO = "-"


def is_stdio(path: str | os.PathLike | None) -> bool:
    return path is not None and str(path) == STDIO


class _Transaction:
    """Outputs of one command: each is complete in its temporary file; all are renamed into place
    at the end, or all removed (a failing second output must not leave the first one written)."""

    def __init__(self):
        self.pid = os.getpid()
        self.pending: list[tuple[str, Path]] = []
        self.decided = False
        self.ok = True

    def commit_if(self, ok: bool) -> None:
        self.decided, self.ok = True, ok

    def rollback(self) -> None:
        for tmp, _ in self.pending:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self.pending.clear()

    def commit(self) -> None:
        pending, self.pending = self.pending, []
        for i, (tmp, target) in enumerate(pending):
            try:
                os.replace(tmp, target)
            except OSError as exc:
                self.pending = pending[i + 1:]
                self.rollback()
                with contextlib.suppress(OSError):
                    os.unlink(tmp)

                raise OutputError(str(target), exc) from None


_transaction: _Transaction | None = None


def commit_outputs() -> None:
    """Rename the outputs written so far into place now. For a command that ends with a non-zero
    exit on its verdict (quality ``rejected``, ``--strict``): its outputs are complete and say why."""
    if _transaction is not None:
        _transaction.commit()


@contextlib.contextmanager
def all_or_none(enabled: bool = True) -> Iterator[_Transaction]:
    """Within the block, every :func:`open_atomic` output of this process is held in its temporary
    file; they become the targets together when the block ends normally (and ``commit_if`` was
    not given False), else they are all removed. Child processes write straight through."""
    global _transaction
    txn = _Transaction()
    previous = _transaction
    if enabled:
        _transaction = txn
    try:
        yield txn
    except BaseException:
        txn.rollback()
        raise
    else:
        if txn.ok:
            txn.commit()
        else:
            txn.rollback()
    finally:
        _transaction = previous


@contextlib.contextmanager
def open_atomic(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """Binary file handle that becomes ``path`` only if the block completes.

    ``path == "-"`` yields stdout's binary buffer (nothing to rename). An OSError on the output
    side (a directory, a path under a file, a full or read-only disk) is an
    :class:`~trackproc.errors.OutputError` naming the path.
    """
    if is_stdio(path):
        out = _WholeWrites(sys.stdout.buffer)
        yield out
        out.flush()
        return
    target = Path(path)
    try:
        mode = os.stat(target).st_mode              # one stat: what the target is, if anything
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
        # a device, FIFO or /dev/stdout: there is nothing to replace atomically (and renaming
        # over /dev/null would destroy it): write straight through
        try:
            handle = open(target, "wb")
        except OSError as exc:
            raise OutputError(str(path), exc) from None
        try:
            with handle:
                yield handle
        except OSError as exc:  # /dev/full: ENOSPC on write or on close
            raise OutputError(str(path), exc) from None
        return
    if mode is not None and stat.S_ISDIR(mode):
        raise OutputError(str(path), IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR)))
    fd, tmp, txn = _temporary(path, target.parent if str(target.parent) else Path("."), target.name)
    try:
        try:
            with os.fdopen(fd, "wb") as handle:
                yield handle
                handle.flush()
                os.fsync(handle.fileno())  # durable before it is renamed: a crash never leaves a visible partial file
            if txn is not None:
                txn.pending.append((tmp, target))
            else:
                os.replace(tmp, target)
        except OSError as exc:
            raise OutputError(str(path), exc) from None
    except BaseException:
        if txn is None or (tmp, target) not in txn.pending:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise


def _temporary(path, directory, name: str):
    """``(fd, tmp, txn)``: the new temporary file for ``path`` (:func:`_create_temporary`) and the
    transaction of this process it joins (None: renamed at once); errors as :class:`OutputError`."""
    try:
        fd, tmp = _create_temporary(directory, name)
    except FileExistsError as exc:  # a parent is a file
        raise OutputError(str(path), NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR))) from exc
    except OSError as exc:
        raise OutputError(str(path), exc) from None
    return fd, tmp, (_transaction if _transaction is not None and _transaction.pid == os.getpid() else None)


#: Exclusive creation of a new file that is not followed through a symbolic link (as mkstemp's).
_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0)


def _create_temporary(directory: str | Path, name: str) -> tuple[int, str]:
    """(fd, path) of a new empty file ``.NAME.XXXXXXXX.tmp`` in ``directory`` (made, with its
    parents, when missing), mode 0666 less the umask, as any file the user writes.

    ``tempfile.mkstemp`` does the same with mode 0600, which needed an ``fchmod`` and two
    ``umask`` calls to read the mask, after a ``mkdir`` of the directory every time (a batch
    writes four files a pass: ~5 % of their CPU; the rest is the kernel's create, write, fsync
    and rename). The name is random (``os.urandom``), retried when taken, as mkstemp's."""
    made = False
    for _ in range(100):
        tmp = os.path.join(directory, f".{name}.{os.urandom(6).hex()}.tmp")
        try:
            return os.open(tmp, _CREATE, 0o666), tmp
        except FileExistsError:
            if made or os.path.isdir(directory):
                continue
            raise                                   # a parent is a file (mkdir would say so too)
        except FileNotFoundError:
            if made:
                raise
            Path(directory).mkdir(parents=True, exist_ok=True)
            made = True
    raise FileExistsError(errno.EEXIST, "no usable temporary name", str(directory))


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


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """``data`` as ``path``, atomically and durably as :func:`open_atomic` writes it (the same
    temporary file, fsync, then rename, or held in the transaction), with the file descriptor's own
    calls: no buffered file object (its ``fstat``, ``ioctl`` and ``lseek``) nor generator context
    (a batch writes four files a pass, and this was most of the driver's Python time for them).
    The standard streams, a target that is not a regular file and the errors on those go through
    :func:`open_atomic`."""
    name = os.fspath(path)
    if name == STDIO:
        with open_atomic(path) as handle:
            handle.write(data)
        return
    try:
        mode = os.stat(name).st_mode
    except OSError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        with open_atomic(path) as handle:                   # a device, a FIFO, a directory
            handle.write(data)
        return
    directory, base = os.path.split(name)
    fd, tmp, txn = _temporary(path, directory or ".", base)
    try:
        try:
            view = memoryview(data).cast("B")
            while view:                                     # a regular file takes it all, or raises
                n = os.write(fd, view)
                if not n:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                view = view[n:]
            os.fsync(fd)                                    # durable before it is renamed
        finally:
            os.close(fd)
        if txn is not None:
            txn.pending.append((tmp, Path(name)))
        else:
            os.replace(tmp, name)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise OutputError(str(path), exc) from None
        raise


def write_text(path: str | os.PathLike, text: str) -> None:
    write_bytes(path, text.encode("utf-8"))


#: Default largest input read (MiB); ``TRACKPROC_MAX_INPUT_MB`` overrides it.
DEFAULT_MAX_INPUT_MB = 256


def max_input_bytes() -> int:
    """The largest input file or stdin stream read, in bytes: ``TRACKPROC_MAX_INPUT_MB`` (MiB),
    default :data:`DEFAULT_MAX_INPUT_MB`. A bound, so that ``/dev/zero`` or a runaway pipe is an
    input error instead of exhausting the machine."""
    text = os.environ.get("TRACKPROC_MAX_INPUT_MB", "")
    if not text:
        return DEFAULT_MAX_INPUT_MB << 20
    try:
        mb = float(text)
        if not (mb > 0 and mb < 1 << 40):
            raise ValueError
    except ValueError:
        raise InputError("invalid environment variable", column="TRACKPROC_MAX_INPUT_MB", found=text,
                         expected="a positive size in MiB") from None
    return int(mb * (1 << 20))


#: Bytes read at a time from an input.
INPUT_BLOCK = 1 << 20


def iter_input_blocks(path: str | os.PathLike, limit: int | None = None) -> Iterator[bytes]:
    """The bytes of a file, or of stdin for ``-``, in blocks of at most :data:`INPUT_BLOCK`, at most
    ``limit`` bytes in all (default :func:`max_input_bytes`): beyond it an input error. The readers
    that stream (CSV, Parquet) hold one block at a time; the file is opened at the first block."""

    limit = max_input_bytes() if limit is None else limit
    name = "<stdin>" if is_stdio(path) else str(path)
    if is_stdio(path):
        handle = sys.stdin.buffer
    else:
        try:
            handle = open(path, "rb")
        except FileNotFoundError:
            raise InputError("file not found", file=name) from None
        except IsADirectoryError:
            raise InputError("is a directory, expected a file", file=name) from None
        except PermissionError:
            raise InputError("permission denied", file=name) from None
        except OSError as exc:
            raise InputError(f"cannot read: {(exc.strerror or str(exc)).lower()}", file=name) from None
    total = 0
    try:
        while True:
            try:
                chunk = handle.read(min(INPUT_BLOCK, limit + 1 - total))
            except IsADirectoryError:
                raise InputError("is a directory, expected a file", file=name) from None
            except OSError as exc:
                if is_stdio(path):
                    raise
                raise InputError(f"cannot read: {(exc.strerror or str(exc)).lower()}", file=name) from None
            if not chunk:
                return
            total += len(chunk)
            if total > limit:
                raise InputError(f"input larger than the limit of {limit / (1 << 20):g} MiB", file=name,
                                 expected="a smaller input, or a larger TRACKPROC_MAX_INPUT_MB")
            yield chunk
    finally:
        if not is_stdio(path):
            handle.close()


def read_input_bytes(path: str | os.PathLike, limit: int | None = None) -> bytes:
    """All bytes of a file, or of stdin for ``-`` (Parquet needs the whole buffer), at most
    ``limit`` bytes (default :func:`max_input_bytes`): beyond it an input error."""
    return b"".join(iter_input_blocks(path, limit))
