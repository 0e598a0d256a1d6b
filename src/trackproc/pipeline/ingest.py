"""Validate raw samples from one or more readers and build the canonical pass table.

Rules (each violation is an :class:`~trackproc.errors.InputError` naming the file, row, column,
what was found and what was expected; with ``drop_invalid`` the offending samples are dropped
instead and counted per reason in :attr:`IngestResult.dropped`):

- value finite; sigma finite and > 0 (a missing sigma takes the per-kind default);
- elevation within [-90, 90] deg (reported in the unit the file used);
- station known: in the stations table, or defined by the input itself (DopTrack sidecar,
  metadata of a canonical pass file);
- no two samples of the same station and kind at the same time (across all inputs);
- Doppler samples need the nominal carrier (``carrier_hz``, Hz) and the mode (one-way or
  two-way), from the options or from the inputs; they are stored in the metadata.

Sign convention: range-rate is positive when the satellite recedes. Doppler = received −
nominal carrier frequency (Hz), so to first order range_rate ≈ −c·doppler/carrier one-way and
range_rate ≈ −c·doppler/(2·carrier) two-way (c = 299 792 458 m/s).

Passes: samples of a station are split where consecutive times are more than ``max_gap_s``
apart and numbered ``<station>-001``, ``-002``, ... by start time, unless the input gives a
``pass_id``.

Memory (issue 14 item 5): :class:`Ingest` takes each input chunk by chunk
(:func:`trackproc.io.tabular.iter_raw`); only the valid samples are kept, in compact columns
(:mod:`trackproc.pipeline.ingest_samples`, ~45 bytes a sample, at most ``TRACKPROC_MAX_INPUT_ROWS``),
for the checks that need them all; the CLI writes the table slice by slice. About 400 lines:
the input's chunks, their checks and the pass numbering in one place (the samples' storage and
the per-sample checks are their own modules).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable, Mapping, Sequence

import numpy as np

from trackproc.errors import InputError
from trackproc.vocabulary import LINK_MODES
from trackproc.isotime import iso_utc
from trackproc.io.passfile import KINDS, PassTable, base_meta
from trackproc.io.raw import RawMeasurements
from trackproc.pipeline.ingest_samples import Names, Samples, factorize, pass_codes
from trackproc.io.stations import Station
from trackproc.io.validate import check_carrier, max_input_rows
from trackproc.io.layouts import DEG
from trackproc.io.problems import add_counts
from trackproc.pipeline.ingest_checks import doppler_settings, sample_problems

if TYPE_CHECKING:
    import pandas as pd

UNKNOWN_STATION = "unknown station"
DUPLICATE_TIME = "duplicated timestamp"

MODES = LINK_MODES


@dataclass
class IngestOptions:
    """Options of ``trackproc ingest``; sigmas are the defaults for samples that have none."""

    carrier_hz: float | None = None       # nominal carrier frequency, Hz
    doppler_mode: str | None = None       # "one-way" | "two-way"
    max_gap_s: float = 300.0              # pass split where samples are further apart, s
    drop_invalid: bool = False
    sigma_range_m: float = 10.0
    #: --sigma-range-m given: it also replaces the precision CRD normal points carry as their sigma
    sigma_range_explicit: bool = False
    sigma_range_rate_m_s: float = 0.1
    sigma_doppler_hz: float = 1.0
    sigma_angle_deg: float = 0.01

    def default_sigmas(self) -> dict[str, float]:
        """Default 1-sigma per kind, SI units."""
        angle = self.sigma_angle_deg * DEG
        return {"range": self.sigma_range_m, "range_rate": self.sigma_range_rate_m_s,
                "doppler": self.sigma_doppler_hz, "elevation": angle, "azimuth": angle}


@dataclass
class IngestResult:
    """The canonical table, how many samples were dropped per reason (``drop_invalid``), and
    warnings for the user (readers' assumptions, station coordinates overridden). ``samples``:
    the same table in compact columns (:mod:`trackproc.pipeline.ingest_samples`), which the
    streaming writer uses; ``table`` is made from it when first asked for."""

    samples: Samples
    meta: dict
    dropped: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    _table: PassTable | None = None

    @property
    def table(self) -> PassTable:
        if self._table is None:
            # numpy columns; the DataFrame only when a caller asks for it (PassTable.frame)
            self._table = PassTable.from_columns(self.samples.numpy_columns(), self.meta, self.samples.frame)
        return self._table


#: Reader metadata keys that ingest interprets; any other key is kept under ``meta["inputs"]``.
_INTERPRETED = {"source", "dropped", "carrier_hz", "doppler_mode", "stations", "doptrack", "time_scale",
                "warnings"}


def ingest(raws: Sequence[RawMeasurements], stations: Mapping[str, Station] | None = None,
           options: IngestOptions | None = None) -> IngestResult:
    """Validate and merge raw samples into one canonical pass table (see the module docstring)."""
    run = Ingest(stations, options)
    for raw in raws:
        run.add_input([raw])
    return run.finish()


class Ingest:
    """One ingest, input by input and chunk by chunk (:func:`trackproc.io.tabular.iter_raw`), in
    bounded memory: each chunk's samples are checked on their own and kept in compact columns;
    what needs every sample (stations of all inputs, duplicates, Doppler settings, order, passes)
    is done by :meth:`finish`. The first error is the one a whole read reports: a reader's error
    at once (readers run before validation), the earliest invalid sample of all inputs at the end.
    """

    def __init__(self, stations: Mapping[str, Station] | None = None, options: IngestOptions | None = None):
        self.options = options or IngestOptions()
        self.option_error: InputError | None = None
        try:
            _check_options(self.options)
        except InputError as exc:   # reported after the inputs are read, as before streaming
            self.option_error = exc
        self.table = stations or {}
        self.inputs: list[RawMeasurements] = []       # per input: source, column map, metadata
        self.samples = Samples()
        self.merged = 0                                # samples the readers gave
        self.reader_dropped: dict[str, int] = {}
        self.checked_dropped: dict[str, int] = {}
        self.pending: tuple[tuple[int, int], InputError] | None = None   # earliest invalid sample
        self.max_samples = max_input_rows()

    def add_input(self, chunks: Iterable[RawMeasurements]) -> None:
        """Read one input's chunks (all of them: a later chunk may hold a reader error)."""
        index = len(self.inputs)
        for raw in chunks:
            if len(self.inputs) == index:
                self.inputs.append(RawMeasurements(frame=None, source=raw.source, column=dict(raw.column),
                                                   meta={**raw.meta, "dropped": {}}))
            add_counts(self.inputs[index].meta["dropped"], raw.meta.get("dropped") or {})
            add_counts(self.reader_dropped, raw.meta.get("dropped") or {})
            self._add_chunk(raw, index)

    def _add_chunk(self, raw: RawMeasurements, index: int) -> None:
        frame = _chunk_frame(raw, index, self.options)
        self.merged += len(frame)
        if self.option_error is not None or self.pending is not None or not len(frame):
            return   # nothing after the first invalid sample can be reported before it
        problems = sample_problems(frame)
        if problems and not self.options.drop_invalid:
            error = problems.first_error()
            self.pending = ((index, int(error.row)), error)
            frame = frame.select(~problems.invalid())
        elif problems:
            keep, counts = problems.resolve(True)
            add_counts(self.checked_dropped, counts)
            frame = frame.select(keep)
        self.samples.append(frame, index)
        if len(self.samples) > self.max_samples:   # ~45 bytes each are kept until the end
            raise InputError(f"more than {self.max_samples} samples in all inputs", file=raw.source,
                             expected="fewer samples (split the inputs), or a larger TRACKPROC_MAX_INPUT_ROWS")

    def finish(self) -> IngestResult:
        """The checks that need every sample, then order and passes (see the module docstring)."""
        if self.option_error is not None:
            raise self.option_error
        if not self.inputs:
            raise InputError("no input files", expected="at least one INPUT")
        raws, options = self.inputs, self.options
        warnings = [f"{raw.source}: {text}" for raw in raws for text in raw.meta.get("warnings") or []]
        known = _known_stations(raws, self.table, warnings)
        if self.merged == 0:
            raise InputError("empty input", file=", ".join(r.source for r in raws), found="no samples",
                             expected="at least one measurement")
        samples = self.samples
        samples.concatenate()
        keep, counts = self._whole_set_checks(known)
        dropped = add_counts(dict(self.reader_dropped), self.checked_dropped)
        add_counts(dropped, counts)
        samples.keep(keep)
        if not len(samples):
            raise InputError("no valid samples left after dropping invalid rows",
                             file=", ".join(r.source for r in raws),
                             found=", ".join(f"{n} {reason}" for reason, n in dropped.items()) or "none",
                             expected="at least one valid sample")
        carrier_hz, mode = doppler_settings(raws, samples, options)
        samples.sort()
        samples.number_passes(options.max_gap_s)
        stations = [samples.stations.names[code] for code in np.unique(samples.columns["station"])]
        meta = _meta(raws, stations, known, options, carrier_hz, mode, dropped)
        return IngestResult(samples, meta, dropped, warnings)

    def _whole_set_checks(self, known: Mapping[str, Station]) -> tuple[np.ndarray, dict[str, int]]:
        """Unknown stations and duplicated timestamps -> (samples to keep, dropped per reason);
        without ``drop_invalid`` the earliest problem, this or a pending one, is raised."""
        c = self.samples.columns
        names = sorted(known)
        is_known = np.array([name in known for name in self.samples.stations.names] or [True], dtype=bool)
        unknown = ~is_known[c["station"]]
        duplicated, first = self.samples.duplicates(~unknown)
        if not self.options.drop_invalid:
            candidates = [self.pending] if self.pending else []
            for mask, make in ((unknown, self._unknown_station_error), (duplicated, self._duplicate_error)):
                if mask.any():
                    at = np.flatnonzero(mask)
                    i = int(at[np.lexsort((at, c["row"][at], c["input"][at]))[0]])
                    candidates.append(((int(c["input"][i]), int(c["row"][i])), make(i, names, first)))
            if candidates:
                raise min(candidates, key=lambda item: item[0])[1]   # min is stable: earlier checks win ties
            return np.ones(len(c["time"]), bool), {}
        counts = {}
        if unknown.any():
            counts[UNKNOWN_STATION] = int(unknown.sum())
        if duplicated.any():
            counts[DUPLICATE_TIME] = int(duplicated.sum())
        return ~(unknown | duplicated), counts

    def _unknown_station_error(self, i: int, names: list, first) -> InputError:
        c = self.samples.columns
        listed = ", ".join(names[:20]) + (" ..." if len(names) > 20 else "")
        return InputError(UNKNOWN_STATION, file=self.inputs[c["input"][i]].source, row=int(c["row"][i]),
                          column="station", found=self.samples.stations.names[c["station"][i]],
                          expected=(f"a station of the stations table or of the input ({listed})" if names
                                    else "a station defined in --stations FILE (none given)"))

    def _duplicate_error(self, i: int, names: list, first) -> InputError:
        c, raws = self.samples.columns, self.inputs
        j = int(first[i])
        kind = KINDS[c["kind"][i]]
        return InputError(f"duplicated timestamp for station {self.samples.stations.names[c['station'][i]]} and "
                          f"kind {kind} (first at {raws[c['input'][j]].source} row {int(c['row'][j])})",
                          file=raws[c["input"][i]].source, row=int(c["row"][i]),
                          column=raws[c["input"][i]].column.get(kind, "value"),
                          found=iso_utc(np.datetime64(int(c["time"][i]), "ns"), 6),
                          expected="one sample per station, kind and time")


class Chunk:
    """One chunk of one input as the numpy columns the checks read (sigma defaults filled in):
    ``time`` (int64 ns since 1970, UTC), ``station``, ``pass_id``, ``kind``, ``unit``,
    ``value_column``, ``sigma_column``, ``source`` (object arrays of str), ``value``, ``sigma``
    (float64), ``row`` (int64). Plain arrays, not a DataFrame: each string column of a DataFrame
    is converted to an Arrow string array on the way in and back to objects on the way out."""

    __slots__ = ("columns",)

    def __init__(self, columns: dict):
        self.columns = columns

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __len__(self) -> int:
        return len(self.columns["time"])

    def select(self, mask: np.ndarray) -> "Chunk":
        return Chunk({name: values[mask] for name, values in self.columns.items()})


def _raw_columns(raw: RawMeasurements) -> dict:
    """The reader's samples as numpy columns: its ``arrays`` as they are (text cells are str
    already), or its DataFrame's columns as the checks read them (text as str, time in ns)."""
    if raw.arrays is not None:
        a = raw.arrays
        missing = [c for c in ("time", "station", "kind", "value", "sigma", "row") if c not in a]
        if missing:
            raise InputError("reader returned incomplete samples", file=raw.source, column=missing[0])
        n = len(a["row"])
        return {"time": np.asarray(a["time"], dtype="datetime64[ns]").astype(np.int64),
                "station": a["station"], "kind": a["kind"],
                "pass_id": a["pass_id"] if "pass_id" in a else np.full(n, "", dtype=object),
                "value": np.asarray(a["value"], dtype=np.float64), "sigma": np.array(a["sigma"], dtype=np.float64),
                "row": np.asarray(a["row"], dtype=np.int64),
                "unit": a["unit"] if "unit" in a else np.full(n, "", dtype=object)}
    import pandas as pd  # start-up: pandas (~0.15 s) only for a reader that gives a DataFrame

    frame = raw.frame
    missing = [c for c in ("time", "station", "kind", "value", "sigma", "row") if c not in frame.columns]
    if missing:
        raise InputError("reader returned incomplete samples", file=raw.source, column=missing[0])
    n = len(frame)
    time = pd.to_datetime(frame["time"], utc=True).dt.as_unit("ns").dt.tz_localize(None)
    return {"time": time.to_numpy().astype(np.int64),
            "station": frame["station"].astype(str).to_numpy(dtype=object),
            "kind": frame["kind"].astype(str).to_numpy(dtype=object),
            "pass_id": (frame["pass_id"].fillna("").astype(str).to_numpy(dtype=object)
                        if "pass_id" in frame.columns else np.full(n, "", dtype=object)),
            "value": frame["value"].to_numpy(dtype=np.float64),
            "sigma": frame["sigma"].to_numpy(dtype=np.float64).copy(),
            "row": frame["row"].to_numpy(dtype=np.int64),
            "unit": (frame["unit"].astype(str).to_numpy(dtype=object) if "unit" in frame.columns
                     else np.full(n, "", dtype=object))}


def _chunk_frame(raw: RawMeasurements, index: int, options: IngestOptions) -> Chunk:
    """One chunk of one input as the merged columns the checks read (sigma defaults filled in)."""
    c = _raw_columns(raw)
    defaults = options.default_sigmas()
    n = len(c["row"])
    kind = c["kind"]
    codes, kinds = factorize(kind)   # per distinct kind, not per row
    kinds = [str(k) for k in kinds]

    def per_kind(values) -> np.ndarray:
        return np.array(values + [None], dtype=object)[codes] if len(codes) else np.zeros(0, object)

    sigma = c["sigma"]   # a copy: the defaults are filled in
    if options.sigma_range_explicit and raw.meta.get("crd"):
        sigma[kind == "range"] = math.nan
    default = per_kind([defaults.get(k, math.nan) for k in kinds]).astype(np.float64)
    c["sigma"] = np.where(np.isnan(sigma), default, sigma)
    c["source"] = np.full(n, raw.source, dtype=object)
    c["value_column"] = per_kind([raw.column.get(k, "value") for k in kinds])
    c["sigma_column"] = per_kind([raw.column.get(f"sigma:{k}", "sigma") for k in kinds])
    return Chunk(c)


def _meta(raws, station_names, known, options: IngestOptions, carrier_hz, mode, dropped) -> dict:
    """File metadata: provenance, settings, stations used, reader extras (see io.passfile)."""
    meta = base_meta(
        carrier_hz=carrier_hz,
        doppler_mode=mode,
        sources=[raw.source for raw in raws],
        stations={name: known[name].as_dict() for name in sorted(station_names)},
        max_gap_s=float(options.max_gap_s),
        sigma_defaults={"range_m": options.sigma_range_m, "range_rate_m_s": options.sigma_range_rate_m_s,
                        "doppler_hz": options.sigma_doppler_hz, "angle_deg": options.sigma_angle_deg},
    )
    if dropped:
        meta["dropped_rows"] = dict(dropped)
    doptrack = {}
    for raw in raws:
        doptrack.update(raw.meta.get("doptrack") or {})
    if doptrack:
        meta["doptrack"] = doptrack
    inputs = {raw.source: _json_safe({k: v for k, v in raw.meta.items() if k not in _INTERPRETED})
              for raw in raws}
    inputs = {source: extra for source, extra in inputs.items() if extra}
    if inputs:
        meta["inputs"] = inputs
    return meta


def _json_safe(value):
    """Reader metadata as plain JSON values (anything else becomes its text)."""
    return json.loads(json.dumps(value, sort_keys=True, default=str))


def _check_options(options: IngestOptions) -> None:
    def positive(name: str, value, unit: str) -> None:
        if value is None or not (math.isfinite(value) and value > 0):
            raise InputError("invalid option", column=name, found=value, expected=f"a number > 0 ({unit})")

    positive("--max-gap", options.max_gap_s, "s")
    positive("--sigma-range-m", options.sigma_range_m, "m")
    positive("--sigma-range-rate-m-s", options.sigma_range_rate_m_s, "m/s")
    positive("--sigma-doppler-hz", options.sigma_doppler_hz, "Hz")
    positive("--sigma-angle-deg", options.sigma_angle_deg, "deg")
    if options.carrier_hz is not None:
        check_carrier(options.carrier_hz)
    if options.doppler_mode is not None and options.doppler_mode not in MODES:
        raise InputError("invalid option", column="--mode", found=options.doppler_mode,
                         expected=" or ".join(MODES))


def _known_stations(raws: Sequence[RawMeasurements], table: Mapping[str, Station],
                    warnings: list[str]) -> dict[str, Station]:
    """Stations from the table, plus those defined by the inputs (the table wins on a clash)."""
    known: dict[str, Station] = {}
    for raw in raws:
        for name, values in (raw.meta.get("stations") or {}).items():
            known.setdefault(name, Station.from_meta(name, values, raw.source))
    for name, station in table.items():
        other = known.get(name)
        if other is not None and (abs(other.lat_deg - station.lat_deg) > 1e-6
                                  or abs(other.lon_deg - station.lon_deg) > 1e-6
                                  or abs(other.height_m - station.height_m) > 0.01):
            warnings.append(f"station {name}: using the stations table, not the coordinates in the input")
        known[name] = station
    return known


def assign_pass_ids(frame: pd.DataFrame, max_gap_s: float) -> np.ndarray:
    """Pass ids: given ones kept; others ``<station>-NNN``, a new pass after a gap > ``max_gap_s``.

    ``frame`` must be sorted by station then time; numbering is per station by start time and
    skips ids the input already uses.
    """
    stations = Names()
    passes = Names([""])
    codes = pass_codes(stations.encode(frame["station"].astype(str).to_numpy(dtype=object)),
                       frame["time"].dt.tz_convert("UTC").dt.tz_localize(None).dt.as_unit("ns").to_numpy()
                       .astype(np.int64),
                       passes.encode(frame["pass_id"].astype(str).to_numpy(dtype=object)), stations.names, passes,
                       max_gap_s)
    return passes.array()[codes]
