"""SGP4's theory error in a TLE fit (issue 18): generalised least squares when every pass also
carries an error of SGP4 itself, independent from pass to pass (:func:`mixed_model_step`), and
the a-priori conflict test under that error model (:func:`apriori_conflict_chi2`). The elements
and their order are :mod:`trackproc.methods.tle_fit`'s.
"""

from __future__ import annotations

import numpy as np


#: SGP4's own (theory) error at a pass of a TLE fitted to passes (on DopTrack mostly the
#: station's per-pass timing), a per-pass random effect independent from pass to pass, with the
#: shape of the default a-priori (refine's element sigmas: e 5e-5, i and Ω 1e-4 rad, argument of
#: latitude 4e-4 rad; mean motion and B* none) scaled by this factor: the default of
#: ``--model-error``. Its provenance: the maximum-likelihood scale over the 68 DopTrack Delfi-C3
#: development pairs (1-10 April 2020; −2 log L 781, 669, 677 at 2, 3.4, 5;
#: ``benchmarks/fit_tle_doptrack.py`` :func:`honesty_rows`, docs/fit-tle.md "Covariance").
MODEL_ERROR_SCALE = 3.4


def model_error_covariance(scale: float, apriori_sigmas) -> np.ndarray:
    """The covariance (7, 7) of SGP4's theory error at one pass, expressed in the fitted
    elements: ``scale`` times the default a-priori's independent element sigmas (``apriori_sigmas``,
    :func:`trackproc.methods.tle_fit.element_sigmas`), mean motion and B* excluded: a pass's error is a displacement at that
    pass (along-track through λ, radial through e, cross-track through i and Ω), not one that
    grows with the pass's distance from the epoch as a mean-motion error would (with it, the
    DopTrack development predictions were covered 2x too loosely a day ahead and too tightly
    within hours: docs/fit-tle.md). Its effect on a pass's samples is ``J η``, ``J`` the pass's
    partials."""
    s = np.asarray(apriori_sigmas, float).copy()
    s[0] = 0.0
    s[6] = 0.0
    return np.diag(np.square(float(scale) * s))


def pass_information(jac, weights, design) -> np.ndarray:
    """The information (m, m) one pass's samples carry on the free elements, its own nuisance
    columns (offset, drift) profiled out: ``Jᵀ W J − Jᵀ W B (Bᵀ W B)⁻¹ Bᵀ W J`` (``weights`` are
    ``1/σ``; rows edited out have weight 0)."""
    a = np.asarray(jac, float) * np.asarray(weights, float)[:, None]
    info = a.T @ a
    b = np.asarray(design, float)
    if b.size:
        bw = b * np.asarray(weights, float)[:, None]
        keep = np.any(bw != 0.0, axis=0)
        if keep.any():
            bw = bw[:, keep]
            cross = a.T @ bw
            info = info - cross @ np.linalg.pinv(bw.T @ bw) @ cross.T
    return 0.5 * (info + info.T)


def mixed_model_step(x, covariance, informations, gradients, q_free, other_information, other_gradient):
    """Generalised least squares when every pass also carries SGP4's theory error ``η_p ~ N(0,
    Q)``, independent per pass (a random effect; its samples are correlated through ``J_p η_p``):
    from the least-squares solution ``x`` (covariance ``C``, free elements), one Gauss-Newton step
    with each pass's information and gradient deflated by the theory error,

        A'_p = A_p (I + Q A_p)⁻¹,   g'_p = (I + A_p Q)⁻¹ g_p

    (``Jᵀ (R + J Q Jᵀ)⁻¹ J`` and ``Jᵀ (R + J Q Jᵀ)⁻¹ r`` by the Woodbury identity), ``A_p`` the
    pass's information (:func:`pass_information`), ``g_p = Jᵀ R⁻¹ r`` its gradient at ``x``
    (nuisance terms at their optimum); ``other_information`` and ``other_gradient`` those of
    everything else (the a-priori ``P⁻¹`` and ``P⁻¹ (x_p − x)``, ephemerides). Returns ``(x', C')``,
    ``C' = (P⁻¹ + Σ A'_p)⁻¹`` (Tapley,
    Schutz & Born 2004, section 4.6: correlated observation errors; a linear step, the theory error
    being the larger error the fit's least-squares weights left out)."""
    if not informations:
        return np.asarray(x, float), np.asarray(covariance, float)
    normal, rhs = deflated_normal(informations, gradients, q_free, other_information, other_gradient)
    cov = np.linalg.pinv(normal, hermitian=True)        # positive semi-definite even when ill-conditioned
    return np.asarray(x, float) + cov @ rhs, 0.5 * (cov + cov.T)


def deflated_normal(informations, gradients, q_free, other_information, other_gradient) -> tuple:
    """The normal matrix and right-hand side of generalised least squares when every pass also
    carries SGP4's theory error ``η_p ~ N(0, Q)``: ``Σ A_p (I + Q A_p)⁻¹ + other_information``
    and ``Σ (I + A_p Q)⁻¹ g_p + other_gradient`` (``Jᵀ (R + J Q Jᵀ)⁻¹ J`` and ``Jᵀ (R + J Q
    Jᵀ)⁻¹ r`` per pass by the Woodbury identity; :func:`mixed_model_step`). ``Q = 0`` gives
    plain least squares' sums."""
    m = len(q_free)
    eye = np.eye(m)
    normal = np.asarray(other_information, float).copy()
    rhs = np.asarray(other_gradient, float).copy()
    for a, g in zip(informations, gradients):
        normal += a @ np.linalg.inv(eye + q_free @ a)
        rhs += np.linalg.solve(eye + a @ q_free, g)
    return 0.5 * (normal + normal.T), rhs


#: Directions whose data information is below this fraction of the a-priori's (or of the largest
#: direction's, when the data dominate) are left out of :func:`apriori_conflict_chi2`: there the
#: eigen-decomposition is rounding, and the data cannot contradict the a-priori anyway.
CONFLICT_RELATIVE_FLOOR = 1e-10


def apriori_conflict_chi2(score, data_information, prior_cov) -> tuple:
    """The a-priori conflict test of a fit (reason ``apriori_conflict``): do the data contradict
    the initial orbit's a-priori ``x_p ~ N(x_true, P)`` under the SAME error model the fit uses?
    A score (Rao) test of ``x_true = x_p``,

        T = bᵀ (A + A P A)⁺ b,   b = g(x̂) + A (x̂ − x_p),

    ``A`` the data's information on the free elements and ``g(x̂)`` their gradient ``Jᵀ V⁻¹ r``
    at the solution ``x̂`` (nuisance terms profiled out; with SGP4's theory error ``V = R + J Q
    Jᵀ`` per pass: :func:`deflated_normal`), so that ``b`` is the data's gradient at ``x_p``
    (linearised at ``x̂``). Under the model ``b = A (x̂_d − x_p)`` with ``x̂_d`` the data-only
    estimate, ``x̂_d − x_p ~ N(0, P + A⁻¹)``: ``b ~ N(0, A + A P A)`` and ``T ~ χ²(rank A)``.
    Equivalently (``A`` invertible) ``T = (x̂_d − x_p)ᵀ (P + A⁻¹)⁻¹ (x̂_d − x_p)``, the
    innovation of the a-priori against the a-priori plus the data's own covariance, and ``T =
    (x̂ − x_p)ᵀ (P − C)⁻¹ (x̂ − x_p)`` with ``x̂`` the (generalised) least-squares solution
    with the a-priori and ``C = (P⁻¹ + A)⁻¹`` its covariance (``P − C`` is the covariance of ``x̂
    − x_p``; Tapley, Schutz & Born 2004, section 4.4 for the combination). Unlike the
    a-priori's share of the cost at the solution, ``(x̂ − x_p)ᵀ P⁻¹ (x̂ − x_p)`` (distributed as
    ``Σ λ_k/(1+λ_k) χ²₁``), it keeps its power where the data are weak against the a-priori: a
    pass whose theory error is large against a tight TLE a-priori moves ``x̂`` little even when
    it contradicts ``x_p`` by many of its own sigmas.

    Computed in the a-priori's whitened coordinates (``P = L Lᵀ``, ``Ã = Lᵀ A L = V diag(λ)
    Vᵀ``, ``β = Vᵀ Lᵀ b``): ``T = Σ β_k² / (λ_k (1 + λ_k))`` over the directions with ``λ_k``
    above :data:`CONFLICT_RELATIVE_FLOOR` (times ``max(1, max λ)``). Returns ``(T, number of
    directions used)``."""
    p = np.asarray(prior_cov, float)
    low = np.linalg.cholesky(0.5 * (p + p.T))
    a = low.T @ np.asarray(data_information, float) @ low
    lam, vec = np.linalg.eigh(0.5 * (a + a.T))
    beta = vec.T @ (low.T @ np.asarray(score, float))
    use = lam > CONFLICT_RELATIVE_FLOOR * max(1.0, float(lam.max(initial=0.0)))
    return float(np.sum(beta[use] ** 2 / (lam[use] * (1.0 + lam[use])))), int(use.sum())
