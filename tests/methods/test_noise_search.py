"""The REML noise search (methods/trust_region.py ``minimise``: trust-region quasi-Newton in
log-parameters, as methods/noise.py calls it) against independent references: the closed-form minimum of quadratics (inside
the box and on its bounds) and a brute-force grid of the restricted likelihood of simulated passes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackproc.methods import noise as nz
from trackproc.methods.trust_region import minimise


@pytest.mark.parametrize("seed", range(6))
def test_minimum_of_a_quadratic_inside_the_box(seed):
    """(x - c)ᵀ A (x - c) with A symmetric positive definite (condition up to ~100, 1-3 dims):
    the minimiser c within the result's 0.001 grid plus the forward differences' bias (their
    step 1e-4 over 2, times A's condition at most)."""
    rng = np.random.default_rng(seed)
    d = 1 + seed % 3
    q, _ = np.linalg.qr(rng.normal(size=(d, d)))
    a = q @ np.diag(np.exp(rng.uniform(0.0, 4.6, d))) @ q.T
    c = rng.uniform(-3.0, 3.0, d)
    calls = []

    def f(x):
        calls.append(1)
        return float((x - c) @ a @ (x - c))

    z, neg = minimise(f, rng.uniform(-3.0, 3.0, d), [(-10.0, 10.0)] * d, ftol=1e-9, xtol=1e-7)
    assert np.max(np.abs(z - c)) <= 5e-4 + 5e-5 * np.linalg.cond(a), (z, c)
    assert -neg == pytest.approx(f(z))
    assert len(calls) < 150


def test_minimum_on_the_bounds_is_held_there():
    """A separable quadratic whose minimiser lies beyond the box in one coordinate: the
    constrained minimum is that coordinate at its bound, the others at their minimiser."""
    c = np.array([1.5, 14.0, -2.0])
    w = np.array([3.0, 0.5, 10.0])
    z, _ = minimise(lambda x: float(np.sum(w * (x - c) ** 2)), np.zeros(3), [(-5.0, 5.0)] * 3,
                        ftol=1e-10, xtol=1e-8)
    assert z[1] == 5.0
    assert np.max(np.abs(z[[0, 2]] - c[[0, 2]])) <= 6e-4


@pytest.mark.parametrize("true", [nz.NoiseModel(1.0, 1.5, 12.0), nz.NoiseModel(1.0, 0.6, 3.0),
                                  nz.NoiseModel(1.0, 0.0, 0.0, 0.08)], ids=["ar1", "ar1-short", "walk"])
def test_reml_fit_reaches_the_grid_maximum(true):
    """The AR(1) and walk candidates' maximised restricted log-likelihood on a simulated pass
    (200 samples at 1 s, a constant and a line as fixed effects) against the largest value on a
    brute-force grid (1-D: 400 points; 2-D: 50 x 50 with a 30 x 30 refinement about its best
    cell): never below it by more than the search's tolerance."""
    rng = np.random.default_rng(5)
    t = np.arange(200.0)
    x = np.column_stack([np.ones_like(t), t / t.max()])
    r = np.linalg.cholesky(true.covariance(t)) @ rng.normal(size=t.size) + x @ rng.normal(size=2)
    fit = nz.fit_noise(t, r, x, models=("white", "ar1", "walk"))
    reml = nz._Reml(t, r, nz._basis(x), 0.0)
    span = float(t.max() - t.min())

    def ar(za, zt):
        return reml(nz.NoiseModel(1.0, math.exp(0.5 * za), math.exp(zt)))[0]

    lo, hi = math.log(0.5), math.log(2.0 * span)
    za, zt = np.linspace(-8.0, 6.0, 50), np.linspace(lo, hi, 50)
    vals = np.array([[ar(u, v) for v in zt] for u in za])
    i, j = np.unravel_index(np.argmax(vals), vals.shape)
    fine = [ar(u, v) for u in np.linspace(za[max(i - 1, 0)], za[min(i + 1, 49)], 30)
            for v in np.linspace(zt[max(j - 1, 0)], zt[min(j + 1, 49)], 30)]
    grid_ar = max(vals.max(), max(fine))
    grid_walk = max(reml(nz.NoiseModel(1.0, 0.0, 0.0, math.exp(0.5 * z)))[0] for z in np.linspace(-25.0, 5.0, 400))
    assert fit.candidates["ar1"]["loglik_restricted"] >= grid_ar - 2e-3
    assert fit.candidates["walk"]["loglik_restricted"] >= grid_walk - 2e-3
    assert fit.candidates["ar1"]["loglik_restricted"] <= grid_ar + 0.5          # the grid is fine enough to tell
