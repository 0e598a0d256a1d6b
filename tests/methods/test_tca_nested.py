"""The TCA degree spread's nested fits (methods/smoothing/tca._nested_coefficients: every degree from
one QR of the widest whitened design) against a separate fit_polynomial of each degree."""

import numpy as np
import pytest

from trackproc.methods.smoothing import fit_polynomial, smooth_pass, tca_degree_spread
from trackproc.methods.smoothing.fit import NoiseModel, SmoothingError
from trackproc.methods.smoothing.tca import _nested_coefficients


def _doppler(n=600, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    y = -4.0e4 * np.tanh((t - 0.45 * n) / 90.0) + 12.0 * np.sin(t / 37.0)
    return t, y, rng


@pytest.mark.parametrize("rho", [0.0, 0.6])
def test_nested_coefficients_equal_separate_fits(rho):
    t, y0, rng = _doppler()
    e = rng.normal(0.0, 1.0, t.size)
    for i in range(1, t.size):                        # AR(1) noise when rho > 0
        e[i] = rho * e[i - 1] + np.sqrt(1 - rho ** 2) * e[i]
    y = y0 + 0.3 * e
    sigma = np.full(t.size, 0.3)
    used = np.ones(t.size, bool)
    used[rng.choice(t.size, 25, replace=False)] = False      # rejected samples are left out of both
    noise = NoiseModel(rho=rho, step_s=1.0) if rho else None
    fit = fit_polynomial(t, y, sigma, 20, used=used, noise=noise)
    coef = _nested_coefficients(t, y, sigma, fit, 26)
    for d in range(14, 27):
        ref = fit_polynomial(t, y, sigma, d, domain_s=fit.domain_s, used=used, noise=noise).coef
        got = coef(d)
        assert got.shape == ref.shape
        # Chebyshev coefficients of a ±4e4 Hz curve: rounding of the two factorisations only
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * np.max(np.abs(ref)))


def test_nested_coefficients_refuse_what_fit_polynomial_refuses():
    t = np.repeat(np.arange(6.0), 2)                  # 6 distinct times: degree 4 at most
    y = t ** 2
    fit = fit_polynomial(t, y, 1.0, 2)
    coef = _nested_coefficients(t, y, np.ones(t.size), fit, 6)
    np.testing.assert_allclose(coef(4), fit_polynomial(t, y, 1.0, 4, domain_s=fit.domain_s).coef, atol=1e-9)
    for d in (5, 6):
        with pytest.raises(SmoothingError):
            fit_polynomial(t, y, 1.0, d, domain_s=fit.domain_s)
        with pytest.raises(SmoothingError):
            coef(d)


def test_nested_coefficients_refuse_rank_deficient_degrees_as_fit_polynomial():
    """Times in two tight clusters: degree 8 is determined (condition ~1e12), 10 and more are not;
    the nested fits accept and refuse the same degrees as separate fits, whether or not the widest
    one is determined."""
    t = np.concatenate([np.linspace(0.0, 1e-3, 30), np.linspace(1.0 - 1e-3, 1.0, 30)])
    y = np.sin(3.0 * t)
    fit = fit_polynomial(t, y, 1.0, 2)
    for top in (8, 14):
        coef = _nested_coefficients(t, y, np.ones(t.size), fit, top)
        for d in range(top + 1):
            try:
                ref = fit_polynomial(t, y, 1.0, d, domain_s=fit.domain_s)
            except SmoothingError as exc:
                assert exc.reason == "rank_deficient" and d >= 10
                with pytest.raises(SmoothingError, match="not determined"):
                    coef(d)
                continue
            # the curves (coefficients at condition 1e12 agree only to ~1e-6)
            got = np.polynomial.Chebyshev(coef(d), domain=list(fit.domain_s))(t)
            np.testing.assert_allclose(got, ref(t), rtol=0, atol=1e-9)


def test_degree_spread_as_with_separate_fits():
    """The spread (std of t* over the degrees around the chosen one) as computed with separate fits."""
    from trackproc.methods.smoothing.tca import _tca_time

    t, y0, rng = _doppler(seed=5)
    y = y0 + rng.normal(0.0, 0.5, t.size)
    fit = smooth_pass(t, y, 0.5, "auto", clip=4.0)
    spread_s, spread_v, count = tca_degree_spread(t, y, 0.5, fit, "doppler")
    times = []
    for d in range(fit.degree - 2 - fit.degree // 5, fit.degree + 3 + fit.degree // 5):
        if abs(d - fit.degree) > max(2, int(np.ceil(fit.degree / 5))):
            continue
        other = fit_polynomial(t, y, 0.5, d, domain_s=fit.domain_s, used=fit.used, noise=fit.noise)
        times.append(_tca_time(other, "doppler", "one-way")[2])
    assert count == len(times) >= 5
    assert spread_s == pytest.approx(np.std(times, ddof=1), rel=1e-6)
