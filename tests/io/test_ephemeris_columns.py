"""The ephemeris written from numpy columns (``io/tables.py``'s buffer-built Arrow arrays, no
pandas): each array equals pyarrow's own ``pa.array`` of the same values, and an ephemeris held
as columns writes the same bytes as the same rows held as a pandas DataFrame (the writer before
the columns), in every format; a written file reads back to the same columns."""

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from trackproc.io import ephemeris as em
from trackproc.io.tables import bool_array, float_array, string_array, utc_time_array


def test_buffer_arrays_equal_pyarrows_own():
    times = np.array(["2026-03-20T09:30:00", "1970-01-01T00:00:00.000000001", "2199-12-31T23:59:59.5"],
                     dtype="datetime64[ns]")
    values = np.array([1.5, -0.0, np.inf])[::-1]                 # a strided view
    flags = np.array([True, False, True, True, False, False, True, False, True])   # 9: two bytes of bits
    text = np.array(["KIR", "", "Zhōngshān ✓"], dtype=object)
    pairs = [(utc_time_array(times), pa.array(times, pa.timestamp("ns")).cast(pa.timestamp("ns", tz="UTC"))),
             (float_array(values), pa.array(values, pa.float64())),
             (bool_array(flags), pa.array(flags, pa.bool_())),
             (string_array(text), pa.array(text, pa.string()))]
    for ours, theirs in pairs:
        ours.validate(full=True)
        assert ours.type == theirs.type and ours.null_count == 0
        assert ours.equals(theirs), (ours, theirs)
    assert string_array([]).equals(pa.array([], pa.string())) and float_array([]).equals(pa.array([], pa.float64()))


def _rows(n=5):
    times = np.datetime64("2026-03-20T09:30:00", "ns") + np.arange(n) * np.timedelta64(1500, "ms")
    rng = np.random.default_rng(3)
    columns = {"time": times}
    for name in em.COLUMNS[1:]:
        columns[name] = rng.normal(size=n) * 7e6
    columns["visible"] = rng.random(n) > 0.5
    columns["note"] = np.array([f"row {k} é" for k in range(n)], dtype=object)
    return columns


@pytest.mark.parametrize("fmt", ["parquet", "arrow", "csv"])
def test_columns_write_the_dataframes_bytes(fmt):
    columns, meta = _rows(), {"force_model": "two-body", "constants": {"mu": 3.986004418e14}}
    frame = pd.DataFrame({**columns, "time": pd.DatetimeIndex(columns["time"]).tz_localize("UTC")})
    ours, theirs = em.Ephemeris(columns, meta), em.Ephemeris(frame, meta)
    assert em.ephemeris_bytes(ours, fmt) == em.ephemeris_bytes(theirs, fmt)
    # the frame built from the columns is the DataFrame's
    pd.testing.assert_frame_equal(ours.frame, frame)


def test_oem_from_columns_and_from_the_dataframe():
    columns = {k: v for k, v in _rows().items() if k in em.COLUMNS}
    cov = np.einsum("nij,nkj->nik", *(np.random.default_rng(5).normal(size=(2, 5, 6, 6))))
    for k, name in enumerate(em.COV_COLUMNS):
        columns[name] = cov.reshape(-1, 36)[:, k]
    frame = pd.DataFrame({**columns, "time": pd.DatetimeIndex(columns["time"]).tz_localize("UTC")})
    texts = [em.oem_text(em.Ephemeris(c, {}), created=np.datetime64("2026-01-01T00:00:00"))
             for c in (columns, frame)]
    assert texts[0] == texts[1] and texts[0].count("EPOCH =") == 5
    np.testing.assert_array_equal(em.Ephemeris(columns).matrix("cov"), cov)


@pytest.mark.parametrize("fmt", ["parquet", "arrow", "csv"])
def test_written_ephemeris_reads_back(fmt):
    columns = _rows(4)
    del columns["visible"]                         # (a CSV's true/false reads back as text)
    back = em.parse_ephemeris(em.ephemeris_bytes(em.Ephemeris(columns, {"a": 1}), fmt), f"e.{fmt}")
    assert list(back.columns) == list(columns) and back.meta["a"] == 1
    np.testing.assert_array_equal(back.columns["time"], columns["time"])
    np.testing.assert_array_equal(back.states, np.column_stack([columns[c] for c in em.COLUMNS[1:]]))
    assert list(back.columns["note"]) == list(columns["note"])
    assert len(back) == 4 and len(back.take(back.columns["x_m"] > 0)) == int((columns["x_m"] > 0).sum())
