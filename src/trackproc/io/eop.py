"""IERS Earth orientation files (finals2000A / finals.all, fixed columns) and the --eop/--dut1 options."""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np

from trackproc.dynamics.timescales import EarthOrientation, eop_from_table
from trackproc.errors import InputError
from trackproc.io import table_cache

NO_EOP_WARNING = ("no --eop file or --dut1 given and no EOP package (astropy-iers-data) installed: "
                  "UT1-UTC and polar motion taken as zero "
                  "(ignoring UT1-UTC, up to 0.9 s, costs up to ~400 m at the equator)")


#: Parsed tables of this process, by (resolved path, mtime, size) or package version: a batch worker
#: reads its EOP file once, not once per pass (issue 19; parsing 20,000 rows takes ~0.1 s).
_PARSED: dict = {}
_PARSED_MAX = 8


def _remember(key, table):
    if len(_PARSED) >= _PARSED_MAX:
        _PARSED.clear()
    for name in ("mjd", "ut1_minus_tai_s", "xp_rad", "yp_rad"):
        getattr(table, name).setflags(write=False)      # shared between callers: read-only
    _PARSED[key] = table
    return table


def read_finals2000a(path: str | Path):
    """Parse an IERS finals2000A file: MJD (cols 8-15) and, per row, the final Bulletin B values
    (PM-x cols 135-144, PM-y 145-154 arcsec, UT1-UTC 155-165 s) where the row has them, else the
    Bulletin A values (PM-x 19-27, PM-y 38-46, UT1-UTC 59-68) — the same choice as Orekit's
    reader; rows without UT1-UTC (beyond the predictions) are skipped. The celestial pole
    offsets dX, dY are not used (sub-centimetre at the station). Returns :class:`~trackproc.dynamics.timescales.EarthOrientation`.

    Parsed once per process and file version (kept by resolved path, modification time and size;
    its arrays read-only), so that a batch worker does not re-read the file for every pass.
    """
    try:
        stat = Path(path).stat()
        key = ("finals2000A", str(Path(path).resolve()), stat.st_mtime_ns, stat.st_size)
    except OSError:
        key = None
    if key in _PARSED:
        return _PARSED[key]
    rows = table_cache.cached_arrays("finals2000a", path, lambda: _parse_rows(path), parser=__file__)
    mjd, dut1, xp, yp = (rows[name].tolist() for name in ("mjd", "dut1", "xp", "yp"))
    table = eop_from_table(mjd, dut1, xp, yp, source=f"IERS finals2000A {Path(path).name}")
    return table if key is None else _remember(key, table)


def _parse_rows(path) -> dict:
    """The rows of a finals2000A file as arrays (``mjd``, ``dut1``, ``xp``, ``yp``): the line-by-line
    parse that :func:`read_finals2000a` caches (io/table_cache.py)."""
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
    return {"mjd": mjd, "dut1": dut1, "xp": xp, "yp": yp}


def bundled_earth_orientation():
    """The IERS finals2000A table shipped by the maintained ``astropy-iers-data`` package (Bulletin A
    with its year of predictions, refreshed with each release), or None when it is not installed.

    Parsing its 20,000 rows takes ~0.1 s, so the parsed table is cached as ``.npz`` under
    the user cache directory (io/table_cache.py), keyed by the package version; a cache
    that cannot be written is simply not used."""
    try:
        import astropy_iers_data  # may be absent: then None
    except ImportError:
        return None
    version = astropy_iers_data.__version__
    source = f"IERS finals2000A from astropy-iers-data {version}"
    cache_dir = Path(table_cache.cache_dir() or os.devnull)      # os.devnull: caching off
    cache = cache_dir / f"eop-astropy-iers-data-{version}.npz"
    key = ("astropy-iers-data", str(cache))
    if key in _PARSED:
        return _PARSED[key]
    try:
        with np.load(cache) as z:
            return _remember(key,
                             EarthOrientation(mjd=z["mjd"], ut1_minus_tai_s=z["ut1_minus_tai_s"],
                                              xp_rad=z["xp_rad"], yp_rad=z["yp_rad"], source=source))
    except (OSError, KeyError, ValueError):
        pass
    table = read_finals2000a(astropy_iers_data.IERS_A_FILE)
    table = EarthOrientation(mjd=table.mjd, ut1_minus_tai_s=table.ut1_minus_tai_s, xp_rad=table.xp_rad,
                             yp_rad=table.yp_rad, source=source)
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=cache_dir, suffix=".npz", delete=False) as tmp:
            np.savez(tmp, mjd=table.mjd, ut1_minus_tai_s=table.ut1_minus_tai_s, xp_rad=table.xp_rad,
                     yp_rad=table.yp_rad)
        os.replace(tmp.name, cache)
    except OSError:
        pass
    return _remember(key, table)


def earth_orientation(eop_path=None, dut1_s=None):
    """The Earth orientation for the --eop / --dut1 options; with neither, the IERS table of the
    ``astropy-iers-data`` package (no warning: dates outside it are warned about where they are
    used), else zero UT1-UTC with a warning text."""
    if eop_path is not None and dut1_s is not None:
        raise InputError("give either --eop or --dut1, not both")
    if eop_path is not None:
        return read_finals2000a(eop_path), None
    if dut1_s is not None:
        if not math.isfinite(dut1_s) or abs(dut1_s) > 0.9:
            raise InputError("UT1-UTC out of range", column="--dut1", found=dut1_s,
                             expected="|UT1-UTC| <= 0.9 s")
        return EarthOrientation.constant(dut1_s), None
    bundled = bundled_earth_orientation()
    if bundled is not None:
        return bundled, None
    return EarthOrientation(), NO_EOP_WARNING
