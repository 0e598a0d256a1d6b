"""The two table layouts, wide and long (see :mod:`trackproc.io.tabular`), as raw samples in SI units.

A :class:`LayoutReader` checks the header once (first chunk), converts each chunk of rows on its
own, and makes the whole-file checks (no rows, no measurement) at :meth:`LayoutReader.finish`, so
a file read whole or streamed chunk by chunk gives the same samples and the same first error.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from trackproc.errors import InputError
from trackproc.io.columns import Column, SourceTable, column_numbers, column_strings, column_times
from trackproc.io.problems import NONFINITE_SIGMA, NONFINITE_VALUE, UNKNOWN_KIND, WRONG_TYPE, Problems
from trackproc.io.raw import KIND_UNITS, RawMeasurements

log = logging.getLogger("trackproc")

DEG = math.pi / 180.0

#: Unit-suffixed spelling -> (canonical kind, factor to SI, unit as written).
UNIT_SPELLINGS: dict[str, tuple[str, float, str]] = {
    "range_m": ("range", 1.0, "m"),
    "range_km": ("range", 1e3, "km"),
    "range_rate_m_s": ("range_rate", 1.0, "m/s"),
    "range_rate_km_s": ("range_rate", 1e3, "km/s"),
    "doppler_hz": ("doppler", 1.0, "Hz"),
    "elevation_deg": ("elevation", DEG, "deg"),
    "elevation_rad": ("elevation", 1.0, "rad"),
    "azimuth_deg": ("azimuth", DEG, "deg"),
    "azimuth_rad": ("azimuth", 1.0, "rad"),
}
#: Long-layout ``kind`` values: the canonical SI kinds and the unit-suffixed spellings.
KIND_SPELLINGS: dict[str, tuple[str, float, str]] = {
    **{kind: (kind, 1.0, unit) for kind, unit in KIND_UNITS.items()},
    **UNIT_SPELLINGS,
}


def is_long_layout(table: SourceTable) -> bool:
    return "kind" in table.columns and "value" in table.columns


def read_long(table: SourceTable, *, drop_invalid: bool = False) -> RawMeasurements:
    """Long layout ``time, station, kind, value [, sigma] [, pass_id]`` -> raw samples (SI)."""
    return LongReader(table, drop_invalid).read_whole(table)


def read_wide(table: SourceTable, *, drop_invalid: bool = False) -> RawMeasurements:
    """Wide layout ``time, station, range_rate_m_s, elevation_deg, ...`` -> raw samples (SI)."""
    return WideReader(table, drop_invalid).read_whole(table)


def layout_reader(first: SourceTable, layout: str, drop_invalid: bool) -> "LayoutReader":
    """The reader of ``layout`` (``long``, ``wide``, or ``auto``/``table``: long when the header has
    kind and value columns), its header checked on the first chunk."""
    if layout == "long" or (layout in ("auto", "table") and is_long_layout(first)):
        return LongReader(first, drop_invalid)
    return WideReader(first, drop_invalid)


class LayoutReader:
    """Header checks at construction; :meth:`read` per chunk; :meth:`finish` after the last one."""

    def __init__(self, first: SourceTable, drop_invalid: bool):
        self.drop_invalid = drop_invalid
        self.source, self.header_row = first.source, first.header_row
        self.rows = self.samples = 0
        self.first_row: int | None = None
        self.column_map: dict = {}

    def read(self, table: SourceTable) -> RawMeasurements:
        if len(table) and self.first_row is None:
            self.first_row = int(table.rows[0])
        self.rows += len(table)
        raw = self._read(table)
        self.samples += raw.size()
        return raw

    def read_whole(self, table: SourceTable) -> RawMeasurements:
        _empty_check(table)
        raw = self.read(table)
        self.finish()
        return raw

    def finish(self) -> None:
        if self.rows == 0:
            first = (self.header_row + 1) if self.header_row is not None else 1
            raise InputError("empty input", file=self.source, row=first, found="no data rows",
                             expected="at least one measurement row")

    def _read(self, table: SourceTable) -> RawMeasurements:
        raise NotImplementedError

    def _raw(self, arrays: dict, keep: np.ndarray, table: SourceTable, dropped: dict) -> RawMeasurements:
        """The samples kept as numpy columns (:attr:`RawMeasurements.arrays`; the frame is built
        from them only for a caller that asks)."""
        meta = {"source": table.source, "dropped": dropped}
        carried = table.meta
        for key in ("carrier_hz", "doppler_mode", "stations", "doptrack"):
            if carried.get(key) is not None:
                meta[key] = carried[key]
        if not keep.all():
            arrays = {name: values[keep] for name, values in arrays.items()}
        return RawMeasurements(source=table.source, column=dict(self.column_map), meta=meta, arrays=arrays)


class LongReader(LayoutReader):
    def __init__(self, first: SourceTable, drop_invalid: bool):
        super().__init__(first, drop_invalid)
        first.require("time", "station", "kind", "value")
        self.column_map = {"time": first.columns["time"].name, "station": first.columns["station"].name}
        if "sigma" in first.columns:
            self.column_map.update({f"sigma:{k}": first.columns["sigma"].name for k in KIND_UNITS})
        self.column_map.update({k: first.columns["value"].name for k in KIND_UNITS})

    def _read(self, table: SourceTable) -> RawMeasurements:
        problems = Problems(table.rows, table.source)
        times = column_times(table, table.columns["time"], problems)
        kinds_written = np.array([k.lower() for k in column_strings(table, table.columns["kind"])], dtype=object)
        spelled = [KIND_SPELLINGS.get(k) for k in kinds_written]
        unknown = np.array([s is None for s in spelled], dtype=bool)
        problems.add(UNKNOWN_KIND, unknown, column=table.columns["kind"].name, found=kinds_written,
                     expected="one of " + ", ".join(KIND_SPELLINGS))
        spelled = [s or ("", math.nan, "") for s in spelled]
        kind = np.array([s[0] for s in spelled], dtype=object)
        factor = np.array([s[1] for s in spelled], dtype=np.float64)
        unit = np.array([s[2] for s in spelled], dtype=object)

        value_col = table.columns["value"]
        value, missing, wrong = column_numbers(table, value_col)
        problems.add(WRONG_TYPE, wrong, column=value_col.name, found=value_col.text, expected="a number")
        problems.add(NONFINITE_VALUE, missing, column=value_col.name, found="",
                     expected="a finite number")
        sigma = np.full(len(table), np.nan)
        if "sigma" in table.columns:
            sigma_col = table.columns["sigma"]
            sigma, _, wrong = column_numbers(table, sigma_col)
            problems.add(WRONG_TYPE, wrong, column=sigma_col.name, found=sigma_col.text,
                         expected="a number or an empty cell")
            explicit_nan = np.isnan(sigma) & ~_blank(table, sigma_col) & ~wrong
            problems.add(NONFINITE_SIGMA, explicit_nan, column=sigma_col.name, found=math.nan,
                         expected="a finite number > 0, or an empty cell for the default")
        arrays = {
            "time": np.asarray(times, dtype="datetime64[ns]"),
            "station": column_strings(table, table.columns["station"]),
            "kind": kind,
            "value": value * factor,
            "sigma": sigma * factor,
            "row": table.rows,
            "unit": unit,
        }
        if "pass_id" in table.columns:
            arrays["pass_id"] = column_strings(table, table.columns["pass_id"])
        keep, dropped = problems.resolve(self.drop_invalid)
        return self._raw(arrays, keep, table, dropped)


class WideReader(LayoutReader):
    def __init__(self, first: SourceTable, drop_invalid: bool):
        super().__init__(first, drop_invalid)
        first.require("time", "station")
        self.measured = [name for name in first.columns if name in UNIT_SPELLINGS]
        if not self.measured:
            raise InputError("no measurement column", file=first.source, row=first.header_row,
                             column="(none)", found=", ".join(c.name for c in first.columns.values()),
                             expected="at least one of " + ", ".join(UNIT_SPELLINGS)
                             + " (wide layout), or kind and value columns (long layout)")
        _check_one_column_per_kind(first, self.measured)
        _warn_unused(first, self.measured)
        self.column_map = {"time": first.columns["time"].name, "station": first.columns["station"].name}
        for name in self.measured:
            kind = UNIT_SPELLINGS[name][0]
            if "sigma_" + name in first.columns:
                self.column_map[f"sigma:{kind}"] = first.columns["sigma_" + name].name
            self.column_map[kind] = first.columns[name].name
        self.measured_names = ", ".join(first.columns[m].name for m in self.measured)

    def finish(self) -> None:
        super().finish()
        if self.candidates == 0:
            raise InputError("empty input", file=self.source, row=self.first_row, column=self.measured_names,
                             found="no measurement in any row", expected="at least one measurement")

    candidates = 0    # samples before the invalid ones are dropped

    def _read(self, table: SourceTable) -> RawMeasurements:
        stations = column_strings(table, table.columns["station"])
        pass_ids = column_strings(table, table.columns["pass_id"]) if "pass_id" in table.columns else None
        # one numpy array per field, the measured columns one after another (the rows a pandas
        # concat of one frame per column gave, without building those frames: ~1 ms a file)
        parts: dict = {name: [] for name in ("src", "position", "kind", "value", "sigma", "unit", "column",
                                             "sigma_column", "wrong", "sigma_wrong", "sigma_nan", "found",
                                             "sigma_found")}
        for position, name in enumerate(self.measured):
            kind, factor, unit = UNIT_SPELLINGS[name]
            col = table.columns[name]
            value, missing, wrong = column_numbers(table, col)
            sigma_col = table.columns.get("sigma_" + name)
            if sigma_col is not None:
                sigma, _, sigma_wrong = column_numbers(table, sigma_col)
                sigma_nan = np.isnan(sigma) & ~_blank(table, sigma_col) & ~sigma_wrong
            else:
                sigma = np.full(len(table), np.nan)
                sigma_wrong = sigma_nan = np.zeros(len(table), dtype=bool)
            take = np.flatnonzero(~missing)
            n = take.size
            for key, values in (
                    ("src", take), ("position", np.full(n, position, dtype=np.int64)),
                    ("kind", _texts(kind, n)), ("value", value[take] * factor), ("sigma", sigma[take] * factor),
                    ("unit", _texts(unit, n)), ("column", _texts(col.name, n)),
                    ("sigma_column", _texts(sigma_col.name if sigma_col is not None else "", n)),
                    ("wrong", wrong[take]), ("sigma_wrong", sigma_wrong[take]), ("sigma_nan", sigma_nan[take]),
                    ("found", col.text[take] if col.text is not None else value[take]),
                    ("sigma_found", sigma_col.text[take] if sigma_col is not None and sigma_col.text is not None
                     else sigma[take])):
                parts[key].append(values)
        samples = {key: _joined(values) for key, values in parts.items()}
        self.candidates += len(samples["src"])
        src = samples["src"].astype(np.int64)
        rows = table.rows[src]
        problems = Problems(rows, table.source, order=rows * 1000 + samples["position"])
        times = column_times(table, table.columns["time"], problems, index=src)
        problems.add(WRONG_TYPE, samples["wrong"].astype(bool), column=samples["column"],
                     found=samples["found"], expected="a number or an empty cell")
        problems.add(WRONG_TYPE, samples["sigma_wrong"].astype(bool),
                     column=samples["sigma_column"],
                     found=samples["sigma_found"], expected="a number or an empty cell")
        problems.add(NONFINITE_SIGMA, samples["sigma_nan"].astype(bool),
                     column=samples["sigma_column"],
                     found=math.nan, expected="a finite number > 0, or an empty cell for the default")
        arrays = {
            "time": np.asarray(times[src], dtype="datetime64[ns]"),
            "station": stations[src],
            "kind": samples["kind"],
            "value": samples["value"].astype(np.float64),
            "sigma": samples["sigma"].astype(np.float64),
            "row": rows,
            "unit": samples["unit"],
        }
        if pass_ids is not None:
            arrays["pass_id"] = pass_ids[src]
        keep, dropped = problems.resolve(self.drop_invalid)
        return self._raw(arrays, keep, table, dropped)


def _texts(text: str, n: int) -> np.ndarray:
    out = np.empty(n, dtype=object)
    out[:] = text
    return out


def _joined(values: list) -> np.ndarray:
    """The arrays of one field end to end, with the dtype pandas' concat gives: object when
    the pieces' dtypes differ (text and numbers), else theirs."""
    if len({v.dtype for v in values}) > 1:
        values = [v.astype(object) for v in values]
    return np.concatenate(values) if len(values) > 1 else values[0]


def _blank(table: SourceTable, column: Column) -> np.ndarray:
    if column.text is not None:
        return column.text == ""
    return column.array.is_null().to_numpy(zero_copy_only=False)


def _empty_check(table: SourceTable) -> None:
    if len(table) == 0:
        first = (table.header_row + 1) if table.header_row is not None else 1
        raise InputError("empty input", file=table.source, row=first, found="no data rows",
                         expected="at least one measurement row")


def _check_one_column_per_kind(table: SourceTable, measured: list[str]) -> None:
    seen: dict[str, str] = {}
    for name in measured:
        kind = UNIT_SPELLINGS[name][0]
        if kind in seen:
            raise InputError(f"two columns give {kind}", file=table.source, row=table.header_row,
                             column=table.columns[name].name, found=f"{seen[kind]} and {name}",
                             expected=f"one {kind} column")
        seen[kind] = name


def _warn_unused(table: SourceTable, measured: list[str]) -> None:
    used = {"time", "station", "pass_id", *measured, *("sigma_" + m for m in measured)}
    for key, column in table.columns.items():
        if key not in used:
            hint = " (name its unit, e.g. elevation_deg)" if key in KIND_UNITS else ""
            log.warning("%s: ignoring column '%s'%s", table.source, column.name, hint)
