"""pipeline.smooth: the (station, pass_id, kind) groups and their rows, against pandas' own groupby.

``smooth`` takes each group's rows from ``groupby(...).indices`` and sorts them by time itself (no
DataFrame per group); the reference here is the DataFrame-per-group iteration it replaced:
``groupby(sort=True)`` in key order, rows stably sorted by time, rows with a missing key left out.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from trackproc.pipeline.smooth import SmoothOptions, smooth
from trackproc.types import PassTable


def _table():
    rng = np.random.default_rng(3)
    rows = []
    for station, pass_id, kind, t0 in (("ZB", "2", "range_rate", 0.0), ("AA", "1", "range_rate", 500.0),
                                       ("AA", "1", "elevation", 500.0), ("AA", "10", "range_rate", 900.0)):
        t = t0 + np.arange(0.0, 120.0, 2.0)
        t[[3, 17]] = t[[3, 17]][::-1]                     # a pair out of time order
        t[25] = t[24]                                     # two samples at one time (stable order)
        value = 0.4 + 1e-3 * (t - t0) - 1e-6 * (t - t0) ** 2 + rng.normal(0.0, 0.01, t.size)
        rows += [(tt, station, pass_id, kind, v) for tt, v in zip(t, value)]
    rows += [(50.0, "AA", None, "range_rate", 0.5)]       # no pass id: in no group
    order = rng.permutation(len(rows))                    # the groups' rows interleaved
    rows = [rows[i] for i in order]
    frame = pd.DataFrame({
        "time": pd.Timestamp("2026-01-01T00:00:00Z") + pd.to_timedelta([r[0] for r in rows], unit="s"),
        "station": [r[1] for r in rows], "pass_id": [r[2] for r in rows], "kind": [r[3] for r in rows],
        "value": [r[4] for r in rows], "sigma": 0.01})
    return frame


def test_groups_rows_and_times_are_pandas_groupby_ones():
    frame = _table()
    result = smooth(PassTable(frame, {}), SmoothOptions(degree=2, clip=None))
    expected = []
    for (station, pass_id, kind), group in frame.groupby(["station", "pass_id", "kind"], sort=True):
        group = group.sort_values("time", kind="mergesort")
        t_ns = group["time"].dt.tz_localize(None).to_numpy().astype("datetime64[ns]").astype(np.int64)
        expected.append(((station, pass_id, kind), group.index.to_numpy(), (t_ns - t_ns[0]) * 1e-9,
                         pd.Timestamp(group["time"].iloc[0])))
    assert [(f.station, f.pass_id, f.kind) for f in result.fits] == [e[0] for e in expected]
    assert [e[0] for e in expected][0] == ("AA", "1", "elevation")          # key order, not row order
    for fit, (_, rows, t_s, epoch) in zip(result.fits, expected):
        np.testing.assert_array_equal(fit.rows, rows)
        np.testing.assert_array_equal(fit.t_s, t_s)
        assert fit.epoch == epoch
    missing = frame["pass_id"].isna().to_numpy()
    assert np.isnan(result.samples.column("smoothed")[missing]).all()
    assert np.isfinite(result.samples.column("smoothed")[~missing]).all()


def test_the_samples_table_columns_are_its_frames():
    result = smooth(PassTable(_table(), {}), SmoothOptions(degree=2, clip=None))
    table = result.samples
    again = PassTable(table.frame.copy(), table.meta)
    assert table.column_names == again.column_names
    for name in table.column_names:
        a, b = table.column(name), again.column(name)
        assert a.dtype == b.dtype, name
        na = pd.isna(a)                                   # a missing pass id stays missing (NaN != NaN)
        np.testing.assert_array_equal(na, pd.isna(b))
        np.testing.assert_array_equal(a[~na], b[~na])


def test_columns_utc_from_a_zone_aware_column_equal_pandas_conversion():
    """_Columns.utc from a zone-aware column's values (its UTC instants) against pandas'
    tz_convert("UTC").tz_localize(None), for another zone, a microsecond unit and a DST change."""
    from trackproc.pipeline.smooth import _Columns

    base = pd.date_range("2026-03-29 00:30", periods=400, freq="7s", tz="Europe/Copenhagen")    # 02:00 -> 03:00
    for times in (base, base.tz_convert("UTC"), base.as_unit("us"), base.tz_convert("America/St_Johns")):
        frame = pd.DataFrame({"time": times, "value": np.arange(400.0), "sigma": np.ones(400)})
        want = frame["time"].dt.tz_convert("UTC").dt.tz_localize(None).to_numpy().astype("datetime64[ns]")
        got = _Columns(frame).utc
        assert got.dtype == want.dtype
        np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))
