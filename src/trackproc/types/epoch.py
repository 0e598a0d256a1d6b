"""The epoch type: a UTC ``datetime64[ns]`` read from ISO 8601 text (:func:`parse_epoch`), within the
years a nanosecond timestamp holds."""

from __future__ import annotations

import numpy as np

from trackproc.errors import InputError
from trackproc.types.checks import check_iso_year


def parse_epoch(text: str, *, file: str | None = None, column: str = "epoch") -> np.datetime64:
    """ISO 8601 UTC text -> ``datetime64[ns]``. ``Z``, ``+00:00`` or any other offset (converted
    to UTC) are accepted; no offset means UTC. Leap seconds (``23:59:60``) cannot be held."""
    expected = "an ISO 8601 UTC time such as 2026-03-20T09:30:00.000Z"
    if not isinstance(text, str) or not text.strip():
        raise InputError("invalid epoch", file=file, column=column, found=text, expected=expected)
    s = text.strip().replace(" ", "T", 1) if "T" not in text else text.strip()
    offset_s = 0
    if s.endswith(("Z", "z")):
        s = s[:-1]
    else:
        tail = s[-6:]
        if len(s) > 16 and tail[0] in "+-" and tail[3] == ":" and tail[1:3].isdigit() and tail[4:].isdigit():
            sign = 1 if tail[0] == "+" else -1
            offset_s = sign * (int(tail[1:3]) * 3600 + int(tail[4:]) * 60)
            s = s[:-6]
    if ":60" in s[13:19]:
        raise InputError("leap-second epoch (23:59:60) cannot be represented", file=file, column=column,
                         found=text, expected="an epoch outside the leap second")
    if len(s) < 10 or not s[:4].isdigit() or s[4] != "-":
        raise InputError("invalid epoch", file=file, column=column, found=text, expected=expected)
    check_iso_year(s, file=file, column=column)
    try:
        t = np.datetime64(s, "ns")
    except ValueError:
        raise InputError("invalid epoch", file=file, column=column, found=text, expected=expected) from None
    if np.isnat(t):
        raise InputError("invalid epoch", file=file, column=column, found=text, expected=expected)
    return t - np.timedelta64(offset_s, "s")
