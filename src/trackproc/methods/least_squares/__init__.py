"""Batch weighted least squares: Gauss-Newton on the whitened system, solved by SVD.

Seed 002 eqs. 4-8: ``Δq = (Aᵀ K⁻¹ A)⁻¹ Aᵀ K⁻¹ Δr``, iterated (Gauss-Newton), and eq. 9: the
error matrix ``K_out = (Aᵀ K⁻¹ A)⁻¹``. Here that is computed without ever forming or inverting
the normal matrix: the residuals and the Jacobian are *whitened* (divided by the measurement
sigmas, so ``K = I``), the columns scaled by the parameters' scales (``x = x_ref + S ξ``), any
a-priori constraints appended as extra whitened rows, and the system ``J ξ ≈ b`` is solved by
the thin SVD ``J = U Σ Vᵀ``:

    step        ξ = V Σ⁻¹ Uᵀ b
    covariance  K_out = S V Σ⁻² Vᵀ S           (= (Aᵀ K⁻¹ A + prior)⁻¹, eq. 9)

which loses no precision to squaring the condition number (the normal matrix would).

Levenberg-Marquardt damping: when the Gauss-Newton step does not reduce the cost, the
damped step ``ξ(λ) = V diag(σᵢ / (σᵢ² + λ)) Uᵀ b`` (the minimiser of ``|J ξ - b|² + λ|ξ|²``,
from the same SVD) is tried with λ growing tenfold until the cost falls.

Convergence: after an accepted step, when the step is below ``step_tol`` formal sigmas in
every parameter, or the relative change of the cost is below ``cost_rtol`` — and the set of
edited samples did not change.

Residual editing (k-sigma, iterated): after every iteration, a sample is edited (excluded,
flagged, still reported) when ``|r/σ| > k · max(1, WRMS)`` with WRMS the RMS of the normalized
residuals of the samples kept in the previous iteration; every sample is re-tested each time,
so a sample edited while the orbit was poor comes back.

Failures raise :class:`~trackproc.errors.ProcessingError` with diagnostics: too few
measurements, rank deficiency (naming the unobservable combinations: the right singular
vectors of the negligible singular values, in parameter names), non-convergence, and a
model that fails (non-finite values).

Pure numpy; the model is a callable ``model(x) -> (computed (N,), jacobian (N, n))``. The problem
(:class:`~.iteration.Problem`) and the iterations (:func:`~.iteration.iterate`) also serve the constrained solver
:func:`trackproc.methods.refinement.solve_kkt`.
"""

from trackproc.methods.least_squares.types import Options, Prior, Solution  # noqa: F401
from trackproc.methods.least_squares.iteration import (  # noqa: F401
    Problem, Run, combination_text, iterate, prior_rhs, prior_rows, whitened_svd)
from trackproc.methods.least_squares.solver import solve, solve_gls  # noqa: F401

__all__ = ["Options", "Prior", "Solution", "solve", "solve_gls", "whitened_svd", "combination_text"]
