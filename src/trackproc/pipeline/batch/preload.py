"""Imported once by the fork server of a batch's process pool, before it forks the workers
(:class:`~trackproc.pipeline.batch.executors.PoolExecutor`): one BLAS thread, then the modules
that the input steps import (numpy, pyarrow, the ingest, smooth and refine pipelines), so that
each worker starts with them instead of importing them again on its first task (~1 s of CPU a
worker); and nothing they do not use: not pyarrow.compute (~30 ms; io.columns casts without
it), not pandas (~0.2 s), which the steps need only for inputs other than CSV, Parquet and Arrow
tables and for a DataFrame asked for, nor numpy.f2py and numpy.testing (~50 ms), which scipy only
looks at (:mod:`trackproc.pipeline.lazy_numpy`).
:mod:`trackproc.pipeline.batch.preload_jit` adds the compiled kernels.

The fork server imports a preload module with ``except ImportError`` only: nothing here may
raise; a module that fails to import is imported again, and reported, by the task that needs it.
"""

from __future__ import annotations

from trackproc.pipeline.batch.executors import single_thread_blas
from trackproc.pipeline.lazy_numpy import defer_unused_numpy_modules

single_thread_blas()                        # before numpy, in this process as in the workers
defer_unused_numpy_modules()                # before scipy: numpy.f2py and numpy.testing stay unloaded

try:
    import numpy  # noqa: F401
    import pyarrow.csv  # noqa: F401 - the ingest step's CSV reader (~10 ms a worker)
    import pyarrow.parquet  # noqa: F401 - the pass files are written as Parquet

    from trackproc.io import passfile, smoothing_record, statefile, stations, tabular  # noqa: F401
    from trackproc.pipeline import ingest, smooth  # noqa: F401
    from trackproc.pipeline import refine  # noqa: F401
except Exception:  # noqa: BLE001 - the workers import what they need themselves
    pass
