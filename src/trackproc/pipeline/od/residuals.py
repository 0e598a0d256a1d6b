"""The residuals of a solution of the shared problem, for people and files: per station and kind
(:func:`rms_table`) and per sample (:func:`residual_frame`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from trackproc.models import observation as ob
from trackproc.pipeline.od.options import UNITS
from trackproc.pipeline.od.problem import Problem


def rms_table(problem: Problem, sol) -> dict:
    """Per station and kind: counts, edited, RMS (unit) and WRMS (normalized) of kept samples."""
    out = {}
    meas = problem.meas
    for st in sorted(set(meas.station)):
        for kind in ob.KINDS:
            rows = (meas.station == st) & (meas.kind == kind)
            if not rows.any():
                continue
            kept = rows & ~sol.edited
            r = sol.residual[kept]
            z = sol.normalized[kept]
            out.setdefault(st, {})[kind] = {
                "n": int(rows.sum()), "edited": int((rows & sol.edited).sum()), "unit": UNITS[kind],
                "rms": float(np.sqrt(np.mean(r * r))) if r.size else None,
                "mean": float(np.mean(r)) if r.size else None,
                "wrms": float(np.sqrt(np.mean(z * z))) if z.size else None}
    return out


def residual_frame(problem: Problem, sol) -> pd.DataFrame:
    """The residual table (:data:`RESIDUAL_COLUMNS`), samples in time order per station."""
    meas = problem.meas
    frame = pd.DataFrame({
        "time": pd.DatetimeIndex(problem.times).tz_localize("UTC"), "station": meas.station.astype(str),
        "pass_id": meas.pass_id.astype(str), "kind": meas.kind.astype(str),
        "unit": [UNITS[k] for k in meas.kind], "observed": meas.observed, "computed": sol.computed,
        "residual": sol.residual, "normalized_residual": sol.normalized, "sigma": meas.sigma,
        "edited": sol.edited.astype(bool)})
    order = np.lexsort((frame["kind"].to_numpy(dtype=str), problem.times, frame["station"].to_numpy(dtype=str)))
    return frame.iloc[order].reset_index(drop=True)
