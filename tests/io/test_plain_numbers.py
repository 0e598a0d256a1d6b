"""Number cells of a CSV read by Arrow's reader are converted by Arrow's cast when they are plain
decimal literals (``io.columns._plain_numbers``): the same float64 bits as ``float()`` per cell,
and no answer (``float()`` decides) for any cell ``float()`` would read otherwise or reject."""

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackproc.io.columns import Column, SourceTable, _plain_numbers, column_numbers, source_table


def _by_float(cells):
    """The reference: Python's float() per cell, None if any cell is rejected."""
    try:
        return np.array([float(c) for c in cells], dtype=np.float64)
    except ValueError:
        return None


def _check(cells):
    got = _plain_numbers(pa.array(cells, pa.string()))
    if got is not None:
        expected = _by_float(cells)
        assert expected is not None, cells
        assert got.tobytes() == expected.tobytes(), cells
    return got


@settings(max_examples=500, deadline=None)
@given(st.lists(st.text(alphabet="0123456789.eE+-", min_size=0, max_size=10), min_size=1, max_size=4))
def test_literals_of_the_alphabet_agree_with_float(cells):
    _check(cells)


@settings(max_examples=500, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=4))
def test_shortest_reprs_are_read_back_bit_for_bit(values):
    assert _check([repr(v) for v in values]) is not None


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 10 ** 40), st.integers(0, 40), st.integers(-340, 320), st.booleans())
def test_long_mantissas_round_as_float_does(digits, point, exponent, negative):
    text = str(digits)
    point = min(point, len(text))
    cell = ("-" if negative else "") + text[:point] + "." + text[point:] + f"e{exponent}"
    assert _check([cell]) is not None


@pytest.mark.parametrize("cells", [
    ["1", ""], ["nan"], ["inf"], ["1_000"], [" 1"], ["１"], ["1e"], ["."], ["+-1"], ["--1"], ["1.2.3"],
])
def test_other_cells_are_left_to_float(cells):
    assert _check(cells) is None


def test_column_numbers_report_as_before():
    import pyarrow.csv  # noqa: F401 - with it loaded a small plain CSV is read by Arrow's reader (as in batch)

    data = b"time,doppler_hz,elevation_deg\n2026-03-20T09:30:00Z,1.5,x\n2026-03-20T09:30:01Z,,2e1\n"
    table = source_table(data, "p.csv")
    assert table.columns["doppler_hz"].strings is not None   # read by Arrow's reader
    values, missing, wrong = column_numbers(table, table.columns["doppler_hz"])
    assert np.isnan(values[1]) and values[0] == 1.5 and missing.tolist() == [False, True] and not wrong.any()
    values, missing, wrong = column_numbers(table, table.columns["elevation_deg"])
    assert wrong.tolist() == [True, False] and values[1] == 20.0
    plain = SourceTable("p.csv", {"v": Column("v", text=np.array(["1e3", "-0.0"], dtype=object),
                                              strings=pa.array(["1e3", "-0.0"]))}, np.array([2, 3]), 1, {})
    values, _, _ = column_numbers(plain, plain.columns["v"])
    assert values.tobytes() == np.array([1000.0, -0.0]).tobytes()
