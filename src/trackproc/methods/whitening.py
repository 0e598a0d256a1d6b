"""Generalised least squares by whitening: the covariance of all samples of a solution, made of
correlated per-pass blocks (each a :class:`trackproc.methods.noise.NoiseModel`) and independent
samples elsewhere, and its Cholesky whitener ``L⁻¹`` (Aitken 1935: GLS with ``C = L Lᵀ`` is
ordinary least squares on ``L⁻¹ r``, ``L⁻¹ J``); the effective number of independent samples of
a covariance (Bayley & Hammersley 1946). The noise models and their REML fit are
:mod:`trackproc.methods.noise`.

The noise of one pass (white + AR(1) + random walk, time-ordered samples) is a Markov process
observed with white noise, so its Cholesky whitener is applied in O(n) (:class:`MarkovFactor`)
instead of factorising the dense n x n covariance (O(n³); issue 19):

* one correlated component (AR(1) or the walk): ``D x = ν`` with ``D`` unit lower bidiagonal
  (``-φ_i`` below the diagonal, ``φ_i = exp(-Δt_i/τ)`` for the AR(1), 1 for the walk) and
  independent ``ν_i`` of variance ``v_i`` (``σ_a²(1 - φ_i²)``, resp. ``q² Δs_i``), hence
  ``C = σ_w² I + D⁻¹ V D⁻ᵀ = D⁻¹ B D⁻ᵀ`` with the tridiagonal ``B = σ_w² D Dᵀ + V``. With
  ``B = L_B L_Bᵀ`` (banded Cholesky), ``L_B⁻¹ D`` is lower triangular with a positive diagonal
  and whitens ``C``: it is the inverse Cholesky factor of ``C`` itself (the factor is unique),
  so the whitened rows (the innovations) are those of the dense factor; ``log|C| = log|B|``.
  Nothing is divided by ``1 - φ²`` or by a gap: duplicate times and near-zero gaps are exact.
* both components: the two-state Kalman filter (state: AR(1) value, walk value; measurement
  their sum plus white noise). Its innovations ``e_k`` with variances ``S_k`` are the
  ``L D Lᵀ`` factorisation of ``C`` in time order (Kalman 1960; the innovations
  representation, Kailath 1968), so ``e_k / √S_k`` is again the dense Cholesky whitening and
  ``log|C| = Σ log S_k`` (the prediction-error decomposition, Schweppe 1965). The gains are a scalar recursion; the
  filtered predictions of all columns at once are one banded triangular solve.

Pure numpy/scipy; the gain recursion optionally compiled (numba, :func:`compiled_riccati`), and
with it the whitening of the two-state case (the filter's state recursion over each column, equal
to the banded solve to rounding). A little over 400 lines: the numpy and compiled paths of the same
recursion are kept together; the kernels themselves are in :mod:`trackproc.methods.whitening_jit`.
"""

from __future__ import annotations

import math
import sys
import threading
from collections import OrderedDict
from typing import Optional, Sequence

import numpy as np

from trackproc.dynamics import jit
from trackproc.methods.lapack import routines

dpbtrf, dtbtrs = routines("dpbtrf", "dtbtrs")     # scipy.linalg.lapack's, without scipy.linalg

__all__ = ["PassCovariance", "effective_samples", "effective_samples_beyond", "MarkovFactor", "markov_factor",
           "kept_markov_factor", "compiled_riccati", "compiled_reml", "markov_grid"]


def effective_samples(cov: np.ndarray) -> float:
    """Effective number of independent samples of a covariance: ``(tr C)² / tr(C²)``
    (= n for independent samples of equal variance, 1 for fully correlated ones; Bayley &
    Hammersley 1946)."""
    c = np.asarray(cov, float)
    return float(np.trace(c) ** 2 / np.sum(c * c))


class MarkovFactor:
    """The Cholesky whitener ``L⁻¹`` of the covariance of a noise model (``white``, ``ar_sigma``,
    ``ar_tau_s``, ``walk``: :class:`trackproc.methods.noise.NoiseModel`) at non-decreasing times,
    in O(n) (module docstring). ``logdet`` is ``log|C|`` (``-inf``/``nan`` never: a covariance
    that is not positive definite raises :class:`numpy.linalg.LinAlgError` like the dense factor).
    ``whiten(M)`` is ``L⁻¹ M`` (rows of ``M`` at the times)."""

    def __init__(self, model, t, t0: Optional[float] = None, grid: Optional[tuple] = None):
        t = np.asarray(t, float)
        n = t.size
        t0 = float(t.min()) if t0 is None else float(t0)
        self.n = n
        self._gains = None
        w2 = float(model.white) ** 2
        has_ar = model.ar_sigma > 0 and model.ar_tau_s > 0
        has_walk = model.walk > 0
        # ``grid``: :func:`markov_grid` of these times (a REML search evaluates hundreds of models on one grid)
        dt, ds = grid if grid is not None else markov_grid(t, t0)
        if has_ar:
            phi = np.exp(-dt / model.ar_tau_s)
            # σ_a² (1 - φ²) without cancellation at small gaps
            v_ar = np.concatenate([[1.0], -np.expm1(-2.0 * dt / model.ar_tau_s)]) * model.ar_sigma ** 2
        if has_walk:
            v_walk = ds * model.walk ** 2
        self._mode = "both" if has_ar and has_walk else "one" if has_ar or has_walk else "white"
        if self._mode == "white":
            if not w2 > 0:
                raise np.linalg.LinAlgError("covariance not positive definite")
            self._sd = math.sqrt(w2)
            self.logdet = n * math.log(w2)
        elif self._mode == "one":
            self._phi = phi if has_ar else np.ones(n - 1)
            v = v_ar if has_ar else v_walk
            ab = np.zeros((2, n))                           # B = σ_w² D Dᵀ + V, lower band storage
            ab[0] = w2 * (1.0 + np.concatenate([[0.0], self._phi ** 2])) + v
            ab[1, :-1] = -w2 * self._phi
            chol, info = dpbtrf(ab, lower=1)
            if info != 0:
                raise np.linalg.LinAlgError("covariance not positive definite")
            self._chol = chol
            self.logdet = 2.0 * float(np.sum(np.log(chol[0])))
        else:
            self._kalman(phi, v_ar, v_walk, w2, float(model.ar_sigma) ** 2)

    def _kalman(self, phi, v_ar, v_walk, w2, a2):
        """The two-state filter's gains: the Riccati recursion in scalars (a 2 x 2 covariance).
        Implements the Kalman (1960) filter's covariance recursion with a scalar measurement."""
        kernel = compiled_riccati()
        if kernel is not None:                              # the same loop, compiled (same bits)
            self._s, h0v, h1v = kernel(phi, v_ar, v_walk, float(w2), float(a2))
        else:
            sv, h0v, h1v = [], [], []
            p00, p01, p11 = a2, 0.0, float(v_walk[0])
            for f, va, vw in zip(phi.tolist() + [0.0], v_ar[1:].tolist() + [0.0], v_walk[1:].tolist() + [0.0]):
                hp0 = p00 + p01                             # P hᵀ, h = (1, 1)
                hp1 = p01 + p11
                s = hp0 + hp1 + w2
                sv.append(s)
                h0v.append(hp0)
                h1v.append(hp1)
                g0 = hp0 / s                                # update with y_k (P - g S gᵀ), predict to t_k+1
                g1 = hp1 / s
                p00 = f * f * (p00 - g0 * hp0) + va
                p01 = f * (p01 - g0 * hp1)
                p11 = p11 - g1 * hp1 + vw
            self._s = np.array(sv)
        if not np.all(self._s > 0):
            raise np.linalg.LinAlgError("covariance not positive definite")
        self.logdet = float(np.sum(np.log(self._s)))
        self._sd = np.sqrt(self._s)
        g0 = (np.array(h0v) / self._s)[:-1]
        g1 = (np.array(h1v) / self._s)[:-1]
        f = phi
        if kernel is not None:         # the compiled filter whitens (whiten): no banded system
            self._gains = (f, g0, g1)
            return
        # x̂_k+1 = A_k x̂_k + b_k y_k with A_k = F (I - g h), b_k = F g, F = diag(φ, 1), h = (1, 1):
        # a unit lower triangular system of bandwidth 3 in the interleaved predictions
        ab = np.zeros((4, 2 * self.n))
        ab[2, 0:-2:2] = -f * (1.0 - g0)                    # row 2k+2, column 2k
        ab[3, 0:-2:2] = g1                                 # row 2k+3, column 2k   (-(-g1))
        ab[1, 1:-2:2] = f * g0                             # row 2k+2, column 2k+1 (-(-φ g0))
        ab[2, 1:-2:2] = -(1.0 - g1)                        # row 2k+3, column 2k+1
        self._band = ab
        self._b = (f * g0, g1)

    def whiten(self, m) -> np.ndarray:
        m = np.asarray(m, float)
        vec = m.ndim == 1
        m2 = m[:, None] if vec else m
        if m2.size == 0:                                    # LAPACK is not called with an empty matrix
            return np.array(m, float)
        if self._mode == "white":
            out = m2 / self._sd
        elif self._mode == "one":
            dm = np.array(m2, order="F")                 # D M; LAPACK's column order, solved in place
            dm[1:] -= self._phi[:, None] * m2[:-1]
            out, _ = dtbtrs(self._chol, dm, uplo="L", overwrite_b=1)
        elif self._gains is not None:
            out = _compiled_whiten()(*self._gains, self._sd, np.ascontiguousarray(m2))
        else:
            rhs = np.zeros((2 * self.n, m2.shape[1]), order="F")
            rhs[2::2] = self._b[0][:, None] * m2[:-1]
            rhs[3::2] = self._b[1][:, None] * m2[:-1]
            xh, _ = dtbtrs(self._band, rhs, uplo="L", diag="U", overwrite_b=1)
            out = (m2 - xh[0::2] - xh[1::2]) / self._sd[:, None]
        return out[:, 0] if vec else out


_RICCATI: list = []        # [compiled kernel or None] once looked up


def compiled_riccati():
    """The compiled gain recursion (:mod:`trackproc.methods.whitening_jit`) when it pays, else None.

    ``TRACKPROC_JIT=0``: never; ``TRACKPROC_JIT=1``: whenever numba is importable; unset: only
    when numba is already loaded in this process (a compiled engine or ``trackproc batch`` paid
    its import, ~0.15 s; a single refine's few hundred filter runs save less than that)."""
    mode = jit.mode()
    if mode == "0" or (mode != "1" and "numba" not in sys.modules):
        return None
    if not _RICCATI:
        kernel = None
        if jit.enabled():
            try:
                from trackproc.methods.whitening_jit import kalman_whiten, reml_terms, riccati as kernel

                # compiled or loaded here, by one process at a time on a fresh cache
                with jit.compile_once([kernel, kalman_whiten, reml_terms], "whitening"):
                    kernel(np.ones(1), np.ones(2), np.ones(2), 1.0, 1.0)
                    kalman_whiten(np.ones(1), np.ones(1), np.ones(1), np.ones(2), np.ones((2, 1)))
                    reml_terms(np.ones(1), np.ones(2), 1.0, 1.0, 1.0, 1.0, np.ones((2, 2)), 1)
            except Exception:                      # noqa: BLE001 - numba unusable here: the Python loop
                kernel = None
        _RICCATI.append(kernel)
    return _RICCATI[0]


def compiled_reml():
    """The compiled one-pass restricted-likelihood terms (:func:`trackproc.methods.whitening_jit.reml_terms`:
    ``(log|C|, log|XᵀC⁻¹X|, rᵀPr)``) when :func:`compiled_riccati` is, else None."""
    if compiled_riccati() is None:
        return None
    from trackproc.methods.whitening_jit import reml_terms

    return reml_terms


def _compiled_whiten():
    """The compiled two-state filter over a matrix's columns (loaded with :func:`compiled_riccati`)."""
    from trackproc.methods.whitening_jit import kalman_whiten

    return kalman_whiten


def markov_grid(t: np.ndarray, t0: float) -> tuple:
    """``(Δt, Δs)`` of times ``t`` for :class:`MarkovFactor`: the gaps and the increments of the
    walk's clock ``s = max(t - t0, 0)`` (its first value first)."""
    s = np.clip(t - t0, 0.0, None)
    return np.diff(t), np.concatenate([s[:1], np.diff(s)])


#: how many samples the factors :func:`kept_markov_factor` keeps may hold in all (a factor of n
#: samples holds about 16 n doubles: ~25 MB in all)
_KEPT_SAMPLES = 200_000
_KEPT: OrderedDict = OrderedDict()
_KEPT_LOCK = threading.Lock()
_KEPT_HELD = [0]


def kept_markov_factor(model, t: np.ndarray, t0: Optional[float], grid: Optional[tuple] = None) -> MarkovFactor:
    """``MarkovFactor(model, t, t0, grid)``, kept while the factors kept hold fewer than
    :data:`_KEPT_SAMPLES` samples (least recently used dropped first): the factor depends on
    nothing else, and the REML searches of one pass (:func:`trackproc.methods.noise.fit_noise`,
    once per update of the orbit) evaluate the same points as long as the residuals barely
    change, so most of their models recur on the pass's times. ``grid`` must be
    :func:`markov_grid` of ``t`` and ``t0``. A factor is never changed after it is made, so one
    object serves every caller."""
    t = np.asarray(t, float)
    key = (float(model.white), float(model.ar_sigma), float(model.ar_tau_s), float(model.walk),
           None if t0 is None else float(t0), t.tobytes())
    with _KEPT_LOCK:
        fac = _KEPT.get(key)
        if fac is not None:
            _KEPT.move_to_end(key)
            return fac
    fac = MarkovFactor(model, t, t0, grid)
    with _KEPT_LOCK:
        if key not in _KEPT:
            _KEPT[key] = fac
            _KEPT_HELD[0] += fac.n
        while _KEPT_HELD[0] > _KEPT_SAMPLES and len(_KEPT) > 1:
            _, old = _KEPT.popitem(last=False)
            _KEPT_HELD[0] -= old.n
    return fac


def markov_factor(model, t, t0: Optional[float] = None) -> Optional[MarkovFactor]:
    """:class:`MarkovFactor` of ``model`` at times ``t``, or None when the times are not in
    non-decreasing order (the dense factor of that order is then the one wanted)."""
    t = np.asarray(t, float)
    if t.size == 0 or (t.size > 1 and not np.all(np.diff(t) >= 0)):
        return None
    return MarkovFactor(model, t, t0)


class PassCovariance:
    """The covariance of all samples: blocks (index arrays with a :class:`NoiseModel` and the
    walk's start) and independent samples (``sigma``) elsewhere; whitening of kept samples.

    ``whitener(keep)`` returns ``w(M)``: the rows of ``M`` at the kept samples (in their original
    order) multiplied by ``L⁻¹`` of their covariance block by block (``C = L Lᵀ``; in O(n) by
    :class:`MarkovFactor` when a block's times are in order). Factors are cached per set of kept
    samples.
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
                fast = markov_factor(model, self.t[k], t0)   # O(n); the dense factor for unordered times
                fac.append((pos[k], fast if fast is not None else np.linalg.cholesky(model.covariance(self.t[k], t0))))
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
                if isinstance(chol, MarkovFactor):
                    out[pos] = chol.whiten(m[pos])
                else:
                    # start-up: scipy.linalg (~70 ms) only for a dense factor (times out of order)
                    from scipy.linalg import solve_triangular

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


def effective_samples_beyond(model, t_s, t0: Optional[float] = None) -> float:
    """Effective number of independent samples of the noise an orbit sees once the explicit
    offset and drift are estimated: :func:`effective_samples` of ``P C P``, ``P`` the projection
    that removes a constant and a line in time (n for white noise)."""
    t = np.asarray(t_s, float)
    if model.is_white:               # C' = σ_w² P: the rank of the projection, without the n x n matrix
        return float(t.size - (2 if t.size > 1 and np.ptp(t) > 0 else 1))
    t0 = float(t.min()) if t0 is None else float(t0)
    q, _ = np.linalg.qr(np.column_stack([np.ones(t.size), t - t0]))
    if t.size > 1 and np.all(np.diff(t) >= 0):
        # tr C' = tr C - tr QᵀCQ, tr C'² = ‖C‖² - 2‖CQ‖² + ‖QᵀCQ‖² (P = I - QQᵀ), all in O(n)
        tr, frob2, cq = _markov_traces(model, t, t0, q)
        qcq = q.T @ cq
        return float((tr - np.trace(qcq)) ** 2 / (frob2 - 2.0 * np.sum(cq * cq) + np.sum(qcq * qcq)))
    c = model.covariance(t, t0)
    cq = c - q @ (q.T @ c)
    return effective_samples(cq - (cq @ q) @ q.T)


def _markov_traces(model, t: np.ndarray, t0: float, v: np.ndarray):
    """``(tr C, ‖C‖_F², C v)`` of the covariance of ``model`` at non-decreasing times ``t`` without
    forming ``C``: ``K v`` of the AR(1) correlation by a forward and a backward first-order
    recursion (``f_i = v_i + φ_i f_i-1``; banded triangular solves), ``M v`` of the walk's
    ``min(s_i, s_j)`` by cumulative sums, and the sums of squares of their entries likewise."""
    n = t.size
    w2, a2, q2 = model.white ** 2, model.ar_sigma ** 2, model.walk ** 2
    has_ar = model.ar_sigma > 0 and model.ar_tau_s > 0
    s = np.clip(t - t0, 0.0, None)

    def kmul(phi, m):                 # Σ_j exp(-|t_i - t_j|/τ) m_j by the two recursions
        lo = np.zeros((2, n))
        lo[0] = 1.0
        lo[1, :-1] = -phi
        up = np.zeros((2, n))
        up[1] = 1.0
        up[0, 1:] = -phi
        mf = np.asfortranarray(m)
        return dtbtrs(lo, mf, uplo="L")[0] + dtbtrs(up, mf, uplo="U")[0] - m

    def mmul(sv, m):                  # Σ_j min(s_i, s_j) m_j, s non-decreasing
        inside = np.cumsum(sv[:, None] * m, axis=0)
        beyond = np.cumsum(m[::-1], axis=0)[::-1]
        beyond = np.vstack([beyond[1:], np.zeros((1, m.shape[1]))])
        return inside + sv[:, None] * beyond

    v = np.asarray(v, float)
    cv = w2 * v
    tr = n * w2
    frob2 = n * w2 * w2
    ones = np.ones((n, 1))
    if has_ar:
        phi = np.exp(-np.diff(t) / model.ar_tau_s)
        kv = kmul(phi, np.column_stack([v, ones]))
        cv = cv + a2 * kv[:, :-1]
        tr += n * a2
        frob2 += 2.0 * w2 * a2 * n + a2 * a2 * float(np.sum(kmul(phi * phi, ones)))
    if q2 > 0:
        cv = cv + q2 * mmul(s, v)
        tr += q2 * float(np.sum(s))
        frob2 += 2.0 * w2 * q2 * float(np.sum(s)) + q2 * q2 * float(np.sum(mmul(s * s, ones)))
        if has_ar:                    # 2 Σ K_ij min(s_i, s_j): s_j for j ≤ i, s_i beyond
            fwd = np.vstack([np.ones(n), np.concatenate([-phi, [0.0]])])     # f_i = m_i + φ_i f_i-1
            inside = dtbtrs(fwd, np.asfortranarray(np.column_stack([s, ones])), uplo="L")[0]
            lo_s = inside[:, 0]                                                # Σ_j≤i K_ij s_j
            up_1 = kv[:, -1] - inside[:, 1]                                    # Σ_j>i K_ij
            frob2 += 2.0 * a2 * q2 * float(np.sum(lo_s) + np.sum(s * up_1))
    return tr, frob2, cv
