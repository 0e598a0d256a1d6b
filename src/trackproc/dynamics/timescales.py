"""Time scales: UTC <-> TAI <-> TT (and GPS -> UTC) with leap seconds, UT1 from UTC, Earth orientation data.

Times cross this module as two-part Julian dates ``(jd1, jd2)`` (SOFA/ERFA convention: a
UTC two-part date is a "quasi-JD" whose day has 86401 s on a leap-second day) or as numpy
``datetime64[ns]`` arrays of UTC (naive, POSIX-like: no 23:59:60). Leap seconds come from
ERFA's built-in table (``erfa.dat``), which pyerfa keeps up to date.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import erfa

import numpy as np

from trackproc.constants import DAY_S

#: Seconds of TT minus TAI (exact, by definition).
TT_MINUS_TAI_S = 32.184
#: Nanoseconds of each supported time scale minus TAI: GPS = TAI - 19 s (IS-GPS-200), TT = TAI + 32.184 s (IAU).
SCALE_MINUS_TAI_NS = {"TAI": 0, "GPS": -19_000_000_000, "TT": 32_184_000_000}
_NS = 1_000_000_000
_DAY_NS = 86_400 * _NS


#: Two-part dates of single epochs already converted, by nanoseconds since 1970 (a refinement
#: propagates from the same epoch hundreds of times; ERFA's call costs ~40 µs a scalar).
_JD_OF_EPOCH: dict = {}
_JD_OF_EPOCH_MAX = 512


def datetime64_to_jd_utc(t) -> tuple[np.ndarray, np.ndarray]:
    """UTC datetime64 (any precision, naive = UTC) -> two-part UTC quasi-JD (ERFA dtf2d).

    A single epoch is remembered once ERFA converted it without a warning (the same two numbers
    on every later call; a dubious year or an error still goes through ERFA each time)."""
    t = np.asarray(t, dtype="datetime64[ns]")
    if t.ndim == 0:
        key = int(t.view(np.int64))
        jd = _JD_OF_EPOCH.get(key)
        if jd is None:
            jd = _jd_of_epoch(t)
            if jd is None:
                return _jd_utc(t)
        return np.asarray(jd[0], float), np.asarray(jd[1], float)
    return _jd_utc(t)


def _fields(t):
    """Year, month, day, hour, minute and seconds of UTC ``datetime64[ns]`` ``t``."""
    days = t.astype("datetime64[D]")
    y = days.astype("datetime64[Y]").astype(np.int64) + 1970
    m = days.astype("datetime64[M]").astype(np.int64) % 12 + 1
    d = (days - days.astype("datetime64[M]")).astype(np.int64) + 1
    ns = (t - days).astype(np.int64)
    hh = ns // 3_600_000_000_000
    mm = (ns // 60_000_000_000) % 60
    ss = (ns % 60_000_000_000) / 1e9
    return y, m, d, hh, mm, ss


def _jd_utc(t):
    jd1, jd2 = erfa.dtf2d("UTC", *_fields(t))
    return np.asarray(jd1, float), np.asarray(jd2, float)


def _jd_of_epoch(t):
    """``(jd1, jd2)`` floats of the single epoch ``t`` by ERFA's dtf2d (the function
    :func:`erfa.dtf2d` wraps, whose status it reports), kept in :data:`_JD_OF_EPOCH`; None when
    ERFA's status is not 0 (the caller's wrapped call then warns or raises as ever)."""
    d1, d2, status = erfa.ufunc.dtf2d("UTC", *_fields(t))
    if int(status) != 0:
        return None
    if len(_JD_OF_EPOCH) >= _JD_OF_EPOCH_MAX:
        _JD_OF_EPOCH.clear()
    jd = _JD_OF_EPOCH[int(t.view(np.int64))] = (float(d1), float(d2))
    return jd


def jd_utc_to_datetime64(jd1, jd2) -> np.ndarray:
    """Two-part UTC quasi-JD -> datetime64[ns] (nanosecond rounding; a leap second maps to :59.999...)."""
    iy, im, id_, ihmsf = erfa.d2dtf("UTC", 9, jd1, jd2)
    iy, im, id_ = np.asarray(iy), np.asarray(im), np.asarray(id_)
    ihmsf = np.asarray(ihmsf)
    h, mi, s, f = ihmsf["h"], ihmsf["m"], ihmsf["s"], ihmsf["f"]
    s = np.minimum(s, 59)  # 23:59:60 cannot be held in datetime64
    # the calendar date by datetime64's own integer arithmetic (year, then month, then day), not
    # by formatting and parsing a string per sample: the same dates
    months = (np.atleast_1d(iy).astype(np.int64) - 1970).astype("datetime64[Y]").astype("datetime64[M]")
    days = (months + (np.atleast_1d(im).astype(np.int64) - 1).astype("timedelta64[M]")).astype("datetime64[D]")
    dates = (days + (np.atleast_1d(id_).astype(np.int64) - 1).astype("timedelta64[D]")).astype("datetime64[ns]")
    out = (dates + np.atleast_1d(h).astype("timedelta64[h]") + np.atleast_1d(mi).astype("timedelta64[m]")
           + np.atleast_1d(s).astype("timedelta64[s]") + np.atleast_1d(f).astype("timedelta64[ns]"))
    return out.reshape(np.shape(jd1)) if np.ndim(jd1) else out[0]


def utc_to_tai(jd1, jd2):
    """UTC -> TAI two-part JD (leap seconds from ERFA's table)."""
    return erfa.utctai(jd1, jd2)


def tai_to_utc(jd1, jd2):
    return erfa.taiutc(jd1, jd2)


def utc_to_tt(jd1, jd2):
    """UTC -> TT two-part JD: TT = TAI + 32.184 s."""
    return erfa.taitt(*erfa.utctai(jd1, jd2))


def tt_to_utc(jd1, jd2):
    return erfa.taiutc(*erfa.tttai(jd1, jd2))


def tai_minus_utc_s(jd1, jd2) -> np.ndarray:
    """TAI - UTC in seconds (the accumulated leap seconds) at the given UTC dates."""
    iy, im, id_, fd = erfa.jd2cal(jd1, jd2)
    return erfa.dat(iy, im, id_, fd)


def scale_ns_to_utc_ns(naive, time_system: str):
    """Epochs of a time scale (int64 ns since 1970 on the scale's own uniform calendar) -> UTC
    ns since 1970 (naive, POSIX-like); ``time_system`` one of UTC, TAI, GPS, TT. None before 1960
    (outside the leap-second table).

    TAI - UTC comes from ERFA's leap-second table, looked up at the UTC date: guess with the
    TAI date, then look up again at the guessed UTC date (exact except inside a leap second,
    which lands on the first second of the next day).
    """
    if time_system == "UTC":
        return naive
    tai = naive - SCALE_MINUS_TAI_NS[time_system]
    dat = tai_minus_utc_ns(tai)
    if dat is None:
        return None
    dat = tai_minus_utc_ns(tai - dat)
    return None if dat is None else (tai - dat).astype(np.int64)


def tai_minus_utc_ns(utc_like):
    """TAI - UTC (int64 ns) at UTC epochs given as int64 ns since 1970; None before 1960."""
    days = np.floor_divide(utc_like, _DAY_NS)
    d = days.astype("datetime64[D]")
    year = d.astype("datetime64[Y]").astype(np.int64) + 1970
    month = d.astype("datetime64[M]").astype(np.int64) % 12 + 1
    day = (d - d.astype("datetime64[M]")).astype(np.int64) + 1
    fd = (utc_like - days * _DAY_NS) / _DAY_NS
    if np.any(year < 1960):
        return None
    seconds = erfa.dat(year.astype(np.int32), month.astype(np.int32), day.astype(np.int32), fd)
    return np.round(np.asarray(seconds, dtype="float64") * _NS).astype(np.int64)


def utc_to_ut1(jd1, jd2, dut1_s):
    """UTC -> UT1 two-part JD given UT1-UTC (seconds, scalar or per date)."""
    return erfa.utcut1(jd1, jd2, dut1_s)


def seconds_since(t_jd_utc: tuple, ref_jd_utc: tuple) -> np.ndarray:
    """Elapsed SI seconds (TAI, so leap seconds count) from ``ref`` to ``t``, both UTC two-part JDs."""
    a1, a2 = utc_to_tai(*t_jd_utc)
    b1, b2 = utc_to_tai(*ref_jd_utc)
    return ((np.asarray(a1) - b1) + (np.asarray(a2) - b2)) * DAY_S


def add_seconds_utc(ref_jd_utc: tuple, dt_s) -> tuple[np.ndarray, np.ndarray]:
    """UTC two-part JD of ``ref + dt_s`` SI seconds (through TAI, so leap seconds are honoured)."""
    b1, b2 = utc_to_tai(*ref_jd_utc)
    dt_s = np.asarray(dt_s, float)
    whole = np.floor(dt_s / DAY_S)
    return tai_to_utc(b1 + whole, b2 + (dt_s - whole * DAY_S) / DAY_S)


#: :meth:`EarthOrientation.at` keeps its answers for up to this many dates a call (the single
#: epochs and short sets that prepare asks again), at most ``_AT_MEMO_MAX`` of them.
_AT_MEMO_DATES = 4
_AT_MEMO_MAX = 256


class EopCoverageWarning(UserWarning):
    """Dates outside the tabulated Earth orientation (values held at the table's end)."""


@dataclass(frozen=True)
class EarthOrientation:
    """UT1-UTC and polar motion as functions of UTC MJD (IERS EOP tabulation, or constants).

    Interpolation is linear in UT1-TAI (continuous across leap seconds, unlike UT1-UTC).
    ``source`` names where the values came from, for the outputs' provenance.
    """

    mjd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ut1_minus_tai_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    xp_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    yp_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))
    constant_dut1_s: float = 0.0
    source: str = "none (UT1-UTC = 0, no polar motion)"

    @classmethod
    def constant(cls, dut1_s: float) -> "EarthOrientation":
        return cls(constant_dut1_s=float(dut1_s), source=f"constant UT1-UTC = {dut1_s} s, no polar motion")

    @property
    def tabulated(self) -> bool:
        return self.mjd.size > 0

    def covers(self, jd1, jd2) -> bool:
        """True when every date lies inside the tabulated span (always true for constants)."""
        if not self.tabulated:
            return True
        mjd = np.asarray(jd1) - 2400000.5 + np.asarray(jd2)
        return bool(np.all((mjd >= self.mjd[0]) & (mjd <= self.mjd[-1])))

    def at(self, jd1, jd2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(UT1-UTC s, xp rad, yp rad) at UTC two-part JDs; clamped at the table's ends."""
        jd1, jd2 = np.broadcast_arrays(np.asarray(jd1, float), np.asarray(jd2, float))
        if not self.tabulated:
            z = np.zeros(jd1.shape)
            return z + self.constant_dut1_s, z, z
        mjd = jd1 - 2400000.5 + jd2
        if mjd.size and (mjd.min() < self.mjd[0] - 1 or mjd.max() > self.mjd[-1] + 1):
            # held at the table's end value: say so (UT1-UTC drifts ~1 ms/day, ~0.5 m/day at the equator)
            warnings.warn(EopCoverageWarning(
                f"dates outside the Earth-orientation table ({self.source}: MJD {self.mjd[0]:.0f}-"
                f"{self.mjd[-1]:.0f}): UT1-UTC and polar motion held at the end value; give --eop with a "
                "table covering them"), stacklevel=2)
        key = (jd1.shape, jd1.tobytes(), jd2.tobytes()) if jd1.size <= _AT_MEMO_DATES else None
        if key is not None:
            # a few dates asked again (an epoch's frame and its station model): the values kept
            memo = self.__dict__.get("_at_memo")
            if memo is None:
                memo = self.__dict__["_at_memo"] = {}
            hit = memo.get(key)
            if hit is not None:
                return tuple(v.copy() for v in hit)
        ut1_tai = np.interp(mjd, self.mjd, self.ut1_minus_tai_s)
        dut1 = ut1_tai + tai_minus_utc_s(jd1, jd2)
        out = dut1, np.interp(mjd, self.mjd, self.xp_rad), np.interp(mjd, self.mjd, self.yp_rad)
        if key is not None:
            if len(memo) >= _AT_MEMO_MAX:
                memo.clear()
            memo[key] = tuple(v.copy() for v in out)
        return out


def eop_from_table(mjd, dut1_s, xp_arcsec, yp_arcsec, source: str) -> EarthOrientation:
    """Build :class:`EarthOrientation` from IERS columns (UT1-UTC in s, polar motion in arcsec)."""
    mjd = np.asarray(mjd, float)
    order = np.argsort(mjd)
    mjd = mjd[order]
    day = np.floor(mjd)
    tai_utc = tai_minus_utc_s(day + 2400000.5, mjd - day)
    as2r = np.pi / (180 * 3600)
    return EarthOrientation(mjd=mjd, ut1_minus_tai_s=np.asarray(dut1_s, float)[order] - tai_utc,
                            xp_rad=np.asarray(xp_arcsec, float)[order] * as2r,
                            yp_rad=np.asarray(yp_arcsec, float)[order] * as2r, source=source)
