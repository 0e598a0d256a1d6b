"""DopTrack adapter: received-frequency CSVs with a YAML sidecar -> one-way Doppler samples.

The TU Delft DopTrack archive (``doptrack-delfic3``) stores one pass per CSV,
``data/<stem>.csv``, with the header line ``# time,frequency,rangerate``: ``time`` in seconds
since ``tracking.epoch`` (UTC) of the sidecar ``metadata/<stem>.yml``, ``frequency`` the received
carrier in Hz. The sidecar also gives the station (``station.name``, ``station.position``
latitude/longitude in degrees and altitude in metres, WGS-84 geodetic) and the upstream team's
own time and frequency of closest approach (``tracking.tca``, ``tracking.fca``), kept in the
metadata under ``doptrack``.

Each sample becomes ``kind = doppler`` with ``value = frequency - carrier_hz`` (Hz), one-way:
Doppler = received − nominal carrier, so range-rate ≈ −c · doppler / carrier (positive when
receding). The carrier is ``--carrier-hz`` when given, else the Delfi-C3 nominal downlink
:data:`DELFI_C3_CARRIER_HZ` when ``satellite.name`` is Delfi-C3. The transmitter's true frequency
differs from the nominal one by an offset and a drift, which later commands estimate.

Each file is one pass as recorded upstream: ``pass_id`` is the file's stem (for stdin, the
sidecar's), e.g. ``Delfi-C3_32789_202004011044``, so ``--max-gap`` does not split it.

The file's ``rangerate`` column is ignored: upstream derived it as ``-c (f - fca) / fca`` with
their own fitted ``fca`` as the rest frequency, i.e. it already contains a fit result.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from trackproc.errors import InputError
from trackproc.io.atomic import read_input_bytes
from trackproc.io.raw import RawMeasurements
from trackproc.io.tabular import (NONFINITE_VALUE, UNPARSEABLE_TIME, WRONG_TYPE, Column, Problems, SourceTable,
                                  column_numbers, parse_text_table)
from trackproc.io.validate import check_iso_year, check_name, check_station, check_year
from trackproc.isotime import iso_utc

if TYPE_CHECKING:
    import pandas as pd

#: Nominal downlink carrier of Delfi-C3 (NORAD 32789), Hz: 145.870 MHz (TU Delft, DopTrack).
DELFI_C3_CARRIER_HZ = 145.870e6
#: Nominal carriers by ``satellite.name`` (lower case) used when ``--carrier-hz`` is not given.
NOMINAL_CARRIERS_HZ = {"delfi-c3": DELFI_C3_CARRIER_HZ}

#: Time-tag sigma (s) of known stations by ``station.name`` (lower case), kept as the station's
#: ``time_sigma_s`` (refine's time-tag consider term; docs/refine.md, "Station timing"). DopTrack's
#: tags lag or lead the satellite by 0.1-2 s from pass to pass (a fresh TLE is good to ~0.05 s):
#: 1.2 s RMS about zero (maximum likelihood with each pass's own formal shift sigma; one pass
#: of 24 beyond 3 sigma left out), measured on the development passes of 1-10 April 2020
#: against each pass's own TLE (``benchmarks/doptrack_timing.py``). A stations table or
#: ``--time-tag-sigma`` overrides it.
KNOWN_STATION_TIME_SIGMA_S = {"doptrack": 1.2}

_HEADER = re.compile(r"#\s*time\s*,\s*frequency\s*,\s*rangerate\s*$", re.IGNORECASE)


def looks_like_doptrack(head: str) -> bool:
    """True when the first line is DopTrack's ``# time,frequency,rangerate`` header."""
    first = head.lstrip().splitlines()[0] if head.strip() else ""
    return bool(_HEADER.match(first.strip()))


def find_sidecar(data_path: Path) -> Path | None:
    """``../metadata/<stem>.yml`` beside the data folder, else ``<stem>.yml`` in the same folder."""
    stem = data_path.stem
    for folder in (data_path.parent.parent / "metadata", data_path.parent):
        for suffix in (".yml", ".yaml"):
            candidate = folder / (stem + suffix)
            if candidate.is_file():
                return candidate
    return None


#: Largest time offset from tracking.epoch accepted, s (a pass lasts minutes).
MAX_OFFSET_S = 86400.0
#: Largest YAML sidecar read, bytes (a real one is under 1 kB).
MAX_SIDECAR_BYTES = 1 << 20


def _safe_loader():
    """PyYAML's SafeLoader without aliases: ``*name`` repeats a node without copying it, so a chain
    of aliases in an 800-byte file expands to gigabytes once the value is used as text."""
    import yaml  # start-up: PyYAML (~10 ms) only when a sidecar is read (tabular imports this module)

    class NoAliasLoader(yaml.SafeLoader):
        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                raise yaml.constructor.ConstructorError(
                    None, None, "YAML aliases (*name) are not accepted in a DopTrack sidecar", event.start_mark)
            return super().compose_node(parent, index)

    return NoAliasLoader


def load_sidecar(path: Path) -> dict:
    """The YAML sidecar as a dict (InputError with the line on a syntax error), loaded safely:
    bounded size, no aliases, no tags beyond plain YAML."""
    data = read_input_bytes(path, limit=MAX_SIDECAR_BYTES)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"cannot read the DopTrack sidecar ({exc.__class__.__name__})",
                         file=str(path), expected="UTF-8 YAML text") from None
    import yaml  # start-up: as in _safe_loader

    try:
        doc = yaml.load(text, Loader=_safe_loader())  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise InputError(f"invalid YAML ({getattr(exc, 'problem', None) or exc})", file=str(path),
                         row=mark.line + 1 if mark else None) from None
    except RecursionError:
        raise InputError("YAML nested too deeply", file=str(path), expected="a DopTrack sidecar") from None
    if not isinstance(doc, dict):
        raise InputError("not a DopTrack sidecar", file=str(path), found=type(doc).__name__,
                         expected="a YAML mapping with satellite, station and tracking")
    return doc


def _get(doc: dict, dotted: str, source: str, expected: str):
    node = doc
    for key in dotted.split("."):
        if not isinstance(node, dict) or node.get(key) is None:
            raise InputError("missing key in the DopTrack sidecar", file=source, column=dotted,
                             expected=expected)
        node = node[key]
    return node


def _utc(value, source: str, key: str) -> pd.Timestamp:
    """A YAML time (datetime or ISO string; naive = UTC) as a UTC timestamp, within 1678-2261."""
    if not isinstance(value, (str, dt.datetime, dt.date)):
        raise InputError("wrong type in the DopTrack sidecar", file=source, column=key, found=value,
                         expected="YYYY-MM-DD hh:mm:ss[.ffffff] (UTC)")
    check_year(value.year if isinstance(value, (dt.datetime, dt.date)) else 2000, file=source, column=key,
               found=str(value))
    if isinstance(value, str):
        check_iso_year(value, file=source, column=key)
    import pandas as pd  # start-up: pandas (~0.15 s) only when a DopTrack file is read (tabular imports this module)

    try:
        stamp = pd.Timestamp(value)
    except (ValueError, TypeError, OverflowError):
        raise InputError("unparseable time in the DopTrack sidecar", file=source, column=key,
                         found=value, expected="YYYY-MM-DD hh:mm:ss[.ffffff] (UTC)") from None
    if pd.isna(stamp):
        raise InputError("unparseable time in the DopTrack sidecar", file=source, column=key,
                         found=value, expected="YYYY-MM-DD hh:mm:ss[.ffffff] (UTC)")
    return stamp.tz_localize("UTC") if stamp.tzinfo is None else stamp.tz_convert("UTC")


def _number(value, source: str, key: str, expected: str) -> float:
    try:
        out = math.nan if isinstance(value, bool) or not isinstance(value, (int, float, str)) else float(value)
    except (TypeError, ValueError, OverflowError):
        out = math.nan
    if not math.isfinite(out):
        raise InputError("invalid number in the DopTrack sidecar", file=source, column=key,
                         found=value, expected=expected)
    return out


def _iso(value) -> object:
    if isinstance(value, (dt.datetime, dt.date)):   # a pandas Timestamp is a datetime
        return iso_utc(value, 6)
    if isinstance(value, dict):
        return {str(k): _iso(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_iso(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def read_doptrack(data: bytes, source: str, *, data_path: Path | None = None,
                  sidecar: str | Path | None = None, carrier_hz: float | None = None,
                  drop_invalid: bool = False) -> RawMeasurements:
    """One DopTrack pass -> raw one-way Doppler samples (Hz) of the sidecar's station.

    ``data_path`` locates the sidecar (see :func:`find_sidecar`) unless ``sidecar`` is given;
    ``carrier_hz`` is the nominal carrier in Hz (default: from the satellite name).

    Over 100 lines with this docstring; its code is under 100.
    """
    side_path = Path(sidecar) if sidecar is not None else (find_sidecar(data_path) if data_path else None)
    if side_path is None:
        where = f"{data_path.parent.parent / 'metadata'}/ or {data_path.parent}/" if data_path else "it"
        raise InputError("DopTrack data needs its YAML sidecar", file=source,
                         expected=f"<same name>.yml in {where}, or --sidecar FILE")
    doc = load_sidecar(side_path)
    side = str(side_path)
    for key in ("station", "tracking", "station.position"):
        node = doc
        for part in key.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if node is not None and not isinstance(node, dict):
            raise InputError("wrong type in the DopTrack sidecar", file=side, column=key, found=node,
                             expected="a mapping")
    epoch = _utc(_get(doc, "tracking.epoch", side, "the UTC time that 'time' counts from"), side,
                 "tracking.epoch")
    station = _get(doc, "station.name", side, "the station name")
    if isinstance(station, int) and not isinstance(station, bool):
        station = str(station)
    check_name(station, "station name", file=side, column="station.name")
    position = {
        "lat_deg": _number(_get(doc, "station.position.latitude", side, "degrees"), side,
                           "station.position.latitude", "degrees in [-90, 90]"),
        "lon_deg": _number(_get(doc, "station.position.longitude", side, "degrees"), side,
                           "station.position.longitude", "degrees"),
        "height_m": _number(_get(doc, "station.position.altitude", side, "metres"), side,
                            "station.position.altitude", "metres above the WGS-84 ellipsoid"),
    }
    check_station(station, position["lat_deg"], position["lon_deg"], position["height_m"], file=side,
                  columns={"lat_deg": "station.position.latitude", "lon_deg": "station.position.longitude",
                           "height_m": "station.position.altitude"})
    timing = KNOWN_STATION_TIME_SIGMA_S.get(station.lower())
    if timing is not None:
        position["time_sigma_s"] = timing
    satellite_doc = doc.get("satellite") or {}
    if not isinstance(satellite_doc, dict):
        raise InputError("wrong type in the DopTrack sidecar", file=side, column="satellite", found=satellite_doc,
                         expected="a mapping with name, noradid, tle")
    satellite = satellite_doc.get("name", "")
    if not isinstance(satellite, str):
        raise InputError("wrong type in the DopTrack sidecar", file=side, column="satellite.name",
                         found=satellite, expected="the satellite name (text)")
    if carrier_hz is None:
        carrier_hz = NOMINAL_CARRIERS_HZ.get(satellite.lower())
        if carrier_hz is None:
            raise InputError(f"no nominal carrier known for satellite {satellite or '(unnamed)'!r}",
                             file=source, expected="--carrier-hz F (the nominal downlink, Hz)")

    text = parse_text_table(data, source, header=["time", "frequency", "rangerate"])
    table = SourceTable(source, {k: Column(k, text=v) for k, v in text.cells.items()},
                        text.rows, 1, {})
    if len(table) == 0:
        raise InputError("empty input", file=source, row=2, found="no data rows",
                         expected="rows of time,frequency,rangerate")
    problems = Problems(table.rows, source)
    seconds, missing_t, wrong_t = column_numbers(table, table.columns["time"])
    bad_time = missing_t | wrong_t | ~np.isfinite(seconds)
    far = ~bad_time & (np.abs(np.where(bad_time, 0.0, seconds)) > MAX_OFFSET_S)
    problems.add(UNPARSEABLE_TIME, far, column="time", found=text.cells["time"],
                 expected=f"seconds since tracking.epoch within +-{MAX_OFFSET_S:g} s (a pass)")
    bad_time |= far
    problems.add(UNPARSEABLE_TIME, bad_time, column="time", found=text.cells["time"],
                 expected="seconds since tracking.epoch")
    frequency, missing_f, wrong_f = column_numbers(table, table.columns["frequency"])
    problems.add(WRONG_TYPE, wrong_f, column="frequency", found=text.cells["frequency"],
                 expected="the received frequency in Hz")
    problems.add(NONFINITE_VALUE, missing_f, column="frequency", found="", expected="a finite frequency, Hz")
    keep, dropped = problems.resolve(drop_invalid)

    import pandas as pd  # start-up: as in _utc

    offset_ns = np.round(np.where(bad_time, 0.0, seconds) * 1e9).astype(np.int64)
    times = pd.DatetimeIndex(epoch.as_unit("ns").value + offset_ns).tz_localize("UTC")
    frame = pd.DataFrame({
        "time": times,
        "station": station,
        "kind": "doppler",
        "value": frequency - carrier_hz,
        "sigma": np.nan,
        "row": table.rows,
        "unit": "Hz",
        "pass_id": (data_path or side_path).stem,
    })[keep].reset_index(drop=True)
    tracking = doc.get("tracking") or {}
    tracking = {k: v for k, v in tracking.items()}
    details = _iso({
        "sidecar": side,
        "satellite": satellite,
        "norad_id": (doc.get("satellite") or {}).get("noradid"),
        "tle": [((doc.get("satellite") or {}).get("tle") or {}).get(k) for k in ("line1", "line2")],
        "epoch": tracking.get("epoch"),
        "tca": tracking.get("tca"), "tca_error_s": tracking.get("tca_error"),
        "fca_hz": tracking.get("fca"), "fca_error_hz": tracking.get("fca_error"),
        "prediction": doc.get("prediction"),
    })
    meta = {
        "source": source, "dropped": dropped, "carrier_hz": float(carrier_hz),
        "doppler_mode": "one-way", "stations": {station: position},
        "doptrack": {source: details},
    }
    return RawMeasurements(frame=frame, source=source,
                           column={"time": "time", "station": "station.name (sidecar)",
                                   "doppler": "frequency"}, meta=meta)
