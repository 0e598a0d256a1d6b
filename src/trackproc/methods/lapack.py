"""LAPACK routines as ``scipy.linalg.lapack`` gives them, without importing ``scipy.linalg``.

``scipy.linalg.lapack.dgeqrf`` and its siblings are the functions of SciPy's compiled Fortran
wrapper module ``scipy.linalg._flapack``. Importing them the usual way runs the package
``scipy.linalg`` first, which loads every decomposition, the matrix functions and SciPy's array-API
layer: ~70 ms of CPU, a tenth of a day's ``estimate`` and a sixth of a ``refine``, for the three
routines the noise model needs (``dgeqrf``, ``dpbtrf``, ``dtbtrs``). :func:`routines` loads the
wrapper module alone (~3 ms) under its own name, so that a later ``import scipy.linalg`` finds it
and hands out the very same function objects (a test holds them identical); when it cannot
(another SciPy layout), it imports ``scipy.linalg.lapack``.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys

__all__ = ["routines"]

_MODULE = "scipy.linalg._flapack"


def routines(*names: str) -> tuple:
    """The LAPACK functions ``names`` (e.g. ``"dgeqrf"``) of ``scipy.linalg.lapack``."""
    module = sys.modules.get(_MODULE) or _load_wrapper()
    if module is None or not all(hasattr(module, name) for name in names):
        from scipy.linalg import lapack as module  # the package's own import: what it costs, it costs
    return tuple(getattr(module, name) for name in names)


def _load_wrapper():
    """``scipy.linalg._flapack`` loaded from its file without its package, registered under its
    name; None when it is not where SciPy keeps it."""
    try:
        scipy_spec = importlib.util.find_spec("scipy")
        if scipy_spec is None or not scipy_spec.submodule_search_locations:
            return None
        for root in scipy_spec.submodule_search_locations:
            for suffix in importlib.machinery.EXTENSION_SUFFIXES:
                path = os.path.join(root, "linalg", "_flapack" + suffix)
                if os.path.exists(path):
                    spec = importlib.util.spec_from_file_location(_MODULE, path)
                    module = importlib.util.module_from_spec(spec)
                    spec.loader.exec_module(module)
                    return sys.modules.setdefault(_MODULE, module)
    except (ImportError, OSError):
        return None
    return None
