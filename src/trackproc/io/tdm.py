"""A small reader for CCSDS Tracking Data Messages in KVN form (CCSDS 503.0-B-2, also B-1).

Only what ``trackproc`` needs is interpreted; everything else is either ignored (metadata
that does not change the values) or counted in ``meta["skipped_keywords"]`` (data keywords we
do not turn into measurements), so nothing is dropped silently.

Layout (503.0-B-2 section 3 and 4): a header (``CCSDS_TDM_VERS`` first, then ``CREATION_DATE``,
``ORIGINATOR``, ``MESSAGE_ID``, ``COMMENT``), then one or more segments, each a metadata block
``META_START`` .. ``META_STOP`` followed by a data block ``DATA_START`` .. ``DATA_STOP`` whose
lines read ``KEYWORD = EPOCH VALUE``. The reader is lenient where files in the wild differ:
TABs and runs of blanks, any spacing around ``=``, blank lines, ``COMMENT`` lines anywhere,
lower-case keywords, epochs ``YYYY-MM-DDThh:mm:ss[.s...][Z]`` or day-of-year
``YYYY-DDDThh:mm:ss[.s...][Z]``, CRLF line ends, a UTF-8 byte-order mark.

Conventions (each is also written where it is applied):

* **Time.** ``TIME_SYSTEM`` UTC is used as is; TAI, GPS (= TAI - 19 s) and TT (= TAI + 32.184 s;
  the old name TDT is accepted) are converted to UTC with ERFA's leap-second table
  (``erfa.dat``); any other time system is an error. ``TIMETAG_REF = TRANSMIT`` is an error
  (trackproc time-tags at reception; moving the tag needs the light time, i.e. the orbit).
* **Station.** The path's first entry is the transmitter (503.0-B-2 3.3.2, ``PATH``), so the
  last one is the receiver, where RANGE, DOPPLER_*, RECEIVE_FREQ and ANGLE are measured.
  Rule: for a round-trip path ``i,j,i`` the station is participant ``i``; for a one-way path
  ``i,j`` the station is the receiver ``j`` (a down-link ``2,1`` gives PARTICIPANT_1, the usual
  ground station). Without ``PATH`` (angle-only data, e.g. optical) the station is
  PARTICIPANT_1, the usual convention. Relay / three-way paths (``1,2,3,2,1``, ``1,2,3``) and
  ``MODE = SINGLE_DIFF`` are refused for the kinds we read: they are not a station-to-spacecraft
  measurement.
* **RANGE** (``RANGE_UNITS``: km, default; s = light time; RU): km x 1000, s x c. RU are
  refused: CCSDS leaves their definition to an ICD (the DSN's depend on the uplink band and
  the ramped uplink frequency) and they are ambiguous modulo ``RANGE_MODULUS``, which needs an
  a-priori orbit to resolve; convert them to km or s upstream. A two-way path (three entries)
  is by default taken as already written as the one-way equivalent
  (``two_way_range="one-way-equivalent"``): the spec's own annex examples are written that
  way (a GSOC 1,2,1 example gives 40,016 km at 1.3 deg elevation, a one-way GEO slant
  range). Producers that write the full round trip need ``two_way_range="round-trip"``
  (``trackproc ingest --tdm-two-way-range round-trip``), which halves the values;
  ``meta["range_two_way_halved"]`` records which was done, and a warning names the assumption.
  ``RANGE_MODULUS`` is not applied (recorded in the warnings). A file whose ranges are all
  of one path and that has no Doppler data takes that path's link mode as its ``doppler_mode``
  (the link mode estimate models ranges with); ranges of another path than the file's
  Doppler data are named in a warning (split such a file by path).
* **DOPPLER_INSTANTANEOUS / DOPPLER_INTEGRATED** are range rates in km/s (503.0-B-2 keyword
  tables; "instantaneous range rate", "mean range rate over INTEGRATION_INTERVAL"), i.e. the
  time derivative of the range: positive when the range increases (receding), which is
  trackproc's convention, so the value is only scaled (x 1000), never negated. They are not
  halved on two-way paths (a range rate, not a round-trip count). DOPPLER_INTEGRATED (and
  RECEIVE_FREQ_n, a counted frequency) is re-tagged to the middle of its integration
  interval: ``INTEGRATION_REF`` START -> +interval/2, END -> -interval/2, MIDDLE -> 0.
* **RECEIVE_FREQ_n** (Hz; ``FREQ_OFFSET`` is added to every RECEIVE_FREQ to reconstruct it)
  becomes kind ``doppler`` = received - nominal. The nominal is the transmitter's
  ``TRANSMIT_FREQ_n`` data (n = the first participant of PATH, as in the spec's annex
  examples), with ``TRANSMIT_FREQ_RATE_n`` ramps integrated, evaluated at the receive time tag
  (the light time is ignored: error = ramp rate x light time), times
  ``TURNAROUND_NUMERATOR/TURNAROUND_DENOMINATOR`` on a two-way path. Without TRANSMIT_FREQ the
  ``carrier_hz`` argument is the nominal carrier of the *received* signal; with neither the
  file is refused (pass ``--carrier-hz``). A received frequency more than 0.1 % away from its
  nominal is refused (a missing turnaround ratio, FREQ_OFFSET or wrong carrier).
* **ANGLE_1 / ANGLE_2** with ``ANGLE_TYPE = AZEL`` are azimuth / elevation in degrees; output in
  radians, azimuth wrapped into [0, 2 pi) (the TDM allows [-180, 360)). Other angle types
  (RADEC, XEYN, XSYE) are refused, naming the ANGLE_TYPE.
* **CORRECTION_*.** When ``CORRECTIONS_APPLIED = NO`` the corrections we can place
  (CORRECTION_RANGE in range units, CORRECTION_DOPPLER km/s, CORRECTION_ANGLE_1/2 deg,
  CORRECTION_RECEIVE / CORRECTION_TRANSMIT Hz) are added to the raw values ("has been added or
  should be added"); when YES they are already in the data; a non-zero correction without
  CORRECTIONS_APPLIED is refused as ambiguous.
* **TRANSMIT_DELAY_n / RECEIVE_DELAY_n** are not applied (the standard does not say whether
  the data already include them); non-zero values are listed in ``meta["warnings"]``, as are
  ``DATA_QUALITY = DEGRADED`` segments and a DOPPLER_INTEGRATED without INTEGRATION_REF.
* **sigma** is NaN: the TDM has no per-sample uncertainty keyword.

Errors are :class:`~trackproc.errors.InputError` naming the file (``source``), the 1-based line
and the keyword (column).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from dataclasses import dataclass, field

from trackproc.constants import C_LIGHT
from trackproc.errors import InputError
from trackproc.io.validate import check_input_rows, check_iso_year
from trackproc.io.raw import RawMeasurements

__all__ = ["read_tdm"]

_NS = 1_000_000_000
_DAY_NS = 86_400 * _NS
#: Largest accepted |received - nominal| / nominal: 1e-3 is 300 km/s one-way, far above any
#: Earth-orbit or interplanetary Doppler, far below any turnaround ratio (240/221 is 8.6 %).
_MAX_RELATIVE_DOPPLER = 1e-3

_HEADER_KEYS = {"CCSDS_TDM_VERS", "CREATION_DATE", "ORIGINATOR", "MESSAGE_ID"}
_IDX = range(1, 6)
#: Metadata keywords of 503.0-B-2 (and B-1) section 3.3.
_META_KEYS = (
    {"TRACK_ID", "DATA_TYPES", "TIME_SYSTEM", "START_TIME", "STOP_TIME", "MODE", "PATH",
     "PATH_1", "PATH_2", "TRANSMIT_BAND", "RECEIVE_BAND", "TURNAROUND_NUMERATOR",
     "TURNAROUND_DENOMINATOR", "TIMETAG_REF", "INTEGRATION_INTERVAL", "INTEGRATION_REF",
     "FREQ_OFFSET", "RANGE_MODE", "RANGE_MODULUS", "RANGE_UNITS", "ANGLE_TYPE",
     "REFERENCE_FRAME", "INTERPOLATION", "INTERPOLATION_DEGREE", "DOPPLER_COUNT_BIAS",
     "DOPPLER_COUNT_SCALE", "DOPPLER_COUNT_ROLLOVER", "DATA_QUALITY", "CORRECTION_ANGLE_1",
     "CORRECTION_ANGLE_2", "CORRECTION_DOPPLER", "CORRECTION_MAG", "CORRECTION_RANGE",
     "CORRECTION_RCS", "CORRECTION_RECEIVE", "CORRECTION_TRANSMIT",
     "CORRECTION_ABERRATION_YEARLY", "CORRECTION_ABERRATION_DIURNAL", "CORRECTIONS_APPLIED"}
    | {f"PARTICIPANT_{i}" for i in _IDX}
    | {f"EPHEMERIS_NAME_{i}" for i in _IDX}
    | {f"TRANSMIT_DELAY_{i}" for i in _IDX}
    | {f"RECEIVE_DELAY_{i}" for i in _IDX}
)
#: Data keywords of 503.0-B-2 section 3.5 (used to recognise a data line out of place).
_DATA_KEYS = (
    {"ANGLE_1", "ANGLE_2", "CARRIER_POWER", "CLOCK_BIAS", "CLOCK_DRIFT", "DOPPLER_COUNT",
     "DOPPLER_INSTANTANEOUS", "DOPPLER_INTEGRATED", "DOR", "MAG", "PC_N0", "PR_N0",
     "PRESSURE", "RANGE", "RCS", "RECEIVE_FREQ", "RHUMIDITY", "STEC", "TEMPERATURE",
     "TROPO_DRY", "TROPO_WET", "VLBI_DELAY"}
    | {f"RECEIVE_FREQ_{i}" for i in _IDX}
    | {f"TRANSMIT_FREQ_{i}" for i in _IDX}
    | {f"TRANSMIT_FREQ_RATE_{i}" for i in _IDX}
    | {f"RECEIVE_PHASE_CT_{i}" for i in _IDX}
    | {f"TRANSMIT_PHASE_CT_{i}" for i in _IDX}
)
_RECEIVE_FREQ_KEYS = {"RECEIVE_FREQ"} | {f"RECEIVE_FREQ_{i}" for i in _IDX}
#: Data keywords turned into measurements, or used to compute them.
_USED_KEYS = ({"RANGE", "DOPPLER_INSTANTANEOUS", "DOPPLER_INTEGRATED", "ANGLE_1", "ANGLE_2"}
              | _RECEIVE_FREQ_KEYS | {f"TRANSMIT_FREQ_{i}" for i in _IDX}
              | {f"TRANSMIT_FREQ_RATE_{i}" for i in _IDX})
_MARKERS = {"META_START", "META_STOP", "DATA_START", "DATA_STOP"}
_SUPPORTED_TIME_SYSTEMS = {"UTC", "TAI", "GPS", "TT", "TDT"}

_KV_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
_EPOCH_RE = re.compile(
    r"^(\d{4})-(?:(\d{2})-(\d{2})|(\d{3}))T(\d{2}):(\d{2}):(\d{2})(?:\.(\d*))?Z?$", re.IGNORECASE)
_NUMBER_RE = re.compile(
    r"^[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)$", re.IGNORECASE)
_UNIT_SUFFIX_RE = re.compile(r"\s*\[[^\]]*\]\s*$")
_EPOCH_FORMAT = "YYYY-MM-DDThh:mm:ss[.fff][Z] or YYYY-DDDThh:mm:ss[.fff][Z]"

_UNIX_ORDINAL = 719_163  # datetime.date(1970, 1, 1).toordinal()


@dataclass
class _Obs:
    key: str
    naive_ns: int     # epoch read in the segment's own time scale, ns since 1970-01-01
    value: float
    row: int


@dataclass
class _Segment:
    number: int
    meta_row: int
    meta: dict = field(default_factory=dict)          # KEY -> (value, row)
    meta_stop_row: int | None = None
    data_row: int | None = None
    obs: list = field(default_factory=list)


def read_tdm(data: bytes, source: str, *, carrier_hz: float | None = None,
             two_way_range: str = "one-way-equivalent") -> RawMeasurements:
    """Read a CCSDS TDM in KVN form into :class:`RawMeasurements` (SI units, UTC).

    ``data`` is the whole file, ``source`` its name for messages. ``carrier_hz`` is the nominal
    carrier of the received signal, used for ``RECEIVE_FREQ_n`` when the segment gives no
    ``TRANSMIT_FREQ_n``. ``two_way_range`` says how the file writes RANGE on a two-way path:
    ``"round-trip"`` (halved here to the one-way equivalent) or ``"one-way-equivalent"``.
    See the module docstring for every convention.
    """
    if carrier_hz is not None and not (math.isfinite(carrier_hz) and carrier_hz > 0):
        raise InputError("the carrier frequency must be a positive number of Hz",
                         column="--carrier-hz", found=carrier_hz, expected="> 0")
    if two_way_range not in ("round-trip", "one-way-equivalent"):
        raise InputError("unknown two-way range convention", found=two_way_range,
                         expected="'round-trip' or 'one-way-equivalent'")
    parser = _Parser(source)
    header, segments = parser.parse(data)
    return _Converter(source, header, segments, parser.skipped, carrier_hz,
                      two_way_range == "round-trip").run()


# --------------------------------------------------------------------------------------------
# Lexing and block structure


class _Parser:
    def __init__(self, source: str):
        self.source = source
        self.skipped: dict[str, int] = {}

    def error(self, message, row=None, column=None, found=None, expected=None):
        return InputError(message, file=self.source, row=row, column=column, found=found,
                          expected=expected)

    def _decode(self, data: bytes) -> str:
        if not data or not data.strip():
            raise self.error("empty file: no CCSDS TDM content",
                             expected="a KVN TDM starting with CCSDS_TDM_VERS")
        if b"\x00" in data:
            row = data[:data.index(b"\x00")].count(b"\n") + 1
            raise self.error("binary data, not a KVN text TDM", row=row)
        try:
            return data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            row = data[:exc.start].count(b"\n") + 1
            raise self.error("not ASCII/UTF-8 text", row=row,
                             found=data[exc.start:exc.start + 4]) from None

    def parse(self, data: bytes):
        check_input_rows(data.count(b"\n"), file=self.source)
        text = self._decode(data)
        header: dict = {}
        segments: list[_Segment] = []
        state = "header"          # header -> meta -> between -> data -> after -> meta ...
        seg: _Segment | None = None
        first_content_row = None

        for row, raw in enumerate(text.split("\n"), start=1):
            line = raw.strip()   # also drops '\r' and TABs at both ends
            if not line:
                continue
            upper = line.upper()
            if upper == "COMMENT" or upper.startswith(("COMMENT ", "COMMENT\t")):
                continue
            if first_content_row is None:
                first_content_row = row
                if line.startswith("<"):
                    raise self.error("XML TDM is not supported; only the KVN text form", row=row,
                                     expected="CCSDS_TDM_VERS = 2.0")

            if upper in _MARKERS:
                if state == "header" and "CCSDS_TDM_VERS" not in header:
                    raise self._missing_version(first_content_row)
                state, seg = self._marker(upper, row, state, seg, segments)
                continue

            m = _KV_RE.match(line)
            if not m:
                raise self.error("cannot read this line", row=row, found=_clip(line),
                                 expected="KEYWORD = value, a COMMENT, or META_/DATA_ START/STOP")
            key, value = m.group(1).upper(), m.group(2)

            if state == "header":
                if key in _HEADER_KEYS:
                    if key != "CCSDS_TDM_VERS" and "CCSDS_TDM_VERS" not in header:
                        raise self._missing_version(first_content_row)
                    if key == "CCSDS_TDM_VERS":
                        self._check_version(value, row)
                    header[key] = (value, row)
                elif _looks_like_data(key, value):
                    raise self._outside(key, value, row, "before the first META_START")
                elif key in _META_KEYS:
                    raise self.error("metadata before META_START (missing META_START?)",
                                     row=row, column=key, expected="META_START first")
                else:
                    if "CCSDS_TDM_VERS" not in header:
                        raise self._missing_version(first_content_row)
                    self._skip(key)
            elif state == "meta":
                if key in _HEADER_KEYS:
                    raise self.error("header keyword inside a META block", row=row, column=key)
                if key in seg.meta:
                    raise self.error(f"{key} given twice in one META block", row=row, column=key,
                                     found=value)
                if key not in _META_KEYS:
                    if _looks_like_data(key, value):
                        raise self.error(
                            "data line inside a META block (missing META_STOP/DATA_START?)",
                            row=row, column=key, found=_clip(line))
                    import difflib

                    close = difflib.get_close_matches(key, sorted(_META_KEYS), n=1, cutoff=0.85)
                    if close:   # ANGLE_TYP for ANGLE_TYPE: a typo must not change the meaning silently
                        raise self.error("unknown TDM metadata keyword", row=row, column=key, found=key,
                                         expected=f"{close[0]} (a CCSDS 503.0-B-2 metadata keyword)")
                    self._skip(key)
                seg.meta[key] = (value, row)
            elif state == "data":
                self._data_line(seg, key, value, row)
            else:  # between a META_STOP and its DATA_START, or after a DATA_STOP
                where = ("between META_STOP and DATA_START" if state == "between"
                         else "after DATA_STOP")
                if _looks_like_data(key, value):
                    raise self._outside(key, value, row, where)
                raise self.error(f"keyword outside any META or DATA block ({where})",
                                 row=row, column=key, found=_clip(line),
                                 expected="META_START or DATA_START")

        if first_content_row is None:
            raise self.error("empty file: only blank lines and comments",
                             expected="a KVN TDM starting with CCSDS_TDM_VERS")
        if "CCSDS_TDM_VERS" not in header:
            raise self._missing_version(first_content_row)
        if state == "meta":
            raise self.error(f"META_START at row {seg.meta_row} has no META_STOP",
                             row=seg.meta_row, column="META_STOP", expected="META_STOP")
        if state == "between":
            raise self.error(f"META_STOP at row {seg.meta_stop_row} is not followed by a data "
                             "block", row=seg.meta_stop_row, column="DATA_START",
                             expected="DATA_START ... DATA_STOP")
        if state == "data":
            raise self.error(f"DATA_START at row {seg.data_row} has no DATA_STOP",
                             row=seg.data_row, column="DATA_STOP", expected="DATA_STOP")
        if not segments:
            raise self.error("no META/DATA segment: the file holds a header only",
                             row=first_content_row, column="META_START",
                             expected="META_START ... META_STOP DATA_START ... DATA_STOP")
        return header, segments

    def _marker(self, marker, row, state, seg, segments):
        expected = {"header": "META_START", "meta": "META_STOP", "between": "DATA_START",
                    "data": "DATA_STOP", "after": "META_START or end of file"}[state]
        nxt = {("header", "META_START"): "meta", ("after", "META_START"): "meta",
               ("meta", "META_STOP"): "between", ("between", "DATA_START"): "data",
               ("data", "DATA_STOP"): "after"}.get((state, marker))
        if nxt is None:
            opened = ""
            if state == "meta":
                opened = f" (META_START at row {seg.meta_row} is still open)"
            elif state == "data":
                opened = f" (DATA_START at row {seg.data_row} is still open)"
            raise self.error(f"unbalanced META/DATA blocks: {marker} here{opened}", row=row,
                             column=marker, found=marker, expected=expected)
        if marker == "META_START":
            seg = _Segment(number=len(segments) + 1, meta_row=row)
            segments.append(seg)
        elif marker == "META_STOP":
            seg.meta_stop_row = row
        elif marker == "DATA_START":
            seg.data_row = row
        return nxt, seg

    def _data_line(self, seg: _Segment, key: str, value: str, row: int):
        if key in _META_KEYS or key in _HEADER_KEYS:
            raise self.error("metadata keyword inside a DATA block", row=row, column=key,
                             found=value, expected="KEYWORD = EPOCH VALUE")
        if key not in _USED_KEYS:
            if key not in _DATA_KEYS:
                import difflib

                close = difflib.get_close_matches(key, sorted(_USED_KEYS | _DATA_KEYS), n=1, cutoff=0.8)
                if close:   # RANGEE for RANGE: a typo must not drop the measurement without a word
                    raise self.error("unknown TDM data keyword", row=row, column=key, found=key,
                                     expected=f"{close[0]} (a CCSDS 503.0-B-2 data keyword)")
            self._skip(key)
            return
        parts = value.split()
        if len(parts) != 2:
            raise self.error("a data line holds an epoch and one value", row=row, column=key,
                             found=value, expected="KEYWORD = EPOCH VALUE")
        epoch, number = parts
        naive_ns = _parse_epoch(epoch)
        if naive_ns is None:
            raise self.error("unparseable epoch", row=row, column=key, found=epoch,
                             expected=_EPOCH_FORMAT)
        if naive_ns == "leap":
            raise self.error("a leap-second epoch (ss = 60) cannot be represented", row=row,
                             column=key, found=epoch)
        check_iso_year(epoch, file=self.source, row=row, column=key)
        if not _NUMBER_RE.match(number):
            raise self.error("non-numeric value", row=row, column=key, found=number,
                             expected="a number")
        seg.obs.append(_Obs(key, naive_ns, float(number), row))

    def _skip(self, key):
        self.skipped[key] = self.skipped.get(key, 0) + 1

    def _check_version(self, value, row):
        try:
            major = int(float(value.split()[0]))
        except (ValueError, IndexError):
            raise self.error("unreadable TDM version", row=row, column="CCSDS_TDM_VERS",
                             found=value, expected="1.0 or 2.0") from None
        if major not in (1, 2):
            raise self.error("unsupported TDM version", row=row, column="CCSDS_TDM_VERS",
                             found=value, expected="1.0 or 2.0")

    def _missing_version(self, row):
        return self.error("missing CCSDS_TDM_VERS: a TDM must start with its version line",
                          row=row, column="CCSDS_TDM_VERS", expected="CCSDS_TDM_VERS = 2.0")

    def _outside(self, key, value, row, where):
        return self.error(f"data outside DATA_START/DATA_STOP ({where})", row=row, column=key,
                          found=_clip(f"{key} = {value}"),
                          expected="data lines between DATA_START and DATA_STOP")


def _looks_like_data(key: str, value: str) -> bool:
    parts = value.split()
    return key in _DATA_KEYS or (len(parts) == 2 and bool(re.match(r"^\d{4}-\d", parts[0])))


def _clip(text: str, n: int = 60) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def _parse_epoch(text: str):
    """Epoch string -> integer ns since 1970-01-01 on a uniform 86400 s day (no leap
    seconds; the caller maps it from its time scale to UTC). None if malformed; "leap" for
    a second of 60."""
    m = _EPOCH_RE.match(text)
    if not m:
        return None
    year, month, day, doy, hh, mm, ss, frac = m.groups()
    year = int(year)
    try:
        if doy is not None:
            date = _dt.date(year, 1, 1) + _dt.timedelta(days=int(doy) - 1)
            if int(doy) < 1 or date.year != year:
                return None
        else:
            date = _dt.date(year, int(month), int(day))
    except (ValueError, OverflowError):
        return None
    hh, mm, ss = int(hh), int(mm), int(ss)
    if hh > 23 or mm > 59 or ss > 60:
        return None
    if ss == 60:
        return "leap"
    frac_ns = int((frac or "").ljust(9, "0")[:9] or 0)
    days = date.toordinal() - _UNIX_ORDINAL
    return days * _DAY_NS + (hh * 3600 + mm * 60 + ss) * _NS + frac_ns


# --------------------------------------------------------------------------------------------
# Metadata interpretation and unit conversion


@dataclass
class _Config:
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


class _Converter:
    def __init__(self, source, header, segments, skipped, carrier_hz, halve_two_way):
        self.source = source
        self.header = header
        self.segments = segments
        self.skipped = skipped
        self.carrier_hz = carrier_hz
        self.halve_two_way = halve_two_way
        self.rows: list[tuple] = []            # (time_ns, station, kind, value, row)
        self.columns: dict[str, list] = {}
        self.warnings: list[str] = []
        self.doppler_mode: tuple | None = None  # (mode, segment number)
        self.nominals: list[tuple] = []          # (nominal_hz, row)
        self.range_modes: set = set()
        self.time_systems: list = []
        self.segment_info: list = []

    def error(self, message, row=None, column=None, found=None, expected=None):
        return InputError(message, file=self.source, row=row, column=column, found=found,
                          expected=expected)

    def run(self) -> RawMeasurements:
        import numpy as np
        import pandas as pd

        for seg in self.segments:
            cfg = self._config(seg)
            self._convert(seg, cfg)

        if not self.rows:
            what = (", ".join(f"{k} x{n}" for k, n in sorted(self.skipped.items()))
                    or "no data lines")
            raise self.error("no supported measurements (RANGE, DOPPLER_INSTANTANEOUS, "
                             "DOPPLER_INTEGRATED, RECEIVE_FREQ_n, ANGLE_1/ANGLE_2) in the file",
                             found=what)

        self.rows.sort(key=lambda r: r[4])
        time = np.array([r[0] for r in self.rows], dtype="int64").astype("datetime64[ns]")
        frame = pd.DataFrame({
            "time": pd.Series(time).dt.tz_localize("UTC"),
            "station": [r[1] for r in self.rows],
            "kind": [r[2] for r in self.rows],
            "value": np.array([r[3] for r in self.rows], dtype="float64"),
            "sigma": np.full(len(self.rows), np.nan),
            "row": np.array([r[4] for r in self.rows], dtype="int64"),
        })

        self.warnings.extend(f"non-standard TDM keyword {key} skipped ({n} lines)"
                             for key, n in sorted(self.skipped.items())
                             if key not in _DATA_KEYS | _META_KEYS | _HEADER_KEYS)
        meta = {
            "source": self.source,
            "format": "CCSDS TDM (KVN)",
            "tdm_version": self.header["CCSDS_TDM_VERS"][0],
            "tdm_segments": len(self.segments),
            "time_scale": "UTC",
            "source_time_systems": sorted(set(self.time_systems)),
            "skipped_keywords": dict(sorted(self.skipped.items())),
            "warnings": self.warnings,
            "tdm_segment_info": self.segment_info,
        }
        if "ORIGINATOR" in self.header:
            meta["originator"] = self.header["ORIGINATOR"][0]
        if self.doppler_mode is not None:
            meta["doppler_mode"] = self.doppler_mode[0]
        carrier = self._file_carrier()
        if carrier is not None:
            meta["carrier_hz"] = carrier
        if self.range_modes:
            meta["range_two_way_halved"] = self.halve_two_way and "two-way" in self.range_modes
            meta["range_source_paths"] = sorted(self.range_modes)
            # the file's link mode (``doppler_mode``) is what estimate models ranges with too
            if self.doppler_mode is None and len(self.range_modes) == 1:
                meta["doppler_mode"] = next(iter(self.range_modes))
            elif self.range_modes - {meta.get("doppler_mode")}:
                link = meta.get("doppler_mode") or "one-way (the default)"
                self.warnings.append(
                    f"RANGE paths are {' and '.join(sorted(self.range_modes))} but the file's link mode is {link}, "
                    "which estimate applies to every range, range-rate and Doppler sample: split the file by path")
            if "two-way" in self.range_modes:
                self.warnings.append(
                    "two-way RANGE values " + ("halved (written as round trips)" if self.halve_two_way
                                               else "taken as one-way equivalents (as the spec's examples "
                                               "write them); use --tdm-two-way-range round-trip if "
                                               "this file holds full round trips"))
        column = {kind: ", ".join(keys) for kind, keys in self.columns.items()}
        return RawMeasurements(frame=frame, source=self.source, column=column, meta=meta)

    # -- metadata ---------------------------------------------------------------------------

    def _config(self, seg: _Segment) -> _Config:
        meta = seg.meta

        def text(key, default=None):
            return meta[key][0] if key in meta else default

        def number(key, default=None):
            if key not in meta:
                return default
            value, row = meta[key]
            value = _UNIT_SUFFIX_RE.sub("", value)
            if not _NUMBER_RE.match(value) or not math.isfinite(float(value)):
                raise self.error("non-numeric metadata value", row=row, column=key,
                                 found=value, expected="a number")
            return float(value)

        if "TIME_SYSTEM" not in meta:
            raise self.error(f"TIME_SYSTEM missing in the META block at row {seg.meta_row}",
                             row=seg.meta_row, column="TIME_SYSTEM",
                             expected="TIME_SYSTEM = UTC (or TAI, GPS, TT)")
        ts, ts_row = meta["TIME_SYSTEM"]
        ts = ts.strip().upper()
        if ts not in _SUPPORTED_TIME_SYSTEMS:
            raise self.error("unsupported time system", row=ts_row, column="TIME_SYSTEM",
                             found=ts, expected="UTC, TAI, GPS or TT")
        ts = "TT" if ts == "TDT" else ts
        self.time_systems.append(ts)

        if "TIMETAG_REF" in meta and text("TIMETAG_REF").strip().upper() != "RECEIVE":
            raise self.error("only reception time tags are supported (moving a transmit time "
                             "tag to reception needs the light time)",
                             row=meta["TIMETAG_REF"][1], column="TIMETAG_REF",
                             found=text("TIMETAG_REF"), expected="RECEIVE")

        participants = {i: meta[f"PARTICIPANT_{i}"][0].strip() for i in _IDX
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
                raise self.error("unreadable PATH", row=row, column="PATH", found=value,
                                 expected="participant indices separated by commas, "
                                 "e.g. 2,1 or 1,2,1") from None
            for p in path:
                if p not in participants:
                    raise self.error(f"PATH names participant {p}, which is not defined",
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
                raise self.error(f"PARTICIPANT_1 missing in the META block at row "
                                 f"{seg.meta_row}", row=seg.meta_row, column="PARTICIPANT_1")
            station = participants[1]

        units = (text("RANGE_UNITS") or "km").strip()
        if units.lower() in ("km", "s"):
            units = units.lower()
        elif units.upper() == "RU":
            units = "RU"
        else:
            raise self.error("unknown RANGE_UNITS", row=meta["RANGE_UNITS"][1],
                             column="RANGE_UNITS", found=units, expected="km, s or RU")

        iref = text("INTEGRATION_REF")
        if iref is not None:
            iref = iref.strip().upper()
            if iref not in ("START", "MIDDLE", "END"):
                raise self.error("unknown INTEGRATION_REF", row=meta["INTEGRATION_REF"][1],
                                 column="INTEGRATION_REF", found=iref,
                                 expected="START, MIDDLE or END")
        interval = number("INTEGRATION_INTERVAL")
        if interval is not None and interval < 0:
            raise self.error("negative integration interval",
                             row=meta["INTEGRATION_INTERVAL"][1],
                             column="INTEGRATION_INTERVAL", found=interval, expected=">= 0 s")

        num, den = number("TURNAROUND_NUMERATOR"), number("TURNAROUND_DENOMINATOR")
        turnaround = None
        if num is not None or den is not None:
            if num is None or den is None or num <= 0 or den <= 0:
                key = "TURNAROUND_DENOMINATOR" if num is not None else "TURNAROUND_NUMERATOR"
                row = meta.get(key, meta.get("TURNAROUND_NUMERATOR", (None, seg.meta_row)))[1]
                raise self.error("the turnaround ratio needs a positive numerator and "
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
                raise self.error("CORRECTIONS_APPLIED must be YES or NO",
                                 row=meta["CORRECTIONS_APPLIED"][1],
                                 column="CORRECTIONS_APPLIED", found=applied,
                                 expected="YES or NO")
        if nonzero:
            if applied is None:
                key = next(iter(nonzero))
                raise self.error(f"{key} is given without CORRECTIONS_APPLIED: cannot tell "
                                 "whether the data already include it", row=meta[key][1],
                                 column="CORRECTIONS_APPLIED",
                                 expected="CORRECTIONS_APPLIED = YES or NO")
            if applied == "NO":
                corrections = nonzero

        quality = (text("DATA_QUALITY") or "").strip().upper() or None
        if quality == "DEGRADED":
            self.warnings.append(f"segment {seg.number}: DATA_QUALITY = DEGRADED "
                                 f"(row {meta['DATA_QUALITY'][1]})")
        delays = {k: number(k) for k in sorted(meta)
                  if k.startswith(("TRANSMIT_DELAY_", "RECEIVE_DELAY_"))}
        delays = {k: v for k, v in delays.items() if v}
        if delays:
            self.warnings.append(
                f"segment {seg.number}: " + ", ".join(f"{k} = {v:g} s" for k, v in delays.items())
                + " not applied (the TDM does not say whether the data include them)")
        if "RANGE_MODULUS" in meta and any(o.key == "RANGE" for o in seg.obs):
            modulus = number("RANGE_MODULUS")
            if modulus:
                self.warnings.append(f"segment {seg.number}: RANGE_MODULUS = {modulus:g} "
                                     f"{units} not applied (ranges taken as unambiguous)")

        self.segment_info.append({
            "segment": seg.number, "meta_row": seg.meta_row, "time_system": ts,
            "participants": {str(k): v for k, v in participants.items()},
            "path": text("PATH"), "station": station, "link": link_mode,
            "data_quality": quality, "corrections_added": sorted(corrections),
        })
        return _Config(
            number=seg.number, time_system=ts, participants=participants, path=path,
            path_problem=path_problem, mode=link_mode, station=station,
            angle_type=(text("ANGLE_TYPE") or "").strip().upper() or None,
            range_units=units, integration_interval=interval, integration_ref=iref,
            freq_offset=number("FREQ_OFFSET", 0.0), turnaround=turnaround,
            corrections=corrections)

    # -- data -------------------------------------------------------------------------------

    def _convert(self, seg: _Segment, cfg: _Config):
        import numpy as np

        from trackproc.dynamics import timescales

        if not seg.obs:
            return
        naive = np.array([o.naive_ns for o in seg.obs], dtype="int64")
        utc = timescales.scale_ns_to_utc_ns(naive, cfg.time_system)
        if utc is None:
            raise self.error("epoch outside the UTC leap-second table (before 1960)",
                             row=seg.obs[0].row, column=seg.obs[0].key)
        shift = self._integration_shift_ns(seg, cfg)
        corr = cfg.corrections

        # TRANSMIT_FREQ_n / TRANSMIT_FREQ_RATE_n only serve as the nominal of RECEIVE_FREQ,
        # and only for n = the transmitter (first entry of PATH); others are counted as skipped.
        tx_index = cfg.path[0] if cfg.path else None
        has_receive = any(o.key in _RECEIVE_FREQ_KEYS for o in seg.obs)
        tx_freq, tx_rate, other_tx = [], [], set()
        for o, t in zip(seg.obs, utc):
            if not o.key.startswith("TRANSMIT_FREQ"):
                continue
            if not has_receive or int(o.key[-1]) != tx_index:
                self.skipped[o.key] = self.skipped.get(o.key, 0) + 1
                if not o.key.startswith("TRANSMIT_FREQ_RATE_"):
                    other_tx.add(o.key)
            elif o.key.startswith("TRANSMIT_FREQ_RATE_"):
                tx_rate.append((int(t), o.value))
            else:
                tx_freq.append((int(t), o.value + corr.get("CORRECTION_TRANSMIT", 0.0)))
        receive = []   # (time_ns, received_hz, obs)

        for o, t in zip(seg.obs, utc):
            t = int(t)
            key = o.key
            if key.startswith("TRANSMIT_FREQ"):
                continue
            self._check_path(o, cfg, need_link=key != "ANGLE_1" and key != "ANGLE_2")
            if key == "RANGE":
                raw = o.value + corr.get("CORRECTION_RANGE", 0.0)
                if cfg.range_units == "RU":
                    raise self.error(
                        "RANGE in range units (RU) is not supported: RU are defined by a "
                        "mission ICD (the DSN's depend on the uplink band and frequency) and "
                        "are ambiguous modulo RANGE_MODULUS; convert to km or s",
                        row=o.row, column=key, found="RANGE_UNITS = RU",
                        expected="RANGE_UNITS = km or s")
                metres = raw * 1000.0 if cfg.range_units == "km" else raw * C_LIGHT
                if cfg.mode == "two-way" and self.halve_two_way:
                    metres /= 2.0
                self.range_modes.add(cfg.mode)
                self._emit(t, cfg.station, "range", metres, o.row, key)
            elif key in ("DOPPLER_INSTANTANEOUS", "DOPPLER_INTEGRATED"):
                self._set_doppler_mode(cfg, o)
                kms = o.value + corr.get("CORRECTION_DOPPLER", 0.0)
                tt = t + shift if key == "DOPPLER_INTEGRATED" else t
                self._emit(tt, cfg.station, "range_rate", kms * 1000.0, o.row, key)
            elif key in _RECEIVE_FREQ_KEYS:
                self._set_doppler_mode(cfg, o)
                received = cfg.freq_offset + o.value + corr.get("CORRECTION_RECEIVE", 0.0)
                receive.append((t + shift, received, o))
            elif key in ("ANGLE_1", "ANGLE_2"):
                if cfg.angle_type != "AZEL":
                    raise self.error(
                        "only ANGLE_TYPE = AZEL (azimuth, elevation) is supported",
                        row=o.row, column=key, found=f"ANGLE_TYPE = {cfg.angle_type}"
                        if cfg.angle_type else "no ANGLE_TYPE in the META block",
                        expected="ANGLE_TYPE = AZEL")
                deg = o.value + corr.get(f"CORRECTION_{key}", 0.0)
                if key == "ANGLE_1":
                    self._emit(t, cfg.station, "azimuth", math.radians(deg % 360.0), o.row, key)
                else:
                    self._emit(t, cfg.station, "elevation", math.radians(deg), o.row, key)

        if receive:
            self._receive_freq(receive, cfg, tx_freq, tx_rate, tx_index, other_tx)

    def _check_path(self, o: _Obs, cfg: _Config, need_link: bool):
        if cfg.path_problem:
            raise self.error(f"cannot read {o.key} from a segment with {cfg.path_problem}",
                             row=o.row, column=o.key,
                             expected="PATH i,j (one-way) or i,j,i (two-way)")
        if need_link and cfg.mode is None:
            raise self.error(f"{o.key} needs PATH in its META block to tell one-way from "
                             "two-way", row=o.row, column=o.key,
                             expected="PATH = 2,1 (one-way) or 1,2,1 (two-way)")

    def _integration_shift_ns(self, seg: _Segment, cfg: _Config) -> int:
        counted = [o for o in seg.obs
                   if o.key == "DOPPLER_INTEGRATED" or o.key in _RECEIVE_FREQ_KEYS]
        if not counted:
            return 0
        interval, ref = cfg.integration_interval, cfg.integration_ref
        if interval is None or ref is None:
            if any(o.key == "DOPPLER_INTEGRATED" for o in counted):
                self.warnings.append(
                    f"segment {seg.number}: DOPPLER_INTEGRATED without INTEGRATION_INTERVAL "
                    "and INTEGRATION_REF; time tags taken as mid-interval")
            return 0
        half = round(interval * _NS / 2)
        return {"START": half, "MIDDLE": 0, "END": -half}[ref]

    def _set_doppler_mode(self, cfg: _Config, o: _Obs):
        if self.doppler_mode is None:
            self.doppler_mode = (cfg.mode, cfg.number)
        elif self.doppler_mode[0] != cfg.mode:
            raise self.error(
                f"segment {cfg.number} is {cfg.mode} but segment {self.doppler_mode[1]} is "
                f"{self.doppler_mode[0]}: one file must hold one Doppler mode (split it)",
                row=o.row, column=o.key, found=cfg.mode, expected=self.doppler_mode[0])

    def _receive_freq(self, receive, cfg: _Config, tx_freq, tx_rate, tx_index, other_tx):
        import numpy as np

        times = np.array([r[0] for r in receive], dtype="int64")
        if tx_freq:
            nominal = _ramped_frequency(times, tx_freq, tx_rate)
            if cfg.mode == "two-way" and cfg.turnaround is not None:
                nominal = nominal * cfg.turnaround
            origin = f"TRANSMIT_FREQ_{tx_index}"
            if cfg.mode == "two-way" and cfg.turnaround is not None:
                origin += " x TURNAROUND_NUMERATOR/TURNAROUND_DENOMINATOR"
        elif self.carrier_hz is not None:
            nominal = np.full(len(times), float(self.carrier_hz))
            origin = "the carrier frequency given (--carrier-hz)"
        else:
            first = receive[0][2]
            extra = (f" ({', '.join(sorted(other_tx))} belong to a participant that does not "
                     f"transmit on PATH)" if other_tx else "")
            raise self.error(
                f"{first.key} needs the nominal carrier: segment {cfg.number} has no "
                f"TRANSMIT_FREQ_{tx_index}{extra}; pass --carrier-hz", row=first.row,
                column=first.key, expected=f"TRANSMIT_FREQ_{tx_index} data or --carrier-hz")
        for (t, received, o), f0 in zip(receive, nominal):
            shift = received - f0
            if not abs(shift) <= _MAX_RELATIVE_DOPPLER * f0:
                raise self.error(
                    f"received frequency is {shift:+.6g} Hz from the nominal carrier "
                    f"{f0:.12g} Hz taken from {origin}: wrong carrier, missing FREQ_OFFSET or "
                    "turnaround ratio?", row=o.row, column=o.key, found=received,
                    expected=f"within {_MAX_RELATIVE_DOPPLER:.1%} of {f0:.12g} Hz")
            self.nominals.append((float(f0), o.row))
            self._emit(t, cfg.station, "doppler", shift, o.row, o.key)

    def _file_carrier(self):
        if not self.nominals:
            return self.carrier_hz
        values = sorted(f for f, _ in self.nominals)
        median = values[len(values) // 2]
        for f, row in self.nominals:
            if abs(f - median) > _MAX_RELATIVE_DOPPLER * median:
                raise self.error(
                    "the file mixes carriers of different nominal frequency; the canonical "
                    "table carries one (split the file)", row=row, found=f,
                    expected=f"about {median:.12g} Hz")
        return median

    def _emit(self, t, station, kind, value, row, key):
        self.rows.append((t, station, kind, value, row))
        keys = self.columns.setdefault(kind, [])
        if key not in keys:
            keys.append(key)


def _ramped_frequency(times, tx_freq, tx_rate):
    """Transmit frequency at ``times`` (ns): the latest TRANSMIT_FREQ sample at or before each
    time (the first one for earlier times) plus the integral of the TRANSMIT_FREQ_RATE ramp,
    which is piecewise constant from each rate time tag to the next (503.0-B-2:
    "starting at the timetag and continuing until the next TRANSMIT_FREQ_RATE_n timetag")."""
    import numpy as np

    tx_freq = sorted(tx_freq)
    ft = np.array([t for t, _ in tx_freq], dtype="int64")
    fv = np.array([v for _, v in tx_freq], dtype="float64")
    k = np.clip(np.searchsorted(ft, times, side="right") - 1, 0, len(ft) - 1)
    if not tx_rate:
        return fv[k]
    tx_rate = sorted(tx_rate)
    bt = np.array([t for t, _ in tx_rate], dtype="int64")
    br = np.array([r for _, r in tx_rate], dtype="float64")
    cum = np.concatenate([[0.0], np.cumsum(br[:-1] * np.diff(bt) / _NS)])

    def ramp(t):  # integral of the rate from the first rate tag to t, Hz
        j = np.searchsorted(bt, t, side="right") - 1
        inside = j >= 0
        jj = np.clip(j, 0, None)
        return np.where(inside, cum[jj] + br[jj] * (t - bt[jj]) / _NS, 0.0)

    anchor = np.minimum(times, ft[k])  # = ft[k]; = t (no ramp) before the first sample
    return fv[k] + ramp(times) - ramp(anchor)
