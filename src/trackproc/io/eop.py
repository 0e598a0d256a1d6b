"""IERS Earth orientation files (finals2000A / finals.all, fixed columns) and the --eop/--dut1 options."""

from __future__ import annotations

import math

from pathlib import Path

from trackproc.errors import InputError

NO_EOP_WARNING = ("no --eop file or --dut1 given: UT1-UTC and polar motion taken as zero "
                  "(ignoring UT1-UTC, up to 0.9 s, costs up to ~400 m at the equator)")


def read_finals2000a(path: str | Path):
    """Parse an IERS finals2000A file: MJD (cols 8-15) and, per row, the final Bulletin B values
    (PM-x cols 135-144, PM-y 145-154 arcsec, UT1-UTC 155-165 s) where the row has them, else the
    Bulletin A values (PM-x 19-27, PM-y 38-46, UT1-UTC 59-68) — the same choice as Orekit's
    reader; rows without UT1-UTC (beyond the predictions) are skipped. The celestial pole
    offsets dX, dY are not used (sub-centimetre at the station). Returns :class:`~trackproc.dynamics.timescales.EarthOrientation`.
    """
    from trackproc.dynamics.timescales import eop_from_table

    try:
        lines = Path(path).read_text(encoding="ascii", errors="replace").splitlines()
    except FileNotFoundError:
        raise InputError("EOP file not found", file=str(path)) from None
    mjd, dut1, xp, yp = [], [], [], []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        if len(line) < 68 or not line[58:68].strip():
            continue  # no UT1-UTC on this row (beyond the predictions)
        try:
            mjd.append(float(line[7:15]))
            bulletin_b = line[134:165]
            if len(line) >= 165 and line[134:144].strip() and line[144:154].strip() and line[154:165].strip():
                # final Bulletin B values, where the row has them (as Orekit uses them)
                xp.append(float(bulletin_b[0:10]))
                yp.append(float(bulletin_b[10:20]))
                dut1.append(float(bulletin_b[20:31]))
            else:
                xp.append(float(line[18:27]))
                yp.append(float(line[37:46]))
                dut1.append(float(line[58:68]))
        except ValueError:
            raise InputError("not an IERS finals2000A row", file=str(path), row=number,
                             found=line[:70], expected="fixed columns MJD 8-15, PM-x 19-27, "
                             "PM-y 38-46, UT1-UTC 59-68") from None
    if len(mjd) < 2:
        raise InputError("no usable rows", file=str(path), expected="an IERS finals2000A file with UT1-UTC")
    return eop_from_table(mjd, dut1, xp, yp, source=f"IERS finals2000A {Path(path).name}")


def earth_orientation(eop_path=None, dut1_s=None):
    """The Earth orientation for the --eop / --dut1 options, and a warning text when neither is given."""
    from trackproc.dynamics.timescales import EarthOrientation

    if eop_path is not None and dut1_s is not None:
        raise InputError("give either --eop or --dut1, not both")
    if eop_path is not None:
        return read_finals2000a(eop_path), None
    if dut1_s is not None:
        if not math.isfinite(dut1_s) or abs(dut1_s) > 0.9:
            raise InputError("UT1-UTC out of range", column="--dut1", found=dut1_s,
                             expected="|UT1-UTC| <= 0.9 s")
        return EarthOrientation.constant(dut1_s), None
    return EarthOrientation(), NO_EOP_WARNING
