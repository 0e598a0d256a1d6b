"""The pass table's numpy columns (``PassTable.column``, what refine and estimate read without
pandas) against the DataFrame the same file gives (``PassTable.frame``, what the other commands
read): the same values, types and rows, also after :meth:`PassTable.take`."""

from pathlib import Path

import numpy as np
import pytest

from trackproc.io.passfile import factorize, read_pass_table
from trackproc.types import PassTable

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def smoothed(tmp_path_factory, run_cli_shared):
    """The files under test, made in-process (this module's subject is what they contain; the
    commands' process paths are test_ingest.py's and test_smooth_cli.py's)."""
    out = tmp_path_factory.mktemp("passes")
    for args in (["ingest", ROOT / "sample_data/doppler_pass.csv", "--stations", ROOT / "sample_data/stations.csv",
                  "--carrier-hz", "2.2e9", "--mode", "one-way", "-o", out / "pass.parquet"],
                 ["smooth", out / "pass.parquet", "-o", out / "smoothed.parquet"],
                 ["smooth", out / "pass.parquet", "-o", out / "smoothed.csv"]):
        result = run_cli_shared(["-q", *args])
        assert result.exit_code == 0, result.stderr
    return out


def _same(columns_table: PassTable, frame_table: PassTable):
    assert columns_table.column_names == frame_table.column_names
    for name in columns_table.column_names:
        a, b = columns_table.column(name), frame_table.column(name)
        assert a.dtype == b.dtype, name
        if a.dtype.kind == "f":
            np.testing.assert_array_equal(a, b)
        else:
            assert list(a) == list(b), name


@pytest.mark.parametrize("name", ["pass.parquet", "smoothed.parquet", "smoothed.csv"])
def test_columns_equal_the_frames(smoothed, name):
    table = read_pass_table(str(smoothed / name))
    from_frame = PassTable(read_pass_table(str(smoothed / name)).frame, table.meta)
    assert table.n_rows == from_frame.n_rows == len(from_frame.frame) > 100
    _same(table, from_frame)
    rows = np.arange(table.n_rows) % 3 == 1
    _same(table.take(rows), from_frame.take(rows))
    assert table.take(rows).frame.equals(from_frame.take(rows).frame)
    assert table.frame.equals(from_frame.frame)


def test_factorize_is_pandas_factorize():
    import pandas as pd

    values = np.array(["b", "a", "c", "a", "b", "d"], dtype=object)
    codes, uniques = factorize(values)
    want_codes, want_uniques = pd.factorize(values)
    assert codes.tolist() == want_codes.tolist() and list(uniques) == list(want_uniques)


@pytest.mark.parametrize("cells, plain", [
    (["2026-03-20T09:24:28Z", "2026-03-20T09:24:28.5Z", "2024-02-29T00:00:00.123456789Z"], True),
    (["2026-03-20T09:24:28Z", "2026-01-01T24:00:00Z"], False),          # pandas' NaT, reported by row
    (["2026-03-20T09:24:28Z", "2026-02-29T00:00:00Z"], False),
    (["2026-03-20T09:24:28+00:00"], False),
    (["2300-01-01T00:00:00Z"], False),                                   # outside the supported years
])
def test_csv_times_parsed_by_numpy_are_pandas_times(cells, plain):
    import pandas as pd

    from trackproc.io.columns import Column
    from trackproc.io.passfile import _plain_times

    got = _plain_times(Column("time", text=np.array(cells, dtype=object)))
    assert (got is not None) == plain
    if plain:
        want = pd.to_datetime(pd.Series(cells), utc=True, format="ISO8601").dt.tz_localize(None).to_numpy()
        assert got.tolist() == want.astype("datetime64[ns]").tolist()


@pytest.mark.parametrize("name", ["smoothed.parquet", "smoothed.csv"])
def test_columns_kept_once_the_frame_is_built(smoothed, name):
    """A table read from a file answers with the same values as the frame's own conversion before and
    after its frame was read (from then on from the frame, which its reader may change in place), also
    after take; setting the frame: the new frame is read."""
    table = read_pass_table(str(smoothed / name))
    before = {column: table.column(column) for column in table.column_names}
    frame = table.frame                                            # built and handed out
    from_frame = PassTable(frame, table.meta)                      # the reference: the frame's conversion
    _same(table, from_frame)
    for column, values in before.items():
        assert np.array_equal(values, from_frame.column(column), equal_nan=values.dtype.kind == "f"), column
    rows = np.arange(table.n_rows) % 3 == 1
    taken = table.take(rows)
    _same(taken, from_frame.take(rows))
    assert taken.frame.equals(from_frame.take(rows).frame)
    changed = frame.copy()
    changed["value"] = changed["value"] + 1.0
    table.frame = changed
    np.testing.assert_array_equal(table.column("value"), from_frame.column("value") + 1.0)
