"""Two-line elements: read and check a TLE, run SGP4, give a GCRF :class:`~trackproc.io.statefile.State`.

A TLE file holds two lines (``1 ...``, ``2 ...``) or three (a name line first, optionally
``0 NAME``). Each element line is 69 characters whose last is a modulo-10 checksum: the sum of
its digits, with each ``-`` counting 1 (Hoots & Roehrich, Spacetrack Report #3; CelesTrak
"NORAD Two-Line Element Set Format").

SGP4 is Vallado's reference implementation (``sgp4.api.Satrec.twoline2rv``, WGS-72
constants, as the elements were fitted with). Its output is in TEME at a UTC time; it is
converted to GCRF through ITRF (GMST 1982 and polar motion, then IAU 2006/2000A) by
:func:`trackproc.dynamics.frames.teme_to_gcrf` (Vallado et al. 2006, AIAA 2006-6753).
A TLE is a mean-element set: the osculating state SGP4 gives at the epoch is accurate to
about a kilometre, good as an initial guess, not as truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from sgp4.api import Satrec

from trackproc.errors import InputError, ProcessingError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.dynamics.timescales import datetime64_to_jd_utc, jd_utc_to_datetime64
from trackproc.dynamics import frames
from trackproc.io.statefile import State, parse_epoch


@dataclass(frozen=True)
class Tle:
    """A checked TLE: ``name`` (or None), the two element lines, and where they came from."""

    name: str | None
    line1: str
    line2: str
    source: str = "<tle>"

    @property
    def satnum(self) -> str:
        return self.line1[2:7].strip()


def checksum(line: str) -> int:
    """Modulo-10 checksum of the first 68 characters: digits count their value, ``-`` counts 1."""
    return sum(int(c) if c.isdigit() else 1 if c == "-" else 0 for c in line[:68]) % 10


def parse_tle(text: str, source: str = "<tle>") -> Tle:
    """Parse and check a 2- or 3-line TLE; errors name the file, the line (row) and the field."""
    raw = text.splitlines()
    numbered = [(i + 1, line.rstrip()) for i, line in enumerate(raw) if line.strip()]
    if len(numbered) not in (2, 3):
        raise InputError("not a TLE", file=source, found=f"{len(numbered)} non-empty lines",
                         expected="2 element lines, optionally after a name line")
    name = None
    if len(numbered) == 3:
        name = numbered[0][1].strip()
        if name.startswith("0 "):
            name = name[2:].strip()
        numbered = numbered[1:]
    lines = []
    for (row, line), number in zip(numbered, ("1", "2")):
        if not line.startswith(number + " "):
            raise InputError("not a TLE element line", file=source, row=row, column="line number",
                             found=line[:20], expected=f"a line starting with '{number} '")
        if len(line) != 69:
            raise InputError("wrong TLE line length", file=source, row=row, found=f"{len(line)} characters",
                             expected="69 characters (columns 1-69, checksum last)")
        if not line[68].isdigit():
            raise InputError("missing TLE checksum", file=source, row=row, column="checksum (column 69)",
                             found=line[68], expected="a digit")
        expected = checksum(line)
        if int(line[68]) != expected:
            raise InputError("TLE checksum mismatch (a corrupted or hand-edited line?)", file=source, row=row,
                             column="checksum (column 69)", found=int(line[68]), expected=str(expected))
        lines.append(line)
    if lines[0][2:7] != lines[1][2:7]:
        raise InputError("the two TLE lines are for different satellites", file=source, row=numbered[1][0],
                         column="satellite number (columns 3-7)", found=lines[1][2:7].strip(),
                         expected=lines[0][2:7].strip())
    check_elements(lines[0], lines[1], source, numbered[0][0], numbered[1][0])
    return Tle(name=name, line1=lines[0], line2=lines[1], source=source)


#: Plausible Kozai mean motion, rev/day: above 0.005 (a semi-major axis inside the Earth's Hill
#: sphere, ~1.5e6 km) and below 17.04 (a semi-major axis above the Earth's equatorial radius).
MEAN_MOTION_RANGE_REV_DAY = (0.005, 17.04)
#: Plausible |B*| (1/earth radii): catalogue values are 1e-5 to 1e-2; 1 would decay in a revolution.
BSTAR_MAX = 1.0

# Columns (1-based, inclusive) of the fields SGP4 uses (CelesTrak "NORAD Two-Line Element Set Format").
_LINE1_FIELDS = {"epoch year": (19, 20), "epoch day": (21, 32), "B*": (54, 61)}
_LINE2_FIELDS = {"inclination": (9, 16), "right ascension of the node": (18, 25), "eccentricity": (27, 33),
                 "argument of perigee": (35, 42), "mean anomaly": (44, 51), "mean motion": (53, 63)}


def _field(line: str, name: str, columns: tuple, source: str, row: int) -> tuple[str, str]:
    text = line[columns[0] - 1:columns[1]]
    return text, f"{name} (columns {columns[0]}-{columns[1]})"


def _number(line, name, columns, source, row, expected) -> float:
    text, column = _field(line, name, columns, source, row)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise InputError("invalid TLE field", file=source, row=row, column=column, found=text.strip(),
                         expected=expected)
    return value


def exp_field_value(text: str) -> float:
    """The value of a ``±MMMMM±E`` field (an assumed leading decimal point), e.g. ``-11606-4``
    = -0.11606e-4; ValueError when it is not one."""
    t = text.strip()
    if not t:
        raise ValueError("empty")
    sign = -1.0 if t[0] == "-" else 1.0
    t = t.lstrip("+-")
    m = __import__("re").fullmatch(r"(\d{1,5})([+-])(\d)", t)
    if m is None:
        if t.strip("0") == "":
            return 0.0
        raise ValueError(text)
    return sign * float("0." + m.group(1).rjust(5, "0")) * 10.0 ** (int(m.group(3)) * (-1 if m.group(2) == "-" else 1))


def check_elements(line1: str, line2: str, source: str, row1: int, row2: int) -> None:
    """Refuse element fields that are not numbers or not physically possible, naming the file,
    the row and the field: the epoch (day 1 to 365, or 366 in a leap year), the angles
    (inclination 0-180 deg, the others 0-360 deg), the eccentricity digits, the mean motion
    (:data:`MEAN_MOTION_RANGE_REV_DAY`) and B* (finite, below :data:`BSTAR_MAX`)."""
    year_text, year_col = _field(line1, "epoch year", _LINE1_FIELDS["epoch year"], source, row1)
    if not year_text.isdigit():
        raise InputError("invalid TLE field", file=source, row=row1, column=year_col, found=year_text,
                         expected="two digits (57-99: 19YY, 00-56: 20YY)")
    yy = int(year_text)
    year = 1900 + yy if yy >= 57 else 2000 + yy
    leap = year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)
    day = _number(line1, "epoch day", _LINE1_FIELDS["epoch day"], source, row1, "a day of the year DDD.DDDDDDDD")
    last = 367.0 if leap else 366.0
    if not 1.0 <= day < last:
        raise InputError(f"TLE epoch day outside the year {year}", file=source, row=row1,
                         column="epoch day (columns 21-32)", found=day,
                         expected=f"1 <= day < {last:.0f} ({'a leap year' if leap else 'not a leap year'})")
    text, column = _field(line1, "B*", _LINE1_FIELDS["B*"], source, row1)
    try:
        bstar = exp_field_value(text)
    except ValueError:
        raise InputError("invalid TLE field", file=source, row=row1, column=column, found=text,
                         expected="an exponent field like ' 12345-4' (0.12345e-4)") from None
    if not abs(bstar) < BSTAR_MAX:
        raise InputError("implausible B* drag term", file=source, row=row1, column=column, found=text,
                         expected=f"|B*| < {BSTAR_MAX:g} per earth radius (catalogue values are 1e-5 to 1e-2)")
    ranges = {"inclination": (0.0, 180.0, True), "right ascension of the node": (0.0, 360.0, False),
              "argument of perigee": (0.0, 360.0, False), "mean anomaly": (0.0, 360.0, False)}
    for name, (lo, hi, closed) in ranges.items():
        value = _number(line2, name, _LINE2_FIELDS[name], source, row2, f"an angle in degrees, {lo:g} to {hi:g}")
        if not (lo <= value <= hi if closed else lo <= value < hi + 1e-9):
            raise InputError(f"TLE {name} out of range", file=source, row=row2,
                             column=_field(line2, name, _LINE2_FIELDS[name], source, row2)[1], found=value,
                             expected=f"{lo:g} to {hi:g} degrees")
    text, column = _field(line2, "eccentricity", _LINE2_FIELDS["eccentricity"], source, row2)
    if not text.replace(" ", "0").isdigit():
        raise InputError("invalid TLE field", file=source, row=row2, column=column, found=text,
                         expected="7 digits after an assumed decimal point (0 <= e < 1)")
    lo, hi = MEAN_MOTION_RANGE_REV_DAY
    n = _number(line2, "mean motion", _LINE2_FIELDS["mean motion"], source, row2, "revolutions per day")
    if not lo < n < hi:
        raise InputError("implausible TLE mean motion", file=source, row=row2, column="mean motion (columns 53-63)",
                         found=n, expected=f"{lo:g} < n < {hi:g} revolutions per day (an orbit above the Earth's "
                                           "surface and inside its Hill sphere)")


def read_tle(path: str) -> Tle:
    """Read a TLE file (or ``-`` for stdin)."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_tle(read_input_bytes(path).decode("utf-8", errors="replace"), source)


def satrec(tle: Tle):
    """The ``sgp4.api.Satrec`` of a TLE (WGS-72)."""
    sat = Satrec.twoline2rv(tle.line1, tle.line2)
    if sat.error:
        raise InputError(f"SGP4 rejects the elements: {sgp4_error_text(sat.error)}", file=tle.source,
                         column=_SGP4_ERROR_FIELD.get(int(sat.error), "elements"), expected="valid mean elements")
    return sat


#: SGP4's error codes (Vallado et al. 2006, AIAA 2006-6753, sgp4 ``SGP4_ERRORS``) in words, and
#: the TLE field each points at.
_SGP4_ERROR_TEXT = {
    1: "mean eccentricity outside 0 to 1",
    2: "mean motion below zero",
    3: "perturbed eccentricity outside 0 to 1 (the drag or the eccentricity is too large)",
    4: "semi-latus rectum below zero",
    5: "the orbit is below the Earth's surface",
    6: "the satellite has decayed (its orbit radius fell below the Earth's radius)",
}
_SGP4_ERROR_FIELD = {1: "eccentricity (columns 27-33)", 2: "mean motion (columns 53-63)",
                     3: "eccentricity (columns 27-33) / B* (columns 54-61)", 4: "eccentricity (columns 27-33)",
                     5: "mean motion (columns 53-63)", 6: "mean motion (columns 53-63) / B* (columns 54-61)"}


def sgp4_error_text(code: int) -> str:
    """SGP4's error ``code`` in words (with the code)."""
    return f"{_SGP4_ERROR_TEXT.get(int(code), 'unknown SGP4 error')} (SGP4 error {int(code)})"


def tle_epoch(tle: Tle) -> np.datetime64:
    """The TLE epoch as UTC ``datetime64[ns]`` (rounded to the nearest microsecond)."""
    sat = satrec(tle)
    t = jd_utc_to_datetime64(sat.jdsatepoch, sat.jdsatepochF)
    return np.datetime64(t, "ns").astype("datetime64[us]").astype("datetime64[ns]")


def sgp4_teme(tle, jd1, jd2):
    """SGP4 position (m) and velocity (m/s) in TEME at UTC two-part Julian dates, shape (N, 3).
    ``tle`` is a :class:`Tle` or an ``sgp4.api.Satrec`` (elements being fitted)."""
    sat = tle if hasattr(tle, "sgp4_array") else satrec(tle)
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    err, r, v = sat.sgp4_array(jd1, jd2)
    if np.any(err):
        first = int(np.flatnonzero(err)[0])
        code = int(np.asarray(err)[first])
        when = str(np.datetime64(jd_utc_to_datetime64(jd1[first], jd2[first]), "s")) + "Z"
        raise ProcessingError(f"SGP4 failed for {getattr(tle, 'source', 'the elements')} at {when}: "
                              f"{sgp4_error_text(code)}")
    return np.asarray(r) * 1e3, np.asarray(v) * 1e3


def is_tle_state(state) -> bool:
    """Whether a :class:`~trackproc.io.statefile.State` is a TLE's SGP4 state (:func:`tle_state`)."""
    return getattr(state, "force_model", None) == "sgp4" and bool((getattr(state, "extra", None) or {}).get("tle"))


def tle_state(tle: Tle, at=None, eop=None):
    """GCRF :class:`~trackproc.io.statefile.State` of the TLE at UTC ``at`` (default: its epoch).

    ``at`` is a ``datetime64`` or ISO 8601 text. The state records the TLE lines in ``extra``.
    """
    if at is None:
        t = tle_epoch(tle)
    else:
        t = parse_epoch(at) if isinstance(at, str) else np.datetime64(at, "ns")
    jd1, jd2 = datetime64_to_jd_utc(t)
    r_teme, v_teme = sgp4_teme(tle, jd1, jd2)
    r, v = frames.teme_to_gcrf(r_teme, v_teme, jd1, jd2, eop)
    extra = {"source": f"TLE {tle.source} via SGP4 (TEME -> GCRF)", "tle": [tle.line1, tle.line2]}
    if tle.name:
        extra["tle_name"] = tle.name
    return State.from_vectors(t, r[0], v[0], force_model="sgp4",
                              eop_source=getattr(eop, "source", None), extra=extra, source=tle.source)


# --------------------------------------------------------------------------- writing

#: Resolution of the epoch field (YYDDD.DDDDDDDD): 1e-8 day.
EPOCH_RESOLUTION_DAY = 1e-8


@dataclass(frozen=True)
class MeanElements:
    """SGP4 mean elements as a TLE states them: UTC ``epoch`` (``datetime64``), angles in
    degrees, Kozai mean motion in revolutions per day, ``bstar`` in 1/earth radii."""

    epoch: np.datetime64
    inclination_deg: float
    raan_deg: float
    eccentricity: float
    arg_perigee_deg: float
    mean_anomaly_deg: float
    mean_motion_rev_day: float
    bstar: float


def round_epoch(t) -> np.datetime64:
    """``t`` (UTC) rounded to what the epoch field can hold (1e-8 day = 0.864 ms), so the
    elements fitted at it are the ones written."""
    t = np.datetime64(t, "ns")
    year = t.astype("datetime64[Y]")
    frac = (t - year.astype("datetime64[ns]")) / np.timedelta64(86400, "s")
    ns = int(round(round(float(frac) / EPOCH_RESOLUTION_DAY) * EPOCH_RESOLUTION_DAY * 86400e9))
    return year.astype("datetime64[ns]") + np.timedelta64(ns, "ns")


def _epoch_field(t) -> str:
    t = np.datetime64(t, "ns")
    year = t.astype("datetime64[Y]")
    days = (t - year.astype("datetime64[ns]")) / np.timedelta64(86400, "s") + 1.0
    text = f"{days:012.8f}"
    if text.startswith("367") or float(text) >= 367.0:
        raise ValueError(f"epoch {t} rounds into the next year")
    return f"{int(str(year)) % 100:02d}{text}"


def _exp_field(value: float) -> str:
    """The ``±MMMMM±E`` field (an assumed leading decimal point): B* and the second derivative."""
    if value == 0.0:
        return " 00000+0"
    exponent = int(np.floor(np.log10(abs(value)))) + 1
    mantissa = int(round(abs(value) / 10.0 ** exponent * 1e5))
    if mantissa >= 100000:
        mantissa //= 10
        exponent += 1
    if exponent < -9:
        return " 00000+0"
    if exponent > 9:
        raise ValueError(f"{value:g} does not fit a TLE exponent field")
    return f"{'-' if value < 0 else ' '}{mantissa:05d}{'-' if exponent < 0 else '+'}{abs(exponent)}"


def _angle(deg: float) -> str:
    text = f"{float(deg) % 360.0:8.4f}"
    return "  0.0000" if text == "360.0000" else text


def format_tle(elements: MeanElements, template: Tle | None = None, *, satnum: str | None = None,
               revolution: int | None = None, element_number: int | None = None, name: str | None = None) -> Tle:
    """A checked :class:`Tle` of ``elements`` (CelesTrak "NORAD Two-Line Element Set Format";
    checksums by :func:`checksum`). From ``template`` (the initial TLE) are kept: the catalogue
    number, classification, international designator, the mean-motion derivative fields (not
    used by SGP4), the ephemeris type, the element set number and the name, unless given."""
    t1 = template.line1 if template is not None else None
    sat = (satnum or (template.satnum if template is not None else "99999")).strip()
    if len(sat) > 5:
        raise ValueError(f"catalogue number {sat!r} has more than 5 characters")
    sat = sat.rjust(5, "0") if sat.isdigit() else sat.rjust(5)
    classification = t1[7] if t1 else "U"
    designator = t1[9:17] if t1 else " " * 8
    ndot = t1[33:43] if t1 else " .00000000"
    nddot = t1[44:52] if t1 else " 00000-0"
    ephtype = t1[62] if t1 else "0"
    elnum = element_number if element_number is not None else (int(t1[64:68]) if t1 and t1[64:68].strip() else 999)
    e = float(elements.eccentricity)
    if not 0.0 <= e < 1.0:
        raise ValueError(f"eccentricity {e} outside [0, 1)")
    inc = float(elements.inclination_deg)
    if not 0.0 <= inc <= 180.0:
        raise ValueError(f"inclination {inc} deg outside [0, 180]")
    rev = revolution if revolution is not None else (int(template.line2[63:68]) if template is not None
                                                     and template.line2[63:68].strip() else 0)
    line1 = (f"1 {sat}{classification} {designator} {_epoch_field(elements.epoch)} {ndot} {nddot} "
             f"{_exp_field(float(elements.bstar))} {ephtype} {elnum % 10000:4d}")
    line2 = (f"2 {sat} {inc:8.4f} {_angle(elements.raan_deg)} {int(round(e * 1e7)):07d} "
             f"{_angle(elements.arg_perigee_deg)} {_angle(elements.mean_anomaly_deg)} "
             f"{float(elements.mean_motion_rev_day):11.8f}{rev % 100000:5d}")
    line1 += str(checksum(line1))
    line2 += str(checksum(line2))
    if name is None and template is not None:
        name = template.name
    try:
        return parse_tle("\n".join(([name] if name else []) + [line1, line2]), "<fitted TLE>")
    except InputError as exc:
        raise ValueError(str(exc)) from None


def tle_text(tle: Tle) -> str:
    """The TLE as a file holds it: the name line (when known), then the two element lines."""
    return "\n".join(([tle.name] if tle.name else []) + [tle.line1, tle.line2]) + "\n"
