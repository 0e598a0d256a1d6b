"""The AR(1) moment equation of the smoothing's noise estimate (correlation.moment_ratio,
estimate_noise) against the dense traces tr(L M C M) / tr(M C M) built from n x n matrices, on
irregular times (gaps, a repeated time), C x itself against the dense C, and the estimate's rho
and white/AR(1) decision against the same dense reference solved by scipy's brentq."""

import numpy as np
import pytest
from scipy.optimize import brentq

from trackproc.methods.smoothing.correlation import RHO_SIGNIFICANCE, estimate_noise, moment_ratio
from trackproc.methods.smoothing.fit import MAX_RHO, NoiseModel, _markov_sum, design_matrix, ou_apply


def _times(rng, n, repeated=True):
    steps = rng.choice([1.0, 1.0, 1.0, 1.0, 2.0, 7.0], size=n - 1)
    if repeated:
        steps[n // 3] = 0.0                               # a repeated time (correlation MAX_RHO there)
    return np.concatenate([[0.0], np.cumsum(steps)])


def _dense_correlation(a):
    """C_ij = a_(j+1) ... a_i (i > j), the Markov correlation, entry by entry."""
    n = a.size + 1
    c = np.eye(n)
    for i in range(1, n):
        c[i, :i] = c[i - 1, :i] * a[i - 1]
    return np.tril(c) + np.tril(c, -1).T


def _dense_ratio(t, q, step):
    n = t.size
    lag = np.zeros((n, n))
    lag[np.arange(1, n), np.arange(n - 1)] = 1.0
    m = np.eye(n) - q @ q.T

    def ratio(rho):
        c = _dense_correlation(NoiseModel(rho=rho, step_s=step).neighbour_correlation(t)) if rho > 0 else np.eye(n)
        return np.trace(lag @ m @ c @ m) / np.trace(m @ c @ m)

    return ratio


@pytest.mark.parametrize("largest", [0.3, 0.9, 0.97, MAX_RHO])
def test_ou_apply_equals_the_dense_correlation(largest):
    """ou_apply (LAPACK dpttrs with the time-reversed precision matrix's own factors) against C x
    with C built entry by entry, and against the forward and backward recurrences to a few ulps
    at every correlation up to MAX_RHO (an assembled tridiagonal solve is 1e3 times worse there)."""
    rng = np.random.default_rng(int(largest * 100))
    a = rng.uniform(0.0, largest, 120)
    a[17:40] = largest
    x = rng.normal(size=(121, 7))
    want = _dense_correlation(a) @ x
    got = ou_apply(a, x)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(want).max())
    sums = _markov_sum(a, x) + _markov_sum(a[::-1], x[::-1])[::-1] - x
    np.testing.assert_allclose(got, sums, rtol=0, atol=2e-15 * np.abs(want).max())


@pytest.mark.parametrize("repeated", [True, False])
@pytest.mark.parametrize("seed, p", [(1, 4), (2, 12), (3, 25)])
def test_moment_ratio_equals_the_dense_traces(seed, p, repeated):
    rng = np.random.default_rng(seed)
    t = _times(rng, 160, repeated)
    s = rng.uniform(0.5, 2.0, t.size)
    q, _ = np.linalg.qr(design_matrix(t, p - 1, (t[0], t[-1])) / s[:, None])
    fast, dense = moment_ratio(t, q, 1.0), _dense_ratio(t, q, 1.0)
    for rho in (0.0, 0.05, 0.3, 0.6, 0.9, MAX_RHO):
        assert fast(rho) == pytest.approx(dense(rho), rel=1e-12, abs=1e-14), rho


@pytest.mark.parametrize("seed", range(6))
def test_estimate_noise_against_the_dense_moment_equation(seed):
    rng = np.random.default_rng(10 + seed)
    t = _times(rng, 150)
    rho_true = [0.0, 0.0, 0.15, 0.3, 0.6, 0.9][seed]
    a = NoiseModel(rho=rho_true).neighbour_correlation(t) if rho_true else np.zeros(t.size - 1)
    e = rng.normal(size=t.size)
    u = np.empty(t.size)
    u[0] = e[0]
    for i in range(1, t.size):                            # AR(1) noise at the irregular times
        u[i] = a[i - 1] * u[i - 1] + np.sqrt(1 - a[i - 1] ** 2) * e[i]
    degree = 6
    y = 3.0 + 0.01 * t - 1e-5 * t ** 2 + u
    model = estimate_noise(t, y, np.ones(t.size), degree)

    q, _ = np.linalg.qr(design_matrix(t, degree, (t[0], t[-1])))
    z = y - q @ (q.T @ y)
    c_obs = float(z[1:] @ z[:-1]) / float(z @ z)
    dense = _dense_ratio(t, q, 1.0)
    e0 = dense(0.0)
    want = 0.0 if c_obs <= e0 else MAX_RHO if c_obs >= dense(MAX_RHO) else \
        brentq(lambda r: dense(r) - c_obs, 0.0, MAX_RHO, xtol=1e-12)
    assert model.rho_estimate == pytest.approx(want, abs=2e-6)           # brentq's xtol 1e-6 in the estimate
    margin = (c_obs - e0) - RHO_SIGNIFICANCE / np.sqrt(t.size - degree - 1)
    assert abs(margin) > 1e-9                                           # not a tie at the rounding level
    assert (model.rho > 0) == (margin > 0)
