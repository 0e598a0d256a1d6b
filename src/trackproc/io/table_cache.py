"""The user cache directory: parsed tables (IERS EOP, ICGEM gravity fields) kept as ``.npz``
so that a command does not parse the same text file line by line on every run.

Location: ``$TRACKPROC_CACHE_DIR`` when set (an empty value, ``0`` or ``off`` turns caching off),
else ``$XDG_CACHE_HOME/trackproc``, else ``~/.cache/trackproc``.

An entry is keyed by the *content* of the source file and of the parser module (SHA-256 of
both): an edited, replaced or touched-but-unchanged file is recognised by its bytes, and a
changed parser invalidates its entries without a version number to bump. The entry also holds
that key, so a file of another key (or a truncated, unreadable one) is a miss: it is parsed
again and rewritten. Writes go to a temporary file in the same directory and are renamed over
the entry (``os.replace``, atomic on POSIX): runs that fill the cache at the same time each
write a whole entry, and a reader sees a whole old entry, a whole new one or none. A cache that
cannot be written (read-only home, full disk) only costs the parse.

Only the standard library is imported at module level (numpy inside the functions): the
command line reads :func:`cache_dir` on its ``--help`` path.
"""

from __future__ import annotations

import hashlib
import os
import tempfile

#: Environment variable that relocates (a directory) or disables (empty, ``0``, ``off``) the cache.
CACHE_ENV = "TRACKPROC_CACHE_DIR"
_OFF = ("", "0", "off", "no", "false", "none")
#: Parsed tables of this process, by entry key (a batch worker reads each file's entry once).
_MEMO: dict = {}
_MEMO_MAX = 8


def cache_dir(kind: str = "") -> str | None:
    """The cache directory (tables), or its ``kind`` subdirectory; not created here. None when
    caching is off."""
    named = os.environ.get(CACHE_ENV)
    if named is not None:
        if named.strip().lower() in _OFF:
            return None
        root = named
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = os.path.join(base, "trackproc")
    return os.path.join(root, kind) if kind else root


def write_atomic(directory: str, name: str, write) -> bool:
    """Write an entry by ``write(binary_file)`` to a temporary file renamed over ``directory/name``.
    False (and nothing left behind) when it cannot be written."""
    tmp = None
    try:
        os.makedirs(directory, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        os.replace(tmp, os.path.join(directory, name))
        return True
    except Exception:  # noqa: BLE001 - a cache that cannot be written is only not used
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        return False


def _digest(*paths) -> str:
    h = hashlib.sha256()
    for path in paths:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        h.update(b"\0")
    return h.hexdigest()


def cached_arrays(kind: str, source, parse, *, parser: str) -> dict:
    """``parse()`` (a dict of numpy arrays: numbers or strings, no objects) for the file
    ``source``, from the cache when an entry for the same bytes of ``source`` and of the parser
    module ``parser`` (its ``__file__``) is there; else parsed and stored. The arrays returned
    are read-only (shared with later callers of this process)."""
    import numpy as np  # start-up: this module is on the --help path (trackproc.io)

    try:
        key = f"{kind}:{_digest(source, parser)}"
    except OSError:
        return parse()                  # the parser reports the unreadable file itself
    if key in _MEMO:
        return _MEMO[key]
    directory = cache_dir()
    name = f"{kind}-{key.rpartition(':')[2][:40]}.npz"
    arrays = None
    if directory is not None:
        try:
            with np.load(os.path.join(directory, name), allow_pickle=False) as z:
                if "_key" in z.files and str(z["_key"]) == key:
                    arrays = {k: z[k] for k in z.files if k != "_key"}
        except Exception:  # noqa: BLE001 - missing, truncated or foreign: parse again, rewrite
            arrays = None
    if arrays is None:
        arrays = {k: np.asarray(v) for k, v in parse().items()}
        if directory is not None:
            write_atomic(directory, name, lambda fh: np.savez(fh, _key=np.array(key), **arrays))
    for value in arrays.values():
        value.setflags(write=False)
    if len(_MEMO) >= _MEMO_MAX:
        _MEMO.clear()
    _MEMO[key] = arrays
    return arrays
