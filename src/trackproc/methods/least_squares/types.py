"""The solver's options, the a-priori terms and the solution (seed 002 eq. 9: the error matrix).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np



@dataclass
class Options:
    """Settings of :func:`solve`.

    ``max_iterations``: Gauss-Newton iterations (each may try several damped steps);
    ``step_tol``: converged when every step component is below this many formal sigmas;
    ``cost_rtol``: or when the relative cost change is below this;
    ``clip``: k of the k-sigma editing (None or 0: no editing);
    ``rank_rtol``: a singular value below ``rank_rtol * max`` (of the whitened, scaled
    Jacobian) is a rank deficiency; ``max_damping_tries``: damped steps tried per iteration.
    """

    max_iterations: int = 20
    step_tol: float = 1e-3
    cost_rtol: float = 1e-9
    clip: Optional[float] = 4.0
    rank_rtol: float = 1e-9
    max_damping_tries: int = 12
    initial_damping: float = 1e-4


@dataclass(frozen=True)
class Prior:
    """An a-priori constraint ``x[index] ~ N(centre, covariance)`` (index into the parameters)."""

    index: np.ndarray
    centre: np.ndarray
    covariance: np.ndarray

    @classmethod
    def diagonal(cls, index, centre, sigma) -> "Prior":
        sigma = np.asarray(sigma, float)
        return cls(np.asarray(index, int), np.asarray(centre, float), np.diag(sigma ** 2))


@dataclass
class Solution:
    """Result of :func:`solve`.

    Parameters: ``names``, ``values``, physical ``covariance`` (seed 002 eq. 9, including any a-priori
    information), ``sigma``, ``correlation``, ``covariance_scaled`` (of ξ = (x - x_ref)/scale:
    Orekit's "normalized" covariance), ``scales``.

    Statistics: ``chi2`` (sum of squared normalized residuals of the kept samples plus the
    a-priori terms), ``dof`` (kept samples + a-priori rows - parameters), ``variance_factor``
    (a-posteriori variance factor = chi2/dof, the reduced χ²; NaN when dof = 0),
    ``condition_number`` (of the whitened, scaled Jacobian), ``singular_values``.

    Samples (all N, edited ones included): ``computed``, ``residual`` (observed - computed,
    azimuth wrapped), ``normalized`` (residual/sigma), ``edited`` (bool), ``jacobian`` (N, n)
    at the solution.

    Run: ``iterations``, ``converged``, ``cost_history``, ``damped_steps``, ``message``.
    A-priori: ``n_prior`` constraint rows and their share of chi2, ``chi2_prior`` (a large value
    means the data pulled the solution far from the a-priori values).
    """

    names: list
    values: np.ndarray
    covariance: np.ndarray
    sigma: np.ndarray
    correlation: np.ndarray
    covariance_scaled: np.ndarray
    scales: np.ndarray
    chi2: float
    dof: int
    variance_factor: float
    condition_number: float
    singular_values: np.ndarray
    computed: np.ndarray
    residual: np.ndarray
    normalized: np.ndarray
    edited: np.ndarray
    jacobian: np.ndarray
    iterations: int
    converged: bool
    cost_history: list = field(default_factory=list)
    damped_steps: int = 0
    message: str = ""
    chi2_prior: float = 0.0
    n_prior: int = 0

    @property
    def n_measurements(self) -> int:
        return int(self.edited.size)

    @property
    def n_edited(self) -> int:
        return int(self.edited.sum())

    @property
    def wrms(self) -> float:
        """RMS of the normalized residuals of the kept samples."""
        z = self.normalized[~self.edited]
        return float(np.sqrt(np.mean(z * z))) if z.size else math.nan

    def block(self, names: Sequence[str]) -> np.ndarray:
        """Covariance block of the named parameters."""
        idx = [self.names.index(n) for n in names]
        return self.covariance[np.ix_(idx, idx)]
