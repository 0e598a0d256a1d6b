"""The Kalman updates, the RTS smoother and the SNC process noise against closed forms: the
filter-smoother over a linear problem equals the batch least squares with the same prior
(Tapley, Schutz & Born 2004, 4.7), and SNC's Q equals the integral it stands for."""

import numpy as np
import pytest
from scipy.integrate import quad

from trackproc.methods import sequential as sq


def _linear_case(seed=1):
    rng = np.random.default_rng(seed)
    dts = rng.uniform(1.0, 20.0, 30)
    t = np.concatenate([[0.0], np.cumsum(dts)])
    x_true = np.array([3.0, -0.2])
    h_rows = [np.array([1.0, 0.0]) if k % 3 else np.array([0.0, 1.0]) for k in range(t.size)]
    sig = np.array([0.5 if r[0] else 0.05 for r in h_rows])
    y = np.array([r @ np.array([x_true[0] + x_true[1] * tk, x_true[1]]) for r, tk in zip(h_rows, t)])
    y = y + sig * rng.standard_normal(t.size)
    return t, h_rows, sig, y


def test_filter_smoother_equals_batch_least_squares():
    t, h_rows, sig, y = _linear_case()
    x0, p0 = np.array([0.0, 0.0]), np.diag([100.0, 1.0])
    # batch: the state at t0, the rows mapped through Φ(t_k, t0)
    a = np.array([r @ np.array([[1.0, tk], [0.0, 1.0]]) for r, tk in zip(h_rows, t)])
    info = np.linalg.inv(p0) + a.T @ (a / sig[:, None] ** 2)
    rhs = np.linalg.inv(p0) @ x0 + a.T @ (y / sig ** 2)
    p_batch = np.linalg.inv(info)
    x_batch = p_batch @ rhs
    xs_f, ps_f, xs_p, ps_p, phis = [], [], [], [], []
    x, p = x0, p0
    for k, tk in enumerate(t):
        phi = np.eye(2) if k == 0 else np.array([[1.0, tk - t[k - 1]], [0.0, 1.0]])
        if k:
            x, p = sq.time_update(x, p, phi)
        xs_p.append(x), ps_p.append(p), phis.append(phi)
        x, p, s = sq.scalar_update(x, p, h_rows[k], y[k] - h_rows[k] @ x, sig[k] ** 2)
        xs_f.append(x), ps_f.append(p)
    x_s, p_s = xs_f[-1], ps_f[-1]
    for k in range(t.size - 2, -1, -1):
        x_s, p_s = sq.rts_step(xs_f[k], ps_f[k], xs_p[k + 1], ps_p[k + 1], phis[k + 1], x_s, p_s)
    np.testing.assert_allclose(x_s, x_batch, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(p_s, p_batch, rtol=1e-9, atol=1e-15)
    # the last filtered state is the batch solution mapped to the last time
    phi_n = np.array([[1.0, t[-1]], [0.0, 1.0]])
    np.testing.assert_allclose(xs_f[-1], phi_n @ x_batch, rtol=1e-10)
    np.testing.assert_allclose(ps_f[-1], phi_n @ p_batch @ phi_n.T, rtol=1e-9)
    # the filter-smoother statistic is NaN where the smoother adds nothing (the last time)
    stat = sq.mcreynolds(np.array(xs_f), np.array(ps_f), np.array(xs_f), np.array(ps_f))
    assert np.isnan(stat).all()


def test_joseph_update_matches_the_textbook_form_and_stays_symmetric():
    rng = np.random.default_rng(3)
    m = rng.standard_normal((6, 6))
    p = m @ m.T + np.eye(6)
    h = rng.standard_normal(6)
    x, pj, s = sq.scalar_update(np.zeros(6), p, h, 0.7, 0.25)
    k = p @ h / (h @ p @ h + 0.25)
    np.testing.assert_allclose(pj, p - np.outer(k, h) @ p, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(x, k * 0.7)
    assert abs(s - (h @ p @ h + 0.25)) < 1e-12 * s and np.array_equal(pj, pj.T)


def test_snc_noise_is_the_integral_of_a_white_acceleration():
    dt, q = 37.0, np.diag([2e-12, 5e-12, 1e-12])
    got = sq.snc_noise(dt, q)
    # Q = ∫ Φ(dt, s) B q Bᵀ Φ(dt, s)ᵀ ds with Φ the kinematic transition and B = [0; I]
    for (i, j), scale in (((0, 0), 1), ((0, 3), 1), ((3, 3), 1)):
        f = {(0, 0): lambda s: (dt - s) ** 2, (0, 3): lambda s: dt - s, (3, 3): lambda s: 1.0}[(i, j)]
        expected = quad(f, 0.0, dt)[0] * q[0, 0]
        assert abs(got[i, j] - expected) <= 1e-12 * abs(expected)
    np.testing.assert_allclose(got, got.T)


def test_nis_band_is_the_chi2_band():
    lo, hi = sq.nis_test(0.0, 100)
    # Wilson-Hilferty: k (1 - 2/(9k) ± z sqrt(2/(9k)))³ with z = 3.2905 (two-sided 99.9 %)
    w = np.sqrt(2.0 / 900.0)
    assert abs(lo - 100 * (1 - 2 / 900 - 3.2905 * w) ** 3) < 0.5
    assert abs(hi - 100 * (1 - 2 / 900 + 3.2905 * w) ** 3) < 0.5


def _gm_integrand(tau):
    """g(u) of a Gauss–Markov acceleration on (r, v, a) after u seconds (cancellation-free)."""
    b = 1.0 / tau
    return lambda u: np.array([(np.expm1(-b * u) + b * u) / b ** 2, -np.expm1(-b * u) / b, np.exp(-b * u)])


@pytest.mark.parametrize("dt,tau", [(10.0, 1e4), (59.0, 600.0), (60.0, 600.0), (61.0, 600.0), (100.0, 600.0),
                                    (5400.0, 600.0), (5400.0, 7200.0), (1.0, 1e6)])
def test_dmc_noise_is_the_integral_of_the_gauss_markov_response(dt, tau):
    """Q of DMC against adaptive quadrature of q g gᵀ (q = 2σ²/τ), on both sides of the switch
    between closed form and Gauss–Legendre (dt/τ = 0.1)."""
    from scipy.integrate import quad

    sigma = 2e-7
    q = 2 * sigma ** 2 / tau
    g = _gm_integrand(tau)
    ref = np.array([[quad(lambda u: q * g(u)[i] * g(u)[j], 0.0, dt, epsabs=0.0, epsrel=1e-12, limit=200)[0]
                     for j in range(3)] for i in range(3)])
    got = sq.dmc_noise(dt, tau, sigma)
    scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    assert np.max(np.abs(got - ref) / scale) < 1e-9
    assert np.all(np.linalg.eigvalsh(got / scale) > -1e-12)


@pytest.mark.parametrize("dt,tau", [(1e-3, 3600.0), (10.0, 3600.0), (3600.0, 3600.0), (5400.0, 600.0)])
def test_gm_transition_factors_are_the_decaying_acceleration_response(dt, tau):
    """A unit Gauss–Markov acceleration's velocity and position after dt (the mean response
    ∫g), over a constant one's (dt, dt²/2), by quadrature; and its decay e^{-dt/τ}."""
    from scipy.integrate import quad

    b = 1.0 / tau
    dv = quad(lambda u: np.exp(-b * u), 0.0, dt, epsrel=1e-13)[0]
    dr = quad(lambda u: -np.expm1(-b * u) / b, 0.0, dt, epsrel=1e-13)[0]
    f_r, f_v, e = sq.gm_transition(dt, tau)
    assert f_v == pytest.approx(dv / dt, rel=1e-10)
    assert f_r == pytest.approx(dr / (dt * dt / 2.0), rel=1e-8)
    assert e == pytest.approx(np.exp(-dt / tau), rel=1e-15)


def test_gauss_markov_variance_tends_to_its_steady_state():
    """Without updates a Gauss–Markov state's variance P ← e²P + Q tends to σ² (the process's
    steady state, Gelb 1974 table 3.3-1) from any start, over irregular steps; the DMC noise's
    acceleration entry is that of the bias."""
    rng = np.random.default_rng(1)
    sigma, tau = 0.7, 300.0
    for p in (0.0, 25.0):
        for dt in rng.uniform(1.0, 200.0, 200):
            e = sq.gm_transition(dt, tau)[2]
            p = e * e * p + sq.gm_bias_noise(dt, tau, sigma)
        assert p == pytest.approx(sigma ** 2, rel=1e-9)
    assert sq.dmc_noise(123.0, tau, sigma)[2, 2] == pytest.approx(sq.gm_bias_noise(123.0, tau, sigma), rel=1e-12)
