"""The input files of ``trackproc batch``: directories, files and globs -> result names and paths."""

from __future__ import annotations

import glob
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from trackproc.errors import InputError
from trackproc.pipeline.batch.report import printable

log = logging.getLogger("trackproc.batch")


@dataclass
class InputFile:
    """An input file found by the patterns: result ``name`` and ``path``."""

    name: str
    path: str
    problem: str | None = None       # why this input cannot be processed (found before reading it)


def utf8_name(text: str) -> str | None:
    """``text`` written so that UTF-8 can hold it (bytes that are not UTF-8, which the file system
    gave as surrogates, as ``\\xNN``); None when it already can."""
    try:
        text.encode("utf-8")
        return None
    except UnicodeEncodeError:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


_MAGIC = set("*?[")


def discover(entries: Sequence[str], patterns: Sequence[str], exclude: Sequence[str] = ()) -> list:
    """The input files of directories, files and globs, in name order.

    A directory gives its files matching ``patterns`` (not recursive; use a ``**`` glob for
    that); a glob gives the regular files it matches (none: a warning; when its fixed part is
    not a directory: :class:`~trackproc.errors.InputError`, as for a missing directory). Hidden
    files are left out, as are ``exclude`` (the output directory, the stations and state
    files). Result names are paths relative to the directory (or the glob's fixed part) without
    the suffix.
    """
    excluded = [os.path.realpath(p) for p in exclude if p]
    found: dict = {}
    for entry in entries:
        if any(ch in _MAGIC for ch in entry):
            base = _glob_base(entry)
            if not os.path.isdir(base):  # nothing can match: a typo or an unmounted disk, not an empty inbox
                raise InputError("the glob's directory does not exist", file=base, column="--input",
                                 found=entry, expected="a glob in an existing directory")
            paths = sorted(glob.glob(entry, recursive=True))
            if not paths:
                log.warning("no input file matches %s", entry)
        elif os.path.isdir(entry):
            base = entry
            paths = sorted({p for pattern in patterns for p in glob.glob(os.path.join(glob.escape(entry), pattern))})
            if not paths:
                log.warning("no input file in %s (patterns %s)", entry, ", ".join(patterns))
        elif os.path.isfile(entry):
            base = os.path.dirname(entry) or "."
            paths = [entry]
        else:
            raise InputError("input not found", file=entry, expected="a directory, a file or a glob")
        for path in paths:
            real = os.path.realpath(path)
            if not os.path.isfile(path) or os.path.basename(path).startswith("."):
                continue
            if any(real == e or real.startswith(e + os.sep) for e in excluded):
                continue
            rel = os.path.relpath(path, base)
            name = os.path.splitext(rel)[0].replace(os.sep, "/")
            if real in found:
                continue
            escaped = utf8_name(name)
            if escaped is not None:      # isolated: this input fails, the others run
                found[real] = InputFile(escaped, utf8_name(path) or path,
                                        problem="the file name is not valid UTF-8 (its bytes are shown as \\xNN); "
                                                "expected a UTF-8 file name: rename the file")
                continue
            found[real] = InputFile(name, path)
    by_name: dict = {}
    for item in found.values():
        other = by_name.get(item.name)
        if other is not None:
            raise InputError("two inputs would give the same result name", file=printable(item.path), found=item.name,
                             expected=f"a name different from {other.path}'s: rename one, or give them separate "
                                      "sub-directories under one input directory glob")
        by_name[item.name] = item
    return [by_name[n] for n in sorted(by_name)]


def _glob_base(pattern: str) -> str:
    parts = Path(pattern).parts
    fixed = []
    for part in parts:
        if any(ch in _MAGIC for ch in part):
            break
        fixed.append(part)
    return str(Path(*fixed)) if fixed else "."


