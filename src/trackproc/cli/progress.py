"""Progress on a terminal only (issue 16): a command that runs longer than :data:`AFTER_S` shows
``trackproc COMMAND: working, 12 s`` on stderr, updated each second and erased when it ends. Not a
word in a pipe, a log or cron (stderr not a terminal), nor under ``--quiet``."""

from __future__ import annotations

import contextlib
import sys
import threading
import time

AFTER_S = 2.0


@contextlib.contextmanager
def ticker(command: str | None, *, enabled: bool = True, stream=None, after_s: float = AFTER_S):
    stream = stream if stream is not None else sys.stderr
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):
        tty = False
    if not (enabled and tty and command and command != "batch"):
        yield
        return
    stop = threading.Event()
    shown = []
    start = time.monotonic()

    def run():
        if stop.wait(after_s):
            return
        while not stop.is_set():
            text = f"\rtrackproc {command}: working, {time.monotonic() - start:.0f} s "
            try:
                stream.write(text)
                stream.flush()
            except (OSError, ValueError):
                return
            shown.append(len(text))
            stop.wait(1.0)

    thread = threading.Thread(target=run, name="trackproc-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=1.0)
        if shown:
            with contextlib.suppress(OSError, ValueError):
                stream.write("\r" + " " * max(shown) + "\r")
                stream.flush()
