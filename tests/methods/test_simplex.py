"""methods/simplex.py against scipy itself (issue 19: the hot paths no longer import
scipy.optimize, and their results must not move by one bit): Nelder-Mead on random quadratics,
Rosenbrock functions and the REML noise-model objectives of methods/noise.py (white, AR(1) and
random-walk residuals; 1, 2 and 3 parameters), and brentq on random monotone and non-monotone
brackets, give the same floating-point numbers (compared as bytes) with the same number of
evaluations as scipy.optimize.minimize(method="Nelder-Mead") and scipy.optimize.brentq; edge
cases (budget spent during the first simplex or a shrink, a flat function, NaN and inf values,
errors) behave as scipy does."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize

from trackproc.methods import noise as nz
from trackproc.methods.simplex import brentq, nelder_mead
from trackproc.methods.smoothing import correlation


def _bits(x) -> bytes:
    return np.asarray(x, dtype=float).tobytes()


def _counted(fun):
    calls = []

    def wrapped(x, *args):
        calls.append(np.array(x, dtype=float, copy=True))
        return fun(x, *args)

    return wrapped, calls


def _assert_same_nm(fun, x0, xatol, fatol, maxfev):
    """Both minimisers from the same start: the same result, value, evaluation count and the
    same sequence of evaluated points."""
    f1, pts1 = _counted(fun)
    f2, pts2 = _counted(fun)
    x, f, nfev = nelder_mead(f1, x0, xatol=xatol, fatol=fatol, maxfev=maxfev)
    ref = optimize.minimize(f2, x0, method="Nelder-Mead", options={"xatol": xatol, "fatol": fatol, "maxfev": maxfev})
    assert nfev == ref.nfev == len(pts1) == len(pts2)
    assert _bits(np.stack(pts1)) == _bits(np.stack(pts2))
    assert _bits(x) == _bits(ref.x) and _bits(f) == _bits(ref.fun), (x, ref.x, f, ref.fun)
    return nfev


def test_random_quadratics_are_scipys_bits():
    rng = np.random.default_rng(19)
    budget_hits = 0
    for _ in range(60):
        n = int(rng.integers(1, 5))
        a = rng.normal(size=(n, n))
        h = a @ a.T + 0.1 * np.eye(n)
        c = rng.normal(scale=3.0, size=n)
        x0 = rng.normal(scale=2.0, size=n)
        x0[rng.random(n) < 0.3] = 0.0                              # zero coordinates: the 0.00025 step
        xatol, fatol = (0.05, 0.02) if rng.random() < 0.5 else (1e-4, 1e-4)
        maxfev = int(rng.choice([30 * n, 200 * n]))
        nfev = _assert_same_nm(lambda x, h=h, c=c: float((x - c) @ h @ (x - c)) + 1.5, x0, xatol, fatol, maxfev)
        budget_hits += nfev == maxfev
    assert budget_hits > 0                                           # some stopped on the budget, not the tolerance


def test_random_rosenbrock_functions_are_scipys_bits():
    rng = np.random.default_rng(1965)
    for _ in range(50):
        n = int(rng.integers(2, 4))
        b = float(rng.uniform(10.0, 100.0))
        x0 = rng.uniform(-2.0, 2.0, n)
        xatol, fatol = (0.05, 0.02) if rng.random() < 0.5 else (1e-6, 1e-8)

        def rosen(x, b=b):
            return float(np.sum(b * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))

        _assert_same_nm(rosen, x0, xatol, fatol, int(rng.choice([30 * n, 200 * n, 1000])))


def _residuals(kind: str, rng, n: int = 160):
    t = np.sort(rng.uniform(0.0, 500.0, n))
    x = np.column_stack([np.ones_like(t), t / t.max(), np.sin(t / 120.0)])
    white = float(rng.uniform(0.3, 1.0))
    true = {"white": nz.NoiseModel(white),
            "ar1": nz.NoiseModel(white, float(rng.uniform(0.5, 3.0)), float(rng.uniform(5.0, 100.0))),
            "walk": nz.NoiseModel(white, 0.0, 0.0, float(rng.uniform(0.02, 0.3)))}[kind]
    r = np.linalg.cholesky(true.covariance(t)) @ rng.normal(size=n) + x @ rng.normal(size=3) * 20.0
    return t, r, x


def test_reml_noise_searches_are_scipys_bits(monkeypatch):
    """Every simplex search fit_noise makes on simulated residuals (white, AR(1), walk; the walk
    estimated or given: 1, 2 and 3 parameters), repeated by both minimisers with _optimise's options."""
    problems = []

    def record(fun, start, bounds):
        problems.append((fun, np.asarray(start, float)))
        return original(fun, start, bounds)

    original = nz._optimise
    monkeypatch.setattr(nz, "_optimise", record)
    rng = np.random.default_rng(1971)
    for k in range(16):
        t, r, x = _residuals(("white", "ar1", "walk")[k % 3], rng)
        nz.fit_noise(t, r, x, walk=None if k % 2 == 0 else float(rng.uniform(0.01, 0.2)))
    dims = {len(z0) for _, z0 in problems}
    assert len(problems) >= 50 and dims == {1, 2, 3}, (len(problems), dims)
    for fun, z0 in problems:
        _assert_same_nm(fun, z0, 0.05, 0.02, 30 * len(z0))


def test_budget_spent_in_the_first_simplex_and_in_a_shrink():
    calls = {"n": 0}

    def ridge(x):                     # |x| kinks: contractions fail and the simplex shrinks
        calls["n"] += 1
        return float(np.sum(np.abs(x - 0.3)) + 0.01 * x[0])

    for maxfev in range(1, 40):       # every stopping point, including inside the first simplex
        _assert_same_nm(ridge, np.array([1.0, 0.0, -2.0]), 1e-8, 1e-8, maxfev)


def test_flat_function_and_int_start():
    _assert_same_nm(lambda x: 2.0, np.array([1.0, 2.0]), 0.05, 0.02, 400)
    _assert_same_nm(lambda x: 0.0, np.array([3, 0, -1]), 1e-4, 1e-4, 600)      # ints become floats
    _assert_same_nm(lambda x: np.array([[float(x[0] ** 2)]]), [0.7], 1e-4, 1e-4, 100)   # a 1x1 array value


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")   # NaN - NaN, in scipy too
def test_nan_and_inf_values_behave_as_in_scipy():
    rng = np.random.default_rng(7)
    for _ in range(20):
        x0 = rng.uniform(-1.0, 1.0, 2)
        _assert_same_nm(lambda x: float("nan") if x[0] > 0.5 else float(x @ x - x[0]), x0, 1e-4, 1e-4, 300)
        _assert_same_nm(lambda x: math.inf if x[1] < -0.2 else float((x - 0.1) @ (x - 0.1)), x0, 1e-4, 1e-4, 300)
    _assert_same_nm(lambda x: float("nan"), np.array([0.5, 1.0]), 0.05, 0.02, 60)          # NaN everywhere


def _brent_pair(f, a, b, **kw):
    f1, pts1 = _counted(f)
    f2, pts2 = _counted(f)
    root = brentq(f1, a, b, **kw)
    ref = optimize.brentq(f2, a, b, **kw)
    assert _bits(root) == _bits(ref) and type(root) is type(ref) is float, (root, ref)
    assert len(pts1) == len(pts2) and _bits(pts1) == _bits(pts2)


#: scipy's defaults, then those of the call sites: smoothing/correlation, refine/traverse, ballistic/encounter
TOLERANCES = [{}, {"xtol": 1e-6}, {"xtol": 1e-6, "rtol": 1e-15}, {"xtol": 1e-9, "rtol": 1e-14},
              {"xtol": 1e-12, "rtol": 1e-10}]


def test_brentq_on_random_monotone_brackets_is_scipys_bits():
    rng = np.random.default_rng(1973)
    for k in range(60):
        root, s, c = rng.uniform(-5.0, 5.0), rng.uniform(0.1, 10.0), rng.uniform(0.0, 3.0)
        f = [lambda x: s * (x - root) + c * (x - root) ** 3,
             lambda x: math.tanh(s * (x - root)) + 1e-3 * (x - root),
             lambda x: math.exp(s * (x - root) / 5.0) - 1.0][k % 3]
        a, b = root - rng.uniform(0.01, 8.0), root + rng.uniform(0.01, 8.0)
        if k % 2:
            a, b = b, a                                          # a reversed bracket
        _brent_pair(f, a, b, **TOLERANCES[k % len(TOLERANCES)])


def test_brentq_on_random_non_monotone_brackets_is_scipys_bits():
    rng = np.random.default_rng(2012)
    found = 0
    while found < 60:
        w, p, c = rng.uniform(0.5, 6.0), rng.uniform(0.0, 6.3), rng.uniform(-0.9, 0.9)
        a, b = sorted(rng.uniform(-4.0, 4.0, 2))

        def f(x, w=w, p=p, c=c):
            return math.sin(w * x + p) + c + 0.05 * x * x * math.cos(3.0 * x)

        if f(a) * f(b) >= 0:
            continue
        _brent_pair(f, a, b, **TOLERANCES[found % len(TOLERANCES)])
        found += 1


def test_brentq_edge_cases_as_in_scipy():
    _brent_pair(lambda x: x - 1.0, 1.0, 3.0)                   # root at a
    _brent_pair(lambda x: x - 3.0, 1.0, 3.0)                   # root at b
    _brent_pair(lambda x: np.float64(x) ** 3 - 2.0, 0, 2)      # int ends, numpy values
    _brent_pair(lambda x: -math.inf if x < 0.3 else x - 0.5, 0.0, 1.0)   # an infinite end
    # tiny values: the extrapolation's denominator underflows to zero (C: an infinite step, bisection)
    _brent_pair(lambda x: 1e-300 * ((x - 0.5) + 4.0 * (x - 0.5) ** 3), 0.0, 2.0)
    _brent_pair(lambda x: 1e-170 * ((x - 0.5) + 4.0 * (x - 0.5) ** 3), 2.0, 0.0)
    _brent_pair(lambda x: -0.0 if x == 1.0 else x - 0.25, 1.0, 0.0)         # a signed zero at a
    for f, a, b, kw, exc, text in [
            (lambda x: x * x + 1.0, -1.0, 1.0, {}, ValueError, "different signs"),
            (lambda x: 1e-300 * (x + 10.0), 0.0, 1.0, {}, ValueError, "different signs"),   # f(a) f(b) underflows
            (lambda x: float("nan") if x > 0.2 else x - 0.5, 0.0, 1.0, {}, ValueError, "NaN"),
            (lambda x: math.atan(x - 0.123456789), -50.0, 70.0, {"maxiter": 3}, RuntimeError, "converge"),
            (lambda x: x, -1.0, 1.0, {"xtol": 0.0}, ValueError, "xtol"),
            (lambda x: x, -1.0, 1.0, {"rtol": 1e-16}, ValueError, "rtol")]:
        with pytest.raises(exc, match=text):
            brentq(f, a, b, **kw)
        with pytest.raises(exc, match=text):
            optimize.brentq(f, a, b, **kw)


def test_ar1_moment_estimate_is_unchanged(monkeypatch):
    """The AR(1) moment equation of methods/smoothing/correlation.py solved by scipy's brentq
    gives the same noise model as by ours, on simulated correlated passes."""
    rng = np.random.default_rng(42)
    solved = 0
    for _ in range(12):
        n = 200
        t = np.sort(rng.uniform(0.0, 400.0, n))
        rho = rng.uniform(0.2, 0.9)
        e = np.empty(n)
        e[0] = rng.normal()
        for i in range(1, n):
            e[i] = rho * e[i - 1] + math.sqrt(1 - rho * rho) * rng.normal()
        y = 3.0 + 0.01 * t + 0.5 * e
        mine = correlation.estimate_noise(t, y, np.full(n, 0.5), 2)
        with monkeypatch.context() as m:
            m.setattr(correlation, "brentq", optimize.brentq)
            ref = correlation.estimate_noise(t, y, np.full(n, 0.5), 2)
        assert mine == ref
        solved += 0.0 < ref.rho_estimate < 0.99
    assert solved >= 6
