"""The degree search's BIC (methods/smoothing/degree.select_degree: every degree's residual sum of
squares from one QR of the whitened [Psi y]) against an independent reference, numpy's lstsq fit of
each degree separately, on near-ties between two degrees and with a large offset (residuals 1e-10
and 1.6e-8 of |y|^2, where a difference of sums cancels)."""

import numpy as np
import pytest

from trackproc.methods.smoothing import select_degree
from trackproc.methods.smoothing.fit import NoiseModel, whiten


def _reference_bic(t, y, sigma, degrees, noise=None):
    """BIC(d) = n ln(chi2_d / n) + (d + 1) ln n, chi2_d from numpy.linalg.lstsq of each degree."""
    x = (2.0 * t - (t[0] + t[-1])) / (t[-1] - t[0])
    out = {}
    for d in degrees:
        a = whiten(t, np.polynomial.chebyshev.chebvander(x, d) / sigma[:, None], noise)
        b = whiten(t, y / sigma, noise)
        coef = np.linalg.lstsq(a, b, rcond=None)[0]
        chi2 = float(np.sum((b - a @ coef) ** 2))
        out[d] = t.size * np.log(chi2 / t.size) + (d + 1) * np.log(t.size)
    return out


def _near_tie(k, delta, n=600, seed=5, offset=1e5):
    """Samples whose BIC at degree k + 1 is BIC at k plus ``delta``: a curve of degree k with an
    ``offset``, noise with no component in the first k + 2 basis directions, and one component
    along the (k + 1)-th direction sized to give the tie."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    x = (2.0 * t - (t[0] + t[-1])) / (t[-1] - t[0])
    v = np.polynomial.chebyshev.chebvander(x, k + 1)
    q, _ = np.linalg.qr(v)
    e = rng.normal(0.0, 1.0, n)
    e -= q @ (q.T @ e)
    chi2_hi = float(e @ e)
    # BIC(k + 1) - BIC(k) = n ln(chi2_hi / (chi2_hi + c^2)) + ln n = delta
    c2 = chi2_hi * (np.exp((np.log(n) - delta) / n) - 1.0)
    curve = v[:, : k + 1] @ np.concatenate([[offset], rng.normal(0.0, 0.03 * offset, k)])
    return t, curve + e + np.sqrt(c2) * q[:, k + 1], np.ones(n)


# offset 8e3: chi2 / |y_w|^2 ~ 1.6e-8, where |y_w|^2 - |Q^T y_w|^2 loses 8 digits (BIC off by 1e-5)
@pytest.mark.parametrize("offset", [1e5, 8e3])
@pytest.mark.parametrize("delta", [-1e-3, 1e-3, -0.05, 0.05])
def test_near_tie_follows_the_lstsq_reference(delta, offset):
    k = 8
    t, y, sigma = _near_tie(k, delta, offset=offset)
    degree, scores, _ = select_degree(t, y, sigma, max_degree=20)
    ref = _reference_bic(t, y, sigma, range(21))
    best = min(ref, key=ref.get)
    assert best == (k + 1 if delta < 0 else k)          # the construction: a tie between k and k + 1
    assert abs((ref[k + 1] - ref[k]) - delta) < 1e-6
    assert degree == best
    for d in ref:                                       # every degree, the large offset included
        assert scores[d] == pytest.approx(ref[d], abs=1e-6)


def test_correlated_noise_scores_follow_the_lstsq_reference():
    t, y, sigma = _near_tie(6, 0.5, n=400, seed=11)
    noise = NoiseModel(rho=0.7, step_s=1.0)
    degree, scores, _ = select_degree(t, y, sigma, max_degree=15, noise=noise)
    ref = _reference_bic(t, y, sigma, range(16), noise)
    assert degree == min(ref, key=ref.get)
    for d in ref:
        assert scores[d] == pytest.approx(ref[d], abs=1e-6)
