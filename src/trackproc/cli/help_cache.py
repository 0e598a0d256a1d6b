"""``trackproc [COMMAND] --help`` from the user cache: the help typer rendered the last time, when
nothing it depends on has changed since.

Importing typer alone costs about 5x starting Python, so the help is rendered by typer once (per
command, terminal width and environment) and kept in ``<cache>/help/`` (io/table_cache.py:
``TRACKPROC_CACHE_DIR`` relocates or turns it off). An entry is used only when

* the request is the same: the command words, the help flag, the terminal width click would
  use, the Python, and the environment that can change the text (``TRACKPROC_*``, the
  config-file location, the locale);
* every file that was loaded to render it (trackproc's and typer's modules, the standard
  library: each ``__file__`` in ``sys.modules`` at the time) and the config file (or its
  absence) still have the same size and modification time.

Anything else (another option, an unknown command, an unreadable or stale entry) goes to typer
as before. Only the standard library is imported here.
"""

from __future__ import annotations

import io
import os
import sys

HELP_FLAGS = ("--help", "-h")
#: Environment variables (besides ``TRACKPROC_*``) that the rendered help may depend on.
_ENV = ("XDG_CONFIG_HOME", "HOME", "LANG", "LANGUAGE", "LC_ALL", "LC_MESSAGES")
_MISSING = "-"


class Capture(io.StringIO):
    """What typer prints while rendering the help (not a terminal, as in a pipe)."""


def _columns() -> int:
    """The terminal width ``shutil.get_terminal_size`` gives click (without importing shutil)."""
    try:
        columns = int(os.environ.get("COLUMNS", "0"))
    except ValueError:
        columns = 0
    if columns <= 0:
        try:
            columns = os.get_terminal_size(sys.__stdout__.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 0
    return columns if columns > 0 else 80


def _config_candidates() -> list[str]:
    """Where cli/config.py looks for a config file (whether or not one is there)."""
    named = os.environ.get("TRACKPROC_CONFIG")
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return [p for p in (named, os.path.join(base, "trackproc", "config.toml")) if p]


def _stamp(path: str) -> str:
    try:
        st = os.stat(path)
    except OSError:
        return f"{_MISSING} {_MISSING}"
    return f"{st.st_mtime_ns} {st.st_size}"


def _fnv1a(text: str) -> str:
    h = 0xCBF29CE484222325
    for byte in text.encode("utf-8", "surrogateescape"):
        h = ((h ^ byte) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return f"{h:016x}"


class HelpRequest:
    """A plain help request (command words, then ``--help`` or ``-h``) and its cache entry."""

    def __init__(self, argv: list[str], directory: str):
        env = sorted((k, v) for k, v in os.environ.items() if k.startswith("TRACKPROC_") or k in _ENV)
        self.key = repr((argv, _columns(), sys.executable, sys.version, env))
        self.path = os.path.join(directory, f"{_fnv1a(self.key)}.txt")
        self.directory = directory

    def lookup(self) -> str | None:
        """The cached help, or None (no entry, another key, a changed file)."""
        try:
            with open(self.path, encoding="utf-8") as fh:
                data = fh.read()
        except (OSError, UnicodeDecodeError):
            return None
        head, sep, text = data.partition("\n\n")
        lines = head.split("\n")
        if not sep or lines[0] != self.key:
            return None
        for line in lines[1:]:
            mtime, size, path = (line.split(" ", 2) + ["", ""])[:3]
            if not path or _stamp(path) != f"{mtime} {size}":
                return None
        return text

    def store(self, text: str) -> None:
        """Keep ``text`` with the stamps of every file loaded so far (the render's inputs)."""
        files = {getattr(m, "__file__", None) for m in list(sys.modules.values())}
        files = sorted(f for f in files if isinstance(f, str)) + _config_candidates()
        if any("\n" in f for f in files) or "\n" in self.key:
            return
        body = "\n".join([self.key] + [f"{_stamp(f)} {f}" for f in files]) + "\n\n" + text
        from trackproc.io.table_cache import write_atomic

        write_atomic(self.directory, os.path.basename(self.path), lambda fh: fh.write(body.encode("utf-8")))


def request(argv: list[str]) -> HelpRequest | None:
    """The cacheable help request that ``argv`` is (up to two command words, then the help flag
    last), or None (another request, or caching off)."""
    if not argv or argv[-1] not in HELP_FLAGS or len(argv) > 3:
        return None
    if any(not word or word.startswith("-") for word in argv[:-1]):
        return None
    from trackproc.io.table_cache import cache_dir

    directory = cache_dir("help")
    return None if directory is None else HelpRequest(list(argv), directory)
