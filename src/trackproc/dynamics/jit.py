"""Optional numba compilation: whether compiled kernels may be used, and the decorator.

numba is an optional dependency (``pip install trackproc[fast]``); every compiled kernel has a
pure-numpy path beside it. ``TRACKPROC_JIT=0`` forces the numpy paths.
"""

from __future__ import annotations

import functools
import os

__all__ = ["enabled", "forced", "mode", "njit"]


@functools.lru_cache(maxsize=1)
def _numba_importable() -> bool:
    try:
        import numba  # noqa: F401
    except Exception:                                              # pragma: no cover - optional
        return False
    return True


def mode() -> str:
    """``TRACKPROC_JIT`` read at each call: ``"0"`` (numpy paths only), ``"1"`` (every compiled
    path, whatever the size of the work) or ``""`` (automatic)."""
    return os.environ.get("TRACKPROC_JIT", "").strip()


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
