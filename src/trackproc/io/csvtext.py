"""CSV text: cells by column with each data row's line number, whole or streamed chunk by chunk.

Row numbers are the physical lines an editor shows (the header on line 1 makes the first data row
row 2); blank lines and ``#`` comment lines are skipped but counted. A streamed file is cut only
after a newline outside quotes, so a chunk holds whole records and the same numbers as a whole read.

A little over 400 lines: the exact line-by-line reader and Arrow's fast reader of plain lines
(with the test of what is plain) are kept side by side, as each must give the other's cells.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import sys
from dataclasses import dataclass, field
from typing import Iterable, Iterator

import numpy as np
import pyarrow as pa

from trackproc.errors import InputError
from trackproc.io.validate import check_input_rows

#: Prefix of the comment line that carries the trackproc metadata in a CSV.
CSV_META_PREFIX = "trackproc:"
#: Rows of a table handled at a time when streaming (``TRACKPROC_CHUNK_ROWS`` overrides it, e.g.
#: to test that the chunk boundaries change nothing); a CSV chunk is about 48 bytes a row.
DEFAULT_CHUNK_ROWS = 100_000
CSV_BYTES_PER_ROW = 48


def chunk_rows() -> int:
    """Rows handled at a time by the streaming readers and writers."""
    try:
        return max(1, int(os.environ.get("TRACKPROC_CHUNK_ROWS", "") or DEFAULT_CHUNK_ROWS))
    except ValueError:
        return DEFAULT_CHUNK_ROWS


#: Width beyond which a metadata value is spread over lines (one key or item a line).
META_WIDTH = 96


def csv_metadata_line(meta_text: str) -> str:
    """The ``# trackproc: {`` ... ``# }`` comment block that opens a CSV output (its JSON spread
    over lines of about :data:`META_WIDTH` characters, one key a line, so that a person reads
    it; :func:`parse_csv_metadata` reads it back, and pandas ``comment="#"`` skips it), or nothing
    when the run asked for plain CSV (``--no-metadata`` / ``TRACKPROC_CSV_METADATA=0``:
    spreadsheets and pandas read it without options; the metadata then lives only in
    Parquet/Arrow outputs)."""
    if os.environ.get("TRACKPROC_CSV_METADATA", "1").strip().lower() in ("0", "false", "no", "off"):
        return ""
    lines = _json_lines(json.loads(meta_text), "", "")
    return f"# {CSV_META_PREFIX} " + "\n# ".join(lines) + "\n"


def _json_lines(value, key: str, indent: str) -> list[str]:
    """``key`` + ``value`` as JSON lines: on one line when it fits in :data:`META_WIDTH`, else
    an object one member a line (a list one item a line), indented by two spaces a level."""
    flat = key + json.dumps(value, ensure_ascii=False, separators=(", ", ": "))
    if len(indent) + len(flat) <= META_WIDTH or not value or not isinstance(value, (dict, list)):
        return [indent + flat]
    opening, closing = ("{", "}") if isinstance(value, dict) else ("[", "]")
    if isinstance(value, list) and not any(isinstance(v, (dict, list)) for v in value):
        return _packed(value, key, indent)      # numbers and words: as many a line as fit
    items = list(value.items()) if isinstance(value, dict) else [(None, v) for v in value]
    out = [indent + key + opening]
    for i, (k, v) in enumerate(items):
        member = _json_lines(v, "" if k is None else json.dumps(str(k), ensure_ascii=False) + ": ", indent + "  ")
        if i < len(items) - 1:
            member[-1] += ","
        out.extend(member)
    out.append(indent + closing)
    return out


def _packed(values: list, key: str, indent: str) -> list[str]:
    """A list of scalars over as few lines of :data:`META_WIDTH` as its items allow, the first
    items on the key's line and the closing bracket after the last."""
    out, line = [], indent + key + "["
    for i, v in enumerate(values):
        item = json.dumps(v, ensure_ascii=False) + ("," if i < len(values) - 1 else "]")
        if len(line) + len(item) > META_WIDTH and line.strip() not in ("", key.strip() + "["):
            out.append(line.rstrip())
            line = indent + "  "
        line += item + " "
    out.append(line.rstrip())
    return out


def parse_csv_metadata(comments: Iterable[str]) -> dict:
    """The trackproc metadata of a CSV from its comment lines (``#`` removed): the block
    :func:`csv_metadata_line` writes, or the one-line ``trackproc: {...}`` of earlier versions;
    {} when there is none or it is not valid JSON."""
    text = None
    for comment in comments:
        comment = comment.strip()
        if text is None:
            if comment.startswith(CSV_META_PREFIX):
                text = comment[len(CSV_META_PREFIX):]
            else:
                continue
        else:
            text += "\n" + comment
        if text.rstrip().endswith("}"):
            try:
                meta = json.loads(text)
            except (ValueError, RecursionError):
                continue
            return meta if isinstance(meta, dict) else {}
    return {}


@dataclass
class TextTable:
    """A CSV read as text: stripped cells per column, the source line of each data row."""

    columns: list[str]                       # header names as written (stripped)
    cells: dict[str, np.ndarray]             # header name -> object array of str ('' = empty)
    rows: np.ndarray                         # 1-based physical line of each data row
    header_row: int
    comments: list[str] = field(default_factory=list)   # '#' lines, without the '#'
    arrow: dict | None = None    # header name -> the same cells as an Arrow string array (Arrow's reader)


def decode_text(data: bytes, source: str, *, line0: int = 0, encoding: str = "utf-8-sig") -> str:
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        line = line0 + data[: exc.start].count(b"\n") + 1
        raise InputError("not UTF-8 text", file=source, row=line,
                         found=data[exc.start: exc.start + 8],
                         expected="a CSV file (UTF-8), Parquet, Arrow IPC or CCSDS TDM") from None


#: A whole file smaller than this is read by Arrow's CSV reader only when that reader is imported
#: already (a batch: its ingest step imports it once for its many pass files): for one small
#: file (a stations table, one pass), importing Arrow's CSV reader and compute (~60 ms of CPU)
#: costs more than the reader saves (~0.4 ms per 500 lines).
ARROW_MIN_BYTES = 1 << 21


def parse_text_table(data: bytes, source: str, *, header: list[str] | None = None) -> TextTable:
    """Split a comma-separated text into columns, keeping each data row's line number.

    Blank lines and lines starting with ``#`` are skipped (their line numbers still count).
    ``header`` given: every non-comment line is data; otherwise the first one is the header.
    """
    check_input_rows(data.count(b"\n") - 1, file=source)
    text = decode_text(data, source)
    if header is None and (len(data) >= ARROW_MIN_BYTES or "pyarrow.csv" in sys.modules):
        table = _plain_table(data, text, source)
        if table is not None:
            return table
    records, starts, comments, _ = _records(text, source, 0)
    header_row = 0
    if header is None:
        if not records:
            raise _no_header(source)
        header, header_row = records.pop(0), starts.pop(0)
        _check_header(header, source, header_row)
    return _text_table(header, records, starts, header_row, comments, source)


def iter_text_tables(blocks: Iterable[bytes], source: str) -> Iterator[TextTable]:
    """A CSV with a header line, streamed: one :class:`TextTable` per chunk of about
    :func:`chunk_rows` rows, the same header and whole-file row numbers in each. The comments
    seen up to the first data rows come with the first table (the metadata line is the first line
    of a trackproc CSV). At least one table is yielded when the file has a header."""
    header, header_row, comments = None, 0, []
    lines = newlines = 0
    limit_bytes = chunk_rows() * CSV_BYTES_PER_ROW
    for first, piece in _whole_records(blocks, limit_bytes):
        text = decode_text(piece, source, line0=newlines, encoding="utf-8-sig" if first else "utf-8")
        newlines += piece.count(b"\n")
        check_input_rows(newlines - 1, file=source)
        table = _plain_chunk(piece, header, lines) if header is not None else None
        if table is not None:   # the common case, parsed by Arrow's CSV reader
            lines += len(table.rows)
            table.header_row, table.comments = header_row, comments
            yield table
            comments = []
            continue
        records, starts, found, count = _records(text, source, lines)
        lines += count
        comments.extend(found)
        if header is None:
            if not records:
                continue
            header, header_row = records.pop(0), starts.pop(0)
            _check_header(header, source, header_row)
        yield _text_table(header, records, starts, header_row, comments, source)
        comments = []
    if header is None:
        raise _no_header(source)


#: What only the line-by-line reader handles exactly: quotes, comments, blank or comma-only lines,
#: line breaks other than \n (str.splitlines counts them), NUL, a last line without its newline.
_NOT_PLAIN = re.compile(rb'["#\r\x00\x0b\x0c\x1c-\x1e]|\xc2\x85|\xe2\x80[\xa8\xa9]|(?:^|\n)[ \t,]*\n')


#: Bytes and sequences any one of which lets :data:`_NOT_PLAIN` match, grouped by what finds them fast (the
#: regular expression takes ~25 ns a byte, 0.8 ms for a pass file): single bytes (``memchr``); the
#: sequences beyond ASCII; a line starting with a space or tab (searched for only when that byte
#: occurs); a line starting with a newline or comma (the bytes after every newline, at once).
_HINT_BYTES = (b'"', b"#", b"\r", b"\x00", b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e")
_HINT_NON_ASCII = (b"\xc2\x85", b"\xe2\x80\xa8", b"\xe2\x80\xa9")


def _is_plain(piece: bytes) -> bool:
    """``not _NOT_PLAIN.search(piece)``, faster on the common plain text: the regular expression
    only when :func:`_has_hint` finds what it could match in ``piece`` (a two-byte substring search takes
    ~1 ns a byte, as long as the regular expression's pass over a pass file's lines; a one-byte one
    is a ``memchr``)."""
    if piece[:1] in (b"\n", b" ", b"\t", b",") or _has_hint(piece):
        return not _NOT_PLAIN.search(piece)
    return True


def _has_hint(piece: bytes) -> bool:
    """Whether ``piece`` holds a byte or sequence that :data:`_NOT_PLAIN` matches: one of
    :data:`_HINT_BYTES` or :data:`_HINT_NON_ASCII`, or a newline followed by a newline, space,
    tab or comma."""
    if any(hint in piece for hint in _HINT_BYTES):
        return True
    if not piece.isascii() and any(hint in piece for hint in _HINT_NON_ASCII):
        return True
    if (b" " in piece and b"\n " in piece) or (b"\t" in piece and b"\n\t" in piece):
        return True
    if len(piece) < 256:
        return b"\n\n" in piece or b"\n," in piece
    data = np.frombuffer(piece, dtype=np.uint8)
    after_newline = data[1:][data[:-1] == 10]
    return bool(((after_newline == 10) | (after_newline == 44)).any())


def _plain_chunk(piece: bytes, header: list[str], line0: int) -> TextTable | None:
    """A chunk of plain lines (one record each) parsed by Arrow's CSV reader, ~5 times faster than
    the csv module; None when the chunk needs the exact line-by-line reader (or has a wrong number
    of fields, which that reader reports with its row)."""
    if not piece.endswith(b"\n") or not _is_plain(piece):
        return None
    import pyarrow.csv as pacsv  # start-up: Arrow's CSV reader (~10 ms) only for large plain files

    try:
        table = pacsv.read_csv(
            pa.BufferReader(piece),
            read_options=pacsv.ReadOptions(column_names=header, block_size=len(piece) + 1, use_threads=False),
            parse_options=pacsv.ParseOptions(quote_char=False),
            convert_options=pacsv.ConvertOptions(column_types={name: pa.string() for name in header},
                                                 strings_can_be_null=False))
    except (pa.ArrowException, ValueError):
        return None
    n = table.num_rows
    if n != piece.count(b"\n"):
        return None
    limit = csv.field_size_limit()   # a cell the csv module refuses: its error, with the row
    if len(piece) > limit and any((_compute().max(_compute().binary_length(table.column(name))).as_py() or 0)
                                  > limit for name in header):
        return None
    # the line-by-line reader strips every cell (str.strip: any Unicode white space); nothing to
    # strip in ASCII text without a space or a tab
    bare = piece.isascii() and b" " not in piece and b"\t" not in piece
    arrow = {name: (table.column(name) if bare else _compute().utf8_trim_whitespace(table.column(name)))
             .combine_chunks() for name in header}
    # to_pylist, not to_numpy: Arrow's to_numpy of a string array imports pandas (~0.15 s a process)
    cells = {name: np.array(array.to_pylist(), dtype=object) for name, array in arrow.items()}
    return TextTable(list(header), cells, np.arange(line0 + 1, line0 + n + 1, dtype=np.int64), 0, arrow=arrow)


def _compute():
    """``pyarrow.compute``, imported where a chunk needs it (~28 ms of CPU a process for its
    wrappers): a plain ASCII pass file without spaces needs none of its functions."""
    import pyarrow.compute as pc

    return pc


def _plain_table(data: bytes, text: str, source: str) -> TextTable | None:
    """A whole file whose first line is its header and whose data lines are plain
    (:func:`_plain_chunk`): the header by the line-by-line reader, the rest by Arrow's (a pass file
    of 500 lines in a third of the time); None for any other file."""
    end = data.find(b"\n")
    if end < 0 or not _is_plain(data[:end + 1]) or not data[:end].strip(b" \t,\xef\xbb\xbf"):
        return None
    records, starts, _, _ = _records(text[:text.find("\n")], source, 0)
    if len(records) != 1 or starts != [1]:
        return None
    _check_header(records[0], source, 1)
    table = _plain_chunk(data[end + 1:], records[0], 1) if end + 1 < len(data) else None
    if table is not None:
        table.header_row = 1
    return table


def _no_header(source: str) -> InputError:
    return InputError("empty input", file=source, row=1, found="no header line",
                      expected="a header line naming the columns")


def _records(text: str, source: str, line0: int) -> tuple[list, list, list, int]:
    """(records of stripped cells, 1-based line of each, comments, number of lines) of a text whose
    first line is line ``line0 + 1``; blank and comment lines give no record."""
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
            starts.append(line0 + start)
    except csv.Error as exc:   # a cell beyond csv.field_size_limit (128 kB), a NUL byte
        raise InputError(f"unreadable CSV ({exc})", file=source, row=line0 + last + 1,
                         expected=f"CSV cells of at most {csv.field_size_limit()} characters, no NUL") from None
    return records, starts, comments, len(lines)


def _text_table(header, records, starts, header_row, comments, source) -> TextTable:
    width = len(header)
    for record, row in zip(records, starts):
        if len(record) != width:
            raise InputError("wrong number of fields", file=source, row=row,
                             found=f"{len(record)} fields",
                             expected=f"{width} fields as in the header ({', '.join(header)})")
    cells = {name: np.array([r[j] for r in records], dtype=object) for j, name in enumerate(header)}
    return TextTable(list(header), cells, np.array(starts, dtype=np.int64), header_row, comments)


def _whole_records(blocks: Iterable[bytes], size: int) -> Iterator[tuple[bool, bytes]]:
    """Byte pieces of about ``size`` (the first one smaller: the header) that end after a newline
    outside double quotes (a quoted cell may hold a newline); ``(is_first, piece)``. The last
    piece is the rest of the input."""
    buffer = bytearray()
    first = True
    target = min(size, 1 << 16)
    retry_at = target
    for block in blocks:
        buffer += block
        while len(buffer) >= retry_at:
            cut = _balanced_cut(buffer, target)
            if cut <= 0:        # one open quote: wait for twice the data before scanning again
                retry_at = 2 * len(buffer)
                break
            yield first, bytes(buffer[:cut])
            del buffer[:cut]
            first, target = False, size
            retry_at = target
    if buffer or first:
        yield first, bytes(buffer)


def _balanced_cut(buffer: bytearray, size: int) -> int:
    """Length of a prefix ending with a newline and holding an even number of quotes outside
    comment lines (comment lines are blanked before the CSV is parsed): the longest one of at most
    ``size`` bytes, else the shortest longer one; 0 when there is none."""
    if b"#" in buffer:
        return _balanced_cut_by_line(buffer, size)
    limit = min(size, len(buffer))
    pos = buffer.rfind(b"\n", 0, limit)
    quotes = buffer.count(b'"', 0, pos + 1)
    while pos >= 0:                          # back from the size
        if quotes % 2 == 0:
            return pos + 1
        before = buffer.rfind(b"\n", 0, pos)
        quotes -= buffer.count(b'"', before + 1, pos + 1)
        pos = before
    pos = buffer.find(b"\n", limit)
    quotes = buffer.count(b'"', 0, pos + 1) if pos >= 0 else 0
    while pos >= 0:                          # on from the size
        if quotes % 2 == 0:
            return pos + 1
        after = buffer.find(b"\n", pos + 1)
        if after < 0:
            break
        quotes += buffer.count(b'"', pos + 1, after + 1)
        pos = after
    return 0


def _balanced_cut_by_line(buffer: bytearray, size: int) -> int:
    best, parity, position = 0, 0, 0
    for line in bytes(buffer).split(b"\n")[:-1]:     # the last piece has no newline yet
        if not line.lstrip(b" \t\r\x0b\x0c").startswith(b"#"):
            parity ^= line.count(b'"') & 1
        position += len(line) + 1
        if not parity:
            if position > size and best:
                return best
            best = position
            if position > size:
                return best
    return best


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
