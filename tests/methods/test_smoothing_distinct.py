"""fit.distinct_count against numpy.unique (the reference) on drawn sample times: sorted (a pass's,
with repeated times), unsorted, with -0.0 and 0.0, NaN and inf, empty, one sample, 2-D."""

import numpy as np
import pytest

from trackproc.methods.smoothing.fit import distinct_count


@pytest.mark.parametrize("seed", range(6))
def test_the_count_of_numpy_unique(seed):
    rng = np.random.default_rng(seed)
    for n in (0, 1, 2, 3, 50, 400):
        base = np.round(rng.uniform(-5, 5, n), int(rng.integers(0, 3)))
        cases = [np.sort(base), base, np.sort(np.r_[base, base[: n // 2]]), np.sort(np.r_[base, 0.0, -0.0, -0.0]),
                 np.sort(np.r_[base, np.inf, -np.inf, np.inf]), np.r_[np.sort(base), np.nan],
                 np.r_[np.nan, np.sort(base)], np.sort(base)[::-1], np.sort(base).reshape(1, -1)]
        for t in cases:
            assert distinct_count(t) == np.unique(t).size
    assert distinct_count([0.0, 1.0, 1.0, 2.0]) == 3
