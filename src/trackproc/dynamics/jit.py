"""Optional numba compilation: whether compiled kernels may be used, and the decorator.

numba is a dependency (skipped on a Python it has no wheels for); every compiled kernel has a
pure-numpy path beside it. ``TRACKPROC_JIT=0`` forces the numpy paths.
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
import time
import logging

__all__ = ["announce_compiling", "cold", "compile_once", "default", "enabled", "forced", "light_cache_load", "mode",
           "njit"]

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
    if args and callable(args[0]):
        return light_cache_load(numba.njit(*args, **kwargs))
    decorate = numba.njit(*args, **kwargs)
    return lambda func: light_cache_load(decorate(func))


#: The numba releases (major, minor) whose internals :func:`light_cache_load` and
#: :mod:`trackproc.dynamics.forces.native` were checked against (their tests:
#: tests/dynamics/test_jit_light_load.py, tests/io/test_forces_native.py). With any other release,
#: or ``TRACKPROC_JIT_LIGHT=0``, both step aside and numba loads its cache its own way: a release
#: that moved an internal could otherwise crash a process instead of costing 0.3 s.
CHECKED_NUMBA = ((0, 68),)


def light_allowed(numba_version: str | None) -> bool:
    """True when numba ``numba_version`` is one of :data:`CHECKED_NUMBA` and ``TRACKPROC_JIT_LIGHT``
    is not ``0``."""
    if os.environ.get("TRACKPROC_JIT_LIGHT", "").strip() == "0" or not numba_version:
        return False
    try:
        release = tuple(int(part) for part in numba_version.split(".")[:2])
    except ValueError:
        return False
    return release in CHECKED_NUMBA


def light_cache_load(kernel):
    """Let ``kernel`` (a numba dispatcher) load its machine code from numba's cache without first
    loading every implementation registry of numba's CPU target, and return it.

    numba's ``Cache.load_overload`` starts with ``target_context.refresh()``, which imports all of
    numba's lowering modules (arrays, linalg with scipy.linalg, datetimes, random, typed
    containers, ...): ~0.27 s of CPU, more than importing numba, and none of it is used by code
    already compiled. Loading needs only the runtime's symbols (``rtsys.initialize``) and the
    modules of the environments the cached code names (imported by the unpickling). When the
    cache has no entry the dispatcher compiles as always, and numba's compiler refreshes the
    context itself. Uses numba internals (``_cache._load_overload``): if they are not there, or
    :func:`light_allowed` says no, the kernel is returned unchanged (numba's own load)."""
    import numba

    if not light_allowed(getattr(numba, "__version__", None)):
        return kernel
    cache = getattr(kernel, "_cache", None)
    load = getattr(cache, "_load_overload", None)
    guard = getattr(cache, "_guard_against_spurious_io_errors", None)
    if load is None or guard is None:
        return kernel
    try:
        from numba.core.runtime import rtsys
    except ImportError:                                   # pragma: no cover - numba internals moved
        return kernel

    def load_overload(sig, target_context):
        rtsys.initialize(target_context)
        with guard():
            return load(sig, target_context)
        return None                                       # the guard swallowed an I/O error: compile

    cache.load_overload = load_overload
    return kernel


_ANNOUNCED: set = set()
#: Kernels seen compiled in this process, by id (a dispatcher keeps its signatures once it has
#: one): :func:`cold` answers for them without numba's ``signatures`` (a list built at each
#: call), which the Taylor engine asks before each run.
_WARM: dict = {}


def cold(kernel) -> bool:
    """True when the numba dispatcher ``kernel`` has neither been compiled in this process nor
    has an entry in numba's on-disk cache: calling it now compiles (tens of seconds of CPU for
    the force and Taylor kernels). Reads one small index file; an internal numba API, so any
    surprise there counts as "not cold" (no announcement rather than a wrong one)."""
    if _WARM.get(id(kernel)) is kernel:
        return False
    try:
        if kernel.signatures:
            _WARM[id(kernel)] = kernel
            return False
        return not kernel._cache._cache_file._load_index()
    except Exception:                                     # noqa: BLE001 - numba internals moved
        return False


def warm(kernel) -> bool:
    """True when ``kernel`` was seen compiled in this process (:func:`cold` found its signatures):
    its calls need no :func:`compile_once` block."""
    return _WARM.get(id(kernel)) is kernel


def announce_compiling(kernels, what: str, cpu_s: float) -> None:
    """Say once per process, on stderr, that ``what`` is being compiled when any of ``kernels``
    is :func:`cold`, so that a first run's long silence has its reason (later runs load the
    kernels from numba's cache in a fraction of a second)."""
    if what in _ANNOUNCED or not any(cold(k) for k in kernels):
        return
    _ANNOUNCED.add(what)
    logging.getLogger("trackproc").warning(
        "compiling %s, once per installation (~%d s of CPU); later runs load them from the cache", what, cpu_s)


#: How long a process waits for another one compiling the same kernels (s): past it, it compiles
#: its own copy, so a lock held by a hung process delays a run but never blocks it. Above a
#: compilation's wall time on a loaded 2-core machine (the force kernels: ~12 s of CPU).
LOCK_TIMEOUT_S = 300.0
#: Between two attempts at the lock while another process holds it (s).
LOCK_POLL_S = 0.1

_HELD = threading.local()


def _lock_path(kernel, family: str) -> str | None:
    """The lock file of ``family`` in the directory where numba caches ``kernel``, so that the
    processes sharing that cache (``NUMBA_CACHE_DIR`` or numba's choice) share the lock; None when
    numba's internals do not say where (no lock then)."""
    try:
        directory = kernel._cache._cache_path
    except Exception:                                     # noqa: BLE001 - numba internals moved
        return None
    return os.path.join(directory, f"trackproc-{family}.lock") if directory else None


@contextlib.contextmanager
def compile_once(kernels, family: str, what: str = "", cpu_s: float = 0, timeout_s: float | None = None):
    """Run the block (a first call of ``kernels``) holding a per-machine lock when any of them is
    :func:`cold`, so that processes needing the same kernels at once on a fresh cache (xdist or
    batch pool workers, two cron jobs) compile them once: the others wait, then load numba's cache.
    With ``what``, :func:`announce_compiling` once the lock is held (the waiters, finding the
    cache written, say nothing).

    The lock is an ``fcntl.flock`` on a file beside numba's cache of the first kernel: the kernel
    releases it when its holder exits, even killed, so a leftover file never blocks. A holder that
    hangs is waited for ``timeout_s`` (:data:`LOCK_TIMEOUT_S`), then the block runs anyway (the
    compilation the lock would have saved). A read-only or missing cache directory, or no
    ``fcntl``: the block runs without a lock (numba compiles in memory as before)."""
    kernels = list(kernels)
    held = getattr(_HELD, "families", None)
    if held is None:
        held = _HELD.families = set()
    if family in held or not any(cold(k) for k in kernels):
        yield
        return
    path = _lock_path(kernels[0], family)
    if path is None:
        if what:
            announce_compiling(kernels, what, cpu_s)
        yield
        return
    try:
        import fcntl

        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except (ImportError, OSError):
        if what:
            announce_compiling(kernels, what, cpu_s)
        yield
        return
    locked = False
    try:
        deadline = time.monotonic() + (LOCK_TIMEOUT_S if timeout_s is None else timeout_s)
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                locked = True
                break
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    logging.getLogger("trackproc").warning(
                        "%s: held past %.0f s by another process; compiling without it", path,
                        LOCK_TIMEOUT_S if timeout_s is None else timeout_s)
                    break
                time.sleep(LOCK_POLL_S)
            except OSError:                               # e.g. a file system without locks
                break
        if what:
            announce_compiling(kernels, what, cpu_s)
        held.add(family)
        try:
            yield
        finally:
            held.discard(family)
    finally:
        if locked:
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
