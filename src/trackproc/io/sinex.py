"""SINEX station coordinates: positions and velocities at an epoch, plus eccentricities.

Reads the blocks of a SINEX (v2.xx) file that station coordinates need:

- ``SOLUTION/ESTIMATE``: ``STAX STAY STAZ`` (m) and ``VELX VELY VELZ`` (m/y) per site code,
  point code and solution number, at a reference epoch ``YY:DOY:SSSSS``;
- ``SOLUTION/EPOCHS``: the data span of each solution (a site with several solutions — after
  an earthquake or an equipment change — takes the one whose span holds the epoch of the data;
  an open end ``00:000:00000`` or a span ending after the epoch counts);
- ``SITE/ECCENTRICITY`` (from the same or another file, e.g. the ILRS ``ecc_une.snx``): the
  vector from the marker to the instrument reference point, ``UNE`` (up, north, east, m) or
  ``XYZ``, with its validity span.

The position at the data epoch ``t`` is ``X(t) = X0 + V (t - t0)`` (years of 365.25 days), the
eccentricity is added in the local east/north/up frame of the marker (WGS-84 normal), and the
result becomes a :class:`~trackproc.io.stations.Station` (WGS-84 geodetic, the stations
table's form; the round trip is exact to < 0.1 mm). Stations are named by their SINEX site
code (the CDP pad id of laser stations, e.g. ``7090``, as CRD files name them).
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.dynamics.geodesy import enu_matrix, itrf_to_geodetic

_YEAR_S = 365.25 * 86400.0
#: Largest plausible station velocity, m/yr: plates move at most ~0.2 m/yr (ITRF2020); a larger
#: value is a unit mistake (mm/yr given as m/yr) or a damaged file.
MAX_STATION_SPEED_M_YR = 1.0
#: A station position must lie near the Earth's surface: |X| within 6.3e6 to 6.4e6 m.
_STATION_RADIUS_M = (6.3e6, 6.4e6)


def looks_like_sinex(data: bytes) -> bool:
    """True when the data start with the SINEX header line ``%=SNX``."""
    return data.lstrip()[:5] == b"%=SNX"


def parse_sinex_epoch(text: str, source: str = "", row: int | None = None, column: str = "epoch"):
    """``YY:DOY:SSSSS`` -> numpy datetime64[ns] (YY ≤ 50: 20YY; ``00:000:00000``: None, open)."""
    try:
        yy, doy, sod = (int(part) for part in text.split(":"))
    except ValueError:
        raise InputError("invalid SINEX epoch", file=source, row=row, column=column, found=text,
                         expected="YY:DOY:SSSSS") from None
    if yy == 0 and doy == 0 and sod == 0:
        return None
    year = 2000 + yy if yy <= 50 else 1900 + yy
    return (np.datetime64(f"{year:04d}-01-01", "ns") + np.timedelta64(doy - 1, "D")
            + np.timedelta64(sod, "s"))


def _blocks(text: str, source: str):
    """Block name -> list of (line number, fields) of its data lines (comments skipped). The block
    structure is checked: every ``+NAME`` closed by its ``-NAME`` before the next block opens or the
    file ends (a cut transfer, an edited file), else an :class:`InputError` naming the row."""
    blocks, name, opened = {}, None, 0
    for row, line in enumerate(text.splitlines(), start=1):
        if line.startswith("+"):
            if name is not None:
                raise InputError(f"SINEX block {name} not closed before the next one opens", file=source, row=row,
                                 found=line.strip()[:40], expected=f"-{name} (the block opened at row {opened})")
            name, opened = (line[1:].split()[0] if line[1:].split() else ""), row
            blocks.setdefault(name, [])
        elif line.startswith("-"):
            closing = line[1:].split()[0] if line[1:].split() else ""
            if name is not None and closing != name:
                raise InputError(f"SINEX block {name} closed as {closing}", file=source, row=row,
                                 found=line.strip()[:40], expected=f"-{name} (the block opened at row {opened})")
            name = None
        elif name is not None and line.strip() and not line.startswith("*"):
            blocks[name].append((row, line))
    if name is not None:
        raise InputError(f"SINEX block {name} not closed: the file ends inside it (cut short?)", file=source,
                         row=opened, expected=f"-{name} before the end of the file")
    return blocks


def _decode(data: bytes, source: str) -> str:
    try:
        return data.decode("ascii", errors="strict")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _in_span(epoch, start, end) -> bool:
    return (start is None or start <= epoch) and (end is None or epoch <= end)


def sinex_stations(data: bytes, source: str, epoch, eccentricities: tuple[bytes, str] | None = None) -> dict:
    """Stations (site code -> :class:`~trackproc.io.stations.Station`) at ``epoch``
    (datetime64, UTC) from the bytes of a SINEX file, with the eccentricities of the same file
    or of ``eccentricities = (bytes, source)`` applied (see the module docstring)."""
    from trackproc.io.stations import Station   # here: io/stations reads SINEX through this module (a cycle)

    epoch = np.datetime64(epoch, "ns")
    blocks = _blocks(_decode(data, source), source)
    if "SOLUTION/ESTIMATE" not in blocks:
        raise InputError("no SOLUTION/ESTIMATE block", file=source, row=1, found="a SINEX file without it",
                         expected="station positions (STAX, STAY, STAZ) in +SOLUTION/ESTIMATE")
    spans = {}
    for row, line in blocks.get("SOLUTION/EPOCHS", []):
        f = line.split()
        if len(f) >= 6:
            spans[(f[0], f[1], f[2])] = (parse_sinex_epoch(f[4], source, row, "data start"),
                                         parse_sinex_epoch(f[5], source, row, "data end"))
    values: dict = {}
    for row, line in blocks["SOLUTION/ESTIMATE"]:
        f = line.split()
        if len(f) < 9:
            raise InputError("short SOLUTION/ESTIMATE line", file=source, row=row, found=" ".join(f),
                             expected="index type code pt soln epoch unit constraint estimate [sigma]")
        ptype = f[1].upper()
        if ptype not in ("STAX", "STAY", "STAZ", "VELX", "VELY", "VELZ"):
            continue
        try:
            value = float(f[8].replace("D", "E"))
        except ValueError:
            raise InputError("invalid SINEX estimate", file=source, row=row, column=ptype, found=f[8],
                             expected="a number") from None
        if not math.isfinite(value):
            raise InputError("invalid SINEX estimate", file=source, row=row, column=ptype, found=f[8],
                             expected="a finite number")
        entry = values.setdefault((f[2], f[3], f[4]), {"row": row})
        entry[ptype] = value
        if ptype.startswith("VEL"):
            entry.setdefault("vrow", row)
        if ptype.startswith("STA"):
            entry["t0"] = parse_sinex_epoch(f[5], source, row, "reference epoch")
    chosen: dict = {}
    for key, entry in values.items():
        code = key[0]
        if not all(k in entry for k in ("STAX", "STAY", "STAZ")):
            raise InputError("incomplete station position", file=source, row=entry["row"], column="STAX/STAY/STAZ",
                             found=f"site {code} solution {key[2]}", expected="STAX, STAY and STAZ")
        span = spans.get(key)
        if span is not None and not _in_span(epoch, *span):
            continue
        if code in chosen and chosen[code][0][1] != key[1]:
            continue                         # several monuments: keep the first point code (A)
        if code in chosen and span is None:
            raise InputError("several solutions and no SOLUTION/EPOCHS to choose", file=source, row=entry["row"],
                             column="SOLN", found=f"site {code}", expected="one solution per site or their epochs")
        chosen[code] = (key, entry)
    ecc = _eccentricities(*(eccentricities if eccentricities is not None else (data, source)), epoch)
    stations = {}
    for code, (key, entry) in sorted(chosen.items()):
        r = np.array([entry["STAX"], entry["STAY"], entry["STAZ"]])
        if not _STATION_RADIUS_M[0] <= float(np.linalg.norm(r)) <= _STATION_RADIUS_M[1]:
            raise InputError(f"implausible station position: |X| = {np.linalg.norm(r):.6g} m", file=source,
                             row=entry["row"], column="STAX/STAY/STAZ", found=f"site {code}",
                             expected=f"a geocentric position in metres, |X| between {_STATION_RADIUS_M[0]:g} and "
                                      f"{_STATION_RADIUS_M[1]:g} m")
        vel = [entry.get(k) for k in ("VELX", "VELY", "VELZ")]
        speed = math.sqrt(sum(v * v for v in vel if v is not None))
        if speed > MAX_STATION_SPEED_M_YR:
            raise InputError(f"implausible station velocity: |V| = {speed:.6g} m/yr", file=source,
                             row=entry.get("vrow", entry["row"]), column="VELX/VELY/VELZ", found=f"site {code}",
                             expected=f"|V| below {MAX_STATION_SPEED_M_YR:g} m/yr (plates move at most ~0.2 m/yr; "
                                      "mm/yr given as m/yr?)")
        if all(k in entry for k in ("VELX", "VELY", "VELZ")):
            dt_y = (epoch - entry["t0"]) / np.timedelta64(1, "s") / _YEAR_S
            r = r + dt_y * np.array([entry["VELX"], entry["VELY"], entry["VELZ"]])
        lat, lon, _ = itrf_to_geodetic(r)
        if code in ecc:
            axes, vec = ecc[code]
            if axes == "UNE":
                up, north, east = vec
                r = r + enu_matrix(lat, lon).T @ np.array([east, north, up])
            else:
                r = r + np.asarray(vec)
            lat, lon, _ = itrf_to_geodetic(r)
        lat, lon, h = itrf_to_geodetic(r)
        stations[code] = Station(code, float(np.degrees(lat)), float(np.degrees(lon)), float(h))
    if not stations:
        raise InputError("no station valid at the data epoch", file=source,
                         found=str(epoch.astype("datetime64[s]")) + "Z", expected="a solution whose span holds it")
    return stations


def _eccentricities(data: bytes, source: str, epoch) -> dict:
    """Site code -> (axes "UNE" | "XYZ", (3,) m) valid at ``epoch``."""
    out = {}
    for row, line in _blocks(_decode(data, source), source).get("SITE/ECCENTRICITY", []):
        # fixed columns (the values may touch: -0.6140-516.4230)
        f = [line[1:5].strip(), line[6:8].strip(), line[9:13].strip(), line[14:15], line[16:28].strip(),
             line[29:41].strip(), line[42:45].strip(), line[46:54], line[55:63], line[64:72]]
        if len(line.rstrip()) < 72 or not f[0]:
            raise InputError("short SITE/ECCENTRICITY line", file=source, row=row, found=line.strip(),
                             expected="code pt soln T start end axes up north east (SINEX fixed columns)")
        start = parse_sinex_epoch(f[4], source, row, "data start")
        end = parse_sinex_epoch(f[5], source, row, "data end")
        if not _in_span(epoch, start, end) or f[0] in out:
            continue
        axes = f[6].upper()
        if axes not in ("UNE", "XYZ"):
            raise InputError("unknown eccentricity axes", file=source, row=row, column="AXE", found=f[6],
                             expected="UNE or XYZ")
        try:
            vec = tuple(float(x) for x in f[7:10])
        except ValueError:
            raise InputError("invalid eccentricity", file=source, row=row, column=axes, found=" ".join(f[7:10]),
                             expected="three numbers in metres") from None
        out[f[0]] = (axes, vec)
    return out


def read_sinex_stations(path: str, epoch, eccentricities: str | None = None) -> dict:
    """:func:`sinex_stations` of a file (``-``: stdin), eccentricities from another file if given."""
    source = "<stdin>" if is_stdio(path) else str(path)
    data = read_input_bytes(path)
    ecc = None
    if eccentricities is not None:
        ecc_source = "<stdin>" if is_stdio(eccentricities) else str(eccentricities)
        ecc = (read_input_bytes(eccentricities), ecc_source)
    return sinex_stations(data, source, epoch, ecc)
