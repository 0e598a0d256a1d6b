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


@pytest.mark.parametrize("kind, mode", [("doppler", "one-way"), ("doppler", "two-way"), ("range_rate", "one-way"),
                                        ("range", "one-way")])
def test_coefficient_tca_equals_the_series_path_bitwise(kind, mode):
    """tca._cheb_tca (the degree spread's neighbours from coefficient arrays) against _tca_time on a
    fit of that degree (numpy series objects): the same t*, the same curve value there, to the bit,
    and the same failures (no root of the right sense)."""
    from trackproc.methods.smoothing.fit import SmoothingError, replace_fit
    from trackproc.methods.smoothing.tca import _cheb_tca, _tca_time

    rng = np.random.default_rng(7)
    t = np.linspace(0.0, 640.0, 321)
    shape = {"doppler": -4e4 * np.tanh((t - 300.0) / 80.0), "range_rate": 6e3 * np.tanh((t - 330.0) / 90.0),
             "range": 1e6 + 2e3 * (t - 310.0) ** 2}[kind]
    fit = fit_polynomial(t, shape + rng.normal(0.0, 1.0, t.size), np.ones(t.size), 22)
    base = fit.series(0)
    outcomes = set()
    for d in range(4, 24):        # tca_degree_spread takes this path from degree order + 1 up
        coef = rng.normal(size=d + 1) * 10.0 ** rng.integers(-2, 3) if d % 5 == 0 else \
            fit_polynomial(t, shape + rng.normal(0.0, 1.0, t.size), np.ones(t.size), d).coef
        other = replace_fit(fit, degree=d, coef=coef)
        try:
            want = _tca_time(other, kind, mode)[2]
        except SmoothingError:
            with pytest.raises(SmoothingError):
                _cheb_tca(coef, base, fit.domain_s, kind, mode)
            outcomes.add("none")
            continue
        got_t, got_v = _cheb_tca(coef, base, fit.domain_s, kind, mode)
        assert float(got_t).hex() == float(want).hex()
        assert float(got_v).hex() == float(other(want)).hex()
        outcomes.add("root")
    assert "root" in outcomes


@pytest.mark.parametrize("n", [1, 2, 3, 4, 9, 17, 31])
def test_companion_roots_equal_numpy_chebroots_bitwise(n):
    """tca._cheb_roots (the kept companion scaffolding) against numpy's chebroots: the same roots to
    the bit, trailing zero coefficients trimmed as numpy trims them, for every size of series."""
    from trackproc.methods.smoothing.tca import _cheb_roots

    rng = np.random.default_rng(200 + n)
    for trial in range(60):
        coef = rng.normal(size=n) * 10.0 ** rng.integers(-6, 7) / np.arange(1, n + 1) ** rng.integers(0, 3)
        if trial % 7 == 0:
            coef[-min(2, n - 1):] = 0.0 if n > 1 else coef[-1:]
        got, want = _cheb_roots(coef), np.polynomial.chebyshev.chebroots(coef)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert got.tobytes() == want.tobytes()
