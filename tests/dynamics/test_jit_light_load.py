"""A kernel held in numba's on-disk cache is loaded without numba's full target refresh
(``jit.light_cache_load``): a fresh process gets the cached machine code (a cache hit, the same
result as numpy), imports neither ``numba.np.arraymath`` nor ``scipy.linalg`` on the way, and can
still compile a new kernel that needs them afterwards."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from trackproc.dynamics import jit

pytest.importorskip("numba")
pytestmark = pytest.mark.slow


def test_only_checked_numba_releases_and_not_when_switched_off(monkeypatch):
    monkeypatch.delenv("TRACKPROC_JIT_LIGHT", raising=False)
    major, minor = jit.CHECKED_NUMBA[-1]
    assert jit.light_allowed(f"{major}.{minor}.1") and jit.light_allowed(f"{major}.{minor}.0rc1")
    for other in (f"{major}.{minor + 1}.0", f"{major}.{minor - 1}.3", "1.0.0", "", None, "dev"):
        assert not jit.light_allowed(other)
    monkeypatch.setenv("TRACKPROC_JIT_LIGHT", "0")
    assert not jit.light_allowed(f"{major}.{minor}.1")

SOURCE = '''
import numpy as np
from trackproc.dynamics.jit import njit


@njit
def scaled(x, k):
    out = np.empty(x.size)
    for i in range(x.size):
        out[i] = k * x[i] + 0.5
    return out
'''

RUN = textwrap.dedent('''
    import json, sys
    import numpy as np
    import lightmod
    x = np.linspace(0.0, 1.0, 7)
    got = lightmod.scaled(x, 3.0)
    report = {"equal": bool(np.array_equal(got, 3.0 * x + 0.5)),
              "hits": int(sum(lightmod.scaled.stats.cache_hits.values())),
              "arraymath": "numba.np.arraymath" in sys.modules,
              "scipy_linalg": "scipy.linalg" in sys.modules}
    if sys.argv[1] == "compile-after":
        from trackproc.dynamics.jit import njit

        @njit(cache=False)
        def interp(v, xp, fp):
            return np.interp(v, xp, fp)
        report["interp"] = float(interp(0.25, x, got))
        report["interp_numpy"] = float(np.interp(0.25, x, got))
    print(json.dumps(report))
''')


def _run(tmp_path, mode, **more):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    env.pop("NUMBA_CACHE_DIR", None)
    env.pop("TRACKPROC_JIT", None)
    env.pop("TRACKPROC_JIT_LIGHT", None)
    env.update(more)
    out = subprocess.run([sys.executable, "-c", RUN, mode], env=env, capture_output=True, text=True,
                         check=True, cwd=tmp_path)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_cached_kernel_loads_without_the_full_refresh(tmp_path):
    import numba

    if not jit.light_allowed(numba.__version__):
        pytest.skip(f"numba {numba.__version__} is not one of jit.CHECKED_NUMBA: numba's own load")
    (tmp_path / "lightmod.py").write_text(SOURCE)
    first = _run(tmp_path, "plain")                          # compiles, writes the cache
    assert first["equal"] and first["hits"] == 0 and first["arraymath"]
    second = _run(tmp_path, "plain")                         # loads it
    assert second == {"equal": True, "hits": 1, "arraymath": False, "scipy_linalg": False}
    # TRACKPROC_JIT_LIGHT=0: numba's own load (its full refresh), the same machine code
    assert _run(tmp_path, "plain", TRACKPROC_JIT_LIGHT="0") == {"equal": True, "hits": 1, "arraymath": True,
                                                                "scipy_linalg": True}
    third = _run(tmp_path, "compile-after")                  # then numba's compiler still works
    assert third["hits"] == 1 and third["interp"] == third["interp_numpy"]
