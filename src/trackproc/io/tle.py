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

from dataclasses import dataclass

import numpy as np

from trackproc.errors import InputError, ProcessingError
from trackproc.io.atomic import is_stdio, read_input_bytes


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
    return Tle(name=name, line1=lines[0], line2=lines[1], source=source)


def read_tle(path: str) -> Tle:
    """Read a TLE file (or ``-`` for stdin)."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_tle(read_input_bytes(path).decode("utf-8", errors="replace"), source)


def satrec(tle: Tle):
    """The ``sgp4.api.Satrec`` of a TLE (WGS-72)."""
    from sgp4.api import Satrec

    sat = Satrec.twoline2rv(tle.line1, tle.line2)
    if sat.error:
        raise InputError(f"SGP4 rejects the elements (error {sat.error})", file=tle.source,
                         expected="valid mean elements")
    return sat


def tle_epoch(tle: Tle) -> np.datetime64:
    """The TLE epoch as UTC ``datetime64[ns]`` (rounded to the nearest microsecond)."""
    from trackproc.dynamics.timescales import jd_utc_to_datetime64

    sat = satrec(tle)
    t = jd_utc_to_datetime64(sat.jdsatepoch, sat.jdsatepochF)
    return np.datetime64(t, "ns").astype("datetime64[us]").astype("datetime64[ns]")


def sgp4_teme(tle: Tle, jd1, jd2):
    """SGP4 position (m) and velocity (m/s) in TEME at UTC two-part Julian dates, shape (N, 3)."""
    sat = satrec(tle)
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    err, r, v = sat.sgp4_array(jd1, jd2)
    if np.any(err):
        code = int(np.asarray(err)[np.flatnonzero(err)[0]])
        raise ProcessingError(f"SGP4 failed for {tle.source} (error {code}: decayed or invalid elements "
                              "at the requested time)")
    return np.asarray(r) * 1e3, np.asarray(v) * 1e3


def tle_state(tle: Tle, at=None, eop=None):
    """GCRF :class:`~trackproc.io.statefile.State` of the TLE at UTC ``at`` (default: its epoch).

    ``at`` is a ``datetime64`` or ISO 8601 text. The state records the TLE lines in ``extra``.
    """
    from trackproc.dynamics import frames
    from trackproc.dynamics.timescales import datetime64_to_jd_utc
    from trackproc.io.statefile import State, parse_epoch

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
