"""The shared a-priori and decision (methods/estimation/): checked against Monte Carlo and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackproc.constants import MU_EARTH
from trackproc.dynamics.rtn import rtn_jacobian
from trackproc.methods.estimation import decision as dm
from trackproc.methods.estimation import prior as pr
from trackproc.methods.least_squares import Prior

R0 = np.array([6878137.0, 0.0, 0.0])
V0 = np.array([0.0, 5000.0, 5500.0])


def test_probability_better_is_the_monte_carlo_frequency():
    """P(|e| < |e - d|) for e ~ N(0, C): the closed form Φ(|d| / 2σ_u) against 200 000 draws."""
    rng = np.random.default_rng(5)
    a = rng.normal(size=(3, 3))
    cov = a @ a.T + np.eye(3)
    assert dm.probability_better(np.zeros(3), cov)[0] == 0.5          # no move: a coin toss, not a gain
    for d in (np.array([0.3, -0.2, 0.5]), np.array([2.0, 1.0, -1.0])):
        p, size, sigma = dm.probability_better(d, cov)
        e = rng.multivariate_normal(np.zeros(3), cov, size=200_000)
        freq = np.mean(np.sum(e ** 2, axis=1) < np.sum((e - d) ** 2, axis=1))
        assert abs(freq - p) < 4 * math.sqrt(p * (1 - p) / e.shape[0]) + 1e-9, (d, freq, p)
        assert size == pytest.approx(np.linalg.norm(d))


def test_probability_better_over_is_probability_better_at_each_time():
    """The stacked form over K times against the one-time closed form at each: random maps, a time
    where the state change does not move the position (0.5), one with no uncertainty along the
    move (1), and the rest to round-off."""
    rng = np.random.default_rng(11)
    maps = rng.normal(size=(9, 3, 6)) * 1e3
    maps[0] = np.hstack([np.zeros((3, 3)), np.eye(3)])            # sees only the velocity
    maps[1] = np.hstack([np.eye(3), np.zeros((3, 3))])            # sees only the position
    change = np.r_[2.0, -1.0, 0.5, 0.0, 0.0, 0.0]
    a = rng.normal(size=(6, 6))
    cov = a @ a.T
    cov[:3, :] = 0.0
    cov[:, :3] = 0.0                                              # the position exactly known
    cov[3:, 3:] += np.eye(3)
    p, size, sigma = dm.probability_better_over(maps, change, cov)
    assert p.shape == size.shape == sigma.shape == (9,)
    assert (p[0], size[0], sigma[0]) == (0.5, 0.0, 0.0)
    assert p[1] == 1.0 and sigma[1] == 0.0 and size[1] == pytest.approx(np.linalg.norm(change[:3]), rel=1e-15)
    for k in range(2, 9):
        pk, sk, gk = dm.probability_better(maps[k] @ change, maps[k] @ cov @ maps[k].T)
        assert p[k] == pytest.approx(pk, abs=1e-14) and size[k] == pytest.approx(sk, rel=1e-14)
        assert sigma[k] == pytest.approx(gk, rel=1e-12)


def test_by_prediction_replaces_on_a_significant_gain_anywhere_and_keeps_otherwise():
    """Two times: a move of 5 sigma at the first replaces even if the second is a coin toss; 0.5 sigma
    at both keeps; the reported probability is the larger one."""
    eye = np.eye(3)
    maps = np.stack([np.hstack([eye, np.zeros((3, 3))]), np.hstack([eye, 1e3 * eye])])
    cov = np.diag([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6])
    big = dm.by_prediction(maps, [0.0, 1.0], np.r_[5.0, 0, 0, 0, 0, 0], cov, 1.0)
    assert big.action == "replaced" and big.probability == pytest.approx(0.5 * math.erfc(-2.5 / math.sqrt(2)))
    small = dm.by_prediction(maps, [0.0, 1.0], np.r_[0.5, 0, 0, 0, 0, 0], cov, 1.0)
    assert small.action == "kept" and small.keeps_prior and small.probability < dm.REPLACE_PROBABILITY


def test_the_tle_apriori_is_its_along_track_accuracy_at_its_age():
    """The GCRF covariance of the TLE a-priori, rotated to RTN: along-track sigma = the TLE-differencing
    model at the age (200 m + 550 m/day to 3.2 days, the measured table beyond; the eccentricity
    vector's error adds ~7 % along-track), radial and cross-track the model's (scaled with age
    beyond 3.2 days), within the first-order mapping."""
    big = rtn_jacobian(R0, V0, rotating=False)
    for age in (0.0, 1.0, 3.0, 6.0, 8.5):
        cov = big @ pr.tle_apriori_covariance(np.r_[R0, V0], MU_EARTH, age) @ big.T
        sig = np.sqrt(np.diag(cov))
        along = pr.tle_along_sigma_m(age)
        grow = along / (200.0 + 550.0 * min(age, 3.2))
        assert sig[1] == pytest.approx(along, rel=0.1), (age, sig)
        assert sig[0] == pytest.approx(100.0 * grow, rel=0.3), (age, sig)       # e: radial ~ a·δe (±√2)
        assert sig[2] == pytest.approx(50.0 * grow * math.sqrt(2), rel=0.3), (age, sig)   # i and Ω
    assert pr.tle_along_sigma_m(2.0) == pytest.approx(1300.0)
    assert pr.tle_along_sigma_m(8.5) == pytest.approx(17000.0)
    ages = np.linspace(0, 12, 49)
    assert np.all(np.diff([pr.tle_along_sigma_m(a) for a in ages]) > 0)


def test_the_apriori_test_is_chi2_under_a_right_prior_and_finds_a_wrong_one():
    """A linear problem, 6 states, 4 observations, a prior drawn from its own covariance: the
    innovation test rejects at its 99.9 % point in ~0.1 % of 4000 draws (at most 0.4 %); a prior 10σ
    off along a direction the data see is found."""
    rng = np.random.default_rng(11)
    h = rng.normal(size=(4, 6))
    p_cov = np.diag([4.0, 4.0, 4.0, 1.0, 1.0, 1.0])
    info = h.T @ h + np.linalg.inv(p_cov)
    post = np.linalg.inv(info)
    truth = np.zeros(6)
    rejected = 0
    for _ in range(4000):
        centre = truth + rng.multivariate_normal(np.zeros(6), p_cov)
        y = h @ truth + rng.normal(size=4)
        x = post @ (h.T @ y + np.linalg.solve(p_cov, centre))
        test = pr.apriori_test([Prior(np.arange(6), centre, p_cov)], x, post)
        rejected += test["conflict"]
    assert rejected <= 16, rejected
    seen = h[0] / np.linalg.norm(h[0])
    centre = truth + 10.0 * math.sqrt(seen @ p_cov @ seen) * seen
    y = h @ truth
    x = post @ (h.T @ y + np.linalg.solve(p_cov, centre))
    assert pr.apriori_test([Prior(np.arange(6), centre, p_cov)], x, post)["conflict"]


def test_scaled_priors_scale_only_the_state_rows():
    """A diagonal prior over state and a bias is split: the state rows scaled, the bias kept."""
    p = Prior.diagonal([0, 1, 2, 3, 4, 5, 6], np.arange(7.0), [1, 1, 1, 2, 2, 2, 3])
    out = pr.scaled_priors([p], 4.0)
    assert len(out) == 2
    np.testing.assert_allclose(pr.state_prior_covariance(out), np.diag([4, 4, 4, 16, 16, 16.0]))
    bias = [q for q in out if 6 in q.index][0]
    np.testing.assert_allclose(bias.covariance, [[9.0]])
    assert pr.state_prior_chi2(out, np.arange(7.0) + 2.0)[1] == 6


def test_the_a_priori_innovation_with_a_consider_term_is_chi2_by_monte_carlo():
    """A linear Gaussian problem with an error the solution does not estimate (a time-tag offset
    ``τ`` moving the data along ``h_c``): the innovation of the a-priori judged with the consider
    term ``E`` is χ² with its degrees of freedom (mean and 95 % point by Monte Carlo, 4000 draws);
    without ``E`` the same corrections are rejected far too often (the pass declined for its own
    timing, never a fault of the a-priori)."""
    from scipy.stats import chi2 as chi2_dist

    from trackproc.methods.quality import prior_innovation_chi2

    rng = np.random.default_rng(7)
    n, m = 6, 40
    p = np.diag([1.0, 4.0, 1.0, 0.5, 2.0, 0.3]) ** 2
    h = rng.normal(size=(m, n)) * 0.3
    h_c = h @ np.array([0.0, 1.0, 0.0, 0.2, 0.0, 0.0]) * 3.0     # the offset looks like a state move
    r_inv = np.eye(m) / 0.5 ** 2
    sig_tau = 1.5
    c = np.linalg.inv(np.linalg.inv(p) + h.T @ r_inv @ h)
    gain = c @ h.T @ r_inv
    move = gain @ h_c
    e = np.outer(move, move) * sig_tau ** 2
    with_e, without = [], []
    for _ in range(4000):
        x_p = rng.multivariate_normal(np.zeros(n), p)              # the prior's error (truth at 0)
        y = rng.normal(size=m) * 0.5 + h_c * rng.normal() * sig_tau
        x_hat = c @ (np.linalg.solve(p, x_p) + h.T @ r_inv @ y)
        t_e, dof = prior_innovation_chi2(x_hat - x_p, p, c, consider_cov=e)
        t_0, _ = prior_innovation_chi2(x_hat - x_p, p, c)
        with_e.append(t_e)
        without.append(t_0)
    with_e, without = np.array(with_e), np.array(without)
    assert dof == n
    assert abs(with_e.mean() - dof) < 0.15 * dof
    assert abs(np.mean(with_e > chi2_dist.ppf(0.95, dof)) - 0.05) < 0.015
    assert np.mean(without > chi2_dist.ppf(0.999, dof)) > 0.05       # the test without E: far too many


def test_one_step_of_the_variance_component_fixed_point():
    """:func:`prior.adapt_step`, the gate every command iterates: k̂ = χ²/r (Koch 1999 eq. 3.291);
    stop when it is within 0.1 of 1, cannot be estimated (redundancy ≤ 0.05), or would tighten a
    stated a-priori; else scale by k̂, never below the stated a-priori."""
    from trackproc.methods.estimation.prior import adapt_step

    assert adapt_step(40.0, 2.0, 1.0) == (20.0, 20.0)          # loosen by k̂
    assert adapt_step(6.0, 2.0, 20.0) == (3.0, 60.0)           # and again, from the loosened one
    assert adapt_step(2.1, 2.0, 60.0) == (1.05, None)          # converged
    assert adapt_step(1.0, 2.0, 1.0) == (0.5, None)            # never tighter than stated
    assert adapt_step(1.0, 2.0, 1.5) == (0.5, 1.0)             # back towards the stated one, not below
    assert adapt_step(40.0, 0.01, 1.0) == (None, None)         # the data cannot check the a-priori
