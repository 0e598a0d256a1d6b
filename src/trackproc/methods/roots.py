"""Brent's root finder written out so that the hot paths do not import ``scipy.optimize``.

``import scipy.optimize`` costs tens of milliseconds of CPU in every process (it pulls in sparse
linear algebra, FFTs, rotations, linear programming ...) for the one routine ``refine`` and
``smooth`` use from it: :func:`brentq`, Brent's (1973) root finder ("zeroin": inverse quadratic
interpolation, secant steps and bisection), for the AR(1) moment equation and the traverse station.

It follows scipy 1.17 as it writes it, operation for operation (the C ``brentq`` of
``scipy/optimize/Zeros/brentq.c``), so the iterates, the number of evaluations and the returned
root are the same floating-point numbers; tests/methods/test_roots.py compares them with scipy's
(which stays a dependency) on random problems with ``==``.
"""

from __future__ import annotations

import math

import numpy as np

#: scipy's smallest accepted relative tolerance of a root (4 ε).
BRENT_RTOL = 4 * float(np.finfo(float).eps)


def brentq(f, a: float, b: float, *, xtol: float = 2e-12, rtol: float = BRENT_RTOL, maxiter: int = 100) -> float:
    """A root of ``f`` in ``[a, b]`` (``f(a)``, ``f(b)`` of opposite signs or zero), to
    ``xtol + rtol |x|``.

    Implements Brent (1973), "Algorithms for minimization without derivatives", ch. 4 (zeroin),
    as scipy 1.17 writes it (``scipy.optimize.brentq``, C ``Zeros/brentq.c``; same iterates):
    inverse quadratic extrapolation, or the secant after the bracket flips, when it is short
    enough, bisection otherwise, and a step of at least half the tolerance. Raises ValueError for
    a NaN value, a bracket without a sign change or bad tolerances, RuntimeError after ``maxiter``
    iterations without convergence (scipy's messages).
    """
    maxiter = int(maxiter)
    if xtol <= 0:
        raise ValueError(f"xtol too small ({xtol:g} <= 0)")
    if rtol < BRENT_RTOL:
        raise ValueError(f"rtol too small ({rtol:g} < {BRENT_RTOL:g})")
    if maxiter < 0:
        raise ValueError("maxiter should be > 0")

    def call(x: float) -> float:
        fx = f(x)
        if np.isnan(fx):
            raise ValueError(f"The function value at x={x} is NaN; solver cannot continue.")
        return float(fx)

    xpre, xcur = float(a), float(b)
    xblk = fblk = spre = scur = 0.0
    fpre = call(xpre)
    fcur = call(xcur)
    if fpre == 0:
        return xpre
    if fcur == 0:
        return xcur
    if _negative(fpre) == _negative(fcur):  # sign bits, not a product that could underflow to zero
        raise ValueError("f(a) and f(b) must have different signs")
    for _ in range(maxiter):
        if fpre != 0 and fcur != 0 and _negative(fpre) != _negative(fcur):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):           # the best estimate in xcur
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            try:
                stry = _brent_step(xpre, xcur, xblk, fpre, fcur, fblk)
            except ZeroDivisionError:       # C divides by zero to ±inf or NaN: numpy's doubles do too
                with np.errstate(all="ignore"):
                    stry = float(_brent_step(*map(np.float64, (xpre, xcur, xblk, fpre, fcur, fblk))))
            limit = 3 * abs(sbis) - delta
            if 2 * abs(stry) < (abs(spre) if abs(spre) < limit else limit):   # C's MIN (NaN: the second)
                spre, scur = scur, stry     # good short step
            else:
                spre = scur = sbis
        else:
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = call(xcur)
    raise RuntimeError(f"Failed to converge after {maxiter} iterations.")


def _negative(x: float) -> bool:
    """C's ``signbit``."""
    return math.copysign(1.0, x) < 0


def _brent_step(xpre, xcur, xblk, fpre, fcur, fblk):
    """The interpolated step of :func:`brentq` (brentq.c's expressions in its order)."""
    if xpre == xblk:                        # interpolate (secant)
        return -fcur * (xcur - xpre) / (fcur - fpre)
    dpre = (fpre - fcur) / (xpre - xcur)    # extrapolate (inverse quadratic)
    dblk = (fblk - fcur) / (xblk - xcur)
    return -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
