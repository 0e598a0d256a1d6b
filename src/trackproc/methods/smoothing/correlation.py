"""The AR(1) noise of a pass's residuals (:func:`estimate_noise`): the method of moments corrected
for the fit's own projection (see :mod:`trackproc.methods.smoothing`).
"""

from __future__ import annotations

import numpy as np

from trackproc.methods.roots import brentq
from trackproc.methods.smoothing.fit import (MAX_RHO, NoiseModel, check_arrays, design_matrix, ou_apply, pass_domain,
                                             replace_fit)


#: An AR(1) estimate within this many standard errors (1 / sqrt(n - p)) of white noise is white.
RHO_SIGNIFICANCE = 2.0


def estimate_noise(t_s, y, sigma, degree: int, *, basis: str = "chebyshev", domain_s=None,
                   white_q=None, _checked: bool = False) -> NoiseModel:
    """AR(1) correlation of the normalized noise from the residuals of a white-noise fit of ``degree``.

    Method of moments corrected for the projection of the fit: with ``z = M u`` the normalized
    residuals (``M = I - Q Q^T``, ``Q`` an orthonormal basis of the whitened design matrix) and
    ``u`` unit-variance noise of correlation ``C(rho)`` (``rho^(|t_i - t_j| / step)``), the observed
    ``c = sum z_i z_(i-1) / sum z_i^2`` is solved for ``rho`` from
    ``E[sum z_i z_(i-1)] / E[sum z_i^2] = tr(L M C M) / tr(M C M)``; both traces cost O(n p) because
    ``C`` is Markov (:func:`moment_ratio`). ``step`` is the median sample spacing. An estimate within
    ``RHO_SIGNIFICANCE`` standard errors (``1 / sqrt(n - p)``) of white gives ``rho = 0``.
    ``white_q``: the caller's ``Q`` of that design matrix (times sorted), when it has it already;
    ``_checked``: the arrays are :func:`check_arrays`' output already.
    """
    t, y, s = (t_s, y, sigma) if _checked else check_arrays(t_s, y, sigma)
    domain = pass_domain(t, domain_s)
    order = np.argsort(t, kind="stable")
    t, y, s = t[order], y[order], s[order]
    n, p = t.size, int(degree) + 1
    steps = np.diff(t)
    positive = steps[steps > 0]
    step = float(np.median(positive)) if positive.size else 1.0
    if n - p < 4:
        return NoiseModel(step_s=step, degree=int(degree), n_eff=float(n))
    if white_q is None:
        a = design_matrix(t, int(degree), domain, basis) / s[:, None]
        q, _ = np.linalg.qr(a)
    else:
        q = white_q
    yw = y / s
    z = yw - q @ (q.T @ yw)
    den = float(z @ z)
    if not den > 0:
        return NoiseModel(step_s=step, degree=int(degree), n_eff=float(n))
    c_obs = float(z[1:] @ z[:-1]) / den
    lag1 = c_obs

    expected = moment_ratio(t, q, step)
    e0 = expected(0.0)
    if c_obs <= e0:
        rho_hat = 0.0
    elif c_obs >= expected(MAX_RHO):
        rho_hat = MAX_RHO
    else:
        rho_hat = float(brentq(lambda r: expected(r) - c_obs, 0.0, MAX_RHO, xtol=1e-6))
    significant = (c_obs - e0) > RHO_SIGNIFICANCE / np.sqrt(n - p)
    rho = rho_hat if significant else 0.0
    model = NoiseModel(rho=rho, step_s=step, rho_estimate=rho_hat, lag1_observed=lag1, degree=int(degree))
    return replace_fit(model, n_eff=model.effective_samples(t))


def moment_ratio(t_sorted, q, step_s: float):
    """``rho -> tr(L M C M) / tr(M C M)``: the expected lag-1 ratio of the residuals
    ``z = M u`` (``M = I - Q Q^T``, ``q`` the orthonormal ``Q`` at the sorted times) of unit-variance
    AR(1) noise of correlation ``C(rho)`` (:func:`estimate_noise`), each rho computed once.

    Both traces are linear in ``w = C q`` (``C`` symmetric): ``tr(M C M) = n - <q, w>`` and
    ``tr(L M C M) = sum_i a_i - <zl, w>`` with ``zl_i = q_(i+1) + q_(i-1) - (q K)_i``,
    ``K = q[1:]^T q[:-1]`` -- the terms ``tr(L C)``, ``tr(L Q Q^T C)``, ``tr(L C Q Q^T)`` and
    ``tr(L Q (Q^T C Q) Q^T)`` of the expanded product -- so ``zl`` is made once and each rho costs
    ``C q`` (:func:`ou_apply`, O(n p)) and two dot products.
    """
    n = q.shape[0]
    zl = q @ (q[1:].T @ q[:-1])
    np.negative(zl, out=zl)
    zl[:-1] += q[1:]
    zl[1:] += q[:-1]
    qv, zv = q.ravel(), zl.ravel()          # C order, like every w below
    # NoiseModel.neighbour_correlation's exponent, made once (the same array at every rho)
    spacing = np.diff(t_sorted) / step_s
    memo: dict = {}

    def expected(rho: float) -> float:
        # each rho once: brentq evaluates the bracket's ends again
        made = memo.get(rho)
        if made is None:
            if rho == 0.0:           # C = I
                w, sum_a = qv, 0.0
            else:
                acorr = np.minimum(rho ** spacing, MAX_RHO)      # neighbour_correlation (rho > 0)
                w, sum_a = ou_apply(acorr, q).ravel(), float(np.sum(acorr))
            made = memo[rho] = (sum_a - float(zv @ w)) / (n - float(qv @ w))
        return made

    return expected
