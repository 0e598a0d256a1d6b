"""ISO 8601 UTC time text, written once: every timestamp a file, a message or a log line shows.

``2026-03-20T09:30:00.000Z``: UTC, a ``T``, a ``Z``. The number of fractional digits is the
caller's choice (it is part of each file format's contract): ``digits=None`` milliseconds at
least and more only when needed (state files, messages), a fixed count 0-9 otherwise;
:func:`iso_utc_array` writes a column at the coarsest precision that is exact for all of it.
Fractions are truncated, never rounded (a time is never shown later than it is).
A leaf module (numpy only, pandas when given a tz-aware time), like ``constants`` and
``vocabulary``: every layer may import it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["to_datetime64_ns", "iso_utc", "iso_utc_array", "iso_utc_offset"]


def to_datetime64_ns(t) -> np.datetime64:
    """A UTC ``datetime64[ns]`` from a datetime64, a (tz-aware or naive = UTC) pandas Timestamp or
    datetime, or an ISO string."""
    if getattr(t, "tzinfo", None) is not None:
        import pandas as pd  # start-up: isotime is a leaf every layer imports; pandas only for Timestamps

        t = pd.Timestamp(t).tz_convert("UTC").tz_localize(None)
    if hasattr(t, "to_datetime64"):
        t = t.to_datetime64()
    return np.datetime64(t, "ns")


def iso_utc(t, digits: int | None = None, *, suffix: str = "Z") -> str:
    """ISO 8601 text of one UTC time: ``digits`` fractional digits (0-9, truncated), or with
    ``None`` milliseconds at least and more digits only when needed; ``suffix`` ``"Z"`` (or ``""``
    where a format has its own time-system keyword, as CCSDS OPM)."""
    text = np.datetime_as_string(to_datetime64_ns(t), unit="ns")
    date, frac = text.split(".")
    if digits is None:
        frac = frac.rstrip("0")
        frac = frac + "0" * (3 - len(frac)) if len(frac) < 3 else frac
    else:
        frac = frac[:digits]
    return f"{date}.{frac}{suffix}" if frac else f"{date}{suffix}"


def iso_utc_array(ns) -> np.ndarray:
    """ISO 8601 text (``Z``) of UTC ``datetime64[ns]`` values at the coarsest precision (s, ms, us
    or ns) that is exact for every one of them."""
    ns = np.asarray(ns, dtype="datetime64[ns]")
    ints = ns.astype(np.int64)
    unit = "ns"
    for candidate, step in (("s", 10**9), ("ms", 10**6), ("us", 10**3)):
        if np.all(ints % step == 0):
            unit = candidate
            break
    return np.char.add(np.datetime_as_string(ns, unit=unit), "Z")


def iso_utc_offset(t) -> str:
    """``YYYY-MM-DDTHH:MM:SS[.ffffff[fff]]+00:00``: a UTC ``datetime64`` as pandas'
    ``Timestamp.isoformat`` writes a tz-aware UTC time (the input-error messages that showed it so
    keep their text without pandas)."""
    t = np.datetime64(t, "ns")
    if np.isnat(t):
        return "NaT"
    date, frac = np.datetime_as_string(t, unit="ns").split(".")
    frac = "" if frac == "000000000" else "." + (frac[:6] if frac.endswith("000") else frac)
    return f"{date}{frac}+00:00"
