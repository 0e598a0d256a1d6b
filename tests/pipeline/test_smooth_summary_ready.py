"""pipeline.smooth._summary_ready against io.jsonutil.json_ready (the reference it replaces): the
same JSON text, key order included (``.smooth.json`` keeps insertion order), on drawn summaries
whose float lists hold NaN, infinities, numpy floats, ints or nested rows."""

import json
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from trackproc.io.jsonutil import json_ready
from trackproc.pipeline import smooth as sm

FLOATS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3).map(np.float64),
                   st.integers(-5, 5))
ROW = st.one_of(st.lists(st.floats(-1e6, 1e6), max_size=6), st.lists(FLOATS, max_size=6))
MATRIX = st.one_of(ROW, st.lists(ROW, max_size=4), st.lists(st.one_of(ROW, FLOATS), max_size=3),
                   st.just("not a list"), st.none())
RECORD = st.fixed_dictionaries({"station": st.text(max_size=3), "coefficients": MATRIX,
                                "covariance_unscaled": MATRIX, "covariance_scaled": MATRIX,
                                "rms": FLOATS, "tca": st.dictionaries(st.text(max_size=2), FLOATS, max_size=2)})


def _text(value) -> str:
    return json.dumps(value, allow_nan=False, separators=(",", ":"))


@settings(max_examples=150, deadline=None)
@given(st.lists(RECORD, max_size=3), FLOATS)
def test_same_as_json_ready(records, carrier):
    summary = {"command": "smooth", "carrier_hz": carrier, "counts": {"fits": np.int64(len(records))},
               "fits": records}
    assert _text(sm._summary_ready(summary)) == _text(json_ready(summary))


def test_finite_lists_kept_and_others_converted():
    cov = [[1.0, 0.5], [0.5, 2.0]]
    out = sm._summary_ready({"fits": [{"covariance_scaled": cov, "coefficients": [1.0, math.nan],
                                       "covariance_unscaled": [[np.float64(1.0)]]}]})
    rec = out["fits"][0]
    assert rec["covariance_scaled"] is cov                    # finite Python floats: as they are
    assert rec["coefficients"] == [1.0, None]                 # NaN -> null, as json_ready
    assert type(rec["covariance_unscaled"][0][0]) is float    # numpy -> Python


def test_no_fits_list():
    for summary in ({"fits": None, "x": np.float64(1.5)}, {"x": [math.inf]}, {"fits": [1, {"a": 2}]}):
        assert _text(sm._summary_ready(summary)) == _text(json_ready(summary))
