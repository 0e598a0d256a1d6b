"""One-row-per-time tables (``trackproc accuracy``'s sigma table, its correlation table) as
Parquet, an Arrow IPC stream, CSV or JSON, with the run's metadata."""

from __future__ import annotations

import csv
import io

import numpy as np
import pandas as pd
import pyarrow as pa

from trackproc.io.jsonutil import dumps, json_ready
from trackproc.io.passfile import iso_times, meta_json
from trackproc.io.tables import arrow_table_bytes
from trackproc.io.tabular import META_KEY, csv_metadata_line

FORMATS = ("parquet", "arrow", "csv", "json")


def table_bytes(frame: pd.DataFrame, meta: dict, fmt: str) -> bytes:
    """The one-row-per-time table as ``parquet``, ``arrow`` (IPC stream), ``csv`` or ``json``.

    Parquet/Arrow carry ``meta`` under the ``trackproc`` key of the schema metadata, CSV on a
    ``# trackproc: {`` comment block (as pass files do); JSON is
    ``{"columns": [...], "metadata": {...}, "rows": [{column: value}, ...]}`` with ISO 8601
    times and null for NaN.
    """
    fmt = getattr(fmt, "value", fmt)
    meta_text = meta_json(json_ready(meta))
    if fmt == "json":
        cols = {c: (list(iso_times(frame[c])) if c.startswith("time") else frame[c].to_numpy()) for c in frame.columns}
        rows = [{c: cols[c][i] for c in frame.columns} for i in range(len(frame))]
        return dumps({"columns": list(frame.columns), "metadata": meta, "rows": rows}).encode("utf-8")
    if fmt == "csv":
        out = io.StringIO()
        out.write(csv_metadata_line(meta_text))
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(list(frame.columns))
        cells = [iso_times(frame[c]) if c.startswith("time") else frame[c].to_numpy() for c in frame.columns]
        for row in zip(*cells):
            writer.writerow([v if isinstance(v, str) else repr(float(v)) for v in row])
        return out.getvalue().encode("utf-8")
    arrays, fields = [], []
    for c in frame.columns:
        if c.startswith("time"):
            ns = frame[c].dt.tz_convert("UTC").dt.tz_localize(None).dt.as_unit("ns").to_numpy()
            arrays.append(pa.array(ns, pa.timestamp("ns")).cast(pa.timestamp("ns", tz="UTC")))
            fields.append(pa.field(c, pa.timestamp("ns", tz="UTC"), nullable=False))
        else:
            arrays.append(pa.array(frame[c].to_numpy(dtype=np.float64), pa.float64()))
            fields.append(pa.field(c, pa.float64()))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata={META_KEY: meta_text.encode()}))
    if fmt not in ("parquet", "arrow"):
        raise ValueError(f"unknown format {fmt!r}; expected one of {FORMATS}")
    return arrow_table_bytes(table, fmt)
