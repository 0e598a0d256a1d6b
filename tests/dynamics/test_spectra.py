"""Spectrum algebra (DT rules) against the Taylor coefficients of known functions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackproc.dynamics import spectra as sp

N = 25
RTOL = 1e-14


def binom_series(a: float, n: int = N, c: float = 1.0) -> np.ndarray:
    """Taylor coefficients of (c + t)^a = c^a sum binom(a, k) (t/c)^k (exact recurrence)."""
    out = np.empty(n)
    out[0] = c ** a
    for k in range(1, n):
        out[k] = out[k - 1] * (a - k + 1) / (k * c)
    return out


def exp_series(a: float = 0.0, b: float = 1.0, n: int = N) -> np.ndarray:
    """exp(a + b t): e^a b^k / k!."""
    return np.array([math.exp(a) * b ** k / math.factorial(k) for k in range(n)])


def sin_series(a: float, b: float, n: int = N) -> np.ndarray:
    """sin(a + b t): sin(a + k pi/2) b^k / k! (the cycle sin, cos, -sin, -cos, exactly)."""
    cyc = (math.sin(a), math.cos(a), -math.sin(a), -math.cos(a))
    return np.array([cyc[k % 4] * b ** k / math.factorial(k) for k in range(n)])


def cos_series(a: float, b: float, n: int = N) -> np.ndarray:
    cyc = (math.cos(a), -math.sin(a), -math.cos(a), math.sin(a))
    return np.array([cyc[k % 4] * b ** k / math.factorial(k) for k in range(n)])


def poly(*coefs, n: int = N) -> np.ndarray:
    out = np.zeros(n)
    out[:len(coefs)] = coefs
    return out


def close(a, b, rtol=RTOL):
    np.testing.assert_allclose(a, b, rtol=rtol, atol=0)


# -- Taylor unit, constants ---------------------------------------------------------------

def test_taylor_unit_and_constant():
    close(sp.taylor_unit(0, 4), [1, 0, 0, 0])
    close(sp.taylor_unit(2, 4), [0, 0, 1, 0])
    c = sp.constant([2.0, 3.0], 3)
    assert c.shape == (2, 3)
    close(c, [[2, 0, 0], [3, 0, 0]])
    with pytest.raises(ValueError):
        sp.taylor_unit(4, 4)


# -- products -----------------------------------------------------------------------------

def test_cauchy_product_of_polynomials_matches_polymul():
    rng = np.random.default_rng(3)
    u, v = rng.normal(size=7), rng.normal(size=7)
    full = np.polynomial.polynomial.polymul(u, v)
    close(sp.cauchy(poly(*u), poly(*v)), poly(*full), rtol=1e-13)
    # the K-th form agrees with the full product
    w = sp.cauchy(poly(*u), poly(*v))
    for k in range(N):
        assert sp.cauchy_k(poly(*u), poly(*v), k) == pytest.approx(w[k], rel=1e-15, abs=1e-15)


def test_cauchy_exp_times_exp_is_exp_of_sum():
    close(sp.cauchy(exp_series(0.3, 1.2), exp_series(-0.1, 0.5)), exp_series(0.2, 1.7))


def test_cauchy_truncates_to_shorter_operand():
    assert sp.cauchy(np.ones(5), np.ones(3)).shape == (3,)


def test_quotient_one_over_one_plus_t():
    close(sp.quotient(sp.constant(1.0, N), poly(1, 1)), [(-1.0) ** k for k in range(N)])


def test_quotient_inverts_product():
    u = exp_series(0.2, -0.7)
    v = poly(2.0, 3.0, 1.0)                          # (1+t)(2+t)
    # a round trip: absolute error at the level of the largest coefficient's rounding
    np.testing.assert_allclose(sp.quotient(sp.cauchy(u, v), v), u, rtol=0,
                               atol=1e-15 * np.abs(u).max())
    with pytest.raises(ValueError):
        sp.quotient(u, poly(0.0, 1.0))


# -- powers, square root ------------------------------------------------------------------

@pytest.mark.parametrize("a", [-1.5, -2.5, -3.5, -1.0, 0.5, 1.0 / 3.0, 2.7])
def test_power_of_one_plus_t(a):
    close(sp.power(poly(1.0, 1.0), a), binom_series(a))


@pytest.mark.parametrize("a", [-1.5, -2.5, 0.5])
def test_power_of_quadratic(a):
    # (1+t)(2+t) = 2 + 3t + t^2: u^a = (1+t)^a * (2+t)^a
    ref = sp.cauchy(binom_series(a), binom_series(a, c=2.0))
    close(sp.power(poly(2.0, 3.0, 1.0), a), ref, rtol=1e-13)


def test_power_integer_exponents_agree_with_products():
    u = poly(0.7, -1.1, 0.4, 2.0)
    uu = sp.cauchy(u, u)
    np.testing.assert_allclose(sp.power(u, 2), uu, rtol=0, atol=1e-14 * np.abs(uu).max())
    close(sp.power(u, -1), sp.quotient(sp.constant(1.0, N), u), rtol=1e-13)
    # U(0) = 0 with a non-negative integer exponent: repeated products
    t = poly(0.0, 1.0)
    close(sp.power(t, 3), poly(0, 0, 0, 1))


def test_power_rejects_bad_base():
    with pytest.raises(ValueError):
        sp.power(poly(-1.0, 1.0), -1.5)
    with pytest.raises(ValueError):
        sp.power(poly(0.0, 1.0), -2)


def test_power_k_matches_full_power():
    u = poly(2.0, 3.0, 1.0)
    w = sp.power(u, -1.5)
    for k in range(1, N):
        assert sp.power_k(w, u, -1.5, k) == pytest.approx(w[k], rel=1e-15)


def test_sqrt_seed004_eq12_of_one_plus_t():
    close(sp.sqrt(poly(1.0, 1.0)), binom_series(0.5))


def test_sqrt_of_quadratic_and_square():
    d2 = poly(2.0, 3.0, 1.0)
    d = sp.sqrt(d2)
    close(d, sp.cauchy(binom_series(0.5), binom_series(0.5, c=2.0)), rtol=1e-13)
    np.testing.assert_allclose(sp.cauchy(d, d), d2, rtol=0, atol=1e-14)
    with pytest.raises(ValueError):
        sp.sqrt(poly(0.0, 1.0))


# -- sin, cos, exp ------------------------------------------------------------------------

@pytest.mark.parametrize("a,b", [(0.3, 1.0), (1.2, -0.7), (-2.0, 3.0)])
def test_sin_cos_seed004_eq9_linear_angle(a, b):
    s, c = sp.sin_cos(poly(a, b))
    close(s, sin_series(a, b))
    close(c, cos_series(a, b))


def test_sin_cos_of_quadratic_angle():
    a, b, c2 = 0.4, 1.3, 0.6
    s, c = sp.sin_cos(poly(a, b, c2))
    # sin(x + y) with x = a + b t, y = c2 t^2
    # cos y = sum (-1)^m y^(2m)/(2m)!, sin y = sum (-1)^m y^(2m+1)/(2m+1)!, y^j at t^(2j)
    sy, cy = np.zeros(N), np.zeros(N)
    for j in range((N + 1) // 2):
        term = (-1) ** (j // 2) * c2 ** j / math.factorial(j)
        (cy if j % 2 == 0 else sy)[2 * j] = term
    ref_s = sp.cauchy(sin_series(a, b), cy) + sp.cauchy(cos_series(a, b), sy)
    ref_c = sp.cauchy(cos_series(a, b), cy) - sp.cauchy(sin_series(a, b), sy)
    np.testing.assert_allclose(s, ref_s, rtol=1e-13, atol=1e-15 * np.abs(ref_s).max())
    np.testing.assert_allclose(c, ref_c, rtol=1e-13, atol=1e-15 * np.abs(ref_c).max())
    np.testing.assert_allclose(sp.cauchy(s, s) + sp.cauchy(c, c), sp.constant(1.0, N),
                               rtol=0, atol=1e-14)


@pytest.mark.parametrize("a,b", [(0.0, 1.0), (0.5, -2.0)])
def test_exp_of_linear(a, b):
    close(sp.exp(poly(a, b)), exp_series(a, b))


def test_exp_of_quadratic_is_product():
    # exp(t + t^2) = exp(t) exp(t^2)
    e2 = np.zeros(N)
    for j in range(0, N, 2):
        e2[j] = 1.0 / math.factorial(j // 2)
    close(sp.exp(poly(0.0, 1.0, 1.0)), sp.cauchy(exp_series(), e2), rtol=1e-13)


# -- derivative, integral, P-model --------------------------------------------------------

def test_derivative_rule_of_exp_and_sin():
    close(sp.derivative(exp_series(0.1, 2.0)), (2.0 * exp_series(0.1, 2.0))[:-1])
    close(sp.derivative(sin_series(0.3, 1.5)), (1.5 * cos_series(0.3, 1.5))[:-1])


def test_integral_seed000_eq14_inverts_derivative():
    u = exp_series(0.3, -1.1)
    close(sp.integral(sp.derivative(u), u[0]), u)
    assert sp.integral(u).shape == (N + 1,)


def test_p_model_seed000_eq14_solves_linear_ode():
    # z' = -z, z(0) = 2  ->  Z(K+1) = F(K)/(K+1), F = -Z
    z = np.zeros(N)
    z[0] = 2.0
    for k in range(N - 1):
        z[k + 1] = -z[k] / (k + 1)
    close(z, 2.0 * exp_series(0.0, -1.0))


# -- scale H, evaluation ------------------------------------------------------------------

def test_rescale_and_evaluate_with_h():
    z = exp_series(0.2, 0.9)
    h = 2.5
    zh = sp.rescale(z, h)
    close(zh, z * h ** np.arange(N))
    tau = np.array([0.0, 0.1, -0.3])
    close(sp.evaluate(zh, tau), sp.evaluate(z, h * tau))
    close(sp.evaluate(zh, h * tau, h=h), sp.evaluate(z, h * tau))
    close(sp.rescale(zh, 1.0 / h), z, rtol=1e-14)


def test_evaluate_horner_and_derivatives():
    z = exp_series(0.2, 0.9)
    dt = np.linspace(-0.5, 0.5, 11)
    close(sp.evaluate(z, dt), np.exp(0.2 + 0.9 * dt))
    close(sp.evaluate(z, dt, derivative=1), 0.9 * np.exp(0.2 + 0.9 * dt))
    close(sp.evaluate(z, dt, derivative=2), 0.81 * np.exp(0.2 + 0.9 * dt))
    # Vandermonde (dense output of many series is one matrix product)
    for m in range(3):
        close(sp.vandermonde(dt, N, derivative=m) @ z, sp.evaluate(z, dt, derivative=m))
    close(sp.vandermonde(dt, N, h=2.0) @ sp.rescale(z, 2.0), sp.evaluate(z, dt))


def test_from_derivatives_is_direct_transform():
    # derivatives of sin at 0.3: sin, cos, -sin, -cos ...
    cyc = (math.sin(0.3), math.cos(0.3), -math.sin(0.3), -math.cos(0.3))
    d = np.array([cyc[k % 4] for k in range(N)])
    close(sp.from_derivatives(d), sin_series(0.3, 1.0))


# -- batch axes ---------------------------------------------------------------------------

def test_batch_axes_match_one_by_one():
    rng = np.random.default_rng(7)
    u = np.zeros((2, 3, N))
    u[..., 0] = 1.0 + rng.random((2, 3))
    u[..., 1:4] = rng.normal(size=(2, 3, 3))
    v = np.zeros((3, N))
    v[:, 0] = 2.0
    v[:, 1:3] = rng.normal(size=(3, 2))
    checks = {
        "cauchy": (sp.cauchy(u, v), lambda i, j: sp.cauchy(u[i, j], v[j])),
        "quotient": (sp.quotient(u, v), lambda i, j: sp.quotient(u[i, j], v[j])),
        "power": (sp.power(u, -1.5), lambda i, j: sp.power(u[i, j], -1.5)),
        "sqrt": (sp.sqrt(u), lambda i, j: sp.sqrt(u[i, j])),
        "exp": (sp.exp(u), lambda i, j: sp.exp(u[i, j])),
        "sin": (sp.sin_cos(u)[0], lambda i, j: sp.sin_cos(u[i, j])[0]),
        "deriv": (sp.derivative(u), lambda i, j: sp.derivative(u[i, j])),
        "integral": (sp.integral(u), lambda i, j: sp.integral(u[i, j])),
    }
    for name, (batch, one) in checks.items():
        assert batch.shape[:2] == (2, 3), name
        for i in range(2):
            for j in range(3):
                np.testing.assert_allclose(batch[i, j], one(i, j), rtol=1e-15, atol=0,
                                           err_msg=name)
    ev = sp.evaluate(u, np.array([0.1, 0.2, 0.3, 0.4]))
    assert ev.shape == (2, 3, 4)
    np.testing.assert_allclose(ev[1, 2], sp.evaluate(u[1, 2], [0.1, 0.2, 0.3, 0.4]), rtol=1e-15)


def test_rejects_scalar_spectrum():
    with pytest.raises(ValueError):
        sp.exp(1.0)


def test_series_sqrt_compiled_recurrence_is_the_numpy_one_bit_for_bit(monkeypatch):
    """The compiled orders of the measurement spectra's square root (seed 004 eq. 12) sum the same
    products in the same order as the numpy path's einsum: equal bit for bit, over random spectra
    of 1-4 segments, 1-32 orders and magnitudes 1e-3..1e13, in C and Fortran order; and the
    square of the result is the input (an independent check of the recurrence)."""
    pytest.importorskip("numba")
    from trackproc.dynamics.measurement_spectra import series as se

    rng = np.random.default_rng(11)
    for trial in range(300):
        s, n = int(rng.integers(1, 5)), int(rng.integers(1, 33))
        d2 = rng.standard_normal((s, n)) * 10.0 ** rng.uniform(-3, 13, (s, n))
        d2[:, 0] = np.abs(d2[:, 0]) + 1.0
        if trial % 2:
            d2 = np.asfortranarray(d2)
        monkeypatch.setattr(se, "_compiled", lambda: True)
        compiled = se.series_sqrt(d2)
        monkeypatch.setattr(se, "_compiled", lambda: False)
        plain = se.series_sqrt(d2)
        assert np.array_equal(compiled, plain) and compiled.flags.c_contiguous == plain.flags.c_contiguous
    d = se.series_sqrt(np.array([[4.0, 4.0, 1.0, 0.0, 0.0]]))     # (2 + t)^2 = 4 + 4t + t^2
    assert np.array_equal(d, [[2.0, 1.0, 0.0, 0.0, 0.0]])
