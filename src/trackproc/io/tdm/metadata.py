"""The meaning of a TDM segment's metadata block (:func:`segment_config`): time system, time-tag
reference, participants and ``PATH`` (which station, which link), range units, integration
interval, turnaround ratio, corrections, quality; see :mod:`trackproc.io.tdm` for each convention.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trackproc.errors import InputError
from trackproc.io.tdm.keywords import PARTICIPANT_NUMBERS, SUPPORTED_TIME_SYSTEMS
from trackproc.io.tdm.kvn import NUMBER_RE, UNIT_SUFFIX_RE, Segment

@dataclass
class SegmentConfig:
    number: int
    time_system: str
    participants: dict
    path: list | None
    path_problem: str | None   # why this path cannot give station measurements, or None
    mode: str | None           # "one-way" | "two-way" | None (no PATH)
    station: str | None
    angle_type: str | None
    range_units: str
    integration_interval: float | None
    integration_ref: str | None
    freq_offset: float
    turnaround: float | None
    corrections: dict          # keyword -> value to add to raw values (empty when applied)


def segment_config(seg: Segment, source: str, warnings: list) -> tuple[SegmentConfig, dict]:
    """The :class:`SegmentConfig` of a segment and its summary for ``meta["tdm_segment_info"]``;
    warnings are appended to ``warnings``; :class:`InputError` for metadata that cannot be read.

    Over 100 lines: each keyword of the segment's META block is read in turn through the local
    ``error``/``text``/``number`` over that block; split, every part would take them along."""
    def error(message, row=None, column=None, found=None, expected=None):
        return InputError(message, file=source, row=row, column=column, found=found, expected=expected)

    meta = seg.meta

    def text(key, default=None):
        return meta[key][0] if key in meta else default

    def number(key, default=None):
        if key not in meta:
            return default
        value, row = meta[key]
        value = UNIT_SUFFIX_RE.sub("", value)
        if not NUMBER_RE.match(value) or not math.isfinite(float(value)):
            raise error("non-numeric metadata value", row=row, column=key,
                        found=value, expected="a number")
        return float(value)

    if "TIME_SYSTEM" not in meta:
        raise error(f"TIME_SYSTEM missing in the META block at row {seg.meta_row}",
                    row=seg.meta_row, column="TIME_SYSTEM",
                    expected="TIME_SYSTEM = UTC (or TAI, GPS, TT)")
    ts, ts_row = meta["TIME_SYSTEM"]
    ts = ts.strip().upper()
    if ts not in SUPPORTED_TIME_SYSTEMS:
        raise error("unsupported time system", row=ts_row, column="TIME_SYSTEM",
                    found=ts, expected="UTC, TAI, GPS or TT")
    ts = "TT" if ts == "TDT" else ts

    if "TIMETAG_REF" in meta and text("TIMETAG_REF").strip().upper() != "RECEIVE":
        raise error("only reception time tags are supported (moving a transmit time "
                    "tag to reception needs the light time)",
                    row=meta["TIMETAG_REF"][1], column="TIMETAG_REF",
                    found=text("TIMETAG_REF"), expected="RECEIVE")

    participants = {i: meta[f"PARTICIPANT_{i}"][0].strip() for i in PARTICIPANT_NUMBERS
                    if f"PARTICIPANT_{i}" in meta}

    mode_kw = (text("MODE") or "SEQUENTIAL").strip().upper()
    path = None
    path_problem = None
    link_mode = None
    station = None
    if mode_kw == "SINGLE_DIFF" or "PATH_1" in meta or "PATH_2" in meta:
        path_problem = "MODE = SINGLE_DIFF (differenced data between two paths)"
    elif "PATH" in meta:
        value, row = meta["PATH"]
        try:
            path = [int(p) for p in value.replace(" ", "").split(",")]
        except ValueError:
            raise error("unreadable PATH", row=row, column="PATH", found=value,
                        expected="participant indices separated by commas, "
                        "e.g. 2,1 or 1,2,1") from None
        for p in path:
            if p not in participants:
                raise error(f"PATH names participant {p}, which is not defined",
                            row=row, column="PATH", found=value,
                            expected=f"indices among {sorted(participants)}")
        if len(path) == 2 and path[0] != path[1]:
            link_mode, station = "one-way", participants[path[-1]]
        elif len(path) == 3 and path[0] == path[2] and path[1] != path[0]:
            link_mode, station = "two-way", participants[path[0]]
        else:
            path_problem = (f"PATH = {value} (relay, three-way or other path: not a "
                            "station-to-spacecraft measurement)")
    else:
        if 1 not in participants:
            raise error(f"PARTICIPANT_1 missing in the META block at row "
                        f"{seg.meta_row}", row=seg.meta_row, column="PARTICIPANT_1")
        station = participants[1]

    units = (text("RANGE_UNITS") or "km").strip()
    if units.lower() in ("km", "s"):
        units = units.lower()
    elif units.upper() == "RU":
        units = "RU"
    else:
        raise error("unknown RANGE_UNITS", row=meta["RANGE_UNITS"][1],
                    column="RANGE_UNITS", found=units, expected="km, s or RU")

    iref = text("INTEGRATION_REF")
    if iref is not None:
        iref = iref.strip().upper()
        if iref not in ("START", "MIDDLE", "END"):
            raise error("unknown INTEGRATION_REF", row=meta["INTEGRATION_REF"][1],
                        column="INTEGRATION_REF", found=iref,
                        expected="START, MIDDLE or END")
    interval = number("INTEGRATION_INTERVAL")
    if interval is not None and interval < 0:
        raise error("negative integration interval",
                    row=meta["INTEGRATION_INTERVAL"][1],
                    column="INTEGRATION_INTERVAL", found=interval, expected=">= 0 s")

    num, den = number("TURNAROUND_NUMERATOR"), number("TURNAROUND_DENOMINATOR")
    turnaround = None
    if num is not None or den is not None:
        if num is None or den is None or num <= 0 or den <= 0:
            key = "TURNAROUND_DENOMINATOR" if num is not None else "TURNAROUND_NUMERATOR"
            row = meta.get(key, meta.get("TURNAROUND_NUMERATOR", (None, seg.meta_row)))[1]
            raise error("the turnaround ratio needs a positive numerator and "
                        "denominator", row=row, column=key,
                        expected="TURNAROUND_NUMERATOR and TURNAROUND_DENOMINATOR > 0")
        turnaround = num / den

    corrections = {}
    correction_keys = ("CORRECTION_RANGE", "CORRECTION_DOPPLER", "CORRECTION_ANGLE_1",
                       "CORRECTION_ANGLE_2", "CORRECTION_RECEIVE", "CORRECTION_TRANSMIT")
    given = {k: number(k) for k in correction_keys if k in meta}
    nonzero = {k: v for k, v in given.items() if v != 0.0}
    applied = text("CORRECTIONS_APPLIED")
    if applied is not None:
        applied = applied.strip().upper()
        if applied not in ("YES", "NO"):
            raise error("CORRECTIONS_APPLIED must be YES or NO",
                        row=meta["CORRECTIONS_APPLIED"][1],
                        column="CORRECTIONS_APPLIED", found=applied,
                        expected="YES or NO")
    if nonzero:
        if applied is None:
            key = next(iter(nonzero))
            raise error(f"{key} is given without CORRECTIONS_APPLIED: cannot tell "
                        "whether the data already include it", row=meta[key][1],
                        column="CORRECTIONS_APPLIED",
                        expected="CORRECTIONS_APPLIED = YES or NO")
        if applied == "NO":
            corrections = nonzero

    quality = (text("DATA_QUALITY") or "").strip().upper() or None
    if quality == "DEGRADED":
        warnings.append(f"segment {seg.number}: DATA_QUALITY = DEGRADED "
                        f"(row {meta['DATA_QUALITY'][1]})")
    delays = {k: number(k) for k in sorted(meta)
              if k.startswith(("TRANSMIT_DELAY_", "RECEIVE_DELAY_"))}
    delays = {k: v for k, v in delays.items() if v}
    if delays:
        warnings.append(
                        f"segment {seg.number}: " + ", ".join(f"{k} = {v:g} s" for k, v in delays.items())
                        + " not applied (the TDM does not say whether the data include them)")
    if "RANGE_MODULUS" in meta and any(o.key == "RANGE" for o in seg.obs):
        modulus = number("RANGE_MODULUS")
        if modulus:
            warnings.append(f"segment {seg.number}: RANGE_MODULUS = {modulus:g} "
                            f"{units} not applied (ranges taken as unambiguous)")

    info = {
        "segment": seg.number, "meta_row": seg.meta_row, "time_system": ts,
        "participants": {str(k): v for k, v in participants.items()},
        "path": text("PATH"), "station": station, "link": link_mode,
        "data_quality": quality, "corrections_added": sorted(corrections),
    }
    return SegmentConfig(
        number=seg.number, time_system=ts, participants=participants, path=path,
        path_problem=path_problem, mode=link_mode, station=station,
        angle_type=(text("ANGLE_TYPE") or "").strip().upper() or None,
        range_units=units, integration_interval=interval, integration_ref=iref,
        freq_offset=number("FREQ_OFFSET", 0.0), turnaround=turnaround,
        corrections=corrections), info
