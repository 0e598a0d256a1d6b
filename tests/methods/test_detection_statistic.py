"""Seed 003 eqs. 2-8 (methods/detection.py): moments of S, error rates by Monte Carlo, γ and g."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import binom, norm

from trackproc.methods import ballistic as bl
from trackproc.methods import detection as dt

DEG = np.pi / 180.0


def _nominal_pass(step_s=2.0, tau_s=30.0, v=3000.0, a_deg=48.0, displacement_m=500.0):
    """a_i (H0) and b_i (H1) of the unfavourable planar orbit on [rise, T - τ] every step_s."""
    enc = bl.PlanarEncounter.from_impact(v, a_deg * DEG)
    s = np.arange(-tau_s, enc.rise_time(), -step_s)[::-1]
    return s, enc.elevation(s), enc.elevation(s, displacement_m)


def _binomial_ok(k: int, n: int, p: float, level: float = 1e-4) -> bool:
    """Two-sided exact binomial test: k successes in n at probability p not rejected at ``level``."""
    lo, hi = binom.cdf(k, n, p), binom.sf(k - 1, n, p)
    return 2 * min(lo, hi) > level


def test_seed003_eq7_equal_error_probability_for_gamma_5():
    assert dt.equal_error(5.0) == pytest.approx(0.00621, abs=1e-5)       # "≈ 0.006"
    assert dt.gamma_from_errors(dt.equal_error(5.0)) == pytest.approx(5.0, rel=1e-12)
    g = dt.gamma_from_errors(0.01, 0.05)                                  # unequal case
    assert g == pytest.approx(norm.ppf(0.99) + norm.ppf(0.95), rel=1e-12)
    assert dt.miss_probability(0.01, g) == pytest.approx(0.05, rel=1e-10)
    with pytest.raises(ValueError):
        dt.gamma_from_errors(0.7)


def test_seed003_eqs3_4_moments_of_s_by_monte_carlo():
    """E[S|H0] = 0, E[S|H1] = C_n, Var S = σ² C_n under both hypotheses (20000 passes each)."""
    _, a, b = _nominal_pass()
    sigma = 4e-3
    rng = np.random.default_rng(3)
    n_mc = 20000
    for truth, mean in ((a, 0.0), (b, None)):
        x = truth + rng.normal(0.0, sigma, (n_mc, a.size))
        st = dt.statistic(x, a, b, np.full(a.size, sigma))
        mean = st.c_n if mean is None else mean
        sd = np.sqrt(st.variance)
        assert np.mean(st.s) == pytest.approx(mean, abs=4 * sd / np.sqrt(n_mc))
        # sample variance: relative standard error sqrt(2/(n-1))
        assert np.var(st.s, ddof=1) / st.variance == pytest.approx(1.0, abs=4 * np.sqrt(2 / (n_mc - 1)))
        assert st.uniform_sigma and st.sigma0 == sigma
    assert st.c_n == pytest.approx(np.sum((b - a) ** 2), rel=1e-14)
    assert st.gamma == pytest.approx(np.sqrt(st.c_n) / sigma, rel=1e-14)


def test_statistic_with_per_sample_sigmas_keeps_the_moments():
    _, a, b = _nominal_pass(step_s=5.0)
    sigma = np.linspace(2e-3, 6e-3, a.size)
    rng = np.random.default_rng(4)
    x0 = a + rng.normal(0.0, 1.0, (20000, a.size)) * sigma
    st = dt.statistic(x0, a, b, sigma)
    assert not st.uniform_sigma
    assert np.mean(st.s) == pytest.approx(0.0, abs=4 * st.std / np.sqrt(20000))
    assert np.var(st.s, ddof=1) / st.variance == pytest.approx(1.0, abs=4 * np.sqrt(2 / 19999))
    assert st.gamma == pytest.approx(np.sqrt(np.sum(((b - a) / sigma) ** 2)), rel=1e-12)  # whitened γ


@pytest.mark.parametrize("gamma_target", [3.0, 5.0])
def test_seed003_monte_carlo_error_rates_match_one_minus_phi_gamma_over_2(gamma_target):
    """≥ 1000 passes per hypothesis (here 4000): the equal-error threshold C_n/2 gives
    false-alarm and miss rates 1 - Φ(γ/2) within their binomial bounds."""
    _, a, b = _nominal_pass()
    sigma = np.sqrt(np.sum((b - a) ** 2)) / gamma_target       # noise that gives the target γ
    sig = np.full(a.size, sigma)
    rng = np.random.default_rng(int(gamma_target * 10))
    n_mc = 4000
    p = dt.equal_error(gamma_target)
    s0 = dt.statistic(a + rng.normal(0.0, sigma, (n_mc, a.size)), a, b, sig)
    s1 = dt.statistic(b + rng.normal(0.0, sigma, (n_mc, a.size)), a, b, sig)
    assert s0.gamma == pytest.approx(gamma_target, rel=1e-12)
    h = dt.decide(dt.statistic(a, a, b, sig)).threshold
    assert h == pytest.approx(s0.c_n / 2)
    false_alarms = int(np.sum(s0.s > h))
    misses = int(np.sum(s1.s <= h))
    assert _binomial_ok(false_alarms, n_mc, p), (false_alarms, n_mc * p)
    assert _binomial_ok(misses, n_mc, p), (misses, n_mc * p)


def test_false_alarm_threshold_and_miss_probability_by_monte_carlo():
    _, a, b = _nominal_pass()
    sigma = np.sqrt(np.sum((b - a) ** 2)) / 3.0
    sig = np.full(a.size, sigma)
    rng = np.random.default_rng(7)
    n_mc = 4000
    d = dt.decide(dt.statistic(a, a, b, sig), false_alarm=0.05)
    assert d.criterion == "false-alarm" and d.alpha == 0.05
    assert d.beta == pytest.approx(norm.cdf(norm.ppf(0.95) - 3.0), rel=1e-10)
    s0 = dt.statistic(a + rng.normal(0.0, sigma, (n_mc, a.size)), a, b, sig).s
    s1 = dt.statistic(b + rng.normal(0.0, sigma, (n_mc, a.size)), a, b, sig).s
    assert _binomial_ok(int(np.sum(s0 > d.threshold)), n_mc, 0.05)
    assert _binomial_ok(int(np.sum(s1 <= d.threshold)), n_mc, d.beta)


def test_decide_refuses_identical_hypotheses():
    a = np.zeros(5)
    with pytest.raises(ValueError, match="C_n = 0"):
        dt.decide(dt.statistic(a, a, a, np.ones(5)))
    with pytest.raises(ValueError):
        dt.statistic(a, a, a + 1, np.zeros(5))


def test_information_distance_quadrature_matches_adaptive_quad():
    for v, a_deg, tau in ((3000.0, 48.0, 30.0), (1000.0, 60.0, 20.0), (5000.0, 12.0, 50.0)):
        enc = bl.PlanarEncounter.from_impact(v, a_deg * DEG)
        rise = enc.rise_time()
        def f(s, enc=enc):
            return enc.elevation(s, 500.0) - enc.elevation(s)

        ours = dt.information_distance(f, rise, -tau)
        ref = np.sqrt(quad(lambda s, f=f: float(f(s)) ** 2, rise, -tau, limit=400, epsabs=0, epsrel=1e-12)[0])
        assert ours == pytest.approx(ref, rel=1e-9)
    assert dt.information_distance(lambda s: s, -10.0, -20.0) == 0.0        # empty window


def test_seed003_eq6_discrete_sum_matches_the_integral():
    """C_n Δt → ‖Δε‖² (eqs. 5-6): γ from the samples equals ‖Δε‖ / (σ sqrt Δt) for a 1 s grid."""
    enc = bl.PlanarEncounter.from_impact(3000.0, 48 * DEG)
    distance = dt.information_distance(lambda s: enc.elevation(s, 500.0) - enc.elevation(s), enc.rise_time(), -30.0)
    _, a, b = _nominal_pass(step_s=1.0)
    st = dt.statistic(a, a, b, np.full(a.size, 4e-3))
    assert st.gamma == pytest.approx(distance / (4e-3 * 1.0), rel=0.02)
