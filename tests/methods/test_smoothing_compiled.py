"""The smoothing's compiled kernels (methods/smoothing/compiled.py, used under ``TRACKPROC_JIT=1``):
the AR(1) product ``C x`` of ``ou_apply`` against LAPACK's ``dpttrs`` path bit for bit and against
``C`` built entry by entry (an independent reference), the noise estimate it serves equal on both
paths; the derivative rows of ``design_matrix`` against numpy's ``chebder`` bit for bit and against
derivatives by central differences of the Chebyshev polynomials."""

import numpy as np
import pytest

pytest.importorskip("numba")

from trackproc.dynamics import jit  # noqa: E402
from trackproc.methods.smoothing import fit as fitmod  # noqa: E402
from trackproc.methods.smoothing.correlation import estimate_noise  # noqa: E402


def _dense(a):
    """``C_ij = prod a_k`` over the steps between i and j."""
    logs = np.concatenate([[0.0], np.cumsum(np.log(a))])
    return np.exp(-np.abs(logs[:, None] - logs[None, :]))


def _lapack_path(a, x):
    d = np.empty(a.size + 1)
    d[0] = 1.0
    d[1:] = 1.0 / (1.0 - a * a)
    out, info = fitmod._lapack("dpttrs")(d[::-1], -a[::-1], x[::-1])
    assert info == 0
    return out[::-1]


@pytest.mark.parametrize("n, p", [(2, 1), (3, 4), (57, 9), (600, 31)])
def test_compiled_product_equals_dpttrs_bitwise_and_the_dense_matrix(n, p):
    rng = np.random.default_rng(n * 100 + p)
    with jit.default("1"):
        assert fitmod._compiled() is not None
        for rho in (0.05, 0.5, 0.9, 0.99):
            gaps = rng.choice([1.0, 1.0, 1.0, 2.0, 7.5], size=n - 1)
            a = np.minimum(rho ** gaps, fitmod.MAX_RHO)
            x = rng.normal(size=(n, p)) * 10.0 ** rng.integers(-3, 4)
            got = fitmod.ou_apply(a, x)
            assert got.flags.c_contiguous
            assert got.tobytes() == np.ascontiguousarray(_lapack_path(a, x)).tobytes()
            np.testing.assert_allclose(got, _dense(a) @ x, rtol=1e-10, atol=1e-12 * np.abs(x).max())


def test_noise_estimate_equal_on_both_paths():
    """estimate_noise's rho (brentq on the moment ratio) the same float with the kernel and with
    dpttrs, on correlated residuals where the search runs."""
    rng = np.random.default_rng(11)
    t = np.arange(400.0)
    e = np.empty(t.size)
    e[0] = rng.normal()
    for i in range(1, t.size):
        e[i] = 0.6 * e[i - 1] + np.sqrt(1 - 0.36) * rng.normal()
    y = 50.0 * np.sin(t / 90.0) + e
    s = np.ones(t.size)
    with jit.default("0"):
        want = estimate_noise(t, y, s, 8)
    with jit.default("1"):
        got = estimate_noise(t, y, s, 8)
    assert 0.3 < want.rho_estimate < 0.9
    assert got.rho_estimate.hex() == want.rho_estimate.hex()
    assert got == want


@pytest.mark.parametrize("degree", [1, 2, 3, 9, 30])
def test_compiled_derivative_rows_equal_numpy_bitwise(degree):
    rng = np.random.default_rng(degree)
    x = rng.uniform(-50.0, 700.0, 7)
    for deriv in range(1, min(degree, 3) + 1):
        for domain in ((0.0, 640.0), (-3.25, 811.5), (1e5, 1e5 + 37.0)):
            with jit.default("0"):
                want = fitmod.design_matrix(x, degree, domain, "chebyshev", deriv)
            with jit.default("1"):
                got = fitmod.design_matrix(x, degree, domain, "chebyshev", deriv)
            assert got.tobytes() == want.tobytes()
            rows = np.polynomial.chebyshev.chebder(np.eye(degree + 1), deriv, 2.0 / (domain[1] - domain[0]), axis=0)
            with jit.default("1"):
                assert fitmod._compiled().cheb_der_rows(np.eye(degree + 1), deriv,
                                                        2.0 / (domain[1] - domain[0])).tobytes() == rows.tobytes()


def test_compiled_derivative_rows_against_differences():
    """The first derivative rows against central differences of the degree-9 basis (independent)."""
    domain = (0.0, 600.0)
    t = np.array([12.0, 300.0, 587.5])
    h = 1e-3
    with jit.default("1"):
        got = fitmod.design_matrix(t, 9, domain, "chebyshev", 1)
    diff = (fitmod.design_matrix(t + h, 9, domain) - fitmod.design_matrix(t - h, 9, domain)) / (2 * h)
    np.testing.assert_allclose(got, diff, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("kind, mode", [("doppler", "one-way"), ("doppler", "two-way"), ("range_rate", "one-way"),
                                        ("range", "one-way")])
def test_compiled_tca_polish_equals_the_python_floats_bitwise(kind, mode):
    """tca._cheb_tca with the compiled polish and evaluations against its Python-float path (itself
    equal to numpy's series path: test_smoothing_scalar_series.py) on fits and random series of
    degrees 2-33: the same t*, the same value there, to the bit, and the same failures."""
    from trackproc.methods.smoothing.fit import SmoothingError, fit_polynomial
    from trackproc.methods.smoothing.tca import _cheb_tca

    rng = np.random.default_rng(17)
    t = np.linspace(0.0, 640.0, 321)
    shape = {"doppler": -4e4 * np.tanh((t - 300.0) / 80.0), "range_rate": 6e3 * np.tanh((t - 330.0) / 90.0),
             "range": 1e6 + 2e3 * (t - 310.0) ** 2}[kind]
    base = fit_polynomial(t, shape, np.ones(t.size), 22).series(0)
    outcomes = set()
    for d in range(4, 34):
        for trial in range(3):
            coef = rng.normal(size=d + 1) * 10.0 ** rng.integers(-2, 3) if trial == 2 else \
                fit_polynomial(t, shape + rng.normal(0.0, 1.0 + 50 * trial, t.size), np.ones(t.size), d).coef
            results = []
            for jit_mode in ("0", "1"):
                with jit.default(jit_mode):
                    try:
                        got = _cheb_tca(coef, base, (0.0, 640.0), kind, mode)
                        results.append(tuple(float(v).hex() for v in got))
                    except SmoothingError:
                        results.append("none")
            assert results[0] == results[1]
            outcomes.add(results[0] == "none")
    assert False in outcomes


@pytest.mark.parametrize("n", [2, 3, 4, 7, 21, 31])
def test_compiled_series_derivative_equals_chebder1_bitwise(n):
    """cheb_der_rows on one column (the TCA spread's derivative series) against fit._chebder1."""
    rng = np.random.default_rng(300 + n)
    with jit.default("1"):
        kernels = fitmod._compiled()
    for _ in range(50):
        coef = rng.normal(size=n) * 10.0 ** rng.integers(-6, 7)
        scl = float(rng.uniform(1e-4, 2.0))
        got = kernels.cheb_der_rows(coef.reshape(-1, 1), 1, scl).reshape(-1)
        assert got.tobytes() == fitmod._chebder1(coef, scl).tobytes()
