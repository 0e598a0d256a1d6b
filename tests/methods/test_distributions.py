"""methods/distributions.py against scipy.special (the functions it replaces on the refine path)."""

import math

import numpy as np
import pytest
from scipy.special import chdtrc, gammaincc, gammaincinv, ndtri

from trackproc.methods import distributions as d

PROBABILITIES = [1e-12, 1e-8, 1e-5, 1e-3, 0.01, 0.05, 0.1, 0.3, 0.5, 0.5000001, 0.7, 0.9, 0.95, 0.99, 0.999,
                 0.9999, 1 - 1e-7, 1 - 1e-10, 1 - 1e-13]
DOF = list(range(1, 25)) + [50, 101, 500, 1000, 5000, 100_000]


def test_normal_quantile_is_scipys_ndtri():
    p = np.r_[np.logspace(-300, -1, 60), np.linspace(0.01, 0.99, 99), 1 - np.logspace(-16, -1, 30)]
    mine = np.array([d.normal_quantile(v) for v in p])
    np.testing.assert_allclose(mine, ndtri(p), rtol=2e-15, atol=1e-15)


def test_chi2_survival_two_dof_is_scipys_chdtrc():
    x = np.r_[0.0, np.logspace(-10, 3, 200)]
    mine = np.array([d.chi2_survival_2(v) for v in x])
    np.testing.assert_allclose(mine, chdtrc(2, x), rtol=1e-13, atol=0)
    assert d.chi2_survival_2(-1.0) == 1.0


@pytest.mark.parametrize("nu", DOF)
def test_chi2_quantile_and_survival_are_scipys(nu):
    for p in PROBABILITIES:
        x = d.chi2_quantile(nu, p)
        reference = 2.0 * gammaincinv(nu / 2.0, p)
        assert x == pytest.approx(reference, rel=1e-12), (nu, p)
        for y in (0.5 * x, x, 1.5 * x):
            expected = gammaincc(nu / 2.0, y / 2.0)
            if expected > 1e-290:
                assert d.chi2_survival(y, nu) == pytest.approx(expected, rel=1e-11), (nu, p, y)
    assert d.chi2_survival(0.0, nu) == 1.0


def test_chi2_quantile_rejects_what_has_no_quantile():
    for nu, p in [(0, 0.5), (3, 0.0), (3, 1.0), (3, math.nan)]:
        with pytest.raises(ValueError):
            d.chi2_quantile(nu, p)
