"""The integral cost's model (:class:`IntegralModel`: the orbit's range-rate at the quadrature nodes
from the image domain, seed 004 eqs. 6-13 and 18-21, or the round trip) and the sandwich covariance
of its estimate.
"""

from __future__ import annotations

import numpy as np

from trackproc.dynamics import measurement_spectra as ms
from trackproc.dynamics import propagator
from trackproc.methods.least_squares import Solution, prior_rows
from trackproc.models import observation as ob
from trackproc.methods.refinement.quadrature import range_rate_samples


class IntegralModel:
    """Range-rate of the orbit at the quadrature nodes and its gradient, from the DT spectra.

    ``model(x) -> (Vr (K,), ∂Vr/∂x (K, n))`` for ``x = (state at the epoch (6), biases..., [r_ka])``:
    the state is propagated by the Taylor (DT) engine with its sensitivity spectra
    (:func:`trackproc.dynamics.propagator.propagate`, ``stm=True``), and the range and range-rate
    spectra of the station (:func:`trackproc.dynamics.measurement_spectra.predict`: seed 004
    eqs. 7-13 with one-way light time) give ``Vr`` and, through the first-order sensitivities
    (eqs. 19-21), ``∂Vr/∂state``. A bias ``j`` adds ``coefficients[j] * x[6 + j]`` (e.g. ``-c/f``
    for a one-way Doppler offset in Hz, ``-c (t - t0)/f`` for its drift; ``-c/(2f)``,
    ``-c (t - t0)/(2f)`` two-way); trailing entries of ``x`` beyond those (``r_ka``) have no
    effect on ``Vr``.

    **Two-way** (``mode="two-way"``: a coherent round trip, the seed's own ``Vr = c/(2 f0) f_D``
    convention). The image-domain spectra follow the signal down one leg only, so a two-way
    ``Vr`` is the estimator's round-trip model instead:
    :func:`trackproc.models.observation.evaluate` on ``range_rate`` samples with mode
    ``two-way`` at the nodes — the mean of the up- and down-leg rates, both light times solved
    on the same Taylor trajectory (its dense output, GCRF), the station in GCRF
    (:func:`trackproc.models.measurements.station_gcrf`, with its acceleration, at the nodes'
    UTC dates, as :func:`trackproc.pipeline.estimate.build_problem` does). ``∂Vr/∂state`` is
    then the leg partials times the Taylor engine's state transition matrix (its first-order
    sensitivity spectra, eqs. 19-21 in spirit) through both light times (observation eqs. 6,
    11-13): analytic, not finite differences. The node set-up (station track) is built once,
    on the first evaluation.

    Parameters
    ----------
    epoch : datetime64 — the epoch of the state (the traverse point).
    frame : QuasiInertialFrame — the integration frame (the estimation problem's).
    station : :class:`~trackproc.dynamics.measurement_spectra.StationModel` built on ``epoch``
        and ``frame`` (two-way: its ITRF position ``r_itrf_m`` is used).
    t_s : (K,) node times, SI s from the epoch (reception times).
    bias_coefficients : list of (K,) arrays, one per bias parameter.
    force, eop, range_rate_model : as elsewhere.
    mode : ``"one-way"`` (default) or ``"two-way"``.
    """

    def __init__(self, epoch, frame, station, t_s, bias_coefficients=(), *, force: str = "j2", eop=None,
                 range_rate_model: str = "doppler", n_extra: int = 0, mode: str = "one-way"):
        if mode not in ("one-way", "two-way"):
            raise ValueError(f"unknown link mode {mode!r}; expected 'one-way' or 'two-way'")
        self.epoch = epoch
        self.frame = frame
        self.station = station
        self.t_s = np.asarray(t_s, float)
        self.bias = [np.asarray(c, float) for c in bias_coefficients]
        self.force = force
        self.eop = eop
        self.range_rate_model = range_rate_model
        self.n_extra = int(n_extra)
        self.mode = mode
        self.evaluations = 0
        self._nodes = None

    @property
    def n_parameters(self) -> int:
        return 6 + len(self.bias) + self.n_extra

    def trajectory(self, x):
        span = [float(self.t_s.min()) - 1.0, float(self.t_s.max())]
        return propagator.propagate(x[:3], x[3:6], self.epoch, span, force=self.force, stm=True, frame=self.frame,
                                    eop=self.eop).raise_for_outcome()

    def node_measurements(self):
        """The nodes as ``range_rate`` samples of the link (:func:`range_rate_samples`, built once)."""
        if self._nodes is None:
            self._nodes = range_rate_samples(self.epoch, self.station.r_itrf_m, self.t_s, self.mode, self.eop)
        return self._nodes

    def _state_part(self, x, partials: bool = True):
        """``(Vr (K,), ∂Vr/∂state (K, 6))`` of the link (one-way: DT spectra; two-way: round trip);
        ``partials=False``: the same ``Vr``, the sensitivities not computed (None)."""
        traj = self.trajectory(x)
        if self.mode == "two-way":
            value, jac, _ = ob.evaluate(self.node_measurements(), traj, n_state_params=6, n_columns=6,
                                        range_rate_model=self.range_rate_model, partials=partials)
            return value, jac
        pred = ms.predict(traj, self.station, self.t_s, range_rate_model=self.range_rate_model, partials=partials)
        return pred.range_rate_m_s.copy(), pred.d_range_rate_d_state if partials else None

    def values(self, x):
        """``Vr`` alone (the same numbers as the call's, without the sensitivities: a step rule's trial point)."""
        x = np.asarray(x, float)
        try:
            value, _ = self._state_part(x, partials=False)
        except ValueError as exc:
            raise ArithmeticError(str(exc)) from None
        for j, coef in enumerate(self.bias):
            value += coef * x[6 + j]
        self.evaluations += 1
        return value

    def __call__(self, x):
        x = np.asarray(x, float)
        try:
            value, d_state = self._state_part(x)
        except ValueError as exc:
            raise ArithmeticError(str(exc)) from None
        jac = np.zeros((self.t_s.size, x.size))
        jac[:, :6] = d_state
        for j, coef in enumerate(self.bias):
            value += coef * x[6 + j]
            jac[:, 6 + j] = coef
        self.evaluations += 1
        return value, jac


def sandwich_covariance(solution: Solution, sigma_nodes, design_nodes, coefficient_covariance,
                        priors=(), *, rows=None) -> np.ndarray:
    """Covariance of the integral estimate from the smoothing polynomial's coefficient covariance.

    The estimate is a function of the polynomial coefficients C (and of the a-priori centre);
    linearised, ``δξ = K (J_dᵀ Σ⁻¹ Φ δC + J_pᵀ δb_p)`` with ``K`` the solver's covariance of the
    scaled parameters (the constrained one under constraints), ``J_d`` the whitened data rows,
    ``Σ = diag(σ_k)`` the pseudo-sigmas, ``Φ`` (K, m) the basis at the nodes in the units of the
    pseudo-observations, ``Cov(C)`` the coefficient covariance and ``J_p`` the whitened a-priori
    rows (``δb_p ~ N(0, I)``). Returns the physical covariance (n, n).
    """
    sol = solution
    scales = np.asarray(sol.scales, float)
    n = scales.size
    k_scaled = np.asarray(sol.covariance_scaled, float)
    sig = np.asarray(sigma_nodes, float)
    jd = sol.jacobian / sig[:, None] * scales[None, :]
    b = jd.T @ (np.asarray(design_nodes, float) / sig[:, None])          # (n, m)
    middle = b @ np.asarray(coefficient_covariance, float) @ b.T
    if priors:
        pa, _ = prior_rows(priors, n, scales)
        middle = middle + pa.T @ pa
    cov_scaled = k_scaled @ middle @ k_scaled
    cov = cov_scaled * np.outer(scales, scales)
    return 0.5 * (cov + cov.T)
