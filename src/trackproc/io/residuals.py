"""Residual tables of an estimation: Parquet (or Arrow stream) or CSV, one row per sample.

Columns: ``time`` (UTC), ``station``, ``pass_id``, ``kind``, ``unit`` (of the value columns),
``observed``, ``computed``, ``residual`` (observed - computed; azimuth wrapped to [-π, π)),
``normalized_residual`` (residual / sigma), ``sigma``, ``edited`` (true = excluded by the
k-sigma editing, still reported). Values in SI (m, m/s, Hz, rad). The JSON metadata (under the
key ``trackproc`` of the schema metadata, or the ``# trackproc: {`` block opening a CSV) names the
solution: epoch, parameters, force model, range-rate model.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pyarrow as pa

from trackproc.io.atomic import open_atomic
from trackproc.io.csvtext import csv_metadata_line
from trackproc.io.passfile import iso_times
from trackproc.io.tables import arrow_table_bytes

__all__ = ["COLUMNS", "residuals_bytes", "write_residuals", "format_for"]

COLUMNS = ("time", "station", "pass_id", "kind", "unit", "observed", "computed", "residual",
           "normalized_residual", "sigma", "edited")
META_KEY = "trackproc"


def format_for(path: str) -> str:
    """``csv`` for a ``.csv`` name, ``arrow`` for stdout, else ``parquet``."""
    if str(path) == "-":
        return "arrow"
    return "csv" if Path(path).suffix.lower() == ".csv" else "parquet"


def _arrow(frame: pd.DataFrame, meta: dict) -> pa.Table:
    times = frame["time"]
    if getattr(times.dt, "tz", None) is None:
        times = times.dt.tz_localize("UTC")
    arrays = [pa.array(times.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(dtype="datetime64[ns]"),
                       pa.timestamp("ns")).cast(pa.timestamp("ns", tz="UTC"))]
    fields = [pa.field("time", pa.timestamp("ns", tz="UTC"), nullable=False)]
    for name in COLUMNS[1:]:
        if name in ("station", "pass_id", "kind", "unit"):
            arrays.append(pa.array(frame[name].astype(str).to_numpy(dtype=object), pa.string()))
            fields.append(pa.field(name, pa.string(), nullable=False))
        elif name == "edited":
            arrays.append(pa.array(frame[name].to_numpy(dtype=bool), pa.bool_()))
            fields.append(pa.field(name, pa.bool_(), nullable=False))
        else:
            arrays.append(pa.array(frame[name].to_numpy(dtype=np.float64), pa.float64()))
            fields.append(pa.field(name, pa.float64(), nullable=False))
    text = json.dumps(meta, sort_keys=True, default=str)
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata={META_KEY: text.encode()}))


def residuals_bytes(frame: pd.DataFrame, meta: dict | None = None, fmt: str = "parquet") -> bytes:
    """The encoded residual table: ``parquet``, ``arrow`` (IPC stream) or ``csv``."""
    meta = meta or {}
    if fmt == "csv":
        out = io.StringIO()
        out.write(csv_metadata_line(json.dumps(meta, sort_keys=True, default=str)))
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(COLUMNS)
        cells = [iso_times(frame["time"])] + [frame[c].to_numpy(dtype=object) for c in COLUMNS[1:]]
        for row in zip(*cells):
            writer.writerow([row[0]] + [("true" if v else "false") if isinstance(v, (bool, np.bool_))
                                        else repr(float(v)) if isinstance(v, (float, np.floating)) else str(v)
                                        for v in row[1:]])
        return out.getvalue().encode("utf-8")
    table = _arrow(frame, meta)
    if fmt not in ("parquet", "arrow"):
        raise ValueError(f"unknown residual format {fmt!r}; expected parquet, arrow or csv")
    return arrow_table_bytes(table, fmt)


def write_residuals(frame: pd.DataFrame, path: str, meta: dict | None = None, fmt: str | None = None) -> None:
    """Write the residual table atomically (format from the suffix unless given)."""
    data = residuals_bytes(frame, meta, fmt or format_for(path))
    with open_atomic(path) as handle:
        handle.write(data)
