"""The light time's written-out norm of 3-vectors is numpy's, bit for bit.

``light_time._norm`` adds the squares as ``(x² + y²) + z²`` instead of calling ``add.reduce`` over
the last axis; the reference is numpy itself (``np.linalg.norm(d, axis=-1)`` and the reduction),
on vectors of every magnitude the light time meets and on the layouts it passes (contiguous rows,
a column slice of a state array, one vector, a stack).
"""

import numpy as np
import pytest

from trackproc.models import light_time as lt


def _vectors(rng, shape):
    return rng.standard_normal(shape) * 10.0 ** rng.uniform(-6, 8, shape)


@pytest.mark.parametrize("shape", [(3,), (1, 3), (2, 3), (7, 3), (9, 3), (661, 3), (4, 5, 3)])
def test_norm_is_numpys_bit_for_bit(shape):
    rng = np.random.default_rng(sum(shape))
    for _ in range(200 if np.prod(shape) < 100 else 20):
        d = _vectors(rng, shape)
        got = lt._norm(d)
        assert got.shape == shape[:-1]
        assert np.array_equal(got, np.linalg.norm(d, axis=-1))
        assert np.array_equal(got, np.sqrt(np.add.reduce(d * d, axis=-1)))


def test_norm_of_a_state_slice_and_special_values():
    rng = np.random.default_rng(7)
    s = _vectors(rng, (661, 6))
    assert np.array_equal(lt._norm(s[:, :3] - 1.0), np.linalg.norm(s[:, :3] - 1.0, axis=-1))
    assert np.array_equal(lt._norm(s[:, 3:]), np.linalg.norm(s[:, 3:], axis=-1))
    d = np.array([[0.0, -0.0, 0.0], [np.nan, 1.0, 2.0], [np.inf, 1.0, 0.0], [1e200, 1e200, 0.0]])
    with np.errstate(over="ignore"):
        assert np.array_equal(lt._norm(d), np.linalg.norm(d, axis=-1), equal_nan=True)


def test_other_lengths_use_the_reduction():
    d = _vectors(np.random.default_rng(3), (50, 4))
    assert np.array_equal(lt._norm(d), np.linalg.norm(d, axis=-1))
