"""The smoothing record, read in one place: what ``trackproc smooth`` leaves in a pass file's
metadata (key ``smoothing``, the same object as its ``--summary`` JSON) for later commands.

Written by :func:`trackproc.pipeline.smooth.smooth` (``_fit_record``): ``{"counts": ...,
"fits": [record, ...], "output": "samples" | "grid", ...}``, one record per station, pass and
kind with ``station``, ``pass_id``, ``kind``, ``unit``, ``status``, ``epoch_utc``, ``n_used``
and, when a polynomial was fitted, ``basis``, ``domain_s``, ``degree``, ``coefficients``,
``covariance_unscaled``, ``chi2``, ``dof``, ``rms``, ``weighted_rms``, ``condition_number``,
``tca`` (``status`` ``ok`` or ``not_observed``, ``time_utc``, ``sigma_s``, ...) and ``fca_hz``
(docs/smooth.md). Read by ``refine`` (the smoothed curve of seed 004 eq. 14) and ``batch``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["META_KEY", "smoothing_of", "output_of", "find_fit_record", "fit_from_record", "record_epoch",
           "fit_summary"]

#: Key of the record in a pass file's metadata.
META_KEY = "smoothing"


def smoothing_of(meta) -> dict:
    """The smoothing record of a pass file's metadata ({} when it was not smoothed)."""
    return (meta or {}).get(META_KEY) or {}


def output_of(meta):
    """``"samples"`` or ``"grid"`` (what ``smooth`` wrote), or None."""
    return smoothing_of(meta).get("output")


def find_fit_record(meta, station: str, pass_id: str, kind: str):
    """The record of ``station``/``pass_id``/``kind`` that holds a fitted polynomial, or None."""
    for r in smoothing_of(meta).get("fits", []) or []:
        if (r.get("station"), r.get("pass_id"), r.get("kind")) == (station, pass_id, kind) and r.get("coefficients"):
            return r
    return None


def fit_from_record(rec: dict):
    """The :class:`~trackproc.methods.smoothing.PolynomialFit` of a record (seed 004 eq. 1's
    coefficients with their covariance; per-sample arrays are not stored and come back empty)."""
    from trackproc.methods.smoothing import PolynomialFit

    n_used = int(rec.get("n_used") or 0)
    cov = np.asarray(rec["covariance_unscaled"], float)
    return PolynomialFit(basis=str(rec["basis"]), domain_s=tuple(float(a) for a in rec["domain_s"]),
                         degree=int(rec["degree"]), coef=np.asarray(rec["coefficients"], float), cov_unscaled=cov,
                         chi2=float(rec["chi2"]), dof=int(rec["dof"]), used=np.ones(n_used, bool),
                         residual=np.zeros(n_used), rms=float(rec.get("rms") or math.nan),
                         wrms=float(rec.get("weighted_rms") or math.nan),
                         condition_number=float(rec.get("condition_number") or math.nan))


def record_epoch(rec: dict) -> np.datetime64:
    """The record's time origin (``epoch_utc``), UTC ``datetime64[ns]``."""
    return np.datetime64(str(rec["epoch_utc"]).rstrip("Zz"), "ns")


def fit_summary(rec: dict) -> dict:
    """The few numbers of a record a batch report shows."""
    tca = rec.get("tca") or {}
    return {"station": rec["station"], "pass_id": rec["pass_id"], "kind": rec["kind"], "status": rec["status"],
            "n_samples": rec["n_samples"], "n_used": rec.get("n_used"), "degree": rec.get("degree"),
            "rms": rec.get("rms"), "rms_unit": rec.get("unit"),
            "tca_utc": tca.get("time_utc"), "tca_sigma_s": tca.get("sigma_s"), "fca_hz": rec.get("fca_hz"),
            "error": rec.get("error") or tca.get("error")}
