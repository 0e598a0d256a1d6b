"""The canonical pass table written batch by batch (``ingest`` of large inputs): the same bytes as
:func:`trackproc.io.passfile.write_pass_table` of the whole table, without holding it whole."""

from __future__ import annotations

import io
import json

import pyarrow as pa
import pyarrow.parquet as pq

from trackproc.io.atomic import open_atomic
from trackproc.io.columns import META_KEY
from trackproc.io.csvtext import csv_metadata_line
from trackproc.io.passfile import FORMATS, _write_csv_rows, meta_json


def canonical_schema(meta: dict) -> pa.Schema:
    """The schema of a canonical pass table (:data:`COLUMNS`) with ``meta`` under ``trackproc``."""
    return pa.schema([pa.field("time", pa.timestamp("ns", tz="UTC"), nullable=False),
                      pa.field("station", pa.string(), nullable=False),
                      pa.field("pass_id", pa.string(), nullable=False),
                      pa.field("kind", pa.string(), nullable=False),
                      pa.field("value", pa.float64(), nullable=False),
                      pa.field("sigma", pa.float64(), nullable=False)],
                     metadata={META_KEY: meta_json(meta).encode()})


def write_pass_batches(batches, schema: pa.Schema, path: str, fmt: str = "parquet") -> None:
    """Write a canonical table given as record batches (``schema``: :func:`canonical_schema`)
    atomically to ``path`` (``-`` = stdout), one batch at a time: the same bytes as
    :func:`write_pass_table` of the whole table when each batch is a Parquet row group
    (:data:`~trackproc.pipeline.ingest_samples.SLICE_ROWS` rows)."""
    fmt = getattr(fmt, "value", fmt)
    if fmt not in FORMATS:
        raise ValueError(f"unknown pass-table format {fmt!r}; expected one of {FORMATS}")
    with open_atomic(path) as handle:
        if fmt == "csv":
            meta = json.loads(schema.metadata[META_KEY])
            handle.write(csv_metadata_line(meta_json(meta)).encode("utf-8"))
            header = True
            for batch in batches:
                out = io.StringIO()
                _write_csv_rows(out, batch.to_pandas(), header=header)
                handle.write(out.getvalue().encode("utf-8"))
                header = False
            if header:
                out = io.StringIO()
                _write_csv_rows(out, schema.empty_table().to_pandas(), header=True)
                handle.write(out.getvalue().encode("utf-8"))
            return
        sink = _Sink(handle)
        if fmt == "parquet":
            writer = pq.ParquetWriter(sink, schema, compression="zstd", version="2.6")   # nanosecond times (io/tables.py)
            empty = True
            for batch in batches:
                writer.write_table(pa.Table.from_batches([batch], schema=schema))
                empty = False
            if empty:
                writer.write_table(schema.empty_table())
            writer.close()
        else:
            with pa.ipc.new_stream(sink, schema) as writer:
                for batch in batches:
                    writer.write_batch(batch)


class _Sink:
    """A write-only file for Arrow's writers over an atomic output or stdout (which cannot tell)."""

    def __init__(self, handle):
        self.handle, self.position, self.closed = handle, 0, False

    def write(self, data) -> int:
        n = len(memoryview(data).cast("B"))
        self.handle.write(data)
        self.position += n
        return n

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        self.handle.flush()

    def close(self) -> None:
        self.closed = True

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False
