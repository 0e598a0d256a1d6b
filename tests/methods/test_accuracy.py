"""Accuracy methods (seed 000): the image-domain statistics against the closed form of the seed's
worked example, the printed series (33)-(34) corrected, the STM and Clohessy-Wiltshire
covariances, and Monte Carlo within its statistical bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackproc.constants import MU_EARTH
from trackproc.dynamics import spectra as sp
from trackproc.dynamics.taylor import propagate
from trackproc.methods import accuracy as ac

R_ORBIT = 7.0e6
N_MOTION = math.sqrt(MU_EARTH / R_ORBIT ** 3)          # 1.078e-3 rad/s, period 5828.5 s
PERIOD = 2 * math.pi / N_MOTION
S1, S2 = 100.0, 0.1                                     # sigma_v1 (m), sigma_v2 (m/s)
#: seed 004 Table 1 "truth" state: near-circular LEO, |r| = 7191 km.
LEO = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])


def _correlated_cov(seed=3, sr=100.0, sv=0.1):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((6, 6))
    c = a @ a.T
    c = c / np.sqrt(np.outer(np.diag(c), np.diag(c)))
    s = np.array([sr] * 3 + [sv] * 3)
    return c * np.outer(s, s)


def _element_scale(phi, p0, terms=None):
    """|Phi| |P0| |Phi|^T, with |Phi| replaced by the sum of the absolute discretes of the
    sensitivity spectra when given: the size of the terms summed into each element."""
    a = np.abs(phi) if terms is None else np.abs(terms).sum(-1)
    return np.einsum("...ij,jk,...lk->...il", a, np.abs(p0), a)


# ----------------------------------------------------------------------------- seed 000 example

def test_seed000_closed_form_with_enough_discretes_to_1e10():
    """Ground truth D_x = s1^2 cos^2(nt) + s2^2 sin^2(nt)/n^2 over ten days (restarted expansion)."""
    t = np.linspace(0.0, 10 * 86400.0, 2001)
    st = ac.seed000_statistics(t, S1, S2, N_MOTION)
    exact = ac.seed000_variance_exact(t, S1, S2, N_MOTION)
    assert np.max(np.abs(st["var_x_m2"] / exact - 1)) < 1e-10
    exact_v = ac.seed000_velocity_variance_exact(t, S1, S2, N_MOTION)
    assert np.max(np.abs(st["var_vx_m2_s2"] / exact_v - 1)) < 1e-10
    # the mean (eq. 18) is the nominal motion x0 cos(nt) + g0 sin(nt)/n
    st = ac.seed000_statistics(t, S1, S2, N_MOTION, x0_m=R_ORBIT, g0_m_s=3.0)
    mean = R_ORBIT * np.cos(N_MOTION * t) + 3.0 * np.sin(N_MOTION * t) / N_MOTION
    assert np.max(np.abs(st["mean_x_m"] - mean)) < 1e-10 * R_ORBIT


def test_seed000_single_expansion_with_enough_discretes():
    """The paper's single expansion (H = t) converges too, within its round-off eps*e^(nt)."""
    t = np.linspace(0.0, PERIOD, 301)
    n_disc = ac.seed000_enough_discretes(N_MOTION * PERIOD)
    st = ac.seed000_statistics(t, S1, S2, N_MOTION, n_discretes=n_disc)
    exact = ac.seed000_variance_exact(t, S1, S2, N_MOTION)
    assert np.max(np.abs(st["var_x_m2"] / exact - 1)) < 1e-10


def _poly(coeffs_by_power, n_terms):
    out = np.zeros(n_terms)
    for k, c in coeffs_by_power.items():
        out[k] = c
    return out


def test_seed000_eq33_eq34_corrected():
    """With H = 1 the variance spectrum R_x(K) is the coefficient of t^K of D_x(t): four discretes
    give eq. 33 and six give eq. 34, with their printed typos corrected (33: the t^6 terms have
    r^6 and sigma_v1 for D_g; the t^4 sigma_v1 term of D_g has 3, not 3!; 34: the t^4 sigma_v1
    coefficient is n^4/3, not n^4/4)."""
    n2 = N_MOTION ** 2
    cov = np.diag([S1 ** 2, S2 ** 2])
    r4 = ac.correlation_spectrum(ac.seed000_spectra([1.0], N_MOTION, 4), cov=cov)[0]    # (2, 2, 7)
    dx33 = _poly({0: S1 ** 2, 2: S2 ** 2 - n2 * S1 ** 2, 4: n2 ** 2 / 4 * S1 ** 2 - n2 / 3 * S2 ** 2,
                  6: n2 ** 2 / 36 * S2 ** 2}, 7)
    dg33 = _poly({0: S2 ** 2, 2: -(n2 * S2 ** 2 - n2 ** 2 * S1 ** 2),
                  4: n2 ** 2 / 4 * S2 ** 2 - n2 ** 3 / 3 * S1 ** 2, 6: n2 ** 4 / 36 * S1 ** 2}, 7)
    np.testing.assert_allclose(r4[0, 0], dx33, rtol=1e-14, atol=1e-30)
    np.testing.assert_allclose(r4[1, 1], dg33, rtol=1e-14, atol=1e-30)
    r6 = ac.correlation_spectrum(ac.seed000_spectra([1.0], N_MOTION, 6), cov=cov)[0]
    dx34 = _poly({0: S1 ** 2, 2: S2 ** 2 - n2 * S1 ** 2, 4: n2 ** 2 / 3 * S1 ** 2 - n2 / 3 * S2 ** 2,
                  6: 2 * n2 ** 2 / 45 * S2 ** 2 - n2 ** 3 / 24 * S1 ** 2,
                  8: n2 ** 4 / 576 * S1 ** 2 - n2 ** 3 / 360 * S2 ** 2, 10: n2 ** 4 / 14400 * S2 ** 2}, 11)
    np.testing.assert_allclose(r6[0, 0], dx34, rtol=1e-14, atol=1e-30)
    # the paper's own 2.67/60 for the t^6 sigma_v2 term is 2/45 rounded
    assert abs(2.67 / 60 - 2 / 45) < 1e-4


def test_seed000_literal_eqs_21_to_24_by_expectation():
    """m_q(K) = E[X(., t1) * X(., t2)](K) by exact Gaussian quadrature, minus m_x * m_x (eqs. 21-24),
    equals the correlation spectrum computed from the random parts alone."""
    t1, t2 = 700.0, 1900.0
    spec1 = ac.seed000_spectra([t1], N_MOTION, 20, x0_m=30.0, g0_m_s=0.02)[0]     # (2, 3, 20)
    spec2 = ac.seed000_spectra([t2], N_MOTION, 20, x0_m=30.0, g0_m_s=0.02)[0]
    nodes, weights = np.polynomial.hermite_e.hermegauss(3)                        # exact to degree 5
    weights = weights / weights.sum()
    mq = np.zeros(39)
    for a, wa in zip(nodes, weights):
        for b, wb in zip(nodes, weights):
            v = np.array([1.0, S1 * a, S2 * b])
            x1 = v @ spec1[0]
            x2 = v @ spec2[0]
            mq += wa * wb * sp.cauchy(np.r_[x1, np.zeros(19)], np.r_[x2, np.zeros(19)])
    mm = sp.cauchy(np.r_[ac.mean_spectrum(spec1)[0], np.zeros(19)], np.r_[ac.mean_spectrum(spec2)[0], np.zeros(19)])
    r = ac.correlation_spectrum(spec1, spec2, np.diag([S1 ** 2, S2 ** 2]))[0, 0]
    np.testing.assert_allclose(mq - mm, r, rtol=1e-9, atol=1e-9 * np.abs(r).max())
    # and its sum is the covariance R_x(t1, t2) of the exact solution
    exact = S1 ** 2 * np.cos(N_MOTION * t1) * np.cos(N_MOTION * t2) + \
        S2 ** 2 * np.sin(N_MOTION * t1) * np.sin(N_MOTION * t2) / N_MOTION ** 2
    assert abs(r.sum() / exact - 1) < 1e-10        # 20 discretes at n t ~ 2: (nt)^20/20! ~ 8e-13


def test_seed000_t100_error_four_orders_below_initial_variance():
    """The paper: at t = 100 s the error of the variance is four orders below the initial
    variance (with 4 discretes; 6 barely change it)."""
    t = np.array([100.0])
    exact = ac.seed000_variance_exact(t, S1, S2, N_MOTION)
    for n_disc in (4, 6):
        d = ac.seed000_statistics(t, S1, S2, N_MOTION, n_discretes=n_disc)["var_x_m2"]
        assert abs(d - exact)[0] / S1 ** 2 < 1e-4


def test_seed000_truncation_degrades_with_time():
    """4 and 6 discretes: the error grows with t (as t^(2N)); enough discretes stay at round-off."""
    t = np.array([100.0, 300.0, 600.0, 1000.0, 2000.0, 3000.0, 6000.0])
    exact = ac.seed000_variance_exact(t, S1, S2, N_MOTION)
    err = {}
    for n_disc in (4, 6, None):
        d = ac.seed000_statistics(t, S1, S2, N_MOTION, n_discretes=n_disc)["var_x_m2"]
        err[n_disc] = np.abs(d / exact - 1)
    assert np.all(np.diff(err[4][:4]) > 0) and np.all(np.diff(err[6]) > 0)
    assert np.all(err[6][:5] < err[4][:5])
    assert err[4][-1] > 100 and err[6][-1] > 10          # useless after one period
    assert err[None].max() < 1e-14


def test_seed000_velocity_errors_dominate_as_time_grows():
    """Seed 000's conclusion, from the spectral method itself: per unit variance the weight of the
    initial velocity error on D_x, relative to that of the position error, exceeds 1 after ~1 s
    and grows monotonically (tan^2(nt)/n^2) up to a quarter period; with the example's errors
    (100 m, 0.1 m/s) the velocity share of D_x grows from 0 to 1 over that quarter period."""
    t = np.linspace(5.0, PERIOD / 4 - 5.0, 200)
    d_pos = ac.seed000_statistics(t, 1.0, 0.0, N_MOTION)["var_x_m2"]            # per m^2
    d_vel = ac.seed000_statistics(t, 0.0, 1.0, N_MOTION)["var_x_m2"]            # per (m/s)^2
    weight = d_vel / d_pos
    np.testing.assert_allclose(weight, ac.seed000_velocity_weight(t, N_MOTION), rtol=1e-10)
    assert np.all(weight > 1.0) and np.all(np.diff(weight) > 0)
    share = S2 ** 2 * d_vel / (S1 ** 2 * d_pos + S2 ** 2 * d_vel)
    assert share[0] < 0.01 and share[-1] > 0.99 and np.all(np.diff(share) > 0)
    # Fig. 1 vs Fig. 2: doubling the velocity error moves sigma_x(t) more and more as t grows,
    # doubling the position error less and less
    base = ac.seed000_statistics(t, S1, S2, N_MOTION)["sigma_x_m"]
    dv = ac.seed000_statistics(t, S1, 2 * S2, N_MOTION)["sigma_x_m"] - base
    dp = ac.seed000_statistics(t, 2 * S1, S2, N_MOTION)["sigma_x_m"] - base
    assert np.all(np.diff(dv) > 0) and np.all(np.diff(dp) < 0)


def test_seed000_spectral_equals_stm_for_the_linear_model():
    """x'' = -n^2 x is linear: the image-domain covariance equals Phi P0 Phi^T to round-off."""
    t = np.linspace(0.0, 3 * 86400.0, 500)
    p0 = np.array([[S1 ** 2, 0.3 * S1 * S2], [0.3 * S1 * S2, S2 ** 2]])        # correlated errors
    spec = ac.seed000_spectra(t, N_MOTION, 18, restart_s=0.5 / N_MOTION)
    spec[:, :, 1:] *= -1                                                         # d/d(x0, g0) = -d/d(v1, v2)
    p_spec = ac.correlation(spec, cov=p0)
    c, s = np.cos(N_MOTION * t), np.sin(N_MOTION * t)
    phi = np.stack([np.stack([c, s / N_MOTION], -1), np.stack([-N_MOTION * s, c], -1)], -2)
    p_stm = ac.stm_covariance(phi, p0)
    assert np.max(np.abs(p_spec - p_stm) / _element_scale(phi, p0)) < 1e-13


def test_seed000_monte_carlo_within_its_bound():
    """Sample variance of N draws of the exact solution: relative sd sqrt(2/(N-1)); checked at
    4 sd, and the bound itself checked on 400 repetitions."""
    t = np.linspace(0.0, PERIOD, 25)
    n = 4000
    v = ac.sample_initial_states([0.0, 0.0], np.diag([S1 ** 2, S2 ** 2]), n, seed=11)
    x = np.cos(N_MOTION * t)[None] * v[:, :1] + np.sin(N_MOTION * t)[None] / N_MOTION * v[:, 1:]
    _, var = ac.sample_covariance(x[..., None])
    exact = ac.seed000_variance_exact(t, S1, S2, N_MOTION)
    rel = ac.monte_carlo_bounds(n)["variance_relative_sd"]
    assert np.max(np.abs(var[:, 0, 0] / exact - 1)) < 4 * rel
    # the bound: spread of s^2 over repetitions
    reps = np.random.default_rng(5).standard_normal((400, 50))
    s2 = reps.var(axis=1, ddof=1)
    assert abs(s2.std() / ac.monte_carlo_bounds(50)["variance_relative_sd"] - 1) < 0.15


# ----------------------------------------------------------------------------- the DT engine

@pytest.fixture(scope="module")
def leo_day():
    return propagate(LEO, 0.0, 86400.0, force="j2", stm=True)


def test_state_spectra_sum_to_state_and_stm(leo_day):
    t = np.linspace(0.0, 86400.0, 97)
    spec = ac.state_spectra(leo_day, t)
    np.testing.assert_allclose(spec[:, :, 0].sum(-1), leo_day.state(t), rtol=0, atol=1e-6)
    np.testing.assert_allclose(spec[:, :, 1:].sum(-1), leo_day.stm(t), rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("force", ["two-body", "j2"])
def test_spectral_equals_stm_covariance_to_round_off(force, leo_day):
    """First-order spectra (seed 000 eqs. 21-25) and Phi P0 Phi^T: the same moments, summed in a
    different order. Compared element by element against the size of the terms summed."""
    prop = leo_day if force == "j2" else propagate(LEO, 0.0, 86400.0, force=force, stm=True)
    t = np.arange(0.0, 86400.0 + 1, 300.0)
    p0 = _correlated_cov()
    p_spec = ac.spectral_covariance(prop, t, p0)
    phi = prop.stm(t)
    p_stm = ac.stm_covariance(phi, p0)
    terms = ac.state_spectra(prop, t)[:, :, 1:]
    assert np.max(np.abs(p_spec - p_stm) / _element_scale(phi, p0, terms)) < 1e-13


def test_spectral_cross_covariance(leo_day):
    t1 = np.array([0.0, 1234.5, 40000.0])
    t2 = np.array([600.0, 86400.0])
    p0 = _correlated_cov()
    r = ac.spectral_cross_covariance(leo_day, t1, t2, p0)
    phi1, phi2 = leo_day.stm(t1), leo_day.stm(t2)
    ref = ac.stm_cross_covariance(phi1, phi2, p0)
    a1 = np.abs(ac.state_spectra(leo_day, t1)[:, :, 1:]).sum(-1)
    a2 = np.abs(ac.state_spectra(leo_day, t2)[:, :, 1:]).sum(-1)
    scale = np.einsum("aij,jk,blk->abil", a1, np.abs(p0), a2)
    assert np.max(np.abs(r - ref) / scale) < 1e-13
    # R(t, t) is the covariance
    np.testing.assert_allclose(ac.spectral_cross_covariance(leo_day, t2, t2, p0)[[0, 1], [0, 1]],
                               ac.spectral_covariance(leo_day, t2, p0), rtol=1e-12, atol=1e-12)


def test_spectral_factors_give_the_cauchy_route(leo_day):
    """eq. 25 factorised, F(t1) F(t2)^T, equals the sum of the complete Cauchy products."""
    t = np.array([0.0, 999.0, 50000.0, 86400.0])
    p0 = _correlated_cov()
    f = ac.spectral_factors(leo_day, t, p0)
    r = np.einsum("aik,bjk->abij", f, f)
    ref = ac.spectral_cross_covariance(leo_day, t, t, p0)
    a = np.abs(ac.state_spectra(leo_day, t)[:, :, 1:]).sum(-1)
    scale = np.einsum("aij,jk,blk->abil", a, np.abs(p0), a)
    assert np.max(np.abs(r - ref) / scale) < 1e-13


def _cw_stm(t, n):
    """Clohessy-Wiltshire STM (x radial, y along-track, z cross-track; rotating-frame rates)."""
    c, s = np.cos(n * t), np.sin(n * t)
    phi = np.zeros(t.shape + (6, 6))
    phi[..., 0, :] = np.stack([4 - 3 * c, 0 * c, 0 * c, s / n, 2 * (1 - c) / n, 0 * c], -1)
    phi[..., 1, :] = np.stack([6 * (s - n * t), 1 + 0 * c, 0 * c, -2 * (1 - c) / n, (4 * s - 3 * n * t) / n, 0 * c], -1)
    phi[..., 2, :] = np.stack([0 * c, 0 * c, c, 0 * c, 0 * c, s / n], -1)
    phi[..., 3, :] = np.stack([3 * n * s, 0 * c, 0 * c, c, 2 * s, 0 * c], -1)
    phi[..., 4, :] = np.stack([6 * n * (c - 1), 0 * c, 0 * c, -2 * s, 4 * c - 3, 0 * c], -1)
    phi[..., 5, :] = np.stack([0 * c, 0 * c, -n * s, 0 * c, 0 * c, c], -1)
    return phi


def test_two_body_circular_rtn_covariance_matches_clohessy_wiltshire():
    """Independent reference for the nonlinear case: on a circular orbit the first-order
    two-body errors obey the Clohessy-Wiltshire equations; their RTN covariance (positions and
    rotating-frame rates) equals the spectral one to 1e-9 (the engine's STM, whose step is
    chosen from the state alone, is good to ~2e-10 relative after three periods at tol 1e-15;
    the small radial variance sees ~1e-9)."""
    v = math.sqrt(MU_EARTH / R_ORBIT)
    inc = math.radians(51.6)
    state = np.array([R_ORBIT, 0, 0, 0, v * math.cos(inc), v * math.sin(inc)])
    t = np.linspace(0.0, 3 * PERIOD, 61)
    prop = propagate(state, 0.0, t[-1], force="two-body", stm=True)
    p0 = _correlated_cov(7)
    nominal = prop.state(t)
    p_rtn = ac.to_rtn(ac.spectral_covariance(prop, t, p0), nominal[:, :3], nominal[:, 3:])
    j0 = ac.rtn_jacobian(state[:3], state[3:])
    # the rotating-frame rate by hand: d(rdot) = M dv - w x (M dr), w = n along cross-track
    m0 = ac.rtn_rotation(state[:3], state[3:])
    w = np.array([0.0, 0.0, N_MOTION])
    np.testing.assert_allclose(j0[3:, :3], -np.array([np.cross(w, m0[:, j]) for j in range(3)]).T, atol=1e-15)
    p0_rot = j0 @ p0 @ j0.T
    phi = _cw_stm(t, N_MOTION)
    p_cw = np.einsum("mij,jk,mlk->mil", phi, p0_rot, phi)
    diff = np.abs(p_rtn - p_cw)
    assert np.max(diff / np.sqrt(np.einsum("mii,mjj->mij", p_cw, p_cw))) < 5e-9
    pos = np.diagonal(p_cw, axis1=1, axis2=2)
    assert np.max(diff[:, :3, :3].max(axis=(1, 2)) / pos[:, :3].max(-1)) < 1e-9
    # the rates cancel M dv against w x M dr, each ~ n sigma_along: a few times more round-off
    assert np.max(diff[:, 3:, 3:].max(axis=(1, 2)) / pos[:, 3:].max(-1)) < 5e-9
    # along-track error grows secularly, radial and cross-track stay bounded; so do the rates
    sig = ac.sigmas(p_rtn)
    assert sig[-1, 1] > 10 * sig[-1, 0] and sig[-1, 1] > 10 * sig[-1, 2]
    assert sig[:, 3:].max() < 10 * sig[0, 3:].max()
    # inertial velocity errors on the same axes instead: the along-track drift turns into radial
    # velocity error n * sigma_along
    inertial = ac.sigmas(ac.to_rtn(ac.spectral_covariance(prop, t, p0), nominal[:, :3], nominal[:, 3:],
                                   rotating=False))
    assert inertial[-1, 3] > 0.5 * N_MOTION * sig[-1, 1]


def test_monte_carlo_agrees_with_linear_methods_within_bounds(leo_day):
    """2000 draws propagated in batch: the sample variances of every component (inertial and RTN)
    agree with the linear covariance within 4 sd = 4 sqrt(2/(N-1)) relative, over six hours
    (where the first order holds: the errors stay ~1e-4 of the orbit)."""
    n = 2000
    t = np.linspace(0.0, 6 * 3600.0, 13)
    p0 = _correlated_cov(sr=50.0, sv=0.05)
    x0 = ac.sample_initial_states(LEO, p0, n, seed=2026)
    batch = propagate(x0, 0.0, t[-1], force="j2")
    mean, p_mc = ac.sample_covariance(batch.state(t))
    p_lin = ac.stm_covariance(leo_day.stm(t), p0)
    rel = ac.monte_carlo_bounds(n)["variance_relative_sd"]
    ratio = np.diagonal(p_mc, axis1=1, axis2=2) / np.diagonal(p_lin, axis1=1, axis2=2)
    assert np.max(np.abs(ratio - 1)) < 4 * rel
    nominal = leo_day.state(t)
    rtn_mc = ac.to_rtn(p_mc, nominal[:, :3], nominal[:, 3:])
    rtn_lin = ac.to_rtn(p_lin, nominal[:, :3], nominal[:, 3:])
    ratio = np.diagonal(rtn_mc, axis1=1, axis2=2)[1:] / np.diagonal(rtn_lin, axis1=1, axis2=2)[1:]
    assert np.max(np.abs(ratio - 1)) < 4 * rel
    # off-diagonal elements within 4 sd of a sample covariance
    sd = ac.covariance_sd(p_lin, n)
    assert np.max(np.abs(p_mc - p_lin)[1:] / sd[1:]) < 4.5
    # the mean stays on the nominal orbit within its standard error
    assert np.max(np.abs(mean - nominal) / np.sqrt(np.diagonal(p_lin, axis1=1, axis2=2) / n)) < 4.5


# ----------------------------------------------------------------------------- small pieces

def test_normalizing_factor_semidefinite_and_errors():
    u = np.array([1.0, 2.0, 0.0])
    c = np.outer(u, u) + np.diag([0.0, 0.0, 4.0])        # rank 2
    lo = ac.normalizing_factor(c)
    np.testing.assert_allclose(lo @ lo.T, c, atol=1e-14)
    with pytest.raises(ValueError, match="not positive semi-definite"):
        ac.normalizing_factor(np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(ValueError, match="square"):
        ac.normalizing_factor(np.ones((2, 3)))


def test_range_range_rate_jacobian_against_finite_differences():
    r_st = np.array([4.0e6, 1.0e6, 4.7e6])
    v_st = np.array([-70.0, 290.0, 0.0])

    def f(x):
        d, dv = x[:3] - r_st, x[3:] - v_st
        rho = np.linalg.norm(d)
        return np.array([rho, d @ dv / rho])

    jac = ac.range_range_rate_jacobian(LEO[:3], LEO[3:], r_st, v_st)
    steps = np.array([1.0] * 3 + [1e-3] * 3)
    num = np.stack([(f(LEO + np.eye(6)[i] * steps[i]) - f(LEO - np.eye(6)[i] * steps[i])) / (2 * steps[i])
                    for i in range(6)], -1)
    np.testing.assert_allclose(jac, num, rtol=1e-7, atol=1e-12)


def test_rtn_rotation_is_orthonormal_and_radial():
    m = ac.rtn_rotation(LEO[:3], LEO[3:])
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(m @ LEO[:3], [np.linalg.norm(LEO[:3]), 0, 0], atol=1e-8)
    assert (m @ LEO[3:])[1] > 0 and abs((m @ LEO[3:])[2]) < 1e-9
