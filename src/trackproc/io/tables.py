"""Encoding of Arrow tables for every tabular output: Parquet (files) or an Arrow IPC stream (pipes)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def arrow_table_bytes(table, fmt: str) -> bytes:
    """``table`` (a pyarrow Table, schema metadata included) as Parquet (zstd) or an Arrow IPC stream."""
    sink = pa.BufferOutputStream()
    if fmt == "parquet":
        import pyarrow.parquet as pq  # start-up: pyarrow.parquet only for Parquet output

        # format 2.6 keeps nanosecond times on every supported pyarrow (12 wrote 2.4: microseconds)
        pq.write_table(table, sink, compression="zstd", version="2.6")
    elif fmt == "arrow":
        with pa.ipc.new_stream(sink, table.schema) as writer:
            writer.write_table(table)
    else:
        raise ValueError(f"unknown table format {fmt!r}; expected parquet or arrow")
    return sink.getvalue().to_pybytes()


# pyarrow's own pa.array() imports pandas (~0.25 s of CPU) on its first call, whatever it is
# given; these build the same arrays from their buffers (Arrow columnar format: values, a
# bit-packed validity or boolean buffer, int32 offsets into UTF-8 bytes for strings).

def float_array(values) -> pa.Array:
    """float64 Arrow array of ``values`` (no nulls)."""
    data = np.ascontiguousarray(values, dtype=np.float64)
    return pa.Array.from_buffers(pa.float64(), data.size, [None, pa.py_buffer(data)])


def utc_time_array(times) -> pa.Array:
    """``timestamp[ns, UTC]`` Arrow array of naive UTC ``datetime64[ns]`` ``times`` (no nulls)."""
    ints = np.ascontiguousarray(np.asarray(times, dtype="datetime64[ns]").view(np.int64))
    return pa.Array.from_buffers(pa.timestamp("ns", tz="UTC"), ints.size, [None, pa.py_buffer(ints)])


def bool_array(values) -> pa.Array:
    """boolean Arrow array of ``values`` (no nulls)."""
    flags = np.asarray(values, dtype=bool).reshape(-1)
    return pa.Array.from_buffers(pa.bool_(), flags.size, [None, pa.py_buffer(np.packbits(flags, bitorder="little"))])


#: Distinct labels up to which :func:`string_array` builds the column from the labels' bytes.
FEW_LABELS = 16


def string_array(values) -> pa.Array:
    """string (UTF-8) Arrow array of ``values`` (each written as ``str``; no nulls)."""
    few = few_labels(values)
    if few is not None:
        return _labels_array(*few)
    encoded = [str(v).encode("utf-8") for v in values]
    offsets = np.zeros(len(encoded) + 1, dtype=np.int64)
    np.cumsum([len(b) for b in encoded], out=offsets[1:])
    if offsets[-1] >= 2 ** 31:
        raise ValueError("text column too large for an Arrow string array (2 GiB)")
    return pa.Array.from_buffers(pa.string(), len(encoded),
                                 [None, pa.py_buffer(offsets.astype(np.int32)), pa.py_buffer(b"".join(encoded))])


def few_labels(values, labels: list | None = None) -> tuple[np.ndarray, list] | None:
    """(codes, distinct labels) of a 1-d object array of at most :data:`FEW_LABELS` distinct
    ``str`` labels (a pass table's station, pass id and kind: a few names, ~1000 rows), found by
    one hashing pass and one comparison per label in C; None for anything else. A value equal to
    a ``str`` label is written as that label (``str`` of a ``numpy.str_`` is the same text).
    ``labels``: the distinct values in order of first appearance, when the caller has them (the
    hashing pass is then not made again)."""
    if not isinstance(values, np.ndarray) or values.dtype != object or values.ndim != 1 or not len(values):
        return None
    if labels is None:
        try:
            labels = list(dict.fromkeys(values.tolist()))
        except TypeError:        # an unhashable value (a list): the caller's own path
            return None
    if len(labels) > FEW_LABELS or not all(type(label) is str for label in labels):
        return None
    codes = np.zeros(len(values), dtype=np.intp)
    for code, label in enumerate(labels[1:], 1):
        # against the label as a Python object: a bare str would become a numpy string, which
        # drops trailing NULs ("a\x00" would then equal "a" and take its code)
        codes[values == np.array(label, dtype=object)] = code
    return codes, labels


def _labels_array(codes: np.ndarray, labels: list) -> pa.Array:
    """The string array of ``labels[codes]`` from the labels' UTF-8 bytes, each encoded once (the
    Arrow columnar layout: int32 offsets, the rows' bytes back to back)."""
    encoded = [label.encode("utf-8") for label in labels]
    n = len(codes)
    if len(encoded) == 1:        # one label (a pass file's station, pass id): no per-row work
        size = len(encoded[0])
        offsets = np.arange(0, (n + 1) * size, size, dtype=np.int64) if size else np.zeros(n + 1, np.int64)
        data = encoded[0] * n
    else:
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.array([len(b) for b in encoded], dtype=np.int64)[codes], out=offsets[1:])
        data = b"".join(map(encoded.__getitem__, codes.tolist()))
    if offsets[-1] >= 2 ** 31:
        raise ValueError("text column too large for an Arrow string array (2 GiB)")
    return pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(offsets.astype(np.int32)), pa.py_buffer(data)])
