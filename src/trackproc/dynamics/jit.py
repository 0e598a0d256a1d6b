"""Optional numba compilation (issues 17, 19): one switch for every compiled kernel.

numba is optional (``pip install trackproc[fast]``); every compiled path has a pure-numpy path
beside it. ``TRACKPROC_JIT=0`` in the environment switches compilation off. Kernels are compiled
with ``cache=True`` (the machine code is kept on disk, so a later process only loads it) and
without ``fastmath`` (IEEE arithmetic: the compiled and numpy paths agree to rounding).
"""

from __future__ import annotations

import os
from functools import lru_cache

__all__ = ["enabled", "njit"]


@lru_cache(maxsize=1)
def enabled() -> bool:
    """True when ``TRACKPROC_JIT`` is not ``"0"`` and numba can be imported (cached)."""
    if os.environ.get("TRACKPROC_JIT", "").strip() == "0":
        return False
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def njit(**kw):
    """Decorator factory: ``numba.njit(cache=True, nogil=True, **kw)`` when :func:`enabled`.

    Otherwise the function is returned unchanged (callers choose the numpy path then).
    """
    if not enabled():
        return lambda fn: fn
    import numba

    return numba.njit(cache=True, nogil=True, **kw)
