"""Kernels compiled once per machine, not once per process (``jit.compile_once``): processes that
need the same cold kernels at once compile them in one process, the others wait for its lock and
then load numba's on-disk cache; a lock held past its timeout, or a cache directory without a
lock file, never blocks the run."""

import fcntl
import importlib
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from trackproc.dynamics import jit  # noqa: E402

SOURCE = '''
from trackproc.dynamics.jit import njit


@njit
def cube(x):
    return x * x * x
'''

# One process of the race. The holder (ROLE=first) takes the lock, then waits until the other
# process is seen polling for it (30 s at most), so the two provably overlap; the waiter marks its first poll.
# Each prints its result and numba's own count of compilations and cache loads of the kernel.
RACER = textwrap.dedent('''
    import os, sys, time
    sys.path.insert(0, os.environ["PROBE_DIR"])
    from trackproc.dynamics import jit
    import probe_cube
    here = os.environ["PROBE_DIR"]
    if os.environ["ROLE"] == "second":
        real_sleep = jit.time.sleep

        def sleep(s):
            open(os.path.join(here, "waiting"), "w").close()
            real_sleep(s)

        jit.time.sleep = sleep
        while not os.path.exists(os.path.join(here, "holding")):
            time.sleep(0.01)
    with jit.compile_once([probe_cube.cube], "probe", "the probe kernel", 1, timeout_s=60):
        if os.environ["ROLE"] == "first":
            open(os.path.join(here, "holding"), "w").close()
            deadline = time.monotonic() + 30          # without a lock the waiter never polls
            while not os.path.exists(os.path.join(here, "waiting")) and time.monotonic() < deadline:
                time.sleep(0.01)
        value = probe_cube.cube(3.0)
    stats = probe_cube.cube.stats
    print(value, sum(stats.cache_misses.values()), sum(stats.cache_hits.values()))
''')


def _env(probe_dir: Path, role: str) -> dict:
    env = dict(os.environ, PROBE_DIR=str(probe_dir), ROLE=role)
    env.pop("NUMBA_CACHE_DIR", None)          # the cache beside the probe's source, in tmp_path
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    return env


def test_two_processes_on_an_empty_cache_compile_once(tmp_path):
    (tmp_path / "probe_cube.py").write_text(SOURCE)
    racer = tmp_path / "racer.py"
    racer.write_text(RACER)
    first = subprocess.Popen([sys.executable, str(racer)], env=_env(tmp_path, "first"),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    second = subprocess.Popen([sys.executable, str(racer)], env=_env(tmp_path, "second"),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out1, err1 = first.communicate(timeout=120)
    out2, err2 = second.communicate(timeout=120)
    assert first.returncode == 0 and second.returncode == 0, (err1, err2)
    assert (tmp_path / "waiting").exists()                    # the second did wait for the lock
    value1, compiled1, loaded1 = out1.split()
    value2, compiled2, loaded2 = out2.split()
    assert float(value1) == float(value2) == 27.0             # 3**3
    assert (compiled1, loaded1) == ("1", "0")                 # the holder compiled
    assert (compiled2, loaded2) == ("0", "1")                 # the waiter loaded the holder's cache
    notices = [e for e in (err1, err2) if "compiling the probe kernel" in e]
    assert len(notices) == 1 and notices[0] is err1


def _fresh_module(tmp_path, monkeypatch, name):
    (tmp_path / f"{name}.py").write_text(SOURCE)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop(name, None)
    return importlib.import_module(name)


def _hold(path: str) -> int:
    """Take the lock at ``path`` the way another process would (a separate open file)."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


def test_a_lock_held_past_its_timeout_is_passed_by(tmp_path, monkeypatch, caplog):
    module = _fresh_module(tmp_path, monkeypatch, "trackproc_jit_lock_probe_a")
    path = jit._lock_path(module.cube, "probe")
    assert path is not None and jit.cold(module.cube)
    fd = _hold(path)                                  # a hung holder: it never lets go
    try:
        with caplog.at_level(logging.WARNING, logger="trackproc"):
            with jit.compile_once([module.cube], "probe", timeout_s=0.3):
                assert module.cube(2.0) == 8.0
    finally:
        os.close(fd)
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and path in said[0] and "compiling without it" in said[0]


def test_the_lock_is_held_while_compiling_and_a_leftover_file_is_no_lock(tmp_path, monkeypatch, caplog):
    module = _fresh_module(tmp_path, monkeypatch, "trackproc_jit_lock_probe_b")
    path = jit._lock_path(module.cube, "probe")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("")                         # left by a process that was killed
    with caplog.at_level(logging.WARNING, logger="trackproc"):
        with jit.compile_once([module.cube], "probe", timeout_s=60):
            with pytest.raises(BlockingIOError):      # another process would wait here
                _hold(path)
            assert module.cube(2.0) == 8.0
    assert not caplog.records                         # taken at once: no timeout passed
    os.close(_hold(path))                             # released after the block
    # warm now: no lock taken at all
    fd = _hold(path)
    try:
        with jit.compile_once([module.cube], "probe", timeout_s=0.0):
            assert module.cube(3.0) == 27.0
    finally:
        os.close(fd)
    assert not caplog.records


def test_an_unwritable_cache_directory_runs_without_a_lock(tmp_path, monkeypatch):
    module = _fresh_module(tmp_path, monkeypatch, "trackproc_jit_lock_probe_c")
    monkeypatch.setattr(jit, "_lock_path", lambda kernel, family: str(tmp_path / "no" / "such" / "x.lock"))
    (tmp_path / "no").write_text("a file, not a directory")
    with jit.compile_once([module.cube], "probe", timeout_s=0.0):
        assert module.cube(4.0) == 64.0


TAYLOR_RUN = textwrap.dedent('''
    import numpy as np
    from trackproc.dynamics.taylor import propagate
    state = np.array([7.0e6, 0.0, 0.0, 0.0, 7.6e3, 0.0])
    run = propagate(state, 0.0, 6000.0, force="two-body", engine="compiled")
    print(repr(float(run.state(np.array([6000.0]))[0, 0])))
''')


@pytest.mark.slow
def test_two_processes_started_together_compile_the_taylor_kernels_once(tmp_path):
    """The real kernels (~11 s of CPU to compile): two processes on an empty numba cache, one
    compile notice between them, the same orbit in both and the closed-form two-body one."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), TRACKPROC_JIT="1")
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    runs = [subprocess.Popen([sys.executable, "-c", TAYLOR_RUN], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [r.communicate(timeout=600) for r in runs]
    assert all(r.returncode == 0 for r in runs), outs
    notices = [err for _, err in outs if "compiling the Taylor engine's kernels" in err]
    assert len(notices) == 1, outs
    x1, x2 = (float(out) for out, _ in outs)
    assert x1 == x2
    # Kepler's equation for the circular-ish orbit above (independent of the integrator)
    mu, r0, v0 = 3.986004418e14, 7.0e6, 7.6e3
    a = 1.0 / (2.0 / r0 - v0 * v0 / mu)
    e = 1.0 - r0 / a                                    # at periapsis (v0 > circular speed)
    n = (mu / a**3) ** 0.5
    mean = n * 6000.0
    ecc = mean
    for _ in range(50):
        ecc = mean + e * np.sin(ecc)
    assert abs(x1 - a * (np.cos(ecc) - e)) < 1e-3       # m
