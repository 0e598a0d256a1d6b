"""JSON output shared by every command: plain Python values, NaN/Inf as null, stable text."""

from __future__ import annotations

import json
import math

import numpy as np

from trackproc.isotime import iso_utc


def json_ready(value):
    """A JSON-ready copy: numpy scalars/arrays to Python, NaN/Inf to None (JSON has neither),
    tuples to lists, datetime64 to ISO 8601 UTC with Z."""
    kind = type(value)
    if kind is float:                         # the common leaves first (issue 19: thousands per pass)
        return value if math.isfinite(value) else None
    if kind is str or kind is int or kind is bool or value is None:
        return value
    if kind is np.ndarray and value.dtype.kind == "f" and np.isfinite(value).all():
        return value.tolist()                 # nothing to replace: Python floats already
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, np.datetime64):
        return iso_utc(value, 9)
    if isinstance(value, np.generic):
        return json_ready(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(value, indent: int | None = 2) -> str:
    """Deterministic JSON text (keys sorted) of :func:`json_ready` of ``value``, newline-terminated."""
    return json.dumps(json_ready(value), indent=indent, sort_keys=True, allow_nan=False) + "\n"
