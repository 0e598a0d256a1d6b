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
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from trackproc.errors import InputError
from trackproc.vocabulary import LINK_MODES
from trackproc.isotime import iso_utc
from trackproc.io.passfile import COLUMNS, KINDS, PassTable, base_meta
from trackproc.io.raw import RawMeasurements
from trackproc.io.stations import Station
from trackproc.io.validate import MAX_LOS_SPEED_M_S, check_carrier, check_los_speed
from trackproc.io.tabular import (DEG, NONFINITE_SIGMA, NONFINITE_VALUE, UNIT_SPELLINGS, UNKNOWN_KIND,
                                  Problems, add_counts)

NONPOSITIVE_SIGMA = "non-positive sigma"
ELEVATION_RANGE = "elevation out of range"
NEGATIVE_RANGE = "negative range"
AZIMUTH_RANGE = "azimuth out of range"
RANGE_RATE_SPEED = "implausible range-rate"
UNKNOWN_STATION = "unknown station"
DUPLICATE_TIME = "duplicated timestamp"

#: Unit as written -> factor to SI (to report values as the user wrote them).
UNIT_FACTORS = {unit: factor for _, factor, unit in UNIT_SPELLINGS.values()}
MODES = LINK_MODES


@dataclass
class IngestOptions:
    """Options of ``trackproc ingest``; sigmas are the defaults for samples that have none."""

    carrier_hz: float | None = None       # nominal carrier frequency, Hz
    doppler_mode: str | None = None       # "one-way" | "two-way"
    max_gap_s: float = 300.0              # pass split where samples are further apart, s
    drop_invalid: bool = False
    sigma_range_m: float = 10.0
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
    warnings for the user (readers' assumptions, station coordinates overridden)."""

    table: PassTable
    dropped: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


#: Reader metadata keys that ingest interprets; any other key is kept under ``meta["inputs"]``.
_INTERPRETED = {"source", "dropped", "carrier_hz", "doppler_mode", "stations", "doptrack", "time_scale",
                "warnings"}


def ingest(raws: Sequence[RawMeasurements], stations: Mapping[str, Station] | None = None,
           options: IngestOptions | None = None) -> IngestResult:
    """Validate and merge raw samples into one canonical pass table (see the module docstring)."""
    options = options or IngestOptions()
    _check_options(options)
    if not raws:
        raise InputError("no input files", expected="at least one INPUT")
    warnings = [f"{raw.source}: {text}" for raw in raws for text in raw.meta.get("warnings") or []]
    known = _known_stations(raws, stations or {}, warnings)
    frame = _merge(raws, options)
    dropped: dict[str, int] = {}
    for raw in raws:
        add_counts(dropped, raw.meta.get("dropped") or {})

    keep, counts = _validate(frame, known, options.drop_invalid)
    add_counts(dropped, counts)
    frame = frame[keep].reset_index(drop=True)
    if frame.empty:
        raise InputError("no valid samples left after dropping invalid rows",
                         file=", ".join(r.source for r in raws),
                         found=", ".join(f"{n} {reason}" for reason, n in dropped.items()) or "none",
                         expected="at least one valid sample")
    carrier_hz, mode = _doppler_settings(raws, frame, options)

    frame = frame.sort_values(["station", "time", "kind"], kind="mergesort").reset_index(drop=True)
    frame["pass_id"] = assign_pass_ids(frame, options.max_gap_s)
    meta = _meta(raws, frame, known, options, carrier_hz, mode, dropped)
    out = pd.DataFrame({
        "time": frame["time"],
        **{c: frame[c].astype(str) for c in ("station", "pass_id", "kind")},
        "value": frame["value"].astype(np.float64),
        "sigma": frame["sigma"].astype(np.float64),
    })[list(COLUMNS)]
    return IngestResult(PassTable(out, meta), dropped, warnings)


def _meta(raws, frame, known, options: IngestOptions, carrier_hz, mode, dropped) -> dict:
    """File metadata: provenance, settings, stations used, reader extras (see io.passfile)."""
    meta = base_meta(
        carrier_hz=carrier_hz,
        doppler_mode=mode,
        sources=[raw.source for raw in raws],
        stations={name: known[name].as_dict() for name in sorted(frame["station"].unique())},
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


def _merge(raws: Sequence[RawMeasurements], options: IngestOptions) -> pd.DataFrame:
    """All inputs in one frame (input order), with source, unit and source columns per sample."""
    defaults = options.default_sigmas()
    pieces = []
    for index, raw in enumerate(raws):
        frame = raw.frame
        missing = [c for c in ("time", "station", "kind", "value", "sigma", "row") if c not in frame.columns]
        if missing:
            raise InputError("reader returned incomplete samples", file=raw.source, column=missing[0])
        kind = frame["kind"].astype(str).to_numpy(dtype=object)
        sigma = frame["sigma"].to_numpy(dtype=np.float64).copy()
        default = np.array([defaults.get(k, math.nan) for k in kind])
        sigma = np.where(np.isnan(sigma), default, sigma)
        pieces.append(pd.DataFrame({
            "time": pd.to_datetime(frame["time"], utc=True).dt.as_unit("ns"),
            "station": frame["station"].astype(str).to_numpy(dtype=object),
            "pass_id": (frame["pass_id"].fillna("").astype(str).to_numpy(dtype=object)
                        if "pass_id" in frame.columns else np.full(len(frame), "", dtype=object)),
            "kind": kind,
            "value": frame["value"].to_numpy(dtype=np.float64),
            "sigma": sigma,
            "row": frame["row"].to_numpy(dtype=np.int64),
            "unit": (frame["unit"].astype(str).to_numpy(dtype=object) if "unit" in frame.columns
                     else np.full(len(frame), "", dtype=object)),
            "source": raw.source,
            "input": index,
            "value_column": [raw.column.get(k, "value") for k in kind],
            "sigma_column": [raw.column.get(f"sigma:{k}", "sigma") for k in kind],
        }))
    frame = pd.concat(pieces, ignore_index=True) if pieces else pd.DataFrame()
    if frame.empty:
        raise InputError("empty input", file=", ".join(r.source for r in raws), found="no samples",
                         expected="at least one measurement")
    return frame


def _unit_factors(units: np.ndarray) -> np.ndarray:
    """Per sample, the factor from the unit the file used to SI (1 where unknown)."""
    return pd.Series(units, dtype=object).map(UNIT_FACTORS).fillna(1.0).to_numpy(dtype=np.float64)


def _validate(frame: pd.DataFrame, known: Mapping[str, Station], drop_invalid: bool):
    """Row checks over the merged frame -> (rows to keep, dropped count per reason)."""
    rows = frame["row"].to_numpy()
    order = frame["input"].to_numpy() * (int(rows.max()) + 1) + rows
    problems = Problems(rows, frame["source"].to_numpy(dtype=object), order=order)
    kind = frame["kind"].to_numpy(dtype=object)
    value = frame["value"].to_numpy()
    sigma = frame["sigma"].to_numpy()
    units = frame["unit"].to_numpy(dtype=object)
    factors = _unit_factors(units)
    value_written, sigma_written = value / factors, sigma / factors
    value_col = frame["value_column"].to_numpy(dtype=object)
    sigma_col = frame["sigma_column"].to_numpy(dtype=object)

    problems.add(UNKNOWN_KIND, ~np.isin(kind, KINDS), column="kind", found=kind,
                 expected="one of " + ", ".join(KINDS))
    problems.add(NONFINITE_VALUE, ~np.isfinite(value), column=value_col, found=value_written,
                 expected="a finite number")
    problems.add(NONFINITE_SIGMA, ~np.isfinite(sigma), column=sigma_col, found=sigma_written,
                 expected="a finite sigma > 0")
    problems.add(NONPOSITIVE_SIGMA, sigma <= 0, column=sigma_col, found=sigma_written,
                 expected="sigma > 0")
    elevation = (kind == "elevation") & np.isfinite(value)
    in_deg = units == "deg"
    problems.add(ELEVATION_RANGE, elevation & (np.abs(value) > math.pi / 2 + 1e-12), column=value_col,
                 found=value_written,
                 expected=lambda i: ("an elevation in [-90, 90] deg" if in_deg[i]
                                     else "an elevation in [-pi/2, pi/2] rad"))
    finite = np.isfinite(value)
    problems.add(NEGATIVE_RANGE, finite & (kind == "range") & (value < 0), column=value_col, found=value_written,
                 expected="a range >= 0")
    problems.add(AZIMUTH_RANGE, finite & (kind == "azimuth") & ((value < -math.pi) | (value > 2 * math.pi)),
                 column=value_col, found=value_written,
                 expected=lambda i: ("an azimuth in [-180, 360] deg" if in_deg[i]
                                     else "an azimuth in [-pi, 2 pi] rad"))
    problems.add(RANGE_RATE_SPEED, finite & (kind == "range_rate") & (np.abs(value) > MAX_LOS_SPEED_M_S),
                 column=value_col, found=value_written,
                 expected=f"|range-rate| <= {MAX_LOS_SPEED_M_S / 1000:g} km/s (an Earth orbit); is the unit right?")
    station = frame["station"].to_numpy(dtype=object)
    names = sorted(known)
    listed = ", ".join(names[:20]) + (" ..." if len(names) > 20 else "")
    problems.add(UNKNOWN_STATION, ~np.isin(station, names), column="station", found=station,
                 expected=(f"a station of the stations table or of the input ({listed})" if names
                           else "a station defined in --stations FILE (none given)"))
    _add_duplicates(problems, frame)
    return problems.resolve(drop_invalid)


def _add_duplicates(problems: Problems, frame: pd.DataFrame) -> None:
    """Same station, kind and time twice: the later rows (input order) are the duplicates.

    Rows already invalid for another reason do not count, so ``drop_invalid`` keeps the valid one.
    """
    valid = np.flatnonzero(~problems.invalid())
    sub = frame.iloc[valid]
    duplicated = sub.duplicated(["station", "kind", "time"], keep="first").to_numpy()
    if not duplicated.any():
        return
    group = sub.groupby(["station", "kind", "time"], sort=False).ngroup().to_numpy()
    first_of_group = pd.Series(valid).groupby(group).transform("min").to_numpy()
    mask = np.zeros(len(frame), dtype=bool)
    mask[valid[duplicated]] = True
    first = np.full(len(frame), -1)
    first[valid] = first_of_group
    source, rows, times = frame["source"].to_numpy(), frame["row"].to_numpy(), frame["time"]

    def detail(i: int) -> str:
        j = first[i]
        return (f"duplicated timestamp for station {frame['station'].iat[i]} and kind "
                f"{frame['kind'].iat[i]} (first at {source[j]} row {rows[j]})")

    problems.add(DUPLICATE_TIME, mask, column=frame["value_column"].to_numpy(dtype=object),
                 found=lambda i: iso_utc(times.iat[i], 6),
                 expected="one sample per station, kind and time", detail=detail)


def _doppler_settings(raws: Sequence[RawMeasurements], frame: pd.DataFrame, options: IngestOptions):
    """Carrier (Hz) and mode from the options or the inputs; required with Doppler samples."""
    settings = {}
    for key, option, flag in (("carrier_hz", options.carrier_hz, "--carrier-hz"),
                              ("doppler_mode", options.doppler_mode, "--mode")):
        value = option
        for raw in raws:
            given = raw.meta.get(key)
            if given is None:
                continue
            if value is None:
                value = given
            elif not _same(value, given):
                raise InputError(f"conflicting {key}", file=raw.source, column=flag, found=given,
                                 expected=f"{value} as {'given by ' + flag if option is not None else 'in the other inputs'}")
        settings[key] = value
    doppler = frame["kind"].to_numpy(dtype=object) == "doppler"
    if doppler.any():
        first = int(np.flatnonzero(doppler)[0])
        where = {"file": frame["source"].iat[first], "row": int(frame["row"].iat[first])}
        if settings["carrier_hz"] is None:
            raise InputError("Doppler samples need the nominal carrier frequency", column="--carrier-hz",
                             expected="--carrier-hz F (Hz)", **where)
        if settings["doppler_mode"] is None:
            raise InputError("Doppler samples need the link mode", column="--mode",
                             expected="--mode one-way or --mode two-way", **where)
    carrier = settings["carrier_hz"]
    if carrier is not None:
        carrier = check_carrier(carrier, column="--carrier-hz" if options.carrier_hz is not None else "carrier_hz")
        for source in pd.unique(frame["source"][doppler]):
            mine = doppler & (frame["source"] == source).to_numpy()
            check_los_speed(frame["value"].to_numpy()[mine], "doppler", carrier_hz=carrier,
                            mode=settings["doppler_mode"], file=source, rows=frame["row"].to_numpy()[mine],
                            column=str(frame["value_column"].to_numpy()[mine][0]))
    return carrier, settings["doppler_mode"]


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return abs(a - b) <= 1e-12 * max(abs(a), abs(b))
    return a == b


def assign_pass_ids(frame: pd.DataFrame, max_gap_s: float) -> np.ndarray:
    """Pass ids: given ones kept; others ``<station>-NNN``, a new pass after a gap > ``max_gap_s``.

    ``frame`` must be sorted by station then time; numbering is per station by start time and
    skips ids the input already uses.
    """
    ids = frame["pass_id"].to_numpy(dtype=object).copy()
    need = ids == ""
    if not need.any():
        return ids
    gap_ns = int(round(max_gap_s * 1e9))
    times = frame["time"].dt.tz_convert("UTC").dt.tz_localize(None).dt.as_unit("ns").to_numpy().astype(np.int64)
    stations = frame["station"].to_numpy(dtype=object)
    for station in pd.unique(stations[need]):
        idx = np.flatnonzero(need & (stations == station))
        taken = set(ids[(stations == station) & ~need])
        new_pass = np.r_[True, np.diff(times[idx]) > gap_ns]
        number = 0
        labels = []
        for _ in range(int(new_pass.sum())):
            number += 1
            while f"{station}-{number:03d}" in taken:
                number += 1
            labels.append(f"{station}-{number:03d}")
        ids[idx] = np.array(labels, dtype=object)[np.cumsum(new_pass) - 1]
    return ids
