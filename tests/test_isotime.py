"""ISO 8601 time text (isotime.py) against pandas' and numpy's own formatting."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trackproc.isotime import iso_utc, iso_utc_array

RNG = np.random.default_rng(5)
#: random instants 1972..2050 at nanosecond resolution
TIMES = (np.datetime64("1972-01-01T00:00:00", "ns")
         + RNG.integers(0, 78 * 365 * 86400 * 10**9, 200).astype("timedelta64[ns]"))


@pytest.mark.parametrize("t", TIMES[:50])
def test_fixed_digits_match_pandas_and_numpy(t):
    ts = pd.Timestamp(t)
    assert iso_utc(t, 6) == ts.strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    assert iso_utc(t, 3) == ts.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
    assert iso_utc(t, 9) == np.datetime_as_string(t, unit="ns") + "Z"
    assert iso_utc(t, 0) == ts.strftime("%Y-%m-%dT%H:%M:%SZ")
    assert iso_utc(t, 6, suffix="") == np.datetime_as_string(t, unit="us")
    # the same instant given as tz-aware pandas time in another zone
    assert iso_utc(ts.tz_localize("UTC").tz_convert("Asia/Kolkata"), 9) == iso_utc(t, 9)


def test_default_is_milliseconds_at_least_more_when_needed():
    assert iso_utc(np.datetime64("2026-03-20T09:30:00")) == "2026-03-20T09:30:00.000Z"
    assert iso_utc(np.datetime64("2026-03-20T09:30:00.5")) == "2026-03-20T09:30:00.500Z"
    assert iso_utc(np.datetime64("2026-03-20T09:30:00.123456789")) == "2026-03-20T09:30:00.123456789Z"
    assert iso_utc(np.datetime64("2026-03-20T09:30:00.1234")) == "2026-03-20T09:30:00.1234Z"
    for t in TIMES:
        text = iso_utc(t)
        assert np.datetime64(text[:-1], "ns") == t            # exact: nothing lost


def test_array_uses_the_coarsest_exact_unit():
    whole = np.array(["2026-03-20T09:30:00", "2026-03-20T09:30:10"], dtype="datetime64[ns]")
    assert list(iso_utc_array(whole)) == ["2026-03-20T09:30:00Z", "2026-03-20T09:30:10Z"]
    milli = whole + np.timedelta64(250, "ms")
    assert list(iso_utc_array(milli)) == ["2026-03-20T09:30:00.250Z", "2026-03-20T09:30:10.250Z"]
    text = iso_utc_array(TIMES)
    assert all(np.datetime64(s[:-1], "ns") == t for s, t in zip(text, TIMES))
