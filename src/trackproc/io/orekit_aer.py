"""Orekit tutorial measurement files (``.aer``, e.g. Eutelsat W3B) -> raw samples.

Whitespace-separated lines ``date TYPE station values...``; ``#`` starts a comment line.
``date`` is ISO 8601 UTC (naive = UTC). Supported types:

- ``AZ_EL station az el``: azimuth from north through east and elevation, degrees;
- ``RANGE station r``: range in kilometres (one-way equivalent, as Orekit's ``Range``).

Values become radians and metres. Row numbers are the file's line numbers.
"""

from __future__ import annotations

import math
import re

import numpy as np

from trackproc.errors import InputError
from trackproc.io.raw import RawMeasurements
from trackproc.io.tabular import (DEG, TIME_EXPECTED, UNPARSEABLE_TIME, WRONG_TYPE,
                                  Problems, decode_text)

UNSUPPORTED_TYPE = "unsupported measurement type"

#: TYPE -> (number of values, [(kind, field name, factor to SI, unit as written), ...])
TYPES = {
    "AZ_EL": [("azimuth", "azimuth_deg", DEG, "deg"), ("elevation", "elevation_deg", DEG, "deg")],
    "RANGE": [("range", "range_km", 1e3, "km")],
}

_LINE = re.compile(r"\d{4}-\d{2}-\d{2}T\S+\s+[A-Z_]+\s+\S+\s+[-+0-9.]")


def looks_like_aer(head: str) -> bool:
    """True when the first non-comment line reads ``date TYPE station value``."""
    for line in head.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            return bool(_LINE.match(line))
    return False


def read_aer(data: bytes, source: str, *, drop_invalid: bool = False) -> RawMeasurements:
    """Parse an Orekit ``.aer`` file into raw samples (azimuth/elevation in rad, range in m)."""
    text = decode_text(data, source)
    times, stations, kinds, values, rows, units, columns, found, wrong_type, unsupported = (
        [], [], [], [], [], [], [], [], [], [])
    for line_no, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) < 3:
            raise InputError("too few fields", file=source, row=line_no, found=line.strip(),
                             expected="date TYPE station values...")
        date, mtype, station, numbers = fields[0], fields[1], fields[2], fields[3:]
        spec = TYPES.get(mtype.upper())
        if spec is None:
            spec = [("", "TYPE", math.nan, "")]
            numbers = [mtype]
        elif len(numbers) != len(spec):
            raise InputError(f"wrong number of values for {mtype}", file=source, row=line_no,
                             found=f"{len(numbers)} values",
                             expected=f"{len(spec)}: " + ", ".join(s[1] for s in spec))
        for (kind, name, factor, unit), text_value in zip(spec, numbers):
            try:
                value = float(text_value) * factor
                bad = False
            except ValueError:
                value, bad = math.nan, True
            times.append(date)
            stations.append(station)
            kinds.append(kind)
            values.append(value)
            rows.append(line_no)
            units.append(unit)
            columns.append(name)
            found.append(text_value)
            wrong_type.append(bad and kind != "")
            unsupported.append(kind == "")
    if not rows:
        raise InputError("empty input", file=source, row=1, found="no measurement lines",
                         expected="lines of 'date TYPE station values'")
    import pandas as pd  # start-up: pandas (~0.15 s) only when an .aer file is read (tabular imports this module)

    rows_arr = np.array(rows, dtype=np.int64)
    problems = Problems(rows_arr, source, order=np.arange(len(rows)))
    parsed = pd.to_datetime(pd.Series(times, dtype=object), utc=True, format="ISO8601", errors="coerce")
    time_values = parsed.dt.as_unit("ns")
    problems.add(UNSUPPORTED_TYPE, np.array(unsupported), column="TYPE", found=np.array(found, dtype=object),
                 expected="AZ_EL or RANGE")
    problems.add(UNPARSEABLE_TIME, time_values.isna().to_numpy(), column="date",
                 found=np.array(times, dtype=object), expected=TIME_EXPECTED)
    problems.add(WRONG_TYPE, np.array(wrong_type), column=np.array(columns, dtype=object),
                 found=np.array(found, dtype=object), expected="a number")
    values_arr = np.array(values)
    keep, dropped = problems.resolve(drop_invalid)
    frame = pd.DataFrame({
        "time": pd.DatetimeIndex(time_values),
        "station": np.array(stations, dtype=object),
        "kind": np.array(kinds, dtype=object),
        "value": values_arr,
        "sigma": np.nan,
        "row": rows_arr,
        "unit": np.array(units, dtype=object),
    })[keep].reset_index(drop=True)
    column = {"time": "date", "station": "station", "azimuth": "azimuth_deg",
              "elevation": "elevation_deg", "range": "range_km"}
    return RawMeasurements(frame=frame, source=source, column=column,
                           meta={"source": source, "dropped": dropped})
