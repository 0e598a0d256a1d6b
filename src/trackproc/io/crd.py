"""ILRS Consolidated laser Ranging Data (CRD, v1 and v2) normal points -> two-way range samples.

A CRD file is a sequence of sessions (``H1`` ... ``H8``, the file ends with ``H9``); record
types are case-insensitive. What is read (ILRS CRD v1.01 and v2.01 specifications):

- ``H1 CRD version year month day hour``: format version 1 or 2;
- ``H2 name CDP-pad-id sys-no occ-seq time-scale [network]``: the station is named by its CDP
  pad id (e.g. ``7090``, as in SINEX station files); time scale 3, 4, 7 or 10 (UTC variants);
- ``H3 target ILRS-id SIC NORAD time-scale target-type``: the target;
- ``H4 type start(y m d h m s) end(y m d h m s) release trop-applied com-applied amp-applied
  station-delay-applied spacecraft-delay-applied range-type quality``: the session span (its
  start date dates the seconds of day), the corrections already applied, the range type
  (2 = two-way is read; one-way and receive-only sessions are refused);
- ``C0 detail wavelength(nm) config-id ...``: the laser wavelength of a configuration;
- ``11 sod tof config-id epoch-event window n-raw rms ...``: a normal point — seconds of day
  (UTC), two-way time of flight (s), epoch event 0 (ground receive), 1 (bounce) or 2 (ground
  transmit);
- ``20 sod pressure(mbar) temperature(K) humidity(%) origin``: surface meteorology;
- ``10`` (full-rate ranges) are read like ``11`` when a file has no normal points; ``12``,
  ``21``, ``30``, ``40``, ``41``, ``42``, ``50``, ``60``, ``00``, ``C1``-``C7``, ``H5`` are
  accepted and not needed here.

Samples: one ``range`` per normal point, time-tagged at **ground reception**
``t_r = t_transmit + tof`` (event 2), ``t_r = t`` (event 0) or ``t_r ≈ t_bounce + tof/2``
(event 1; exact to the legs' asymmetry ρ̇·tof/c ≲ 1 µs, a few mm), value the one-way
equivalent ``c·tof/2`` (m), the file's link mode ``two-way``. The sessions (station, span,
wavelength, corrections already applied) and the meteorological records go to the metadata
(``crd.sessions``, ``crd.meteo``) for the range corrections
(:mod:`trackproc.pipeline.range_corrections`). A malformed record is an input error whatever
``drop_invalid`` says (the structure of the file is in doubt); invalid values that parse are
left to ingest's checks.
Seconds of day that restart after midnight are moved to the next day (a sample more than an
hour before its session's start).
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.errors import InputError
from trackproc.io.raw import RawMeasurements
from trackproc.io.tabular import decode_text
from trackproc.isotime import iso_utc

#: H2 time-scale codes that are UTC (USNO, GPS-steered, BIPM, station UTC).
UTC_SCALES = {3, 4, 7, 10}
RANGE_TYPES = {0: "no ranges", 1: "one-way", 2: "two-way", 3: "receive times only", 4: "mixed"}
_NS = 1_000_000_000
#: Record types of CRD v1/v2 (header, configuration and data records); anything else is refused.
KNOWN_RECORDS = ({f"H{k}" for k in range(1, 10)} | {f"C{k}" for k in range(0, 8)}
                 | {"00", "10", "11", "12", "20", "21", "30", "40", "41", "42", "50", "60"})


def looks_like_crd(head: str) -> bool:
    """True when the first non-blank line is an ``H1 CRD`` header."""
    for line in head.splitlines():
        fields = line.split()
        if fields:
            return len(fields) >= 2 and fields[0].upper() == "H1" and fields[1].upper() == "CRD"
    return False


def _number(fields, index, name, source, row, *, kind=float):
    try:
        text = fields[index]
    except IndexError:
        raise InputError(f"record {fields[0]} too short", file=source, row=row, column=name,
                         found=f"{len(fields)} fields", expected=f"a {name} in field {index + 1}") from None
    try:
        return kind(text)
    except ValueError:
        if text.lower() == "na":
            return math.nan
        raise InputError(f"invalid {name} in record {fields[0]}", file=source, row=row, column=name,
                         found=text, expected="an integer" if kind is int else "a number") from None


def _date_ns(fields, start, name, source, row) -> int:
    """Nanoseconds since 1970 of ``y m d h m s`` in ``fields[start:start+6]``."""
    import pandas as pd  # start-up: pandas (~0.15 s) only when a CRD file is read (tabular imports this module)

    y, mo, d, h, mi, s = (_number(fields, start + k, name, source, row, kind=int) for k in range(6))
    try:
        return pd.Timestamp(year=y, month=mo, day=d, hour=h, minute=mi, second=s).value
    except ValueError:
        raise InputError(f"invalid {name}", file=source, row=row, column=name,
                         found=" ".join(fields[start:start + 6]), expected="year month day hour minute second") from None


def read_crd(data: bytes, source: str, *, drop_invalid: bool = False) -> RawMeasurements:
    """Parse a CRD file's normal points into two-way range samples (see the module docstring).

    Over 100 lines: one pass over the records, a few lines per record type, so that the rules of
    their order (H4 ... H8 per session, nothing after H9) read in one loop."""
    text = decode_text(data, source)
    session = None
    sessions, meteo = [], {}
    times, full_rate = [], []             # (reception ns, station, value m, line, pass id) of 11 / 10 records
    wavelengths = {}
    version = None
    open_session = None                   # row of an H4 not yet closed by its H8
    ended = None                          # row of the H9 (end of file)
    last_row = 0
    for row, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        last_row = row
        rec = fields[0].upper()
        if rec not in KNOWN_RECORDS:
            raise InputError("unknown CRD record type", file=source, row=row, column="record type", found=fields[0],
                             expected="H1-H9, C0-C7, 00, 10-12, 20, 21, 30, 40-42, 50 or 60 (ILRS CRD v1/v2)")
        if ended is not None and rec != "00":
            raise InputError(f"record {fields[0]} after the end of file (H9)", file=source, row=row,
                             column="record type", found=fields[0], expected=f"nothing after the H9 of row {ended}")
        if rec == "H4" and open_session is not None:
            raise InputError("a new session (H4) before the previous one ended", file=source, row=row,
                             column="record type", found=fields[0], expected=f"H8 closing the H4 of row {open_session}")
        if rec == "H4":
            open_session = row
        elif rec == "H8":
            open_session = None
        elif rec == "H9":
            if open_session is not None:
                raise InputError("end of file (H9) inside a session", file=source, row=row, column="record type",
                                 found=fields[0], expected=f"H8 closing the H4 of row {open_session} first")
            ended = row
        if rec == "H1":
            if len(fields) < 3 or fields[1].upper() != "CRD":
                raise InputError("not a CRD H1 header", file=source, row=row, column="H1", found=line.strip(),
                                 expected="H1 CRD version year month day hour")
            version = _number(fields, 2, "format version", source, row, kind=int)
            if version not in (1, 2):
                raise InputError("unsupported CRD version", file=source, row=row, column="format version",
                                 found=fields[2], expected="1 or 2")
            session = {"row": row, "station": None, "target": None, "start_ns": None}
            wavelengths = {}
        elif session is None and rec not in ("H9", "00"):
            raise InputError(f"record {fields[0]} before the H1 header", file=source, row=row, column="record type",
                             found=fields[0], expected="H1 CRD ... first")
        elif rec == "H2":
            if len(fields) < 6:
                raise InputError("record H2 too short", file=source, row=row, column="H2", found=line.strip(),
                                 expected="H2 name CDP-pad-id system occupancy time-scale")
            session["station"] = fields[2]
            scale = _number(fields, 5, "time scale", source, row, kind=int)
            if scale not in UTC_SCALES:
                raise InputError("unsupported CRD time scale", file=source, row=row, column="time scale",
                                 found=fields[5], expected="3, 4, 7 or 10 (UTC)")
        elif rec == "H3":
            session["target"] = fields[1] if len(fields) > 1 else ""
        elif rec == "H4":
            session["start_ns"] = _date_ns(fields, 2, "session start", source, row)
            session["end_ns"] = _date_ns(fields, 8, "session end", source, row)
            session["troposphere_applied"] = _number(fields, 15, "tropospheric correction applied", source, row,
                                                     kind=int) == 1
            session["com_applied"] = _number(fields, 16, "centre-of-mass correction applied", source, row,
                                             kind=int) == 1
            rtype = _number(fields, 20, "range type", source, row, kind=int)
            if rtype != 2:
                raise InputError("unsupported CRD range type", file=source, row=row, column="range type",
                                 found=f"{rtype} ({RANGE_TYPES.get(rtype, 'unknown')})",
                                 expected="2 (two-way ranges)")
            sessions.append(session)
        elif rec == "C0":
            config = fields[3] if len(fields) > 3 else ""
            wavelengths[config] = _number(fields, 2, "wavelength", source, row)
            session["wavelength_nm"] = wavelengths[config]
        elif rec in ("10", "11"):
            if session.get("start_ns") is None or session.get("station") is None:
                raise InputError(f"record {rec} before the session's H2/H4 headers", file=source, row=row,
                                 column="record type", found=rec, expected="H2 and H4 before the data")
            sod = _number(fields, 1, "seconds of day", source, row)
            tof = _number(fields, 2, "time of flight", source, row)
            event = _number(fields, 4, "epoch event", source, row, kind=int)
            if event not in (0, 1, 2):
                raise InputError("unsupported epoch event", file=source, row=row, column="epoch event",
                                 found=fields[4], expected="0 (ground receive), 1 (bounce) or 2 (ground transmit)")
            if not (math.isfinite(sod) and 0 <= sod < 86401) or not (math.isfinite(tof) and 0 < tof < 1):
                bad, name = ((fields[1], "seconds of day") if not (math.isfinite(sod) and 0 <= sod < 86401)
                             else (fields[2], "time of flight"))
                raise InputError(f"invalid {name} in record {rec}", file=source, row=row, column=name, found=bad,
                                 expected="seconds in [0, 86400]" if name == "seconds of day"
                                 else "a two-way time of flight in (0, 1) s")
            t_ns = _sod_ns(session, sod) + round({0: 0.0, 1: tof / 2, 2: tof}[event] * _NS)
            target = full_rate if rec == "10" else times
            sigma = _normal_point_sigma(fields) if rec == "11" else math.nan
            target.append((t_ns, session["station"], C_LIGHT * tof / 2, row, _pass_id(session), sigma))
        elif rec == "20":
            sod = _number(fields, 1, "seconds of day", source, row)
            values20 = [_number(fields, k, name, source, row) for k, name in
                        ((2, "pressure"), (3, "temperature"), (4, "humidity"))]
            meteo.setdefault(session["station"] or "", []).append((_sod_ns(session, sod), *values20))
    if version is None:
        raise InputError("not a CRD file", file=source, row=1, found="no H1 header",
                         expected="an ILRS CRD file (H1 CRD ...)")
    if open_session is not None or ended is None:
        raise InputError("the file ends without its end records (cut short?)", file=source, row=last_row,
                         column="record type", found="no H8 after the H4 of row %d" % open_session
                         if open_session is not None else "no H9",
                         expected="each session closed by H8 and the file by H9")
    samples = times or full_rate
    if not samples:
        raise InputError("no range records", file=source, row=1, found="no 11 (or 10) records",
                         expected="CRD normal points")
    import pandas as pd  # start-up: as in _date_ns

    t_ns, stations, values, rows, pass_ids, sigmas = (list(x) for x in zip(*samples))
    frame = pd.DataFrame({
        "time": pd.to_datetime(np.array(t_ns, dtype=np.int64), utc=True).as_unit("ns"),
        "station": np.array(stations, dtype=object),
        "pass_id": np.array(pass_ids, dtype=object),
        "kind": "range",
        "value": np.array(values, float),
        "sigma": np.array(sigmas, float),
        "row": np.array(rows, dtype=np.int64),
        "unit": "m",
    })
    meta = {"source": source, "doppler_mode": "two-way", "dropped": {},
            "crd": {"version": version, "records": "normal points" if times else "full rate",
                    "sessions": [_session_meta(s) for s in sessions],
                    "meteo": {st: _meteo_meta(recs) for st, recs in sorted(meteo.items()) if st}}}
    return RawMeasurements(frame=frame, source=source, column={"range": "time of flight", "time": "seconds of day"},
                           meta=meta)


def _normal_point_sigma(fields) -> float:
    """The one-way precision of a normal point (m): ``c/2 · rms / √n`` from its record 11's bin
    RMS (ps, two-way, of the ``n`` raw ranges about the trend; ILRS CRD v1.01/v2.01 record 11
    fields 8 and 7), the standard error of the bin's mean; the RMS alone when ``n`` is not given;
    NaN (ingest's ``--sigma-range-m`` then) when the RMS is missing, ``na`` or not positive."""
    try:
        rms_ps = float(fields[7])
    except (IndexError, ValueError):
        return math.nan
    try:
        n = int(fields[6])
    except (IndexError, ValueError):
        n = 1
    if not (math.isfinite(rms_ps) and rms_ps > 0):
        return math.nan
    return C_LIGHT * rms_ps * 1e-12 / 2 / math.sqrt(max(n, 1))


def _sod_ns(session, sod: float) -> int:
    day = session["start_ns"] - session["start_ns"] % (86400 * _NS)
    t = day + round(sod * _NS)
    if t < session["start_ns"] - 3600 * _NS:      # seconds of day restarted after midnight
        t += 86400 * _NS
    return t


def _pass_id(session) -> str:
    import pandas as pd  # start-up: as in _date_ns

    return f"{session['station']}-" + pd.Timestamp(session["start_ns"]).strftime("%Y%m%dT%H%M")


def _iso(ns: int) -> str:
    return iso_utc(np.datetime64(int(ns), "ns"), 6)


def _session_meta(s) -> dict:
    return {"station": s["station"], "target": s["target"], "pass_id": _pass_id(s), "start": _iso(s["start_ns"]),
            "end": _iso(s["end_ns"]), "wavelength_nm": s.get("wavelength_nm"),
            "troposphere_applied": s["troposphere_applied"], "com_applied": s["com_applied"]}


def _meteo_meta(records) -> dict:
    records = sorted(records)
    return {"time": [_iso(r[0]) for r in records], "pressure_hpa": [r[1] for r in records],
            "temperature_k": [r[2] for r in records], "humidity_percent": [r[3] for r in records]}
