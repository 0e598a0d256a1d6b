"""Optional numba compilation: whether compiled kernels may be used, and the decorator.

numba is an optional dependency (``pip install trackproc[fast]``); every compiled kernel has a
pure-numpy path beside it. ``TRACKPROC_JIT=0`` forces the numpy paths.
"""

from __future__ import annotations

import functools
import os

__all__ = ["enabled", "njit"]


@functools.lru_cache(maxsize=1)
def _numba_importable() -> bool:
    try:
        import numba  # noqa: F401
    except Exception:                                              # pragma: no cover - optional
        return False
    return True


def enabled() -> bool:
    """True when compiled kernels may be used: numba importable and ``TRACKPROC_JIT`` not ``0``."""
    return os.environ.get("TRACKPROC_JIT", "1") != "0" and _numba_importable()


def njit(*args, **kwargs):
    """``numba.njit(cache=True, ...)`` (IEEE arithmetic: no fastmath); import numba only here."""
    import numba

    kwargs.setdefault("cache", True)
    return numba.njit(*args, **kwargs)
