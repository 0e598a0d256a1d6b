"""A batch's pool workers are forked by a fork server that has already imported what the input
steps need (pipeline/batch/preload.py) with one BLAS thread: a worker does not import them again;
and nothing the nightly path does not use (pandas, pyarrow.compute, numpy.f2py, numpy.testing)."""

from __future__ import annotations

import multiprocessing

import pytest

from trackproc.pipeline import batch as batch_module

MODULES = ("numpy", "pyarrow.parquet", "trackproc.pipeline.ingest", "trackproc.pipeline.smooth",
           "trackproc.pipeline.refine")
#: Not used by ingest -> smooth -> refine of CSV pass files: not preloaded (numpy's two: lazy modules).
UNUSED = ("pandas", "pyarrow.compute", "numpy.f2py", "numpy.testing")


@pytest.mark.slow
@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(), reason="no fork server here")
@pytest.mark.parametrize("jit", [False, True])   # preload, preload_jit (its kernels import scipy.linalg)
def test_a_worker_starts_with_the_steps_modules_and_one_blas_thread(jit):
    executor = batch_module.PoolExecutor(1, jit)
    try:
        # eval: a builtin, so the call pickles by name and runs before the worker's first task
        loaded = executor.pool.submit(eval, f"[m for m in {MODULES!r} if m in __import__('sys').modules]").result()
        threads = executor.pool.submit(eval, "__import__('os').environ.get('OPENBLAS_NUM_THREADS')").result()
        unused = executor.pool.submit(eval, f"[m for m in {UNUSED!r} if type(__import__('sys').modules.get(m))"
                                            ".__name__ == 'module']").result()
    finally:
        executor.close()
    assert loaded == list(MODULES)
    assert unused == []
    assert threads == "1"


_DRIVER = """
import sys
from trackproc.pipeline.batch.config import Settings
from trackproc.pipeline.batch.executors import make_executor
from trackproc.pipeline.batch.kernels import compiled_kernels

settings = Settings(values={"batch": {"scheduler": None, "workers": 2, "steps": ["ingest", "smooth", "refine"]}},
                    origins={})
jit = compiled_kernels(settings)
executor = make_executor(settings, 4, jit)
try:
    worker = executor.pool.submit(eval, "'numba' in __import__('sys').modules").result()
finally:
    executor.close()
print(jit, "numba" in sys.modules, worker)
"""


@pytest.mark.slow
@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(), reason="no fork server here")
def test_a_pool_driver_leaves_the_kernels_to_the_workers():
    """With a pool the driver runs no task: it does not import numba (~0.3-0.5 s of CPU a run);
    its workers start with the kernels loaded (by the fork server, under the compile locks)."""
    import subprocess
    import sys

    pytest.importorskip("numba")
    done = subprocess.run([sys.executable, "-c", _DRIVER], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["True", "False", "True"]


_LOAD = """
import sys
from trackproc.pipeline.batch.kernels import load_numba
from trackproc.methods import whitening_jit

load_numba()
kernels = (whitening_jit.riccati, whitening_jit.kalman_whiten, whitening_jit.reml_terms)
print(all(k.signatures for k in kernels), "numba.np.linalg" in sys.modules)
"""


@pytest.mark.slow
def test_loading_the_cached_kernels_skips_numbas_target_refresh():
    """``load_numba`` (a fork server's preload, a 1-worker run) loads every cached kernel, the
    whitening ones too, without numba's ``target_context.refresh()`` (which imports all of numba's
    lowering modules, numba.np.linalg among them: ~0.17 s of CPU a process). The first run warms
    the cache (it may compile, and then refresh); the second must only load."""
    import subprocess
    import sys

    pytest.importorskip("numba")
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", _LOAD], capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["True", "False"]
