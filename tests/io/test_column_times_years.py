"""column_times skips its per-row year test when every cell starts with an in-range ``YYYY-``;
the times (and the rows reported unparseable) must be those of the year test itself."""

import numpy as np
import pandas as pd

from trackproc.io.columns import Column, SourceTable, _years_in_range, column_times
from trackproc.io.problems import Problems
from trackproc.io.validate import FIRST_YEAR, LAST_YEAR


def _times(cells):
    text = np.array(cells, dtype=object)
    table = SourceTable("t.csv", {"time": Column("time", text=text)}, np.arange(2, len(cells) + 2), 1, {})
    problems = Problems(table.rows, "t.csv")
    return column_times(table, table.columns["time"], problems), problems


def _reference(cells):
    """The year test written out: a cell whose leading year is outside the range is unparseable."""
    out = []
    for cell in cells:
        head = cell.strip().split("-")[0]
        year = int(head) if head.lstrip("+-").isdigit() and len(head.lstrip("+-")) >= 4 else None
        if year is not None and not FIRST_YEAR <= year <= LAST_YEAR:
            out.append(np.datetime64("NaT"))
            continue
        stamp = pd.to_datetime(cell, utc=True, format="ISO8601", errors="coerce")
        out.append(np.datetime64("NaT") if pd.isna(stamp) else stamp.tz_localize(None).as_unit("ns").to_datetime64())
    return np.array(out, dtype="datetime64[ns]")


def test_plain_years_take_the_short_way_and_give_the_same_times():
    cells = ["2026-03-20T09:30:00.000000Z", "2026-03-20T09:30:01.500000Z", "2026-03-20T09:30:02Z"]
    assert _years_in_range(cells)
    got, problems = _times(cells)
    np.testing.assert_array_equal(got, _reference(cells))
    assert not np.isnat(got).any()


def test_any_other_year_takes_the_year_test():
    for odd in ("1600-01-01T00:00:00Z", "3000-01-01T00:00:00Z", " 2026-03-20T09:30:00Z", "+2026-03-20T09:30:00Z",
                "garbage", "", "２０２６-03-20T09:30:00Z"):
        cells = ["2026-03-20T09:30:00Z", odd]
        assert not _years_in_range(cells), odd
        got, _ = _times(cells)
        np.testing.assert_array_equal(got, _reference(cells), err_msg=odd)
    got, _ = _times(["1600-01-01T00:00:00Z", "2026-03-20T09:30:00Z"])
    assert np.isnat(got[0]) and not np.isnat(got[1])
