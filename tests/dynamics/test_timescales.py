"""Time scales: leap seconds, TT, UT1 from an EOP table, datetime64 <-> two-part JD."""

import erfa
import numpy as np
import pytest

from trackproc.dynamics import timescales as ts


def jd(text):
    return ts.datetime64_to_jd_utc(np.datetime64(text))


def test_leap_second_2016_12_31_counts_in_elapsed_time():
    # 2016-12-31T23:59:60 exists: from 23:59:59.5 to 00:00:00 is 1.5 SI seconds, not 0.5
    dt = ts.seconds_since(jd("2017-01-01T00:00:00"), jd("2016-12-31T23:59:59.5"))
    assert float(dt) == pytest.approx(1.5, abs=1e-9)
    # a day without a leap second
    dt = ts.seconds_since(jd("2016-12-31T00:00:00"), jd("2016-12-30T23:59:59.5"))
    assert float(dt) == pytest.approx(0.5, abs=1e-9)


def test_add_seconds_crosses_the_leap_second():
    j1, j2 = ts.add_seconds_utc(jd("2016-12-31T23:59:59.5"), 1.5)
    assert ts.jd_utc_to_datetime64(j1, j2) == np.datetime64("2017-01-01T00:00:00", "ns")


def test_tai_minus_utc_steps_by_one_second():
    assert float(ts.tai_minus_utc_s(*jd("2016-12-31T12:00:00"))) == 36.0
    assert float(ts.tai_minus_utc_s(*jd("2017-01-01T12:00:00"))) == 37.0


def test_tt_minus_tai_is_32_184_s():
    j = jd("2026-03-20T09:30:00")
    tai = ts.utc_to_tai(*j)
    tt = ts.utc_to_tt(*j)
    diff = ((tt[0] - tai[0]) + (tt[1] - tai[1])) * 86400.0
    assert float(diff) == pytest.approx(ts.TT_MINUS_TAI_S, abs=1e-6)
    # and TT - UTC = 37 + 32.184 s after 2017
    utc_diff = ((tt[0] - j[0]) + (tt[1] - j[1])) * 86400.0
    assert float(utc_diff) == pytest.approx(69.184, abs=1e-6)


def test_tt_round_trip():
    j = jd("2026-03-20T09:30:00.123456")
    back = ts.tt_to_utc(*ts.utc_to_tt(*j))
    assert abs(((back[0] - j[0]) + (back[1] - j[1])) * 86400.0) < 1e-6


def test_eop_interpolation_is_continuous_in_ut1_across_a_leap_second():
    # IERS Bulletin values around the 2016-12-31 leap second: UT1-UTC jumps by +1 s
    mjd = [57752.0, 57753.0, 57754.0, 57755.0]
    dut1 = [-0.4078, -0.4086, 0.5914, 0.5906]
    eop = ts.eop_from_table(mjd, dut1, [0.0] * 4, [0.0] * 4, source="test")

    def ut1_minus_tai(text):
        j = jd(text)
        d, _, _ = eop.at(*j)
        u1, u2 = ts.utc_to_ut1(*j, d)
        a1, a2 = ts.utc_to_tai(*j)
        return float(((u1 - a1) + (u2 - a2)) * 86400.0)

    before = ut1_minus_tai("2016-12-31T23:59:59.9")
    after = ut1_minus_tai("2017-01-01T00:00:00.1")
    assert abs(after - before) < 1e-6          # continuous (no 1 s jump)
    assert before == pytest.approx(-0.4086 - 36.0, abs=1e-4)
    # UT1-UTC itself steps by one second across the leap
    d_before = float(eop.at(*jd("2016-12-31T23:59:59.9"))[0])
    d_after = float(eop.at(*jd("2017-01-01T00:00:00.1"))[0])
    assert d_after - d_before == pytest.approx(1.0, abs=1e-4)
    # mid-day: linear in UT1-TAI
    mid = float(eop.at(*jd("2016-12-30T12:00:00"))[0])
    assert mid == pytest.approx(0.5 * (-0.4078 - 0.4086), abs=1e-9)


def test_datetime64_to_jd_matches_erfa_dtf2d_and_round_trips():
    t = np.array(["2026-03-20T09:30:00.123456789", "2000-01-01T12:00:00"], dtype="datetime64[ns]")
    j1, j2 = ts.datetime64_to_jd_utc(t)
    e1, e2 = erfa.dtf2d("UTC", 2026, 3, 20, 9, 30, 0.123456789)
    assert j1[0] + j2[0] == pytest.approx(e1 + e2, abs=1e-12)
    assert j1[1] + j2[1] == 2451545.0
    back = ts.jd_utc_to_datetime64(j1, j2)
    assert np.all(np.abs((back - t).astype(np.int64)) <= 1)


def test_constant_eop_has_no_polar_motion():
    eop = ts.EarthOrientation.constant(-0.2)
    d, xp, yp = eop.at(*jd("2026-03-20T00:00:00"))
    assert float(d) == -0.2 and float(xp) == 0.0 and float(yp) == 0.0


@pytest.mark.parametrize("scale", ["TAI", "GPS", "TT"])
def test_scale_ns_to_utc_against_erfa(scale):
    """TAI/GPS/TT epochs (ns on the scale's calendar) -> UTC, against ERFA's taiutc/tttai,
    across the 2016-12-31 leap second."""
    import erfa

    utc = np.array(["2016-12-31T23:59:00", "2017-01-01T00:00:30", "2020-06-01T12:00:00.25"], dtype="datetime64[ns]")
    offset = {"TAI": 0.0, "GPS": -19.0, "TT": 32.184}[scale]
    # the same instants on the scale's calendar, by ERFA
    u1, u2 = ts.datetime64_to_jd_utc(utc)
    a1, a2 = erfa.utctai(u1, u2)
    tai_ns = np.array([np.datetime64("2000-01-01T12:00:00", "ns")
                       + np.timedelta64(int(round(((x - 2451545.0) + y) * 86400e9)), "ns") for x, y in zip(a1, a2)])
    naive = tai_ns.astype(np.int64) + int(round(offset * 1e9))
    back = ts.scale_ns_to_utc_ns(naive, scale)
    assert np.all(np.abs(back - utc.astype(np.int64)) <= 1000)          # within 1 us (JD round-off)
    assert ts.scale_ns_to_utc_ns(naive, "UTC") is naive
