"""``dynamics/geodesy._distinct_rows`` (the stations' repeated reception dates, evaluated once)
equals numpy's ``np.unique(..., axis=0, return_inverse=True)``: the same sorted rows and inverse."""

import numpy as np

from trackproc.dynamics.geodesy import _distinct_rows


def test_distinct_rows_equal_numpys_unique():
    rng = np.random.default_rng(11)
    day = np.sort(rng.random(500))
    # two-part dates: a range and a range-rate sample share theirs; a date split two ways
    # (jd1 differing with jd2) is two rows; shuffled, as several files merged
    jd1 = np.concatenate([np.full(1000, 2460000.5), np.full(40, 2460001.5), np.full(40, 2460000.5)])
    jd2 = np.concatenate([np.repeat(day, 2), day[:40] - 1.0, day[:40]])
    perm = rng.permutation(jd1.size)
    a = np.stack([jd1[perm], jd2[perm]], -1)
    rows, inverse = _distinct_rows(a)
    ref_rows, ref_inverse = np.unique(a, axis=0, return_inverse=True)
    np.testing.assert_array_equal(rows, ref_rows)
    np.testing.assert_array_equal(inverse, ref_inverse.reshape(-1))
    np.testing.assert_array_equal(rows[inverse], a)
    assert len(rows) == 540
