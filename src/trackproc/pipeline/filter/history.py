"""The filter's outputs beside the state file, as tables: the innovation table (``--residuals``),
the history of every filtered and smoothed state with its covariance (``--history`` CSV, and CCSDS OEM
with covariance blocks), the RTN sigmas over time (``--plot``)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from trackproc.dynamics.rtn import rtn_covariance
from trackproc.io.statefile import format_epoch
from trackproc.pipeline.od import UNITS, Problem
from trackproc.pipeline.od.state import sigma_rtn

INNOVATION_COLUMNS = ("time", "station", "pass_id", "kind", "unit", "observed", "predicted", "innovation",
                      "innovation_sigma", "normalized_innovation", "edited", "residual")


def utc_of_step(problem: Problem, sw, k: int):
    """The UTC time of the sweep's step ``k`` (the problem's epoch for the a-priori step at t = 0)."""
    if sw.t_s[k] == 0.0:
        return problem.epoch
    i = int(np.flatnonzero(sw.step == k)[0])
    return problem.times[i]


def solutions(sw) -> list:
    """``[(which, label), ...]`` of the solutions a sweep holds: ``("f", "filtered")``, and
    ``("s", "smoothed")`` after the smoother."""
    return [(which, label) for which, label in (("f", "filtered"), ("s", "smoothed"))
            if getattr(sw, "x_" + which) is not None]


def innovation_frame(problem: Problem, sw) -> pd.DataFrame:
    """The innovation table (:data:`INNOVATION_COLUMNS`), in time order."""
    meas = problem.meas
    sig = np.sqrt(sw.variance)
    frame = pd.DataFrame({
        "time": pd.DatetimeIndex(problem.times).tz_localize("UTC"), "station": meas.station.astype(str),
        "pass_id": meas.pass_id.astype(str), "kind": meas.kind.astype(str), "unit": [UNITS[k] for k in meas.kind],
        "observed": meas.observed, "predicted": meas.observed - sw.innovation, "innovation": sw.innovation,
        "innovation_sigma": sig, "normalized_innovation": sw.innovation / sig, "edited": sw.edited,
        "residual": sw.residuals("f")})
    if sw.x_s is not None:
        frame["smoothed_residual"] = sw.residuals("s")
    order = np.lexsort((np.arange(len(frame)), problem.times))
    return frame.iloc[order].reset_index(drop=True)


def history_frame(problem: Problem, sw) -> pd.DataFrame:
    """One row per step and solution (``filtered``, ``smoothed``): time, the values, sigmas and
    the covariance's lower triangle (``cov_I_J``, rows/columns in parameter order)."""
    names = problem.names
    n = len(names)
    low = np.tril_indices(n)
    rows = []
    for which, label in solutions(sw):
        for k in range(sw.t_s.size):
            x, p = sw.absolute(which, k)
            row = {"time": format_epoch(utc_of_step(problem, sw, k)), "solution": label}
            row.update({nm: float(v) for nm, v in zip(names, x)})
            row.update({f"sigma_{nm}": float(math.sqrt(max(p[i, i], 0.0))) for i, nm in enumerate(names)})
            row.update({f"cov_{i}_{j}": float(p[i, j]) for i, j in zip(*low)})
            rows.append(row)
    return pd.DataFrame(rows)


def sigma_rtn_frame(problem: Problem, sw) -> pd.DataFrame:
    """One row per step and solution (``filtered``, ``smoothed``): ``time`` (UTC), ``solution``
    and the RTN sigmas of the state file's ``sigma_rtn`` (``radial_m`` ... ``cross_m_s``)."""
    rows = []
    for which, label in solutions(sw):
        for k in range(sw.t_s.size):
            x, p = sw.absolute(which, k)
            rows.append({"time": pd.Timestamp(utc_of_step(problem, sw, k)).tz_localize("UTC"), "solution": label,
                         **sigma_rtn(rtn_covariance(x[:3], x[3:6], p[:6, :6]))})
    return pd.DataFrame(rows)


def history_ephemerides(problem: Problem, sw, state=None) -> list:
    """``[(label, Ephemeris), ...]`` per solution (``filtered``, ``smoothed``): every step's
    position, velocity (GCRF, m, m/s) and the orbit's 6 × 6 block of the filter's covariance
    (``cov_I_J``, I, J = 1..6)."""
    from trackproc.io.ephemeris import COLUMNS, Ephemeris

    out = []
    meta = {}
    if state is not None:
        meta = {"force_model": state.force_model, "constants": state.constants}
    for which, label in solutions(sw):
        xs, ps = [], []
        for k in range(sw.t_s.size):
            x, p = sw.absolute(which, k)
            xs.append(x[:6])
            ps.append(p[:6, :6])
        times = pd.DatetimeIndex([utc_of_step(problem, sw, k) for k in range(sw.t_s.size)]).tz_localize("UTC")
        frame = pd.DataFrame({"time": times, **{c: np.array(xs)[:, i] for i, c in enumerate(COLUMNS[1:])}})
        cov = np.array(ps)
        for i in range(6):
            for j in range(6):
                frame[f"cov_{i + 1}_{j + 1}"] = cov[:, i, j]
        out.append((label, Ephemeris(frame, dict(meta))))
    return out


def history_oem(problem: Problem, sw, state=None, **oem_kwargs) -> str:
    """The history as CCSDS OEM KVN (CCSDS 502.0-B-3): one segment per solution (filtered, then
    smoothed), each with its covariance section (the filter's orbit covariance at every step)."""
    from trackproc.io.ephemeris import oem_segments_text

    segments = [(eph, f"{label} states of trackproc filter") for label, eph in history_ephemerides(problem, sw, state)]
    return oem_segments_text(segments, **oem_kwargs)
