"""The estimation problem of ``estimate``, ``refine`` and ``filter``: :class:`Problem` and
:func:`build_problem`.

The parameters are the six state drivers ``x..vz`` plus the drivers that the measurement
modifiers own (:mod:`trackproc.models.modifiers`): the options choose the modifiers
(:func:`trackproc.pipeline.od.modifiers.bias_modifiers`), the estimator collects their drivers,
and the model applies the modifiers bound to the samples (steps 3-5 of
:mod:`trackproc.pipeline.estimate`). A little over 400 lines: the problem, its builder and the
model's memo (which evaluations are reused) are one unit; the priors' assembly could move out.
"""

from __future__ import annotations

import copy
import threading
from dataclasses import dataclass
from typing import Optional

import numpy as np

from trackproc.constants import MU_EARTH
from trackproc.dynamics import propagator
from trackproc.dynamics import timescales as ts
from trackproc.errors import InputError
from trackproc.io.tle import is_tle_state
from trackproc.methods.estimation.prior import default_apriori_covariance, tle_along_sigma_m, tle_apriori_covariance
from trackproc.methods.least_squares import Options, Prior, solve, solve_gls
from trackproc.methods.refinement import CachedModel, geodesic_retraction
from trackproc.models import modifiers as md
from trackproc.models import observation as ob
from trackproc.models import parameters as pm
from trackproc.pipeline.od import samples as sm
from trackproc.pipeline.od.modifiers import bias_modifiers
from trackproc.pipeline.timing import tle_age_days
from trackproc.pipeline.od.options import (GROUPS, LIGHT_TIME_MARGIN_S, EstimateOptions, apriori_for,
                                                 check_apriori, check_options, force_parameter_names)
from dataclasses import replace
from trackproc.dynamics.forces import ForceModel
from trackproc.io.icgem import load_field
from trackproc.pipeline.range_corrections import range_correction_modifiers


#: Model results a :class:`Problem` keeps (see :meth:`Problem.model`).
MODEL_MEMO = 4


def _memo_key(x, cols, fixed) -> tuple:
    """A :class:`Problem`'s memo key of a model result: the values, and the selection too."""
    return x.tobytes(), tuple(cols), repr(sorted(fixed.items()))


@dataclass
class Problem:
    """An assembled estimation problem: samples, parameters, model (reusable, e.g. Monte Carlo).

    ``meas`` (:class:`~trackproc.models.observation.MeasurementSet`), ``params`` (the drivers;
    the selected ones are the estimated vector), ``epoch`` (UTC datetime64) and ``frame`` of the
    propagation, ``force``, ``range_rate_model``, ``modifiers`` (bound to ``meas``; they own
    the bias drivers), ``priors``,
    ``times`` (UTC datetime64 of the samples), ``sources`` (file of each sample).
    """

    meas: ob.MeasurementSet
    params: pm.ParameterSet
    epoch: np.datetime64
    frame: object
    force: str
    range_rate_model: str
    modifiers: list
    priors: list
    times: np.ndarray
    sources: np.ndarray
    eop: object = None
    force_model: object = None            # the ForceModel of force "full"
    evaluations: int = 0
    #: where the state's a-priori came from (the state file's ``estimation`` record)
    apriori_note: str = ""
    #: the initial state is an a-priori (``--apriori-initial``, or by default a TLE's)
    apriori_initial: bool = False
    #: estimated force-model parameters (``--estimate-force``), columns 6.. of the vector
    force_names: tuple = ()
    #: where the state's a-priori came from: "stated", "default" or "" (none;
    #: :data:`trackproc.methods.estimation.prior.SOURCES`)
    apriori_source: str = ""
    #: what became of the initial state (methods/estimation/decision.py), set by the estimator
    decision: Optional[dict] = None
    #: the full model's integrator for every run of :meth:`trajectory` (True compiled, False numpy;
    #: None: chosen per run from its span, :func:`~trackproc.dynamics.forces.integrator.use_compiled`)
    compiled: Optional[bool] = None

    @property
    def names(self) -> list:
        return self.params.selected_names

    @property
    def x0(self) -> np.ndarray:
        return self.params.values()

    def _columns(self):
        names = self.names
        cols = {n: i for i, n in enumerate(names) if n not in pm.STATE_NAMES}
        fixed = {d.name: d.value for d in self.params if not d.selected and d.family != "state"}
        return cols, fixed

    def force_model_at(self, x):
        """The force model with the estimated force parameters at their values in ``x``."""
        if not self.force_names:
            return self.force_model
        return self.force_model.with_parameters(**{n: float(x[6 + i]) for i, n in enumerate(self.force_names)})

    def trajectory(self, x, cover=(), start_s: float = 0.0):
        """The propagated trajectory (with STM, and the force parameters' partials) of ``x``, over
        the samples' times and ``cover`` (further times, s from the epoch). ``start_s``: the
        state ``x[:6]`` is the one at that time (s from the epoch), where the run starts (at that
        absolute time, in the epoch's integration frame); the trajectory is read on the epoch's
        time axis and its STM is Ψ(t, start_s) (:class:`~trackproc.dynamics.propagator.Restarted`)."""
        t = np.concatenate([self.meas.t_s, np.asarray(cover, float).ravel()])
        # a time-tag offset moves samples up to its bound (and the derivative's step) either way
        margin = (md.TIME_BIAS_LIMIT_S + 1.0) if any(b.modifier.shifts_time for b in self.modifiers) else 0.0
        span = [float(t.min()) - LIGHT_TIME_MARGIN_S - margin, float(t.max()) + margin]
        traj = propagator.propagate_from(x[:3], x[3:6], self.epoch, float(start_s), span, force=self.force, stm=True,
                                         frame=self.frame, eop=self.eop, force_model=self.force_model_at(x),
                                         compiled=self.compiled)
        traj = traj.raise_for_outcome()
        return _WithForceParameters(traj) if self.force_names else traj

    def compiled_for(self, span_s: float) -> Optional[bool]:
        """The full model's integrator (:attr:`compiled`) for runs that together integrate ``span_s``
        seconds, as one run of that span would choose it; None under the Taylor models. A filter's
        restarted chunks each integrate a short span: chosen per run, every one of them would pay
        the numpy path's cost per step to spare the one load of the compiled kernels."""
        if self.force != "full":
            return None
        from trackproc.dynamics.forces import integrator  # start-up: the force models load only for "full"

        return integrator.use_compiled(self.force_model, float(span_s), stm=True)

    def values(self, x):
        """``computed (N,)`` at ``x``: :meth:`model`'s values (the same numbers: the same trajectory,
        its sensitivities propagated too) without the partials, for a step rule's trial point."""
        x = np.asarray(x, float)
        cols, fixed = self._columns()
        hit = self.__dict__.get("_memo", {}).get(_memo_key(x, cols, fixed))
        if hit is not None and hit[2] is self.force_model:
            return hit[0].copy()
        return self._model(x, cols, fixed, partials=False)[0]

    def model(self, x):
        """``(computed (N,), jacobian (N, n))`` at the selected parameter values ``x`` (copies of
        the last :data:`MODEL_MEMO` results for the same ``x``, fixed drivers and force model: a
        refinement evaluates its solution again in the noise model and the step and second-signal
        scans)."""
        x = np.asarray(x, float)
        cols, fixed = self._columns()
        key = _memo_key(x, cols, fixed)
        memo = self.__dict__.setdefault("_memo", {})
        hit = memo.get(key)
        if hit is not None and hit[2] is self.force_model:
            return hit[0].copy(), hit[1].copy()
        h, jac = self._model(x, cols, fixed)
        if len(memo) >= MODEL_MEMO:
            memo.pop(next(iter(memo)))
        memo[key] = (h, jac, self.force_model)
        if key[0] == self.x0.tobytes():
            # the solve's start point, kept for :meth:`model_near` (a refinement's stale-state test)
            self.__dict__["_start"] = (key, memo[key])
        return h.copy(), jac.copy()

    def model_near(self, x):
        """:meth:`model` at ``x``, from the result kept at the start point :attr:`x0` when ``x``
        differs from it only in drivers of modifiers that add to the samples (a bias, a Doppler
        offset or drift: ``h`` is affine in them, with constant partials, and ``J`` does not depend
        on them), else evaluated."""
        x = np.asarray(x, float)
        start = self.__dict__.get("_start")
        x0 = self.x0
        cols, fixed = self._columns()
        if (start is None or start[1][2] is not self.force_model or x.shape != x0.shape
                or start[0] != _memo_key(x0, cols, fixed)):
            return self.model(x)
        linear = {n for b in self.modifiers if not b.modifier.shifts_time for n in b.names}
        moved = np.flatnonzero(x != x0)
        if not all(self.names[i] in linear for i in moved):
            return self.model(x)
        h, jac = start[1][0], start[1][1]
        return h + jac[:, moved] @ (x[moved] - x0[moved]), jac.copy()

    def _model(self, x, cols, fixed, partials: bool = True):
        values = dict(fixed)
        values.update({n: x[i] for n, i in cols.items()})
        try:
            traj = self.trajectory(x)
            # the light times of the last evaluation start this one's iteration (one trajectory
            # evaluation fewer; the same numbers to the iteration's tolerance)
            h, jac, geo = ob.evaluate(self.meas, traj, n_state_params=6 + len(self.force_names),
                                      modifiers=self.modifiers, bias_values=values, bias_columns=cols,
                                      n_columns=x.size, range_rate_model=self.range_rate_model, partials=partials,
                                      tau0=self.__dict__.get("_light_times"))
        except ValueError as exc:
            raise ArithmeticError(str(exc)) from None
        self.__dict__["_light_times"] = geo.tau_s
        self.evaluations += 1
        return h, jac

    def solve(self, observed=None, *, max_iterations: int = 20, clip: Optional[float] = 4.0,
              rank_rtol: float = 1e-9, x0=None, priors=None, noise=None, edited=None):
        """:func:`~trackproc.methods.least_squares.solve` on this problem (``observed``
        replaces the samples' values, e.g. for Monte Carlo); with ``noise`` (a correlated
        :class:`~trackproc.methods.noise.PassCovariance`), generalised least squares
        (:func:`~trackproc.methods.least_squares.solve_gls`, starting from the ``edited`` samples)."""
        y = self.meas.observed if observed is None else np.asarray(observed, float)
        lo, hi = self.params.bounds()
        if noise is not None and not noise.is_white:
            opts = Options(max_iterations=max_iterations, clip=None, rank_rtol=rank_rtol)
            pri = self.priors if priors is None else priors

            def fit(model_w, y_w, start):
                # the step follows the curved valleys the correlated weighting leaves (as refine's)
                cached = CachedModel(model_w, values=model_w.values)
                ones = np.ones(y_w.size)
                return solve(cached, start, y_w, ones, names=self.names, scales=self.params.scales(), priors=pri,
                             bounds=(lo, hi), options=opts,
                             retract=geodesic_retraction(cached, ones, self.params.scales(), pri)), None

            return solve_gls(self.model, self.x0 if x0 is None else x0, y, noise, fit, clip=clip, edited=edited,
                             values=self.values)[0]
        return solve(self.model, self.x0 if x0 is None else x0, y, self.meas.sigma, names=self.names,
                     scales=self.params.scales(), priors=self.priors if priors is None else priors,
                     periodic=self.meas.periodic, bounds=(lo, hi),
                     options=Options(max_iterations=max_iterations, clip=clip, rank_rtol=rank_rtol))


class _WithForceParameters:
    """A trajectory whose ``stm`` is ``[Φ | ∂state/∂p]`` (6 × (6 + P)): the force parameters'
    columns of the measurement partials then follow the state's through the same chain (light
    time, two-way legs) as the STM's: ∂h/∂p = ∂h/∂s(t_e) · ∂s(t_e)/∂p (Montenbruck & Gill 2000
    eq. 7.44 for the sensitivities)."""

    def __init__(self, traj):
        self.traj = traj

    def state(self, t_s, **kw):
        return self.traj.state(t_s, **kw)

    def stm(self, t_s):
        return np.concatenate([self.traj.stm(t_s), self.traj.parameter_partials(t_s)], -1)

    def __getattr__(self, name):
        return getattr(self.traj, name)


def force_drivers(force_model, names, apriori) -> list:
    """The drivers of the estimated force parameters, at the force model's values."""
    if not names:
        return []
    values = force_model.parameter_values()
    return [pm.force_parameter(n, values[n], apriori_sigma=apriori_for(n, n, apriori)) for n in names]


def with_estimated(force_model, names):
    """``force_model`` carrying the partials of ``names``; an :class:`InputError` when the model
    cannot (Cr without radiation pressure, Cd without drag)."""
    if force_model is None:
        raise InputError("force parameters need the full force model", column="--estimate-force",
                         found=",".join(names), expected="--force full")
    try:
        return replace(force_model, estimated=tuple(names))
    except ValueError as exc:
        hint = {"cr": " (--srp and the spacecraft's mass and SRP area)", "cd": " (--drag and the spacecraft's "
                "mass and drag area)"}
        extra = "".join(h for k, h in hint.items() if k in names and k in str(exc))
        raise InputError(str(exc) + extra, column="--estimate-force", found=",".join(names)) from None


def default_force_model(epoch, eop, degree: int = 20):
    """Force ``full`` without a given model: the shipped field to ``degree`` x ``degree`` at ``epoch``,
    Sun and Moon, relativity (no SRP or drag: they need the spacecraft's properties)."""
    return ForceModel(field=load_field(degree=degree, date=np.datetime64(epoch, "s")), third_bodies=("sun", "moon"),
                      relativity=True, eop=eop)


#: Integration frames by UTC epoch (ns since 1970) with the Earth orientation they were made with:
#: a batch refines every pass from the same stale state, whose frame is then made once.
_FRAMES: dict = {}
_FRAMES_MAX = 16
_FRAMES_LOCK = threading.Lock()


def epoch_frame(epoch, eop):
    """:func:`~trackproc.dynamics.propagator.reference_frame` of the UTC ``epoch`` (what
    :func:`~trackproc.dynamics.propagator.propagate` makes by default), kept for the same epoch
    and ``eop`` object (the frame is a function of them alone)."""
    if isinstance(epoch, str):
        epoch = epoch.rstrip("Zz")
    epoch = np.datetime64(epoch, "ns")
    key = int(epoch.astype(np.int64))
    with _FRAMES_LOCK:
        hit = _FRAMES.pop(key, None)
    if hit is None or hit[0] is not eop:
        jd1, jd2 = ts.datetime64_to_jd_utc(epoch)
        hit = (eop, propagator.reference_frame(float(jd1), float(jd2), eop))
    with _FRAMES_LOCK:
        if len(_FRAMES) >= _FRAMES_MAX:
            _FRAMES.pop(next(iter(_FRAMES)))        # the least recently used
        _FRAMES[key] = hit
    return hit[1]


def initial_at_epoch(initial, epoch, force, eop, force_model=None):
    """Initial GCRF state (and 6 × 6 covariance if any) moved to ``epoch`` (Taylor + STM)."""
    cov = initial.state_covariance
    if np.datetime64(initial.epoch, "ns") == epoch:
        return initial.rv, cov
    dt = float(ts.seconds_since(ts.datetime64_to_jd_utc(epoch), initial.jd_utc))
    traj = propagator.propagate(initial.r_m, initial.v_m_s, initial.epoch, [dt], force=force, stm=cov is not None,
                                eop=eop, force_model=force_model,
                                frame=epoch_frame(initial.epoch, eop)).raise_for_outcome()
    rv = traj.state(dt)
    if cov is not None:
        cov = traj.covariance(dt, cov)
    return rv, cov


def default_apriori(rv0) -> np.ndarray:
    """refine's documented a-priori of a state without covariance (a TLE): independent errors of
    the non-singular elements, the along-track phase loose and the period tight
    (:data:`trackproc.methods.estimation.prior.DEFAULT_APRIORI_ELEMENTS`), as a GCRF 6 × 6 covariance."""
    return default_apriori_covariance(np.asarray(rv0, float), MU_EARTH)


def priors_of(params: pm.ParameterSet, opt: EstimateOptions, rv0, cov0, initial,
              epoch=None) -> tuple[list, str, bool, str]:
    """The a-priori constraints: the drivers' own sigmas, and ``--apriori-initial`` (the initial
    state's 6 × 6 covariance; for a TLE, its accuracy at its age by TLE differencing
    (:func:`~trackproc.methods.estimation.prior.tle_apriori_covariance`); for another state without
    one, refine's default element a-priori, :func:`default_apriori`; by default on for a TLE).
    Returns ``(priors, note, whether the initial state is one of them, source)``: ``source``
    ``"stated"`` (--apriori-sigma on the state, a state covariance, a TLE), ``"default"`` or ``""``
    (no state a-priori), :data:`trackproc.methods.estimation.prior.SOURCES`."""
    priors = []
    note, source = "", ""
    mask, centre, sigma = params.apriori()
    if mask.any():
        priors.append(Prior.diagonal(np.flatnonzero(mask), centre[mask], sigma[mask]))
        if mask[:6].any():
            note, source = "--apriori-sigma on the state", "stated"
    apriori_initial = opt.apriori_initial
    if apriori_initial is None:         # auto: a TLE's state, unless the state's a-priori is given otherwise
        apriori_initial = cov0 is None and is_tle_state(initial) and not mask[:6].any()
    if apriori_initial:
        if mask[:6].any():
            raise InputError("give --apriori-initial or state a-priori sigmas, not both", column="--apriori-sigma")
        source = "stated"
        if cov0 is None and is_tle_state(initial):
            age = tle_age_days(initial, epoch) if epoch is not None else None
            age = 0.0 if age is None else age
            cov0 = tle_apriori_covariance(rv0, MU_EARTH, age)
            note = (f"the TLE's accuracy {age:.2g} days from its epoch (TLE differencing: along-track "
                    f"{tle_along_sigma_m(age):.0f} m)" + ("; on by default for a TLE" if opt.apriori_initial is None
                                                          else ""))
        elif cov0 is None:
            cov0 = default_apriori(rv0)
            source = "default"
            note = ("the initial state has no covariance: refine's default element a-priori (a 50 m, e 5e-5, "
                    "i and RAAN 1e-4 rad, argument of latitude 4e-4 rad)")
        else:
            note = "the initial state's covariance"
        priors.append(Prior(np.arange(6), np.asarray(rv0, float), np.asarray(cov0, float)))
    return priors, note, bool(apriori_initial), source


def build_problem(tables, initial, stations=None, options: EstimateOptions | None = None, eop=None,
                  like: Problem | None = None) -> Problem:
    """Assemble the :class:`Problem` from pass tables, an initial state and stations.

    ``tables``: sequence of ``(source name, PassTable)``; ``initial``: a GCRF
    :class:`~trackproc.io.statefile.State`; ``stations``: name -> Station (optional when the pass
    files' metadata carry them). ``like``: a problem built before from the same tables, stations,
    Earth model and EOP (a refinement prepared again at another epoch or with another transmitter
    model): its stations' GCRF geometry at the reception times is reused when the samples' times
    and stations are the same. Raises :class:`InputError` for invalid input.
    """
    opt = options or EstimateOptions()
    check_options(opt)
    if not tables:
        raise InputError("no pass files given", column="PASS", expected="one or more pass files, or -")
    frame, file_models = sm.merge_tables(tables, opt.kinds)
    sm.check_samples(frame)
    model = sm.range_rate_model(opt.range_rate_model, file_models)
    known = sm.resolve_stations(frame, tables, stations)
    t64 = frame["time"]
    epoch = sm.solution_epoch(opt.epoch, initial, t64)
    same = (like is not None and like.eop is eop and like.meas.gcrf_to_enu is not None and like.meas.a_st is not None
            and np.array_equal(like.times, t64) and np.array_equal(like.meas.station, frame["station"]))
    meas = sm.measurement_set(frame, t64, epoch, known, opt.earth, eop, geometry=like.meas if same else None)

    force_model = opt.force_model
    if opt.force == "full" and force_model is None:
        force_model = default_force_model(epoch, eop)
    force_names = force_parameter_names(opt.estimate_force)
    if force_names:
        force_model = with_estimated(force_model, force_names)
    rv0, cov0 = initial_at_epoch(initial, epoch, opt.force, eop, force_model)
    apriori = dict(opt.apriori_sigma)
    check_apriori(apriori)
    params = pm.ParameterSet(pm.state_drivers(rv0, sigma=[apriori_for(s, "state", apriori) for s in pm.STATE_NAMES]))
    for d in force_drivers(force_model, force_names, apriori):     # columns 6..: after the state, as in the STM
        params.add(d)
    modifiers = bias_modifiers(opt, frame, meas.t_s, known, apriori) + [copy.deepcopy(m) for m in opt.modifiers]
    modifiers += range_correction_modifiers(frame, tables, known, epoch, troposphere=opt.troposphere,
                                            com_offset_m=opt.com_offset_m, wavelength_nm=opt.wavelength_nm)
    for d in md.collect_drivers(modifiers):
        params.add(d)
    unknown = [k for k in apriori if k not in params and k not in GROUPS and k not in pm.KINDS
               and k not in pm.STATE_NAMES]
    if unknown:
        raise InputError("a-priori sigma for an unknown parameter", column="--apriori-sigma", found=unknown[0],
                         expected="one of " + ", ".join(params.names + list(GROUPS) + list(pm.KINDS)))
    try:
        bound = md.bind_all(modifiers, meas)
    except ValueError as exc:
        raise InputError(str(exc), column="--doppler-bias") from None
    priors, note, initial_prior, source = priors_of(params, opt, rv0, cov0, initial, epoch)
    frame_q = epoch_frame(epoch, eop)
    return Problem(meas=meas, params=params, epoch=epoch, frame=frame_q, force=opt.force, range_rate_model=model,
                   modifiers=bound, priors=priors, times=t64, sources=frame["_source"],
                   eop=eop, apriori_note=note, force_model=force_model, force_names=force_names,
                   apriori_initial=initial_prior, apriori_source=source)
