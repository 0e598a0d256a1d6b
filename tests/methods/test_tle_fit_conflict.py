"""fit-tle's a-priori conflict statistic (:func:`trackproc.methods.tle_theory_error.apriori_conflict_chi2`)
against independent references on a linear Gaussian model with a per-pass random effect (SGP4's
theory error) and per-pass nuisance terms (offset, drift):

* dense generalised least squares (the samples' covariance ``R + J Q Jᵀ`` per pass written out,
  the nuisance terms as parameters with a flat prior): the same number as the innovation of the
  a-priori, ``(x̂_d − x_p)ᵀ (P + C_d)⁻¹ (x̂_d − x_p)``, and as ``(x̂ − x_p)ᵀ (P − C)⁻¹ (x̂ − x_p)``;
* Monte Carlo: with data drawn from the model, its distribution is χ²(7) (mean, 99 % point);
* the a-priori's share of the cost at the solution, the check before, loses the conflict when the
  data are weak against the a-priori (a tight TLE, a large theory error); this test keeps it.
"""

from __future__ import annotations

import numpy as np

from trackproc.methods import tle_theory_error as te

M, SIZES = 7, (30, 45, 25)


def _problem(rng, q_scale=1.0):
    p = np.diag(rng.uniform(0.5, 3.0, M) ** 2)
    q = np.diag(q_scale * rng.uniform(0.1, 2.0, M) ** 2)
    q[0, 0] = q[6, 6] = 0.0                                    # mean motion and B*: no theory error
    passes = []
    for n in SIZES:
        t = np.linspace(0.0, 1.0, n)
        passes.append((rng.normal(size=(n, M)), np.stack([np.ones(n), t], axis=1), rng.uniform(0.5, 1.5, n)))
    return p, q, passes


def _draw(rng, p, q, passes, x_true):
    """The a-priori mean ``x_p ~ N(x_true, P)`` and per pass ``z = J (x_true + η) + B c + noise``."""
    x_p = x_true + rng.multivariate_normal(np.zeros(M), p)
    data = [j @ (x_true + rng.multivariate_normal(np.zeros(M), q)) + b @ rng.normal(0, 100, 2) + rng.normal(0, s)
            for j, b, s in passes]
    return x_p, data


def _statistic(p, q, passes, data, x_p, at):
    """``apriori_conflict_chi2`` with the data's terms at the elements ``at`` (as fit-tle: the
    nuisance profiled out per pass, :func:`tle_theory_error.pass_information`, :func:`tle_theory_error.deflated_normal`)."""
    infos, grads = [], []
    for (j, b, s), z in zip(passes, data):
        w = 1.0 / s
        r = z - j @ at
        r = r - b @ np.linalg.lstsq(b * w[:, None], r * w, rcond=None)[0]
        infos.append(te.pass_information(j, w, b))
        grads.append(j.T @ (w ** 2 * r))
    a, g = te.deflated_normal(infos, grads, q, np.zeros((M, M)), np.zeros(M))
    return te.apriori_conflict_chi2(g + a @ (at - x_p), a, p)


def _dense(p, q, passes, data):
    """Dense GLS of the data alone (nuisance as parameters, flat): ``x̂_d`` and its covariance."""
    k = 2 * len(passes)
    normal, rhs = np.zeros((M + k, M + k)), np.zeros(M + k)
    for i, ((j, b, s), z) in enumerate(zip(passes, data)):
        a = np.zeros((len(z), M + k))
        a[:, :M], a[:, M + 2 * i:M + 2 * i + 2] = j, b
        vi = np.linalg.inv(np.diag(s ** 2) + j @ q @ j.T)
        normal += a.T @ vi @ a
        rhs += a.T @ vi @ z
    cov = np.linalg.inv(normal)
    return (cov @ rhs)[:M], cov[:M, :M]


def test_conflict_statistic_is_the_innovation_of_the_apriori():
    rng = np.random.default_rng(3)
    p, q, passes = _problem(rng)
    x_true = rng.normal(size=M)
    x_p, data = _draw(rng, p, q, passes, x_true)
    x_d, c_d = _dense(p, q, passes, data)
    innovation = (x_d - x_p) @ np.linalg.solve(p + c_d, x_d - x_p)
    c = np.linalg.inv(np.linalg.inv(p) + np.linalg.inv(c_d))       # with the a-priori
    x_hat = c @ (np.linalg.solve(p, x_p) + np.linalg.solve(c_d, x_d))
    posterior = (x_hat - x_p) @ np.linalg.solve(p - c, x_hat - x_p)
    for at in (x_p, x_hat, x_true):                # the data's terms anywhere: the model is linear
        chi2, used = _statistic(p, q, passes, data, x_p, at)
        assert used == M
        assert np.isclose(chi2, innovation, rtol=1e-7) and np.isclose(chi2, posterior, rtol=1e-6), (chi2, innovation,
                                                                                                   posterior)


def test_conflict_statistic_is_chi2_7_monte_carlo():
    """2000 draws from the model: mean 7 (± 3 standard errors, sqrt(14/2000)) and the 99 % point
    of χ²(7), 18.48, exceeded in 1 % of them (± 3 binomial standard errors)."""
    rng = np.random.default_rng(7)
    p, q, passes = _problem(rng)
    x_true = rng.normal(size=M)
    chi2 = []
    for _ in range(2000):
        x_p, data = _draw(rng, p, q, passes, x_true)
        chi2.append(_statistic(p, q, passes, data, x_p, x_p)[0])
    chi2 = np.array(chi2)
    assert abs(chi2.mean() - 7.0) < 3 * np.sqrt(14.0 / chi2.size), chi2.mean()
    beyond = np.mean(chi2 > 18.475)
    assert abs(beyond - 0.01) < 3 * np.sqrt(0.01 * 0.99 / chi2.size), beyond


def test_conflict_is_seen_where_the_apriori_share_of_the_cost_misses_it():
    """A tight a-priori and a large theory error (a TLE and a pass's timing): the a-priori mean off
    the truth by 30 sigmas (of the a-priori plus the data's own error) in the direction the data
    see least against the a-priori. The statistic is 900; the a-priori's share of the cost at
    the solution, ``(x̂ − x_p)ᵀ P⁻¹ (x̂ − x_p)``, stays below the 99.9 % limit of χ²(7) (24.3):
    the data move the solution little, however much they disagree."""
    rng = np.random.default_rng(11)
    p, q, passes = _problem(rng, q_scale=1e3)
    x_true = np.zeros(M)
    data = [j @ x_true + b @ rng.normal(0, 100, 2) for j, b, _ in passes]    # noise-free, no η: the truth
    x_d, c_d = _dense(p, q, passes, data)
    low = np.linalg.cholesky(p)
    lam, vec = np.linalg.eigh(low.T @ np.linalg.inv(c_d) @ low)   # the data's information, a-priori whitened
    x_p = x_true + low @ vec[:, 0] * 30.0 * np.sqrt((1.0 + lam[0]) / lam[0])
    chi2, _ = _statistic(p, q, passes, data, x_p, x_p)
    c = np.linalg.inv(np.linalg.inv(p) + np.linalg.inv(c_d))
    x_hat = c @ (np.linalg.solve(p, x_p) + np.linalg.solve(c_d, x_d))
    share = (x_hat - x_p) @ np.linalg.solve(p, x_hat - x_p)
    print("statistic", chi2, "a-priori share", share, "information / a-priori", lam[0])
    assert np.isclose(chi2, 900.0, rtol=1e-6), chi2
    assert share < 24.3, share
