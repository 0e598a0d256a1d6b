"""The smoothing's Python-float shortcuts of numpy's Chebyshev operations (fit._chebder1 for the
derivative series, tca._scalar for one-point evaluation in the TCA root polish) against numpy
itself: equal to the last bit, on random series of every length and scale, inside and outside
the domain."""

import numpy as np
import pytest

from trackproc.methods.smoothing.fit import _chebder1, fit_polynomial
from trackproc.methods.smoothing.tca import _scalar


@pytest.mark.parametrize("n", [2, 3, 4, 7, 21, 31])
def test_chebder1_equals_numpy_bitwise(n):
    rng = np.random.default_rng(n)
    for _ in range(100):
        coef = rng.normal(size=n) * 10.0 ** rng.integers(-6, 7)
        scl = np.float64(rng.uniform(1e-4, 2.0))
        np.testing.assert_array_equal(_chebder1(coef, scl), np.polynomial.chebyshev.chebder(coef, 1, scl))


@pytest.mark.parametrize("n", [1, 2, 3, 5, 21, 31])
def test_scalar_evaluation_equals_numpy_bitwise(n):
    rng = np.random.default_rng(100 + n)
    for _ in range(50):
        series = np.polynomial.Chebyshev(rng.normal(size=n) * 1e3, domain=[-37.5, 812.25])
        value = _scalar(series)
        for x in rng.uniform(-100.0, 900.0, 10):
            assert value(float(x)).hex() == float(series(x)).hex()


def test_derivative_series_of_a_fit_equal_numpy_deriv():
    t = np.linspace(0.0, 600.0, 301)
    fit = fit_polynomial(t, 4e4 * np.tanh((t - 280.0) / 90.0), np.ones(t.size), 24)
    reference = np.polynomial.Chebyshev(fit.coef, domain=list(fit.domain_s))
    for m in (1, 2, 3):
        np.testing.assert_array_equal(fit.series(m).coef, reference.deriv(m).coef)
