"""``methods.quality.block_consistency``: the score test of "this block of samples has its own
copy of the parameters" in a linear Gauss-Markov model, against closed forms: it equals the
likelihood-ratio drop in χ² of the refit with the block's own parameters (exact for a linear
model), it is χ²(rank) under the model (Monte Carlo: mean and Kolmogorov-Smirnov), and a block
shifted by a few of its own sigmas is detected."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc.methods import quality as qm


def _problem(rng, blocks=(30, 30, 30), n_par=4, n_local=1, prior_sigma=None):
    """A whitened linear model: common parameters (random partials: each block sees them its
    own way) plus ``n_local`` parameters per block (an offset: only that block sees it)."""
    rows = []
    n_all = n_par + n_local * len(blocks)
    jac = np.zeros((sum(blocks), n_all))
    start = 0
    for b, n in enumerate(blocks):
        t = np.linspace(-1, 1, n) + 0.3 * b
        jac[start:start + n, :n_par] = rng.normal(size=(n, n_par)) * (1 + 0.2 * np.arange(n_par))
        for k in range(n_local):
            jac[start:start + n, n_par + n_local * b + k] = t ** k
        rows.append(np.arange(start, start + n))
        start += n
    info = jac.T @ jac
    if prior_sigma is not None:
        info[:n_par, :n_par] += np.eye(n_par) / prior_sigma ** 2
    return jac, rows, np.linalg.inv(info), prior_sigma


def _fit(jac, y, prior_sigma, n_par):
    """Least squares of whitened ``y`` (with a zero-centred a-priori on the common parameters);
    residuals and χ²."""
    a, b = jac, y
    if prior_sigma is not None:
        p = np.zeros((n_par, jac.shape[1]))
        p[:, :n_par] = np.eye(n_par) / prior_sigma
        a, b = np.vstack([jac, p]), np.r_[y, np.zeros(n_par)]
    x = np.linalg.lstsq(a, b, rcond=None)[0]
    r = b - a @ x
    return y - jac @ x, float(r @ r)


@pytest.mark.parametrize("prior_sigma", [None, 0.5])
def test_equals_the_chi2_drop_of_the_refit_with_the_block_own_parameters(prior_sigma):
    rng = np.random.default_rng(1)
    jac, rows, cov, _ = _problem(rng, prior_sigma=prior_sigma)
    y = rng.normal(size=jac.shape[0])
    y[rows[1]] += 0.8 * jac[rows[1], 0]            # block 1 disagrees a little
    z, chi2 = _fit(jac, y, prior_sigma, 4)
    for blk in rows:
        t = qm.block_consistency(jac, z, cov, blk)
        # the alternative: the block's own copy of the common parameters (its own offset is already its own)
        extra = np.zeros((jac.shape[0], 4))
        extra[blk] = jac[blk, :4]
        _, chi2_alt = _fit(np.hstack([jac, extra]), y, prior_sigma, 4)
        assert t["dof"] == 4
        assert t["statistic"] == pytest.approx(chi2 - chi2_alt, rel=1e-8, abs=1e-9)


@pytest.mark.statistical
def test_is_chi2_of_its_rank_when_the_model_holds_and_detects_a_shifted_block():
    from scipy import stats

    rng = np.random.default_rng(7)
    jac, rows, cov, ps = _problem(rng, prior_sigma=1.0)
    stat = []
    for _ in range(2000):
        y = rng.normal(size=jac.shape[0])
        z, _ = _fit(jac, y, ps, 4)
        stat.append(qm.block_consistency(jac, z, cov, rows[0])["statistic"])
    stat = np.asarray(stat)
    assert abs(stat.mean() - 4.0) < 4 * np.sqrt(8.0 / stat.size)       # E = 4, Var = 8
    assert stats.kstest(stat, "chi2", args=(4,)).pvalue > 0.001
    ps_ = np.array([qm.chi2_survival(s, 4) for s in stat])
    assert np.mean(ps_ < 0.01) < 0.02                                  # nominal 1 %
    # a block whose samples follow other parameters (3-6 sigmas of its own information) is found
    y = rng.normal(size=jac.shape[0])
    own = jac[rows[2], :4]
    y[rows[2]] += own @ (np.array([6.0, -4.0, 3.0, 5.0]) / np.sqrt(np.diag(own.T @ own)))
    z, _ = _fit(jac, y, ps, 4)
    t = [qm.block_consistency(jac, z, cov, b) for b in rows]
    assert qm.chi2_survival(t[2]["statistic"], 4) < 0.001 / 3
    assert int(np.argmax([x["statistic"] for x in t])) == 2


def test_step_scan_equals_the_chi2_drop_of_the_refit_with_a_step_and_finds_one():
    """``step_scan``: at every position its statistic is the χ² drop of refitting with a level
    shift from that sample on (exact for a linear model); a shift of 6 sigma-of-its-estimate in
    the middle block is found at its sample, and none beyond the Bonferroni point without it."""
    rng = np.random.default_rng(5)
    jac, rows, cov, ps = _problem(rng, prior_sigma=0.5)
    sig = rng.uniform(0.5, 2.0, size=rows[1].size)          # the block's sigmas (whitened rows = raw / sigma)
    y = rng.normal(size=jac.shape[0])
    z, chi2 = _fit(jac, y, ps, 4)
    r = qm.step_scan(jac, z, cov, rows[1], 1.0 / sig)
    assert r["candidates"] == rows[1].size - 5
    step = np.zeros(jac.shape[0])
    step[rows[1][r["index"]:]] = 1.0 / sig[r["index"]:]
    _, chi2_alt = _fit(np.hstack([jac, step[:, None]]), y, ps, 4)
    assert r["statistic"] == pytest.approx(chi2 - chi2_alt, rel=1e-8)
    assert r["statistic"] < qm.chi2_limit(1, 1 - 0.001 / r["candidates"])
    # a level shift of 3 raw units from sample 17 of the block on
    y2 = y.copy()
    y2[rows[1][17:]] += 3.0 / sig[17:]
    z2, _ = _fit(jac, y2, ps, 4)
    r2 = qm.step_scan(jac, z2, cov, rows[1], 1.0 / sig)
    assert r2["statistic"] > qm.chi2_limit(1, 1 - 0.001 / r2["candidates"]) and abs(r2["index"] - 17) <= 1
