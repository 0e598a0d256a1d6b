"""The shared builder of the *covered or said* tests of ``refine`` (test_refine_mismodel.py,
test_refine_steps.py, test_refine_second_signal.py): refine a pass whose truth is known and
return how far the state is from it, in sigmas, with the verdict."""

from __future__ import annotations

import numpy as np

from trackproc.errors import ProcessingError
from trackproc.pipeline.refine import refine


def refine_outcome(table, initial, stations, options, eop, truth_at) -> dict:
    """``refine`` of ``table`` from ``initial`` with ``options``: ``{"failed": message}``
    on exit 1, otherwise the largest |error|/sigma over x..vz at the solution epoch against
    ``truth_at(epoch)`` (``max_z``), the ``verdict``, the quality ``reasons`` by code and the
    ``result``."""
    try:
        res = refine(table, initial, stations, options, eop)
    except ProcessingError as exc:
        return {"failed": str(exc)}
    err = res.state.values[:6] - truth_at(res.state.epoch)
    q = res.state.extra["quality"]
    return {"max_z": float(np.max(np.abs(err / res.state.sigma[:6]))), "verdict": q["verdict"],
            "reasons": {r["code"]: r for r in q["reasons"]}, "result": res}


def covered_or_said(out: dict) -> bool:
    """The rule: exit 1, or every state component within 4 sigma of the truth, or a verdict that
    is not ``ok``."""
    return "failed" in out or out["max_z"] < 4.0 or out["verdict"] != "ok"
