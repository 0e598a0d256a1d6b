"""A cached model and the geodesic-acceleration retraction of Transtrum & Sethna for Gauss-Newton steps along
curved valleys.
"""

from __future__ import annotations

import numpy as np

from trackproc.errors import ProcessingError

from trackproc.methods.least_squares import prior_rows


class CachedModel:
    """``model(x)`` remembering its last few results (the geodesic step re-uses the solver's).

    ``values(x)``: the values alone. ``values`` (optional) computes them without the Jacobian
    (the same numbers as ``model(x)[0]``, cheaper); the default is ``model(x)[0]``."""

    def __init__(self, model, size: int = 8, values=None):
        self.model = model
        self.size = size
        self._cache: dict = {}
        self._values = values
        self.evaluations = 0

    def values(self, x):
        hit = self._cache.get(np.asarray(x, float).tobytes())
        if hit is not None:
            return hit[0]
        if self._values is None:
            return self(x)[0]
        return self._values(x)

    def __call__(self, x):
        key = np.asarray(x, float).tobytes()
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) >= self.size:
                self._cache.pop(next(iter(self._cache)))
            hit = self.model(x)
            self.evaluations += 1
            self._cache[key] = hit
        return hit


def geodesic_retraction(model, sigma, scales, priors=(), *, fraction: float = 0.1, alpha: float = 0.75):
    """A step rule with geodesic acceleration (Transtrum & Sethna, arXiv:1201.5885).

    One pass of Doppler leaves the orbit in narrow, curved valleys of the cost (a slant range
    traded against radial and cross-track position; a rotation about the station's geocentric
    axis, which leaves every station-satellite distance unchanged): a straight Gauss-Newton step
    along the valley leaves it, is refused, and damped steps creep. The rule adds half the
    second-order correction ``a = -J⁺ h_vv``, with the directional second derivative of the
    model ``h_vv ≈ (2/f) ((h(x + f δ) - h(x))/f - J δ)`` (one extra model evaluation, ``f`` =
    ``fraction``), so the step follows the valley: ``x_new = x + δ + a/2``; the correction is
    dropped when ``|a| > alpha |δ|`` (scaled), where the expansion is not to be trusted.

    ``model`` (a :class:`CachedModel`, so that ``h(x), J(x)`` come from the solver's own
    evaluation, and the trial point's values come without a Jacobian), ``sigma`` the data
    sigmas, ``scales`` the parameter scales, ``priors`` the a-priori constraints (linear: no
    curvature). Returns ``retract(x, dx) -> x_new`` for
    :func:`trackproc.methods.least_squares.solve`.
    """
    sig = np.asarray(sigma, float)
    sc = np.asarray(scales, float)
    prior_a, _ = prior_rows(priors, sc.size, sc)

    def retract(x, dx):
        x = np.asarray(x, float)
        dx = np.asarray(dx, float)
        try:
            h0, jac = model(x)
            h1 = model.values(x + fraction * dx) if hasattr(model, "values") else model(x + fraction * dx)[0]
        except (ArithmeticError, ValueError, ProcessingError):
            return x + dx
        hvv = (2.0 / fraction) * ((np.asarray(h1) - h0) / fraction - jac @ dx)
        a_w = np.vstack([jac / sig[:, None] * sc[None, :], prior_a])
        rhs = np.r_[hvv / sig, np.zeros(prior_a.shape[0])]
        if not (np.isfinite(a_w).all() and np.isfinite(rhs).all()):
            return x + dx
        acc = -np.linalg.lstsq(a_w, rhs, rcond=None)[0]
        if np.linalg.norm(acc) > alpha * np.linalg.norm(dx / sc):
            return x + dx
        return x + dx + 0.5 * sc * acc

    return retract
