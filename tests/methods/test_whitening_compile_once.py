"""Two processes loading the real whitening kernels (methods/whitening_jit.py, the cheapest real
kernel family to compile) on an empty numba cache compile them once: the one holding the family's
lock (``jit.compile_once``) compiles, the other waits for it and loads numba's cache. The probe
kernel's race (tests/dynamics/test_jit_compile_once.py) proves the lock itself; this one proves a
real family's public entry point (``whitening.compiled_riccati``) takes it, with the real cache
directory and lock file of an installed module."""

import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("numba")

# The holder (ROLE=first) waits, inside the whitening lock, until the other process is seen polling
# for it (30 s at most): the two provably overlap. The waiter starts once the holder holds the lock.
# Each prints numba's counts of compilations and cache loads of both kernels.
RACER = textwrap.dedent('''
    import contextlib, os, time, types
    from trackproc.dynamics import jit
    here, role = os.environ["RACE_DIR"], os.environ["ROLE"]
    mark = lambda name: open(os.path.join(here, name), "w").close()
    seen = lambda name: os.path.exists(os.path.join(here, name))
    real_lock = jit.compile_once

    @contextlib.contextmanager
    def lock(kernels, family, *args, **kwargs):
        with real_lock(kernels, family, *args, **kwargs):
            if role == "first" and family == "whitening":
                mark("holding")
                deadline = time.monotonic() + 30          # without a lock the waiter never polls
                while not seen("waiting") and time.monotonic() < deadline:
                    time.sleep(0.01)
            yield

    jit.compile_once = lock
    if role == "second":
        def sleep(s):                                  # the lock's poll, not this process's own waits
            mark("waiting")
            time.sleep(s)

        jit.time = types.SimpleNamespace(monotonic=time.monotonic, sleep=sleep)
        deadline = time.monotonic() + 30
        while not seen("holding") and time.monotonic() < deadline:
            time.sleep(0.01)
    from trackproc.methods import whitening, whitening_jit
    assert whitening.compiled_riccati() is whitening_jit.riccati
    stats = [k.stats for k in (whitening_jit.riccati, whitening_jit.kalman_whiten)]
    print(sum(sum(s.cache_misses.values()) for s in stats), sum(sum(s.cache_hits.values()) for s in stats))
''')


@pytest.mark.slow
def test_two_processes_on_an_empty_cache_compile_the_whitening_kernels_once(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), TRACKPROC_JIT="1", RACE_DIR=str(tmp_path))
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    runs = [subprocess.Popen([sys.executable, "-c", RACER], env=dict(env, ROLE=role), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for role in ("first", "second")]
    outs = [r.communicate(timeout=300) for r in runs]
    assert all(r.returncode == 0 for r in runs), outs
    assert (tmp_path / "holding").exists() and (tmp_path / "waiting").exists()   # the second waited for the lock
    (compiled1, loaded1), (compiled2, loaded2) = (out.split() for out, _ in outs)
    assert (compiled1, loaded1) == ("2", "0")                 # the holder compiled both kernels
    assert (compiled2, loaded2) == ("0", "2")                 # the waiter loaded them from its cache
