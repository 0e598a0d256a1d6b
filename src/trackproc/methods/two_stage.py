"""Seed 002's error-matrix algebra: the extended state theorem and the two-stage method.

Notation of seed 002: ``A1`` (n1 × m) partials of the "original" measurements (one-way
Doppler, range-rate, angles) with error matrix ``K_n``; ``A2`` (N × m) partials of the
additional measurements (ranges) with error matrix ``Π_N``; ``E`` maps the N offsets ``D0``
to the ranges. All functions take plain arrays and never form an explicit inverse of a
normal matrix where a factorisation will do.

* :func:`covariance` — ``(Aᵀ K⁻¹ A)⁻¹`` (eq. 9) by the SVD of the whitened matrix.
* :func:`extended_covariance` — the (m+N) × (m+N) error matrix of eq. 10 with the Jacobian
  ``[[A1, 0], [A2, E]]``.
* :func:`theorem_blocks` — what eqs. 15-16 predict for it: motion block ``(A1ᵀ K_n⁻¹ A1)⁻¹``,
  offset block ``Π_N + A2 (A1ᵀ K_n⁻¹ A1)⁻¹ A2ᵀ``. The proof needs E square (one range per
  offset); with many ranges per offset the motion block is strictly smaller (tested).
* :func:`accumulate` — stage 1 of the two-stage method: per-pass offset estimates averaged
  per station (weighted mean) with their error matrix ``Π``.
* :func:`two_stage_update` — stage 2 (eqs. 18-22): ``K' = (A1ᵀ K_n⁻¹ A1 + A2ᵀ Π⁻¹ A2)⁻¹`` and
  the matrix-inversion-lemma form ``K' = K - ΔK``, ``ΔK = K A2ᵀ S⁻¹ A2 K``,
  ``S = Π + A2 K A2ᵀ``, ``K = (A1ᵀ K_n⁻¹ A1)⁻¹``.
* :func:`compress` — an m-row equivalent ``(Ã2, I)`` of ranges with error matrix
  ``D + E Π Eᵀ``, the same information by QR (for thousands of ranges, where S would be
  thousands square).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["covariance", "extended_covariance", "theorem_blocks", "two_stage_update", "information_update",
           "accumulate", "compress", "is_psd", "TwoStage"]


def _whiten(a, cov):
    """Rows ``L⁻¹ A`` with ``cov = L Lᵀ`` (cov: (n,) variances or (n, n))."""
    a = np.asarray(a, float)
    cov = np.asarray(cov, float)
    if cov.ndim == 1:
        return a / np.sqrt(cov)[:, None]
    chol = np.linalg.cholesky(cov)
    return np.linalg.solve(chol, a)


def _cov_from_rows(w):
    """``(Wᵀ W)⁻¹`` from the SVD of W (no normal matrix)."""
    _, s, vt = np.linalg.svd(w, full_matrices=False)
    if s.size < w.shape[1] or s[-1] <= 1e-14 * s[0]:
        raise np.linalg.LinAlgError("singular: the measurements do not determine every parameter")
    out = (vt.T / s ** 2) @ vt
    return 0.5 * (out + out.T)


def covariance(a, cov) -> np.ndarray:
    """Error matrix ``(Aᵀ K⁻¹ A)⁻¹`` (seed 002 eq. 9); ``cov`` = variances (n,) or K (n, n)."""
    return _cov_from_rows(_whiten(a, cov))


def extended_covariance(a1, k_n, a2, pi_n, e) -> np.ndarray:
    """Error matrix of the extended state (motion + offsets), seed 002 eqs. 10-11.

    ``a1`` (n1, m), ``k_n`` its error matrix/variances; ``a2`` (n2, m) the ranges' motion
    partials, ``pi_n`` their error matrix/variances, ``e`` (n2, N) their offset partials.
    """
    a1, a2, e = (np.asarray(x, float) for x in (a1, a2, e))
    top = np.hstack([_whiten(a1, k_n), np.zeros((a1.shape[0], e.shape[1]))])
    bottom = _whiten(np.hstack([a2, e]), pi_n)
    return _cov_from_rows(np.vstack([top, bottom]))


def theorem_blocks(a1, k_n, a2, pi_n):
    """Seed 002 eqs. 15-16: ``(K_motion, K_offsets)`` predicted for the extended error matrix.

    ``K_motion = (A1ᵀ K_n⁻¹ A1)⁻¹``; ``K_offsets = Π_N + A2 K_motion A2ᵀ``.
    """
    k = covariance(a1, k_n)
    pi = np.diag(np.asarray(pi_n, float)) if np.ndim(pi_n) == 1 else np.asarray(pi_n, float)
    a2 = np.asarray(a2, float)
    return k, pi + a2 @ k @ a2.T


def information_update(k, a2, pi) -> np.ndarray:
    """``(K⁻¹ + A2ᵀ Π⁻¹ A2)⁻¹`` (seed 002 eq. 19), from the rows ``[L_K⁻¹; L_Π⁻¹ A2]``."""
    k = np.asarray(k, float)
    lk = np.linalg.cholesky(k)
    rows_k = np.linalg.solve(lk, np.eye(k.shape[0]))           # (L⁻¹)ᵀ(L⁻¹) = K⁻¹
    return _cov_from_rows(np.vstack([rows_k, _whiten(a2, pi)]))


def two_stage_update(k, a2, pi):
    """Stage 2 of the two-stage method (seed 002 eqs. 20-22).

    Returns ``(K', ΔK, S)`` with ``S = Π + A2 K A2ᵀ``, ``ΔK = K A2ᵀ S⁻¹ A2 K`` (by a Cholesky
    solve with S) and ``K' = K - ΔK``.
    """
    k = np.asarray(k, float)
    a2 = np.asarray(a2, float)
    pi = np.diag(np.asarray(pi, float)) if np.ndim(pi) == 1 else np.asarray(pi, float)
    s = pi + a2 @ k @ a2.T
    s = 0.5 * (s + s.T)
    chol = np.linalg.cholesky(s)
    g = np.linalg.solve(chol, a2 @ k)                         # L⁻¹ A2 K
    dk = g.T @ g
    dk = 0.5 * (dk + dk.T)
    return k - dk, dk, s


def compress(a2, pi_diag, e, pi_offsets):
    """An m-row equivalent of ranges with error matrix ``diag(pi_diag) + E Π Eᵀ``.

    The n2 bias-corrected ranges carry the information ``A2ᵀ (D + E Π Eᵀ)⁻¹ A2`` on the motion
    parameters. It equals the Schur complement, for the motion columns, of the whitened system
    ``[[D^-1/2 E, D^-1/2 A2], [L_Π⁻¹, 0]]`` (ranges with the offsets as unknowns, plus Π as
    their prior); a QR factorisation with the offset columns first gives it as ``R_θθᵀ R_θθ``
    without any cancellation (no explicit Woodbury subtraction). Returns ``(Ã2 = R_θθ, I)``:
    in :func:`two_stage_update` it gives the same K', ΔK as ``(A2, D + E Π Eᵀ)`` with an m × m S
    instead of an n2 × n2 one.

    Implements the range information ``A2ᵀ Π⁻¹ A2`` of seed 002 eq. 19 in compressed form.
    """
    a2 = np.asarray(a2, float)
    w = 1.0 / np.sqrt(np.asarray(pi_diag, float))
    e = np.atleast_2d(np.asarray(e, float))
    pi = np.atleast_2d(np.asarray(pi_offsets, float))
    nb, m = pi.shape[0], a2.shape[1]
    chol = np.linalg.cholesky(pi)
    top = np.hstack([e * w[:, None], a2 * w[:, None]])
    bottom = np.hstack([np.linalg.solve(chol, np.eye(nb)), np.zeros((nb, m))])
    r = np.linalg.qr(np.vstack([top, bottom]), mode="r")
    return r[nb:nb + m, nb:], np.eye(m)


def accumulate(estimates, covariance_passes, groups, names):
    """Stage 1: weighted means of per-pass offsets per group, and their error matrix Π.

    ``estimates`` (P,) per-pass offsets, ``covariance_passes`` (P, P) their error matrix
    (diagonal noise part plus any correlated part), ``groups`` (P,) the station of each pass,
    ``names`` the N stations in order. Weights ``1/var_p`` (the diagonal). Returns
    ``(means (N,), Π (N, N), M (N, P))`` with ``means = M estimates``, ``Π = M C Mᵀ``.

    Implements seed 002 eq. 17 (stage 1 of the two-stage method: the offsets accumulated over passes).
    """
    est = np.asarray(estimates, float)
    c = np.asarray(covariance_passes, float)
    groups = np.asarray(groups, dtype=object)
    w = 1.0 / np.diag(c)
    m = np.zeros((len(names), est.size))
    for i, name in enumerate(names):
        sel = groups == name
        if not sel.any():
            raise ValueError(f"no pass of {name!r} to accumulate")
        m[i, sel] = w[sel] / w[sel].sum()
    pi = m @ c @ m.T
    return m @ est, 0.5 * (pi + pi.T), m


def is_psd(matrix, rtol: float = 1e-10) -> bool:
    """Symmetric positive semidefinite within round-off (smallest eigenvalue ≥ -rtol · largest)."""
    a = np.asarray(matrix, float)
    w = np.linalg.eigvalsh(0.5 * (a + a.T))
    return bool(w.min() >= -rtol * max(abs(w.max()), 1e-300))


@dataclass
class TwoStage:
    """Report of the two-stage method: parameter ``names`` (the motion block), ``k`` (without the
    ranges), ``k_prime`` (stage 2), ``delta_k``, the stage-1 offsets ``biases`` (station ->
    value), their error matrix ``pi`` (stations order ``stations``), per-pass table ``passes``
    and the round-off check ``identity_error`` = max |K' - (K - ΔK)| / max |K|.

    Implements seed 002 eqs. 17-22.
    """

    names: list
    k: np.ndarray
    k_prime: np.ndarray
    delta_k: np.ndarray
    stations: list
    biases: np.ndarray
    pi: np.ndarray
    passes: list
    identity_error: float
    delta_k_min_eigenvalue: float
