"""The residuals of a solution of the shared problem, for people and files: per station and kind
(:func:`rms_table`) and per sample (:func:`residual_frame`)."""

from __future__ import annotations

import numpy as np

from trackproc.models import observation as ob
from trackproc.pipeline.od.options import UNITS
from trackproc.pipeline.od.problem import Problem
from trackproc.pipeline.od.samples import groups


def rms_table(problem: Problem, sol) -> dict:
    """Per station and kind: counts, edited, RMS (unit) and WRMS (normalized) of kept samples."""
    out = {}
    meas = problem.meas
    edited = np.asarray(sol.edited, bool)
    rows_of = dict(groups(meas.station, meas.kind))        # (station, kind) -> its rows, increasing
    for st in sorted({st for st, _ in rows_of}):
        for kind in ob.KINDS:
            rows = rows_of.get((st, kind))
            if rows is None:
                continue
            kept = rows[~edited[rows]]
            r = sol.residual[kept]
            z = sol.normalized[kept]
            out.setdefault(st, {})[kind] = {
                "n": int(rows.size), "edited": int(edited[rows].sum()), "unit": UNITS[kind],
                "rms": float(np.sqrt(np.mean(r * r))) if r.size else None,
                "mean": float(np.mean(r)) if r.size else None,
                "wrms": float(np.sqrt(np.mean(z * z))) if z.size else None}
    return out


def residual_frame(problem: Problem, sol) -> "DeferredFrame":
    """The residual table (:data:`RESIDUAL_COLUMNS`), samples in time order per station: its columns
    now, the DataFrame when first read (a :class:`DeferredField` of the result)."""
    meas = problem.meas
    # copies now (the table is the solution's as it stands), the text columns and the row order
    # when the table is read (~10 ms on a day of samples, for a table most runs never write)
    return DeferredFrame({
        "time": np.array(problem.times, "datetime64[ns]"), "station": np.array(meas.station),
        "pass_id": np.array(meas.pass_id), "kind": np.array(meas.kind),
        "observed": np.array(meas.observed), "computed": np.array(sol.computed),
        "residual": np.array(sol.residual), "normalized_residual": np.array(sol.normalized),
        "sigma": np.array(meas.sigma), "edited": sol.edited.astype(bool)})


class DeferredFrame:
    """A residual table's copied columns, built into the DataFrame (text columns as ``str``, the
    unit of each kind, rows in time order per station and kind) by :meth:`build` (pandas is
    imported there: a ``refine`` or ``estimate`` that writes no residual table never loads it)."""

    def __init__(self, raw: dict):
        self.raw = raw

    def build(self):
        import pandas as pd  # start-up: pandas (~0.15 s) only when the table is read

        raw = self.raw
        columns = {"time": raw["time"], "station": raw["station"].astype(str), "pass_id": raw["pass_id"].astype(str),
                   "kind": raw["kind"].astype(str), "unit": [UNITS[k] for k in raw["kind"]]}
        columns.update((name, raw[name]) for name in ("observed", "computed", "residual", "normalized_residual",
                                                      "sigma", "edited"))
        order = np.lexsort((columns["kind"].astype(str), raw["time"], columns["station"].astype(str)))
        columns["time"] = pd.DatetimeIndex(columns["time"]).tz_localize("UTC")
        return pd.DataFrame(columns).iloc[order].reset_index(drop=True)


class DeferredField:
    """A dataclass field that may be given a :class:`DeferredFrame`: the DataFrame is built when
    the field is first read, and kept."""

    def __set_name__(self, owner, name):
        self.slot = "_deferred_" + name

    def __get__(self, obj, owner=None):
        if obj is None:
            raise AttributeError(self.slot)          # no default value for the dataclass
        value = obj.__dict__[self.slot]
        if isinstance(value, DeferredFrame):
            value = obj.__dict__[self.slot] = value.build()
        return value

    def __set__(self, obj, value):
        obj.__dict__[self.slot] = value
