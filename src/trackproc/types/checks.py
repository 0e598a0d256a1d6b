"""Plausibility checks where inputs enter: what no real tracking input can hold is an input error.

The limits of each data type's values live here, below ``io``, so that the types
(:mod:`trackproc.types`) check themselves; :mod:`trackproc.io.validate` re-exports every name.

One home for the limits (issue 14 items 2-4, issue 13 item 5); readers and command entries call
these functions, each raising :class:`~trackproc.errors.InputError` naming the file, row or
field, what was found and what was expected. The limits are wide on purpose: they reject unit
mistakes (km for m, km/s for m/s, Hz for GHz) and corrupt values, never a real pass.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np

from trackproc.constants import MU_EARTH
from trackproc.errors import InputError
from trackproc.models.observables import range_rate_per_hz

#: Earliest and latest time a datetime64[ns] holds (1677-09-21 .. 2262-04-11); inputs are
#: accepted in whole years within it.
FIRST_YEAR, LAST_YEAR = 1678, 2261
#: Fastest line-of-sight speed of anything in an Earth orbit as seen from the ground, m/s
#: (escape speed at the surface is 11.2 km/s; issue 13 item 5).
MAX_LOS_SPEED_M_S = 12_000.0
#: Carriers of radio tracking links, Hz (VHF to beyond Ka band).
CARRIER_RANGE_HZ = (1.0e6, 1.0e12)
#: Station heights above the WGS-84 ellipsoid, m (the Dead Sea shore is -430 m; the geoid departs
#: by up to ~110 m; the highest observatories are near 5.6 km).
STATION_HEIGHT_RANGE_M = (-1_000.0, 10_000.0)
#: Distance of a satellite from the geocentre: at least the polar radius, at most ~ the Earth's
#: Hill sphere (1.5e9 m).
ORBIT_RADIUS_RANGE_M = (6_356_000.0, 1.5e9)
#: A speed below this fraction of the circular speed at that radius is a unit mistake
#: (km/s given for m/s is 1e-3), not a trajectory.
MIN_SPEED_FRACTION = 0.05
#: Longest name (station, object, pass) accepted from an input or an option.
MAX_NAME = 200
#: Propagation and simulation spans, s, and row counts, the commands accept.
MAX_SPAN_S = 400 * 86400.0
MAX_ROWS = 20_000_000

_CONTROL = re.compile(r"[\x00-\x1f\x7f\u0085\u2028\u2029]")


def check_name(value, what: str, *, file: str | None = None, row: int | None = None,
               column: str | None = None) -> str:
    """A name from an input or an option (station, object, pass): a string of printable
    characters (a newline would forge a line of a KVN output or of the log)."""
    if not isinstance(value, str):
        raise InputError(f"{what} is not a text", file=file, row=row, column=column,
                         found=value, expected="a name (a string)")
    if _CONTROL.search(value):
        raise InputError(f"{what} holds a control character", file=file, row=row, column=column,
                         found=value, expected="printable characters only (no newline, tab or NUL)")
    if not value.strip() or len(value) > MAX_NAME:
        raise InputError(f"invalid {what}", file=file, row=row, column=column, found=value,
                         expected=f"1 to {MAX_NAME} printable characters")
    return value


def check_year(year: int, *, file: str | None = None, row: int | None = None,
               column: str | None = None, found=None) -> None:
    """A time must lie within what a nanosecond timestamp holds (years 1678-2261): beyond, the
    representation wraps silently (2300 becomes 1715)."""
    if not FIRST_YEAR <= year <= LAST_YEAR:
        raise InputError("time outside the supported span", file=file, row=row, column=column,
                         found=found if found is not None else year,
                         expected=f"a UTC time in the years {FIRST_YEAR}-{LAST_YEAR}")


def check_iso_year(text: str, **where) -> None:
    """:func:`check_year` on the year of an ISO 8601 / TDM epoch text (``YYYY-...``)."""
    match = re.match(r"\s*([+-]?\d{4,})", str(text))
    if match:
        check_year(int(match.group(1)), found=text, **where)


def check_carrier(carrier_hz, *, file: str | None = None, column: str = "--carrier-hz") -> float:
    """A nominal carrier of a radio link, in Hz (2.2 is GHz given for Hz: rejected)."""
    try:
        value = float(carrier_hz)
    except (TypeError, ValueError):
        value = math.nan
    low, high = CARRIER_RANGE_HZ
    if isinstance(carrier_hz, bool) or not (math.isfinite(value) and low <= value <= high):
        raise InputError("implausible carrier frequency", file=file, column=column, found=carrier_hz,
                         expected=f"a carrier in Hz between {low:g} and {high:g} (e.g. 2.2e9)")
    return value


def stated_carrier(meta, *, file: str | None = None, needed: bool = False, missing: float | None = math.nan):
    """The carrier a pass file's metadata states, in Hz; ``missing`` when it states none.

    The value was checked where it entered (:func:`check_carrier`: ingest's ``--carrier-hz`` or an
    input's own carrier, a pass file's metadata when it is read), so it is trusted here;
    ``needed`` (Doppler samples to convert) makes a missing carrier the input error."""
    carrier = (meta or {}).get("carrier_hz")
    if carrier is None:
        if needed:
            raise InputError("Doppler samples need the carrier frequency", file=file, column="carrier_hz",
                             found=None, expected="carrier_hz in the file metadata (trackproc ingest --carrier-hz)")
        return missing
    return float(carrier)


def doppler_speed_factor(carrier_hz: float, mode: str | None) -> float:
    """|line-of-sight speed| per Hz of Doppler: c / carrier one-way, c / (2 carrier) two-way."""
    return abs(range_rate_per_hz(carrier_hz, mode == "two-way"))


def check_los_speed(values, kind: str, *, carrier_hz: float | None = None, mode: str | None = None,
                    file: str | None = None, rows=None, column: str | None = None) -> None:
    """Range-rate or Doppler samples: the line-of-sight speed they imply must be one an Earth
    orbit allows (|range-rate| <= 12 km/s; issue 13 item 5). Range-rate: every sample; Doppler:
    the median sample of the file (see below)."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return
    if kind == "doppler":
        if carrier_hz is None:
            return
        speed = np.abs(values) * doppler_speed_factor(carrier_hz, mode)
        expected = (f"a median |Doppler| <= {MAX_LOS_SPEED_M_S / doppler_speed_factor(carrier_hz, mode):.6g} Hz "
                    f"at a carrier of {carrier_hz:g} Hz ({mode or 'one-way'}), i.e. a line-of-sight "
                    f"speed <= {MAX_LOS_SPEED_M_S / 1000:g} km/s; is the carrier in Hz?")
    else:
        speed = np.abs(values)
        expected = f"|range-rate| <= {MAX_LOS_SPEED_M_S:g} m/s (an Earth orbit); is it in m/s?"
    finite = np.isfinite(speed)
    if kind == "doppler":
        # A one-way Doppler holds the transmitter's unknown offset and real passes hold spurious
        # tones (DopTrack, 12 April 2020: 91 samples beyond 12 km/s): the file's median decides,
        # which a wrong carrier unit (2.2 for 2.2e9 Hz) moves by orders of magnitude.
        if not finite.any() or np.median(speed[finite]) <= MAX_LOS_SPEED_M_S:
            return
        i = int(np.flatnonzero(finite)[np.argsort(speed[finite])[finite.sum() // 2]])
        detail = f"implausible Doppler: the median sample implies {speed[i] / 1000:.4g} km/s"
    else:
        bad = np.flatnonzero(finite & (speed > MAX_LOS_SPEED_M_S))
        if not bad.size:
            return
        i = int(bad[0])
        detail = f"implausible range-rate ({bad.size} samples)"
    row = None if rows is None else int(np.asarray(rows)[i])
    raise InputError(detail, file=file, row=row, column=column, found=float(values[i]), expected=expected)


def check_station(name: str, lat_deg, lon_deg, height_m, *, file: str | None = None,
                  row: int | None = None, prefix: str = "", columns: dict | None = None) -> None:
    """A ground station: latitude in [-90, 90], longitude in [-180, 360), height within
    :data:`STATION_HEIGHT_RANGE_M` of the WGS-84 ellipsoid."""
    checks = (
        ("lat_deg", lat_deg, lambda v: -90.0 <= v <= 90.0, "degrees in [-90, 90]"),
        ("lon_deg", lon_deg, lambda v: -180.0 <= v < 360.0, "degrees in [-180, 360)"),
        ("height_m", height_m,
         lambda v: STATION_HEIGHT_RANGE_M[0] <= v <= STATION_HEIGHT_RANGE_M[1],
         f"metres above the WGS-84 ellipsoid in [{STATION_HEIGHT_RANGE_M[0]:g}, {STATION_HEIGHT_RANGE_M[1]:g}] "
         "(a ground station)"),
    )
    for key, value, ok, expected in checks:
        number = _float(value)
        if not (math.isfinite(number) and ok(number)):
            raise InputError(f"implausible coordinate of station {name}", file=file, row=row,
                             column=(columns or {}).get(key, prefix + key), found=value, expected=expected)


def check_orbit_state(position_m, velocity_m_s, *, file: str | None = None, field: str = "") -> None:
    """A geocentric state of something in Earth orbit (or on a ballistic arc above the surface):
    |r| between the polar radius and the Hill sphere, |v| below the escape speed at |r| and
    above a twentieth of the circular speed (a state in km or km/s fails here)."""
    r = np.asarray(position_m, dtype=float).reshape(-1)
    v = np.asarray(velocity_m_s, dtype=float).reshape(-1)
    prefix = f"{field}." if field else ""
    if r.size != 3 or not np.all(np.isfinite(r)):
        raise InputError("invalid position", file=file, column=prefix + "position_m", found=r.tolist(),
                         expected="three finite numbers, metres")
    if v.size != 3 or not np.all(np.isfinite(v)):
        raise InputError("invalid velocity", file=file, column=prefix + "velocity_m_s", found=v.tolist(),
                         expected="three finite numbers, m/s")
    radius, speed = float(np.linalg.norm(r)), float(np.linalg.norm(v))
    low, high = ORBIT_RADIUS_RANGE_M
    if not low <= radius <= high:
        raise InputError("implausible position: |r| = %.6g m" % radius, file=file, column=prefix + "position_m",
                         found=r.tolist(),
                         expected=f"|r| between {low:g} m (the Earth's surface) and {high:g} m; is it in metres?")
    escape = math.sqrt(2.0 * MU_EARTH / radius)
    if speed >= escape:
        raise InputError("implausible velocity: |v| = %.6g m/s is above the escape speed %.6g m/s" % (speed, escape),
                         file=file, column=prefix + "velocity_m_s", found=v.tolist(),
                         expected="a bound Earth orbit, velocity in m/s")
    if speed < MIN_SPEED_FRACTION * escape / math.sqrt(2.0):
        raise InputError("implausible velocity: |v| = %.6g m/s" % speed, file=file,
                         column=prefix + "velocity_m_s", found=v.tolist(),
                         expected=f"|v| of an orbit at |r| = {radius:.6g} m (circular speed "
                                  f"{escape / math.sqrt(2.0):.6g} m/s); is it in m/s, not km/s?")


def check_span(seconds, what: str, *, column: str) -> None:
    """A propagation or simulation span within :data:`MAX_SPAN_S` (beyond, the computation would
    run for hours: refused before it starts)."""
    value = _float(seconds)
    if not (math.isfinite(value) and abs(value) <= MAX_SPAN_S):
        raise InputError(f"{what} too long", column=column, found=seconds,
                         expected=f"at most {MAX_SPAN_S / 86400:g} days ({MAX_SPAN_S:g} s)")


def check_rows(count, what: str, *, column: str) -> None:
    """A number of output rows within :data:`MAX_ROWS`."""
    if not (math.isfinite(_float(count)) and count <= MAX_ROWS):
        raise InputError(f"too many {what}", column=column, found=count,
                         expected=f"at most {MAX_ROWS:g} rows (a longer step or a shorter span)")


def check_distinct_files(paths, what: str) -> None:
    """The same input named twice (``estimate f f``, or a link to it) would count every sample
    twice and make every sigma sqrt(2) too small: an input error."""
    seen: dict = {}
    for path in paths:
        if str(path) == "-":
            continue
        try:
            st = os.stat(path)
            key = (st.st_dev, st.st_ino)
        except OSError:
            key = os.path.realpath(path)   # a missing file is reported by its reader
        if key in seen:
            raise InputError("the same file given twice", file=str(path), column=what,
                             found=f"{seen[key]} and {path}",
                             expected="each input once (its samples would count twice)")
        seen[key] = str(path)


def check_no_repeated_samples(frames) -> None:
    """The same sample (station, kind, time) in two inputs (a copy of a pass file): an input
    error naming both files. ``frames`` is a list of (source, DataFrame with station, kind, time)."""
    if len(frames) < 2:
        return
    import pandas as pd  # start-up: pandas (~0.15 s) only when several inputs are compared

    parts = [pd.DataFrame({"station": f["station"].astype(str).to_numpy(), "kind": f["kind"].astype(str).to_numpy(),
                           "time": f["time"].to_numpy(), "input": i})
             for i, (_, f) in enumerate(frames)]
    both = pd.concat(parts, ignore_index=True)
    repeated = both.duplicated(["station", "kind", "time"], keep=False)
    if not repeated.any():
        return
    dup = both[repeated]
    first = dup.iloc[0]
    same = dup[(dup["station"] == first["station"]) & (dup["kind"] == first["kind"]) & (dup["time"] == first["time"])]
    inputs = sorted(set(same["input"]))
    if len(inputs) < 2:   # repeated inside one file: its own reader's business
        others = dup.groupby(["station", "kind", "time"])["input"].nunique()
        if not (others > 1).any():
            return
        key = others[others > 1].index[0]
        same = dup[(dup["station"] == key[0]) & (dup["kind"] == key[1]) & (dup["time"] == key[2])]
        inputs = sorted(set(same["input"]))
        first = same.iloc[0]
    n = int(both.duplicated(["station", "kind", "time"]).sum())
    raise InputError(f"{n} samples appear in two inputs", file=frames[inputs[1]][0], column="time",
                     found=f"station {first['station']}, {first['kind']} at {pd.Timestamp(first['time'])} "
                           f"also in {frames[inputs[0]][0]}",
                     expected="each sample in one input only (it would count twice)")


#: Default largest number of rows (samples) read from one input; ``TRACKPROC_MAX_INPUT_ROWS``
#: overrides it. ``ingest`` streams (~50 bytes a sample kept, benchmarks/ingest_memory.py: 5e6 rows
#: in ~0.5 GB), so 1e7 rows stay near 1 GB; commands that load a pass table whole need more a row.
DEFAULT_MAX_INPUT_ROWS = 10_000_000


def max_input_rows() -> int:
    text = os.environ.get("TRACKPROC_MAX_INPUT_ROWS", "")
    if not text:
        return DEFAULT_MAX_INPUT_ROWS
    value = _float(text)
    if not (math.isfinite(value) and value >= 1):
        raise InputError("invalid environment variable", column="TRACKPROC_MAX_INPUT_ROWS", found=text,
                         expected="a positive number of rows")
    return int(value)


def check_input_rows(count: int, *, file: str | None = None) -> None:
    """An input of more rows than :func:`max_input_rows` is refused before it is parsed."""
    limit = max_input_rows()
    if count > limit:
        raise InputError(f"input of {count} rows, more than the limit of {limit}", file=file,
                         expected="a smaller input (split it), or a larger TRACKPROC_MAX_INPUT_ROWS")


def _float(value) -> float:
    if isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError, OverflowError):
        return math.nan


#: Units a duration may carry (``90s``, ``45m``, ``6h``, ``2d``); a plain number is in the option's
#: own unit (seconds, except where the option says otherwise, e.g. ``fit-tle --horizon`` days).
DURATION_UNITS_S = {"s": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}
_DURATION = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?)\s*(s|min|m|h|d)?")


def parse_duration(text, option: str, *, plain_unit_s: float = 1.0) -> float:
    """``3600``, ``90s``, ``45m``, ``1.5h``, ``2d``, ``-1d`` -> seconds (a plain number counts in
    ``plain_unit_s``). Every option that takes a duration is read by this one function."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text) * plain_unit_s
    else:
        match = _DURATION.fullmatch(str(text).strip().lower())
        if match is None:
            plain = {1.0: "seconds", 86400.0: "days"}.get(plain_unit_s, f"{plain_unit_s:g} s")
            raise InputError("invalid duration", column=option, found=str(text),
                             expected=f"a number of {plain}, or one with a unit s, m, h or d (90s, 45m, 1.5h, 2d)")
        unit = match.group(2)
        value = float(match.group(1)) * (DURATION_UNITS_S[unit] if unit else plain_unit_s)
    if not math.isfinite(value):
        raise InputError("invalid duration", column=option, found=str(text), expected="a finite duration")
    return value
