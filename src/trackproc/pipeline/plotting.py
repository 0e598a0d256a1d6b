"""matplotlib for every ``--plot``: an optional extra, imported only when a plot is asked for."""

from __future__ import annotations

from trackproc.errors import InputError


def require_matplotlib() -> None:
    """Raise an InputError (exit 2) with the fix when matplotlib is missing."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise InputError("--plot needs matplotlib, which is not installed",
                         expected="pip install 'trackproc[plot]' (or matplotlib), or run without --plot") from None
