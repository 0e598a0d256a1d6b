"""The KVN layer of a TDM: lines, ``KEYWORD = value`` pairs, ``COMMENT``s and the
``META_START``/``META_STOP``/``DATA_START``/``DATA_STOP`` blocks (503.0-B-2 section 4), into a
header and :class:`Segment` s of raw metadata and data lines (:class:`Parser`); epochs read on a
uniform day (:func:`parse_epoch`). What the keywords mean is :mod:`trackproc.io.tdm.convert`'s.
"""

from __future__ import annotations

import datetime as _dt
import difflib
import re
from dataclasses import dataclass, field

from trackproc.errors import InputError
from trackproc.io.tdm.keywords import DATA_KEYS, HEADER_KEYS, MARKERS, META_KEYS, USED_KEYS
from trackproc.io.validate import check_input_rows, check_iso_year

NS = 1_000_000_000
DAY_NS = 86_400 * NS

KV_RE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
EPOCH_RE = re.compile(
    r"^(\d{4})-(?:(\d{2})-(\d{2})|(\d{3}))T(\d{2}):(\d{2}):(\d{2})(?:\.(\d*))?Z?$", re.IGNORECASE)
NUMBER_RE = re.compile(
    r"^[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)$", re.IGNORECASE)
UNIT_SUFFIX_RE = re.compile(r"\s*\[[^\]]*\]\s*$")
EPOCH_FORMAT = "YYYY-MM-DDThh:mm:ss[.fff][Z] or YYYY-DDDThh:mm:ss[.fff][Z]"

UNIX_ORDINAL = 719_163  # datetime.date(1970, 1, 1).toordinal()


@dataclass
class Obs:
    key: str
    naive_ns: int     # epoch read in the segment's own time scale, ns since 1970-01-01
    value: float
    row: int


@dataclass
class Segment:
    number: int
    meta_row: int
    meta: dict = field(default_factory=dict)          # KEY -> (value, row)
    meta_stop_row: int | None = None
    data_row: int | None = None
    obs: list = field(default_factory=list)


class Parser:
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
        segments: list[Segment] = []
        state = "header"          # header -> meta -> between -> data -> after -> meta ...
        seg: Segment | None = None
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

            if upper in MARKERS:
                if state == "header" and "CCSDS_TDM_VERS" not in header:
                    raise self._missing_version(first_content_row)
                state, seg = self._marker(upper, row, state, seg, segments)
                continue

            m = KV_RE.match(line)
            if not m:
                raise self.error("cannot read this line", row=row, found=clip(line),
                                 expected="KEYWORD = value, a COMMENT, or META_/DATA_ START/STOP")
            key, value = m.group(1).upper(), m.group(2)

            if state == "header":
                if key in HEADER_KEYS:
                    if key != "CCSDS_TDM_VERS" and "CCSDS_TDM_VERS" not in header:
                        raise self._missing_version(first_content_row)
                    if key == "CCSDS_TDM_VERS":
                        self._check_version(value, row)
                    header[key] = (value, row)
                elif looks_like_data(key, value):
                    raise self._outside(key, value, row, "before the first META_START")
                elif key in META_KEYS:
                    raise self.error("metadata before META_START (missing META_START?)",
                                     row=row, column=key, expected="META_START first")
                else:
                    if "CCSDS_TDM_VERS" not in header:
                        raise self._missing_version(first_content_row)
                    self._skip(key)
            elif state == "meta":
                if key in HEADER_KEYS:
                    raise self.error("header keyword inside a META block", row=row, column=key)
                if key in seg.meta:
                    raise self.error(f"{key} given twice in one META block", row=row, column=key,
                                     found=value)
                if key not in META_KEYS:
                    if looks_like_data(key, value):
                        raise self.error(
                            "data line inside a META block (missing META_STOP/DATA_START?)",
                            row=row, column=key, found=clip(line))
                    close = difflib.get_close_matches(key, sorted(META_KEYS), n=1, cutoff=0.85)
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
                if looks_like_data(key, value):
                    raise self._outside(key, value, row, where)
                raise self.error(f"keyword outside any META or DATA block ({where})",
                                 row=row, column=key, found=clip(line),
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
            seg = Segment(number=len(segments) + 1, meta_row=row)
            segments.append(seg)
        elif marker == "META_STOP":
            seg.meta_stop_row = row
        elif marker == "DATA_START":
            seg.data_row = row
        return nxt, seg

    def _data_line(self, seg: Segment, key: str, value: str, row: int):
        if key in META_KEYS or key in HEADER_KEYS:
            raise self.error("metadata keyword inside a DATA block", row=row, column=key,
                             found=value, expected="KEYWORD = EPOCH VALUE")
        if key not in USED_KEYS:
            if key not in DATA_KEYS:
                close = difflib.get_close_matches(key, sorted(USED_KEYS | DATA_KEYS), n=1, cutoff=0.8)
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
        naive_ns = parse_epoch(epoch)
        if naive_ns is None:
            raise self.error("unparseable epoch", row=row, column=key, found=epoch,
                             expected=EPOCH_FORMAT)
        if naive_ns == "leap":
            raise self.error("a leap-second epoch (ss = 60) cannot be represented", row=row,
                             column=key, found=epoch)
        check_iso_year(epoch, file=self.source, row=row, column=key)
        if not NUMBER_RE.match(number):
            raise self.error("non-numeric value", row=row, column=key, found=number,
                             expected="a number")
        seg.obs.append(Obs(key, naive_ns, float(number), row))

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
                          found=clip(f"{key} = {value}"),
                          expected="data lines between DATA_START and DATA_STOP")


def looks_like_data(key: str, value: str) -> bool:
    parts = value.split()
    return key in DATA_KEYS or (len(parts) == 2 and bool(re.match(r"^\d{4}-\d", parts[0])))


def clip(text: str, n: int = 60) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def parse_epoch(text: str):
    """Epoch string -> integer ns since 1970-01-01 on a uniform 86400 s day (no leap
    seconds; the caller maps it from its time scale to UTC). None if malformed; "leap" for
    a second of 60."""
    m = EPOCH_RE.match(text)
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
    days = date.toordinal() - UNIX_ORDINAL
    return days * DAY_NS + (hh * 3600 + mm * 60 + ss) * NS + frac_ns
