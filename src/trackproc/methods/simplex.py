"""Two classic optimizers written out so that the hot paths do not import ``scipy.optimize``.

``import scipy.optimize`` costs tens of milliseconds of CPU in every process (it pulls in sparse
linear algebra, FFTs, rotations, linear programming ...) for the two routines ``refine``,
``estimate`` and ``smooth`` use from it:

* :func:`nelder_mead`, the downhill simplex of Nelder & Mead (1965) (the REML noise-model search
  used it until it moved to a quasi-Newton search with far fewer likelihood evaluations,
  :func:`trackproc.methods.noise._optimise`; tests/methods/test_simplex.py still holds it to
  scipy's bits on those likelihoods);
* :func:`brentq`, Brent's (1973) root finder ("zeroin": inverse quadratic interpolation,
  secant steps and bisection), for the AR(1) moment equation and the traverse station.

Both follow scipy 1.17 as it writes them, operation for operation (``_minimize_neldermead``
without bounds, ``adaptive=False`` and the default initial simplex; the C ``brentq`` of
``scipy/optimize/Zeros/brentq.c``), so the iterates, the number of evaluations and the returned
point are the same floating-point numbers; tests/methods/test_simplex.py compares them with
scipy's (which stays a dependency) on random problems with ``==``.
"""

from __future__ import annotations

import math

import numpy as np

#: scipy's smallest accepted relative tolerance of a root (4 ε).
BRENT_RTOL = 4 * float(np.finfo(float).eps)


class _MaxFev(RuntimeError):
    """The evaluation budget is spent (scipy's ``_MaxFuncCallError``)."""


def nelder_mead(fun, x0, *, xatol: float, fatol: float, maxfev: int) -> tuple[np.ndarray, float, int]:
    """Minimise ``fun`` from ``x0`` by the downhill simplex; returns ``(x, f, nfev)``: the best
    vertex, the smallest value in the final simplex and the number of evaluations.

    Implements Nelder & Mead (1965) as scipy 1.17 writes it (same iterates):
    ``scipy.optimize.minimize(fun, x0, method="Nelder-Mead", options={"xatol": xatol,
    "fatol": fatol, "maxfev": maxfev})``: reflection 1, expansion 2, contraction ½, shrink ½;
    the initial simplex moves each coordinate by 5 % (0.00025 if it is zero); it stops when every
    vertex is within ``xatol`` of the best (each coordinate) and every value within ``fatol``, or
    when ``maxfev`` evaluations are spent (no iteration limit, as scipy when only ``maxfev`` is
    given). ``fun`` receives a copy of the point. A NaN value compares false everywhere, as there.
    """
    x0 = np.atleast_1d(x0).flatten()
    dtype = x0.dtype if np.issubdtype(x0.dtype, np.inexact) else np.float64
    x0 = np.asarray(x0, dtype=dtype)
    rho, chi, psi, sigma = 1, 2, 0.5, 0.5
    nonzdelt, zdelt = 0.05, 0.00025

    n = len(x0)
    sim = np.empty((n + 1, n), dtype=x0.dtype)
    sim[0] = x0
    for k in range(n):
        y = np.array(x0, copy=True)
        if y[k] != 0:
            y[k] = (1 + nonzdelt) * y[k]
        else:
            y[k] = zdelt
        sim[k + 1] = y

    calls = [0]

    def func(x):
        if calls[0] >= maxfev:
            raise _MaxFev
        calls[0] += 1
        fx = fun(np.copy(x))
        if not np.isscalar(fx):
            fx = np.asarray(fx).item()
        return fx

    fsim = np.full((n + 1,), np.inf, dtype=float)
    try:
        for k in range(n + 1):
            fsim[k] = func(sim[k])
    except _MaxFev:
        pass
    finally:
        ind = np.argsort(fsim)
        sim = np.take(sim, ind, 0)
        fsim = np.take(fsim, ind, 0)
    ind = np.argsort(fsim)
    fsim = np.take(fsim, ind, 0)
    sim = np.take(sim, ind, 0)

    while calls[0] < maxfev:
        try:
            if (np.max(np.ravel(np.abs(sim[1:] - sim[0]))) <= xatol
                    and np.max(np.abs(fsim[0] - fsim[1:])) <= fatol):
                break
            xbar = np.add.reduce(sim[:-1], 0) / n
            xr = (1 + rho) * xbar - rho * sim[-1]
            fxr = func(xr)
            if fxr < fsim[0]:
                xe = (1 + rho * chi) * xbar - rho * chi * sim[-1]
                fxe = func(xe)
                if fxe < fxr:
                    sim[-1], fsim[-1] = xe, fxe
                else:
                    sim[-1], fsim[-1] = xr, fxr
            elif fxr < fsim[-2]:
                sim[-1], fsim[-1] = xr, fxr
            else:
                shrink = False
                if fxr < fsim[-1]:          # outside contraction
                    xc = (1 + psi * rho) * xbar - psi * rho * sim[-1]
                    fxc = func(xc)
                    if fxc <= fxr:
                        sim[-1], fsim[-1] = xc, fxc
                    else:
                        shrink = True
                else:                       # inside contraction
                    xcc = (1 - psi) * xbar + psi * sim[-1]
                    fxcc = func(xcc)
                    if fxcc < fsim[-1]:
                        sim[-1], fsim[-1] = xcc, fxcc
                    else:
                        shrink = True
                if shrink:
                    for j in range(1, n + 1):
                        # the vertex moves before its evaluation: a spent budget leaves it moved
                        # with its old value, as in scipy
                        sim[j] = sim[0] + sigma * (sim[j] - sim[0])
                        fsim[j] = func(sim[j])
        except _MaxFev:
            pass
        ind = np.argsort(fsim)
        sim = np.take(sim, ind, 0)
        fsim = np.take(fsim, ind, 0)
    return sim[0], np.min(fsim), calls[0]


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
