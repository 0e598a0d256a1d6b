"""``trackproc refine``: refine a stale orbit from one Doppler pass of one station (seed 004).

Input: one pass of one station (one- or two-way Doppler or range-rate; raw from ``ingest``/``simulate``
or smoothed by ``smooth``), a stale state (state file, or a TLE evaluated by SGP4 at the traverse
epoch) with an optional covariance, and the station (from ``--stations`` or the pass metadata).

1. **The smoothed curve** (seed 004 eq. 1): the polynomial ``smooth`` stored in the file's
   metadata for this station, pass and kind, or, for a raw pass, the same fit made here
   (:func:`trackproc.pipeline.smooth.smooth`).
2. **The traverse point**: the time of closest approach of that curve (the zero of the
   range-rate; for one-way Doppler, whose transmitter offset is unknown, the inflection point of
   the S-curve, which an offset or a linear drift does not move). The refined state is the GCRF
   state at that epoch; ``r_ka`` is its radius (seed 004 eq. 5).
3. **The problem**: :func:`trackproc.pipeline.estimate.build_problem` with the solution epoch at
   the traverse point: the parameter registry (state, ``doppler_offset:PASS`` and
   ``doppler_drift:PASS`` for one-way Doppler), the measurement model (one-way light time, or
   the round trip of a two-way pass, partials through the light times) and the a-priori
   constraints (the stale covariance moved to the traverse epoch by the state transition
   matrix, or ``--apriori-sigma``, or the documented default :data:`DEFAULT_APRIORI_ELEMENTS`).
4. **The cost**:

   * ``pointwise`` (default, the practical method): weighted least squares on the samples
     themselves with the stale state as an a-priori, solved by
     :func:`trackproc.methods.least_squares.solve` on the estimator's model. A single pass
     cannot determine all six elements; the a-priori keeps the unseen directions where the
     stale state put them, with their stale uncertainty, instead of letting them diverge. Its
     covariance adds to the linear one the curvature along those unseen directions
     (:meth:`Refinement.profile_covariance`; ``covariance="linear"`` leaves it out).
   * ``integral`` (the seed's method): seed 004 eq. 14 by Gauss-Legendre quadrature on the
     smoothed polynomial, the orbit's range-rate and its gradient from the DT spectra
     (:class:`trackproc.methods.refinement.IntegralModel`; for a two-way pass, the seed's own
     ``Vr = c/(2 f0) f_D``, the round-trip model and the Taylor STM), no a-priori unless asked.
     Its covariance propagates the polynomial's coefficient covariance through the estimator
     (:func:`~trackproc.methods.refinement.sandwich_covariance`).

   ``circular=True`` adds the circular-orbit constraints of eq. 5 with ``r_ka`` as a seventh
   parameter, solved by Lagrange multipliers (:func:`~trackproc.methods.refinement.solve_kkt`).
5. **Outputs**: the refined state at the traverse point and at the stale epoch (both with the
   covariance), constraint residuals (and multipliers), an observability report, residuals at
   the samples and the iterations.

:func:`traverse_station` places a station so that a given state is the traverse point of a
visible pass: the seed 004 Table 1 scenario.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Mapping, Optional

import numpy as np
import pandas as pd

from trackproc import vocabulary
from trackproc.constants import C_LIGHT
from trackproc.vocabulary import REFINE_DOPPLER_BIASES
from trackproc.errors import InputError, ProcessingError
from trackproc.io.passfile import PassTable

COSTS = ("pointwise", "integral")
DOPPLER_BIAS = REFINE_DOPPLER_BIASES
#: Range-rate-like kinds a Doppler station gives, in order of preference.
RANGE_RATE_KINDS = ("doppler", "range_rate")
#: ``--circular`` is reported as contradicted by the pass below this p-value (:func:`circular_consistency`).
CIRCULAR_TEST_P = 1e-3
#: Links (the pass metadata's ``doppler_mode``): both costs take either.
LINK_MODES = vocabulary.LINK_MODES
#: The a-priori of a stale state that carries no covariance, as independent 1-sigma errors of
#: its non-singular orbital elements (:func:`trackproc.methods.refinement.element_covariance`):
#: a state a day or so old (a TLE, an old solution) is off by kilometres along-track (the
#: phase ``u``: 4e-4 rad = 2.9 km at 7200 km) but knows its period well (``a``: 50 m) and its
#: plane and shape to hundreds of metres (``e`` 5e-5, ``i`` and ``raan`` 1e-4 rad). In RTN at
#: 7200 km: about 360 m radial, 2.9 km along-track, 720 m cross-track, 3 / 0.4 / 0.7 m/s.
#: Pointwise: when the a-posteriori variance factor exceeds this, the sample sigmas are scaled by
#: its square root and the fit repeated (at most :data:`MAX_REWEIGHT` times), so that the stale
#: state and the pass are weighed by the pass's actual scatter, not by nominal sigmas.
REWEIGHT_THRESHOLD = 1.5
MAX_REWEIGHT = 6
#: At most this many re-solves with the a-priori scaled by its variance component (:func:`solve_adapted`).
MAX_APRIORI_ADAPT = 8
MAX_ADAPT_ITERATIONS = 12
#: :func:`refine` re-solves at the refined orbit's own zero range-rate until it is within this of
#: the solution epoch (at most :data:`MAX_TRAVERSE_ITERATIONS` times; else ``traverse_mismatch``).
TRAVERSE_TOLERANCE_S = 0.5
MAX_TRAVERSE_ITERATIONS = 3
#: A pass whose highest elevation is below this gives a weak refinement (see docs/refine.md).
LOW_PASS_DEG = 25.0
DEFAULT_APRIORI_ELEMENTS = {"a_m": 50.0, "ex": 5e-5, "ey": 5e-5, "i_rad": 1e-4, "raan_rad": 1e-4, "u_rad": 4e-4}


@dataclass
class RefineOptions:
    """Options of :func:`refine` (defaults = the CLI's).

    ``cost``: ``"pointwise"`` or ``"integral"``; ``circular``: the constraints of seed 004
    eq. 5; ``doppler_bias``: ``"none"``, ``"offset"``, ``"offset+drift"`` or None (= ``offset``
    for one-way Doppler, ``none`` for range-rate); ``apriori``: use the stale state as an
    a-priori (None = yes for ``pointwise``, no for ``integral``); ``apriori_sigma``: name ->
    1-sigma (as ``estimate --apriori-sigma``), overriding the stale covariance and the default;
    ``pass_id``/``kind``: which pass and kind when the file holds several; quadrature:
    ``quadrature_order`` nodes per panel of at most ``quadrature_panel_s`` seconds, over the
    parts of the pass without gaps longer than ``max_gap_s``; ``circular_tolerance``: the
    eccentricity to which the orbit is taken to be circular under ``circular``: it adds the
    covariance of an approximate constraint (:func:`~trackproc.methods.refinement.constraint_error_covariance`);
    0 (the default, the seed's assumption) makes the covariance conditional on an exactly circular
    orbit. With J2 the osculating eccentricity of a mean-circular LEO orbit swings by
    ``1.5 J2 (Re/r)^2`` (about 1e-3): see docs/refine.md before trusting a conditional covariance.
    ``reweight``: weigh the data by their actual scatter (:data:`REWEIGHT_THRESHOLD`).
    ``covariance``: ``"profile"`` (pointwise without ``circular``: the linear covariance plus the
    curvature along the directions the pass cannot see, :meth:`Refinement.profile_covariance`)
    or ``"linear"``.
    ``noise`` (pointwise): the samples' noise model (:mod:`trackproc.methods.noise`): ``"auto"``
    (chosen per pass by REML among white, AR(1), oscillator random walk and both, and, for
    one-way Doppler without ``doppler_bias``, offset or offset+drift), ``"white"`` (independent
    samples: the weighted least squares of before), or one of ``"ar1"``, ``"walk"``,
    ``"ar1+walk"`` (that model, its parameters by REML); ``oscillator_noise``: the random-walk
    intensity of the transmitter frequency (Hz/√s) instead of estimating it.
    """

    cost: str = "pointwise"
    circular: bool = False
    doppler_bias: Optional[str] = None
    apriori: Optional[bool] = None
    apriori_sigma: Mapping[str, float] = field(default_factory=dict)
    force: str = "j2"
    earth: str = "wgs84"
    range_rate_model: Optional[str] = None
    max_iterations: int = 30
    clip: Optional[float] = 4.0
    pass_id: Optional[str] = None
    kind: Optional[str] = None
    quadrature_order: int = 16
    quadrature_panel_s: float = 30.0
    max_gap_s: float = 30.0
    circular_tolerance: Optional[float] = None
    reweight: bool = True
    rank_rtol: float = 1e-12
    covariance: str = "profile"
    noise: str = "auto"
    oscillator_noise: Optional[float] = None
    #: The solution epoch instead of the smoothed curve's traverse point (UTC datetime64; set by
    #: :func:`refine` when it moves the epoch to the refined orbit's own zero range-rate).
    traverse_epoch: Optional[np.datetime64] = None
    #: Refuse (keep the stale state) when the pass cannot improve it (:func:`refusal_test`).
    allow_refusal: bool = True


@dataclass
class SmoothedCurve:
    """The smoothed pass: ``fit`` (a :class:`~trackproc.methods.smoothing.PolynomialFit` in seconds
    from ``epoch``, UTC), its ``tca`` (or None, with ``tca_note``), where it came from
    (``source``: ``"metadata"`` or ``"fitted here"``) and the times ``used_t_s`` of the samples it
    was fitted to (s from ``epoch``)."""

    fit: object
    epoch: np.datetime64
    kind: str
    tca: object
    tca_note: str
    source: str
    used_t_s: np.ndarray


@dataclass
class RefineResult:
    """Everything :func:`refine` produces (the CLI writes it).

    ``state`` (GCRF :class:`~trackproc.io.statefile.State` at the traverse epoch, with every
    parameter, the covariance and the diagnostics), ``stale_epoch_state`` (the same orbit at the
    stale state's epoch), ``solution`` (the solver's), ``problem`` (the estimator's), ``curve``,
    ``residuals`` (one row per sample, as ``estimate --residuals``), ``observability``
    (:class:`~trackproc.methods.refinement.Observability`), ``constraints`` (dict), ``warnings``.
    """

    state: object
    stale_epoch_state: object
    solution: object
    problem: object
    curve: SmoothedCurve
    residuals: pd.DataFrame
    observability: object
    constraints: dict
    covariance: np.ndarray
    names: list
    warnings: list = field(default_factory=list)
    quality: object = None


# ----------------------------------------------------------------------------- the pass

def _select_pass(table: PassTable, options: RefineOptions, source: str) -> tuple[PassTable, str, str, str]:
    frame = table.frame
    if len(frame) == 0:
        raise InputError("no samples", file=source, expected="a pass file with one Doppler or range-rate pass")
    kinds = set(frame["kind"].astype(str))
    if options.kind is not None:
        if options.kind not in RANGE_RATE_KINDS:
            raise InputError("refine uses Doppler or range-rate", column="--kind", found=options.kind,
                             expected=" or ".join(RANGE_RATE_KINDS))
        if options.kind not in kinds:
            raise InputError("no samples of the requested kind", file=source, column="kind",
                             found=", ".join(sorted(kinds)), expected=options.kind)
        kind = options.kind
    else:
        present = [k for k in RANGE_RATE_KINDS if k in kinds]
        if not present:
            raise InputError("no Doppler or range-rate samples", file=source, column="kind",
                             found=", ".join(sorted(kinds)), expected="doppler or range_rate (one Doppler station)")
        kind = present[0]
    sub = frame[frame["kind"].astype(str) == kind]
    if options.pass_id is not None:
        sub = sub[sub["pass_id"].astype(str) == options.pass_id]
        if len(sub) == 0:
            found = ", ".join(sorted(set(frame.loc[frame["kind"] == kind, "pass_id"].astype(str))))
            raise InputError("no such pass", file=source, column="--pass-id", found=options.pass_id,
                             expected=f"one of {found}")
    keys = sorted(set(zip(sub["station"].astype(str), sub["pass_id"].astype(str))))
    if len(keys) > 1:
        listed = ", ".join(f"{s}/{p}" for s, p in keys[:8]) + (" ..." if len(keys) > 8 else "")
        raise InputError("more than one pass", file=source, column="pass_id", found=listed,
                         expected="one pass of one station; choose one with --pass-id")
    station, pass_id = keys[0]
    mode = (table.meta or {}).get("doppler_mode") or "one-way"
    if mode not in LINK_MODES:
        raise InputError("unknown link mode", file=source, column="doppler_mode", found=mode,
                         expected=" or ".join(LINK_MODES))
    return PassTable(sub.reset_index(drop=True), dict(table.meta or {})), kind, station, pass_id


def _utc64(times) -> np.ndarray:
    t = pd.DatetimeIndex(times)
    if t.tz is not None:
        t = t.tz_convert("UTC").tz_localize(None)
    return t.to_numpy(dtype="datetime64[ns]")


def smoothed_curve(sub: PassTable, kind: str, station: str, pass_id: str, source: str) -> SmoothedCurve:
    """The smoothed polynomial of the pass: from the ``smoothing`` metadata when ``smooth`` made
    it (seed 004 eq. 1), else fitted here with ``smooth``'s defaults; and its closest approach."""
    from trackproc.io import smoothing_record
    from trackproc.methods.smoothing import SmoothingError, closest_approach

    meta = sub.meta or {}
    mode = str(meta.get("doppler_mode") or "one-way")
    times = _utc64(sub.frame["time"])
    rec = smoothing_record.find_fit_record(meta, station, pass_id, kind)
    if rec is not None:
        fit = smoothing_record.fit_from_record(rec)
        epoch = smoothing_record.record_epoch(rec)
        used = ~sub.frame["flag"].to_numpy(bool) if "flag" in sub.frame.columns else np.ones(len(sub.frame), bool)
        t_used = (times[used] - epoch).astype(np.int64) * 1e-9
        tca, note = None, ""
        try:
            tca = closest_approach(fit, kind, mode)
        except SmoothingError as exc:
            note = str(exc)
        if isinstance(rec.get("tca"), dict) and rec["tca"].get("status") == "not_observed":
            note = str(rec["tca"].get("error") or "closest approach not observed")
        return SmoothedCurve(fit=fit, epoch=epoch, kind=kind, tca=tca, tca_note=note, source="metadata",
                             used_t_s=np.sort(t_used))
    if smoothing_record.output_of(meta) == "grid":
        raise InputError("a smoothed grid without its polynomial", file=source, column="smoothing",
                         expected=f"the smoothing record of {station}/{pass_id}/{kind} in the metadata")
    from trackproc.pipeline.smooth import SmoothOptions, smooth

    try:
        result = smooth(PassTable(sub.frame[["time", "station", "pass_id", "kind", "value", "sigma"]], meta),
                        SmoothOptions(), source=source)
    except ProcessingError as exc:
        raise ProcessingError(f"the pass cannot be smoothed: {exc}") from None
    pf = result.fits[0]
    if pf.fit is None:
        raise ProcessingError(f"the pass cannot be smoothed: {pf.error}")
    epoch = np.datetime64(pd.Timestamp(pf.epoch).tz_convert("UTC").tz_localize(None).as_unit("ns").to_datetime64())
    tca, note = pf.tca, pf.tca_error or ""
    if tca is None:
        try:
            tca = closest_approach(pf.fit, kind, mode)
        except SmoothingError as exc:
            note = str(exc)
    return SmoothedCurve(fit=pf.fit, epoch=epoch, kind=kind, tca=tca, tca_note=note, source="fitted here",
                         used_t_s=np.sort(pf.t_s[pf.fit.used]))


def _traverse_epoch(curve: SmoothedCurve, warnings: list, override=None) -> tuple[np.datetime64, str]:
    if override is not None:
        return np.datetime64(override, "ns"), "the refined orbit's own zero range-rate (iterated)"
    if curve.tca is not None:
        t = curve.tca.t_s
        how = curve.tca.definition
        if curve.tca_note:
            warnings.append(f"the closest approach of the smoothed curve is not well observed ({curve.tca_note}); "
                            "the traverse epoch rests on the polynomial there")
    else:
        a, b = curve.fit.domain_s
        t = 0.5 * (a + b)
        how = "middle of the pass (no closest approach in the smoothed curve)"
        warnings.append(f"no traverse point in the pass ({curve.tca_note}); the state is given at mid-pass")
    return curve.epoch + np.timedelta64(int(round(t * 1e9)), "ns"), how


# ----------------------------------------------------------------------------- the problem

def _is_tle_state(state) -> bool:
    return state.force_model == "sgp4" and bool((state.extra or {}).get("tle"))


def _state_prior_covariance(priors) -> Optional[np.ndarray]:
    """The 6 × 6 a-priori covariance of x..vz from the problem's priors (None unless all six)."""
    cov = np.full((6, 6), np.nan)
    for p in priors:
        idx = np.asarray(p.index, int)
        pc = np.asarray(p.covariance, float)
        sel = np.flatnonzero(idx < 6)
        if sel.size:
            cov[np.ix_(idx[sel], idx[sel])] = pc[np.ix_(sel, sel)]
    if np.isnan(np.diag(cov)).any():
        return None
    return np.nan_to_num(cov, nan=0.0)


def default_apriori_covariance(rv, mu_m3_s2: float) -> np.ndarray:
    """GCRF covariance (6, 6) of :data:`DEFAULT_APRIORI_ELEMENTS` at the state ``rv``."""
    from trackproc.methods.refinement import ELEMENT_NAMES, element_covariance

    return element_covariance(rv, mu_m3_s2, [DEFAULT_APRIORI_ELEMENTS[k] for k in ELEMENT_NAMES])


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

    @property
    def n_problem(self) -> int:
        return len(self.problem.names)

    # -- models ------------------------------------------------------------------------------
    def pointwise_model(self, x):
        h, jac = self.problem.model(np.asarray(x, float)[: self.n_problem])
        if len(self.names) > self.n_problem:
            jac = np.hstack([jac, np.zeros((jac.shape[0], len(self.names) - self.n_problem))])
        return h, jac

    def constraints(self, x):
        from trackproc.methods.refinement import circular_constraints

        return circular_constraints(x, self.mu, rka_index=len(self.names) - 1)

    def constraint_scale(self, x):
        from trackproc.methods.refinement import constraint_scales

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
        from trackproc.methods.least_squares import Options, solve
        from trackproc.methods.refinement import CachedModel, geodesic_retraction, solve_kkt

        model, y, sigma, periodic, clip = self.data()
        sigma = np.asarray(sigma, float) * sigma_scale
        if observed is not None:
            y = np.asarray(observed, float)
        priors = self.priors_at(prior_centre)
        start = self.x0 if x0 is None else np.asarray(x0, float)
        opts = Options(max_iterations=self.options.max_iterations, clip=clip, rank_rtol=self.options.rank_rtol)
        model = CachedModel(model)
        retract = geodesic_retraction(model, sigma, self.scales, priors)
        if self.options.circular:
            kkt = solve_kkt(model, start, y, sigma, names=self.names, constraints=self.constraints,
                            constraint_scale=self.constraint_scale, scales=self.scales, priors=priors,
                            periodic=periodic, options=opts, retract=retract)
            return kkt.solution, kkt
        lo, hi = self.bounds()
        return solve(model, start, y, sigma, names=self.names, scales=self.scales, priors=priors, periodic=periodic,
                     bounds=(lo, hi), options=opts, retract=retract), None

    def bounds(self):
        lo, hi = self.problem.params.bounds()
        return (np.r_[lo, [-np.inf] * (len(self.names) - lo.size)], np.r_[hi, [np.inf] * (len(self.names) - hi.size)])

    def solve_gls(self, observed=None, prior_centre=None, x0=None, sigma_scale=1.0):
        """Generalised least squares with the correlated-noise model (:attr:`noise`):
        :func:`trackproc.methods.least_squares.solve_gls` (whitened kept samples, editing on the
        innovations) with this refinement's solver (constrained under ``circular``)."""
        from dataclasses import replace as dc_replace

        from trackproc.methods.least_squares import Options, solve, solve_gls
        from trackproc.methods.refinement import CachedModel, geodesic_retraction, solve_kkt

        model, y, _, _, clip = self.data()
        if observed is not None:
            y = np.asarray(observed, float)
        priors = self.priors_at(prior_centre)
        lo, hi = self.bounds()
        opts = Options(max_iterations=self.options.max_iterations, clip=None, rank_rtol=self.options.rank_rtol)

        def fit(model_w, y_w, start):
            cached = CachedModel(model_w)
            ones = np.ones(y_w.size)
            retract = geodesic_retraction(cached, ones, self.scales, priors)
            if self.options.circular:
                kkt = solve_kkt(cached, start, y_w, ones, names=self.names, constraints=self.constraints,
                                constraint_scale=self.constraint_scale, scales=self.scales, priors=priors,
                                options=opts, retract=retract)
                return kkt.solution, kkt
            return solve(cached, start, y_w, ones, names=self.names, scales=self.scales, priors=priors,
                         bounds=(lo, hi), options=opts, retract=retract), None

        sol, kkt = solve_gls(model, self.x0 if x0 is None else np.asarray(x0, float), y, self.noise, fit, clip=clip,
                             sigma_scale=sigma_scale, edited=self.noise_edited)
        if kkt is not None:
            kkt = dc_replace(kkt, solution=sol)
        return sol, kkt

    def priors_at(self, prior_centre=None) -> list:
        """The a-priori terms, centred on ``prior_centre`` (6,) instead of the stale state if given."""
        from trackproc.methods.least_squares import Prior

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
        from trackproc.methods.least_squares import Options
        from trackproc.methods.refinement import CachedModel, profile_mixture, solve_kkt

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
        cached = CachedModel(kept)
        out = cov.copy()
        for i in obs.unobservable:
            row = np.r_[obs.dual[i], np.zeros(n - 6)]
            sigma_i = float(np.sqrt(row @ cov @ row))

            def fixed(target, row=row, sigma_i=sigma_i):
                def constraint(x):
                    return np.array([row @ (x - x_hat) - target]), row[None, :]

                k = solve_kkt(cached, x_hat, y, sigma, names=self.names, constraints=constraint,
                              constraint_scale=lambda x: np.array([max(sigma_i, 1.0)]), scales=self.scales,
                              priors=priors, periodic=periodic, options=opts)
                return k.solution.values, k.solution.covariance

            out += profile_mixture(fixed, x_hat, sigma_i) - cov
        return out

    def tolerance(self) -> float:
        """The eccentricity tolerance of ``--circular`` (0 unless given)."""
        return float(self.options.circular_tolerance or 0.0)

    def covariance(self, sol, kkt=None, priors=None) -> np.ndarray:
        """The reported covariance: the solver's (pointwise) or the sandwich (integral), plus,
        under ``--circular``, what a constraint holding only to :meth:`tolerance` adds."""
        from trackproc.methods import refinement as rf

        if self.options.cost != "integral":
            cov = sol.covariance
        else:
            d = self.integral
            cov = rf.sandwich_covariance(sol, d["sigma"], d["design"], d["coefficient_covariance"],
                                         self.priors if priors is None else priors)
        if kkt is not None and self.tolerance() > 0:
            sigma_eps = rf.circular_tolerance_covariance(sol.values, self.mu, self.tolerance())
            cov = cov + rf.constraint_error_covariance(kkt.sensitivity, sigma_eps)
        return cov


def prepare(table: PassTable, initial, stations=None, options: RefineOptions | None = None, eop=None,
            source: str = "<pass>", curve: Optional[SmoothedCurve] = None) -> Refinement:
    """Assemble a :class:`Refinement` (see the module docstring); :class:`InputError` for bad input.
    ``curve``: the pass's smoothed curve when already made (:func:`refine`'s re-solves)."""
    from trackproc.dynamics import geodesy, propagator
    from trackproc.io import smoothing_record
    from trackproc.dynamics import measurement_spectra as ms
    from trackproc.dynamics import timescales as ts
    from trackproc.pipeline.estimate import EstimateOptions, build_problem

    opt = options or RefineOptions()
    if opt.cost not in COSTS:
        raise InputError("unknown cost", column="--cost", found=opt.cost, expected=" or ".join(COSTS))
    if opt.noise not in NOISE_MODELS:
        raise InputError("unknown noise model", column="--noise", found=opt.noise, expected=", ".join(NOISE_MODELS))
    if opt.oscillator_noise is not None and not (math.isfinite(opt.oscillator_noise) and opt.oscillator_noise > 0):
        raise InputError("the oscillator noise must be positive", column="--oscillator-noise",
                         found=opt.oscillator_noise, expected="a random-walk intensity > 0 in Hz per sqrt(s)")
    if opt.covariance not in ("linear", "profile"):
        raise InputError("unknown covariance", column="--covariance", found=opt.covariance,
                         expected="linear or profile")
    if opt.doppler_bias not in (None,) + DOPPLER_BIAS:
        raise InputError("unknown Doppler bias model", column="--doppler-bias", found=opt.doppler_bias,
                         expected=" or ".join(DOPPLER_BIAS))
    if opt.force not in propagator.FORCES:
        raise InputError("unknown force model", column="--force", found=opt.force, expected="two-body or j2")
    if not (opt.quadrature_order >= 2 and opt.quadrature_panel_s > 0 and opt.max_gap_s > 0):
        raise InputError("bad quadrature settings", column="--quadrature-order",
                         found=(opt.quadrature_order, opt.quadrature_panel_s, opt.max_gap_s),
                         expected="order >= 2, panel > 0 s, gap > 0 s")
    warnings: list = []
    sub, kind, station, pass_id = _select_pass(table, opt, source)
    meta = sub.meta
    if opt.cost == "pointwise" and smoothing_record.output_of(meta) == "grid":
        raise InputError("a smoothed grid is a curve, not samples", file=source, column="smoothing",
                         found="output = grid",
                         expected="the samples (smooth without --grid), or --cost integral")
    carrier = meta.get("carrier_hz")
    carrier = float(carrier) if isinstance(carrier, (int, float)) and carrier > 0 else math.nan
    if kind == "doppler" and not carrier > 0:
        raise InputError("Doppler samples need the carrier frequency", file=source, column="carrier_hz",
                         found=meta.get("carrier_hz"), expected="carrier_hz > 0 in the file metadata "
                                                                "(trackproc ingest --carrier-hz)")
    # a coherent two-way link returns the ground station's own frequency: no transmitter offset
    one_way = (meta.get("doppler_mode") or "one-way") == "one-way"
    bias = opt.doppler_bias if opt.doppler_bias is not None else ("offset" if kind == "doppler" and one_way else "none")
    if bias != "none" and kind == "range_rate" and not carrier > 0:
        raise InputError("a Doppler offset on range-rate samples needs the carrier frequency", file=source,
                         column="carrier_hz", found=meta.get("carrier_hz"),
                         expected="carrier_hz in the metadata, or --doppler-bias none")
    frame = sub.frame
    sig = frame["sigma"].to_numpy(float)
    if not np.all(np.isfinite(sig) & (sig > 0)):
        i = int(np.flatnonzero(~(np.isfinite(sig) & (sig > 0)))[0])
        raise InputError(f"invalid sigma at {pd.Timestamp(frame['time'].iloc[i]).isoformat()} (sample {i + 1} of the "
                         "pass)", file=source, column="sigma", found=sig[i], expected="a positive number")
    if len(frame) < 8:
        raise ProcessingError(f"too few samples in the pass: {len(frame)} (at least 8 are needed)")

    curve = curve if curve is not None else smoothed_curve(sub, kind, station, pass_id, source)
    t_traverse, how = _traverse_epoch(curve, warnings, opt.traverse_epoch)

    # the stale state: a TLE is evaluated by SGP4 at the traverse epoch
    if _is_tle_state(initial):
        from trackproc.io.tle import parse_tle, tle_state

        lines = initial.extra["tle"]
        tle = parse_tle("\n".join(([initial.extra["tle_name"]] if initial.extra.get("tle_name") else []) + list(lines)),
                        initial.source or "<tle>")
        initial = tle_state(tle, at=t_traverse, eop=eop)
        warnings.append("the TLE is evaluated by SGP4 at the traverse epoch: the stale epoch is the traverse epoch")
    stale_epoch = np.datetime64(initial.epoch, "ns")

    use_apriori = opt.apriori if opt.apriori is not None else (opt.cost == "pointwise")
    apriori_sigma, apriori_initial, note, default_prior = {}, False, "none (the pass alone)", False
    if use_apriori:
        if opt.apriori_sigma:
            apriori_sigma, note = dict(opt.apriori_sigma), "--apriori-sigma"
        elif initial.state_covariance is not None:
            apriori_initial, note = True, "the stale state's covariance, moved to the traverse epoch by the STM"
        else:
            default_prior = True
            note = ("default (the stale state has no covariance): orbital-element sigmas " +
                    ", ".join(f"{k} {v:g}" for k, v in DEFAULT_APRIORI_ELEMENTS.items()))
    elif opt.apriori_sigma:
        raise InputError("--apriori-sigma with --no-apriori", column="--apriori-sigma",
                         expected="one of the two")
    est = EstimateOptions(doppler_bias=None if bias == "none" else bias, doppler_bias_per="pass",
                          apriori_sigma=apriori_sigma, apriori_initial=apriori_initial, force=opt.force,
                          earth=opt.earth, range_rate_model=opt.range_rate_model, max_iterations=opt.max_iterations,
                          clip=opt.clip, epoch=t_traverse, kinds=[kind])
    problem = build_problem([(source, PassTable(frame, meta))], initial, stations, est, eop)
    mu = propagator.force_parameters(opt.force)[0]
    if default_prior:
        from trackproc.methods.least_squares import Prior

        rv0 = problem.x0[:6]
        problem.priors.append(Prior(np.arange(6), rv0.copy(), default_apriori_covariance(rv0, mu)))

    names = list(problem.names)
    x0 = problem.x0.copy()
    scales = problem.params.scales()
    if opt.circular:
        names.append("r_ka")
        x0 = np.r_[x0, np.linalg.norm(x0[:3])]
        scales = np.r_[scales, scales[0]]

    # the station in the image domain (seed 004 eqs. 7-10), for the integral and the model traverse time
    known = dict(stations or {})
    for n_, s_ in sub.stations().items():
        known.setdefault(n_, s_)
    st = known[station]
    lat, lon, r_itrf = geodesy.station_itrf(st, opt.earth)
    t_meas = problem.meas.t_s
    epoch_jd = tuple(float(a) for a in ts.datetime64_to_jd_utc(problem.epoch))
    station_model = ms.StationModel.build(r_itrf, lat, lon, epoch_jd, problem.frame.q, float(t_meas.min()) - 60.0,
                                          float(t_meas.max()) + 60.0, eop=eop)

    # the station's geocentric axis at the traverse epoch (GCRF): the single-pass rotation family
    r_st0, _ = station_model.state(np.array([0.0]))
    axis = problem.frame.q.T @ r_st0[0]
    ref = Refinement(options=opt, problem=problem, curve=curve, kind=kind, station_name=station, pass_id=pass_id,
                     initial=initial, stale_epoch=stale_epoch, traverse_how=how, names=names, x0=x0, scales=scales,
                     priors=list(problem.priors), apriori_note=note, station_model=station_model, mu=mu,
                     carrier_hz=carrier, station_axis=axis / np.linalg.norm(axis), warnings=warnings)
    if opt.cost == "integral":
        ref.integral = _integral_setup(ref, frame)
    return ref


def _integral_setup(ref: Refinement, frame) -> dict:
    """Gauss-Legendre nodes on the covered parts of the pass, the curve there (range-rate), the
    pseudo-sigmas, the bias coefficients and the basis (for the sandwich covariance)."""
    from trackproc.dynamics import timescales as ts
    from trackproc.methods import refinement as rf

    opt = ref.options
    curve = ref.curve
    intervals = rf.covered_intervals(curve.used_t_s, opt.max_gap_s)
    if not intervals:
        raise ProcessingError("the smoothed pass has no interval without gaps to integrate over")
    t_poly, w = rf.gauss_legendre(intervals, order=opt.quadrature_order, panel_s=opt.quadrature_panel_s)
    # node times: polynomial time (s from the curve's epoch) -> s from the traverse epoch (SI)
    jd_c = ts.datetime64_to_jd_utc(curve.epoch)
    jd_e = tuple(float(a) for a in ts.datetime64_to_jd_utc(ref.problem.epoch))
    offset = float(ts.seconds_since(jd_c, jd_e))
    t_nodes = t_poly + offset
    # Doppler -> range-rate: -c Δf/f one-way, -c Δf/(2f) two-way (seed 004: Vr = c/(2 f0) f_D)
    mode = _link_mode(ref)
    k_link = 2.0 if mode == "two-way" else 1.0
    to_rr = -C_LIGHT / (k_link * ref.carrier_hz) if ref.kind == "doppler" else 1.0
    observed = to_rr * curve.fit(t_poly)
    design = to_rr * curve.fit.design(t_poly)
    sig = frame["sigma"].to_numpy(float) * abs(to_rr)
    n_used = curve.used_t_s.size
    covered = float(sum(b - a for a, b in intervals))
    spacing = covered / max(n_used - len(intervals), 1)
    sigma_ref = float(np.sqrt(np.mean(sig * sig)))
    vf_curve = float(curve.fit.variance_factor)
    if opt.reweight and math.isfinite(vf_curve) and vf_curve > 1.0:
        sigma_ref *= math.sqrt(vf_curve)           # the samples' actual scatter about the curve
    sigma_nodes = rf.pseudo_sigma(w, sigma_ref, spacing)
    bias_cols = []
    for d in ref.problem.params.selected[6:]:
        # an offset in Hz on range-rate: -c/f one-way, -c/(2f) two-way (observation.bias_modifiers)
        coef = -C_LIGHT / (k_link * ref.carrier_hz) * np.ones(t_nodes.size)
        if d.family == "doppler_drift":
            coef = coef * (t_nodes - d.epoch_s)
        elif d.family != "doppler_offset":
            raise ProcessingError(f"parameter {d.name} has no meaning for the integral cost")
        bias_cols.append(coef)
    model = rf.IntegralModel(ref.problem.epoch, ref.problem.frame, ref.station_model, t_nodes, bias_cols,
                             force=opt.force, eop=ref.problem.eop, range_rate_model=ref.problem.range_rate_model,
                             n_extra=1 if opt.circular else 0, mode=mode)
    return {"model": model, "observed": observed, "sigma": sigma_nodes, "weights": w, "t_nodes": t_nodes,
            "t_poly": t_poly, "design": design, "coefficient_covariance": curve.fit.cov_scaled,
            "intervals": intervals, "sigma_ref": sigma_ref, "spacing": spacing, "to_range_rate": to_rr,
            "mode": mode}


def _link_mode(ref: Refinement) -> str:
    """``"two-way"`` when the pass's samples are modelled as round trips, else ``"one-way"``."""
    return "two-way" if bool(np.any(ref.problem.meas.two_way)) else "one-way"


# ----------------------------------------------------------------------------- the run

def _max_elevation_deg(ref: Refinement, x) -> Optional[float]:
    """Highest elevation (deg) of the refined orbit at the pass's sample times."""
    from trackproc.dynamics import measurement_spectra as ms
    from trackproc.dynamics import propagator

    t = ref.problem.meas.t_s
    try:
        traj = propagator.propagate(x[:3], x[3:6], ref.problem.epoch, [float(t.min()) - 1.0, float(t.max())],
                                    force=ref.options.force, frame=ref.problem.frame,
                                    eop=ref.problem.eop).raise_for_outcome()
        el = ms.predict(traj, ref.station_model, t, partials=False).elevation_rad
        return float(np.degrees(el.max()))
    except (ArithmeticError, ValueError, ProcessingError):
        return None


def _link_range_rate(ref: Refinement, traj, t_s) -> np.ndarray:
    """The orbit's range-rate (m/s) at reception times ``t_s`` (s from the traverse epoch) by the
    pass's link: one-way from the DT spectra, two-way by the round trip (mean of both legs,
    :mod:`trackproc.models.observation` eqs. 7-9, on the same samples as the integral cost's
    :class:`~trackproc.methods.refinement.IntegralModel`), with the problem's range-rate model.
    ``traj`` carries its STM (the round trip's :func:`~trackproc.models.observation.evaluate`)."""
    from trackproc.dynamics import measurement_spectra as ms
    from trackproc.methods.refinement import range_rate_samples
    from trackproc.models import observation as ob

    t = np.atleast_1d(np.asarray(t_s, float))
    model = ref.problem.range_rate_model
    if _link_mode(ref) == "one-way":
        return ms.predict(traj, ref.station_model, t, range_rate_model=model, partials=False).range_rate_m_s
    meas = range_rate_samples(ref.problem.epoch, ref.station_model.r_itrf_m, t, "two-way", ref.problem.eop)
    return ob.evaluate(meas, traj, n_columns=6, range_rate_model=model)[0]


def _model_traverse(ref: Refinement, x) -> Optional[float]:
    """Seconds from the traverse epoch where the refined orbit's range-rate (by the pass's link,
    one- or two-way) vanishes (None if not within ±60 s)."""
    from trackproc.dynamics import propagator

    try:
        traj = propagator.propagate(x[:3], x[3:6], ref.problem.epoch, [-62.0, 62.0], force=ref.options.force,
                                    stm=_link_mode(ref) == "two-way", frame=ref.problem.frame,
                                    eop=ref.problem.eop).raise_for_outcome()
        t = np.linspace(-60.0, 60.0, 241)
        rr = _link_range_rate(ref, traj, t)
        k = np.flatnonzero((rr[:-1] < 0) & (rr[1:] >= 0))
        if k.size == 0:
            return None
        i = int(k[np.argmin(np.abs(t[k]))])
        a, b = t[i], t[i + 1]
        fa, fb = rr[i], rr[i + 1]
        for _ in range(30):
            m = a - fa * (b - a) / (fb - fa)
            fm = float(_link_range_rate(ref, traj, np.array([m]))[0])
            if abs(fm) < 1e-9 or b - a < 1e-7:
                return float(m)
            if fm < 0:
                a, fa = m, fm
            else:
                b, fb = m, fm
        return float(m)
    except (ArithmeticError, ValueError, ProcessingError):
        return None


def _eccentricity(r, v, mu) -> float:
    r = np.asarray(r, float)
    v = np.asarray(v, float)
    e = ((v @ v - mu / np.linalg.norm(r)) * r - (r @ v) * v) / mu
    return float(np.linalg.norm(e))


def refine(table: PassTable, initial, stations=None, options: RefineOptions | None = None, eop=None,
           source: str = "<pass>") -> RefineResult:
    """Refine ``initial`` (a GCRF :class:`~trackproc.io.statefile.State`, or a TLE's) from one pass.

    The consistency gates (docs/refine.md, "Quality"): the a-priori is scaled by its variance
    component when the pass contradicts it (:func:`solve_adapted`); the solution epoch follows the
    refined orbit's own zero range-rate; and when the pass cannot improve the stale state
    (an a-priori conflict the pass cannot carry, or one on residuals correlated beyond the pass's noise model), the
    stale state is kept with its covariance (``refused`` in the diagnostics and the quality).
    The result's ``quality`` (:func:`refine_quality`) says what was found.

    Returns :class:`RefineResult`; raises :class:`InputError` (exit 2) for invalid input and
    :class:`ProcessingError` (exit 1) when the refinement fails (no convergence, rank deficiency).
    """
    opt = options or RefineOptions()
    ref = prepare(table, initial, stations, opt, eop, source)
    # the pass's noise model (REML) and transmitter drift first, then the gates on that solution
    ref, sol, kkt, scale = solve_noise(table, initial, ref, stations, eop, source)
    ref, sol, kkt, scale, adaptation, improvement, refusal = _solve_gated(ref, first=(sol, kkt, scale))
    # the solution epoch is the refined orbit's own traverse point: re-solve there until it stays
    moves = []
    for _ in range(MAX_TRAVERSE_ITERATIONS if refusal is None else 0):
        t_model = _model_traverse(ref, sol.values)
        if t_model is None or abs(t_model) <= TRAVERSE_TOLERANCE_S:
            break
        epoch = ref.problem.epoch + np.timedelta64(int(round(t_model * 1e9)), "ns")
        try:
            # the same transmitter model (a drift the pass wanted) and a noise model refitted there
            bias = "offset+drift" if any(n.startswith("doppler_drift") for n in ref.names) else opt.doppler_bias
            moved = prepare(table, initial, stations, replace(opt, traverse_epoch=epoch, doppler_bias=bias), eop,
                            source, curve=ref.curve)
            moved.warnings[:] = list(ref.warnings)
            moved = _with_noise_of(moved, ref)
            first = solve_weighted(moved)
            factor = adaptation["factor"] if adaptation else 1.0
            moved_out = _solve_gated(moved, factor, first=tuple(first) if factor == 1.0 else None)
        except ProcessingError:
            break                                        # the quality reports the mismatch left
        moves.append(float(t_model))
        ref, sol, kkt, scale, adaptation, improvement, refusal = moved_out
        if refusal is not None:
            break
    consistency = None
    if ref.options.circular:
        # the same assembled problem without the constraints and r_ka (always the last parameter)
        free = replace(ref, options=replace(ref.options, circular=False), names=ref.names[:-1], x0=ref.x0[:-1],
                       scales=ref.scales[:-1])
        consistency = circular_consistency(free, sol, scale)
    return finish(ref, sol, kkt, scale, consistency=consistency, adaptation=adaptation, traverse_moves=moves,
                  improvement=improvement, refusal=refusal)


def _with_noise_of(moved: Refinement, ref: Refinement) -> Refinement:
    """``moved`` (the same pass at another solution epoch) with ``ref``'s noise model: the model
    depends on the sample times' differences only, so it carries over (REML is not run again: a
    traverse re-solve moves the epoch by seconds)."""
    if ref.noise is None:
        return replace(moved, noise=None, noise_edited=ref.noise_edited, noise_report=ref.noise_report)
    from trackproc.methods.noise import PassCovariance

    t = moved.problem.meas.t_s
    shift = float(np.min(t) - np.min(ref.problem.meas.t_s))
    blocks = [(idx, model, t0 + shift) for idx, model, t0 in ref.noise.blocks]
    cov = PassCovariance(moved.problem.meas.sigma, t, blocks)
    return replace(moved, noise=cov, noise_edited=ref.noise_edited, noise_report=ref.noise_report)


def _may_refuse(ref: Refinement) -> bool:
    """Refusal applies to the pointwise cost with a stale a-priori on the whole state, unconstrained."""
    opt = ref.options
    return (opt.allow_refusal and opt.cost == "pointwise" and not opt.circular
            and _state_prior_covariance([ref.priors[k] for k in _state_prior_indices(ref)]) is not None)


def _solve_gated(ref: Refinement, start_factor: float = 1.0, first=None):
    """Solve with the gates: the improvement test (reported), then the a-priori: a conflict on
    residuals still correlated after the pass's noise model is refused (the data's noise model is
    as doubtful as the a-priori), otherwise the a-priori is adapted (a conflict the pass cannot
    carry is refused). ``ref`` carries the pass's noise
    model (:func:`solve_noise`; the solves are then GLS and the tests read whitened residuals);
    ``first`` ``(sol, kkt, scale)`` a solution of ``ref`` already made. Returns ``(ref, sol, kkt,
    scale, adaptation, improvement, refusal)``; ``refusal`` None or ``{"reason", "code",
    "state_covariance"}``."""
    may = _may_refuse(ref)
    original = _state_prior_covariance([ref.priors[k] for k in _state_prior_indices(ref)]) if may else None
    work = _scaled_priors(ref, start_factor) if start_factor != 1.0 else ref
    if first is None or start_factor != 1.0:
        first = solve_weighted(work)
    improvement = stale_improvement(work, first[0], first[2]) if work.priors else None
    # A pass that does not significantly tell the refined state from the stale one is no reason to
    # keep the stale state: the posterior already weighs the pass by its information (measured on
    # the DopTrack development pairs: refusing those kept 4 of 7 states whose refinement predicted
    # the next pass 9-35 % better). The test is reported (quality reason ``improvement``).
    if may and improvement is not None:
        # an a-priori conflict is evidence against the a-priori only if the data's own noise model
        # holds: time-correlated residuals overstate the data's information just as much, and
        # loosening the a-priori would then let the pass move the state by its own systematic
        # errors (docs/refine.md, "Quality")
        from trackproc.methods import quality as qm

        chi2, rows = _state_prior_chi2(work, first[0].values)
        w = improvement["whiteness"]
        correlated = (w["lag1_autocorrelation"] > qm.WHITENESS_RHO
                      or (np.isfinite(w["runs_z"]) and abs(w["runs_z"]) > qm.RUNS_Z))
        if rows and chi2 > qm.chi2_limit(rows) and correlated:
            # the kept covariance: the a-priori scaled by its variance component with the data's
            # information deflated by the correlation (never below the a-priori as given)
            pcov = _state_prior_covariance([work.priors[k] for k in _state_prior_indices(work)])
            red = qm.prior_redundancy(np.asarray(work.covariance(first[0], first[1]), float)[:6, :6], pcov)
            comp = qm.prior_variance_component(chi2 / improvement["inflation"], red) or 1.0
            factor = max(1.0, comp)
            return work, first[0], first[1], first[2], None, improvement, {
                "code": "apriori_conflict_correlated", "state_covariance": original * factor,
                "covariance_factor": factor,
                "reason": (f"the pass contradicts the stale state's a-priori (chi2 {chi2:.4g} over {rows}, limit "
                           f"{qm.chi2_limit(rows):.3g}) but its residuals are correlated in time (lag-1 "
                           f"{w['lag1_autocorrelation']:.2f}, runs-test z {w['runs_z']:.1f}): the data's noise model "
                           "is as doubtful as the a-priori, so neither the refined state nor a loosened a-priori "
                           "can be trusted; the stale covariance is scaled by "
                           f"{factor:.3g} (its variance component with the data's information deflated by "
                           f"{improvement['inflation']:.3g})")}
    work, sol, kkt, scale, adaptation = solve_adapted(ref, start_factor, first=(work,) + tuple(first))
    if adaptation is not None:
        improvement = stale_improvement(work, sol, scale) if work.priors else improvement
        if may and not adaptation.get("resolved", True):
            return work, sol, kkt, scale, adaptation, improvement, {
                "code": "apriori_conflict", "state_covariance": original,
                "reason": "the pass contradicts the stale state's a-priori and cannot carry a looser one "
                          "(apriori_conflict); the stale covariance is kept as given"}
    return work, sol, kkt, scale, adaptation, improvement, None


NOISE_MODELS = vocabulary.NOISE_MODELS
#: A drift is added to a one-way pass's offset when its GLS estimate exceeds this many sigmas
#: (and √(ln n), the BIC threshold): p = 0.001, so that a pass without drift keeps the offset alone.
DRIFT_T = 3.29


def _oscillator(ref: Refinement) -> bool:
    """A one-way link with a transmitter offset: the frequency can wander."""
    return _link_mode(ref) == "one-way" and any(n.startswith("doppler_offset") for n in ref.problem.names)


def noise_model(ref: Refinement, sol, sigma_scale: float = 1.0) -> tuple[Refinement, bool]:
    """The noise model of the pass from the residuals of a fit ``sol`` (:func:`trackproc.methods.noise.fit_noise`:
    REML, the fixed effects being the Jacobian columns of the state, the offset and a drift),
    and whether the pass wants a drift it does not have (the GLS estimate of a drift, with the
    a-priori, beyond :data:`DRIFT_T` sigmas; only under ``noise="auto"`` without ``doppler_bias``).
    Returns ``(the Refinement with the model, drift wanted)``; the model is reported in
    ``noise_report``."""
    from trackproc.methods import noise as nz
    from trackproc.methods.least_squares import _prior_rows, _prior_rhs

    opt = ref.options
    meas = ref.problem.meas
    keep = ~np.asarray(sol.edited, bool)
    t = meas.t_s
    t0 = float(t.min())
    osc = _oscillator(ref)
    r = np.asarray(sol.residual, float)
    npb = ref.n_problem
    _, jac = ref.pointwise_model(sol.values)
    x = np.asarray(jac, float)[:, :npb]
    has_drift = any(n.startswith("doppler_drift") for n in ref.problem.names)
    if osc and not has_drift:        # the drift column (Hz/s; the offset's column times t - t0)
        i_off = [i for i, n in enumerate(ref.problem.names) if n.startswith("doppler_offset")][0]
        x = np.column_stack([x, x[:, i_off] * (t - t0)])
    if opt.noise == "auto":
        models = nz.MODELS if osc else ("white", "ar1")
    elif opt.noise == "white":
        models = ("white",)
    else:
        models = (opt.noise,)
    walk = opt.oscillator_noise
    nf = nz.fit_noise(t[keep], r[keep], x[keep], models=models, walk=walk, t0=t0)
    cov = nz.PassCovariance(meas.sigma, t, [(np.arange(t.size), nf.model, t0)])
    want_drift = False
    drift_t = None
    if osc and not has_drift:
        w = cov.whitener(keep)
        a = w(x)
        b = w(r)
        pa, factors = _prior_rows(ref.priors, len(ref.names), np.ones(len(ref.names)))
        if pa.shape[0]:
            pa = np.column_stack([pa[:, :npb], np.zeros(pa.shape[0])])
            a = np.vstack([a, pa])
            b = np.concatenate([b, _prior_rhs(factors, np.asarray(sol.values, float))])
        u, sv, vt = np.linalg.svd(a, full_matrices=False)
        ok = sv > 1e-10 * sv[0]
        beta = vt[ok].T @ ((u[:, ok].T @ b) / sv[ok])
        sd = float(np.sqrt(np.sum((vt[ok, -1] / sv[ok]) ** 2)))
        drift_t = float(beta[-1] / sd) if sd > 0 else 0.0
        want_drift = (opt.noise == "auto" and opt.doppler_bias is None
                      and abs(drift_t) > max(DRIFT_T, math.sqrt(math.log(max(keep.sum(), 3)))))
    report = nf.as_dict()
    report.update({"option": opt.noise,
                   "oscillator_noise_given": walk, "link": _link_mode(ref)})
    if drift_t is not None:
        report["drift_t"] = drift_t
    bias = [n.split(":")[0] for n in ref.problem.names if n.startswith("doppler_")]
    report["transmitter"] = ("offset+drift" if (want_drift or has_drift) else "offset" if bias else "none") + \
        ("+wander" if nf.model.walk > 0 else "")
    model = None if nf.model.is_white else cov
    return replace(ref, noise=model, noise_edited=np.asarray(sol.edited, bool).copy(), noise_report=report), want_drift


def solve_noise(table, initial, ref: Refinement, stations=None, eop=None, source: str = "<pass>", rounds: int = 1,
                observed=None, prior_centre=None, x0=None):
    """:func:`solve_weighted` with the noise model of the pass (:func:`noise_model`): a first
    (white) fit, the model by REML, a drift if the pass wants one (the problem prepared again
    from ``table``/``initial`` with ``offset+drift``), then GLS; with ``rounds`` > 1 the model is
    refitted on the GLS residuals and the fit repeated (REML does not depend on the fixed
    effects' estimate to first order: a second round changed the DopTrack development ratios by
    < 0.01 and costs 0.1 s of CPU, so one is the default). A pass whose noise is white and needs no drift keeps the
    white fit unchanged. ``observed``, ``prior_centre``, ``x0`` as in :meth:`Refinement.solve`
    (Monte Carlo: the problem must then already carry the drift it needs).
    Returns ``(Refinement, Solution, KKTResult or None, sigma scale)``."""
    sol, kkt, scale = solve_weighted(ref, observed, prior_centre, x0)
    if ref.options.cost != "pointwise" or (ref.options.noise == "white" and ref.options.oscillator_noise is None):
        return ref, sol, kkt, scale
    for _ in range(rounds):
        noisy, want_drift = noise_model(ref, sol, scale)
        if want_drift and observed is None:
            ref = prepare(table, initial, stations, replace(ref.options, doppler_bias="offset+drift"), eop, source,
                          curve=ref.curve)   # the same smoothed curve and epoch: no second smoothing
            noisy = replace(ref, noise=noisy.noise, noise_edited=noisy.noise_edited, noise_report=noisy.noise_report)
        elif not noisy.correlated() and not ref.correlated():
            return noisy, sol, kkt, scale                 # white, no drift to add: the white fit stands
        ref = noisy
        sol, kkt, scale = solve_weighted(ref, observed, prior_centre, x0)
    return ref, sol, kkt, scale


def circular_consistency(free: Refinement, constrained, sigma_scale: float = 1.0) -> dict:
    """Do the data contradict the circular-orbit constraints (seed 004 eq. 5)? The likelihood-ratio
    test: ``Δχ² = χ²(constrained) - χ²(free)`` is χ² with 2 degrees of freedom when the orbit is
    circular — three constraints, less the free radius ``r_ka`` that absorbs ``|r|² = r_ka²``
    (checked by Monte Carlo in the tests; with a fixed a-priori centre it is smaller on average,
    so the test errs towards silence). ``free`` is the same refinement without the constraints,
    solved here from the constrained solution with the same data sigmas."""
    from scipy.special import chdtrc  # chi-square survival without scipy.stats (issue 19)

    try:
        sol, _ = free.solve(sigma_scale=sigma_scale, x0=np.asarray(constrained.values, float)[:len(free.names)])
    except ProcessingError as exc:
        return {"test": "likelihood ratio", "status": f"the unconstrained fit failed: {exc}"}
    delta = float(constrained.chi2 - sol.chi2)
    out = {"test": "likelihood ratio", "delta_chi2": delta, "dof": 2,
           "p_value": float(chdtrc(2, max(delta, 0.0))),
           "free_fit_eccentricity": _eccentricity(sol.values[:3], sol.values[3:6], free.mu),
           "edited_constrained_free": [int(constrained.n_edited), int(sol.n_edited)]}
    if constrained.n_edited != sol.n_edited:
        out["note"] = "the two fits edited different samples: the test is approximate"
    return out


def stale_improvement(ref: Refinement, sol, sigma_scale: float = 1.0, n_seen: int = 6) -> Optional[dict]:
    """:func:`~trackproc.methods.quality.improvement_test` of a pointwise solution: the data's χ²
    at the stale state (at the solution epoch, the Doppler offset/drift refitted — they enter
    linearly) against the refined state's, on the same samples and sigmas, deflated by the
    correlation of the refined residuals (:func:`~trackproc.methods.quality.whiteness`), with
    ``n_seen`` (the state directions the pass sees) degrees of freedom. None for the integral cost."""
    from trackproc.methods import quality as qm

    if ref.options.cost != "pointwise":
        return None
    _, y, sigma, _, _ = ref.data()
    keep = ~np.asarray(sol.edited, bool)
    s = np.asarray(sigma, float)[keep] * sigma_scale
    if ref.correlated():
        # GLS: the residuals whitened by the pass's noise model (independent, unit sigma)
        whiten = ref.noise.whitener(keep)

        def white(v):
            return whiten(v) / sigma_scale
    else:
        def white(v):
            v = np.asarray(v, float)[keep]
            return v / (s[:, None] if v.ndim == 2 else s)
    npb = ref.n_problem
    x = np.asarray(sol.values, float)[:npb].copy()
    x[:6] = ref.x0[:6]
    h, jac = ref.problem.model(x)
    r = white(np.asarray(y, float) - h)
    bias, bias_cov = np.zeros(0), np.zeros((0, 0))
    if npb > 6:
        a = white(np.asarray(jac, float)[:, 6:npb])
        db = np.linalg.lstsq(a, r, rcond=None)[0]
        r = r - a @ db
        bias, bias_cov = x[6:npb] + db, np.linalg.pinv(a.T @ a)
    chi2_stale = float(r @ r)
    computed = np.asarray(sol.computed, float)
    rr = white(np.asarray(y, float) - computed) if ref.correlated() else np.asarray(sol.residual, float)[keep] / s
    w = qm.whiteness(rr)
    out = qm.improvement_test(chi2_stale, float(rr @ rr), max(n_seen, 1), qm.correlation_inflation(
        w["lag1_autocorrelation"]))
    out["whiteness"] = w
    out["stale_nuisance"] = {"values": bias.tolist(), "covariance": bias_cov.tolist()}
    return out


def _state_prior_indices(ref: Refinement) -> list:
    """Positions in ``ref.priors`` of the a-priori terms on the state alone (indices < 6)."""
    return [k for k, p in enumerate(ref.priors) if np.all(np.asarray(p.index) < 6)]


def _state_prior_chi2(ref: Refinement, x) -> tuple[float, int]:
    """``(chi2, rows)`` of the state a-priori terms at the solution ``x``."""
    chi2, rows = 0.0, 0
    for k in _state_prior_indices(ref):
        p = ref.priors[k]
        idx = np.asarray(p.index, int)
        d = np.asarray(x, float)[idx] - np.asarray(p.centre, float)
        chi2 += float(d @ np.linalg.solve(np.asarray(p.covariance, float), d))
        rows += idx.size
    return chi2, rows


def _scaled_priors(ref: Refinement, factor: float) -> Refinement:
    """``ref`` with the covariance of its state a-priori terms multiplied by ``factor``."""
    from trackproc.methods.least_squares import Prior

    priors = list(ref.priors)
    for k in _state_prior_indices(ref):
        p = priors[k]
        priors[k] = Prior(p.index, p.centre, np.asarray(p.covariance, float) * factor)
    return replace(ref, priors=priors)


def solve_adapted(ref: Refinement, start_factor: float = 1.0, x0=None, first=None):
    """:func:`solve_weighted`, then, when the a-priori test rejects (the state's a-priori share of
    χ² above the 99.9 % point of χ²(rows)), the a-priori covariance is scaled by its
    maximum-likelihood variance component (Helmert/Förstner:
    :func:`~trackproc.methods.quality.prior_variance_component`, iterated to a fixed point,
    never below 1) and the problem solved again: a stale state further off than its a-priori says
    is weighed by how far off the data show it to be, and the covariance covers that.
    ``start_factor`` starts from an already scaled a-priori; ``first`` ``(work, sol, kkt, scale)``
    a solution already made with it. Returns ``(Refinement with the a-priori used, Solution,
    KKTResult or None, sigma scale, adaptation dict or None)``."""
    from trackproc.methods import quality as qm

    if first is not None:
        work, sol, kkt, scale = first
    else:
        work = _scaled_priors(ref, start_factor) if start_factor != 1.0 else ref
        sol, kkt, scale = solve_weighted(work, x0=x0)
    if not (ref.priors and _state_prior_indices(ref)):
        return work, sol, kkt, scale, None
    chi2, rows = _state_prior_chi2(work, sol.values)
    limit = qm.chi2_limit(rows)
    if chi2 <= limit and start_factor == 1.0:
        return work, sol, kkt, scale, None
    start = {"chi2": chi2, "rows": rows, "limit": limit}
    factor = start_factor
    history = []
    kept = (work, sol, kkt, scale)
    for _ in range(MAX_APRIORI_ADAPT):
        pcov = _state_prior_covariance([work.priors[k] for k in _state_prior_indices(work)])
        red = (qm.prior_redundancy(np.asarray(work.covariance(sol, kkt), float)[:6, :6], pcov)
               if pcov is not None else math.nan)
        k_hat = qm.prior_variance_component(chi2, red)
        history.append({"factor": factor, "chi2": chi2, "redundancy": red, "component": k_hat})
        if k_hat is None or abs(k_hat - 1.0) < 0.1 or (k_hat < 1.0 and factor <= 1.0):
            break
        factor = max(1.0, factor * k_hat)
        try:
            trial = _scaled_priors(ref, factor)
            # from the previous solution a consistent scale converges in a few iterations
            quick = replace(trial, options=replace(ref.options, max_iterations=min(ref.options.max_iterations,
                                                                                     MAX_ADAPT_ITERATIONS)))
            sol, kkt, scale = solve_weighted(quick, x0=sol.values)
            work = trial
        except ProcessingError as exc:
            # the pass alone cannot carry a looser a-priori: keep the last solution, say so
            work, sol, kkt, scale = kept
            history.append({"factor": factor, "failed": str(exc)})
            factor = history[-2]["factor"] if len(history) > 1 else start_factor
            chi2, rows = _state_prior_chi2(work, sol.values)
            return work, sol, kkt, scale, {
                "method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated",
                "factor": factor, "sigma_factor": math.sqrt(factor), "chi2_before": start["chi2"], "chi2_after": chi2,
                "rows": rows, "limit": start["limit"], "iterations": history, "resolved": False,
                "failure": f"with the a-priori scaled by {history[-1]['factor']:.3g} the refinement failed: "
                           f"{str(exc).split(' (')[0]}"}
        kept = (work, sol, kkt, scale)
        chi2, rows = _state_prior_chi2(work, sol.values)
    adaptation = {"method": "maximum-likelihood variance component of the a-priori (Helmert/Foerstner), iterated",
                  "factor": factor, "sigma_factor": math.sqrt(factor), "chi2_before": start["chi2"],
                  "chi2_after": chi2, "rows": rows, "limit": start["limit"], "iterations": history,
                  "resolved": bool(chi2 <= start["limit"] or (history and history[-1].get("component") is not None
                                                             and abs(history[-1]["component"] - 1.0) < 0.1))}
    return work, sol, kkt, scale, adaptation


def solve_weighted(ref: Refinement, observed=None, prior_centre=None, x0=None):
    """:meth:`Refinement.solve`, repeated with the sample sigmas scaled by √(variance factor) while
    that exceeds :data:`REWEIGHT_THRESHOLD` (pointwise with ``reweight``). Returns
    ``(Solution, KKTResult or None, sigma scale)``. ``observed``, ``prior_centre``, ``x0`` as in
    :meth:`Refinement.solve` (Monte Carlo)."""
    scale = 1.0
    for _ in range(MAX_REWEIGHT):
        sol, kkt = ref.solve(observed=observed, prior_centre=prior_centre, sigma_scale=scale, x0=x0)
        vf = sol.variance_factor
        if not (ref.options.reweight and ref.options.cost == "pointwise" and math.isfinite(vf)
                and vf > REWEIGHT_THRESHOLD):
            break
        scale *= math.sqrt(vf)
        x0 = sol.values
    return sol, kkt, scale


def finish(ref: Refinement, sol, kkt=None, sigma_scale: float = 1.0, consistency: dict | None = None,
           prior_centre=None, adaptation: dict | None = None, traverse_moves: list | None = None,
           improvement: dict | None = None, refusal: dict | None = None) -> RefineResult:
    """Outputs of a solved :class:`Refinement` (states, covariance, report, residuals);
    ``consistency`` the :func:`circular_consistency` of a ``--circular`` solution;
    ``prior_centre`` the a-priori centre the solution was solved with (:meth:`Refinement.solve`)."""
    from trackproc.constants import force_model_constants
    from trackproc.dynamics import propagator
    from trackproc.dynamics import timescales as ts
    from trackproc.io.statefile import State, format_epoch
    from trackproc.methods import refinement as rf
    from trackproc.dynamics.rtn import rtn_covariance, rtn_jacobian
    from trackproc.pipeline.estimate import UNITS, residual_frame

    opt = ref.options
    problem = ref.problem
    warnings = list(ref.warnings)
    x = sol.values
    names = list(ref.names)
    npb = ref.n_problem
    cov = ref.covariance(sol, kkt)
    if refusal is not None:
        # the pass cannot improve the stale state: keep it with its a-priori covariance, the
        # Doppler offset/drift fitted at it
        x = np.asarray(sol.values, float).copy()
        x[:6] = ref.x0[:6]
        cov = np.zeros_like(np.asarray(cov, float))
        cov[:6, :6] = refusal["state_covariance"]
        nuisance = (improvement or {}).get("stale_nuisance") or {}
        if len(nuisance.get("values", [])) == npb - 6 and npb > 6:
            x[6:npb] = nuisance["values"]
            cov[6:npb, 6:npb] = np.asarray(nuisance["covariance"], float)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    units = problem.params.units() + (["m"] if opt.circular else [])

    # residuals at the samples (both costs)
    if refusal is not None:
        h, _ = problem.model(x[:npb])
        r = problem.meas.observed - h
        samples = SimpleNamespace(computed=h, residual=r, normalized=r / (problem.meas.sigma * sigma_scale),
                                  edited=np.asarray(sol.edited, bool))
    elif opt.cost == "pointwise":
        samples = sol
    else:
        h, _ = problem.model(x[:npb])
        r = problem.meas.observed - h
        samples = SimpleNamespace(computed=h, residual=r, normalized=r / problem.meas.sigma,
                                  edited=np.zeros(r.size, bool))
    residuals = residual_frame(problem, samples)
    kept = ~samples.edited
    # Doppler residual (Hz) -> m/s: c/f one-way, c/(2f) two-way
    rr_factor = (C_LIGHT / ((2.0 if _link_mode(ref) == "two-way" else 1.0) * ref.carrier_hz)
                 if ref.kind == "doppler" else 1.0)
    res_kept = samples.residual[kept]
    rms = float(np.sqrt(np.mean(res_kept ** 2))) if res_kept.size else math.nan

    # constraints (eq. 5) at the solution
    rka = float(x[-1]) if opt.circular else float(np.linalg.norm(x[:3]))
    x7 = np.r_[x[:6], rka]
    f, _ = rf.circular_constraints(x7, ref.mu)
    fscale = rf.constraint_scales(x7, ref.mu)
    constraints = {"names": list(rf.CONSTRAINT_NAMES), "units": ["m^2", "m^2/s^2", "m^2/s"],
                   "values": f.tolist(), "relative": (f / fscale).tolist(), "imposed": bool(opt.circular),
                   "r_ka_m": rka, "eccentricity": _eccentricity(x[:3], x[3:6], ref.mu)}
    if kkt is not None:
        constraints.update({"multipliers": kkt.multipliers.tolist(),
                            "multipliers_note": "lambda of L = chi2 + lambda^T f (chi2: the whitened cost; "
                                                "seed 004 eq. 16), per unit of each constraint",
                            "stationarity": kkt.stationarity, "restoration_steps": kkt.restorations,
                            "free_directions": kkt.null_space_dim, "eccentricity_tolerance": ref.tolerance(),
                            "tolerance_note": "the covariance includes the constraints' own uncertainty for an orbit "
                                              "circular only to this eccentricity (0: conditional on an exactly "
                                              "circular orbit)"})
        i_rka = names.index("r_ka")
        constraints["r_ka_sigma_m"] = float(sigma[i_rka])
        if consistency is not None:
            constraints["consistency"] = consistency
    else:
        u = x[:3] / np.linalg.norm(x[:3])
        constraints["r_ka_sigma_m"] = float(np.sqrt(u @ cov[:3, :3] @ u))

    # observability of the state from this pass
    reference = _state_prior_covariance(ref.priors)
    ref_name = "the a-priori covariance at the traverse epoch"
    if reference is None:
        reference = default_apriori_covariance(x[:6], ref.mu)
        ref_name = "the default a-priori covariance (not used in the fit)"
    _, _, sig_data, _, _ = ref.data()
    keep = ~sol.edited
    obs = rf.observability(sol.jacobian[keep][:, :npb], np.asarray(sig_data)[keep] * sigma_scale, problem.names,
                           rtn_jacobian(x[:3], x[3:6], rotating=False), reference, cov[:6, :6],
                           other_scales=problem.params.scales()[6:], reference=ref_name,
                           station_axis=ref.station_axis, state=x[:6])
    if opt.circular:
        obs.notes.append("--circular: the three constraints of eq. 5 fix three combinations of the state; "
                         "the covariance is zero across them (it is conditional on a circular orbit)")
    if ref.priors and opt.cost == "pointwise" and obs.unobservable:
        obs.notes.append("directions the pass cannot see keep the a-priori (stale) uncertainty")
    big = rtn_jacobian(x[:3], x[3:6], rotating=False)             # GCRF -> RTN for (r, v)
    covariance_note = "linear (the inverse of the whitened normal matrix at the solution)"
    if (opt.covariance == "profile" and opt.cost == "pointwise" and not opt.circular and obs.unobservable and ref.priors
            and refusal is None):
        # the estimate slides along a curved valley where the pass sees nothing: the linear
        # covariance misses that curvature along the best-determined combinations
        try:
            cov = ref.profile_covariance(sol, obs, sigma_scale, prior_centre)
            sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
            obs.posterior_sigma_rtn = np.sqrt(np.clip(np.diag(big @ cov[:6, :6] @ big.T), 0.0, None))
            covariance_note = (f"profile: linear, plus the curvature along the {len(obs.unobservable)} "
                               f"direction(s) the pass cannot see ({rf.PROFILE_NODES} Gauss-Hermite points each)")
        except ProcessingError as exc:
            warnings.append(f"the profile covariance could not be computed ({exc}); the linear one is reported")
    # how far the pass moved the stale state, along what it sees and along what it cannot
    # (a large unseen part means the a-priori, not the data, put the state there)
    obs.correction_rtn = {part: dict(zip(rf.RTN_NAMES, (big @ d).tolist()))
                          for part, d in zip(("seen", "unseen"), obs.split(x[:6] - ref.x0[:6]))}
    if refusal is not None:
        refusal = dict(refusal)
        refusal.pop("state_covariance", None)
        refusal["refused_correction_rtn"] = {
            part: dict(zip(rf.RTN_NAMES, (big @ d).tolist()))
            for part, d in zip(("seen", "unseen"), obs.split(np.asarray(sol.values, float)[:6] - ref.x0[:6]))}

    # the state at the stale epoch
    dt = float(ts.seconds_since(ts.datetime64_to_jd_utc(ref.stale_epoch),
                                tuple(float(a) for a in ts.datetime64_to_jd_utc(problem.epoch))))
    if dt == 0.0:
        rv_s, cov_s = x[:6].copy(), cov.copy()
    else:
        traj = propagator.propagate(x[:3], x[3:6], problem.epoch, [dt], force=opt.force, stm=True,
                                    frame=problem.frame, eop=problem.eop).raise_for_outcome()
        rv_s = traj.state(dt)
        jac = np.eye(len(names))
        jac[:6, :6] = traj.stm(dt)
        cov_s = jac @ cov @ jac.T
        cov_s = 0.5 * (cov_s + cov_s.T)

    # traverse-point diagnostics
    t_model = _model_traverse(ref, x)
    traverse = {"epoch": format_epoch(problem.epoch), "definition": ref.traverse_how,
                "sigma_s": float(ref.curve.tca.sigma_s) if ref.curve.tca is not None else None,
                "curve": ref.curve.source,
                "refined_orbit_zero_range_rate_s": t_model,
                "moved_s": list(traverse_moves or []),
                "refined_orbit_zero_range_rate_utc": (format_epoch(problem.epoch + np.timedelta64(
                    int(round(t_model * 1e9)), "ns")) if t_model is not None else None)}

    # warnings
    max_el = _max_elevation_deg(ref, x)
    if max_el is not None and max_el < LOW_PASS_DEG:
        warnings.append(f"a low pass (highest elevation {max_el:.1f} deg < {LOW_PASS_DEG:g}): one low pass "
                        "determines the orbit poorly and an onboard oscillator's wander is easily taken for orbit; "
                        "see docs/refine.md")
    if sigma_scale > 1.0:
        warnings.append(f"the samples scatter more than their sigmas say: sigmas scaled by {sigma_scale:.3g} "
                        "(sqrt of the variance factor, iterated) before weighing them against the a-priori")
    if consistency is not None and consistency.get("p_value", 1.0) < CIRCULAR_TEST_P:
        c = consistency
        warnings.append(f"the pass contradicts the circular-orbit constraints (delta chi2 = {c['delta_chi2']:.4g}, 2 "
                        f"degrees of freedom, p = {c['p_value']:.2g}; the unconstrained fit's eccentricity is "
                        f"{c['free_fit_eccentricity']:.2g}): the constrained state is biased and its covariance too "
                        "small; give --circular-tolerance (the eccentricity the orbit is circular to) or drop "
                        "--circular")
    if opt.circular and kkt is not None and ref.tolerance() == 0.0:
        warnings.append("--circular: the covariance is conditional on an exactly circular orbit; with J2 the "
                        "osculating eccentricity of a circular orbit swings by about 1e-3 (give --circular-tolerance)")
    if sol.dof > 0 and sol.variance_factor > 4.0 and opt.cost == "pointwise":
        warnings.append(f"a-posteriori variance factor {sol.variance_factor:.3g} (> 4): the sigmas of the data are too "
                        "small or the model misses something; the covariance is optimistic")
    if sol.n_prior:
        from scipy.special import gammaincinv  # chi-square quantile without scipy.stats (issue 19)

        limit = 2.0 * float(gammaincinv(sol.n_prior / 2.0, 0.999))
        if sol.chi2_prior > limit:
            warnings.append(f"the refined state departs from the stale state by chi2 = {sol.chi2_prior:.4g} over "
                            f"{sol.n_prior} a-priori constraints (99.9 % limit {limit:.3g}): the pass and the stale "
                            "state disagree; check the pass, or loosen the a-priori")
    if opt.cost == "pointwise" and sol.n_edited > 0.1 * sol.n_measurements:
        warnings.append(f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)")
    if opt.cost == "integral" and not ref.priors and obs.unobservable:
        warnings.append(f"{len(obs.unobservable)} state direction(s) are weakly determined by the pass alone "
                        "(see the observability report); consider --apriori")

    quality = refine_quality(ref, sol, sigma_scale=sigma_scale, adaptation=adaptation, improvement=improvement,
                             refusal=refusal, t_model=t_model, max_el=max_el, consistency=consistency)
    if refusal is not None:
        warnings.append(f"the stale state is kept: {refusal['reason']}")
    apriori_note = ref.apriori_note
    if adaptation is not None and adaptation.get("factor", 1.0) > 1.0 and refusal is None:
        a = adaptation
        warnings.append(f"the pass contradicted the a-priori (chi2 {a['chi2_before']:.4g} over {a['rows']}, 99.9 % limit "
                        f"{a['limit']:.3g}): its covariance was scaled by {a['factor']:.3g} (sigmas x"
                        f"{a['sigma_factor']:.3g}; maximum-likelihood variance component) and the pass refined again")
        apriori_note += f"; scaled by {a['factor']:.3g} (the pass contradicted it)"
    rtn = rtn_covariance(x[:3], x[3:6], cov[:6, :6])
    diagnostics = {
        "converged": bool(sol.converged), "message": sol.message, "iterations": int(sol.iterations),
        "damped_steps": int(sol.damped_steps), "cost": float(sol.chi2), "cost_history": sol.cost_history,
        "dof": int(sol.dof), "variance_factor": sol.variance_factor, "condition_number": sol.condition_number,
        "apriori_rows": sol.n_prior, "chi2_apriori": sol.chi2_prior,
        "samples": int(problem.meas.observed.size), "edited": int((~kept).sum()),
        "sigma_scale": sigma_scale, "max_elevation_deg": max_el,
        "residual_rms": {"value": rms, "unit": UNITS[ref.kind], "range_rate_m_s": rms * rr_factor},
        "apriori_adaptation": adaptation, "improvement": _without_nuisance(improvement), "refused": refusal,
        "traverse": traverse, "constraints": constraints, "observability": obs.as_dict(),
        "covariance_rtn": rtn,
        "sigma_rtn": dict(zip(rf.RTN_NAMES, np.sqrt(np.clip(np.diag(rtn), 0.0, None)).tolist())),
        "units": units, "warnings": warnings,
    }
    if ref.noise_report is not None:                  # the noise model of the pass (methods/noise.py)
        diagnostics["noise"] = ref.noise_report
    method = {"cost": opt.cost, "circular": bool(opt.circular),
              "solver": ("Gauss-Newton with equality constraints, KKT by the null-space method (seed 004 eqs. 15-17)"
                         if opt.circular else "Gauss-Newton by QR/SVD with Levenberg-Marquardt damping"),
              "apriori": apriori_note, "covariance": covariance_note,
              "kind": ref.kind, "station": ref.station_name, "pass_id": ref.pass_id,
              "range_rate_model": problem.range_rate_model, "force_model": opt.force, "earth": opt.earth,
              "doppler_bias": [n for n in problem.names if n.startswith("doppler_")],
              "propagator": "Taylor (DT) with first-order sensitivity spectra, quasi-inertial frame of the traverse "
                            "epoch"}
    if opt.cost == "integral":
        d = ref.integral
        w = d["weights"]
        res_nodes = d["observed"] - sol.computed
        integral = float(np.sum(w * res_nodes ** 2))
        method.update({
            "integral": {"equation": "I = integral over the pass of (Vr_LSQ - Vr(X, t))^2 dt (seed 004 eq. 14)",
                         "quadrature": f"composite Gauss-Legendre, {opt.quadrature_order} nodes per panel of at most "
                                       f"{opt.quadrature_panel_s:g} s", "nodes": int(w.size),
                         "intervals_s": d["intervals"], "I_m2_s": integral,
                         "rms_curve_difference_m_s": math.sqrt(integral / float(np.sum(w))),
                         "normalisation": "chi2 = I / (sigma_ref^2 * spacing)", "sigma_ref_m_s": d["sigma_ref"],
                         "spacing_s": d["spacing"],
                         "link": d["mode"],
                         "gradient": ("first-order 2-D DT sensitivities (seed 004 eqs. 19-21) through the range and "
                                      "range-rate spectra" if d["mode"] == "one-way" else
                                      "round-trip (two-way) range-rate partials through both light times times the "
                                      "Taylor engine's state transition matrix (first-order DT sensitivities)"),
                         "covariance": "the smoothing polynomial's scaled coefficient covariance propagated through "
                                       "the linearised estimator (sandwich)",
                         "sigma_formal": sol.sigma.tolist()},
            "curve": {"degree": int(ref.curve.fit.degree), "basis": ref.curve.fit.basis, "source": ref.curve.source}})
    stale_doc = {"epoch": format_epoch(ref.stale_epoch), "frame": "GCRF", "position_m": rv_s[:3].tolist(),
                 "velocity_m_s": rv_s[3:].tolist(), "parameters": names, "values": np.r_[rv_s, x[6:]].tolist(),
                 "sigma": np.sqrt(np.clip(np.diag(cov_s), 0.0, None)).tolist(), "covariance": cov_s.tolist()}
    values = x.copy()
    extra = {"refinement": method, "at_stale_epoch": stale_doc,
             "stale_state": {"epoch": format_epoch(ref.initial.epoch), "position_m": ref.initial.r_m.tolist(),
                             "velocity_m_s": ref.initial.v_m_s.tolist(),
                             "source": ref.initial.source or (ref.initial.extra or {}).get("source")}}
    eop_source = getattr(problem.eop, "source", None) or "none (UT1-UTC = 0, no polar motion)"
    extra["quality"] = quality.as_dict()
    state = State.from_vectors(problem.epoch, x[:3], x[3:6], parameters=names, values=values, sigma=sigma,
                               covariance=cov, force_model=opt.force, constants=force_model_constants(opt.force),
                               eop_source=eop_source, diagnostics=diagnostics, extra=extra)
    stale_state = State.from_vectors(ref.stale_epoch, rv_s[:3], rv_s[3:], parameters=names,
                                     values=np.r_[rv_s, x[6:]], sigma=np.sqrt(np.clip(np.diag(cov_s), 0.0, None)),
                                     covariance=cov_s, force_model=opt.force,
                                     constants=force_model_constants(opt.force), eop_source=eop_source,
                                     diagnostics=diagnostics,
                                     extra={"refinement": method, "at_traverse_epoch": format_epoch(problem.epoch),
                                            "quality": quality.as_dict()})
    return RefineResult(state=state, stale_epoch_state=stale_state, solution=sol, problem=problem, curve=ref.curve,
                        residuals=residuals, observability=obs, constraints=constraints, covariance=cov, names=names,
                        warnings=warnings, quality=quality)


def _without_nuisance(improvement):
    if improvement is None:
        return None
    return {k: v for k, v in improvement.items() if k != "stale_nuisance"}


def refine_quality(ref: Refinement, sol, *, sigma_scale=1.0, adaptation=None, improvement=None, refusal=None,
                   t_model=None, max_el=None, consistency=None):
    """The :class:`~trackproc.methods.quality.Quality` of a refinement: a-priori conflict (and
    its adaptation), variance factor of the nominal sigmas, residual whiteness, traverse-epoch
    mismatch, low pass, circular-constraint conflict, edited samples, refusal."""
    from trackproc.methods import quality as qm

    q = qm.Quality()
    opt = ref.options
    if refusal is not None:
        q.add("refused", "suspect", f"the stale state is kept: {refusal['reason']}", value=refusal.get("code"))
    # a-priori conflict
    if adaptation is not None:
        a = adaptation
        if a.get("resolved", True):
            q.add("apriori_conflict", "ok",
                  f"the pass contradicted the a-priori (chi2 {a['chi2_before']:.4g} over {a['rows']}, limit "
                  f"{a['limit']:.3g}); its covariance was scaled by {a['factor']:.3g} (sigmas x{a['sigma_factor']:.3g}, "
                  "maximum-likelihood variance component)", value=a["chi2_before"], limit=a["limit"])
        else:
            q.add("apriori_conflict", "suspect" if refusal is not None else "rejected",
                  f"the pass contradicts the a-priori (chi2 {a['chi2_before']:.4g} over {a['rows']}, limit "
                  f"{a['limit']:.3g}) and cannot carry a looser one ({a.get('failure', '')})",
                  value=a["chi2_before"], limit=a["limit"])
    elif sol.n_prior:
        chi2, rows = _state_prior_chi2(ref, sol.values)
        if rows:
            limit = qm.chi2_limit(rows)
            # a refused refinement writes the stale state: the conflict is the rejected solution's
            q.add("apriori_conflict", "ok" if chi2 <= limit else "suspect" if refusal is not None else "rejected",
                  f"a-priori chi2 {chi2:.4g} over {rows} (limit {limit:.3g})"
                  + (" of the refused solution" if refusal is not None else ""), value=chi2, limit=limit)
    # the variance factor of the nominal sigmas (reweighting hides it in the solution's own)
    if sol.dof > 0 and math.isfinite(sol.variance_factor):
        vf = float(sol.variance_factor) * sigma_scale ** 2
        limit = qm.variance_factor_limit(sol.dof)
        if opt.cost == "integral":
            q.add("variance_factor", "ok", f"variance factor {vf:.3g} of the curve (the integral cost's pseudo-sigmas "
                  "are not a test of the data)", value=vf, limit=None)
        else:
            q.add("variance_factor", "ok" if vf <= limit else "suspect",
                  f"a-posteriori variance factor {vf:.3g} with the samples' own sigmas (99.9 % limit {limit:.3g})"
                  + (f"; sigmas scaled by {sigma_scale:.3g} to their actual scatter" if sigma_scale > 1 else ""),
                  value=vf, limit=limit)
    # whiteness of the residuals
    if improvement is not None and "whiteness" in improvement:
        w = improvement["whiteness"]
    else:
        keep = ~np.asarray(sol.edited, bool)
        w = qm.whiteness(np.asarray(sol.normalized, float)[keep]) if opt.cost == "pointwise" else None
    if w is not None:
        qm.add_whiteness(q, w)
    if improvement is not None and refusal is None and "significant" in improvement:
        q.add("improvement", "ok",
              f"the pass {'tells' if improvement['significant'] else 'does not significantly tell'} the refined "
              f"state from the stale one (delta chi2 {improvement['delta_chi2']:.4g}, "
              f"{improvement['delta_chi2_effective']:.3g} after the residuals' correlation; 99.9 % point "
              f"{improvement['limit']:.3g})" + ("" if improvement["significant"] else
                                                 ": the a-priori carries most of the refined state"),
              value=improvement["delta_chi2_effective"], limit=improvement["limit"])
    # the epoch: the refined orbit's own traverse point
    if ref.curve.tca is not None or opt.traverse_epoch is not None:
        if t_model is None:
            q.add("traverse_mismatch", "suspect", "the refined orbit's range-rate does not vanish within 60 s of the "
                  "solution epoch", value=None, limit=TRAVERSE_TOLERANCE_S)
        else:
            q.add("traverse_mismatch", "ok" if abs(t_model) <= TRAVERSE_TOLERANCE_S else "suspect",
                  f"the refined orbit's own zero range-rate is {t_model:+.3g} s from the solution epoch",
                  value=abs(t_model), limit=TRAVERSE_TOLERANCE_S)
    if max_el is not None:
        q.add("low_pass", "ok" if max_el >= LOW_PASS_DEG else "suspect",
              f"highest elevation {max_el:.1f} deg" + (" (one low pass determines the orbit poorly)"
                                                       if max_el < LOW_PASS_DEG else ""),
              value=max_el, limit=LOW_PASS_DEG)
    if consistency is not None and "p_value" in consistency:
        bad = consistency["p_value"] < CIRCULAR_TEST_P
        q.add("circular_conflict", "suspect" if bad else "ok",
              f"circular-orbit constraints: delta chi2 {consistency['delta_chi2']:.4g} over 2, p = "
              f"{consistency['p_value']:.2g}", value=consistency["p_value"], limit=CIRCULAR_TEST_P)
    if opt.cost == "pointwise" and sol.n_edited > 0.1 * sol.n_measurements:
        q.add("edited", "suspect", f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)",
              value=int(sol.n_edited), limit=0.1 * sol.n_measurements)
    return q


# ----------------------------------------------------------------------------- text

def summary_text(result: RefineResult) -> str:
    """One screen for a person: the refined state ± sigma, RTN sigmas, constraints, observability."""
    st = result.state
    d = st.diagnostics
    m = st.extra["refinement"]
    sol = result.solution
    lines = [f"trackproc refine ({m['cost']}{', circular' if m['circular'] else ''}): converged in "
             f"{sol.iterations} iterations ({sol.message}); traverse epoch {d['traverse']['epoch']} "
             f"({m['station']}/{m['pass_id']}, {m['kind']}); a-priori: {m['apriori']}"]
    for name, value, sigma, unit in zip(st.parameters, st.values, st.sigma, d["units"]):
        lines.append(f"  {name:<28s}{value:>18.6f} ± {sigma:<12.4g} {unit}")
    s = d["sigma_rtn"]
    lines.append(f"  sigma RTN: radial {s['radial_m']:.3g} m, along {s['along_m']:.3g} m, cross {s['cross_m']:.3g} m; "
                 f"{s['radial_m_s']:.3g}, {s['along_m_s']:.3g}, {s['cross_m_s']:.3g} m/s")
    rr = d["residual_rms"]
    lines.append(f"  residual RMS {rr['value']:.4g} {rr['unit']} ({rr['range_rate_m_s']:.4g} m/s), samples "
                 f"{d['samples']}, edited {d['edited']}, cost {d['cost']:.6g}, "
                 f"condition number {d['condition_number']:.3g}")
    c = d["constraints"]
    rel = ", ".join(f"{v:.2e}" for v in c["relative"])
    lines.append(f"  constraints (eq. 5{', imposed' if c['imposed'] else ', not imposed'}): relative [{rel}]; "
                 f"r_ka {c['r_ka_m']:.3f} ± {c['r_ka_sigma_m']:.3g} m, e {c['eccentricity']:.2e}")
    o = result.observability
    sv = ", ".join(f"{v:.3g}" for v in o.state_singular_values)
    lines.append(f"  observability (state singular values, units of {o.reference}): {sv}")
    for i in o.unobservable:
        lines.append(f"    not seen by the pass: {o.direction_text(i)} (posterior/reference sigma {o.gain[i]:.2f})")
    if o.correction_rtn:
        for part, c in o.correction_rtn.items():
            lines.append(f"    correction {part}: R/A/C {c['radial_m']:.4g}, {c['along_m']:.4g}, {c['cross_m']:.4g} m; "
                         f"{c['radial_m_s']:.3g}, {c['along_m_s']:.3g}, {c['cross_m_s']:.3g} m/s")
    stale = st.extra["at_stale_epoch"]
    r_text = ", ".join(f"{v:.3f}" for v in stale["position_m"])
    v_text = ", ".join(f"{v:.5f}" for v in stale["velocity_m_s"])
    lines.append(f"  at the stale epoch {stale['epoch']}: r = [{r_text}] m, v = [{v_text}] m/s")
    for w in result.warnings:
        lines.append(f"  warning: {w}")
    if result.quality is not None:
        lines.append(f"  {result.quality.text()}")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- the Table 1 scenario

def traverse_station(state, *, cross_track_m: float = 600e3, side: str = "left", height_m: float = 0.0,
                     name: str = "TRV", eop=None, earth: str = "wgs84", force: str = "j2",
                     range_rate_model: str = "doppler"):
    """A station for which ``state`` (GCRF, at its epoch) is the traverse point of a visible pass.

    The station is placed ``cross_track_m`` from the sub-satellite point at the epoch, to the
    ``side`` (``"left"``/``"right"``) of the ground track (perpendicular to the satellite's
    Earth-fixed velocity), then moved along the track until the one-way range-rate received at
    the epoch (light time, station motion, ``range_rate_model``) is zero to 1 µm/s. Returns
    ``(Station, info)`` with the elevation and range at the epoch (the top of the pass).
    """
    from scipy.optimize import brentq

    from trackproc.dynamics import frames, geodesy, propagator
    from trackproc.dynamics import timescales as ts
    from trackproc.io.stations import Station
    from trackproc.models import observation as ob

    jd = tuple(float(a) for a in ts.datetime64_to_jd_utc(np.datetime64(state.epoch, "ns")))
    r_itrf, v_itrf = frames.gcrf_to_itrf(state.r_m, state.v_m_s, *jd, eop)
    r_itrf, v_itrf = r_itrf.reshape(3), v_itrf.reshape(3)
    up = r_itrf / np.linalg.norm(r_itrf)
    track = v_itrf - up * (up @ v_itrf)
    track /= np.linalg.norm(track)
    left = np.cross(up, track)
    cross = left if side == "left" else -left
    traj = propagator.propagate(state.r_m, state.v_m_s, state.epoch, [-2.0, 2.0], force=force, eop=eop)
    radius = 6371e3

    def site(s):
        n = up + (cross_track_m / radius) * cross + (s / radius) * track
        n /= np.linalg.norm(n)
        lat, lon, _ = geodesy.itrf_to_geodetic(n * radius, earth)
        return float(lat), float(lon)

    def rate(s):
        lat, lon = site(s)
        r_st_itrf = geodesy.geodetic_to_itrf(lat, lon, height_m, earth)
        trk = geodesy.station_gcrf(r_st_itrf, np.array([jd[0]]), np.array([jd[1]]), eop)
        geo = ob.solve_light_time(traj, np.array([0.0]), trk.r)
        return float(ob.range_rate_value(geo.state[:, :3], geo.state[:, 3:], trk.r, trk.v, range_rate_model)[0])

    s = brentq(rate, -400e3, 400e3, xtol=1e-6, rtol=1e-15)
    lat, lon = site(s)
    r_st_itrf = geodesy.geodetic_to_itrf(lat, lon, height_m, earth)
    enu = geodesy.itrf_to_enu(r_itrf, r_st_itrf, lat, lon)
    az, el, rng = geodesy.enu_to_azel(enu)
    station = Station(name, math.degrees(lat), math.degrees(lon) if lon >= -math.pi else math.degrees(lon) + 360.0,
                      float(height_m))
    return station, {"elevation_deg": float(np.degrees(el)), "range_m": float(rng),
                     "azimuth_deg": float(np.degrees(az)), "along_track_shift_m": float(s), "range_rate_m_s": rate(s)}
