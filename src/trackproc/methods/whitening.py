"""Generalised least squares by whitening: the covariance of all samples of a solution, made of
correlated per-pass blocks (each a :class:`trackproc.methods.noise.NoiseModel`) and independent
samples elsewhere, and its Cholesky whitener ``L⁻¹`` (Aitken 1935: GLS with ``C = L Lᵀ`` is
ordinary least squares on ``L⁻¹ r``, ``L⁻¹ J``); the effective number of independent samples of
a covariance (Bayley & Hammersley 1946). The noise models and their REML fit are
:mod:`trackproc.methods.noise`.

Pure numpy/scipy.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.linalg import solve_triangular

__all__ = ["PassCovariance", "effective_samples"]


def effective_samples(cov: np.ndarray) -> float:
    """Effective number of independent samples of a covariance: ``(tr C)² / tr(C²)``
    (= n for independent samples of equal variance, 1 for fully correlated ones; Bayley &
    Hammersley 1946)."""
    c = np.asarray(cov, float)
    return float(np.trace(c) ** 2 / np.sum(c * c))


class PassCovariance:
    """The covariance of all samples: blocks (index arrays with a :class:`NoiseModel` and the
    walk's start) and independent samples (``sigma``) elsewhere; whitening of kept samples.

    ``whitener(keep)`` returns ``w(M)``: the rows of ``M`` at the kept samples (in their original
    order) multiplied by ``L⁻¹`` of their covariance block by block (``C = L Lᵀ``). Factors are
    cached per set of kept samples.
    """

    def __init__(self, sigma, t_s, blocks: Sequence[tuple] = ()):
        self.sigma = np.asarray(sigma, float)
        self.t = np.asarray(t_s, float)
        self.blocks = [(np.asarray(i, int), m, t0) for i, m, t0 in blocks]
        self._cache: dict = {}

    @property
    def is_white(self) -> bool:
        return all(m.is_white for _, m, _ in self.blocks)

    def _factors(self, keep: np.ndarray):
        key = keep.tobytes()
        hit = self._cache.get(key)
        if hit is None:
            pos = np.cumsum(keep) - 1               # position of a kept sample among the kept ones
            in_block = np.zeros(keep.size, bool)
            fac = []
            for idx, model, t0 in self.blocks:
                in_block[idx] = True
                k = idx[keep[idx]]
                if k.size == 0:
                    continue
                c = model.covariance(self.t[k], t0)
                fac.append((pos[k], np.linalg.cholesky(c)))
            diag = np.flatnonzero(keep & ~in_block)
            hit = (fac, pos[diag], self.sigma[diag])
            if len(self._cache) > 16:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def whitener(self, keep):
        keep = np.asarray(keep, bool)
        fac, dpos, dsig = self._factors(keep)

        def apply(m):
            m = np.asarray(m, float)[keep]
            out = np.empty_like(m)
            for pos, chol in fac:
                out[pos] = solve_triangular(chol, m[pos], lower=True, check_finite=False)
            out[dpos] = m[dpos] / (dsig if m.ndim == 1 else dsig[:, None])
            return out

        return apply

    def innovations(self, r) -> np.ndarray:
        """Normalized residuals of every sample: ``L⁻¹ r`` over all samples (the standardised
        one-step prediction errors, in time order within a block; white: ``r/σ``)."""
        return self.whitener(np.ones(self.sigma.size, bool))(r)

    def effective_samples(self, keep=None) -> float:
        keep = np.ones(self.sigma.size, bool) if keep is None else np.asarray(keep, bool)
        total = 0.0
        in_block = np.zeros(keep.size, bool)
        for idx, model, t0 in self.blocks:
            in_block[idx] = True
            k = idx[keep[idx]]
            if k.size:
                total += effective_samples(model.covariance(self.t[k], t0))
        return total + float((keep & ~in_block).sum())
