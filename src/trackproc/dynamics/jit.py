"""Optional numba compilation: whether compiled kernels may be used, and the decorator.

numba is a dependency (skipped on a Python it has no wheels for); every compiled kernel has a
pure-numpy path beside it. ``TRACKPROC_JIT=0`` forces the numpy paths.
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
import logging

__all__ = ["announce_compiling", "cold", "default", "enabled", "forced", "mode", "njit"]

_LOCAL = threading.local()


@functools.lru_cache(maxsize=1)
def _numba_importable() -> bool:
    try:
        import numba  # noqa: F401
    except Exception:                                              # pragma: no cover - optional
        return False
    return True


def mode() -> str:
    """``TRACKPROC_JIT`` read at each call: ``"0"`` (numpy paths only), ``"1"`` (every compiled
    path, whatever the size of the work) or ``""`` (automatic); when it is unset or empty, the
    value :func:`default` gives this thread (``trackproc batch`` runs its tasks under ``"1"``)."""
    return os.environ.get("TRACKPROC_JIT", "").strip() or getattr(_LOCAL, "mode", "")


@contextlib.contextmanager
def default(value: str):
    """Within the block, :func:`mode` in this thread is ``value`` unless ``TRACKPROC_JIT`` is set
    (the user's setting wins, ``0`` included)."""
    saved = getattr(_LOCAL, "mode", "")
    _LOCAL.mode = value
    try:
        yield
    finally:
        _LOCAL.mode = saved


def enabled() -> bool:
    """True when compiled kernels may be used: numba importable and ``TRACKPROC_JIT`` not ``0``."""
    return mode() != "0" and _numba_importable()


def forced() -> bool:
    """True when ``TRACKPROC_JIT=1`` asks for the compiled paths whatever the size of the work."""
    return mode() == "1"


def njit(*args, **kwargs):
    """``numba.njit(cache=True, error_model="numpy", ...)``: IEEE arithmetic (no fastmath), and a
    division by zero gives inf/NaN as in numpy (then a NON_FINITE outcome), not an exception.
    numba is imported only here."""
    import numba

    kwargs.setdefault("cache", True)
    kwargs.setdefault("error_model", "numpy")
    return numba.njit(*args, **kwargs)


_ANNOUNCED: set = set()


def cold(kernel) -> bool:
    """True when the numba dispatcher ``kernel`` has neither been compiled in this process nor
    has an entry in numba's on-disk cache: calling it now compiles (tens of seconds of CPU for
    the force and Taylor kernels). Reads one small index file; an internal numba API, so any
    surprise there counts as "not cold" (no announcement rather than a wrong one)."""
    try:
        if kernel.signatures:
            return False
        return not kernel._cache._cache_file._load_index()
    except Exception:                                     # noqa: BLE001 - numba internals moved
        return False


def announce_compiling(kernels, what: str, cpu_s: float) -> None:
    """Say once per process, on stderr, that ``what`` is being compiled when any of ``kernels``
    is :func:`cold`, so that a first run's long silence has its reason (later runs load the
    kernels from numba's cache in a fraction of a second)."""
    if what in _ANNOUNCED or not any(cold(k) for k in kernels):
        return
    _ANNOUNCED.add(what)
    logging.getLogger("trackproc").warning(
        "compiling %s, once per installation (~%d s of CPU); later runs load them from the cache", what, cpu_s)
