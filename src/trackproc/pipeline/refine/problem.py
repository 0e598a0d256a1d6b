"""The assembled refinement (:class:`Refinement`): the estimator's problem with the a-priori,
its models, the pointwise and the GLS solves (constrained under ``circular``, seed 004 eqs. 5 and
15-17), the profile covariance and the reported covariance.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from trackproc.methods import refinement as rf
from trackproc.methods.least_squares import Options, Prior, solve, solve_gls
from trackproc.models import modifiers as md
from trackproc.methods.refinement import (ELEMENT_NAMES, CachedModel, circular_constraints, constraint_scales,
                                           element_covariance, geodesic_retraction, profile_mixture, solve_kkt,
                                           solve_soft_kkt)
from trackproc.methods.estimation.prior import default_apriori_covariance, state_prior_covariance  # noqa: F401
from trackproc.methods.whitening import PassCovariance
from trackproc.pipeline.refine.options import RefineOptions, SmoothedCurve


def link_mode(ref: Refinement) -> str:
    """``"two-way"`` when the pass's samples are modelled as round trips, else ``"one-way"``."""
    return "two-way" if bool(np.any(ref.problem.meas.two_way)) else "one-way"


@dataclass
class Refinement:
    """An assembled refinement, reusable (e.g. Monte Carlo): :func:`prepare` builds it,
    :meth:`solve` solves it (optionally with other observations and another a-priori centre),
    :func:`refine` turns a solution into the outputs."""

    options: RefineOptions
    problem: object
    curve: SmoothedCurve
    kind: str
    station_name: str
    pass_id: str
    initial: object
    stale_epoch: np.datetime64
    traverse_how: str
    names: list
    x0: np.ndarray
    scales: np.ndarray
    priors: list
    apriori_note: str
    station_model: object
    mu: float
    carrier_hz: float
    station_axis: np.ndarray
    integral: Optional[dict] = None
    warnings: list = field(default_factory=list)
    #: correlated-noise model of the samples (:class:`~trackproc.methods.noise.PassCovariance`), None = white
    noise: Optional[object] = None
    #: samples edited when the noise model was fitted (the GLS starts from them)
    noise_edited: Optional[np.ndarray] = None
    #: what :func:`noise_model` found (written to the diagnostics)
    noise_report: Optional[dict] = None
    #: where the state's a-priori came from (:data:`trackproc.methods.estimation.prior.SOURCES`; "" = none)
    apriori_source: str = ""
    #: the station's ``time_sigma_s`` (stations table or pass metadata; None = not given)
    station_time_sigma_s: Optional[float] = None
    #: :func:`~trackproc.pipeline.refine.traverse.model_traverse` by solution bytes: the traverse
    #: loop's last call and the result's are the same propagation (a ``replace`` starts it empty)
    traverse_memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def time_tag_sigma(self) -> tuple:
        """``(sigma_s, source)`` of the time-tag consider parameter: ``--time-tag-sigma`` when
        given (0 included), else the station's ``time_sigma_s``; ``(0.0, "")`` without either."""
        if self.options.time_tag_sigma_s is not None:
            return float(self.options.time_tag_sigma_s), "--time-tag-sigma"
        if self.station_time_sigma_s is not None:
            return float(self.station_time_sigma_s), "station table"
        return 0.0, ""

    @property
    def n_problem(self) -> int:
        return len(self.problem.names)

    def modifier_drivers(self, *kinds) -> list:
        """The estimated drivers of the problem's measurement modifiers of the classes ``kinds``
        (:mod:`trackproc.models.modifiers`), in the order of the parameters."""
        return [d for b in self.problem.modifiers if isinstance(b.modifier, kinds)
                for d in b.modifier.parameter_drivers() if d.selected]

    def oscillator_wander(self):
        """The :class:`~trackproc.models.modifiers.OscillatorWander` acting on the pass's samples
        (a one-way link with a frequency offset; a coherent two-way link has no free oscillator), or None."""
        return next((b.modifier for b in self.problem.modifiers
                     if isinstance(b.modifier, md.OscillatorWander) and b.rows.size), None)

    def oscillator_link(self) -> bool:
        """The pass's transmitter frequency can wander (:meth:`oscillator_wander`)."""
        return self.oscillator_wander() is not None

    # -- models ------------------------------------------------------------------------------
    def pointwise_model(self, x):
        h, jac = self.problem.model(np.asarray(x, float)[: self.n_problem])
        if len(self.names) > self.n_problem:
            jac = np.hstack([jac, np.zeros((jac.shape[0], len(self.names) - self.n_problem))])
        return h, jac

    def pointwise_values(self, x):
        """:meth:`pointwise_model`'s values alone (the same numbers, no Jacobian)."""
        return self.problem.values(np.asarray(x, float)[: self.n_problem])

    def values_function(self):
        """The values-only function of :meth:`data`'s model (for a step rule's trial point)."""
        return self.integral["model"].values if self.options.cost == "integral" else self.pointwise_values

    def constraints(self, x):
        return circular_constraints(x, self.mu, rka_index=len(self.names) - 1)

    def constraint_scale(self, x):
        return constraint_scales(x, self.mu, rka_index=len(self.names) - 1)

    def data(self):
        """``(model, observed, sigma, periodic, clip)`` of the chosen cost."""
        if self.options.cost == "integral":
            d = self.integral
            return d["model"], d["observed"], d["sigma"], None, None
        meas = self.problem.meas
        return self.pointwise_model, meas.observed, meas.sigma, meas.periodic, self.options.clip

    def correlated(self) -> bool:
        """True when the samples carry a correlated-noise model (the solve is then GLS)."""
        return self.noise is not None and not self.noise.is_white and self.options.cost == "pointwise"

    def whitened(self, keep, sigma_scale=1.0, observed=None):
        """The GLS system of the kept samples: ``(model_w, y_w)`` with ``model_w(x) = (L⁻¹ h, L⁻¹ J)``
        and ``y_w = L⁻¹ y`` (``C = L Lᵀ`` of :attr:`noise` over the kept samples, times
        ``sigma_scale²``): independent samples of unit sigma."""
        model, y, _, _, _ = self.data()
        if observed is not None:
            y = np.asarray(observed, float)
        w = self.noise.whitener(np.asarray(keep, bool))
        k = 1.0 / sigma_scale

        def model_w(x):
            h, jac = model(x)
            return w(h) * k, w(jac) * k

        return model_w, w(y) * k

    def solve(self, observed=None, prior_centre=None, x0=None, sigma_scale=1.0):
        """Solve (``observed`` replaces the data: the samples, or the curve at the nodes;
        ``prior_centre`` (6,) the stale state at the traverse epoch; ``sigma_scale`` multiplies
        the data sigmas). Returns ``(Solution, KKTResult or None)``. With a correlated-noise
        model (:meth:`correlated`) the problem is solved by GLS (:meth:`solve_gls`)."""
        if self.correlated():
            return self.solve_gls(observed, prior_centre, x0, sigma_scale)
        model, y, sigma, periodic, clip = self.data()
        sigma = np.asarray(sigma, float) * sigma_scale
        if observed is not None:
            y = np.asarray(observed, float)
        priors = self.priors_at(prior_centre)
        start = self.x0 if x0 is None else np.asarray(x0, float)
        opts = Options(max_iterations=self.options.max_iterations, clip=clip, rank_rtol=self.options.rank_rtol)
        model = CachedModel(model, values=self.values_function())
        retract = geodesic_retraction(model, sigma, self.scales, priors)
        if self.options.circular:
            kkt = self.solve_circular(model, start, y, sigma, priors=priors, periodic=periodic, options=opts,
                                      retract=retract)
            return kkt.solution, kkt
        lo, hi = self.bounds()
        return solve(model, start, y, sigma, names=self.names, scales=self.scales, priors=priors, periodic=periodic,
                     bounds=(lo, hi), options=opts, retract=retract), None

    def solve_circular(self, model, start, y, sigma, **kw):
        """The circular-orbit constraints of seed 004 eq. 5: exact (:func:`solve_kkt`, the seed's
        Lagrange multipliers), or with ``circular_tolerance`` soft, ``f(x) = ε`` with ε of the
        covariance an orbit circular to that eccentricity has (:func:`circular_tolerance_covariance`;
        ``|r| = r_ka`` stays exact), solved by :func:`solve_soft_kkt`."""
        common = dict(names=self.names, constraints=self.constraints, constraint_scale=self.constraint_scale,
                      scales=self.scales, **kw)
        tol = self.tolerance()
        if tol > 0:
            def sigma_eps(x):
                return rf.circular_tolerance_covariance(x, self.mu, tol)

            return solve_soft_kkt(model, start, y, sigma, constraint_covariance=sigma_eps, **common)
        return solve_kkt(model, start, y, sigma, **common)

    def bounds(self):
        lo, hi = self.problem.params.bounds()
        return (np.r_[lo, [-np.inf] * (len(self.names) - lo.size)], np.r_[hi, [np.inf] * (len(self.names) - hi.size)])

    def solve_gls(self, observed=None, prior_centre=None, x0=None, sigma_scale=1.0):
        """Generalised least squares with the correlated-noise model (:attr:`noise`):
        :func:`trackproc.methods.least_squares.solve_gls` (whitened kept samples, editing on the
        innovations) with this refinement's solver (constrained under ``circular``)."""
        model, y, _, _, clip = self.data()
        if observed is not None:
            y = np.asarray(observed, float)
        priors = self.priors_at(prior_centre)
        lo, hi = self.bounds()
        opts = Options(max_iterations=self.options.max_iterations, clip=None, rank_rtol=self.options.rank_rtol)

        def fit(model_w, y_w, start):
            cached = CachedModel(model_w, values=model_w.values)
            ones = np.ones(y_w.size)
            retract = geodesic_retraction(cached, ones, self.scales, priors)
            if self.options.circular:
                kkt = self.solve_circular(cached, start, y_w, ones, priors=priors, options=opts, retract=retract)
                return kkt.solution, kkt
            return solve(cached, start, y_w, ones, names=self.names, scales=self.scales, priors=priors,
                         bounds=(lo, hi), options=opts, retract=retract), None

        sol, kkt = solve_gls(model, self.x0 if x0 is None else np.asarray(x0, float), y, self.noise, fit, clip=clip,
                             sigma_scale=sigma_scale, edited=self.noise_edited, values=self.values_function())
        if kkt is not None:
            kkt = replace(kkt, solution=sol)
        return sol, kkt

    def priors_at(self, prior_centre=None) -> list:
        """The a-priori terms, centred on ``prior_centre`` (6,) instead of the stale state if given."""
        if prior_centre is None:
            return list(self.priors)
        out = []
        for p in self.priors:
            centre = np.asarray(p.centre, float).copy()
            sel = np.asarray(p.index) < 6
            centre[sel] = np.asarray(prior_centre, float)[np.asarray(p.index)[sel]]
            out.append(Prior(p.index, centre, p.covariance))
        return out

    def profile_covariance(self, sol, obs, sigma_scale: float = 1.0, prior_centre=None) -> np.ndarray:
        """The covariance of a pointwise solution with the curvature along the directions the pass
        cannot see (:func:`trackproc.methods.refinement.profile_mixture`): for each unseen
        direction ``i`` (``obs.dual[i]``), the refinement is solved again with that coordinate
        held at the Gauss-Hermite nodes of its posterior (linear equality constraint, KKT), and
        the conditional solutions and covariances are mixed. The data are the solution's own
        (``computed + residual``, the same editing); ``prior_centre`` as in :meth:`solve`.
        Raises :class:`ProcessingError` if a profile point cannot be solved."""
        model, _, sigma, periodic, _ = self.data()
        keep = ~np.asarray(sol.edited, bool)
        y = (np.asarray(sol.computed, float) + np.asarray(sol.residual, float))[keep]
        sigma = (np.asarray(sigma, float) * sigma_scale)[keep]
        periodic = None if periodic is None else np.asarray(periodic)[keep]

        def kept(x):
            h, jac = model(x)
            return h[keep], jac[keep]

        if self.correlated():        # GLS: the whitened kept samples, unit sigmas
            y_all = np.asarray(sol.computed, float) + np.asarray(sol.residual, float)
            kept, y = self.whitened(keep, sigma_scale, y_all)
            sigma, periodic = np.ones(y.size), None

        x_hat = np.asarray(sol.values, float)
        cov = np.asarray(sol.covariance, float)
        n = x_hat.size
        priors = self.priors_at(prior_centre)
        opts = Options(max_iterations=self.options.max_iterations, clip=None, rank_rtol=self.options.rank_rtol)
        cached = CachedModel(kept, size=32)   # all the profile solves: each starts from x_hat
        out = cov.copy()
        for i in obs.unobservable:
            row = np.r_[obs.dual[i], np.zeros(n - 6)]
            gain = cov @ row
            sigma_i = float(np.sqrt(row @ gain))

            def fixed(target, row=row, sigma_i=sigma_i, gain=gain):
                # the centre node is the solution itself, with the Gaussian conditional covariance
                # (what the constrained solve returns there, without its model evaluations); the
                # others start from the linear conditional mean, which lies on the constraint
                if target == 0.0:
                    return x_hat, cov - np.outer(gain, gain) / sigma_i ** 2

                def constraint(x):
                    return np.array([row @ (x - x_hat) - target]), row[None, :]

                start = x_hat + gain * (target / sigma_i ** 2)
                k = solve_kkt(cached, start, y, sigma, names=self.names, constraints=constraint,
                              constraint_scale=lambda x: np.array([max(sigma_i, 1.0)]), scales=self.scales,
                              priors=priors, periodic=periodic, options=opts, diagnostics=False)
                return k.solution.values, k.solution.covariance

            out += profile_mixture(fixed, x_hat, sigma_i) - cov
        return out

    def tolerance(self) -> float:
        """The eccentricity tolerance of ``--circular`` (0 unless given)."""
        return float(self.options.circular_tolerance or 0.0)

    def covariance(self, sol, kkt=None, priors=None) -> np.ndarray:
        """The reported covariance: the solver's (pointwise; with ``circular_tolerance`` the soft
        constraints' Laplace covariance, :func:`solve_soft_kkt`) or the sandwich (integral; with
        soft constraints on the joint problem in the state and the constraint values, whose
        a-priori enters as one more a-priori term)."""
        if self.options.cost != "integral":
            return sol.covariance
        d = self.integral
        if kkt is None or kkt.soft is None:
            priors = list(self.priors if priors is None else priors)
            return rf.sandwich_covariance(sol, d["sigma"], d["design"], d["coefficient_covariance"], priors)
        n = len(sol.values)
        return self.joint_covariance(sol, kkt, priors)[:n, :n]

    def joint_covariance(self, sol, kkt, priors=None) -> np.ndarray:
        """Integral cost with soft constraints (``--circular-tolerance``): the sandwich covariance of
        the joint problem in the state and the soft constraint values ``ε`` (their a-priori one
        more a-priori term), ``(n + s, n + s)``: the state block is :meth:`covariance`, the ``ε``
        block what the pass and the smoothed curve's own error leave of the tolerance."""
        d = self.integral
        priors = list(self.priors if priors is None else priors)
        n = len(sol.values)
        cov_j, jac_j, scales_j = kkt.joint()
        soft = np.flatnonzero(kkt.soft)
        sigma_eps = rf.circular_tolerance_covariance(sol.values, self.mu, self.tolerance())[np.ix_(soft, soft)]
        joint = replace(sol, covariance_scaled=cov_j, jacobian=jac_j, scales=scales_j)
        prior_eps = Prior(n + np.arange(soft.size), np.zeros(soft.size), sigma_eps)
        return rf.sandwich_covariance(joint, d["sigma"], d["design"], d["coefficient_covariance"],
                                      priors + [prior_eps])

    def soft_sigma(self, kkt) -> np.ndarray:
        """1-σ of the soft constraint values of a ``--circular-tolerance`` solution: the joint
        sandwich's for the integral cost (as its state covariance), the Laplace covariance of the
        soft-constrained MAP problem otherwise."""
        if self.options.cost == "integral":
            n = len(kkt.solution.values)
            return np.sqrt(np.clip(np.diag(self.joint_covariance(kkt.solution, kkt)[n:, n:]), 0.0, None))
        return np.sqrt(np.diag(kkt.target_covariance))


def with_noise_of(target: Refinement, source: Refinement, *, same_samples: bool = True) -> Refinement:
    """``target`` (the pass of ``source`` at another solution epoch, or with samples removed) with
    ``source``'s noise model, REML not run again: the model depends on the sample times'
    differences only, so it carries over with each block's walk start moved by the shift of the
    time axis.

    ``same_samples``: ``target`` has ``source``'s samples (a traverse re-solve moves the epoch by
    seconds): the blocks keep their samples, the shift is that of the first sample's time, and the
    samples edited in the fit stay edited. Otherwise (a second signal's samples removed) every block
    spans all of ``target``'s samples, the shift is that of the epoch, and nothing starts edited."""
    edited = source.noise_edited if same_samples else None
    if source.noise is None:
        return replace(target, noise=None, noise_edited=edited, noise_report=source.noise_report)
    t = target.problem.meas.t_s
    if same_samples:
        shift = float(np.min(t) - np.min(source.problem.meas.t_s))
        blocks = [(idx, model, t0 + shift) for idx, model, t0 in source.noise.blocks]
    else:
        shift = float((source.problem.epoch - target.problem.epoch) / np.timedelta64(1, "ns")) * 1e-9
        blocks = [(np.arange(t.size), model, t0 + shift) for _, model, t0 in source.noise.blocks]
    return replace(target, noise=PassCovariance(target.problem.meas.sigma, t, blocks), noise_edited=edited,
                   noise_report=source.noise_report)
