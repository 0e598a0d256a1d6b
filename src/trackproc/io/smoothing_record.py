"""The smoothing record, read in one place: what ``trackproc smooth`` leaves in a pass file's
metadata (key ``smoothing``, the same object as its ``--summary`` JSON) for later commands.

Written by :func:`trackproc.pipeline.smooth.smooth` (:func:`trackproc.pipeline.smooth_summary.fit_record`): ``{"counts": ...,
"fits": [record, ...], "output": "samples" | "grid", ...}``, one record per station, pass and
kind with ``station``, ``pass_id``, ``kind``, ``unit``, ``status``, ``epoch_utc``, ``n_used``
and, when a polynomial was fitted, ``basis``, ``domain_s``, ``degree``, ``coefficients``,
``covariance_unscaled``, ``chi2``, ``dof``, ``rms``, ``weighted_rms``, ``condition_number``,
``tca`` (``status`` ``ok`` or ``not_observed``, ``time_utc``, ``sigma_s``, ...) and ``fca_hz``
(docs/smooth.md). Read by ``refine`` (the smoothed curve of seed 004 eq. 14) and ``batch``.

Where the records are stored (layout 1 inline, layout 2 a compact table beside or after the
samples) is below; readers see ``smoothing_of(meta)["fits"]`` as a sequence of records either way.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from trackproc.errors import InputError
from trackproc.io.atomic import read_input_bytes

__all__ = ["META_KEY", "smoothing_of", "output_of", "find_fit_record", "fit_from_record", "record_epoch",
           "fit_summary", "FitRecords", "records_table", "record_of", "split_records", "attach_records",
           "sidecar_path"]

#: Key of the record in a pass file's metadata.
META_KEY = "smoothing"


def smoothing_of(meta) -> dict:
    """The smoothing record of a pass file's metadata ({} when it was not smoothed)."""
    return (meta or {}).get(META_KEY) or {}


def output_of(meta):
    """``"samples"`` or ``"grid"`` (what ``smooth`` wrote), or None."""
    return smoothing_of(meta).get("output")


def find_fit_record(meta, station: str, pass_id: str, kind: str):
    """The record of ``station``/``pass_id``/``kind`` that holds a fitted polynomial, or None."""
    fits = smoothing_of(meta).get("fits")
    if isinstance(fits, FitRecords):
        return fits.find(station, pass_id, kind)
    for r in smoothing_of(meta).get("fits", []) or []:
        if (r.get("station"), r.get("pass_id"), r.get("kind")) == (station, pass_id, kind) and r.get("coefficients"):
            return r
    return None


def fit_from_record(rec: dict):
    """The :class:`~trackproc.methods.smoothing.PolynomialFit` of a record (seed 004 eq. 1's
    coefficients with their covariance; per-sample arrays are not stored and come back empty)."""

    n_used = int(rec.get("n_used") or 0)
    cov = np.asarray(rec["covariance_unscaled"], float)
    from trackproc.methods.smoothing import PolynomialFit   # (numpy.polynomial: only for a smoothed pass)

    return PolynomialFit(basis=str(rec["basis"]), domain_s=tuple(float(a) for a in rec["domain_s"]),
                         degree=int(rec["degree"]), coef=np.asarray(rec["coefficients"], float), cov_unscaled=cov,
                         chi2=float(rec["chi2"]), dof=int(rec["dof"]), used=np.ones(n_used, bool),
                         residual=np.zeros(n_used), rms=float(rec.get("rms") or math.nan),
                         wrms=float(rec.get("weighted_rms") or math.nan),
                         condition_number=float(rec.get("condition_number") or math.nan))


def record_epoch(rec: dict) -> np.datetime64:
    """The record's time origin (``epoch_utc``), UTC ``datetime64[ns]``."""
    return np.datetime64(str(rec["epoch_utc"]).rstrip("Zz"), "ns")


def fit_summary(rec: dict) -> dict:
    """The few numbers of a record a batch report shows."""
    tca = rec.get("tca") or {}
    return {"station": rec["station"], "pass_id": rec["pass_id"], "kind": rec["kind"], "status": rec["status"],
            "n_samples": rec["n_samples"], "n_used": rec.get("n_used"), "degree": rec.get("degree"),
            "rms": rec.get("rms"), "rms_unit": rec.get("unit"),
            "tca_utc": tca.get("time_utc"), "tca_sigma_s": tca.get("sigma_s"), "fca_hz": rec.get("fca_hz"),
            "error": rec.get("error") or tca.get("error")}


# --------------------------------------------------------------------------- where the records live
#
# Layout 1 (up to INLINE_BYTES of records, and every file before layout 2): the records inline,
# ``meta["smoothing"]["fits"]`` (up to ~40 kB a fit in JSON; a Parquet footer holds ~100 MB, about
# 2,300 passes, and is read whole by every command). Layout 2 (more records): one row per record
# in a compact table
# (:func:`records_table`): the sidecar ``NAME.passes.parquet`` next to a Parquet or CSV file, or a
# second Arrow IPC stream after the table's own in an Arrow output; the metadata keeps the summary
# and a pointer, ``meta["smoothing"]["records"]``.

#: Name of the compact table's layout in the pointer.
RECORDS_LAYOUT = "smoothing-records/2"
#: Records of at most this many bytes of JSON stay inline (~100 fits); more go to the compact table.
INLINE_BYTES = 4 << 20
#: Inline records above this many bytes of JSON are refused (a Parquet footer's limit is ~100 MB).
MAX_INLINE_BYTES = 32 << 20
_ARRAYS = ("coefficients", "covariance_unscaled")


def sidecar_path(path) -> "Path":
    """``x.parquet`` -> ``x.passes.parquet``; any other name gets ``.passes.parquet`` appended."""

    path = Path(path)
    stem = path.stem if path.suffix.lower() == ".parquet" else path.name
    return path.with_name(stem + ".passes.parquet")


def records_table(fits):
    """The records as a compact Arrow table: key columns, the polynomial's coefficients and unscaled
    covariance as float64 lists, every other field in a JSON text column. ``covariance_scaled`` is
    left out when it is ``variance_factor * covariance_unscaled`` (as smooth writes it)."""

    columns = {name: [] for name in ("station", "pass_id", "kind", "status", *_ARRAYS, "scaled_derived", "record")}
    for rec in fits:
        rest = dict(rec)
        for key in ("station", "pass_id", "kind", "status"):
            columns[key].append(str(rest.pop(key, "")))
        coef, cov = rest.pop("coefficients", None), rest.pop("covariance_unscaled", None)
        columns["coefficients"].append(None if coef is None else [_float(v) for v in coef])
        flat = None if cov is None else [_float(v) for row in cov for v in row]
        columns["covariance_unscaled"].append(flat)
        derived = cov is not None and "covariance_scaled" in rest and _is_scaled(
            rest["covariance_scaled"], np.asarray(flat, float).reshape(len(cov), -1), rest.get("variance_factor"))
        if derived:
            del rest["covariance_scaled"]
        columns["scaled_derived"].append(bool(derived))
        columns["record"].append(json.dumps(rest, allow_nan=False, separators=(",", ":")))
    types = {"coefficients": pa.list_(pa.float64()), "covariance_unscaled": pa.list_(pa.float64()),
             "scaled_derived": pa.bool_()}
    return pa.table({name: pa.array(values, types.get(name, pa.string())) for name, values in columns.items()})


def _float(value) -> float:
    return math.nan if value is None else float(value)


def _is_scaled(scaled, unscaled: np.ndarray, factor) -> bool:
    """``scaled`` (JSON: null for non-finite) is exactly ``unscaled * factor`` (as smooth makes it)."""
    try:
        given = np.array(scaled, dtype=float)     # None -> nan
    except (TypeError, ValueError):
        return False
    made = unscaled * _float(factor)
    made[~np.isfinite(made)] = np.nan
    return given.shape == made.shape and bool(np.array_equal(given, made, equal_nan=True))


def _plain(values: list) -> list:
    """Floats as JSON holds them: NaN and infinities as None."""
    return [v if v is not None and math.isfinite(v) else None for v in values]


def record_of(table, i: int) -> dict:
    """Row ``i`` of :func:`records_table` as the record it was made from."""
    return next(_records(table.slice(i, 1)))


def _records(table):
    """Every row of :func:`records_table` as its record (columns converted once, not cell by cell)."""

    columns = {name: table.column(name).to_pylist() for name in table.column_names}
    for i in range(table.num_rows):
        rec = {key: columns[key][i] for key in ("station", "pass_id", "kind", "status")}
        rec.update(json.loads(columns["record"][i]))
        coef = columns["coefficients"][i]
        if coef is not None:
            rec["coefficients"] = _plain(coef)
        flat = columns["covariance_unscaled"][i]
        if flat is not None:
            n = math.isqrt(len(flat))
            cov = np.asarray(flat, float).reshape(n, n) if n * n == len(flat) else np.asarray(flat, float)[None, :]
            rec["covariance_unscaled"] = [_plain(row) for row in cov.tolist()]
            if columns["scaled_derived"][i]:
                rec["covariance_scaled"] = [_plain(row) for row in (cov * _float(rec.get("variance_factor"))).tolist()]
        yield rec


class FitRecords:
    """The records of layout 2, read when first needed (``info`` or ``detect`` never load them):
    a sequence of record dicts, with :meth:`find` by station, pass and kind."""

    def __init__(self, load, count: int | None = None):
        self._load, self._count = load, count
        self._table = None
        self._index: dict | None = None

    def table(self):
        if self._table is None:
            self._table = self._load()
        return self._table

    def __len__(self) -> int:
        return self.table().num_rows if self._count is None or self._table is not None else self._count

    def __getitem__(self, i: int) -> dict:
        n = len(self)
        if not -n <= i < n:
            raise IndexError(i)
        return record_of(self.table(), i % n)

    def __iter__(self):
        return _records(self.table())

    def __bool__(self) -> bool:
        return len(self) > 0

    def find(self, station: str, pass_id: str, kind: str):
        if self._index is None:
            table = self.table()
            self._index = {}
            keys = zip(*(table.column(k).to_pylist() for k in ("station", "pass_id", "kind")))
            fitted = table.column("coefficients").is_valid().to_pylist()
            for i, (key, ok) in enumerate(zip(keys, fitted)):
                if ok:
                    self._index.setdefault(key, i)
        i = self._index.get((station, pass_id, kind))
        return None if i is None else record_of(self.table(), i)


def split_records(meta: dict, where: str):
    """``(meta, records table or None)`` for writing. Records of at most :data:`INLINE_BYTES` of
    JSON stay inline (a file that travels alone, through pipes too); more move to a compact table
    with a pointer left behind (``where``: ``"sidecar"`` or ``"stream"``); ``"inline"`` (a Parquet
    or CSV without a file of its own) keeps them inline, within :data:`MAX_INLINE_BYTES`."""
    smoothing = (meta or {}).get(META_KEY)
    if not isinstance(smoothing, dict) or "fits" not in smoothing:
        return meta, None
    fits = smoothing["fits"]
    rest = {k: v for k, v in smoothing.items() if k not in ("fits", "records")}
    if where != "inline" and not isinstance(fits, FitRecords) and _json_size(fits) <= INLINE_BYTES:
        where = "inline"
    if where == "inline":
        return {**meta, META_KEY: {**rest, "fits": list(fits)}}, None
    table = records_table(fits)
    pointer = {"layout": RECORDS_LAYOUT, "count": table.num_rows, "in": where}
    return {**meta, META_KEY: {**rest, "records": pointer}}, table


def _json_size(fits) -> int:
    return len(json.dumps(fits, separators=(",", ":"), default=str))


def check_inline_size(meta_text: str, what: str) -> None:
    """Inline records beyond :data:`MAX_INLINE_BYTES`: an error before anything is written."""

    if len(meta_text) > MAX_INLINE_BYTES:
        raise InputError(f"{len(meta_text) / 1e6:.0f} MB of smoothing records do not fit in the metadata of {what}",
                         column="-o", expected="-o FILE (the records go to FILE.passes.parquet) or --format arrow")


def attach_records(meta: dict, source: str, stream_rest: bytes | None = None) -> None:
    """On reading a pass file: replace a layout-2 pointer by a lazy :class:`FitRecords` (the sidecar
    next to ``source``, or ``stream_rest``: the bytes after an Arrow stream's table)."""
    smoothing = (meta or {}).get(META_KEY)
    if not isinstance(smoothing, dict) or not isinstance(smoothing.get("records"), dict):
        return
    pointer = smoothing["records"]
    count = pointer.get("count") if isinstance(pointer.get("count"), int) else None
    if pointer.get("in") == "stream":
        smoothing["fits"] = FitRecords(lambda: _stream_records(stream_rest, source), count)
    else:
        smoothing["fits"] = FitRecords(lambda: _sidecar_records(pointer, source), count)


def _check_table(table, where: str):
    need = {"station", "pass_id", "kind", "status", *_ARRAYS, "scaled_derived", "record"}
    if not need <= set(table.column_names):
        raise InputError("not a table of smoothing records", file=where, found=", ".join(table.column_names),
                         expected="the records trackproc smooth wrote (" + ", ".join(sorted(need)) + ")")
    return table


def _stream_records(rest: bytes | None, source: str):
    try:
        if not rest:
            raise ValueError("nothing after the table")
        return _check_table(pa.ipc.open_stream(pa.BufferReader(rest)).read_all(), source)
    except (pa.ArrowException, ValueError, OSError) as exc:
        raise InputError(f"the smoothing records after the table are missing or unreadable ({exc})", file=source,
                         column="smoothing", expected="the whole Arrow output of trackproc smooth") from None


def _sidecar_records(pointer: dict, source: str):
    name = pointer.get("file")
    if not isinstance(name, str) or Path(name).name != name:
        raise InputError("invalid metadata", file=source, column="smoothing.records.file", found=name,
                         expected="the name of the records file next to the pass file")
    if source == "<stdin>":
        raise InputError(f"the smoothing records are in the file {name} next to the pass file, which stdin does "
                         "not carry", file=source, column="smoothing",
                         expected="the pass file by its path, or smooth's Arrow output (-o - or --format arrow)")
    path = Path(source).parent / name
    data = read_input_bytes(path)
    if pointer.get("sha256") not in (None, hashlib.sha256(data).hexdigest()):
        raise InputError("the smoothing records file does not belong to this pass file (its checksum differs)",
                         file=str(path), column="smoothing.records.sha256",
                         expected=f"the {name} that smooth wrote with {Path(source).name}")
    try:
        return _check_table(pq.ParquetFile(pa.BufferReader(data)).read(), str(path))   # no pyarrow.dataset
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise InputError(f"unreadable smoothing records ({exc})", file=str(path),
                         expected="the Parquet file smooth wrote") from None
