"""PolynomialFit.series is made once per derivative order; a fit made from another by replace_fit
(new coefficients: the TCA degree spread) must not see the other's series."""

import numpy as np

from trackproc.methods.smoothing.fit import fit_polynomial, replace_fit


def test_series_cached_per_fit_and_order_and_not_shared_by_replace():
    t = np.linspace(0.0, 100.0, 50)
    fit = fit_polynomial(t, np.sin(t / 30.0), np.ones(t.size), 5)
    first = fit.series(1)
    assert fit.series(1) is first
    # the closed form: the derivative series at x equals the numpy derivative of the fitted curve
    x = np.array([10.0, 55.0])
    reference = np.polynomial.Chebyshev(fit.coef, domain=list(fit.domain_s)).deriv(1)(x)
    np.testing.assert_array_equal(first(x), reference)
    other = replace_fit(fit, coef=2.0 * fit.coef)
    np.testing.assert_allclose(other.series(1)(x), 2.0 * reference, rtol=1e-15)
    np.testing.assert_allclose(other(x), 2.0 * fit(x), rtol=1e-15)
    assert other.series(1) is not first
