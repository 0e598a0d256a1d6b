"""ingest_checks.sample_problems' unknown-kind check (by the distinct kinds) against numpy's
``isin`` of the kind column (the reference it replaces), on drawn kind columns of known, unknown,
missing and non-str labels; the other checks' rows are unchanged by it."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from trackproc.io.passfile import KINDS
from trackproc.io.problems import UNKNOWN_KIND
from trackproc.pipeline.ingest_checks import sample_problems

LABELS = st.one_of(st.sampled_from(KINDS), st.sampled_from(["Doppler", "range-rate", "", "x"]),
                   st.none(), st.just(math.nan), st.integers(0, 2), st.sampled_from(KINDS).map(np.str_))


def _frame(kinds):
    n = len(kinds)
    return {"row": np.arange(1, n + 1), "source": "t.csv", "kind": np.array(kinds, dtype=object),
            "value": np.linspace(-1, 1, n), "sigma": np.full(n, 0.1), "unit": np.full(n, "", dtype=object),
            "value_column": np.full(n, "value", dtype=object), "sigma_column": np.full(n, "sigma", dtype=object)}


@settings(max_examples=150, deadline=None)
@given(st.lists(LABELS, min_size=1, max_size=25))
def test_unknown_kind_rows_as_isin(kinds):
    frame = _frame(kinds)
    problems = sample_problems(frame)
    masks = {check[0]: check[1] for check in problems._checks}
    expected = ~np.isin(frame["kind"], KINDS)
    if expected.any():
        assert masks[UNKNOWN_KIND].tolist() == expected.tolist()
    else:
        assert UNKNOWN_KIND not in masks
