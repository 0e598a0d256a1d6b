"""Ephemeris tables (the output of ``trackproc propagate``) and CCSDS OEM (KVN) text.

Columns, in this order (GCRF, SI units; README "Data contract" and docs/propagate.md):

==============================  =================  ==============================================
column                          unit               present
==============================  =================  ==============================================
time                            timestamp[ns, UTC] always
x_m, y_m, z_m                   m                  always
vx_m_s, vy_m_s, vz_m_s          m/s                always
stm_I_J (I, J = 1..6)           see below          ``--stm``: Phi_IJ = d x_I(t) / d x_J(epoch)
sigma_x_m .. sigma_vz_m_s       m, m/s             the state file has a covariance
cov_I_J (I, J = 1..6)           m^2, m^2/s, m^2/s^2  the same: the full propagated 6 x 6
range_m                         m                  ``--at-station``
range_rate_m_s                  m/s                ``--at-station`` (positive receding)
doppler_hz                      Hz                 ``--at-station`` with ``--carrier-hz``
azimuth_deg, elevation_deg      deg                ``--at-station``
light_time_s                    s                  ``--at-station``
sigma_range_m, sigma_range_rate_m_s (, sigma_doppler_hz)    ``--at-station`` with a covariance
==============================  =================  ==============================================

State components are numbered 1..6 = x, y, z, vx, vy, vz, so ``stm_1_4 = d x(t) / d vx(epoch)``
(unit s) and ``cov_1_4`` the x-vx covariance (m^2/s). Rows are in time order. The metadata (a
JSON object under the key ``trackproc`` of the Arrow/Parquet schema metadata; the first line
``# trackproc: {`` block opening a CSV) names the force model and its constants, the Earth
orientation, the propagator and its tolerance, the station and the range-rate model.

CCSDS OEM: :func:`oem_text` writes Orbit Ephemeris Message KVN (CCSDS 502.0-B-2/B-3
section 5; ``CCSDS_OEM_VERS = 2.0``, whose keywords B-3 keeps): header, one META block
(OBJECT_NAME, OBJECT_ID, CENTER_NAME = EARTH, REF_FRAME = GCRF, TIME_SYSTEM = UTC,
START_TIME, STOP_TIME), data lines ``epoch x y z x_dot y_dot z_dot`` in km and km/s, and
with a propagated covariance one COVARIANCE_START .. COVARIANCE_STOP section with a matrix per
epoch (``EPOCH =``, ``COV_REF_FRAME = GCRF``, the lower triangle row by row in km^2, km^2/s,
km^2/s^2). Times are ISO 8601 without a zone letter. Numbers are written as the shortest
text that reads back to the same double (of the km values).
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping
from datetime import datetime, timezone

import numpy as np
import pyarrow as pa

from trackproc.errors import InputError
from trackproc.io.atomic import is_stdio, open_atomic, read_input_bytes
from trackproc.io.columns import META_KEY, column_numbers, column_times, source_table
from trackproc.io.csvtext import csv_metadata_line
from trackproc.io.passfile import meta_json
from trackproc.io.problems import Problems
from trackproc.io.tables import arrow_table_bytes, bool_array, float_array, string_array, utc_time_array
from trackproc.io.validate import check_name
from trackproc.isotime import iso_utc, iso_utc_array

__all__ = ["COLUMNS", "STATE_NAMES", "STM_COLUMNS", "SIGMA_COLUMNS", "COV_COLUMNS", "MEASUREMENT_COLUMNS",
           "FORMATS", "Ephemeris", "ephemeris_bytes", "write_ephemeris", "read_ephemeris", "oem_text", "oem_segments_text",
           "international_designator"]

SCHEMA_VERSION = 1
COLUMNS = ("time", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")
STATE_NAMES = ("x", "y", "z", "vx", "vy", "vz")
STM_COLUMNS = tuple(f"stm_{i}_{j}" for i in range(1, 7) for j in range(1, 7))
SIGMA_COLUMNS = ("sigma_x_m", "sigma_y_m", "sigma_z_m", "sigma_vx_m_s", "sigma_vy_m_s", "sigma_vz_m_s")
COV_COLUMNS = tuple(f"cov_{i}_{j}" for i in range(1, 7) for j in range(1, 7))
MEASUREMENT_COLUMNS = ("range_m", "range_rate_m_s", "doppler_hz", "azimuth_deg", "elevation_deg",
                       "light_time_s", "sigma_range_m", "sigma_range_rate_m_s", "sigma_doppler_hz")
FORMATS = ("parquet", "arrow", "csv", "oem")
OEM_VERSION = "2.0"


class Ephemeris:
    """Ephemeris rows and metadata (``meta``).

    Held as numpy columns (``columns``: name -> array in :data:`COLUMNS` order first; ``time``
    naive UTC ``datetime64[ns]``, numbers float64, text object arrays of ``str``), from which
    the writers work; ``frame``, the pandas DataFrame (time tz-aware UTC), is built when first
    read, so that ``propagate`` writes Parquet, Arrow, CSV and OEM without importing pandas.
    ``Ephemeris(frame, meta)`` takes a DataFrame or a mapping of such columns."""

    def __init__(self, frame=None, meta: dict | None = None):
        if frame is None:
            raise TypeError("an Ephemeris needs its rows (a DataFrame or a mapping of columns)")
        self._frame, self._columns = (None, _as_columns(frame)) if isinstance(frame, Mapping) else (frame, None)
        self.meta = {} if meta is None else meta

    @property
    def columns(self) -> dict:
        """name -> numpy column (``time`` naive UTC ``datetime64[ns]``)."""
        if self._columns is None:
            self._columns = _frame_columns(self._frame)
        return self._columns

    @property
    def frame(self):
        """The rows as a pandas DataFrame (``time`` tz-aware UTC); pandas is imported here."""
        if self._frame is None:
            import pandas as pd  # start-up: pandas only for a caller that asks for the DataFrame

            cols = dict(self._columns)
            cols["time"] = pd.DatetimeIndex(cols["time"]).tz_localize("UTC")
            self._frame = pd.DataFrame(cols)
        return self._frame

    def __len__(self) -> int:
        return len(self.columns["time"]) if self._frame is None else len(self._frame)

    def take(self, rows) -> "Ephemeris":
        """The rows ``rows`` (a boolean mask or indices), same metadata."""
        rows = np.asarray(rows)
        return Ephemeris({name: values[rows] for name, values in self.columns.items()}, self.meta)

    def matrix(self, prefix: str) -> np.ndarray | None:
        """The (N, 6, 6) matrices of the ``stm`` or ``cov`` columns, or None."""
        names = [f"{prefix}_{i}_{j}" for i in range(1, 7) for j in range(1, 7)]
        columns = self.columns
        if not all(n in columns for n in names):
            return None
        return _float_matrix(columns, names).reshape(-1, 6, 6)

    @property
    def states(self) -> np.ndarray:
        """(N, 6) positions (m) and velocities (m/s), GCRF."""
        return _float_matrix(self.columns, COLUMNS[1:])

    def __repr__(self) -> str:
        return f"Ephemeris({len(self)} rows, columns {list(self.columns)})"


def _as_columns(columns: Mapping) -> dict:
    out = {}
    for name, values in columns.items():
        if name == "time":
            values = np.asarray(values)
            if values.dtype.kind != "M":      # a tz-aware pandas index: to naive UTC
                values = values.tz_convert("UTC").tz_localize(None).to_numpy()
            out[name] = values.astype("datetime64[ns]")
        else:
            out[str(name)] = np.asarray(values)
    return out


def _frame_columns(frame) -> dict:
    import pandas as pd

    times = pd.DatetimeIndex(frame["time"])
    if times.tz is not None:
        times = times.tz_convert("UTC").tz_localize(None)
    out = {"time": times.as_unit("ns").to_numpy()}
    for name in frame.columns:
        if name == "time":
            continue
        col = frame[name]
        if pd.api.types.is_bool_dtype(col):
            out[str(name)] = col.to_numpy(bool)
        elif pd.api.types.is_numeric_dtype(col):
            out[str(name)] = col.to_numpy(np.float64)
        else:
            out[str(name)] = col.astype(str).to_numpy(object)
    return out


def _float_matrix(columns: dict, names) -> np.ndarray:
    out = np.empty((len(columns["time"]), len(names)))
    for k, name in enumerate(names):
        out[:, k] = columns[name]
    return out


def _kind(values: np.ndarray) -> str:
    """``bool``, ``number`` or ``text``: how a column is written (as pandas' dtype tests did)."""
    kind = values.dtype.kind
    return "bool" if kind == "b" else "number" if kind in "iufc" else "text"


# --------------------------------------------------------------------------- tables

def to_arrow(eph: Ephemeris) -> pa.Table:
    """Arrow table: time as timestamp[ns, UTC], numbers float64, metadata under ``trackproc``
    (no pandas metadata: the schema holds only the fields and ``trackproc``)."""
    columns = eph.columns
    missing = [c for c in COLUMNS if c not in columns]
    if missing:
        raise ValueError(f"ephemeris lacks columns {missing}")
    arrays = [utc_time_array(columns["time"])]
    fields = [pa.field("time", pa.timestamp("ns", tz="UTC"), nullable=False)]
    for name, values in columns.items():
        if name == "time":
            continue
        kind = _kind(values)
        array = (bool_array(values) if kind == "bool" else float_array(values) if kind == "number"
                 else string_array(values))
        arrays.append(array)
        fields.append(pa.field(str(name), array.type, nullable=False))
    schema = pa.schema(fields, metadata={META_KEY: meta_json(eph.meta).encode()})
    return pa.Table.from_arrays(arrays, schema=schema)


def _csv_bytes(eph: Ephemeris) -> bytes:
    columns = eph.columns
    out = io.StringIO()
    out.write(csv_metadata_line(meta_json(eph.meta)))
    writer = csv.writer(out, lineterminator="\n")
    names = list(columns)
    writer.writerow(names)
    cells = [iso_utc_array(columns["time"])]
    for name in names[1:]:
        values = columns[name]
        kind = _kind(values)
        if kind == "bool":
            cells.append(np.where(values.astype(bool), "true", "false"))
        elif kind == "number":
            cells.append([repr(float(v)) for v in values.astype(np.float64)])
        else:
            cells.append(values.astype(str).astype(object))
    for row in zip(*cells):
        writer.writerow(row)
    return out.getvalue().encode("utf-8")


def ephemeris_bytes(eph: Ephemeris, fmt: str = "parquet", **oem_kwargs) -> bytes:
    """The encoded ephemeris: ``parquet``, ``arrow`` (IPC stream), ``csv`` or ``oem`` (KVN)."""
    fmt = getattr(fmt, "value", fmt)
    if fmt == "csv":
        return _csv_bytes(eph)
    if fmt == "oem":
        return oem_text(eph, **oem_kwargs).encode("utf-8")
    table = to_arrow(eph)
    if fmt not in ("parquet", "arrow"):
        raise ValueError(f"unknown ephemeris format {fmt!r}; expected one of {FORMATS}")
    return arrow_table_bytes(table, fmt)


def write_ephemeris(eph: Ephemeris, path: str, fmt: str = "parquet", **oem_kwargs) -> None:
    """Write ``eph`` atomically to ``path`` (``-`` = stdout); ``oem_kwargs`` go to :func:`oem_text`."""
    data = ephemeris_bytes(eph, fmt, **oem_kwargs)
    with open_atomic(path) as handle:
        handle.write(data)


def read_ephemeris(path: str) -> Ephemeris:
    """Read an ephemeris written by :func:`write_ephemeris` (Parquet, Arrow, CSV; ``-`` = stdin)."""
    source = "<stdin>" if is_stdio(path) else str(path)
    return parse_ephemeris(read_input_bytes(path), source)


def parse_ephemeris(data: bytes, source: str) -> Ephemeris:
    """An ephemeris from the bytes of a Parquet, Arrow or CSV file named ``source`` (for messages)."""
    if not data.strip():
        raise InputError("empty input", file=source, row=1, found="no data", expected="an ephemeris table")
    table = source_table(data, source)
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise InputError("not an ephemeris", file=source, row=table.header_row, column=missing[0],
                         found=", ".join(c.name for c in table.columns.values()),
                         expected="columns " + ", ".join(COLUMNS) + " (from trackproc propagate)")
    problems = Problems(table.rows, source)
    columns = {"time": np.asarray(column_times(table, table.columns["time"], problems), dtype="datetime64[ns]")}
    for key, column in table.columns.items():
        if key == "time":
            continue
        if column.text is not None and key not in COLUMNS and not _numeric_text(column.text):
            columns[column.name] = np.array([str(v) for v in column.text], dtype=object)
            continue
        values, missing_mask, wrong = column_numbers(table, column)
        problems.add("wrong column type", wrong | missing_mask, column=column.name,
                     found=column.text if column.text is not None else "null", expected="a number (SI units)")
        columns[column.name] = values
    problems.resolve(drop_invalid=False)
    return Ephemeris(columns, dict(table.meta))


def _numeric_text(cells) -> bool:
    try:
        [float(c) for c in cells if c]
    except ValueError:
        return False
    return True


# --------------------------------------------------------------------------- CCSDS OEM

def _oem_epoch(t) -> str:
    """UTC ISO 8601 without zone letter, milliseconds at least, more digits only when needed."""
    return iso_utc(t, suffix="")


def _num(value: float) -> str:
    return repr(float(value))


def creation_date() -> datetime:
    """Now (UTC), or ``SOURCE_DATE_EPOCH`` when set (reproducible outputs)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch:
        try:
            return datetime.fromtimestamp(int(epoch), timezone.utc).replace(tzinfo=None)
        except ValueError:
            pass
    return datetime.now(timezone.utc).replace(tzinfo=None)


def international_designator(tle_line1: str) -> str:
    """``YYYY-NNNP{PP}`` from TLE line 1 columns 10-17 (``98067A`` -> ``1998-067A``), or UNKNOWN."""
    raw = tle_line1[9:17].strip() if len(tle_line1) >= 17 else ""
    if len(raw) < 6 or not raw[:5].isdigit():
        return "UNKNOWN"
    yy = int(raw[:2])
    year = 1900 + yy if yy >= 57 else 2000 + yy
    return f"{year}-{raw[2:5]}{raw[5:]}"


def oem_text(eph: Ephemeris, *, object_name: str = "UNKNOWN", object_id: str = "UNKNOWN",
             originator: str = "TRACKPROC", created: datetime | None = None, comments=()) -> str:
    """CCSDS OEM KVN of an ephemeris (states; the propagated covariances if present).

    Positions and velocities are converted to km and km/s, covariances to km^2, km^2/s, km^2/s^2
    (CCSDS 502.0 section 5.2.4-5.2.5); see the module docstring for the layout.
    """
    for key, text in (("OBJECT_NAME", object_name), ("OBJECT_ID", object_id), ("ORIGINATOR", originator)):
        check_name(str(text), "OEM " + key, column=key)   # a newline would forge a KVN line
    t64 = _oem_times(eph)
    covariance_comment = "propagated P(t) = Phi P0 Phi^T; km**2, km**2/s, km**2/s**2"
    stamp = np.datetime64(created or creation_date(), "ms")
    lines = [f"CCSDS_OEM_VERS = {OEM_VERSION}"]
    for c in comments:
        lines.extend(f"COMMENT {part}" for part in str(c).splitlines())
    lines += [f"CREATION_DATE = {iso_utc(stamp, 3, suffix='')}", f"ORIGINATOR = {originator}", ""]
    lines += _oem_segment(eph, t64, object_name, object_id, covariance_comment)
    return "\n".join(lines) + "\n"


def oem_segments_text(segments, *, object_name: str = "UNKNOWN", object_id: str = "UNKNOWN",
                      originator: str = "TRACKPROC", created: datetime | None = None, comments=()) -> str:
    """CCSDS OEM KVN of several ephemerides of one object, one segment each (META block, data
    lines, covariance section: CCSDS 502.0-B-3 5.2.1, an OEM holds one or more segments).
    ``segments``: ``[(Ephemeris, comment), ...]``; the comment (may be empty) opens the segment's
    data section. Layout and units per segment as :func:`oem_text`."""
    for key, text in (("OBJECT_NAME", object_name), ("OBJECT_ID", object_id), ("ORIGINATOR", originator)):
        check_name(str(text), "OEM " + key, column=key)
    segments = list(segments)
    if not segments:
        raise ValueError("an OEM needs at least one segment")
    stamp = np.datetime64(created or creation_date(), "ms")
    lines = [f"CCSDS_OEM_VERS = {OEM_VERSION}"]
    for c in comments:
        lines.extend(f"COMMENT {part}" for part in str(c).splitlines())
    lines += [f"CREATION_DATE = {iso_utc(stamp, 3, suffix='')}", f"ORIGINATOR = {originator}", ""]
    for k, (eph, comment) in enumerate(segments):
        if k:
            lines.append("")
        t64 = _oem_times(eph)
        seg = _oem_segment(eph, t64, object_name, object_id, "covariance; km**2, km**2/s, km**2/s**2")
        if comment:
            at = seg.index("META_STOP") + 2
            seg[at:at] = [f"COMMENT {part}" for part in str(comment).splitlines()]
        lines += seg
    return "\n".join(lines) + "\n"


def _oem_times(eph: Ephemeris) -> np.ndarray:
    if len(eph) == 0:
        raise ValueError("an OEM needs at least one ephemeris line")
    t64 = eph.columns["time"]
    if np.any(np.diff(t64.astype(np.int64)) <= 0):
        raise ValueError("OEM ephemeris lines must be in increasing time order")
    return t64


def _oem_segment(eph: Ephemeris, t64, object_name: str, object_id: str, covariance_comment: str) -> list:
    """One OEM segment's lines: META block, data lines (km, km/s), covariance section."""
    lines = ["META_START", f"OBJECT_NAME = {object_name}", f"OBJECT_ID = {object_id}", "CENTER_NAME = EARTH",
             "REF_FRAME = GCRF", "TIME_SYSTEM = UTC", f"START_TIME = {_oem_epoch(t64[0])}",
             f"STOP_TIME = {_oem_epoch(t64[-1])}", "META_STOP", ""]
    force = eph.meta.get("force_model")
    if force:
        constants = ", ".join(f"{k} = {v!r}" for k, v in sorted((eph.meta.get("constants") or {}).items()))
        lines.append(f"COMMENT force model {force} ({constants})")
    if eph.meta.get("earth_orientation"):
        lines.append(f"COMMENT Earth orientation: {eph.meta['earth_orientation']}")
    lines.append("COMMENT position km, velocity km/s")
    states = eph.states / 1000.0
    for t, row in zip(t64, states):
        lines.append(" ".join([_oem_epoch(t)] + [_num(v) for v in row]))
    cov = eph.matrix("cov")
    if cov is not None:
        lines += ["", "COVARIANCE_START", f"COMMENT {covariance_comment}"]
        ckm = cov / 1.0e6
        for k, (t, m) in enumerate(zip(t64, ckm)):
            if k:
                lines.append("")
            lines += [f"EPOCH = {_oem_epoch(t)}", "COV_REF_FRAME = GCRF"]
            lines += [" ".join(_num(m[i, j]) for j in range(i + 1)) for i in range(6)]
        lines.append("COVARIANCE_STOP")
    return lines
