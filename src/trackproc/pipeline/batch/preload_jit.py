""":mod:`trackproc.pipeline.batch.preload` and the compiled kernels
(:func:`~trackproc.pipeline.batch.kernels.load_numba`), loaded once by the fork server of a
batch whose tasks use them instead of once by every worker (~0.3 s of CPU a worker)."""

from __future__ import annotations

from trackproc.pipeline.batch import preload  # noqa: F401
from trackproc.pipeline.batch.kernels import load_numba

load_numba()                                # never raises: the numpy paths serve without it
