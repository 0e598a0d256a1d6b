"""CCSDS Orbit Parameter Message (OPM), KVN, with the 6 × 6 covariance: writer and reader.

Follows CCSDS 502.0-B-2 (Orbit Data Messages, Blue Book, Issue 2) section 3, OPM in keyword =
value notation: header (``CCSDS_OPM_VERS``, ``CREATION_DATE``, ``ORIGINATOR``), metadata
(``OBJECT_NAME``, ``OBJECT_ID``, ``CENTER_NAME``, ``REF_FRAME``, ``TIME_SYSTEM``), the state
vector (``EPOCH``, ``X`` .. ``Z_DOT`` in km and km/s) and the optional covariance in its
mandatory units — km², km²/s, km²/s² — as the **lower triangle** row by row::

    CX_X
    CY_X      CY_Y
    CZ_X      CZ_Y      CZ_Z
    CX_DOT_X  CX_DOT_Y  CX_DOT_Z  CX_DOT_X_DOT
    ...                                          CZ_DOT_Z_DOT

(21 keywords, ``COV_REF_FRAME`` optional: when absent the covariance is in ``REF_FRAME``.)
Times are UTC, ISO 8601 without a zone letter, as the standard writes them. Estimated
parameters beyond the state (range biases, Doppler offsets) have no OPM keyword: they are
written as ``COMMENT`` lines (and are in the JSON state file in full).
"""

from __future__ import annotations

import math
from datetime import datetime, timezone

import numpy as np

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes, write_text
from trackproc.io.statefile import FORCE_LABELS
from trackproc.io.validate import check_name
from trackproc.isotime import iso_utc

__all__ = ["COVARIANCE_KEYS", "opm_text", "write_opm", "parse_opm", "read_opm"]

VERSION = "2.0"
_AXES = ("X", "Y", "Z", "X_DOT", "Y_DOT", "Z_DOT")
#: The 21 covariance keywords in lower-triangle row order, with their (row, column).
COVARIANCE_KEYS = tuple((f"C{_AXES[i]}_{_AXES[j]}", i, j) for i in range(6) for j in range(i + 1))
_STATE_KEYS = _AXES


def _epoch_text(t) -> str:
    return iso_utc(t, 6, suffix="")


def _num(value: float) -> str:
    return f"{value: .16e}"


def opm_text(state, *, object_name: str = "UNKNOWN", object_id: str = "UNKNOWN", originator: str = "TRACKPROC",
             creation_date=None, comments=()) -> str:
    """OPM KVN text of a GCRF :class:`~trackproc.io.statefile.State` (covariance if it has one).

    ``state.state_covariance`` (m, m/s) is converted to km and km/s; the other estimated
    parameters (if any) are listed in COMMENT lines with their sigmas.
    """
    for key, text in (("OBJECT_NAME", object_name), ("OBJECT_ID", object_id), ("ORIGINATOR", originator)):
        check_name(str(text), "OPM " + key, column=key)   # a newline would forge a KVN line
    created = creation_date or datetime.now(timezone.utc).replace(tzinfo=None)
    created_text = iso_utc(created, 3, suffix="")
    lines = [f"CCSDS_OPM_VERS = {VERSION}"]
    for c in comments:
        for part in str(c).splitlines():
            lines.append(f"COMMENT {part}")
    lines += [f"CREATION_DATE = {created_text}", f"ORIGINATOR = {originator}", "",
              f"OBJECT_NAME = {object_name}", f"OBJECT_ID = {object_id}", "CENTER_NAME = EARTH",
              "REF_FRAME = GCRF", "TIME_SYSTEM = UTC", ""]
    if state.force_model:
        label = FORCE_LABELS.get(state.force_model, state.force_model)
        lines.append(f"COMMENT force model {label}")
    quality = (state.extra or {}).get("quality") if hasattr(state, "extra") else None
    if isinstance(quality, dict) and quality.get("verdict"):
        lines.append(f"COMMENT {quality_comment(quality)}")
    lines.append(f"EPOCH = {_epoch_text(state.epoch)}")
    rv_km = np.concatenate([state.r_m, state.v_m_s]) / 1000.0
    for key, value, unit in zip(_STATE_KEYS, rv_km, ["km"] * 3 + ["km/s"] * 3):
        lines.append(f"{key} = {_num(value)} [{unit}]")
    extra = [p for p in state.parameters if p not in ("x", "y", "z", "vx", "vy", "vz")]
    if extra and state.values is not None:
        sigma = state.sigma if state.sigma is not None else np.full(len(state.parameters), math.nan)
        lines.append("")
        lines.append("COMMENT other estimated parameters (SI units), value and 1-sigma:")
        for p in extra:
            i = state.parameters.index(p)
            lines.append(f"COMMENT {p} = {float(state.values[i])!r} +/- {float(sigma[i])!r}")
    cov = state.state_covariance
    if cov is not None:
        lines.append("")
        lines.append("COMMENT covariance in km**2, km**2/s, km**2/s**2 (lower triangle)")
        lines.append("COV_REF_FRAME = GCRF")
        ckm = np.asarray(cov, float) / 1.0e6
        for key, i, j in COVARIANCE_KEYS:
            lines.append(f"{key} = {_num(ckm[i, j])}")
    return "\n".join(lines) + "\n"


def quality_comment(quality: dict) -> str:
    """The OPM comment of a ``quality`` verdict (one line, machine-readable):
    ``QUALITY verdict=suspect reasons=low_pass,whiteness`` (the reasons not ``ok``)."""
    bad = [r.get("code", "?") for r in quality.get("reasons", []) if r.get("severity", "suspect") != "ok"]
    return f"QUALITY verdict={quality['verdict']} reasons={','.join(bad) if bad else 'none'}"


def write_opm(state, path: str, **kwargs) -> None:
    """Write :func:`opm_text` atomically to ``path`` (``-`` = stdout)."""
    write_text(path, opm_text(state, **kwargs))


def parse_opm(text: str, source: str = "<opm>") -> dict:
    """Read back an OPM KVN: ``{"epoch", "ref_frame", "time_system", "r_m", "v_m_s", "covariance"
    (6 × 6 m-based or None), "meta": {...}}``. Only what :func:`opm_text` writes is interpreted."""
    values, meta = {}, {}
    for row, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("COMMENT"):
            continue
        key, sep, value = line.partition("=")
        if not sep:
            raise InputError("not a KVN line", file=source, row=row, found=line, expected="KEYWORD = value")
        key = key.strip()
        value = value.strip()
        if value.endswith("]"):
            value = value[: value.rfind("[")].strip()
        values[key] = (value, row)
    for key in ("CCSDS_OPM_VERS", "EPOCH", "REF_FRAME", "TIME_SYSTEM") + _STATE_KEYS:
        if key not in values:
            raise InputError("missing keyword", file=source, column=key, expected="a CCSDS OPM (KVN)")

    def number(key):
        value, row = values[key]
        try:
            return float(value)
        except ValueError:
            raise InputError("not a number", file=source, row=row, column=key, found=value) from None

    for key in ("OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "ORIGINATOR", "CREATION_DATE", "COV_REF_FRAME"):
        if key in values:
            meta[key] = values[key][0]
    rv = np.array([number(k) for k in _STATE_KEYS]) * 1000.0
    cov = None
    if any(k in values for k, _, _ in COVARIANCE_KEYS):
        cov = np.zeros((6, 6))
        for key, i, j in COVARIANCE_KEYS:
            if key not in values:
                raise InputError("incomplete covariance", file=source, column=key,
                                 expected="all 21 lower-triangle keywords")
            cov[i, j] = cov[j, i] = number(key) * 1.0e6
    return {"version": values["CCSDS_OPM_VERS"][0], "epoch": np.datetime64(values["EPOCH"][0], "ns"),
            "ref_frame": values["REF_FRAME"][0], "time_system": values["TIME_SYSTEM"][0],
            "r_m": rv[:3], "v_m_s": rv[3:], "covariance": cov, "meta": meta}


def read_opm(path: str) -> dict:
    """:func:`parse_opm` of a file (or ``-``)."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_opm(read_input_bytes(path).decode("utf-8", errors="replace"), source)
