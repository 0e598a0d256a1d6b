"""Kernels compiled once per machine, not once per process (``jit.compile_once``): processes that
need the same cold kernels at once compile them in one process, the others wait for its lock and
then load numba's on-disk cache; a lock held past its timeout, or a cache directory without a
lock file, never blocks the run."""

import contextlib
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
        import types

        def sleep(s):                                  # the lock's poll, not this process's own waits
            open(os.path.join(here, "waiting"), "w").close()
            time.sleep(s)

        jit.time = types.SimpleNamespace(monotonic=time.monotonic, sleep=sleep)
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


# -- every real kernel family runs its first call under its lock ------------------------------------
# The race above proves the lock; these prove each family's first call goes through it, in-process and
# without compiling anything: jit.compile_once is replaced by a recorder of the open blocks and the
# kernel by a stand-in that stops the run, reporting which families were open around its call and
# whether it was among their kernels (the ones whose coldness decides the lock).
# tests/methods/test_whitening_compile_once.py races two processes on the real whitening kernels.


class _Called(Exception):
    """Raised by a stand-in kernel: ``args[0]`` the [(family, kernel listed)] open around the call."""


@pytest.fixture
def open_blocks(monkeypatch):
    from trackproc.dynamics.forces import compiled

    blocks = []

    @contextlib.contextmanager
    def record(kernels, family, *args, **kwargs):
        blocks.append((family, list(kernels)))
        try:
            yield
        finally:
            blocks.pop()

    monkeypatch.setattr(jit, "compile_once", record)
    monkeypatch.setattr(compiled, "compile_once", record)       # bound by name there
    return blocks


def _stand_in(monkeypatch, module, name, blocks):
    def kernel(*args, **kwargs):
        raise _Called([(family, any(k is kernel for k in kernels)) for family, kernels in blocks])

    monkeypatch.setattr(module, name, kernel)


def _families(run):
    with pytest.raises(_Called) as called:
        run()
    return called.value.args[0]


@pytest.mark.parametrize("stm, kernel", [(False, "propagate_state"), (True, "propagate_var")])
def test_the_taylor_loops_run_under_the_taylor_lock(stm, kernel, monkeypatch, open_blocks):
    from trackproc.dynamics import taylor, taylor_jit

    _stand_in(monkeypatch, taylor_jit, kernel, open_blocks)
    state = np.array([7.0e6, 0.0, 0.0, 0.0, 7.6e3, 0.0])
    assert _families(lambda: taylor.propagate(state, 0.0, 600.0, force="j2", stm=stm, engine="compiled")) == [
        ("taylor", True)]
    if not stm:              # python -m trackproc.dynamics.taylor_jit: both families, in the order taken everywhere
        assert _families(taylor_jit.compile_all) == [("taylor", True), ("taylor-dense", False)]


def test_the_taylor_dense_output_runs_under_its_lock(monkeypatch, open_blocks):
    import dataclasses

    from trackproc.dynamics import taylor, taylor_jit

    state = np.array([7.0e6, 0.0, 0.0, 0.0, 7.6e3, 0.0])
    run = dataclasses.replace(taylor.propagate(state, 0.0, 6000.0, force="j2", engine="numpy"), engine="compiled")
    assert run.n_steps > 1                                    # (a single step needs no kernel)
    _stand_in(monkeypatch, taylor_jit, "dense", open_blocks)
    assert _families(lambda: run.state(np.array([100.0, 5000.0]))) == [("taylor-dense", True)]


def test_the_force_kernels_run_under_the_force_lock(monkeypatch, open_blocks):
    from trackproc.dynamics.forces import ForceModel, compiled, integrator
    from trackproc.dynamics.forces.gravity_field import GravityField

    cbar, sbar = np.zeros((3, 3)), np.zeros((3, 3))
    cbar[0, 0], cbar[2, 0] = 1.0, -4.84e-4
    model = ForceModel(field=GravityField(3.986004415e14, 6378136.3, cbar, sbar))
    env = model.environment((2458944.5, 0.0), np.eye(3), 0.0, 600.0)
    r, v = np.array([7.0e6, 0.0, 0.0]), np.array([0.0, 7.6e3, 0.0])
    _stand_in(monkeypatch, compiled, "integrate", open_blocks)
    assert _families(lambda: integrator.propagate(env, np.concatenate([r, v]), 600.0, compiled=True)) == [
        ("force", True)]
    for helper, kernel in ((compiled.perturbation, "_acceleration"), (compiled.partials, "_partials")):
        _stand_in(monkeypatch, compiled, kernel, open_blocks)
        assert _families(lambda: helper(env, 0.0, r, v)) == [("force", True)]
