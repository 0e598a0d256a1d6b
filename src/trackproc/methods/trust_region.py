"""A bounded minimiser of a smooth function of a few parameters without derivatives: quasi-Newton
with a trust region on forward-difference gradients (Nocedal & Wright 2006). The REML noise model's
search (:mod:`trackproc.methods.noise`), where each function value is a likelihood evaluation, so
the count of evaluations is what it saves; it replaced a Nelder-Mead simplex that took three times
as many.
"""

from __future__ import annotations

import math

import numpy as np

#: The step (in the parameters' units: log-parameters in the noise model) of the initial curvature probes.
_PROBE = 0.5
#: The floor of the initial curvatures: on a plateau a step goes to the trust radius.
_CMIN = 1e-3


def minimise(fun, start, bounds, xtol: float, ftol: float, maxiter: int = 40, final=None):
    """Minimise ``fun`` from ``start`` within ``bounds`` (a few log-parameters): quasi-Newton
    with a trust region (Nocedal & Wright 2006, alg. 4.1 with the exact subproblem of sec. 4.3
    in these 2-3 dimensions, BFGS updates, eq. 6.19) on forward-difference gradients, the first
    Hessian from one probe ``_PROBE`` downhill per coordinate and their cross terms, a
    coordinate at a bound whose gradient points out of the box held there (projected
    gradient). Stops when the quadratic model promises less than ``ftol`` or the step is below
    ``xtol`` in every coordinate. Returns ``(z, -fun(z))``, ``z`` rounded to 0.001 (``final``:
    ``-final(z)``, ``final`` being ``fun`` by a more exact path)."""
    lo = np.array([b[0] for b in bounds], float)
    hi = np.array([b[1] for b in bounds], float)
    x = np.clip(np.asarray(start, float), lo, hi)
    d = x.size
    f = float(fun(x))
    h = 1e-4

    def grad(x, f):
        g = np.empty(d)
        for i in range(d):
            step = h if x[i] + h <= hi[i] else -h       # inside the box: the likelihood is defined there
            y = x.copy()
            y[i] += step
            g[i] = (float(fun(y)) - f) / step
        return g

    g = grad(x, f)
    # the initial curvature of each coordinate from one probe a finite step downhill (the
    # likelihood has plateaus where a component vanishes: a unit matrix would stop there)
    curv = np.empty(d)
    steps = np.empty(d)
    probe = np.empty(d)
    for i in range(d):
        step = -_PROBE if g[i] > 0 else _PROBE
        if not lo[i] <= x[i] + step <= hi[i]:
            step = -step
        y = x.copy()
        y[i] += step
        fy = float(fun(y))
        steps[i], probe[i] = step, fy
        curv[i] = 2.0 * (fy - f - g[i] * step) / step ** 2 if math.isfinite(fy) else 1.0
    b = np.diag(np.maximum(curv, _CMIN))
    if np.all(curv > 0.01) and np.all(np.isfinite(probe)):
        hess = np.diag(curv)
        for i in range(d):
            for j in range(i + 1, d):
                y = x.copy()
                y[i] += steps[i]
                y[j] += steps[j]
                hess[i, j] = hess[j, i] = (float(fun(y)) - probe[i] - probe[j] + f) / (steps[i] * steps[j])
        if np.all(np.isfinite(hess)) and np.linalg.eigvalsh(hess).min() > 0.01:
            b = hess
    radius = 1.0
    for _ in range(maxiter):
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        if not free.any() or not np.isfinite(g).all():
            break
        gf = g[free]
        # every coordinate free (the usual case): B itself, the same numbers as its full selection
        w, v = np.linalg.eigh(b if free.all() else b[np.ix_(free, free)])
        gv = v.T @ gf
        lam = max(0.0, -float(w.min()) + 1e-10)
        s = -v @ (gv / (w + lam))
        if np.linalg.norm(s) > radius:       # the boundary solution: ‖(B + λI)⁻¹g‖ = radius
            s = -v @ (gv / (w + _boundary_shift(w, gv, lam, float(np.linalg.norm(gf)), radius)))
        step = np.zeros(d)
        step[free] = s
        y = np.clip(x + step, lo, hi)
        step = y - x
        pred = -float(g @ step + 0.5 * step @ b @ step)
        if pred < ftol or (np.abs(step) < xtol).all():
            break
        fy = float(fun(y))
        rho = (f - fy) / pred if math.isfinite(fy) else -1.0
        if rho < 0.25:
            radius = 0.25 * float(np.linalg.norm(step))
        elif rho > 0.75 and np.linalg.norm(step) > 0.9 * radius:
            radius *= 2.0
        if rho > 0.0:
            gy = grad(y, fy)
            dg = gy - g
            sy = float(step @ dg)
            if sy > 1e-12:                  # BFGS keeps B positive definite only with sᵀy > 0
                bs = b @ step
                b = b - np.outer(bs, bs) / float(step @ bs) + np.outer(dg, dg) / sy
            x, f, g = y, fy, gy
    # the result on a grid of 0.001 in the log-parameters (0.1 % of each, far below what a pass
    # determines): the gradients differ from path to path by the likelihood's rounding / h, so
    # likelihoods equal to rounding (the O(n) and the dense path) end on the same point
    z = np.clip(np.round(x, 3), lo, hi)
    return z, -float((fun if final is None else final)(z))


def _boundary_shift(w, gv, lam: float, g_norm: float, radius: float) -> float:
    """The shift λ ≥ ``lam`` with ‖(B + λI)⁻¹g‖ = ``radius`` (Nocedal & Wright 2006, sec. 4.3), ``w``
    the eigenvalues of B and ``gv`` the gradient in its eigenvectors, by 40 bisections between ``lam``
    and an upper bound; the upper end of the last bracket (inside the radius)."""
    wl = w.tolist()
    lo_l, hi_l = lam, lam + g_norm / radius + max(abs(e) for e in wl)
    pairs = list(zip(gv.tolist(), wl))
    r2 = radius * radius
    for _ in range(40):
        mid = 0.5 * (lo_l + hi_l)
        total = 0.0                 # the terms summed in order (as sum() did: the same bits)
        for gi, wi in pairs:
            total += (gi / (wi + mid)) ** 2
        if total > r2:
            lo_l = mid
        else:
            hi_l = mid
    return hi_l
