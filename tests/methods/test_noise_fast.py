"""The O(n) whitening of a pass's noise (methods/whitening.py MarkovFactor: the tridiagonal form of
one Markov component, the two-state Kalman filter of both) against its oracle, the dense n x n
Cholesky factor of the covariance (NoiseModel.covariance): log|C|, the whitened rows (the
innovations), the whitened products XᵀC⁻¹X, XᵀC⁻¹r and the restricted likelihood agree to 1e-9
relative on random irregular time grids with duplicate times and near-zero gaps; the REML fit of
a pass chooses the same model with the same parameters either way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackproc.methods import noise as nz
from trackproc.methods.whitening import MarkovFactor, PassCovariance, markov_factor

MODELS = [
    nz.NoiseModel(0.7),
    nz.NoiseModel(0.7, 1.5, 12.0),                 # AR(1), τ comparable to the gaps
    nz.NoiseModel(0.7, 3.0, 2000.0),               # AR(1), τ much longer than the pass
    nz.NoiseModel(0.7, 0.0, 0.0, 0.2),             # random walk
    nz.NoiseModel(0.7, 1.5, 12.0, 0.2),            # both
    nz.NoiseModel(0.05, 2.0, 300.0, 0.05),         # both, white small beside them (ill-conditioned C)
]


def _grid(seed: int, n: int = 90) -> np.ndarray:
    """Irregular times: random gaps from 1e-9 s to 40 s, some exact duplicates, a long gap."""
    rng = np.random.default_rng(seed)
    gaps = rng.exponential(3.0, n - 1)
    gaps[rng.choice(n - 1, 6, replace=False)] = 0.0             # duplicate times
    gaps[rng.choice(n - 1, 6, replace=False)] = 10.0 ** rng.uniform(-9, -4, 6)   # near-zero gaps
    gaps[n // 2] = 200.0                                           # a gap in the pass
    return 100.0 + np.concatenate([[0.0], np.cumsum(gaps)])


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("model", MODELS, ids=lambda m: f"{m.name}-{m.white}")
def test_markov_factor_is_the_dense_cholesky_whitener(model, seed):
    t = _grid(seed)
    rng = np.random.default_rng(100 + seed)
    for t0 in (None, float(t[0]) - 7.0, float(t[5])):     # walk started before, at and after the first sample
        c = model.covariance(t, t0)
        chol = np.linalg.cholesky(c)
        fac = MarkovFactor(model, t, t0)
        assert fac.logdet == pytest.approx(2.0 * np.sum(np.log(np.diag(chol))), rel=1e-9, abs=1e-9)
        x = rng.normal(size=(t.size, 5))
        r = rng.normal(size=t.size) * 3.0
        wx, wr = fac.whiten(x), fac.whiten(r)
        dx, dr = np.linalg.solve(chol, x), np.linalg.solve(chol, r)
        assert _rel(wr, dr) < 1e-9 and _rel(wx, dx) < 1e-9              # the innovations themselves
        assert _rel(wx.T @ wx, dx.T @ dx) < 1e-9                           # XᵀC⁻¹X
        assert _rel(wx.T @ wr, dx.T @ dr) < 1e-9                           # XᵀC⁻¹r
        assert float(wr @ wr) == pytest.approx(float(r @ np.linalg.solve(c, r)), rel=1e-9)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("model", MODELS, ids=lambda m: f"{m.name}-{m.white}")
def test_restricted_likelihood_in_o_n_equals_the_dense_one(model, seed):
    t = _grid(seed, 120)
    rng = np.random.default_rng(seed)
    x = nz._basis(np.column_stack([np.ones_like(t), t - t[0], np.sin(t / 90.0), np.cos(t / 90.0)]))
    r = np.linalg.cholesky(model.covariance(t)) @ rng.normal(size=t.size) + x @ rng.normal(size=x.shape[1])
    for profile in (True, False):
        fast = nz.restricted_loglik(model, t, r, x, profile=profile)
        dense = nz.restricted_loglik(model, t, r, x, profile=profile, dense=True)
        assert fast[0] == pytest.approx(dense[0], rel=1e-9)
        assert fast[1] == pytest.approx(dense[1], rel=1e-9)


def test_a_covariance_that_is_not_positive_definite_is_refused_by_both_paths():
    """No white noise and two samples at the same time: C is singular; both give -inf (with both
    components the zero pivot is a rounding residue either way, not a test of anything)."""
    t = np.array([0.0, 1.0, 1.0, 2.5, 4.0])
    x = nz._basis(np.ones((5, 1)))
    r = np.array([0.3, -1.0, 0.5, 2.0, -0.4])
    for model in (nz.NoiseModel(0.0, 1.0, 5.0), nz.NoiseModel(0.0, 0.0, 0.0, 0.3)):
        assert nz.restricted_loglik(model, t, r, x)[0] == -math.inf
        assert nz.restricted_loglik(model, t, r, x, dense=True)[0] == -math.inf


def test_unordered_times_fall_back_to_the_dense_factor():
    t = np.array([0.0, 2.0, 1.0, 3.0])
    assert markov_factor(nz.NoiseModel(1.0, 1.0, 3.0), t) is None
    assert markov_factor(nz.NoiseModel(1.0, 1.0, 3.0), np.sort(t)) is not None


def test_pass_covariance_whitens_blocks_as_the_dense_factor_does():
    """Two correlated blocks (one with its samples out of time order: the dense factor of that
    order), independent samples elsewhere, some samples not kept: whitened rows as the dense
    block Cholesky factors give them."""
    rng = np.random.default_rng(5)
    t = _grid(11, 80)
    sigma = rng.uniform(0.5, 2.0, t.size)
    b1 = np.arange(0, 40)
    b2 = np.arange(70, 50, -1)                         # times decreasing in the block's order
    m1, m2 = nz.NoiseModel(0.6, 1.2, 15.0, 0.1), nz.NoiseModel(0.9, 0.0, 0.0, 0.3)
    cov = PassCovariance(sigma, t, [(b1, m1, float(t[0])), (b2, m2, float(t[50]))])
    keep = rng.uniform(size=t.size) > 0.2
    m = rng.normal(size=(t.size, 3))
    out = cov.whitener(keep)(m)
    pos = np.cumsum(keep) - 1
    expected = np.empty((keep.sum(), 3))
    rest = keep.copy()
    for idx, model, t0 in ((b1, m1, float(t[0])), (b2, m2, float(t[50]))):
        k = idx[keep[idx]]
        expected[pos[k]] = np.linalg.solve(np.linalg.cholesky(model.covariance(t[k], t0)), m[k])
        rest[idx] = False
    expected[pos[rest]] = m[rest] / sigma[rest, None]
    assert _rel(out, expected) < 1e-9


@pytest.mark.parametrize("true", [nz.NoiseModel(0.6, 1.5, 15.0), nz.NoiseModel(0.6, 0.0, 0.0, 0.2),
                                  nz.NoiseModel(0.6, 1.0, 40.0, 0.1)], ids=lambda m: m.name)
def test_reml_fit_is_the_same_in_o_n_and_dense(true):
    """The noise model chosen for a simulated pass (400 samples: the REML subset of 320) and its
    parameters and likelihoods, by the O(n) and the dense path: the same to 1e-9."""
    rng = np.random.default_rng(21)
    t = np.sort(rng.uniform(0.0, 600.0, 400))
    x = np.column_stack([np.ones_like(t), t / t.max(), np.sin(t / 150.0), np.cos(t / 150.0)])
    r = np.linalg.cholesky(true.covariance(t)) @ rng.normal(size=t.size) + x @ rng.normal(size=4) * 50.0
    for walk in (None, 0.1):                       # the walk estimated, or given (--oscillator-noise)
        fast, dense = nz.fit_noise(t, r, x, walk=walk), nz.fit_noise(t, r, x, walk=walk, dense=True)
        assert fast.model.name == dense.model.name
        for name, cand in dense.candidates.items():
            for key, value in cand.items():
                if isinstance(value, float):
                    assert fast.candidates[name][key] == pytest.approx(value, rel=1e-9, abs=1e-12), (name, key, walk)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: f"{m.name}-{m.white}")
def test_effective_samples_beyond_offset_and_drift_is_the_dense_formula(model):
    """(tr C')²/tr(C'²), C' = P C P without a constant and a line, in O(n) (white noise: the rank
    of P, n - 2; correlated: traces and C Q by the Markov recursions) against the n x n matrix;
    times out of order take the dense path, with the same number."""
    t = _grid(3, 150)
    q, _ = np.linalg.qr(np.column_stack([np.ones(t.size), t - t[0]]))
    p = np.eye(t.size) - q @ q.T
    c = p @ model.covariance(t, float(t[0])) @ p
    expected = np.trace(c) ** 2 / np.sum(c * c)
    assert nz.effective_samples_beyond(model, t, float(t[0])) == pytest.approx(expected, rel=1e-9)
    perm = np.random.default_rng(0).permutation(t.size)
    assert nz.effective_samples_beyond(model, t[perm], float(t[0])) == pytest.approx(expected, rel=1e-9)
    assert nz.effective_samples_beyond(model, t, float(t[0]) - 50.0) == pytest.approx(
        nz.effective_samples_beyond(model, t[perm], float(t[0]) - 50.0), rel=1e-9)


@pytest.mark.parametrize("n", [1, 2, 3])
@pytest.mark.parametrize("model", MODELS, ids=lambda m: f"{m.name}-{m.white}")
def test_markov_factor_of_tiny_passes_and_empty_matrices(model, n):
    """One to three samples (the walk started before them or at the first), and a matrix without
    columns (returned as it is; LAPACK is not called with it)."""
    t = 5.0 + 2.0 * np.arange(n)
    x = np.random.default_rng(n).normal(size=(n, 2))
    for t0 in (None, 0.0):
        chol = np.linalg.cholesky(model.covariance(t, t0))
        fac = MarkovFactor(model, t, t0)
        assert fac.logdet == pytest.approx(2.0 * np.sum(np.log(np.diag(chol))), rel=1e-12, abs=1e-12)
        assert _rel(fac.whiten(x), np.linalg.solve(chol, x)) < 1e-12
        assert _rel(fac.whiten(x[:, 0]), np.linalg.solve(chol, x[:, 0])) < 1e-12
        assert fac.whiten(np.zeros((n, 0))).shape == (n, 0)
