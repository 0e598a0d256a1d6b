"""``detect``'s choice of the station and pass in a pass file (pipeline/detect/run.select_samples):
the nominal file's choice, or the only one there is; otherwise a one-line error naming the field,
what the file has and what is expected."""

from types import SimpleNamespace

import pandas as pd
import pytest

from trackproc.errors import InputError
from trackproc.pipeline.detect import parse_nominal
from trackproc.pipeline.detect.run import select_samples

NOMINAL = '{"impact_time": "2026-03-20T10:00:00Z", "velocity_kms": 3, "angle_deg": 30%s}'
#: station A has passes p1 and p2, station B only p1; all elevation samples
TABLE = SimpleNamespace(frame=pd.DataFrame({
    "time": pd.to_datetime(["2026-03-20T09:59:00Z"] * 4), "station": ["A", "B", "A", "A"],
    "pass_id": ["p1", "p1", "p1", "p2"], "kind": ["elevation"] * 4, "value": [0.1] * 4, "sigma": [1e-3] * 4}))


def _select(extra: str):
    return select_samples(TABLE, parse_nominal(NOMINAL % extra, "n.json"), "p.csv")


def test_the_given_or_only_station_and_pass_are_chosen():
    name, pass_id, rows = _select(', "station": "B"')
    assert (name, pass_id, len(rows)) == ("B", "p1", 1)
    name, pass_id, rows = _select(', "station": "A", "pass_id": "p2"')
    assert (name, pass_id, len(rows)) == ("A", "p2", 1)


@pytest.mark.parametrize("extra, column, message, found, expected", [
    ("", "station", "several stations have elevations", "A, B", "the station to use"),
    (', "station": "C"', "station", "station has no elevation samples in the pass file", "C", "one of A, B"),
    (', "station": "A"', "pass_id", "the station has several passes", "p1, p2", "the pass to use"),
    (', "station": "A", "pass_id": "p9"', "pass_id", "unknown pass", "p9", "one of p1, p2"),
])
def test_an_ambiguous_or_unknown_choice_names_the_field(extra, column, message, found, expected):
    with pytest.raises(InputError) as info:
        _select(extra)
    assert str(info.value) == f"n.json, column '{column}': {message}; found '{found}'; expected {expected}"
