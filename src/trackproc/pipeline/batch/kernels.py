"""Which compiled kernels (numba) a batch run's tasks use, and loading them into a process
before its tasks run (:func:`compiled_kernels`, :func:`load_numba`)."""

from __future__ import annotations

import importlib.util
import logging

from trackproc.dynamics import jit
from trackproc.pipeline.batch.config import Settings

log = logging.getLogger("trackproc.batch")


def compiled_kernels(settings: Settings) -> bool:
    """Whether this run's tasks use the compiled kernels (numba): a chain
    that refines or estimates, numba importable, and ``TRACKPROC_JIT`` not ``0``. Its tasks then
    run as under ``TRACKPROC_JIT=1`` (:class:`~trackproc.pipeline.batch.tasks.Task` ``jit``):
    every single-trajectory propagation and the noise model's Kalman gains compiled, whatever the
    task, the number of workers or their order, so a batch's outputs are those of
    ``TRACKPROC_JIT=1 trackproc refine`` (``TRACKPROC_JIT=0 trackproc batch``: those of plain
    ``trackproc refine``; the two agree to ~1e-13 relative, not bit for bit). ``import numba``
    and loading the cached kernels cost ~0.2 s of CPU a process; the compiled Taylor engine
    saves ~0.03–0.04 s of CPU a pass (measured in ``benchmarks/throughput.py``)."""
    if jit.mode() == "0":
        return False
    if not {"refine", "estimate"} & set(settings.get("batch.steps")):
        return False
    return importlib.util.find_spec("numba") is not None


def load_numba() -> None:
    """Import numba and load (or, the first time on this installation, compile) the compiled
    Taylor kernels, the Kalman gains and the predictions' square-root recurrence in this process
    (:func:`compiled_kernels`), so that the workers only load them; nothing when they cannot be."""
    try:
        import numpy as np

        from trackproc.dynamics import jit, taylor
        from trackproc.dynamics.measurement_spectra.series import series_sqrt
        from trackproc.methods.whitening import compiled_riccati

        module = taylor._jit_module()
        if module is not None and not (module.ready(True) and module.ready(False)):
            # the same locks as the engine's first calls: one process compiles, the others load
            with jit.compile_once([module.propagate_state, module.propagate_var], "taylor"), \
                    jit.compile_once([module.dense], "taylor-dense"):
                if not (module.ready(True) and module.ready(False)):
                    log.info("compiling the Taylor engine's kernels for this installation (once: ~10 s of CPU)")
                module.compile_all()
        # numba.njit kernels (not jit.njit): loaded light, as jit.njit's are, so that no process
        # of the run pays numba's target refresh (~0.17 s of CPU) for code already compiled
        from trackproc.methods import whitening_jit

        for kernel in (whitening_jit.riccati, whitening_jit.kalman_whiten, whitening_jit.reml_terms):
            jit.light_cache_load(kernel)
        with jit.default("1"):
            compiled_riccati()                 # the Kalman gains and whitening, compiled or loaded here
            series_sqrt(np.ones((1, 3)))       # the predictions' recurrence (series_jit), likewise
    except Exception:  # noqa: BLE001 - optional: the numpy paths serve
        pass
