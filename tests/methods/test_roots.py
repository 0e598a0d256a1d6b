"""methods/roots.py against scipy itself (the hot paths do not import scipy.optimize, and their
results must not move by one bit): brentq on random monotone and non-monotone brackets gives the
same floating-point numbers (compared as bytes) with the same number of evaluations as
scipy.optimize.brentq; edge cases (NaN and infinite values, errors) behave as scipy does."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize

from trackproc.methods.roots import brentq
from trackproc.methods.smoothing import correlation


def _bits(x) -> bytes:
    return np.asarray(x, dtype=float).tobytes()


def _counted(fun):
    calls = []

    def wrapped(x, *args):
        calls.append(np.array(x, dtype=float, copy=True))
        return fun(x, *args)

    return wrapped, calls


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
