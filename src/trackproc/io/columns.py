"""Columns of an input table, CSV text or typed Arrow (Parquet, Arrow IPC), whole or streamed:
lookup by lower-case name, and conversion of a column to times, numbers or strings with the
invalid cells reported to :class:`~trackproc.io.problems.Problems`. A little over 400 lines: each
conversion has an exact path and a fast path for the common case (fixed-layout ISO times, plain
decimal numbers) that must give the same values, and they are kept side by side."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np
import pyarrow as pa

from trackproc.errors import InputError
from trackproc.io.csvtext import TextTable, chunk_rows, iter_text_tables, parse_csv_metadata, parse_text_table
from trackproc.io.problems import TIME_EXPECTED, UNPARSEABLE_TIME, WRONG_TYPE, Problems
from trackproc.io.validate import FIRST_YEAR, LAST_YEAR, check_input_rows

#: Key of the trackproc metadata (JSON) in the Arrow / Parquet schema metadata.
META_KEY = b"trackproc"

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
    """One column: ``text`` (object array of str, '' = empty) or typed Arrow ``array``;
    ``strings``: the same ``text`` as an Arrow string array when Arrow's CSV reader read it."""

    name: str
    text: np.ndarray | None = None
    array: pa.Array | None = None
    strings: pa.Array | None = None

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
            import pyarrow.parquet as pq  # start-up: pyarrow.parquet only for Parquet input
            parquet = pq.ParquetFile(pa.BufferReader(data))
            check_input_rows(parquet.metadata.num_rows, file=source)
            # text columns as stored, a dictionary: each string once, and no pyarrow.compute to encode them
            text = [f.name for f in parquet.schema_arrow if _is_string(f.type)]
            if text:
                parquet = pq.ParquetFile(pa.BufferReader(data), read_dictionary=text)
            return parquet.read()      # not pq.read_table: it imports pyarrow.dataset (~0.1 s CPU)
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
        return _text_source(parse_text_table(data, source), source)
    table = load_arrow(data, source, container)
    check_input_rows(table.num_rows, file=source)
    return _arrow_source(table, source, 0, table_meta(table.schema))


def iter_source_tables(blocks: Iterable[bytes], source: str, *, path: str | None = None) -> Iterator[SourceTable]:
    """The same, streamed: one :class:`SourceTable` per chunk of :func:`~trackproc.io.csvtext.chunk_rows`
    rows, the file's row numbers in each (at least one, perhaps empty, table). ``blocks``: the input's
    bytes (:func:`~trackproc.io.atomic.iter_input_blocks`); ``path``: a regular file, read by Parquet
    and Arrow directly (one row group at a time) instead of from ``blocks``."""
    blocks = iter(blocks)
    head = next(blocks, b"")
    container = sniff_container(head)
    if container == "text":
        meta = None
        for text in iter_text_tables(_chain(head, blocks), source):
            if meta is None:
                meta = _csv_meta(text.comments)
            table = _text_source(text, source)
            table.meta = meta
            yield table
        return
    stream = path if path is not None else pa.BufferReader(head + b"".join(blocks))
    yield from _arrow_chunks(stream, source, container)


def _chain(head: bytes, blocks: Iterator[bytes]) -> Iterator[bytes]:
    yield head
    yield from blocks


def _csv_meta(comments: list[str]) -> dict:
    return parse_csv_metadata(comments)


def _text_source(text: TextTable, source: str) -> SourceTable:
    arrow = text.arrow or {}
    columns = {name.lower(): Column(name, text=text.cells[name], strings=arrow.get(name)) for name in text.columns}
    return SourceTable(source, columns, text.rows, text.header_row, _csv_meta(text.comments))


def _arrow_source(table, source: str, offset: int, meta: dict) -> SourceTable:
    columns = {}
    for name in table.schema.names:
        if name.strip().lower() in columns:
            raise InputError("duplicate column", file=source, column=name, expected="each column name once")
        column = table.column(name)
        columns[name.strip().lower()] = _arrow_column(
            name, column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column)
    rows = np.arange(offset + 1, offset + table.num_rows + 1, dtype=np.int64)
    return SourceTable(source, columns, rows, None, meta)


def _arrow_chunks(stream, source: str, container: str) -> Iterator[SourceTable]:
    """Record batches of a Parquet file (row group by row group) or an Arrow IPC file or stream."""
    size = chunk_rows()
    try:
        if container == "parquet":
            import pyarrow.parquet as pq  # start-up: pyarrow.parquet only for Parquet input

            handle = pq.ParquetFile(stream)
            check_input_rows(handle.metadata.num_rows, file=source)
            schema, batches = handle.schema_arrow, handle.iter_batches(batch_size=size)
        elif container == "arrow-file":
            handle = pa.ipc.open_file(stream)
            schema = handle.schema
            batches = (handle.get_batch(i) for i in range(handle.num_record_batches))
        else:
            handle = pa.ipc.open_stream(stream)
            schema, batches = handle.schema, iter(handle)
        meta, offset = table_meta(schema), 0
        empty = True
        for batch in batches:
            for start in range(0, batch.num_rows, size):
                piece = batch.slice(start, size)
                check_input_rows(offset + piece.num_rows, file=source)
                empty = False
                yield _arrow_source(piece, source, offset, meta)
                offset += piece.num_rows
        if empty:
            yield _arrow_source(schema.empty_table(), source, 0, meta)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise InputError(f"unreadable {container} data ({exc})", file=source,
                         expected=f"a complete {container} file") from None


#: numpy dtypes of the Arrow types :func:`arrow_numpy` reads from their buffers.
_NUMPY_OF_ARROW = {"int8": "i1", "int16": "i2", "int32": "i4", "int64": "i8", "uint8": "u1", "uint16": "u2",
                   "uint32": "u4", "uint64": "u8", "halffloat": "f2", "float": "f4", "double": "f8"}


def arrow_numpy(array) -> np.ndarray:
    """A null-free Arrow array of numbers, booleans or timestamps (as int64) as numpy, read from its
    buffers: pyarrow's own ``to_numpy`` imports pandas (~0.15 s of CPU) on its first call."""
    if isinstance(array, pa.ChunkedArray):
        array = array.combine_chunks()
    kind = str(array.type)
    if array.null_count or not (kind in _NUMPY_OF_ARROW or kind == "bool" or pa.types.is_timestamp(array.type)):
        return array.to_numpy(zero_copy_only=False)
    n, data = len(array), array.buffers()[1]
    if kind == "bool":
        bits = np.unpackbits(np.frombuffer(data, np.uint8), bitorder="little")
        return bits[array.offset:array.offset + n].astype(bool)
    dtype = np.dtype(_NUMPY_OF_ARROW.get(kind, "i8"))
    return np.frombuffer(data, dtype, count=n, offset=array.offset * dtype.itemsize).copy()


def _is_string(kind) -> bool:
    # string_view exists from pyarrow 16 (the oldest supported is 12)
    is_view = getattr(pa.types, "is_string_view", None)
    return pa.types.is_string(kind) or pa.types.is_large_string(kind) or (is_view is not None and is_view(kind))


def _arrow_column(name: str, array: pa.Array) -> Column:
    if pa.types.is_dictionary(array.type) and _is_string(array.type.value_type) and not array.null_count \
            and not array.dictionary.null_count:
        # a dictionary as Parquet stores text (load_arrow): one Python string per entry, rows by index
        values = np.array([v.strip() for v in array.dictionary.to_pylist()] or [""], dtype=object)
        return Column(name, text=values[arrow_numpy(array.indices)])
    if pa.types.is_dictionary(array.type):
        array = array.cast(array.type.value_type)
    if _is_string(array.type):
        import pyarrow.compute as pc  # start-up: pyarrow.compute (~30 ms) only for other text columns

        # one Python string per distinct value (station, pass and kind repeat): ~8 bytes a row;
        # without nulls no fill value: a Python scalar given to Arrow makes it import pandas (~0.15 s)
        strings = array.cast(pa.string())
        encoded = strings.dictionary_encode() if not strings.null_count else \
            pc.dictionary_encode(pc.fill_null(strings, ""))
        values = np.array([v.strip() for v in encoded.dictionary.to_pylist()] or [""], dtype=object)
        return Column(name, text=values[arrow_numpy(encoded.indices)])
    return Column(name, array=array)


def _cast_to_numpy(array, kind) -> np.ndarray:
    import pyarrow.compute as pc  # start-up: as in _arrow_column

    return arrow_numpy(pc.cast(array, kind))


def _wrong_type(table: SourceTable, column: Column, expected: str) -> InputError:
    return InputError(WRONG_TYPE, file=table.source, row=int(table.rows[0]) if len(table) else None,
                      column=column.name, found=column.type_name, expected=expected)


def column_times(table: SourceTable, column: Column, problems: Problems, index=None) -> np.ndarray:
    """UTC times as ``datetime64[ns]`` (NaT where unparseable, reported to ``problems``).

    ``index`` maps the problems' positions to the table's rows (default: one to one).
    """
    if column.text is not None:
        # a pass file's times have one layout: read without a parse per cell when every one is valid
        values = _fixed_iso_times(column.text)
        if values is None:
            values = _iso_times(column.text)
    elif pa.types.is_timestamp(column.array.type):
        # Out-of-range stamps (year 3000 in ms or us) become NaT and are reported by row; a failing
        # cast is not used for this (its exception left Arrow aborting at exit in ~7 % of runs).
        unit = column.array.type.unit
        ticks = arrow_numpy(column.array) if not column.array.null_count else \
            _cast_to_numpy(column.array, pa.int64())
        ticks = np.where(np.isnan(ticks.astype(float)), 0, ticks).astype(np.int64) if ticks.dtype != np.int64 \
            else ticks
        lo = np.datetime64(f"{FIRST_YEAR}-01-01", unit).astype(np.int64)
        hi = np.datetime64(f"{LAST_YEAR + 1}-01-01", unit).astype(np.int64)
        outside = (ticks < lo) | (ticks >= hi)
        values = np.where(outside, np.int64(0), ticks).astype(f"datetime64[{unit}]").astype("datetime64[ns]")
        values[outside] = np.datetime64("NaT")
        if column.array.null_count:     # (is_null's numpy conversion imports pandas: only when needed)
            values[column.array.is_null().to_numpy(zero_copy_only=False)] = np.datetime64("NaT")
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


def _iso_times(cells) -> np.ndarray:
    """ISO 8601 text of any layout pandas reads as ``datetime64[ns]``, NaT where unparseable."""
    import pandas as pd  # start-up: pandas (~0.15 s) only for times written as text (CSV)

    text = pd.Series(cells, dtype=object)
    # beyond 1678-2261 a nanosecond timestamp wraps or raises: such rows are unparseable times
    if not _years_in_range(cells):
        year = pd.to_numeric(text.astype(str).str.extract(r"^\s*([+-]?\d+)-", expand=False),
                             errors="coerce")
        text = text.where(~((year < FIRST_YEAR) | (year > LAST_YEAR)), "")
    try:
        parsed = pd.to_datetime(text, utc=True, format="ISO8601", errors="coerce")
    except (ValueError, OverflowError):   # OutOfBoundsDatetime despite errors="coerce"
        parsed = pd.Series([_one_time(t) for t in text], dtype="datetime64[ns, UTC]")
    return parsed.dt.tz_localize(None).dt.as_unit("ns").to_numpy()


#: Suffixes :func:`_fixed_iso_times` reads as UTC (pandas' ISO 8601 parser with ``utc=True`` does).
_UTC_SUFFIXES = ("Z", "+00:00", "")


def _fixed_iso_times(text) -> np.ndarray | None:
    """``datetime64[ns]`` of ISO 8601 UTC cells that all have one fixed layout,
    ``YYYY-MM-DDTHH:MM:SS[.f]`` with 1-9 fractional digits (or none) and ``Z``, ``+00:00`` or no
    zone, every field in range (Gregorian calendar, second 0-59, years FIRST_YEAR..LAST_YEAR);
    None when any cell is otherwise (the general parser then reads them all and reports the bad
    rows). The same instants as ``pandas.to_datetime(..., utc=True, format="ISO8601")``: ISO 8601
    calendar date and time of day (ISO 8601-1:2019, 5.2.2 and 5.3.1.4), days counted by numpy's
    proleptic Gregorian months. Read from one byte matrix instead of a Python parse per cell."""
    n = len(text)
    if not n or type(text[0]) is not str:
        return None
    width = len(text[0])
    suffix = next(s for s in _UTC_SUFFIXES if text[0].endswith(s))
    body = width - len(suffix)
    digits = body - 20 if body > 20 else 0
    if not (body == 19 or 1 <= digits <= 9):
        return None
    try:
        data = "".join(text).encode("ascii")
        lengths = np.fromiter(map(len, text), np.int64, n)
    except (TypeError, UnicodeEncodeError):
        return None
    if len(data) != n * width or (lengths != width).any():
        return None
    cells = np.frombuffer(data, np.uint8).reshape(n, width)
    layout = "0000-00-00T00:00:00" + ("." + "0" * digits if digits else "") + suffix
    number = np.array([c == "0" for c in layout])
    if ((cells[:, number] - 48) > 9).any() or \
            (cells[:, ~number] != np.frombuffer(layout.encode(), np.uint8)[~number]).any():
        return None
    d = (cells[:, number] - 48).astype(np.int64)     # the digits, most significant first per field

    def field(start, stop):
        return d[:, start:stop] @ (10 ** np.arange(stop - start - 1, -1, -1, dtype=np.int64))

    year, month, day = field(0, 4), field(4, 6), field(6, 8)
    hour, minute, second = field(8, 10), field(10, 12), field(12, 14)
    if not ((year >= FIRST_YEAR) & (year <= LAST_YEAR) & (month >= 1) & (month <= 12) & (day >= 1)
            & (hour <= 23) & (minute <= 59) & (second <= 59)).all():
        return None
    months = (year - 1970) * 12 + month - 1
    first = months.astype("datetime64[M]").astype("datetime64[D]").astype(np.int64)
    length = (months + 1).astype("datetime64[M]").astype("datetime64[D]").astype(np.int64) - first
    if (day > length).any():
        return None
    ns = (((first + day - 1) * 24 + hour) * 60 + minute) * 60 + second
    ns *= 1_000_000_000
    if digits:
        ns += field(14, 14 + digits) * 10 ** (9 - digits)
    return ns.astype("datetime64[ns]")


def _years_in_range(text) -> bool:
    """True when every cell starts with a four-digit year and a dash (``YYYY-``, what the year
    test of :func:`column_times` reads there) inside FIRST_YEAR..LAST_YEAR: the test can be skipped.
    One look per distinct first five characters (a pass file has one or two)."""
    heads = {cell[:5] if type(cell) is str else None for cell in text}
    return all(head is not None and len(head) == 5 and head[4] == "-" and head[:4].isascii() and head[:4].isdigit()
               and FIRST_YEAR <= int(head[:4]) <= LAST_YEAR for head in heads)


def _one_time(text):
    import pandas as pd  # start-up: as in column_times

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
        values = _plain_numbers(column.strings)
        if values is not None:
            return values, np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        try:   # every cell a number (the common case): numpy calls float() on each, in C
            return (column.text.astype(np.float64), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
        except (ValueError, TypeError):
            pass
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
    if not arr.null_count:              # no fill value, no null mask: both make Arrow import pandas
        values = arrow_numpy(arr) if pa.types.is_float64(arr.type) else _cast_to_numpy(arr, pa.float64())
        return values.astype(np.float64), np.zeros(len(values), dtype=bool), np.zeros(len(values), dtype=bool)
    import pyarrow.compute as pc  # start-up: as in _arrow_column

    missing = arr.is_null().to_numpy(zero_copy_only=False)
    values = pc.fill_null(arr.cast(pa.float64()), math.nan).to_numpy(zero_copy_only=False)
    return values.astype(np.float64), missing, np.zeros(len(values), dtype=bool)


#: Bytes of a decimal number literal without spaces, underscores, ``inf`` or ``nan``.
_NUMBER_BYTES = np.zeros(256, dtype=bool)
_NUMBER_BYTES[np.frombuffer(b"0123456789.eE+-", np.uint8)] = True


def _plain_numbers(strings) -> np.ndarray | None:
    """float64 of Arrow string cells that are all non-empty and made only of :data:`_NUMBER_BYTES`,
    by Arrow's cast (correctly rounded, like ``float()``, and on that alphabet accepting only what
    ``float()`` accepts: ``tests/io/test_plain_numbers.py``); None otherwise (``float()`` per cell
    then decides, and reports the wrong cells)."""
    if strings is None or strings.null_count or not pa.types.is_string(strings.type) or not len(strings):
        return None
    offsets = np.frombuffer(strings.buffers()[1], np.int32, len(strings) + 1, strings.offset * 4)
    if (offsets[1:] == offsets[:-1]).any():
        return None
    data = np.frombuffer(strings.buffers()[2], np.uint8)[offsets[0]:offsets[-1]]
    if not _NUMBER_BYTES[data].all():
        return None
    try:
        return arrow_numpy(_safe_cast(strings, pa.float64()))
    except (pa.ArrowInvalid, ValueError):
        return None


def _safe_cast(array, target):
    """``pyarrow.compute.cast(array, target)`` (a safe cast) by the same call of Arrow's compute
    functions, without importing ``pyarrow.compute``: its module builds Python wrappers and
    docstrings for every compute function when imported (~28 ms of CPU a process), and a plain
    CSV pass file needs only this cast."""
    try:
        from pyarrow._compute import CastOptions, call_function
    except ImportError:                    # another layout of pyarrow: its public function
        import pyarrow.compute as pc

        return pc.cast(array, target)
    return call_function("cast", [array], CastOptions.safe(target))


def column_strings(table: SourceTable, column: Column) -> np.ndarray:
    """Text cells ('' where empty); integer columns (station numbers) become their digits."""
    if column.text is not None:
        return column.text
    if pa.types.is_integer(column.array.type):
        return np.array(["" if v is None else str(v) for v in column.array.to_pylist()], dtype=object)
    raise _wrong_type(table, column, "a text column")
