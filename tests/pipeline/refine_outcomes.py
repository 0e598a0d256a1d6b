"""The shared builder of the *covered or said* tests of ``refine`` (test_refine_mismodel.py,
test_refine_steps.py, test_refine_second_signal.py): refine a pass whose truth is known and
return how far the state is from it, in sigmas, with the verdict."""

from __future__ import annotations

import hashlib
import json
from contextlib import contextmanager

import numpy as np
import pandas as pd

from trackproc.errors import ProcessingError
from trackproc.pipeline.refine import assemble, refine


#: outcomes by their inputs: the sweeps of test_refine_steps.py, test_refine_second_signal.py and
#: test_refine_mismodel.py refine some passes that another of them (or their fast tier) refines too
#: (a clean pass, a tone on 10 % of the samples, the fast tier's rows); refine is deterministic
_DONE: dict = {}


def _content(table) -> "hashlib._Hash":
    h = hashlib.sha256(pd.util.hash_pandas_object(table.frame, index=True).to_numpy().tobytes())
    h.update(json.dumps(table.meta, sort_keys=True, default=str).encode())
    return h


#: smoothed curves by the samples they were fitted to (see :func:`curves_once`)
_CURVES: dict = {}


@contextmanager
def curves_once():
    """Within the block, ``refine`` smooths a pass whose samples it has smoothed before in this
    process only once: the Monte Carlos and sweeps refine the same samples under several a-priori
    or methods, and the curve (``selection.smoothed_curve``, a quarter of a refinement's CPU)
    depends on the samples alone. Smoothing is deterministic; the curve is only read."""
    real = assemble.smoothed_curve

    def once(sub, kind, station, pass_id, source):
        key = (_content(sub).hexdigest(), kind, station, pass_id, source)
        if key not in _CURVES:
            _CURVES[key] = real(sub, kind, station, pass_id, source)
        return _CURVES[key]

    assemble.smoothed_curve = once
    try:
        yield
    finally:
        assemble.smoothed_curve = real


def _key(table, initial, stations, options, eop, truth_at) -> tuple:
    """The inputs of one refinement: the samples and metadata by content, the stale state by its
    values, epoch and covariance; ``eop`` and ``truth_at`` are the tests' module constants (by id)."""
    h = _content(table)
    h.update(str(initial.epoch).encode())
    for a in (initial.values, initial.covariance):
        h.update(b"-" if a is None else np.ascontiguousarray(a, float).tobytes())
    h.update(repr(sorted((stations or {}).items())).encode())
    return h.hexdigest(), repr(options), id(eop), id(truth_at)


def refine_outcome(table, initial, stations, options, eop, truth_at) -> dict:
    """``refine`` of ``table`` from ``initial`` with ``options``: ``{"failed": message}``
    on exit 1, otherwise the largest |error|/sigma over x..vz at the solution epoch against
    ``truth_at(epoch)`` (``max_z``), the ``verdict``, the quality ``reasons`` by code and the
    ``result``. The same inputs are refined once per process (a new dict each call; its values,
    the result among them, are shared: read them only)."""
    key = _key(table, initial, stations, options, eop, truth_at)
    if key not in _DONE:
        _DONE[key] = _refine_outcome(table, initial, stations, options, eop, truth_at)
    return dict(_DONE[key])


def _refine_outcome(table, initial, stations, options, eop, truth_at) -> dict:
    try:
        with curves_once():
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
