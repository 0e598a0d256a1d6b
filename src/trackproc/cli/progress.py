"""Progress on a terminal only (issue 16): a command that runs longer than :data:`AFTER_S` shows
``trackproc COMMAND: working, 12 s`` on stderr, updated each second, erased before anything else
is written to stderr (the summary, a warning) and when it ends. Not a
word in a pipe, a log or cron (stderr not a terminal), nor under ``--quiet``."""

from __future__ import annotations

import contextlib
import sys
import threading
import time

AFTER_S = 2.0


class _Erasing:
    """The stream the command writes to while the ticker runs: the progress line is erased before
    any other text goes out (a summary, a warning, an error), and redrawn only at the start of a
    line, so the line never mixes with the command's own output."""

    def __init__(self, stream):
        self._stream = stream
        self._lock = threading.Lock()
        self._shown = 0          # width of the progress line on screen, 0: none
        self._at_line_start = True

    def draw(self, text: str) -> None:
        with self._lock:
            if not self._at_line_start:
                return
            self._stream.write("\r" + text + " " * max(0, self._shown - len(text)))
            self._stream.flush()
            self._shown = max(self._shown, len(text) + 1)

    def erase(self) -> None:
        with self._lock:
            self._erase()

    def _erase(self) -> None:
        if self._shown:
            self._stream.write("\r" + " " * self._shown + "\r")
            self._shown = 0

    def write(self, text):
        with self._lock:
            if text:
                self._erase()
                self._at_line_start = text.endswith("\n")
            return self._stream.write(text)

    def writelines(self, lines):
        for line in lines:
            self.write(line)

    def __getattr__(self, name):  # flush, isatty, encoding, fileno, buffer, ...
        return getattr(self._stream, name)


@contextlib.contextmanager
def ticker(command: str | None, *, enabled: bool = True, stream=None, after_s: float = AFTER_S):
    """Show the progress line on ``stream`` (default: stderr) while the block runs; ``sys.stderr``
    is the erasing wrapper meanwhile when it is that stream."""
    stream = stream if stream is not None else sys.stderr
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):
        tty = False
    if not (enabled and tty and command and command != "batch"):
        yield
        return
    stop = threading.Event()
    start = time.monotonic()
    line = _Erasing(stream)

    def run():
        if stop.wait(after_s):
            return
        while not stop.is_set():
            try:
                line.draw(f"trackproc {command}: working, {time.monotonic() - start:.0f} s")
            except (OSError, ValueError):
                return
            stop.wait(1.0)

    swapped = sys.stderr is stream
    if swapped:
        sys.stderr = line
    thread = threading.Thread(target=run, name="trackproc-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=1.0)
        with contextlib.suppress(OSError, ValueError):
            line.erase()
            stream.flush()
        if swapped and sys.stderr is line:
            sys.stderr = stream
