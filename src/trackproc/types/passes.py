"""The canonical pass table in memory (:class:`PassTable`): samples and file metadata. Its columns and
metadata are described in :mod:`trackproc.io.passfile`, which reads and writes it.

A table read from a file holds its columns as numpy arrays and builds the pandas DataFrame
(``frame``) only when a caller asks for it: ``refine`` and ``estimate`` read the columns
(:meth:`PassTable.column`) and never import pandas (~0.15 s of CPU, a quarter of a refine)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from trackproc.types.station import Station


class PassTable:
    """Canonical samples (``frame``, columns :data:`COLUMNS` first) and file metadata (``meta``).

    Made from a DataFrame (``PassTable(frame, meta)``) or from numpy columns
    (:meth:`from_columns`: ``time`` naive UTC ``datetime64[ns]``, text columns object arrays of
    ``str``, numbers float64; None for a column only the DataFrame holds) with the function that
    builds the same DataFrame when ``frame`` is first read."""

    def __init__(self, frame=None, meta: dict | None = None):
        self._frame = frame
        self._columns: dict | None = None
        self._build: Callable | None = None
        self.meta = {} if meta is None else meta

    @classmethod
    def from_columns(cls, columns: dict, meta: dict | None, build_frame: Callable) -> "PassTable":
        table = cls(None, meta)
        table._columns, table._build = dict(columns), build_frame
        return table

    @property
    def frame(self):
        """The samples as a DataFrame, built from the numpy columns when first read. Once handed
        out it is the table's truth: a caller may change it in place (``table.frame["station"] =
        ...``), so the numpy columns are dropped and :meth:`column` reads the frame from then on."""
        if self._frame is None:
            self._frame = self._build()
        self._columns = self._build = None
        return self._frame

    @frame.setter
    def frame(self, value) -> None:
        self._frame, self._columns, self._build = value, None, None

    @property
    def column_names(self) -> list:
        return list(self._columns) if self._frame is None else [str(c) for c in self._frame.columns]

    @property
    def n_rows(self) -> int:
        if self._frame is None:
            return len(self._columns["time"])
        return len(self._frame)

    def column(self, name: str) -> np.ndarray:
        """One column as numpy: ``time`` naive UTC ``datetime64[ns]``, text as object arrays of str.
        A table made by :meth:`from_columns` answers from its numpy columns until its frame is read
        (:attr:`frame`: then from the frame, which its reader may have changed)."""
        if self._columns is not None and self._columns.get(name) is not None:
            return self._columns[name]
        values = self.frame[name]
        if name == "time":
            if getattr(values.dt, "tz", None) is not None:
                values = values.dt.tz_convert("UTC").dt.tz_localize(None)
            return values.to_numpy(dtype="datetime64[ns]")
        if name in ("station", "pass_id", "kind"):
            return values.astype(str).to_numpy(dtype=object)
        return values.to_numpy()

    def numpy_columns(self) -> dict | None:
        """Every column as numpy (as :meth:`column` gives them), by name in table order, when the
        table was made by :meth:`from_columns` with all of them; else None (the frame holds some)."""
        if self._columns is None or any(values is None for values in self._columns.values()):
            return None
        return dict(self._columns)

    def with_meta(self, meta: dict) -> "PassTable":
        """The same samples with ``meta``: its numpy columns and its frame (built or not) shared."""
        if self._columns is None:
            return PassTable(self._frame, meta)
        table = PassTable.from_columns(self._columns, meta, self._build)
        table._frame = self._frame
        return table

    def take(self, rows: np.ndarray, meta: dict | None = None) -> "PassTable":
        """The rows ``rows`` (indices or a boolean mask), renumbered from 0, with ``meta`` (default: this one's)."""
        meta = self.meta if meta is None else meta
        if self._columns is None:
            rows = np.asarray(rows)
            picked = self._frame.loc[rows] if rows.dtype == bool else self._frame.iloc[rows]
            return PassTable(picked.reset_index(drop=True), meta)
        rows = np.asarray(rows)
        columns = {name: None if values is None else values[rows] for name, values in self._columns.items()}
        built = self._frame
        build = self._build if built is None else (lambda: built)

        def build_taken():
            frame = build()
            return (frame.loc[rows] if rows.dtype == bool else frame.iloc[rows]).reset_index(drop=True)
        return PassTable.from_columns(columns, meta, build_taken)

    def stations(self) -> dict:
        """Stations recorded at ingest, name -> :class:`trackproc.types.Station`."""
        source = str(self.meta.get("source") or "<pass file>")
        return {name: Station.from_meta(name, values, source)
                for name, values in (self.meta.get("stations") or {}).items()}

    def __repr__(self) -> str:
        return f"PassTable({self.n_rows} samples, meta keys {sorted(self.meta)})"

