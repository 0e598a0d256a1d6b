"""A batch's pool workers are forked by a fork server that has already imported what the input
steps need (pipeline/batch/preload.py) with one BLAS thread: a worker does not import them again."""

from __future__ import annotations

import multiprocessing

import pytest

from trackproc.pipeline import batch as batch_module

MODULES = ("numpy", "pandas", "pyarrow.parquet", "trackproc.pipeline.ingest", "trackproc.pipeline.smooth",
           "trackproc.pipeline.refine")


@pytest.mark.slow
@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(), reason="no fork server here")
def test_a_worker_starts_with_the_steps_modules_and_one_blas_thread():
    executor = batch_module.PoolExecutor(1)
    try:
        # eval: a builtin, so the call pickles by name and runs before the worker's first task
        loaded = executor.pool.submit(eval, f"[m for m in {MODULES!r} if m in __import__('sys').modules]").result()
        threads = executor.pool.submit(eval, "__import__('os').environ.get('OPENBLAS_NUM_THREADS')").result()
    finally:
        executor.close()
    assert loaded == list(MODULES)
    assert threads == "1"
