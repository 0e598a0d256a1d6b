"""The fixed-layout ISO 8601 reader of CSV time columns (``io.columns._fixed_iso_times``) against
the general one (pandas' ISO 8601 parser): where it answers, the same instants bit for bit; on any
cell the general reader rejects or reads differently, no answer (the general reader then reports
the rows)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackproc.io.columns import _fixed_iso_times, _iso_times, column_times, source_table
from trackproc.io.problems import Problems


def _agree(cells):
    cells = np.array(cells, dtype=object)
    fast, general = _fixed_iso_times(cells), _iso_times(cells)
    if fast is not None:
        assert fast.dtype == np.dtype("datetime64[ns]")
        assert not np.isnat(general).any()
        np.testing.assert_array_equal(fast.view(np.int64), general.view(np.int64))
    return fast


@st.composite
def layouts(draw):
    """Cells of one layout, fields drawn partly out of range (month 13, day 31 of a short month,
    hour 24, second 60 as a leap second, years outside 1678-2261)."""
    digits = draw(st.integers(0, 10))
    sep = draw(st.sampled_from(["T", "T", " ", "t"]))
    zone = draw(st.sampled_from(["Z", "+00:00", "", "z", "+01:00", "-00:00", "+0000"]))
    cell = st.builds(
        lambda y, mo, d, h, mi, s, f: (f"{y:04d}-{mo:02d}-{d:02d}{sep}{h:02d}:{mi:02d}:{s:02d}"
                                       + (f".{f % 10 ** digits:0{digits}d}" if digits else "") + zone),
        st.integers(1600, 2300), st.integers(0, 13), st.integers(0, 32), st.integers(0, 24),
        st.integers(0, 60), st.integers(0, 60), st.integers(0, 10 ** 10))
    return draw(st.lists(cell, min_size=1, max_size=6))


@settings(max_examples=300, deadline=None)
@given(layouts())
def test_fixed_layouts_agree_with_the_general_reader(cells):
    _agree(cells)


@settings(max_examples=200, deadline=None)
@given(layouts(), st.integers(0, 40), st.sampled_from(["", " ", "x", "9", "-", ":", ".", "é", "Z", "00"]))
def test_damaged_cells_agree_with_the_general_reader(cells, at, text):
    """One cell with a character replaced, removed or inserted: answered only when still valid."""
    cell = cells[0]
    at = min(at, len(cell))
    cells[0] = cell[:at] + text + cell[at + 1:]
    _agree(cells)


@pytest.mark.parametrize("cells", [
    ["2026-03-20T09:30:00.000000Z", "2026-03-20T09:30:01.000000Z"],          # the nightly pass files
    ["2024-02-29T23:59:59Z"], ["2020-04-01T08:44:03.29Z"], ["2026-03-20T09:30:00"],
    ["2026-03-20T09:30:00.123456789+00:00"], ["1678-01-01T00:00:00Z"], ["2261-12-31T23:59:59.999999999Z"],
])
def test_valid_layouts_are_read(cells):
    assert _agree(cells) is not None


@pytest.mark.parametrize("cells", [
    ["2023-02-29T00:00:00Z"], ["2026-03-20T09:30:60Z"], ["2026-13-01T00:00:00Z"], ["2026-03-20T24:00:00Z"],
    ["1677-12-31T00:00:00Z"], ["2262-01-01T00:00:00Z"], ["2026-03-20T09:30:00.Z"],
    ["2026-03-20T09:30:00.1234567891Z"], ["2026-03-20T09:30:00+01:00"], ["2026-03-20 09:30:00Z"],
    ["2026-03-20T09:30:00Z", "2026-03-20T09:30:01.5Z"], ["2026-03-20T09:30:00Z", ""], ["２026-03-20T09:30:00Z"],
])
def test_other_cells_go_to_the_general_reader(cells):
    assert _agree(cells) is None


def test_an_invalid_row_is_reported_as_before():
    data = b"time,doppler_hz\n2026-03-20T09:30:00Z,1\n2026-02-30T09:30:01Z,2\n"
    table = source_table(data, "p.csv")
    problems = Problems(table.rows, table.source)
    values = column_times(table, table.columns["time"], problems)
    assert np.isnat(values).tolist() == [False, True]
    error = problems.first_error()
    assert error.row == 3 and "2026-02-30T09:30:01Z" in str(error)


def test_a_short_signed_year_is_an_unparseable_time_not_a_traceback():
    """pandas reads ``-600-01-01`` as year -600 and fails converting it to nanoseconds."""
    got = _iso_times(np.array(["-600-01-01T00:00:00Z", "2026-01-01T00:00:00Z"], dtype=object))
    assert np.isnat(got).tolist() == [True, False]
