"""``io.tables.string_array`` against Arrow's own ``pa.array(..., pa.string())`` of the values'
``str``: the labels' path (few distinct ``str`` labels, the pass table's key columns) and the
per-value path give the same array, buffers included (a Parquet or Arrow file of it is the same
bytes)."""

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackproc.io import tables
from trackproc.io.tables import string_array


def _reference(values) -> pa.Array:
    return pa.array([str(v) for v in values], pa.string())


def _same(got: pa.Array, want: pa.Array) -> None:
    assert got.equals(want)
    assert got.null_count == 0 and got.offset == 0
    # the same offsets and bytes (what reaches a file), not only equal values
    offsets_got = np.frombuffer(got.buffers()[1], np.int32, len(got) + 1)
    offsets_want = np.frombuffer(want.buffers()[1], np.int32, len(want) + 1)
    assert offsets_got.tolist() == offsets_want.tolist()
    end = int(offsets_want[-1])
    assert got.buffers()[2].to_pybytes()[:end] == want.buffers()[2].to_pybytes()[:end]


LABELS = st.lists(st.text(min_size=0, max_size=6), min_size=1, max_size=5, unique=True)


@settings(max_examples=80, deadline=None)
@given(LABELS, st.lists(st.integers(0, 4), min_size=1, max_size=60))
def testfew_labels_same_array(labels, picks):
    values = np.array([labels[i % len(labels)] for i in picks], dtype=object)
    assert tables.few_labels(values) is not None          # the labels' path is the one tested
    _same(string_array(values), _reference(values))


def test_pass_key_columns():
    station = np.array(["CPH"] * 5 + ["Aalborg Øst"] * 3, dtype=object)
    kind = np.array(["doppler", "elevation"] * 4, dtype=object)
    for values in (station, kind, np.array(["", "", ""], dtype=object)):
        _same(string_array(values), _reference(values))


@pytest.mark.parametrize("values", [
    np.array([1, 1.0, True, "1"], dtype=object),           # equal labels of other types: str of each
    np.array(["a", None, "a"], dtype=object),
    np.array([np.str_("x"), "x", "y"], dtype=object),
    np.array([f"s{i}" for i in range(tables.FEW_LABELS + 1)], dtype=object),   # many labels
    ["a", "b", "a"],
    np.array([["x"], "x", ["y"]], dtype=object),          # unhashable values: str of each
    np.array([], dtype=object),
])
def test_other_values_same_array(values):
    _same(string_array(values), _reference(values))


def test_labels_with_trailing_nul_keep_their_codes():
    """A label ending in NUL is its own label (numpy's string type would drop the NUL and make
    it equal to the label without it): the case hypothesis found, and the coding itself."""
    values = np.array(["", "\x00", "a\x00", "a", "\x00"], dtype=object)
    codes, labels = tables.few_labels(values)
    assert labels == ["", "\x00", "a\x00", "a"]
    assert codes.tolist() == [0, 1, 2, 3, 1]
    _same(string_array(values), _reference(values))
    _same(string_array(values[[1, 0]]), _reference(values[[1, 0]]))
