"""Stations table: ``station, lat_deg, lon_deg, height_m [, range_bias_m] [, time_sigma_s]`` (WGS-84 geodetic).

Latitude in degrees in [-90, 90], longitude in degrees in [-180, 360), height in metres above the
WGS-84 ellipsoid, optional range bias prior in metres, optional 1-sigma uncertainty of the
station's time tags in seconds (finite, >= 0; an empty cell = not given). Lines starting with ``#`` and blank lines
are skipped; other columns are ignored. Row numbers in errors are the file's line numbers (the
header is row 1 when it is the first line).
"""

from __future__ import annotations

import math

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.io.csvtext import CSV_META_PREFIX
from trackproc.io.csvtext import parse_text_table  # not io.tabular: it loads every raw reader (and pandas)
from trackproc.io.validate import check_name, check_station
from trackproc.types.station import Station  # noqa: F401  (re-exported)
from trackproc.io.columns import sniff_container

REQUIRED = ("station", "lat_deg", "lon_deg", "height_m")
#: ``metadata:PASS`` (the spelling of ``--initial``) names the pass file's stations, as PASS does.
PASS_PREFIX = "metadata:"


_LIMITS = {
    "lat_deg": (lambda v: -90.0 <= v <= 90.0, "degrees in [-90, 90]"),
    "lon_deg": (lambda v: -180.0 <= v < 360.0, "degrees in [-180, 360)"),
    "height_m": (math.isfinite, "a finite height in metres"),
    "range_bias_m": (math.isfinite, "a finite bias in metres, or an empty cell"),
    "time_sigma_s": (lambda v: math.isfinite(v) and v >= 0.0, "a finite time-tag sigma in seconds >= 0, or an empty cell"),
}

#: Optional columns: an empty cell means "not given".
OPTIONAL = ("range_bias_m", "time_sigma_s")


def parse_stations(data: bytes, source: str) -> dict[str, Station]:
    """Stations by name from the bytes of a stations CSV (``source`` names it in errors)."""
    table = parse_text_table(data, source)
    by_key = {name.lower(): name for name in table.columns}
    for column in REQUIRED:
        if column not in by_key:
            raise InputError("missing required column", file=source, row=table.header_row, column=column,
                             found=", ".join(table.columns), expected="columns " + ", ".join(REQUIRED))
    if len(table.rows) == 0:
        raise InputError("empty stations table", file=source, row=table.header_row + 1,
                         found="no data rows", expected="one row per station")
    stations: dict[str, Station] = {}
    first_row: dict[str, int] = {}
    for i, row in enumerate(table.rows.tolist()):
        cell = {key: table.cells[name][i] for key, name in by_key.items()}
        name = cell["station"]
        if not name:
            raise InputError("empty station name", file=source, row=row, column=by_key["station"],
                             expected="a station name")
        if name in stations:
            raise InputError(f"duplicate station (first on row {first_row[name]})", file=source, row=row,
                             column=by_key["station"], found=name, expected="each station once")
        numbers = {}
        for key in ("lat_deg", "lon_deg", "height_m") + OPTIONAL:
            if key not in by_key or (key in OPTIONAL and not cell[key]):
                continue
            ok, expected = _LIMITS[key]
            try:
                value = float(cell[key])
            except ValueError:
                value = math.nan
            if not (math.isfinite(value) and ok(value)):
                raise InputError("invalid station time-tag sigma" if key == "time_sigma_s"
                                 else "invalid station coordinate", file=source, row=row, column=by_key[key],
                                 found=cell[key], expected=expected)
            numbers[key] = value
        check_name(name, "station name", file=source, row=row, column=by_key["station"])
        check_station(name, numbers["lat_deg"], numbers["lon_deg"], numbers["height_m"], file=source, row=row)
        stations[name] = Station(name, numbers["lat_deg"], numbers["lon_deg"], numbers["height_m"],
                                 numbers.get("range_bias_m"), numbers.get("time_sigma_s"))
        first_row[name] = row
    return stations


def read_stations(path: str, epoch=None, eccentricities: str | None = None) -> dict[str, Station]:
    """Stations by name from a stations CSV file (or ``-`` for stdin), from a SINEX file
    (positions and velocities at ``epoch``, datetime64 UTC, with ``eccentricities``: see
    :mod:`trackproc.io.sinex`), or from a pass file's metadata (Parquet, Arrow or trackproc CSV;
    ``metadata:PASS`` the same)."""
    if str(path).startswith(PASS_PREFIX):
        path = str(path)[len(PASS_PREFIX):]
        if not path:
            raise InputError("no pass file after 'metadata:'", found=PASS_PREFIX,
                             expected="metadata:PASS.parquet (the pass file whose metadata holds the stations)")
    source = "<stdin>" if is_stdio(path) else str(path)
    data = read_input_bytes(path)
    if sniff_container(data) != "text":
        return pass_file_stations(data, source)
    if not data.strip():
        raise InputError("empty stations table", file=source, row=1, found="no data",
                         expected="a header station, lat_deg, lon_deg, height_m and one row per station")
    from trackproc.io import sinex   # here, not at the top: sinex builds this module's Station (a cycle)

    if sinex.looks_like_sinex(data):
        if epoch is None:
            raise InputError("SINEX stations need the epoch of the data", file=source,
                             expected="a stations CSV here, or tracking data to date the SINEX positions")
        ecc = None
        if eccentricities is not None:
            ecc = (read_input_bytes(eccentricities), "<stdin>" if is_stdio(eccentricities) else str(eccentricities))
        return sinex.sinex_stations(data, source, epoch, ecc)
    if eccentricities is not None:
        raise InputError("eccentricities apply to SINEX station files", file=source, column="--eccentricities",
                         expected="--stations FILE.snx")
    try:
        return parse_stations(data, source)
    except InputError as exc:
        if not data.lstrip().startswith(b"# " + CSV_META_PREFIX.encode()):
            raise
        error = exc
    try:                                    # a trackproc CSV: a pass file's stations?
        return pass_file_stations(data, source)
    except InputError:
        raise error from None


def pass_file_stations(data: bytes, source: str) -> dict[str, Station]:
    """The stations a pass file records in its metadata (as ``ingest`` wrote them), so that a
    pass file can stand for its stations table."""
    from trackproc.io.passfile import parse_pass_table  # import cycle: io.passfile imports this module

    stations = parse_pass_table(data, source).stations()
    if not stations:
        raise InputError("no stations in the pass file's metadata", file=source, column="stations",
                         found="a pass file without station coordinates",
                         expected="a stations CSV, a SINEX file, or a pass file ingested with --stations (or from DopTrack)")
    return stations
