"""pipeline.smooth._group_rows (the key columns' codes when each holds a few str labels, one pass
over them as lists otherwise; groupby when a key is not a string) against pandas' groupby of the same
rows (the reference): the same groups, the same rows in increasing order, on drawn tables."""

import numpy as np
import pandas as pd
import pytest

from trackproc.pipeline import smooth as sm


def _reference(frame, kinds):
    selected = frame[frame["kind"].isin(list(kinds))]
    positions = selected.index.to_numpy()
    return {key: positions[idx] for key, idx in
            selected.groupby(["station", "pass_id", "kind"], sort=True).indices.items()}


def _frame(rng, n, odd=False):
    stations = np.array(["CPH", "DLF", "", "\u00e9t\u00e9", "A,B"], dtype=object)
    passes = np.array(["p1", "p2", "P1", "p10"], dtype=object)
    kinds = np.array(["doppler", "elevation", "azimuth", "range"], dtype=object)
    frame = pd.DataFrame({"station": stations[rng.integers(0, len(stations), n)],
                          "pass_id": passes[rng.integers(0, len(passes), n)],
                          "kind": kinds[rng.integers(0, len(kinds), n)]})
    if odd:   # a missing key on some rows: the row loop and groupby's fallback
        frame.loc[rng.integers(0, n, 3), "pass_id"] = None
    return frame


@pytest.mark.parametrize("seed", range(8))
def test_the_groups_of_pandas_groupby(seed):
    rng = np.random.default_rng(seed)
    for n in (1, 2, 7, 300):
        for odd in (False, True):
            frame = _frame(rng, n, odd and n > 3)
            kinds = list(rng.choice(["doppler", "elevation", "azimuth", "range", "range_rate"],
                                    int(rng.integers(1, 4)), replace=False))
            keys = {c: frame[c].to_numpy() for c in ("station", "pass_id", "kind")}
            ours = sm._group_rows(frame, kinds, keys)
            if not odd or n <= 3:   # str labels only: the codes' path, its groups in order of first row
                assert sm._coded_groups(list(keys.values()), kinds) is not None
                assert list(ours) == list(dict.fromkeys(k for k in zip(*keys.values()) if k[2] in kinds))
            expected = _reference(frame, kinds)
            assert sorted(ours) == sorted(expected)
            for key, rows in expected.items():
                assert ours[key].dtype == np.intp and np.array_equal(ours[key], rows)
                assert np.all(np.diff(ours[key]) > 0)

