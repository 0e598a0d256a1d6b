"""numpy submodules that no trackproc path uses, made lazy before scipy loads: used by the
command line (``cli/app.py``, every command) and by a batch's fork server (its preload, from
which every worker is forked). Standard library only, and numpy is not imported here: a
command that never needs numpy (a pool's batch driver) does not pay for it."""

from __future__ import annotations

import sys

#: numpy submodules no trackproc command uses, which scipy imports only to copy their names
UNUSED_NUMPY_MODULES = ("numpy.f2py", "numpy.testing")


class _LazyFinder:
    """A meta path finder that gives each of :data:`UNUSED_NUMPY_MODULES`, when it is first
    imported, the spec of the installed module with its loader wrapped in
    ``importlib.util.LazyLoader`` (executed on first attribute access), then steps out of
    ``sys.meta_path`` once it has served them all."""

    def __init__(self):
        self.pending = set(UNUSED_NUMPY_MODULES)

    def find_spec(self, name, path=None, target=None):
        if name not in self.pending:
            return None
        self.pending.discard(name)
        if not self.pending:
            self.remove()
        try:
            import importlib.machinery
            import importlib.util

            spec = importlib.machinery.PathFinder.find_spec(name, path)
            if spec is not None and spec.loader is not None and hasattr(spec.loader, "exec_module"):
                spec.loader = importlib.util.LazyLoader(spec.loader)
            return spec
        except Exception:  # noqa: BLE001 - only a start-up saving: the ordinary import serves
            return None

    def remove(self):
        try:
            sys.meta_path.remove(self)
        except ValueError:
            pass


def defer_unused_numpy_modules() -> None:
    """Make :data:`UNUSED_NUMPY_MODULES` lazy modules (``importlib.util.LazyLoader``: loaded on
    first attribute access) when they are first imported, before scipy loads, without importing
    numpy. scipy >= 1.15 copies numpy's namespace when it starts
    (``scipy._lib.array_api_compat.clone_module``: ``hasattr(numpy, name)`` for every name of
    ``dir(numpy)``, whose lazily imported submodules include these), which imports them: ~45-55 ms
    of CPU in every process that imports scipy. A finder first in ``sys.meta_path`` (nothing else
    is imported until numpy asks for them; numpy alone costs ~0.1 s, which the batch driver of a
    pool never needs). Any failure leaves numpy as it is."""
    if any(name in sys.modules for name in UNUSED_NUMPY_MODULES) or "scipy" in sys.modules:
        return
    if any(isinstance(finder, _LazyFinder) for finder in sys.meta_path):
        return
    sys.meta_path.insert(0, _LazyFinder())
