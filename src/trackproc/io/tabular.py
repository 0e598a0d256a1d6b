"""Readers for tabular measurement files: CSV, Parquet and Arrow IPC, in wide or long layout.

Every reader returns :class:`trackproc.io.raw.RawMeasurements` (long form, SI units); the
validation rules live in :mod:`trackproc.pipeline.ingest`. :func:`iter_raw` streams a CSV or
Parquet/Arrow table chunk by chunk (bounded memory); :func:`read_raw` reads an input whole. The
pieces: :mod:`~trackproc.io.csvtext` (CSV text), :mod:`~trackproc.io.columns` (columns of any
container), :mod:`~trackproc.io.layouts` (wide and long), :mod:`~trackproc.io.problems` (invalid rows).

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

import os
from pathlib import Path
from typing import Iterator

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, iter_input_blocks, max_input_bytes, read_input_bytes
from trackproc.io.columns import (META_KEY, Column, SourceTable, column_numbers, column_strings,  # noqa: F401
                                  column_times, iter_source_tables, load_arrow, sniff_container, source_table,
                                  table_meta)
from trackproc.io.csvtext import (CSV_META_PREFIX, TextTable, csv_metadata_line, decode_text,  # noqa: F401
                                  parse_text_table)
from trackproc.io.layouts import (DEG, KIND_SPELLINGS, UNIT_SPELLINGS, is_long_layout, layout_reader,  # noqa: F401
                                  read_long, read_wide)
from trackproc.io.problems import (NONFINITE_SIGMA, NONFINITE_VALUE, TIME_EXPECTED, UNKNOWN_KIND,  # noqa: F401
                                   UNPARSEABLE_TIME, WRONG_TYPE, Problems, add_counts)
from trackproc.io.raw import RawMeasurements
from trackproc.io import crd, doptrack, orekit_aer



LAYOUTS = ("auto", "wide", "long", "doptrack", "aer", "tdm", "crd")


def detect_layout(data: bytes, name: str) -> str:
    """Guess the layout of an input from its first bytes and its name (``auto``)."""
    if sniff_container(data) != "text":
        return "table"
    head = data[:4096].decode("utf-8-sig", errors="replace").lstrip()
    if head.startswith("CCSDS_TDM_VERS"):
        return "tdm"
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
             tdm_two_way_range: str = "one-way-equivalent", data: bytes | None = None) -> RawMeasurements:
    """Read one input file (or ``-`` for stdin) into raw samples (``data``: its bytes, already read).

    ``layout``: one of :data:`LAYOUTS`; ``sidecar``: DopTrack YAML (overrides the lookup next
    to the data file); ``carrier_hz``: nominal carrier, Hz, used by the DopTrack and TDM readers
    to turn received frequencies into Doppler shifts; ``tdm_two_way_range``: how a TDM writes
    two-way RANGE (``one-way-equivalent`` or ``round-trip``, see :mod:`trackproc.io.tdm`).
    """
    source = "<stdin>" if is_stdio(path) else str(path)
    data = read_input_bytes(path) if data is None else data
    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="a CSV, Parquet, Arrow IPC, DopTrack, Orekit .aer, CCSDS TDM or ILRS CRD file")
    if layout == "auto":
        layout = detect_layout(data, "" if is_stdio(path) else Path(path).name)
    if layout == "doptrack":
        data_path = None if is_stdio(path) else Path(path)
        return doptrack.read_doptrack(data, source, data_path=data_path, sidecar=sidecar,
                             carrier_hz=carrier_hz, drop_invalid=drop_invalid)
    if layout == "crd":
        return crd.read_crd(data, source, drop_invalid=drop_invalid)
    if layout == "aer":
        return orekit_aer.read_aer(data, source, drop_invalid=drop_invalid)
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


def iter_raw(path: str, layout: str = "auto", *, sidecar: str | None = None,
             carrier_hz: float | None = None, drop_invalid: bool = False,
             tdm_two_way_range: str = "one-way-equivalent") -> Iterator[RawMeasurements]:
    """:func:`read_raw` chunk by chunk: a CSV or Parquet/Arrow table in chunks of
    :func:`~trackproc.io.csvtext.chunk_rows` rows (bounded memory, the same samples, row numbers and
    first error as a whole read); DopTrack, Orekit .aer, TDM and CRD inputs (small files) in one chunk."""
    source = "<stdin>" if is_stdio(path) else str(path)
    blocks = iter_input_blocks(path)
    head = b""
    for block in blocks:            # up to the first non-blank bytes: enough to detect the layout
        head += block
        if head.strip() and len(head) >= 4096:
            break
    if not head.strip():
        raise InputError("empty input", file=source, row=1, found="no data",
                         expected="a CSV, Parquet, Arrow IPC, DopTrack, Orekit .aer, CCSDS TDM or ILRS CRD file")
    name = "" if is_stdio(path) else Path(path).name
    if layout == "auto":
        layout = detect_layout(head, name)
    if layout in ("doptrack", "aer", "tdm", "crd"):
        yield read_raw(path, layout, sidecar=sidecar, carrier_hz=carrier_hz, drop_invalid=drop_invalid,
                       tdm_two_way_range=tdm_two_way_range, data=head + b"".join(blocks))
        return
    regular = not is_stdio(path) and sniff_container(head) != "text" and os.path.isfile(path)
    if regular:   # Parquet and Arrow read the file directly, one row group at a time
        blocks.close()
        limit = max_input_bytes()
        if os.path.getsize(path) > limit:
            raise InputError(f"input larger than the limit of {limit / (1 << 20):g} MiB", file=source,
                             expected="a smaller input, or a larger TRACKPROC_MAX_INPUT_MB")
    tables = iter_source_tables(_chain(head, blocks), source, path=str(path) if regular else None)
    first = next(tables)
    reader = layout_reader(first, layout, drop_invalid)
    yield reader.read(first)
    for table in tables:
        yield reader.read(table)
    reader.finish()


def _chain(head: bytes, blocks) -> Iterator[bytes]:
    yield head
    yield from blocks
