"""Correlated noise and a wandering oscillator (methods/noise.py; refine and estimate by GLS).

Independent references: the noise model's REML choice against processes of known kind
(simulated), the effective sample count against its closed form, GLS against the textbook
generalised least squares, and Monte Carlo of ``refine`` on passes with oscillator wander (random
walk), AR(1) noise and 2 Hz quantisation (truth known): NEES of the refined state in its
chi-square band. The seed 004 Table 1 pass (tests/report/test_refine.py) carries the simulation.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from trackproc.methods import noise as nz
from trackproc.methods.least_squares import Options, solve, solve_gls
from trackproc.pipeline.refine import RefineOptions, prepare, solve_noise

from test_refine import EOP, EPOCH, OFFSET_HZ, STALE_RV, scenario, table, truth_at
from trackproc.io.statefile import State

#: the simulated oscillator: drift (Hz/s), random walk (Hz/√s); AR(1) noise: sigma (Hz), tau (s);
#: receiver quantisation step (Hz)
DRIFT_HZ_S = 0.2
WALK = 0.05
AR_SIGMA_HZ, AR_TAU_S = 2.0, 20.0
QUANTUM_HZ = 2.0


def _design(t):
    return np.column_stack([np.ones_like(t), t / t.max(), np.sin(t / 150.0), np.cos(t / 150.0)])


@pytest.mark.parametrize("true,expected", [
    (nz.NoiseModel(0.6), "white"),
    (nz.NoiseModel(0.6, 1.5, 15.0), "ar1"),
    (nz.NoiseModel(0.6, 0.0, 0.0, 0.2), "walk"),
])
def test_reml_chooses_the_process_that_made_the_residuals(true, expected):
    """White noise is never taken for correlated noise (10 of 10 draws), correlated noise never
    for white (it may be given the model with both components, which nests it); the REML
    estimates of the true model's parameters are near the truth."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 500.0, 1.0)
    x = _design(t)
    chol = np.linalg.cholesky(true.covariance(t))
    names, fits = [], []
    for _ in range(10):
        r = chol @ rng.normal(size=t.size) + x @ rng.normal(size=x.shape[1]) * 50.0
        f = nz.fit_noise(t, r, x)
        names.append(f.model.name)
        fits.append(f.candidates[expected])
    if expected == "white":
        assert names == ["white"] * 10, names
    else:
        assert all(n in (expected, "ar1+walk") for n in names), names
    assert abs(np.median([m["white"] for m in fits]) / true.white - 1) < 0.2
    if expected == "ar1":
        assert abs(np.median([m["ar1_sigma"] for m in fits]) / true.ar_sigma - 1) < 0.35
        assert 0.5 < np.median([m["ar1_tau_s"] for m in fits]) / true.ar_tau_s < 2.0
    if expected == "walk":
        assert 0.6 < np.median([m["walk_per_sqrt_s"] for m in fits]) / true.walk < 1.6


def test_effective_samples_of_an_ar1_process_is_its_closed_form():
    """(tr C)²/tr(C²) of a stationary AR(1) of correlation ρ on n samples tends to
    n (1 - ρ²)/(1 + ρ²) (Bayley & Hammersley 1946)."""
    t = np.arange(4000.0)
    m = nz.NoiseModel(1e-9, 1.0, 10.0)
    rho = np.exp(-0.1)
    assert nz.effective_samples(m.covariance(t)) == pytest.approx(t.size * (1 - rho ** 2) / (1 + rho ** 2), rel=0.01)


def test_gls_equals_the_textbook_estimate_and_edits_an_outlier():
    """Linear model: solve_gls gives (XᵀC⁻¹X)⁻¹XᵀC⁻¹y and its covariance exactly; a 30-sigma
    outlier is edited on its innovation and the rest of the pass kept."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 300.0, 1.0)
    x = _design(t)
    model = nz.NoiseModel(0.5, 1.0, 10.0, 0.02)
    c = model.covariance(t)
    y = x @ np.array([1.0, 2.0, 3.0, 4.0]) + np.linalg.cholesky(c) @ rng.normal(size=t.size)
    cov = nz.PassCovariance(np.full(t.size, 0.5), t, [(np.arange(t.size), model, 0.0)])

    def fit(model_w, y_w, start):
        return solve(model_w, start, y_w, np.ones(y_w.size), names=list("abcd"), options=Options(clip=None)), None

    lin = lambda p: (x @ p, x)      # noqa: E731
    sol, _ = solve_gls(lin, np.zeros(4), y, cov, fit, clip=None)
    ci = np.linalg.inv(c)
    k = np.linalg.inv(x.T @ ci @ x)
    np.testing.assert_allclose(sol.values, k @ x.T @ ci @ y, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(sol.covariance, k, rtol=1e-8)
    y2 = y.copy()
    y2[150] += 30.0 * np.sqrt(c[150, 150])
    sol2, _ = solve_gls(lin, np.zeros(4), y2, cov, fit, clip=4.0)
    # the outlier, and at most the few samples after it whose one-step prediction it spoils
    assert sol2.edited[150] and set(np.flatnonzero(sol2.edited)) <= set(range(150, 156))


def _wander_factor(t, t0):
    """The Cholesky factor of the AR(1) + random walk covariance of the oscillator at the sample
    times: ``factor @ N(0, I)`` is one draw of that noise."""
    return np.linalg.cholesky(nz.NoiseModel(1e-6, AR_SIGMA_HZ, AR_TAU_S, WALK).covariance(t, t0))


def _nees_draws(n_draws, seed, step_s, white_fit=True):
    """``white_fit``: also fit each draw as white noise (its NEES; NaN when False)."""
    _, _, sim = scenario(step_s=step_s, noise=False)
    stale = State.from_vectors(EPOCH, STALE_RV[:3], STALE_RV[3:])            # no covariance: the default a-priori
    ref = prepare(table(sim), stale, None, RefineOptions(doppler_bias="offset+drift", covariance="linear"), EOP)
    t = ref.problem.meas.t_s
    t0 = float(t.min())
    truth = np.r_[truth_at(ref.problem.epoch), OFFSET_HZ, DRIFT_HZ_S]
    chol = np.linalg.cholesky(ref.priors[0].covariance)
    wander = _wander_factor(t, t0)                  # the same times every draw: factored once
    rng = np.random.default_rng(seed)
    nees6, nees8, models, white_nees, zmax = [], [], [], [], []
    for _ in range(n_draws):
        centre = truth[:6] + chol @ rng.normal(size=6)
        clean = sim.truth_values + OFFSET_HZ + DRIFT_HZ_S * (t - t0) + wander @ rng.normal(size=t.size)
        y = QUANTUM_HZ * np.round(clean / QUANTUM_HZ)
        x0 = np.r_[centre, 0.0, 0.0]
        noisy, sol, _, _ = solve_noise(None, None, ref, observed=y, prior_centre=centre, x0=x0)
        e = sol.values - truth
        nees8.append(float(e @ np.linalg.solve(sol.covariance, e)))
        nees6.append(float(e[:6] @ np.linalg.solve(sol.covariance[:6, :6], e[:6])))
        zmax.append(float(np.max(np.abs(e[:6]) / sol.sigma[:6])))
        models.append(noisy.noise_report["model"])
        if not white_fit:
            white_nees.append(float("nan"))
            continue
        white = ref.solve(observed=y, prior_centre=centre, x0=x0)[0]           # what independent samples claim
        ew = white.values[:6] - truth[:6]
        white_nees.append(float(ew @ np.linalg.solve(white.covariance[:6, :6], ew)))
    return np.array(nees6), np.array(nees8), models, np.array(white_nees), np.array(zmax)


def test_refine_with_wander_ar1_and_quantisation_is_honest_fast():
    """20 draws (the slow test has 100): mean NEES of the state within 2x its dimension, every
    draw within chi2(6) at 0.9999, the noise recognised as correlated, while the white fit on
    the same data is overconfident."""
    nees6, nees8, models, white, zmax = _nees_draws(20, 11, 2.0)
    print(f"NEES6 mean {nees6.mean():.2f} max {nees6.max():.1f}; NEES8 mean {nees8.mean():.2f}; "
          f"white-fit NEES6 mean {white.mean():.1f}; models {sorted(set(models))}")
    assert nees6.mean() <= 12.0 and nees8.mean() <= 16.0
    assert nees6.max() < stats.chi2.ppf(0.9999, 6) and zmax.max() < 4.0
    assert all(m != "white" for m in models)
    assert white.mean() > 2 * nees6.mean()


@pytest.mark.slow
def test_refine_with_wander_ar1_and_quantisation_nees_in_its_chi2_band():
    """100 draws: mean NEES of the state (6) in the 99 % chi-square band of the mean, every state
    component within 4 sigma of the truth, and the NEES of state + offset + drift (8) within issue
    13's 2x its dimension. Measured: NEES6 mean 6.66 in [5.15, 6.93] (its largest 32.5: two draws
    beyond chi2(6)'s 4-sigma point 28.9, heavier tails than chi-square as the noise parameters are
    estimates); NEES8 12.4 (band [7.0, 9.1]): the offset and drift are somewhat overconfident
    because the walk's intensity is a REML estimate plugged in (with the true noise model the same
    machinery gives NEES6 5.8, NEES8 7.9 over 30 draws)."""
    # the white fit is the fast test's claim; here it would only be printed
    nees6, nees8, models, _, zmax = _nees_draws(100, 2026, 2.0, white_fit=False)
    lo6, hi6 = stats.chi2.ppf([0.005, 0.995], 6 * 100) / 100
    print(f"NEES6 mean {nees6.mean():.2f} in [{lo6:.2f}, {hi6:.2f}], max {nees6.max():.1f}; NEES8 mean "
          f"{nees8.mean():.2f}; largest |error|/sigma {zmax.max():.2f}; "
          f"models { {m: models.count(m) for m in set(models)} }")
    assert lo6 < nees6.mean() < hi6
    assert nees8.mean() <= 16.0
    assert zmax.max() < 4.0
    assert (nees6 > stats.chi2.ppf(1 - 6.3e-5, 6)).sum() <= 3
