"""pipeline.smooth and io.passfile on a table of numpy columns (a pass file read, ingest's compact
columns): smoothed and written without building the DataFrame, and without importing pandas.

The reference is the DataFrame path of the same functions (the table given as ``PassTable(frame,
meta)``): the pass file's bytes (Parquet and Arrow), the summary and the fits must be the same;
the Arrow columns there come from ``pa.array(..., from_pandas=True)``, here from their buffers.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackproc.io.passfile import pass_table_bytes, read_pass_table
from trackproc.pipeline.smooth import SmoothOptions, smooth
from trackproc.types import PassTable

SAMPLE = Path(__file__).resolve().parents[2] / "sample_data" / "multistation.parquet"


def _frame_copy(table: PassTable) -> PassTable:
    # through a twin (with_meta): reading a table's frame hands it out, which drops that table's columns
    return PassTable(table.with_meta(dict(table.meta)).frame.copy(), dict(table.meta))


def _assert_same_result(got, expected, names=("time", "station", "pass_id", "kind", "value", "sigma")):
    assert got.summary == expected.summary
    assert [(f.label, f.status) for f in got.fits] == [(f.label, f.status) for f in expected.fits]
    for a, b in zip(got.fits, expected.fits):
        np.testing.assert_array_equal(a.rows, b.rows)
        np.testing.assert_array_equal(a.t_s, b.t_s)
        assert a.epoch == b.epoch and a.epoch_utc == b.epoch_utc
    for name in (*names, "smoothed", "residual", "flag"):
        np.testing.assert_array_equal(got.samples.column(name), expected.samples.column(name))


def test_pass_file_columns_smoothed_and_written_as_through_the_frame():
    table = read_pass_table(str(SAMPLE))
    assert table.numpy_columns() is not None               # the path under test
    reference = smooth(_frame_copy(table))
    result = smooth(table)
    _assert_same_result(result, reference)
    assert result.table.numpy_columns() is not None
    for fmt in ("parquet", "arrow"):
        assert pass_table_bytes(result.table, fmt) == pass_table_bytes(reference.table, fmt), fmt
    assert result.table._frame is None                      # written without its DataFrame
    # smoothed again (the added columns replaced): as the frame path does it
    again, again_ref = smooth(result.table), smooth(_frame_copy(reference.table))
    assert pass_table_bytes(again.table) == pass_table_bytes(again_ref.table)


def _columns_table(with_failed: bool, missing_key: bool):
    rng = np.random.default_rng(5)
    t0 = np.datetime64("2026-01-01T00:00:00", "ns")
    rows = []
    for station, pass_id, t_start in (("B", "2", 0), ("A", "1", 400)):
        t = t_start + np.arange(0.0, 90.0, 1.5)
        rows += [(ts, station, pass_id, "range_rate", 0.3 + 1e-3 * (ts - t_start) + rng.normal(0, 0.01))
                 for ts in t]
    if with_failed:                                         # one sample: its fit fails, NaN smoothed
        rows.append((700.0, "C", "9", "range_rate", 0.1))
    if missing_key:                                         # no pass id: in no group
        rows.append((30.0, "A", None, "range_rate", 0.2))
    order = rng.permutation(len(rows))
    rows = [rows[i] for i in order]
    columns = {"time": t0 + np.array([round(r[0] * 1e9) for r in rows], dtype="timedelta64[ns]"),
               "station": np.array([r[1] for r in rows], dtype=object),
               "pass_id": np.array([r[2] for r in rows], dtype=object),
               "kind": np.array([r[3] for r in rows], dtype=object),
               "value": np.array([r[4] for r in rows]), "sigma": np.full(len(rows), 0.01)}
    frame = pd.DataFrame({**columns, "time": pd.DatetimeIndex(columns["time"]).tz_localize("UTC")})
    meta = {"doppler_mode": "one-way"}
    return PassTable.from_columns(columns, meta, lambda: frame.copy()), PassTable(frame.copy(), meta)


def test_failed_fit_nan_written_as_null_as_from_pandas():
    table, reference = _columns_table(with_failed=True, missing_key=False)
    result, expected = smooth(table, SmoothOptions(degree=2)), smooth(reference, SmoothOptions(degree=2))
    assert [f.status for f in result.fits].count("failed") == 1
    _assert_same_result(result, expected)
    assert np.isnan(result.samples.column("smoothed")).sum() == 1
    assert pass_table_bytes(result.table) == pass_table_bytes(expected.table)
    assert result.table._frame is None


def test_missing_key_falls_back_to_the_frame_groups():
    table, reference = _columns_table(with_failed=False, missing_key=True)
    result, expected = smooth(table), smooth(reference)
    # (the missing pass id itself: None in the column, NaN in the frame)
    _assert_same_result(result, expected, ("time", "station", "kind", "value", "sigma"))
    assert np.isnan(result.samples.column("smoothed")[pd.isna(table.column("pass_id"))]).all()


@pytest.mark.subprocess
def test_read_smooth_write_imports_no_pandas(tmp_path):
    probe = ("import sys; from trackproc.io.passfile import read_pass_table, pass_table_bytes; "
             "from trackproc.pipeline.smooth import smooth; "
             f"r = smooth(read_pass_table({str(SAMPLE)!r})); data = pass_table_bytes(r.table, 'parquet'); "
             "print(len(data) > 0, 'pandas' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["True", "False"], res.stdout + res.stderr
