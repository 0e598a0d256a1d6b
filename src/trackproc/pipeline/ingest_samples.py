"""The validated samples of ``ingest`` in compact columns: what needs the whole set (duplicates,
sorting, pass numbering) done on ~45 bytes a sample instead of pandas rows of Python objects.

Text fields (station, pass_id, kind, unit) are codes into small name lists; times are int64 ns;
``seq`` is the order in which samples arrived (inputs in order, rows in order), the tie-break of
"first" everywhere, as in a whole read. The canonical table is built slice by slice
(:meth:`Samples.arrow_batches`) so the writer never holds it whole.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa

from trackproc.io.passfile import COLUMNS, KINDS
from trackproc.io.tables import few_labels

if TYPE_CHECKING:
    import pandas as pd

#: Columns and their dtypes; ``kind`` codes index :data:`KINDS`.
DTYPES = {"time": np.int64, "station": np.int32, "pass_id": np.int32, "kind": np.int8, "value": np.float64,
          "sigma": np.float64, "row": np.int64, "input": np.int32, "unit": np.int16}
#: Rows of the canonical table built at a time (the Parquet writer's default row group).
SLICE_ROWS = 1 << 20


def factorize(values) -> tuple[np.ndarray, list]:
    """``pandas.factorize(values)`` of a 1-d array of labels: codes (intp) into the distinct
    values in order of first appearance, -1 for a missing one. Labels that are all ``str`` (the
    readers' text columns) are coded here with two dict passes in C, without importing pandas
    (~0.15 s of CPU a process); any other label (None, NaN, a number) goes to pandas itself, so
    its rules for missing values and for equal labels of different types stay the rules."""
    array = np.asarray(values, dtype=object)
    items = array.tolist()
    uniques = list(dict.fromkeys(items))
    if not all(isinstance(u, str) for u in uniques):
        import pandas as pd  # start-up: only for labels other than str (see above)

        codes, found = pd.factorize(array, sort=False)
        return codes, list(found)
    few = few_labels(array, uniques)
    if few is not None:          # a few str labels (a pass file's): one comparison per label in numpy
        return few
    lookup = {u: i for i, u in enumerate(uniques)}
    return np.fromiter(map(lookup.__getitem__, items), dtype=np.intp, count=len(items)), uniques


class Names:
    """Strings <-> int codes, in first-seen order."""

    def __init__(self, first=()):
        self.names: list[str] = []
        self.codes: dict[str, int] = {}
        for name in first:
            self.code(name)

    def code(self, name: str) -> int:
        code = self.codes.get(name)
        if code is None:
            code = self.codes[name] = len(self.names)
            self.names.append(name)
        return code

    def encode(self, values) -> np.ndarray:
        """Codes of an array of strings (factorised first: one dictionary lookup per distinct value)."""
        codes, uniques = factorize(values)
        mapping = np.array([self.code(str(u)) for u in uniques] or [0], dtype=np.int32)
        return mapping[codes] if len(codes) else np.zeros(0, np.int32)

    def array(self) -> np.ndarray:
        return np.array(self.names, dtype=object)


class Samples:
    """Compact columns (:data:`DTYPES`) appended chunk by chunk, then concatenated once."""

    def __init__(self):
        self.stations, self.passes, self.units = Names(), Names([""]), Names()
        self._pieces: dict[str, list] = {name: [] for name in DTYPES}
        self.columns: dict[str, np.ndarray] = {}
        self._appended = 0

    def append(self, frame, input_index: int) -> None:
        """Samples of one chunk (:class:`trackproc.pipeline.ingest.Chunk`: numpy columns by name)."""
        n = len(frame)
        if not n:
            return
        self._appended += n
        kind_codes = {k: i for i, k in enumerate(KINDS)}
        pieces = self._pieces
        pieces["time"].append(np.asarray(frame["time"], dtype=np.int64))
        pieces["station"].append(self.stations.encode(frame["station"]))
        pieces["pass_id"].append(self.passes.encode(frame["pass_id"]))
        codes, kinds = factorize(frame["kind"])   # kinds checked before
        pieces["kind"].append(np.array([kind_codes[k] for k in kinds] or [0], dtype=np.int8)[codes])
        pieces["value"].append(np.asarray(frame["value"], dtype=np.float64))
        pieces["sigma"].append(np.asarray(frame["sigma"], dtype=np.float64))
        pieces["row"].append(np.asarray(frame["row"], dtype=np.int64))
        pieces["input"].append(np.full(n, input_index, dtype=np.int32))
        pieces["unit"].append(self.units.encode(frame["unit"]).astype(np.int16))

    def concatenate(self) -> None:
        for name, dtype in DTYPES.items():
            parts = self._pieces.pop(name)
            self.columns[name] = np.concatenate(parts).astype(dtype, copy=False) if parts \
                else np.zeros(0, dtype)
            del parts

    def __len__(self) -> int:
        return len(self.columns["time"]) if self.columns else self._appended

    def keep(self, mask: np.ndarray) -> None:
        for name in list(self.columns):
            self.columns[name] = self.columns[name][mask]

    def take(self, order: np.ndarray) -> None:
        for name in list(self.columns):
            self.columns[name] = self.columns[name][order]

    # ------------------------------------------------------------------ whole-set operations

    def duplicates(self, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Among ``valid`` samples, those whose station, kind and time came earlier (a mask), and
        for each the position of that first one (-1 elsewhere)."""
        c = self.columns
        idx = np.flatnonzero(valid)
        order = idx[np.lexsort((idx, c["time"][idx], c["kind"][idx], c["station"][idx]))]
        same = np.zeros(len(order), dtype=bool)
        if len(order) > 1:
            same[1:] = ((c["time"][order[1:]] == c["time"][order[:-1]]) & (c["kind"][order[1:]] == c["kind"][order[:-1]])
                        & (c["station"][order[1:]] == c["station"][order[:-1]]))
        mask = np.zeros(len(valid), dtype=bool)
        first = np.full(len(valid), -1, dtype=np.int64)
        if same.any():
            head = np.maximum.accumulate(np.where(same, 0, np.arange(len(order))))
            mask[order[same]] = True
            first[order[same]] = order[head[same]]
        return mask, first

    def sort(self) -> None:
        """Canonical order: station, then time, then kind (by name), stable over arrival."""
        c = self.columns
        station_rank = np.argsort(np.argsort(self.stations.array(), kind="stable")).astype(np.int32) \
            if self.stations.names else np.zeros(0, np.int32)
        kind_rank = np.argsort(np.argsort(np.array(KINDS, dtype=object), kind="stable")).astype(np.int8)
        order = np.lexsort((kind_rank[c["kind"]], c["time"], station_rank[c["station"]]))
        self.take(order)

    def number_passes(self, max_gap_s: float) -> None:
        """Pass ids: given ones kept; others ``<station>-NNN``, a new pass after a gap > ``max_gap_s``
        (the samples sorted; numbering per station by start time, skipping ids the input uses)."""
        c = self.columns
        c["pass_id"] = pass_codes(c["station"], c["time"], c["pass_id"], self.stations.names, self.passes,
                                  max_gap_s)

    # ------------------------------------------------------------------ the canonical table

    def frame(self) -> pd.DataFrame:
        import pandas as pd  # start-up: pandas (~0.15 s) only when a caller asks for the DataFrame

        c = self.columns

        def strings(names, codes) -> pd.Series:
            # the few distinct names as a str array, taken by code (in Arrow): not one Python
            # string per row converted to Arrow
            return pd.Series(pd.array([str(n) for n in names], dtype="str").take(codes.astype(np.intp)))

        # built in COLUMNS order: no reindexing copy after (the same columns, dtypes and blocks)
        columns = {
            "time": pd.DatetimeIndex(c["time"].astype("datetime64[ns]")).tz_localize("UTC"),
            "station": strings(self.stations.names, c["station"]),
            "pass_id": strings(self.passes.names, c["pass_id"]),
            "kind": strings(KINDS, c["kind"]),
            "value": c["value"], "sigma": c["sigma"],
        }
        return pd.DataFrame({name: columns[name] for name in COLUMNS})

    def numpy_columns(self) -> dict:
        """The canonical table's columns as :meth:`~trackproc.types.passes.PassTable.column` gives
        them of :meth:`frame` (time datetime64[ns] UTC, the names as str objects, value and sigma
        float64), without the DataFrame: a batch's smooth and refine read these."""
        c = self.columns

        def names(known, codes):
            return np.array([str(n) for n in known], dtype=object)[codes.astype(np.intp)]

        return {"time": c["time"].astype("datetime64[ns]"), "station": names(self.stations.names, c["station"]),
                "pass_id": names(self.passes.names, c["pass_id"]), "kind": names(KINDS, c["kind"]),
                "value": np.asarray(c["value"], dtype=np.float64), "sigma": np.asarray(c["sigma"], dtype=np.float64)}

    def arrow_batches(self, schema):
        """The canonical table as Arrow record batches of :data:`SLICE_ROWS` rows."""
        c = self.columns
        dictionaries = [pa.array(self.stations.names, pa.string()), pa.array(self.passes.names, pa.string()),
                        pa.array(list(KINDS), pa.string())]
        for start in range(0, len(c["time"]), SLICE_ROWS):
            part = slice(start, start + SLICE_ROWS)
            strings = [dictionary.take(pa.array(c[name][part])) for dictionary, name in
                       zip(dictionaries, ("station", "pass_id", "kind"))]
            yield pa.record_batch([pa.array(c["time"][part], pa.int64()).cast(pa.timestamp("ns", tz="UTC")),
                                   *strings, pa.array(c["value"][part], pa.float64()),
                                   pa.array(c["sigma"][part], pa.float64())], schema=schema)

    def counts(self) -> tuple[int, int, int]:
        """(samples, passes, stations)."""
        c = self.columns
        passes = len(np.unique(c["pass_id"])) if len(c["pass_id"]) else 0
        stations = len(np.unique(c["station"])) if len(c["station"]) else 0
        return len(c["time"]), passes, stations


def pass_codes(stations: np.ndarray, times: np.ndarray, passes: np.ndarray, station_names, pass_names: Names,
               max_gap_s: float) -> np.ndarray:
    """Pass codes with the missing ones (code 0, "") numbered (see :meth:`Samples.number_passes`)."""
    ids = passes.copy()
    need = ids == 0
    if not need.any():
        return ids
    gap_ns = int(round(max_gap_s * 1e9))
    for station in dict.fromkeys(stations[need].tolist()):   # in order of first appearance
        mine = stations == station
        idx = np.flatnonzero(need & mine)
        name = station_names[station]
        taken = {pass_names.names[code] for code in np.unique(ids[mine & ~need])}
        new_pass = np.r_[True, np.diff(times[idx]) > gap_ns]
        number, labels = 0, []
        for _ in range(int(new_pass.sum())):
            number += 1
            while f"{name}-{number:03d}" in taken:
                number += 1
            labels.append(pass_names.code(f"{name}-{number:03d}"))
        ids[idx] = np.array(labels, dtype=np.int32)[np.cumsum(new_pass) - 1]
    return ids
