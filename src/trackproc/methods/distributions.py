"""Normal and chi-square quantiles and tails without ``scipy.special``: closed forms and short iterations.

``import scipy.special`` costs tens of milliseconds of CPU in every process (its ufunc tables and
docstrings load at import), and a single ``refine`` needs only three values from it: a chi-square
survival with two degrees of freedom, normal quantiles and chi-square quantiles. They have closed
forms or short converging iterations; ``tests/methods/test_distributions.py`` checks them against
scipy's ``chdtrc``, ``gammaincc``, ``ndtri`` and ``gammaincinv``.
"""

from __future__ import annotations

import math
from statistics import NormalDist

_STANDARD = NormalDist()


def normal_quantile(p: float) -> float:
    """``x`` with ``P(Z <= x) = p`` for a standard normal ``Z`` (scipy's ``ndtri``), 0 < p < 1.

    Wichura (1988), "Algorithm AS 241: the percentage points of the normal distribution", Applied
    Statistics 37(3), 477-484, PPND16 (relative error ~1e-16): the standard library's
    ``NormalDist.inv_cdf``."""
    return _STANDARD.inv_cdf(float(p))


def chi2_survival_2(x: float) -> float:
    """``P(X > x)`` for ``X`` chi-square with 2 degrees of freedom: ``exp(-x / 2)`` (x >= 0; 1 below).

    Abramowitz & Stegun (1964) 26.4.5 with ν = 2 (scipy's ``chdtrc(2, x)``)."""
    return math.exp(-0.5 * x) if x > 0.0 else 1.0


def _log_front(a: float, y: float) -> float:
    """``a ln y - y - ln Γ(a)``, the logarithm of the incomplete gamma functions' common factor,
    without the cancellation of its large terms when ``a`` is large (Loader 2000, "Fast and
    accurate computation of binomial probabilities": a (ln(1+t) - t) with t = (y - a)/a, plus
    ½ ln(a / 2π) minus Stirling's remainder, A&S 6.1.41)."""
    t = (y - a) / a
    if a < 10.0 or t < -0.9:
        return a * math.log(y) - y - math.lgamma(a)
    if abs(t) < 0.3:                                     # ln(1+t) - t by its series
        term, k, log1pmx = t, 1, 0.0
        while True:
            k += 1
            term *= -t
            add = term / k
            log1pmx += add
            if abs(add) <= 1e-17 * abs(log1pmx):
                break
    else:
        log1pmx = math.log1p(t) - t
    inv, inv2 = 1.0 / a, 1.0 / (a * a)
    stirling = inv * (1 / 12 - inv2 * (1 / 360 - inv2 * (1 / 1260 - inv2 * (1 / 1680 - inv2 * (1 / 1188
                                                                              - inv2 * 691 / 360360)))))
    return a * log1pmx + 0.5 * math.log(a / (2.0 * math.pi)) - stirling


def _chi2_tails(nu: int, x: float) -> tuple[float, float]:
    """(P, Q): lower and upper tail of the chi-square distribution with ``nu`` degrees of freedom
    at ``x`` > 0, each computed where it does not cancel: P(a, y) and Q(a, y), the regularised
    incomplete gamma functions with a = ν/2, y = x/2 (A&S 26.4.19).

    Below y = a + 1 the series A&S 6.5.29, P = y^a e^-y / Γ(a+1) Σ_n y^n / ((a+1)...(a+n));
    above it the continued fraction A&S 6.5.31 for Q = y^a e^-y / Γ(a) · 1/(y+1-a- 1·(1-a)/(y+3-a-
    ...)), evaluated by the modified Lentz method (Press et al., Numerical Recipes 3rd ed., 6.2.7)."""
    a, y = 0.5 * nu, 0.5 * x
    front = _log_front(a, y)
    if y < a + 1.0:
        term = total = 1.0
        n = 0
        while term > 1e-17 * total:
            n += 1
            term *= y / (a + n)
            total += term
        p = math.exp(front - math.log(a)) * total
        return p, 1.0 - p
    tiny = 1e-300
    b = y + 1.0 - a
    c, d = 1.0 / tiny, 1.0 / b
    h = d
    for i in range(1, 1000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) <= 1e-16:
            break
    q = math.exp(front) * h
    return 1.0 - q, q


def chi2_survival(x: float, nu: int) -> float:
    """``P(X > x)`` for ``X`` chi-square with ``nu`` (>= 1) degrees of freedom (scipy's
    ``gammaincc(nu / 2, x / 2)``); 1 for x <= 0."""
    return _chi2_tails(max(int(nu), 1), float(x))[1] if x > 0.0 else 1.0


def chi2_quantile(nu: int, p: float) -> float:
    """``x`` with ``P(X <= x) = p`` for ``X`` chi-square with ``nu`` (>= 1) degrees of
    freedom, 0 < p < 1 (scipy's ``2 * gammaincinv(nu / 2, p)``).

    Wilson & Hilferty (1931) for the start, then Newton's method on the logarithm of the tail
    that is smaller (the lower tail below the median, the upper one above it), whose slope is
    the density f(x) = x^{ν/2-1} e^{-x/2} / (2^{ν/2} Γ(ν/2)) over that tail; :func:`_chi2_tails`
    gives the tails."""
    nu = int(nu)
    if nu < 1 or not 0.0 < p < 1.0:
        raise ValueError(f"chi2_quantile needs nu >= 1 and 0 < p < 1, got nu={nu}, p={p}")
    upper = p > 0.5
    target = math.log1p(-p) if upper else math.log(p)
    h = 2.0 / (9.0 * nu)
    x = nu * max(1.0 - h + normal_quantile(p) * math.sqrt(h), 0.05) ** 3
    log_norm = 0.5 * nu * math.log(2.0) + math.lgamma(0.5 * nu)
    for _ in range(100):
        lower_tail, upper_tail = _chi2_tails(nu, x)
        tail = upper_tail if upper else lower_tail
        if tail <= 0.0:                                   # far out: back towards the median
            x = 0.5 * x if not upper else 2.0 * x
            continue
        density = math.exp((0.5 * nu - 1.0) * math.log(x) - 0.5 * x - log_norm)
        step = (math.log(tail) - target) * tail / density
        step = -step if upper else step                   # d log Q / dx = -f / Q, d log P / dx = f / P
        new = x - step
        if new <= 0.0:
            new = 0.5 * x
        if abs(new - x) <= 1e-15 * x:
            return new
        x = new
    return x
