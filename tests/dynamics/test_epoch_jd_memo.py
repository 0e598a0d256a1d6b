"""A single epoch's two-part UTC date is remembered (dynamics.timescales.datetime64_to_jd_utc): the
remembered numbers are bit for bit the array path's (ERFA's dtf2d on the same fields), on the first
call and on later ones, and a date ERFA warns about warns on every call."""

import warnings

import erfa
import numpy as np
import pytest

from trackproc.dynamics import timescales as ts


def test_a_single_epoch_is_the_array_path_bit_for_bit_first_and_later():
    rng = np.random.default_rng(7)
    lo = np.datetime64("1975-01-01", "ns").astype(np.int64)
    hi = np.datetime64("2026-12-31", "ns").astype(np.int64)
    ns = np.concatenate([rng.integers(lo, hi, 300),
                         # a leap second's day and its neighbours, whole and odd nanoseconds
                         np.array(["2016-12-31T00:00:00", "2016-12-31T23:59:59.999999999", "2017-01-01T00:00:00",
                                   "2016-12-31T12:00:00.5"], "datetime64[ns]").astype(np.int64)])
    t = ns.view("datetime64[ns]")
    jd1, jd2 = ts.datetime64_to_jd_utc(t)
    ref1, ref2 = erfa.dtf2d("UTC", *ts._fields(t))
    assert np.array_equal(jd1, ref1) and np.array_equal(jd2, ref2)
    ts._JD_OF_EPOCH.clear()
    for k in range(t.size):
        for _ in range(2):                                  # computed, then remembered
            a, b = ts.datetime64_to_jd_utc(t[k])
            assert a.shape == () and a.dtype == np.float64 and b.dtype == np.float64
            assert a.tobytes() == jd1[k].tobytes() and b.tobytes() == jd2[k].tobytes()
    assert len(ts._JD_OF_EPOCH) > 0


def test_other_precisions_and_the_remembered_pair_is_not_shared_state():
    t = np.datetime64("2026-03-20T09:30:00.25")
    a, b = ts.datetime64_to_jd_utc(t)
    a += 1.0                                               # a caller's change does not reach the memo
    c, d = ts.datetime64_to_jd_utc(np.datetime64(t, "ns"))
    assert c == a - 1.0 and d == b


def test_a_dubious_year_warns_on_every_call():
    t = np.datetime64("2090-01-01T00:00:00", "ns")
    for _ in range(2):
        with pytest.warns(erfa.ErfaWarning, match="dubious year"):
            jd1, jd2 = ts.datetime64_to_jd_utc(t)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert (jd1, jd2) == tuple(np.asarray(x, float) for x in erfa.dtf2d("UTC", 2090, 1, 1, 0, 0, 0.0))
    assert int(t.view(np.int64)) not in ts._JD_OF_EPOCH


def _table():
    mjd = np.arange(60000.0, 61500.0)
    rng = np.random.default_rng(3)
    return ts.eop_from_table(mjd, rng.normal(0.0, 0.2, mjd.size), rng.normal(0.0, 0.3, mjd.size),
                             rng.normal(0.0, 0.3, mjd.size), "test")


def test_earth_orientation_of_a_few_dates_is_remembered_bit_for_bit():
    eop = _table()
    fresh = _table()                                       # the same table, nothing remembered
    dates = [(np.float64(2461119.5), np.float64(0.3961)), (np.array([2461119.5]), np.array([0.25])),
             (np.full(3, 2461119.5), np.array([0.1, 0.2, 0.3])), (np.full(4, 2460000.5), np.linspace(0, 1, 4))]
    for jd1, jd2 in dates:
        want = fresh.at(jd1, jd2)
        fresh.__dict__.pop("_at_memo", None)
        for _ in range(3):                                 # computed, then remembered
            got = eop.at(jd1, jd2)
            for g, w in zip(got, want):
                assert type(g) is type(w) and np.shape(g) == np.shape(w)
                assert np.asarray(g).tobytes() == np.asarray(w).tobytes()
        if isinstance(got[0], np.ndarray):
            got[0][...] = 99.0                             # a caller's change does not reach the memo
            assert np.asarray(eop.at(jd1, jd2)[0]).tobytes() == np.asarray(want[0]).tobytes()
    many = np.full(50, 2461119.5), np.linspace(0.0, 0.5, 50)
    eop.at(*many)
    assert all(k[0] != (50,) for k in eop.__dict__["_at_memo"])     # long sets are not kept


def test_dates_outside_the_table_warn_on_every_call():
    eop = _table()
    for _ in range(2):
        with pytest.warns(ts.EopCoverageWarning):
            eop.at(np.float64(2461600.5), np.float64(0.0))        # MJD 61600, past the table
