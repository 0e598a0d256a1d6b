"""numpy submodules that no trackproc path uses, made lazy before scipy loads: used by the
command line (``cli/app.py``, every command) and by a batch's fork server (its preload, from
which every worker is forked). Standard library only: imported at start-up."""

from __future__ import annotations

import sys

#: numpy submodules no trackproc command uses, which scipy imports only to copy their names
UNUSED_NUMPY_MODULES = ("numpy.f2py", "numpy.testing")


def defer_unused_numpy_modules() -> None:
    """Make :data:`UNUSED_NUMPY_MODULES` lazy modules (``importlib.util.LazyLoader``: loaded
    on first attribute access) before scipy loads. scipy >= 1.15 copies numpy's namespace when
    it starts (``scipy._lib.array_api_compat.clone_module``: ``hasattr(numpy, name)`` for every
    name of ``dir(numpy)``, whose lazily imported submodules include these), which imports them:
    ~45-55 ms of CPU in every process that imports scipy. Any failure leaves numpy as it is."""
    if any(name in sys.modules for name in UNUSED_NUMPY_MODULES) or "scipy" in sys.modules:
        return
    try:
        import importlib.util

        import numpy

        for name in UNUSED_NUMPY_MODULES:
            spec = importlib.util.find_spec(name)
            if spec is None or spec.loader is None:
                continue
            spec.loader = importlib.util.LazyLoader(spec.loader)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
            setattr(numpy, name.rpartition(".")[2], module)
    except Exception:  # noqa: BLE001 - only a start-up saving: never a reason to fail
        pass
