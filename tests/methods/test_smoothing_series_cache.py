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


def test_kept_fit_is_the_fit_made_afresh():
    """solve_fit through DesignRows keeps its fits by (degree, samples, noise): asked again it gives
    the fit made, equal bit for bit to one made without the rows (white and AR(1))."""
    from trackproc.methods.smoothing.fit import DesignRows, NoiseModel, WHITE, solve_fit

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 400.0, 2.0)
    y = 3e3 * np.sin(t / 120.0) + rng.normal(0.0, 1.0, t.size)
    s = np.full(t.size, 1.0)
    used = rng.uniform(size=t.size) > 0.05
    domain = (0.0, float(t[-1]))
    rows = DesignRows(t, y, s, domain, "chebyshev")
    for noise in (WHITE, NoiseModel(rho=0.6, step_s=2.0)):
        first = solve_fit(t, y, s, 9, domain, "chebyshev", used, noise, rows)
        assert solve_fit(t, y, s, 9, domain, "chebyshev", used.copy(), noise, rows) is first
        fresh = solve_fit(t, y, s, 9, domain, "chebyshev", used, noise)
        for name in ("coef", "cov_unscaled", "residual"):
            assert getattr(first, name).tobytes() == getattr(fresh, name).tobytes()
        assert (first.chi2, first.rms, first.wrms, first.condition_number) == \
            (fresh.chi2, fresh.rms, fresh.wrms, fresh.condition_number)
        other = solve_fit(t, y, s, 8, domain, "chebyshev", used, noise, rows)
        assert other is not first and other.degree == 8
