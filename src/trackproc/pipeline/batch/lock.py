"""The output directory's lock (``OUTPUT/.batch.lock``): two runs on one output directory never overlap."""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import time
from pathlib import Path

from trackproc.errors import ProcessingError
from trackproc.pipeline.batch.store import utc_now

log = logging.getLogger("trackproc.batch")

LOCK_NAME = ".batch.lock"


class LockedError(ProcessingError):
    """Another run holds the output directory's lock (exit 1: this run did nothing)."""


@contextlib.contextmanager
def batch_lock(directory: Path, wait: bool = False, timeout_s: float = 0.0):
    """Hold ``directory/.batch.lock`` (``fcntl.flock``, exclusive) for the block.

    Held by another process: wait for it when ``wait`` (at most ``timeout_s`` seconds, 0 = no
    limit), else raise :class:`LockedError` naming the holder. The file stays in place (removing
    it would let a third run lock a different file); the kernel releases the lock when the
    holder exits, however it exits.
    """
    import fcntl  # POSIX only: imported where the lock is taken

    path = directory / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _lock_holder(fd)
            if not wait:
                raise LockedError(f"{path} is held by another trackproc batch run ({holder}); this run did "
                                  "nothing: try again later, or use --wait") from None
            log.info("waiting for %s (held by %s)", path, holder)
            deadline = time.monotonic() + timeout_s if timeout_s > 0 else None
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if deadline is not None and time.monotonic() > deadline:
                        raise LockedError(f"{path} is still held by another trackproc batch run ({holder}) "
                                          f"after {timeout_s:g} s; this run did nothing") from None
                    time.sleep(0.1)
        os.ftruncate(fd, 0)
        os.pwrite(fd, (f"pid {os.getpid()} on {socket.gethostname()} since {utc_now()}\n").encode(), 0)
        yield path
    finally:
        os.close(fd)  # releases the lock


def _lock_holder(fd: int) -> str:
    try:
        text = os.pread(fd, 200, 0).decode("utf-8", errors="replace").strip()
    except OSError:
        text = ""
    return text or "holder unknown"


