"""Readers for tabular measurement files: CSV, Parquet and Arrow IPC, in wide or long layout.

Every reader returns :class:`trackproc.io.raw.RawMeasurements` (long form, SI units); the
validation rules live in :mod:`trackproc.pipeline.ingest`.

Layouts
    *wide*: ``time, station, <measurement columns> [, sigma_<measurement column> ...] [, pass_id]``
    where a measurement column names its unit: ``range_m``, ``range_km``, ``range_rate_m_s``,
    ``range_rate_km_s``, ``doppler_hz``, ``elevation_deg``, ``elevation_rad``, ``azimuth_deg``,
    ``azimuth_rad`` (see :data:`UNIT_SPELLINGS`). An empty cell means "no sample"; an explicit
    ``nan`` is a sample with a NaN value (an error at validation).
    *long*: ``time, station, kind, value [, sigma] [, pass_id]`` where ``kind`` is a canonical SI
    kind (``range`` m, ``range_rate`` m/s, ``doppler`` Hz, ``elevation``/``azimuth`` rad) or a
    unit-suffixed spelling of :data:`UNIT_SPELLINGS` (``elevation_deg``, ``range_km``, ...);
    ``sigma`` is in the same unit as ``value``. The canonical pass table is a long layout, so
    ingesting a trackproc output again gives the same samples.

Degrees become radians and kilometres metres. Times are ISO 8601 with ``Z``, with an offset, or
naive (taken as UTC); in Parquet/Arrow a timestamp column (naive = UTC) or ISO strings.

Row numbers in error messages
    CSV: the physical line in the file as an editor or spreadsheet shows it; with the header on the
    first line, the first data row is row 2. Parquet and Arrow: the 1-based record index (the
    first record is row 1).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, read_input_bytes
from trackproc.io.validate import FIRST_YEAR, LAST_YEAR, check_input_rows
from trackproc.io.raw import KIND_UNITS, RawMeasurements

log = logging.getLogger("trackproc")

#: Key of the trackproc metadata (JSON) in the Arrow / Parquet schema metadata.
META_KEY = b"trackproc"
#: Prefix of the comment line that carries the same metadata in a trackproc CSV.
CSV_META_PREFIX = "trackproc:"


def csv_metadata_line(meta_text: str) -> str:
    """The ``# trackproc: {...}`` first line of a CSV output, or nothing when the run asked for
    plain CSV (``--no-metadata`` / ``TRACKPROC_CSV_METADATA=0``: spreadsheets and pandas read it
    without options; the metadata then lives only in Parquet/Arrow outputs)."""
    import os

    if os.environ.get("TRACKPROC_CSV_METADATA", "1").strip().lower() in ("0", "false", "no", "off"):
        return ""
    return f"# {CSV_META_PREFIX} {meta_text}\n"

DEG = math.pi / 180.0

#: Unit-suffixed spelling -> (canonical kind, factor to SI, unit as written).
UNIT_SPELLINGS: dict[str, tuple[str, float, str]] = {
    "range_m": ("range", 1.0, "m"),
    "range_km": ("range", 1e3, "km"),
    "range_rate_m_s": ("range_rate", 1.0, "m/s"),
    "range_rate_km_s": ("range_rate", 1e3, "km/s"),
    "doppler_hz": ("doppler", 1.0, "Hz"),
    "elevation_deg": ("elevation", DEG, "deg"),
    "elevation_rad": ("elevation", 1.0, "rad"),
    "azimuth_deg": ("azimuth", DEG, "deg"),
    "azimuth_rad": ("azimuth", 1.0, "rad"),
}
#: Long-layout ``kind`` values: the canonical SI kinds and the unit-suffixed spellings.
KIND_SPELLINGS: dict[str, tuple[str, float, str]] = {
    **{kind: (kind, 1.0, unit) for kind, unit in KIND_UNITS.items()},
    **UNIT_SPELLINGS,
}

#: Reasons an invalid row is reported (or dropped with ``drop_invalid``).
UNPARSEABLE_TIME = "unparseable time"
WRONG_TYPE = "wrong column type"
UNKNOWN_KIND = "unknown kind"
NONFINITE_VALUE = "non-finite value"
NONFINITE_SIGMA = "non-finite sigma"

TIME_EXPECTED = "an ISO 8601 UTC time such as 2020-04-01T08:44:03.29Z (years 1678-2261)"


# --------------------------------------------------------------------------- invalid rows


class Problems:
    """Invalid rows of a table, by reason: raise the earliest one, or drop them all.

    ``rows`` are the 1-based source rows shown in messages, ``files`` the source of each row (one
    name, or an array when several files were merged); ``order`` sorts rows for "earliest"
    (defaults to ``rows``). Each :meth:`add` takes a boolean mask over the rows and, per row,
    the column, the value found and the expected form (a scalar, an array, or a callable of the
    row position).
    """

    def __init__(self, rows, files, order=None):
        self.rows = np.asarray(rows)
        self.files = files
        self.order = self.rows if order is None else np.asarray(order)
        self._checks: list[tuple] = []

    def add(self, reason: str, mask, *, column, found, expected, detail="") -> None:
        mask = np.asarray(mask, dtype=bool)
        if mask.any():
            self._checks.append((reason, mask, column, found, expected, detail))

    def __bool__(self) -> bool:
        return bool(self._checks)

    def invalid(self) -> np.ndarray:
        """True for every row with at least one problem so far."""
        bad = np.zeros(len(self.rows), dtype=bool)
        for check in self._checks:
            bad |= check[1]
        return bad

    def first_error(self) -> InputError | None:
        best = None
        for check in self._checks:
            positions = np.flatnonzero(check[1])
            pos = int(positions[np.argmin(self.order[positions])])
            if best is None or self.order[pos] < self.order[best[0]]:
                best = (pos, check)
        if best is None:
            return None
        pos, (reason, _, column, found, expected, detail) = best
        pick = _picker(pos)
        return InputError(pick(detail) or reason, file=pick(self.files), row=int(self.rows[pos]),
                          column=pick(column), found=_plain(pick(found)), expected=pick(expected))

    def resolve(self, drop_invalid: bool) -> tuple[np.ndarray, dict[str, int]]:
        """Rows to keep and, per reason, how many rows were dropped (each counted once)."""
        keep = np.ones(len(self.rows), dtype=bool)
        if not self._checks:
            return keep, {}
        if not drop_invalid:
            raise self.first_error()
        counts: dict[str, int] = {}
        for reason, mask, *_ in self._checks:
            newly = mask & keep
            if newly.any():
                counts[reason] = counts.get(reason, 0) + int(newly.sum())
            keep &= ~mask
        return keep, counts


def _picker(pos: int) -> Callable[[object], object]:
    def pick(item):
        if callable(item):
            return item(pos)
        if isinstance(item, (np.ndarray, pd.Series, list, tuple)):
            return item[pos] if not isinstance(item, pd.Series) else item.iloc[pos]
        return item
    return pick


def _plain(value):
    """numpy scalars shown as Python values in messages."""
    return value.item() if isinstance(value, np.generic) else value


def add_counts(total: dict[str, int], more: dict[str, int]) -> dict[str, int]:
    for reason, n in more.items():
        total[reason] = total.get(reason, 0) + n
    return total


# --------------------------------------------------------------------------- CSV text


@dataclass
class TextTable:
    """A CSV read as text: stripped cells per column, the source line of each data row."""

    columns: list[str]                       # header names as written (stripped)
    cells: dict[str, np.ndarray]             # header name -> object array of str ('' = empty)
    rows: np.ndarray                         # 1-based physical line of each data row
    header_row: int
    comments: list[str] = field(default_factory=list)   # '#' lines, without the '#'


def decode_text(data: bytes, source: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError("not UTF-8 text", file=source, row=line,
                         found=data[exc.start: exc.start + 8],
                         expected="a CSV file (UTF-8), Parquet, Arrow IPC or CCSDS TDM") from None


def parse_text_table(data: bytes, source: str, *, header: list[str] | None = None) -> TextTable:
    """Split a comma-separated text into columns, keeping each data row's line number.

    Blank lines and lines starting with ``#`` are skipped (their line numbers still count).
    ``header`` given: every non-comment line is data; otherwise the first one is the header.
    """
    check_input_rows(data.count(b"\n") - 1, file=source)
    text = decode_text(data, source)
    lines = text.splitlines()
    comments = []
    for i, line in enumerate(lines):
        if line.lstrip().startswith("#"):
            comments.append(line.lstrip()[1:].strip())
            lines[i] = ""
    reader = csv.reader(io.StringIO("\n".join(lines)), skipinitialspace=True)
    records, starts, last = [], [], 0
    try:
        for record in reader:
            start, last = last + 1, reader.line_num
            if not any(cell.strip() for cell in record):
                continue
            records.append([cell.strip() for cell in record])
            starts.append(start)
    except csv.Error as exc:   # a cell beyond csv.field_size_limit (128 kB), a NUL byte
        raise InputError(f"unreadable CSV ({exc})", file=source, row=last + 1,
                         expected=f"CSV cells of at most {csv.field_size_limit()} characters, no NUL") from None
    header_row = 0
    if header is None:
        if not records:
            raise InputError("empty input", file=source, row=1, found="no header line",
                             expected="a header line naming the columns")
        header, header_row = records.pop(0), starts.pop(0)
        _check_header(header, source, header_row)
    width = len(header)
    for record, row in zip(records, starts):
        if len(record) != width:
            raise InputError("wrong number of fields", file=source, row=row,
                             found=f"{len(record)} fields",
                             expected=f"{width} fields as in the header ({', '.join(header)})")
    cells = {name: np.array([r[j] for r in records], dtype=object) for j, name in enumerate(header)}
    return TextTable(list(header), cells, np.array(starts, dtype=np.int64), header_row, comments)


def _check_header(header: list[str], source: str, row: int) -> None:
    seen = set()
    for name in header:
        key = name.lower()
        if not key:
            raise InputError("empty column name in the header", file=source, row=row,
                             found=",".join(header), expected="a name for every column")
        if key in seen:
            raise InputError("duplicate column", file=source, row=row, column=name,
                             expected="each column name once")
        seen.add(key)


# --------------------------------------------------------------------------- source tables


@dataclass
class SourceTable:
    """Columns of a CSV (text) or of a Parquet/Arrow table (typed), by lower-case name."""

    source: str
    columns: dict[str, "Column"]
    rows: np.ndarray
    header_row: int | None                  # CSV header line; None for Parquet/Arrow
    meta: dict                              # trackproc metadata carried by the file, or {}

    def __len__(self) -> int:
        return len(self.rows)

    def require(self, *names: str) -> None:
        missing = [n for n in names if n not in self.columns]
        if missing:
            raise InputError("missing required column", file=self.source, row=self.header_row,
                             column=missing[0], found=", ".join(c.name for c in self.columns.values()),
                             expected="columns " + ", ".join(names))


@dataclass
class Column:
    """One column: ``text`` (object array of str, '' = empty) or typed Arrow ``array``."""

    name: str
    text: np.ndarray | None = None
    array: pa.Array | None = None

    @property
    def type_name(self) -> str:
        return "text" if self.text is not None else str(self.array.type)


def sniff_container(data: bytes) -> str:
    """``parquet``, ``arrow-file``, ``arrow-stream`` or ``text`` from the first bytes."""
    if data[:4] == b"PAR1":
        return "parquet"
    if data[:6] == b"ARROW1":
        return "arrow-file"
    if data[:4] == b"\xff\xff\xff\xff":
        return "arrow-stream"
    return "text"


def load_arrow(data: bytes, source: str, container: str) -> pa.Table:
    """A Parquet or Arrow IPC (file or stream) buffer as an Arrow table."""
    try:
        if container == "parquet":
            import pyarrow.parquet as pq
            check_input_rows(pq.ParquetFile(pa.BufferReader(data)).metadata.num_rows, file=source)
            return pq.read_table(pa.BufferReader(data))
        if container == "arrow-file":
            return pa.ipc.open_file(pa.BufferReader(data)).read_all()
        return pa.ipc.open_stream(pa.BufferReader(data)).read_all()
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise InputError(f"unreadable {container} data ({exc})", file=source,
                         expected=f"a complete {container} file") from None


def table_meta(schema: pa.Schema) -> dict:
    raw = (schema.metadata or {}).get(META_KEY)
    if raw is None:
        return {}
    try:
        meta = json.loads(raw)
    except (ValueError, RecursionError):
        return {}
    return meta if isinstance(meta, dict) else {}


def source_table(data: bytes, source: str) -> SourceTable:
    """Any supported table container (CSV text, Parquet, Arrow file/stream) as columns."""
    container = sniff_container(data)
    if container == "text":
        text = parse_text_table(data, source)
        meta = {}
        for comment in text.comments:
            if comment.startswith(CSV_META_PREFIX):
                try:
                    meta = json.loads(comment[len(CSV_META_PREFIX):])
                except (ValueError, RecursionError):
                    meta = {}
        columns = {name.lower(): Column(name, text=text.cells[name]) for name in text.columns}
        return SourceTable(source, columns, text.rows, text.header_row, meta)
    table = load_arrow(data, source, container)
    check_input_rows(table.num_rows, file=source)
    columns = {}
    for name in table.column_names:
        if name.strip().lower() in columns:
            raise InputError("duplicate column", file=source, column=name, expected="each column name once")
        columns[name.strip().lower()] = _arrow_column(name, table.column(name).combine_chunks())
    rows = np.arange(1, table.num_rows + 1, dtype=np.int64)
    return SourceTable(source, columns, rows, None, table_meta(table.schema))


def _arrow_column(name: str, array: pa.Array) -> Column:
    if pa.types.is_dictionary(array.type):
        array = array.cast(array.type.value_type)
    if pa.types.is_string(array.type) or pa.types.is_large_string(array.type) or \
            pa.types.is_string_view(array.type):
        values = pc.fill_null(array.cast(pa.string()), "").to_numpy(zero_copy_only=False)
        return Column(name, text=np.array([v.strip() for v in values], dtype=object))
    return Column(name, array=array)


def _wrong_type(table: SourceTable, column: Column, expected: str) -> InputError:
    return InputError(WRONG_TYPE, file=table.source, row=int(table.rows[0]) if len(table) else None,
                      column=column.name, found=column.type_name, expected=expected)


def column_times(table: SourceTable, column: Column, problems: Problems, index=None) -> np.ndarray:
    """UTC times as ``datetime64[ns]`` (NaT where unparseable, reported to ``problems``).

    ``index`` maps the problems' positions to the table's rows (default: one to one).
    """
    if column.text is not None:
        text = pd.Series(column.text, dtype=object)
        # beyond 1678-2261 a nanosecond timestamp wraps or raises: such rows are unparseable times
        year = pd.to_numeric(text.astype(str).str.extract(r"^\s*([+-]?\d{4,})-", expand=False), errors="coerce")
        text = text.where(~((year < FIRST_YEAR) | (year > LAST_YEAR)), "")
        try:
            parsed = pd.to_datetime(text, utc=True, format="ISO8601", errors="coerce")
        except (ValueError, OverflowError):   # OutOfBoundsDatetime despite errors="coerce"
            parsed = pd.Series([_one_time(t) for t in text], dtype="datetime64[ns, UTC]")
        values = parsed.dt.tz_localize(None).dt.as_unit("ns").to_numpy()
    elif pa.types.is_timestamp(column.array.type):
        # Out-of-range stamps (year 3000 in ms or us) become NaT and are reported by row; a failing
        # cast is not used for this (its exception left Arrow aborting at exit in ~7 % of runs).
        unit = column.array.type.unit
        ticks = pc.cast(column.array, pa.int64()).to_numpy(zero_copy_only=False)
        ticks = np.where(np.isnan(ticks.astype(float)), 0, ticks).astype(np.int64) if ticks.dtype != np.int64 \
            else ticks
        lo = np.datetime64(f"{FIRST_YEAR}-01-01", unit).astype(np.int64)
        hi = np.datetime64(f"{LAST_YEAR + 1}-01-01", unit).astype(np.int64)
        outside = (ticks < lo) | (ticks >= hi)
        values = np.where(outside, np.int64(0), ticks).astype(f"datetime64[{unit}]").astype("datetime64[ns]")
        values[outside | column.array.is_null().to_numpy(zero_copy_only=False)] = np.datetime64("NaT")
    else:
        raise _wrong_type(table, column, "a timestamp column or ISO 8601 strings")
    bad = np.isnat(values)
    if index is not None:
        bad = bad[index]
    found = column.text if column.text is not None else None
    if found is not None:
        found = _indexed(found, index)
    elif index is None:
        found = lambda i: "null" if not column.array[i].is_valid else str(column.array[i])  # noqa: E731
    else:
        found = "null or out of range"
    problems.add(UNPARSEABLE_TIME, bad, column=column.name, found=found, expected=TIME_EXPECTED)
    return values


def _one_time(text) -> pd.Timestamp:
    try:
        return pd.to_datetime(text, utc=True, format="ISO8601")
    except (ValueError, OverflowError, TypeError):
        return pd.NaT


def _indexed(array, index):
    return array if index is None else array[index]


def column_numbers(table: SourceTable, column: Column) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(values, missing, wrong)`` as float64 / bool arrays (NaN where missing or wrong).

    Text: '' is missing; ``nan``/``inf`` parse to NaN/inf; anything else not a number is wrong.
    Typed: null is missing; integers, floats and decimals convert; other types raise.
    """
    if column.text is not None:
        n = len(column.text)
        values = np.full(n, np.nan)
        missing = np.zeros(n, dtype=bool)
        wrong = np.zeros(n, dtype=bool)
        for i, cell in enumerate(column.text):
            if not cell:
                missing[i] = True
                continue
            try:
                values[i] = float(cell)
            except ValueError:
                wrong[i] = True
        return values, missing, wrong
    arr = column.array
    if not (pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type) or pa.types.is_decimal(arr.type)):
        raise _wrong_type(table, column, "a numeric column")
    missing = arr.is_null().to_numpy(zero_copy_only=False)
    values = pc.fill_null(arr.cast(pa.float64()), math.nan).to_numpy(zero_copy_only=False)
    return values.astype(np.float64), missing, np.zeros(len(values), dtype=bool)


def column_strings(table: SourceTable, column: Column) -> np.ndarray:
    """Text cells ('' where empty); integer columns (station numbers) become their digits."""
    if column.text is not None:
        return column.text
    if pa.types.is_integer(column.array.type):
        return np.array(["" if v is None else str(v) for v in column.array.to_pylist()], dtype=object)
    raise _wrong_type(table, column, "a text column")


# --------------------------------------------------------------------------- layouts


def is_long_layout(table: SourceTable) -> bool:
    return "kind" in table.columns and "value" in table.columns


def read_long(table: SourceTable, *, drop_invalid: bool = False) -> RawMeasurements:
    """Long layout ``time, station, kind, value [, sigma] [, pass_id]`` -> raw samples (SI)."""
    table.require("time", "station", "kind", "value")
    _empty_check(table)
    problems = Problems(table.rows, table.source)
    times = column_times(table, table.columns["time"], problems)
    kinds_written = np.array([k.lower() for k in column_strings(table, table.columns["kind"])], dtype=object)
    spelled = [KIND_SPELLINGS.get(k) for k in kinds_written]
    unknown = np.array([s is None for s in spelled])
    problems.add(UNKNOWN_KIND, unknown, column=table.columns["kind"].name, found=kinds_written,
                 expected="one of " + ", ".join(KIND_SPELLINGS))
    spelled = [s or ("", math.nan, "") for s in spelled]
    kind = np.array([s[0] for s in spelled], dtype=object)
    factor = np.array([s[1] for s in spelled])
    unit = np.array([s[2] for s in spelled], dtype=object)

    value_col = table.columns["value"]
    value, missing, wrong = column_numbers(table, value_col)
    problems.add(WRONG_TYPE, wrong, column=value_col.name, found=value_col.text, expected="a number")
    problems.add(NONFINITE_VALUE, missing, column=value_col.name, found="",
                 expected="a finite number")
    sigma = np.full(len(table), np.nan)
    column_map = {"time": table.columns["time"].name, "station": table.columns["station"].name}
    if "sigma" in table.columns:
        sigma_col = table.columns["sigma"]
        sigma, _, wrong = column_numbers(table, sigma_col)
        problems.add(WRONG_TYPE, wrong, column=sigma_col.name, found=sigma_col.text,
                     expected="a number or an empty cell")
        explicit_nan = np.isnan(sigma) & ~_blank(table, sigma_col) & ~wrong
        problems.add(NONFINITE_SIGMA, explicit_nan, column=sigma_col.name, found=math.nan,
                     expected="a finite number > 0, or an empty cell for the default")
        column_map.update({f"sigma:{k}": sigma_col.name for k in KIND_UNITS})
    column_map.update({k: value_col.name for k in KIND_UNITS})
    frame = pd.DataFrame({
        "time": pd.DatetimeIndex(times).tz_localize("UTC"),
        "station": column_strings(table, table.columns["station"]),
        "kind": kind,
        "value": value * factor,
        "sigma": sigma * factor,
        "row": table.rows,
        "unit": unit,
    })
    if "pass_id" in table.columns:
        frame["pass_id"] = column_strings(table, table.columns["pass_id"])
    keep, dropped = problems.resolve(drop_invalid)
    return _raw(frame[keep].reset_index(drop=True), table, column_map, dropped)


def read_wide(table: SourceTable, *, drop_invalid: bool = False) -> RawMeasurements:
    """Wide layout ``time, station, range_rate_m_s, elevation_deg, ...`` -> raw samples (SI)."""
    table.require("time", "station")
    measured = [name for name in table.columns if name in UNIT_SPELLINGS]
    if not measured:
        raise InputError("no measurement column", file=table.source, row=table.header_row,
                         column="(none)", found=", ".join(c.name for c in table.columns.values()),
                         expected="at least one of " + ", ".join(UNIT_SPELLINGS)
                         + " (wide layout), or kind and value columns (long layout)")
    _check_one_column_per_kind(table, measured)
    _warn_unused(table, measured)
    _empty_check(table)
    stations = column_strings(table, table.columns["station"])
    pass_ids = column_strings(table, table.columns["pass_id"]) if "pass_id" in table.columns else None
    pieces, column_map = [], {"time": table.columns["time"].name, "station": table.columns["station"].name}
    for position, name in enumerate(measured):
        kind, factor, unit = UNIT_SPELLINGS[name]
        col = table.columns[name]
        value, missing, wrong = column_numbers(table, col)
        sigma_col = table.columns.get("sigma_" + name)
        if sigma_col is not None:
            sigma, _, sigma_wrong = column_numbers(table, sigma_col)
            sigma_nan = np.isnan(sigma) & ~_blank(table, sigma_col) & ~sigma_wrong
            column_map[f"sigma:{kind}"] = sigma_col.name
        else:
            sigma = np.full(len(table), np.nan)
            sigma_wrong = sigma_nan = np.zeros(len(table), dtype=bool)
        column_map[kind] = col.name
        take = np.flatnonzero(~missing)
        pieces.append(pd.DataFrame({
            "src": take, "position": position, "kind": kind, "value": value[take] * factor,
            "sigma": sigma[take] * factor, "unit": unit, "column": col.name,
            "sigma_column": sigma_col.name if sigma_col is not None else "",
            "wrong": wrong[take], "sigma_wrong": sigma_wrong[take], "sigma_nan": sigma_nan[take],
            "found": col.text[take] if col.text is not None else value[take],
            "sigma_found": sigma_col.text[take] if sigma_col is not None and sigma_col.text is not None
            else sigma[take],
        }))
    samples = pd.concat(pieces, ignore_index=True)
    if samples.empty:
        raise InputError("empty input", file=table.source, row=int(table.rows[0]),
                         column=", ".join(table.columns[m].name for m in measured),
                         found="no measurement in any row", expected="at least one measurement")
    src = samples["src"].to_numpy()
    rows = table.rows[src]
    problems = Problems(rows, table.source, order=rows * 1000 + samples["position"].to_numpy())
    times = column_times(table, table.columns["time"], problems, index=src)
    problems.add(WRONG_TYPE, samples["wrong"].to_numpy(), column=samples["column"].to_numpy(),
                 found=samples["found"].to_numpy(), expected="a number or an empty cell")
    problems.add(WRONG_TYPE, samples["sigma_wrong"].to_numpy(), column=samples["sigma_column"].to_numpy(),
                 found=samples["sigma_found"].to_numpy(), expected="a number or an empty cell")
    problems.add(NONFINITE_SIGMA, samples["sigma_nan"].to_numpy(), column=samples["sigma_column"].to_numpy(),
                 found=math.nan, expected="a finite number > 0, or an empty cell for the default")
    frame = pd.DataFrame({
        "time": pd.DatetimeIndex(times[src]).tz_localize("UTC"),
        "station": stations[src],
        "kind": samples["kind"].to_numpy(dtype=object),
        "value": samples["value"].to_numpy(),
        "sigma": samples["sigma"].to_numpy(),
        "row": rows,
        "unit": samples["unit"].to_numpy(dtype=object),
    })
    if pass_ids is not None:
        frame["pass_id"] = pass_ids[src]
    keep, dropped = problems.resolve(drop_invalid)
    return _raw(frame[keep].reset_index(drop=True), table, column_map, dropped)


def _blank(table: SourceTable, column: Column) -> np.ndarray:
    if column.text is not None:
        return column.text == ""
    return column.array.is_null().to_numpy(zero_copy_only=False)


def _empty_check(table: SourceTable) -> None:
    if len(table) == 0:
        first = (table.header_row + 1) if table.header_row is not None else 1
        raise InputError("empty input", file=table.source, row=first, found="no data rows",
                         expected="at least one measurement row")


def _check_one_column_per_kind(table: SourceTable, measured: list[str]) -> None:
    seen: dict[str, str] = {}
    for name in measured:
        kind = UNIT_SPELLINGS[name][0]
        if kind in seen:
            raise InputError(f"two columns give {kind}", file=table.source, row=table.header_row,
                             column=table.columns[name].name, found=f"{seen[kind]} and {name}",
                             expected=f"one {kind} column")
        seen[kind] = name


def _warn_unused(table: SourceTable, measured: list[str]) -> None:
    used = {"time", "station", "pass_id", *measured, *("sigma_" + m for m in measured)}
    for key, column in table.columns.items():
        if key not in used:
            hint = " (name its unit, e.g. elevation_deg)" if key in KIND_UNITS else ""
            log.warning("%s: ignoring column '%s'%s", table.source, column.name, hint)


def _raw(frame: pd.DataFrame, table: SourceTable, column_map: dict, dropped: dict) -> RawMeasurements:
    meta = {"source": table.source, "dropped": dropped}
    carried = table.meta
    for key in ("carrier_hz", "doppler_mode", "stations", "doptrack"):
        if carried.get(key) is not None:
            meta[key] = carried[key]
    return RawMeasurements(frame=frame, source=table.source, column=column_map, meta=meta)


# --------------------------------------------------------------------------- dispatch

LAYOUTS = ("auto", "wide", "long", "doptrack", "aer", "tdm", "crd")


def detect_layout(data: bytes, name: str) -> str:
    """Guess the layout of an input from its first bytes and its name (``auto``)."""
    if sniff_container(data) != "text":
        return "table"
    head = data[:4096].decode("utf-8-sig", errors="replace").lstrip()
    if head.startswith("CCSDS_TDM_VERS"):
        return "tdm"
    from trackproc.io import crd, doptrack, orekit_aer

    if crd.looks_like_crd(head) or name.lower().endswith((".npt", ".crd", ".frd")):
        return "crd"
    if doptrack.looks_like_doptrack(head):
        return "doptrack"
    if name.lower().endswith(".aer") or orekit_aer.looks_like_aer(head):
        return "aer"
    if name.lower().endswith(".tdm") or name.lower().endswith(".kvn"):
        return "tdm"
    return "table"


def read_raw(path: str, layout: str = "auto", *, sidecar: str | None = None,
             carrier_hz: float | None = None, drop_invalid: bool = False,
             tdm_two_way_range: str = "one-way-equivalent") -> RawMeasurements:
    """Read one input file (or ``-`` for stdin) into raw samples.

    ``layout``: one of :data:`LAYOUTS`; ``sidecar``: DopTrack YAML (overrides the lookup next
    to the data file); ``carrier_hz``: nominal carrier, Hz, used by the DopTrack and TDM readers
    to turn received frequencies into Doppler shifts; ``tdm_two_way_range``: how a TDM writes
    two-way RANGE (``one-way-equivalent`` or ``round-trip``, see :mod:`trackproc.io.tdm`).
    """
    source = "<stdin>" if is_stdio(path) else str(path)
    data = read_input_bytes(path)
    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="a CSV, Parquet, Arrow IPC, DopTrack, Orekit .aer or CCSDS TDM file")
    if layout == "auto":
        layout = detect_layout(data, "" if is_stdio(path) else Path(path).name)
    if layout == "doptrack":
        from trackproc.io.doptrack import read_doptrack

        data_path = None if is_stdio(path) else Path(path)
        return read_doptrack(data, source, data_path=data_path, sidecar=sidecar,
                             carrier_hz=carrier_hz, drop_invalid=drop_invalid)
    if layout == "crd":
        from trackproc.io.crd import read_crd

        return read_crd(data, source, drop_invalid=drop_invalid)
    if layout == "aer":
        from trackproc.io.orekit_aer import read_aer

        return read_aer(data, source, drop_invalid=drop_invalid)
    if layout == "tdm":
        try:
            from trackproc.io.tdm import read_tdm
        except ImportError:
            raise InputError("CCSDS TDM input is not supported by this installation",
                             file=source, expected="CSV, Parquet, Arrow, DopTrack or .aer") from None
        return read_tdm(data, source, carrier_hz=carrier_hz, two_way_range=tdm_two_way_range)
    table = source_table(data, source)
    if layout == "long" or (layout in ("auto", "table") and is_long_layout(table)):
        return read_long(table, drop_invalid=drop_invalid)
    return read_wide(table, drop_invalid=drop_invalid)
