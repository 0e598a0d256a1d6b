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
