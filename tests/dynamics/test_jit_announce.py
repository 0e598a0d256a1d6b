"""The first call of a compiled kernel that numba's cache does not hold is announced once on
stderr (a first full-force run compiles for tens of seconds); a cached or compiled one is not."""

import importlib
import logging
import sys

import pytest

pytest.importorskip("numba")

from trackproc.dynamics import jit  # noqa: E402

SOURCE = '''
from trackproc.dynamics.jit import njit


@njit
def twice(x):
    return 2.0 * x
'''


def _fresh_module(tmp_path, monkeypatch, name):
    (tmp_path / f"{name}.py").write_text(SOURCE)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop(name, None)
    return importlib.import_module(name)


def test_cold_kernel_announced_once_then_cached(tmp_path, monkeypatch, caplog):
    module = _fresh_module(tmp_path, monkeypatch, "trackproc_jit_probe_a")
    monkeypatch.setattr(jit, "_ANNOUNCED", set())
    assert jit.cold(module.twice)                      # new source, empty cache: compiling ahead
    with caplog.at_level(logging.WARNING, logger="trackproc"):
        jit.announce_compiling([module.twice], "the probe kernels", 1)
        jit.announce_compiling([module.twice], "the probe kernels", 1)
    said = [r.getMessage() for r in caplog.records if "compiling the probe kernels" in r.getMessage()]
    assert len(said) == 1 and "once per installation" in said[0]
    assert module.twice(2.0) == 4.0
    assert not jit.cold(module.twice)                  # compiled in this process
    # a new process (here: a re-import) finds it in numba's on-disk cache: nothing to announce
    again = _fresh_module(tmp_path, monkeypatch, "trackproc_jit_probe_a")
    assert not jit.cold(again.twice)
    caplog.clear()
    monkeypatch.setattr(jit, "_ANNOUNCED", set())
    with caplog.at_level(logging.WARNING, logger="trackproc"):
        jit.announce_compiling([again.twice], "the probe kernels", 1)
    assert not caplog.records


def test_not_a_dispatcher_is_never_cold():
    assert jit.cold(len) is False
