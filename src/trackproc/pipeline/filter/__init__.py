"""``trackproc filter``: sequential orbit determination, an extended Kalman filter and a
Rauch–Tung–Striebel smoother over the same problem as ``trackproc estimate``.

The problem (samples, stations, measurement models, modifiers and their bias drivers, force
model, a-priori) is the shared OD core's (:mod:`.problem`); the filter evaluates its model, so
every measurement kind, modifier and force model of ``estimate`` is the filter's too.

The package, one responsibility per module: :mod:`.options` (:class:`FilterOptions`),
:mod:`.run` (the sweep, the smoother, the iterated run), :mod:`.result` (:func:`filter_passes`,
the verdict, the innovation and history tables); the numerical updates are
:mod:`trackproc.methods.sequential`.
"""

from __future__ import annotations

from trackproc.pipeline.filter.options import FilterOptions
from trackproc.pipeline.filter.history import INNOVATION_COLUMNS
from trackproc.pipeline.filter.result import FilterResult, filter_passes, summary_text

__all__ = ["FilterOptions", "FilterResult", "filter_passes", "INNOVATION_COLUMNS", "summary_text"]
