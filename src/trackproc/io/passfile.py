"""The canonical pass table: one row per sample, SI units, with provenance in the metadata.

Columns (in this order; later commands may append their own, e.g. smoothed/residual/flag):

=======  =====================  =================================================
column   type                   meaning
=======  =====================  =================================================
time     timestamp[ns, UTC]     reception time, UTC (ISO 8601 with Z in CSV)
station  string                 station name (see ``meta["stations"]``)
pass_id  string                 pass identifier, e.g. ``ZHY-001``
kind     string                 range | range_rate | doppler | elevation | azimuth
value    float64                m | m/s | Hz | rad | rad (see :data:`KIND_UNITS`)
sigma    float64                1-sigma, same unit as value, > 0
=======  =====================  =================================================

Rows are sorted by station, then time, then kind. The metadata (a JSON object under the key
``trackproc`` of the Arrow/Parquet schema metadata; the ``# trackproc: {`` comment block opening a
CSV) holds ``schema_version``, ``units``, ``time_scale`` ("UTC"), ``carrier_hz``,
``doppler_mode`` (one-way | two-way), ``doppler_sign_convention``, ``sources``, ``stations``
(name -> {lat_deg, lon_deg, height_m[, range_bias_m]}) and ``trackproc_version``.

Sign convention: range-rate is positive when the range grows (receding); Doppler = received −
nominal carrier frequency, so range_rate ≈ −c·doppler/carrier one-way and
range_rate ≈ −c·doppler/(2·carrier) two-way.

Formats: Parquet (files), Arrow IPC stream (pipes: ``-``), CSV (for people; values in SI).
Written bytes depend only on the table and the metadata: the same input gives the same file.

One module for one format (a little over 400 lines): its schema, reader, checks and writer share the
column and metadata definitions above; split, each part would import the others'.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa

from trackproc.io.jsonshare import dumps_shared
from trackproc.io.tables import arrow_table_bytes, bool_array, float_array, string_array, utc_time_array
from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, open_atomic, read_input_bytes
from trackproc.isotime import iso_utc_array
from trackproc.io.raw import KIND_UNITS
from trackproc.types.passes import PassTable  # noqa: F401  (re-exported)
# the column readers themselves, not io.tabular: it loads every raw layout's reader (and pandas)
from trackproc.io.columns import META_KEY, arrow_numpy, column_numbers, column_strings, column_times, source_table
from trackproc.io.csvtext import csv_metadata_line
from trackproc.io.problems import Problems
from trackproc import __version__
from trackproc.io import smoothing_record
from trackproc.io.validate import (FIRST_YEAR, LAST_YEAR, MAX_LOS_SPEED_M_S, check_carrier, check_los_speed,
                                  check_name)
from trackproc.io.stations import Station

SCHEMA_VERSION = 1
COLUMNS = ("time", "station", "pass_id", "kind", "value", "sigma")
KINDS = tuple(KIND_UNITS)
FORMATS = ("parquet", "arrow", "csv")
SIGN_CONVENTION = (
    "doppler = received - nominal carrier frequency (Hz); range_rate > 0 when receding; "
    "one-way: range_rate = -c*doppler/carrier_hz, two-way: range_rate = -c*doppler/(2*carrier_hz) "
    "(first order)"
)


def base_meta(**extra) -> dict:
    """Metadata fields every pass file carries, updated with ``extra``."""
    meta = {
        "schema_version": SCHEMA_VERSION,
        "time_scale": "UTC",
        "units": dict(KIND_UNITS),
        "doppler_sign_convention": SIGN_CONVENTION,
        "trackproc_version": __version__,
    }
    meta.update(extra)
    return meta


def meta_json(meta: dict) -> str:
    """Deterministic JSON of the metadata (sorted keys, no NaN): ``json.dumps(meta, sort_keys=True,
    separators=(",", ":"), allow_nan=False, default=...)``, the same text, the smoothing records'
    float lists' text shared with the last encodings of the same lists (``.smooth.json``, the size
    check; :mod:`trackproc.io.jsonshare`)."""
    return dumps_shared(meta, _META_ENCODER)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


#: ``json.dumps``'s encoder for :func:`meta_json`'s arguments.
_META_ENCODER = json.JSONEncoder(sort_keys=True, separators=(",", ":"), allow_nan=False, default=_json_default)


# --------------------------------------------------------------------------- writing


def to_arrow(table: PassTable, meta_text: str | None = None) -> pa.Table:
    """The table as Arrow, canonical types, metadata under ``trackproc`` (no pandas metadata).
    A table that holds every column as numpy is converted from them, without its DataFrame (the
    same arrays: the frame path converts the frame to these numpy types first). ``meta_text``:
    :func:`meta_json` of ``table.meta`` when the caller has it (a pass file's smoothing records
    make it ~1 ms of float text)."""
    if meta_text is None:
        meta_text = meta_json(table.meta)
    columns = table.numpy_columns()
    arrow = _arrow_of_columns(columns, meta_text) if columns is not None and all(c in columns for c in COLUMNS) \
        else None
    if arrow is not None:
        return arrow
    frame = table.frame
    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"pass table lacks columns {missing}")
    times = frame["time"]
    if getattr(times.dt, "tz", None) is None:
        times = times.dt.tz_localize("UTC")
    arrays = [
        pa.array(times.dt.tz_convert("UTC").dt.as_unit("ns").dt.tz_localize(None).to_numpy(),
                 pa.timestamp("ns")).cast(pa.timestamp("ns", tz="UTC")),
        *(pa.array(frame[c].astype(object).to_numpy(), pa.string()) for c in ("station", "pass_id", "kind")),
        *(pa.array(frame[c].to_numpy(dtype=np.float64), pa.float64()) for c in ("value", "sigma")),
    ]
    fields = _canonical_fields()
    for name in frame.columns:
        if name not in COLUMNS:
            array = pa.array(frame[name], from_pandas=True)
            arrays.append(array)
            fields.append(pa.field(str(name), array.type))
    schema = pa.schema(fields, metadata={META_KEY: meta_text.encode()})
    return pa.Table.from_arrays(arrays, schema=schema)


def _canonical_fields() -> list:
    """The Arrow fields of :data:`COLUMNS` (a new list: the added columns' fields are appended)."""
    return [pa.field("time", pa.timestamp("ns", tz="UTC"), nullable=False),
            pa.field("station", pa.string(), nullable=False),
            pa.field("pass_id", pa.string(), nullable=False),
            pa.field("kind", pa.string(), nullable=False),
            pa.field("value", pa.float64(), nullable=False),
            pa.field("sigma", pa.float64(), nullable=False)]


def _arrow_of_columns(columns: dict, meta_text: str) -> pa.Table | None:
    """:func:`to_arrow` of numpy columns (``time`` naive UTC ``datetime64[ns]``, text object arrays
    of str), built from their buffers (``pa.array`` imports pandas, ~0.25 s of CPU): the same
    schema, NaN in an added float column a null as ``from_pandas`` makes it. None when an added
    column is neither float64 nor bool (the DataFrame path converts it)."""
    extras = {name: values for name, values in columns.items() if name not in COLUMNS}
    if any(values.dtype not in (np.float64, np.bool_) for values in extras.values()):
        return None
    arrays = [utc_time_array(columns["time"]), *(string_array(columns[c]) for c in ("station", "pass_id", "kind")),
              *(float_array(columns[c]) for c in ("value", "sigma"))]
    fields = _canonical_fields()
    for name, values in extras.items():
        array = bool_array(values) if values.dtype == np.bool_ else _float_array_nan_null(values)
        arrays.append(array)
        fields.append(pa.field(str(name), array.type))
    schema = pa.schema(fields, metadata={META_KEY: meta_text.encode()})
    return pa.Table.from_arrays(arrays, schema=schema)


def _float_array_nan_null(values: np.ndarray) -> pa.Array:
    """float64 Arrow array of ``values`` with NaN as null (``pa.array(..., from_pandas=True)``),
    from its buffers: the validity bitmap bit-packed least significant bit first (Arrow columnar format)."""
    data = np.ascontiguousarray(values, dtype=np.float64)
    valid = ~np.isnan(data)
    nulls = int(data.size - np.count_nonzero(valid))
    if not nulls:
        return float_array(data)
    bitmap = pa.py_buffer(np.packbits(valid, bitorder="little"))
    return pa.Array.from_buffers(pa.float64(), data.size, [bitmap, pa.py_buffer(data)], null_count=nulls)


def iso_times(times: pd.Series) -> np.ndarray:
    """UTC timestamps as ISO 8601 strings with ``Z``, at the coarsest exact precision (s..ns)."""
    return iso_utc_array(times.dt.tz_convert("UTC").dt.tz_localize(None).dt.as_unit("ns").to_numpy())


def _csv_cell(value) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return "" if value is None else str(value)


#: Angle kinds, and the columns that carry an angle on their rows (value and what smooth adds).
ANGLE_KINDS = ("elevation", "azimuth")
ANGLE_COLUMNS = ("value", "sigma", "smoothed", "residual")


def angles_in_degrees(frame: pd.DataFrame) -> pd.DataFrame:
    """Angle rows for a person's eyes (the CSV edge): kind ``elevation_deg`` / ``azimuth_deg``
    with value, sigma, smoothed and residual in degrees; radians stay in Parquet/Arrow."""
    rows = frame["kind"].isin(ANGLE_KINDS).to_numpy()
    if not rows.any():
        return frame
    frame = frame.copy()
    frame.loc[rows, "kind"] = frame.loc[rows, "kind"] + "_deg"
    for column in ANGLE_COLUMNS:
        if column in frame.columns and frame[column].dtype.kind == "f":
            # 1e-12 deg (2e-14 rad) is below any angle measurement; it hides the conversion's float
            # noise (14.999999999999998 for an input of 15)
            frame.loc[rows, column] = np.round(np.degrees(frame.loc[rows, column].to_numpy(dtype=np.float64)), 12)
    return frame


def pass_table_bytes(table: PassTable, fmt: str = "parquet") -> bytes:
    """The encoded file: ``parquet``, ``arrow`` (IPC stream) or ``csv``. Smoothing records (see
    :mod:`trackproc.io.smoothing_record`) follow an Arrow table as a second stream, and stay inline
    in the metadata of a Parquet or CSV that has no file of its own (:func:`write_pass_table` puts
    them in a sidecar)."""
    fmt = getattr(fmt, "value", fmt)
    if fmt not in FORMATS:
        raise ValueError(f"unknown pass-table format {fmt!r}; expected one of {FORMATS}")
    meta, records = smoothing_record.split_records(table.meta, "stream" if fmt == "arrow" else "inline")
    text = meta_json(meta)         # once: the size check and the file (the records' floats dominate)
    if records is None and smoothing_record.smoothing_of(meta).get("fits"):
        smoothing_record.check_inline_size(text, f"a {fmt} stream")
    table = table.with_meta(meta)
    if fmt == "csv":
        out = io.StringIO()
        out.write(csv_metadata_line(text))
        _write_csv_rows(out, table.frame, header=True)
        return out.getvalue().encode("utf-8")
    data = arrow_table_bytes(to_arrow(table, text), fmt)
    return data if records is None else data + arrow_table_bytes(records, "arrow")


def _write_csv_rows(out, frame: pd.DataFrame, *, header: bool) -> None:
    frame = angles_in_degrees(frame)
    writer = csv.writer(out, lineterminator="\n")
    columns = list(COLUMNS) + [c for c in frame.columns if c not in COLUMNS]
    if header:
        writer.writerow(columns)
    cells = [iso_times(frame["time"])] + [frame[c].to_numpy(dtype=object) for c in columns[1:]]
    for row in zip(*cells):
        writer.writerow([row[0]] + [_csv_cell(v) for v in row[1:]])


def write_pass_table(table: PassTable, path: str, fmt: str = "parquet") -> None:
    """Write ``table`` atomically to ``path`` (``-`` = stdout) as parquet, arrow or csv; the
    smoothing records of a Parquet or CSV file go to its sidecar (``x.passes.parquet``, written
    first) with their checksum in the pointer."""
    fmt = getattr(fmt, "value", fmt)
    target = None if is_stdio(path) else Path(path)
    if fmt != "arrow" and target is not None and not (target.exists() and not target.is_file()):
        meta, records = smoothing_record.split_records(table.meta, "sidecar")
        if records is not None:
            side = smoothing_record.sidecar_path(target)
            side_bytes = arrow_table_bytes(records, "parquet")
            meta[smoothing_record.META_KEY]["records"].update(
                file=side.name, sha256=hashlib.sha256(side_bytes).hexdigest())
            with open_atomic(side) as handle:
                handle.write(side_bytes)
            table = table.with_meta(meta)
    data = pass_table_bytes(table, fmt)
    with open_atomic(path) as handle:
        handle.write(data)


# --------------------------------------------------------------------------- reading


def read_pass_table(path: str) -> PassTable:
    """Read a canonical pass file (Parquet, Arrow file or stream, CSV) or ``-`` (stdin, buffered)."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_pass_table(read_input_bytes(path), source)


def parse_pass_table(data: bytes, source: str) -> PassTable:
    """The canonical pass table in ``data``; the format is detected from the first bytes."""
    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="a pass file (Parquet, Arrow or CSV from trackproc ingest)")
    table = source_table(data, source)
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise InputError("not a canonical pass file", file=source, row=table.header_row, column=missing[0],
                         found=", ".join(c.name for c in table.columns.values()),
                         expected="columns " + ", ".join(COLUMNS) + " (run trackproc ingest first)")
    meta = dict(table.meta)
    version = meta.get("schema_version", SCHEMA_VERSION)
    if not isinstance(version, int) or version > SCHEMA_VERSION:
        raise InputError("pass file written by a newer trackproc", file=source, column="schema_version",
                         found=version, expected=f"schema_version <= {SCHEMA_VERSION}")
    problems = Problems(table.rows, source)
    times = _plain_times(table.columns["time"])
    if times is None:
        times = column_times(table, table.columns["time"], problems)
    columns = {"time": times}
    for name in ("station", "pass_id", "kind"):
        columns[name] = np.asarray(column_strings(table, table.columns[name]), dtype=object)
    # text columns compared through their few distinct values (codes), never row by row
    codes, written = factorize(columns["kind"])
    written = [str(k) for k in written]
    in_degrees = [k in [a + "_deg" for a in ANGLE_KINDS] for k in written]   # a trackproc CSV's angle rows
    names = np.array([k[:-4] if deg else k for k, deg in zip(written, in_degrees)] or [""], dtype=object)
    degrees = np.array(in_degrees or [False])[codes]
    problems.add("unknown kind", ~np.array([k in KINDS for k in names])[codes], column="kind",
                 found=lambda i: names[codes[i]], expected="one of " + ", ".join(KINDS))
    for name in ("value", "sigma"):
        values, missing_mask, wrong = column_numbers(table, table.columns[name])
        problems.add("wrong column type", wrong | missing_mask, column=name,
                     found=table.columns[name].text if table.columns[name].text is not None else "null",
                     expected="a number (SI units)")
        columns[name] = values
    if degrees.any():   # a trackproc CSV's angle rows are in degrees (the CSV edge): radians inside
        columns["kind"] = names[codes]
        for name in ("value", "sigma"):
            columns[name] = np.where(degrees, np.radians(columns[name]), columns[name])
    _check_samples(problems, columns, table, source)
    problems.resolve(drop_invalid=False)
    extras = [column for key, column in table.columns.items() if key not in COLUMNS]
    for column in extras:
        columns[column.name] = _extra_array(column, degrees)
    _check_meta(meta, columns, table.rows, source)
    _attach_records(meta, data, source)
    base = {name: columns[name] for name in COLUMNS}
    return PassTable.from_columns(columns, meta, lambda: _frame_of(base, extras, degrees))


#: The time text a trackproc CSV holds (:func:`iso_times`).
_PLAIN_UTC = re.compile(r"\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(?:\.\d{1,9})?Z")


def _plain_times(column):
    """A CSV's time column as trackproc writes it (``YYYY-MM-DDTHH:MM:SS[.fff]Z``, every one a valid
    time in the supported years) parsed by numpy; None for anything else, which
    :func:`~trackproc.io.columns.column_times` parses with pandas and reports row by row."""
    text = column.text
    if text is None or not len(text) or not all(_PLAIN_UTC.fullmatch(t) for t in text):
        return None
    years = [int(t[:4]) for t in text]        # before parsing: beyond 2262 numpy's nanoseconds wrap
    if not FIRST_YEAR <= min(years) <= max(years) <= LAST_YEAR:
        return None
    try:
        return np.array([t[:-1] for t in text], dtype="datetime64[ns]")
    except ValueError:                          # e.g. 24:00:00, 23:59:60, 30 February: pandas' NaT
        return None


def _frame_of(columns: dict, extras: list, degrees: np.ndarray):
    """The DataFrame of a pass file's columns (pandas imported here: refine and estimate read numpy)."""
    import pandas as pd  # start-up: pandas (~0.15 s) only for the commands that use the DataFrame

    data = {"time": pd.DatetimeIndex(columns["time"]).tz_localize("UTC")}
    for name in ("station", "pass_id", "kind"):
        data[name] = pd.Series(columns[name], dtype=object).astype(str)
    data["value"], data["sigma"] = columns["value"], columns["sigma"]
    frame = pd.DataFrame(data)
    for column in extras:
        frame[column.name] = _extra_column(column)
    for name in ANGLE_COLUMNS[2:]:   # what smooth added on those rows (smoothed, residual)
        if degrees.any() and name in frame.columns and frame[name].dtype.kind == "f":
            frame.loc[degrees, name] = np.radians(frame.loc[degrees, name].to_numpy(dtype=np.float64))
    return frame


def factorize(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(codes, uniques)`` with the uniques in order of first appearance, as ``pandas.factorize``."""
    uniques, first, inverse = np.unique(np.asarray(values), return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(order), np.intp)
    rank[order] = np.arange(len(order))
    return rank[inverse.reshape(-1)], uniques[order]


def _extra_array(column, degrees: np.ndarray):
    """A later command's column as numpy when Arrow typed it without nulls (bool, integer, float)
    or a CSV holds booleans; None otherwise (the DataFrame's :func:`_extra_column` types it)."""
    if column.text is not None:           # a CSV's: its booleans (as _extra_column reads them) only
        lowered = [t.lower() for t in column.text]
        return np.array([t == "true" for t in lowered]) if lowered and all(
            t in ("true", "false") for t in lowered) else None
    array = column.array
    if array.null_count or not (
            pa.types.is_boolean(array.type) or pa.types.is_integer(array.type) or pa.types.is_floating(array.type)):
        return None
    values = arrow_numpy(array)
    if column.name in ANGLE_COLUMNS[2:] and values.dtype.kind == "f" and degrees.any():
        values = np.where(degrees, np.radians(values), values)
    return values


def _attach_records(meta: dict, data: bytes, source: str) -> None:
    """Layout-2 smoothing records, loaded when first used: in a sidecar, or after an Arrow stream."""
    pointer = smoothing_record.smoothing_of(meta).get("records")
    rest = None
    if isinstance(pointer, dict) and pointer.get("in") == "stream" and data[:4] == b"\xff\xff\xff\xff":
        reader = pa.BufferReader(data)
        try:
            pa.ipc.open_stream(reader).read_all()
            rest = data[reader.tell():]
        except (pa.ArrowException, OSError, ValueError):
            rest = None
    smoothing_record.attach_records(meta, source, rest)


def _check_samples(problems, columns: dict, table, source: str) -> None:
    """Values a pass file can hold: finite, sigma > 0, ranges >= 0, angles in their domains,
    |range-rate| <= 12 km/s; station names printable."""
    codes, names = factorize(columns["kind"])
    names = [str(k) for k in names]

    def of_kind(kind: str) -> np.ndarray:
        return codes == names.index(kind) if kind in names else np.zeros(len(codes), bool)

    value, sigma = np.asarray(columns["value"], float), np.asarray(columns["sigma"], float)
    given = np.isfinite(value)
    problems.add("non-finite value", ~given, column="value", found=value, expected="a finite number")
    problems.add("invalid sigma", ~(np.isfinite(sigma) & (sigma > 0)), column="sigma",
                 found=sigma, expected="a finite sigma > 0")
    problems.add("negative range", given & of_kind("range") & (value < 0), column="value", found=value,
                 expected="a range >= 0 m")
    problems.add("elevation out of range", given & of_kind("elevation") & (np.abs(value) > np.pi / 2 + 1e-12),
                 column="value", found=value, expected="an elevation in [-pi/2, pi/2] rad")
    problems.add("azimuth out of range", given & of_kind("azimuth") & ((value < -np.pi) | (value > 2 * np.pi)),
                 column="value", found=value, expected="an azimuth in [-pi, 2 pi] rad")
    problems.add("implausible range-rate", given & of_kind("range_rate") & (np.abs(value) > MAX_LOS_SPEED_M_S),
                 column="value", found=value,
                 expected=f"|range-rate| <= {MAX_LOS_SPEED_M_S:g} m/s (an Earth orbit)")
    codes, stations = factorize(columns["station"])
    _, first = np.unique(codes, return_index=True)
    for code, at in zip(range(len(stations)), first):
        check_name(str(stations[code]), "station name", file=source, row=int(table.rows[int(at)]), column="station")


def _check_meta(meta: dict, columns: dict, rows, source: str) -> None:
    """Metadata types and plausibility: stations (coordinates near the ellipsoid), the carrier
    (a radio carrier in Hz) and the Doppler it implies (a line-of-sight speed <= 12 km/s)."""
    stations = meta.get("stations")
    if stations is not None:
        if not isinstance(stations, dict):
            raise InputError("invalid metadata", file=source, column="stations", found=stations,
                             expected="an object: station name -> {lat_deg, lon_deg, height_m}")
        for name, values in stations.items():
            Station.from_meta(name, values, source)
    mode = meta.get("doppler_mode")
    if mode is not None and mode not in ("one-way", "two-way"):
        raise InputError("invalid metadata", file=source, column="doppler_mode", found=mode,
                         expected="one-way or two-way")
    carrier = meta.get("carrier_hz")
    if carrier is not None:
        carrier = check_carrier(carrier, file=source, column="carrier_hz")
        doppler = columns["kind"] == "doppler"
        check_los_speed(columns["value"][doppler], "doppler", carrier_hz=carrier, mode=mode,
                        file=source, rows=np.asarray(rows)[doppler], column="value")


def _extra_column(column):
    """A column appended by a later command: typed as stored (CSV: number, boolean or text)."""
    import pandas as pd  # start-up: pandas only where the DataFrame is built

    if column.text is None:
        return column.array.to_pandas()
    text = pd.Series(column.text, dtype=object)
    lowered = text.str.lower()
    if len(text) and lowered.isin(["true", "false"]).all():
        return lowered == "true"
    numbers = pd.to_numeric(text.replace("", np.nan), errors="coerce")
    if (numbers.notna() | lowered.isin(["", "nan", "inf", "-inf"])).all():
        numbers = pd.Series([float(v) if v else np.nan for v in text], dtype=np.float64)
        return numbers.astype(np.float64)
    return text.astype(str)
