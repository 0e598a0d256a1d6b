"""``trackproc estimate``: batch weighted least squares of an orbit and its biases (seed 002).

The extended state vector (:mod:`trackproc.models.parameters`): the GCRF state at the solution
epoch, plus per-station range biases, per-pass (or per-station) one-way Doppler frequency
offsets and drifts, and per-station azimuth/elevation biases, each switched on by an option.

The problem (:class:`Problem`, built by :func:`build_problem`):

1. **Samples.** Every pass file's samples (any kinds: range, range_rate, doppler, azimuth,
   elevation), time-tagged at reception, with their sigma; UTC labels become SI seconds from
   the solution epoch (through TAI).
2. **Stations.** From ``--stations`` or, failing that, the pass files' metadata; WGS-84 (or
   spherical) geodetic -> ITRF -> GCRF at every reception time by IAU 2006/2000A
   (:func:`trackproc.models.measurements.station_gcrf`, the simulator's function), and the
   GCRF -> east-north-up rotation for angles.
3. **Trajectory.** :func:`trackproc.dynamics.propagator.propagate` — the Taylor (DT) engine
   with its state transition matrix, integrated in the quasi-inertial frame of the solution
   epoch (J2 about that epoch's rotation axis, as the simulator does), evaluated in GCRF by
   dense output at every emission time. One propagation per model evaluation.
4. **Measurement model.** :func:`trackproc.models.observation.evaluate`: one-way light time
   (Newton on the dense output), ``--range-rate-model`` doppler/instantaneous, station motion,
   partials through the light time, biases as modifiers. A pass file whose ``doppler_mode`` is
   ``two-way`` has its range, range-rate and Doppler samples modelled as round trips (the same
   station transmits and receives, turnaround ratio 1: range = round trip / 2, range-rate =
   mean of both legs' rates, Doppler = -2 f ρ̇ / c), with partials through both light times;
   its angles are the down leg's, as one-way.
5. **Solver.** :func:`trackproc.methods.least_squares.solve`: whitened Gauss-Newton by SVD,
   Levenberg-Marquardt damping, k-sigma editing, a-priori constraints (``--apriori-sigma``,
   ``--apriori-initial``), failures as :class:`~trackproc.errors.ProcessingError`.

Reports: the full covariance, correlation, sigmas, a-posteriori variance factor and condition
number; the state covariance in RTN (radial, along-track = N × R, cross-track = r × v / |r × v|,
an inertial rotation: the velocity block is rotated, not differentiated); residual RMS per
station and kind; optionally seed 002's comparison (Doppler-only vs extended) and the
two-stage method.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from typing import Mapping, Optional, Sequence

import numpy as np
import pandas as pd

from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)
from trackproc.errors import InputError, ProcessingError
from trackproc.isotime import iso_utc
from trackproc.dynamics.rtn import rtn_covariance
from trackproc.models import observation as ob
from trackproc.models import parameters as pm
from trackproc.vocabulary import DOPPLER_BIASES, KIND_UNITS, NOISE_MODELS

#: Unit of each kind's values (SI).
UNITS = KIND_UNITS
DOPPLER_BIAS = DOPPLER_BIASES
DOPPLER_BIAS_PER = ("pass", "station")
#: Margin (s) added before the first sample so that emission times are covered.
_LIGHT_TIME_MARGIN_S = 1.0
#: Names that stand for several parameters in ``apriori_sigma``.
_GROUPS = {"position": ("x", "y", "z"), "velocity": ("vx", "vy", "vz"), "state": pm.STATE_NAMES}
RESIDUAL_COLUMNS = ("time", "station", "pass_id", "kind", "unit", "observed", "computed", "residual",
                    "normalized_residual", "sigma", "edited")


@dataclass
class EstimateOptions:
    """Options of :func:`estimate` (defaults = the CLI's).

    ``range_bias``: estimate a range bias for every station with ranges (True), for the listed
    stations, or none (False); ``doppler_bias``: None, ``"offset"`` or ``"offset+drift"``,
    ``doppler_bias_per``: ``"pass"`` or ``"station"``; ``angle_bias``: azimuth and elevation
    biases per station with angles; ``apriori_sigma``: name -> 1-sigma (a parameter name, a
    family such as ``range_bias``, or ``position``/``velocity``/``state``); ``apriori_initial``:
    use the initial state's 6 × 6 covariance as an a-priori constraint; ``epoch``: the solution
    epoch (None = the initial state's; ``"first"`` = the first sample; or a UTC datetime64);
    ``kinds``: kinds to use (None = all); ``range_rate_model``: None = from the pass files
    (default doppler); ``compare_doppler_only``, ``two_stage``: the seed 002 reports.
    ``noise``: the noise model of each pass's Doppler/range-rate samples (:func:`pass_noise`):
    ``"auto"`` (chosen per pass by REML among white, AR(1), and for one-way passes with a
    frequency offset a random walk of the transmitter frequency and both; then GLS), ``"white"``
    (independent samples), or one of ``"ar1"``, ``"walk"``, ``"ar1+walk"``;
    ``oscillator_noise``: the random-walk intensity (Hz/√s) instead of estimating it.
    """

    range_bias: bool | Sequence[str] = False
    doppler_bias: Optional[str] = None
    doppler_bias_per: str = "pass"
    angle_bias: bool = False
    apriori_sigma: Mapping[str, float] = field(default_factory=dict)
    apriori_initial: bool = False
    force: str = "j2"
    earth: str = "wgs84"
    range_rate_model: Optional[str] = None
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None
    max_iterations: int = 20
    clip: Optional[float] = 4.0
    epoch: object = None
    kinds: Optional[Sequence[str]] = None
    compare_doppler_only: bool = False
    two_stage: bool = False
    rank_rtol: float = 1e-9
    noise: str = "auto"
    oscillator_noise: Optional[float] = None


# ----------------------------------------------------------------------------- the problem

@dataclass
class Problem:
    """An assembled estimation problem: samples, parameters, model (reusable, e.g. Monte Carlo).

    ``meas`` (:class:`~trackproc.models.observation.MeasurementSet`), ``params`` (the drivers;
    the selected ones are the estimated vector), ``epoch`` (UTC datetime64) and ``frame`` of the
    propagation, ``force``, ``range_rate_model``, ``modifiers`` of the bias drivers, ``priors``,
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
    evaluations: int = 0

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

    def trajectory(self, x):
        """The propagated trajectory (with STM) of the state in ``x``."""
        from trackproc.dynamics import propagator

        t = self.meas.t_s
        span = [float(t.min()) - _LIGHT_TIME_MARGIN_S, float(t.max())]
        traj = propagator.propagate(x[:3], x[3:6], self.epoch, span, force=self.force, stm=True, frame=self.frame,
                                    eop=self.eop)
        return traj.raise_for_outcome()

    def model(self, x):
        """``(computed (N,), jacobian (N, n))`` at the selected parameter values ``x``."""
        x = np.asarray(x, float)
        cols, fixed = self._columns()
        values = dict(fixed)
        values.update({n: x[i] for n, i in cols.items()})
        try:
            traj = self.trajectory(x)
            h, jac, _ = ob.evaluate(self.meas, traj, modifiers=self.modifiers, bias_values=values, bias_columns=cols,
                                    n_columns=x.size, range_rate_model=self.range_rate_model)
        except ValueError as exc:
            raise ArithmeticError(str(exc)) from None
        self.evaluations += 1
        return h, jac

    def solve(self, observed=None, *, max_iterations: int = 20, clip: Optional[float] = 4.0,
              rank_rtol: float = 1e-9, x0=None, priors=None, noise=None, edited=None):
        """:func:`~trackproc.methods.least_squares.solve` on this problem (``observed``
        replaces the samples' values, e.g. for Monte Carlo); with ``noise`` (a correlated
        :class:`~trackproc.methods.noise.PassCovariance`), generalised least squares
        (:func:`~trackproc.methods.least_squares.solve_gls`, starting from the ``edited`` samples)."""
        from trackproc.methods.least_squares import Options, solve, solve_gls

        y = self.meas.observed if observed is None else np.asarray(observed, float)
        lo, hi = self.params.bounds()
        if noise is not None and not noise.is_white:
            opts = Options(max_iterations=max_iterations, clip=None, rank_rtol=rank_rtol)

            from trackproc.methods.refinement import CachedModel, geodesic_retraction

            pri = self.priors if priors is None else priors

            def fit(model_w, y_w, start):
                # the step follows the curved valleys the correlated weighting leaves (as refine's)
                cached = CachedModel(model_w)
                ones = np.ones(y_w.size)
                return solve(cached, start, y_w, ones, names=self.names, scales=self.params.scales(), priors=pri,
                             bounds=(lo, hi), options=opts,
                             retract=geodesic_retraction(cached, ones, self.params.scales(), pri)), None

            return solve_gls(self.model, self.x0 if x0 is None else x0, y, noise, fit, clip=clip, edited=edited)[0]
        return solve(self.model, self.x0 if x0 is None else x0, y, self.meas.sigma, names=self.names,
                     scales=self.params.scales(), priors=self.priors if priors is None else priors,
                     periodic=self.meas.periodic, bounds=(lo, hi),
                     options=Options(max_iterations=max_iterations, clip=clip, rank_rtol=rank_rtol))


def _merge_tables(tables, kinds):
    """One frame of all samples with their file, carrier and metadata checks."""
    frames, carriers, models, sources = [], [], [], []
    for source, table in tables:
        frame = table.frame
        meta = table.meta or {}
        if len(frame) == 0:
            raise InputError("no samples", file=source, expected="a pass file with at least one sample")
        mode = meta.get("doppler_mode") or "one-way"
        kinds_here = set(frame["kind"].astype(str))
        if mode not in ob.MODES and kinds_here & set(ob.LINK_KINDS):
            raise InputError("unknown link mode", file=source, column="doppler_mode", found=mode,
                             expected="one-way or two-way (a round trip through a transponder of ratio 1)")
        carrier = meta.get("carrier_hz")
        if "doppler" in kinds_here and (kinds is None or "doppler" in kinds):
            if not isinstance(carrier, (int, float)) or not (carrier > 0):
                raise InputError("Doppler samples need the carrier frequency", file=source, column="carrier_hz",
                                 found=carrier, expected="carrier_hz > 0 in the file metadata (trackproc ingest "
                                                         "--carrier-hz)")
        carriers.append(float(carrier) if isinstance(carrier, (int, float)) and carrier > 0 else math.nan)
        models.append(meta.get("range_rate_model"))
        sub = frame[["time", "station", "pass_id", "kind", "value", "sigma"]].copy()
        sub["_source"] = source
        sub["_carrier"] = carriers[-1]
        sub["_mode"] = mode if mode in ob.MODES else "one-way"     # angles only: the link does not matter
        sub["_row"] = np.arange(len(sub))
        frames.append(sub)
        sources.append(source)
    frame = pd.concat(frames, ignore_index=True)
    if kinds is not None:
        frame = frame[frame["kind"].isin(list(kinds))].reset_index(drop=True)
        if len(frame) == 0:
            raise InputError("no samples of the requested kinds", column="--kinds", found=",".join(kinds),
                             expected="kinds present in the pass files")
    return frame, models


def _check_samples(frame):
    bad = ~(np.isfinite(frame["value"].to_numpy(float)))
    bad_sigma = ~(np.isfinite(frame["sigma"].to_numpy(float)) & (frame["sigma"].to_numpy(float) > 0))
    for mask, column, expected in ((bad, "value", "a finite number"), (bad_sigma, "sigma", "a positive number")):
        if mask.any():
            i = int(np.flatnonzero(mask)[0])
            r = frame.iloc[i]
            raise InputError(f"invalid {column} at {pd.Timestamp(r['time']).isoformat()} ({r['station']}, "
                             f"{r['kind']}; sample {int(r['_row']) + 1} of the file)", file=r["_source"],
                             column=column, found=r[column], expected=expected)


def _resolve_stations(frame, tables, stations):
    """Station objects for every station in the samples: --stations first, then metadata."""
    known = dict(stations or {})
    for source, table in tables:
        for name, st in table.stations().items():
            known.setdefault(name, st)
    missing = sorted(set(frame["station"].astype(str)) - set(known))
    if missing:
        name = missing[0]
        src = frame.loc[frame["station"] == name, "_source"].iloc[0]
        raise InputError("unknown station", file=src, column="station", found=name,
                         expected="a station of --stations or of the pass file's metadata"
                         + (f" ({', '.join(sorted(known))})" if known else " (give --stations STATIONS.csv)"))
    return known


def _solution_epoch(option, initial, times):
    if option is None or (isinstance(option, str) and option.lower() == "initial"):
        return np.datetime64(initial.epoch, "ns")
    if isinstance(option, str) and option.lower() == "first":
        return np.datetime64(times.min(), "ns")
    if isinstance(option, str):
        from trackproc.io.statefile import parse_epoch

        return parse_epoch(option, column="--epoch")
    return np.datetime64(option, "ns")


def _initial_at_epoch(initial, epoch, force, eop):
    """Initial GCRF state (and 6 × 6 covariance if any) moved to ``epoch`` (Taylor + STM)."""
    cov = initial.state_covariance
    if np.datetime64(initial.epoch, "ns") == epoch:
        return initial.rv, cov
    from trackproc.dynamics import propagator
    from trackproc.dynamics import timescales as ts

    dt = float(ts.seconds_since(ts.datetime64_to_jd_utc(epoch), initial.jd_utc))
    traj = propagator.propagate(initial.r_m, initial.v_m_s, initial.epoch, [dt], force=force, stm=cov is not None,
                                eop=eop).raise_for_outcome()
    rv = traj.state(dt)
    if cov is not None:
        cov = traj.covariance(dt, cov)
    return rv, cov


def _apriori_for(name, family, apriori):
    """The a-priori sigma of a parameter from the option's keys (exact name wins)."""
    if name in apriori:
        return apriori[name]
    for group, members in _GROUPS.items():
        if name in members and group in apriori:
            return apriori[group]
    if family in apriori:
        return apriori[family]
    return None


def build_problem(tables, initial, stations=None, options: EstimateOptions | None = None, eop=None) -> Problem:
    """Assemble the :class:`Problem` from pass tables, an initial state and stations.

    ``tables``: sequence of ``(source name, PassTable)``; ``initial``: a GCRF
    :class:`~trackproc.io.statefile.State`; ``stations``: name -> Station (optional when the pass
    files' metadata carry them). Raises :class:`InputError` for invalid input.
    """
    from trackproc.dynamics import geodesy, propagator
    from trackproc.dynamics import timescales as ts

    opt = options or EstimateOptions()
    if opt.noise not in ("auto", "white", "ar1", "walk", "ar1+walk"):
        raise InputError("unknown noise model", column="--noise", found=opt.noise,
                         expected="auto, white, ar1, walk or ar1+walk")
    if opt.oscillator_noise is not None and not (math.isfinite(opt.oscillator_noise) and opt.oscillator_noise > 0):
        raise InputError("the oscillator noise must be positive", column="--oscillator-noise",
                         found=opt.oscillator_noise, expected="a random-walk intensity > 0 in Hz per sqrt(s)")
    if opt.doppler_bias not in (None,) + DOPPLER_BIAS:
        raise InputError("unknown Doppler bias model", column="--doppler-bias", found=opt.doppler_bias,
                         expected=" or ".join(DOPPLER_BIAS))
    if opt.doppler_bias_per not in DOPPLER_BIAS_PER:
        raise InputError("unknown Doppler bias grouping", column="--doppler-bias-per", found=opt.doppler_bias_per,
                         expected=" or ".join(DOPPLER_BIAS_PER))
    if opt.kinds is not None:
        bad = [k for k in opt.kinds if k not in ob.KINDS]
        if bad or not opt.kinds:
            raise InputError("unknown measurement kind", column="--kinds", found=",".join(bad) or "(none)",
                             expected="a comma list of " + ",".join(ob.KINDS))
    if opt.force not in propagator.FORCES:
        raise InputError("unknown force model", column="--force", found=opt.force, expected="two-body or j2")
    if not tables:
        raise InputError("no pass files given", column="PASS", expected="one or more pass files, or -")
    frame, file_models = _merge_tables(tables, opt.kinds)
    _check_samples(frame)
    model = opt.range_rate_model
    if model is None:
        found = sorted({m for m in file_models if m})
        if len(found) > 1:
            raise InputError("pass files disagree on the range-rate model", column="range_rate_model",
                             found=", ".join(found), expected="one model; choose with --range-rate-model")
        model = found[0] if found else "doppler"
    if model not in ob.RANGE_RATE_MODELS:
        raise InputError("unknown range-rate model", column="--range-rate-model", found=model,
                         expected=" or ".join(ob.RANGE_RATE_MODELS))
    known = _resolve_stations(frame, tables, stations)

    times = frame["time"]
    if getattr(times.dt, "tz", None) is not None:
        times = times.dt.tz_convert("UTC").dt.tz_localize(None)
    t64 = times.to_numpy(dtype="datetime64[ns]")
    epoch = _solution_epoch(opt.epoch, initial, t64)
    epoch_jd = tuple(float(a) for a in ts.datetime64_to_jd_utc(epoch))
    jd1, jd2 = ts.datetime64_to_jd_utc(t64)
    t_s = np.asarray(ts.seconds_since((jd1, jd2), epoch_jd), float)

    n = len(frame)
    r_st = np.empty((n, 3))
    v_st = np.empty((n, 3))
    a_st = np.empty((n, 3))
    enu = np.empty((n, 3, 3))
    station_col = frame["station"].astype(str).to_numpy(dtype=object)
    for name in sorted(set(station_col)):
        rows = np.flatnonzero(station_col == name)
        st = known[name]
        lat, lon, r_itrf = geodesy.station_itrf(st, opt.earth)
        track = geodesy.station_gcrf(r_itrf, jd1[rows], jd2[rows], eop)
        r_st[rows], v_st[rows], a_st[rows] = track.r, track.v, track.a
        enu[rows] = geodesy.enu_matrix(lat, lon) @ track.gcrf_to_itrf
    meas = ob.MeasurementSet(t_s=t_s, kind=frame["kind"].astype(str).to_numpy(dtype=object), station=station_col,
                             pass_id=frame["pass_id"].astype(str).to_numpy(dtype=object),
                             observed=frame["value"].to_numpy(float), sigma=frame["sigma"].to_numpy(float),
                             r_st=r_st, v_st=v_st, gcrf_to_enu=enu, carrier_hz=frame["_carrier"].to_numpy(float),
                             a_st=a_st, mode=frame["_mode"].to_numpy(dtype=object))

    # parameters
    rv0, cov0 = _initial_at_epoch(initial, epoch, opt.force_model or opt.force, eop)
    apriori = dict(opt.apriori_sigma)
    for key, sigma in apriori.items():
        if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
            raise InputError("a-priori sigma must be positive", column="--apriori-sigma", found=f"{key}={sigma}",
                             expected="NAME=SIGMA with SIGMA > 0")
    params = pm.ParameterSet(pm.state_drivers(rv0, sigma=[_apriori_for(s, "state", apriori) for s in pm.STATE_NAMES]))
    kinds_by_station = frame.groupby("station")["kind"].agg(lambda k: set(k.astype(str))).to_dict()
    range_stations = sorted(s for s, k in kinds_by_station.items() if "range" in k)
    if opt.range_bias is True:
        wanted = range_stations
    elif opt.range_bias:
        wanted = list(opt.range_bias)
        dup = sorted({s for s in wanted if wanted.count(s) > 1})
        if dup:
            raise InputError("duplicate parameter", column="--range-bias", found=f"range_bias:{dup[0]}",
                             expected="each station once")
        for s in wanted:
            if s not in range_stations:
                raise InputError("range bias for a station without ranges", column="--range-bias", found=s,
                                 expected="one of " + (", ".join(range_stations) or "(no station has ranges)"))
    else:
        wanted = []
    for s in range_stations:
        prior_value = getattr(known[s], "range_bias_m", None)
        if s in wanted:
            params.add(pm.range_bias(s, prior_value or 0.0,
                                     apriori_sigma=_apriori_for(f"range_bias:{s}", "range_bias", apriori)))
        elif prior_value:
            d = params.add(pm.range_bias(s, prior_value))        # a known bias from the stations table
            d.selected = False
    epochs = {}
    if opt.doppler_bias:
        rr_rows = frame["kind"].isin(["doppler", "range_rate"]).to_numpy()
        keys_col = "pass_id" if opt.doppler_bias_per == "pass" else "station"
        keys = frame.loc[rr_rows, keys_col].astype(str)
        first = pd.Series(t_s[rr_rows], index=keys.index).groupby(keys.to_numpy()).min()
        for key in sorted(first.index):
            params.add(pm.doppler_offset(key, apriori_sigma=_apriori_for(f"doppler_offset:{key}", "doppler_offset",
                                                                         apriori)))
            if opt.doppler_bias == "offset+drift":
                d = params.add(pm.doppler_drift(key, float(first[key]),
                                                apriori_sigma=_apriori_for(f"doppler_drift:{key}", "doppler_drift",
                                                                           apriori)))
                epochs[d.name] = d.epoch_s
        if not len(first):
            raise InputError("no Doppler or range-rate samples for --doppler-bias", column="--doppler-bias",
                             found=opt.doppler_bias, expected="pass files with doppler or range_rate samples")
    if opt.angle_bias:
        for s, k in sorted(kinds_by_station.items()):
            if "azimuth" in k:
                params.add(pm.az_bias(s, apriori_sigma=_apriori_for(f"az_bias:{s}", "az_bias", apriori)))
            if "elevation" in k:
                params.add(pm.el_bias(s, apriori_sigma=_apriori_for(f"el_bias:{s}", "el_bias", apriori)))
    unknown = [k for k in apriori if k not in params and k not in _GROUPS and k not in pm.KINDS
               and k not in pm.STATE_NAMES]
    if unknown:
        raise InputError("a-priori sigma for an unknown parameter", column="--apriori-sigma", found=unknown[0],
                         expected="one of " + ", ".join(params.names + list(_GROUPS) + list(pm.KINDS)))
    try:
        modifiers = ob.bias_modifiers(meas, [d.name for d in params], epochs)
    except ValueError as exc:
        raise InputError(str(exc), column="--doppler-bias") from None

    # a-priori constraints
    from trackproc.methods.least_squares import Prior

    priors = []
    mask, centre, sigma = params.apriori()
    if mask.any():
        priors.append(Prior.diagonal(np.flatnonzero(mask), centre[mask], sigma[mask]))
    if opt.apriori_initial:
        if cov0 is None:
            raise InputError("the initial state has no covariance", file=initial.source, column="covariance",
                             expected="a state file with a 6 x 6 covariance for --apriori-initial")
        if mask[:6].any():
            raise InputError("give --apriori-initial or state a-priori sigmas, not both", column="--apriori-sigma")
        priors.append(Prior(np.arange(6), np.asarray(rv0, float), np.asarray(cov0, float)))
    frame_q = propagator.reference_frame(*epoch_jd, eop)
    return Problem(meas=meas, params=params, epoch=epoch, frame=frame_q, force=opt.force_model or opt.force,
                   range_rate_model=model,
                   modifiers=modifiers, priors=priors, times=t64, sources=frame["_source"].to_numpy(dtype=object),
                   eop=eop)


# ----------------------------------------------------------------------------- result

@dataclass
class EstimateResult:
    """Everything :func:`estimate` produces (the CLI writes it).

    ``state`` (:class:`~trackproc.io.statefile.State`, GCRF, every estimated parameter, its
    sigma, the full covariance and the diagnostics), ``solution`` (the solver's
    :class:`~trackproc.methods.least_squares.Solution`), ``problem``, ``residuals`` (one row per
    sample: :data:`RESIDUAL_COLUMNS`), ``rtn_covariance`` (6 × 6, m and m/s), ``comparison``
    (Doppler-only vs extended, or None), ``two_stage`` (:class:`~trackproc.methods.two_stage.TwoStage`
    or None) and ``two_stage_solution`` (its stage-2 solution), ``warnings``.
    """

    state: object
    solution: object
    problem: Problem
    residuals: pd.DataFrame
    rtn_covariance: np.ndarray
    comparison: Optional[dict] = None
    two_stage: Optional[object] = None
    two_stage_solution: Optional[object] = None
    warnings: list = field(default_factory=list)
    quality: Optional[object] = None


def _rms_table(problem: Problem, sol) -> dict:
    """Per station and kind: counts, edited, RMS (unit) and WRMS (normalized) of kept samples."""
    out = {}
    meas = problem.meas
    for st in sorted(set(meas.station)):
        for kind in ob.KINDS:
            rows = (meas.station == st) & (meas.kind == kind)
            if not rows.any():
                continue
            kept = rows & ~sol.edited
            r = sol.residual[kept]
            z = sol.normalized[kept]
            out.setdefault(st, {})[kind] = {
                "n": int(rows.sum()), "edited": int((rows & sol.edited).sum()), "unit": UNITS[kind],
                "rms": float(np.sqrt(np.mean(r * r))) if r.size else None,
                "mean": float(np.mean(r)) if r.size else None,
                "wrms": float(np.sqrt(np.mean(z * z))) if z.size else None}
    return out


def residual_frame(problem: Problem, sol) -> pd.DataFrame:
    """The residual table (:data:`RESIDUAL_COLUMNS`), samples in time order per station."""
    meas = problem.meas
    frame = pd.DataFrame({
        "time": pd.DatetimeIndex(problem.times).tz_localize("UTC"), "station": meas.station.astype(str),
        "pass_id": meas.pass_id.astype(str), "kind": meas.kind.astype(str),
        "unit": [UNITS[k] for k in meas.kind], "observed": meas.observed, "computed": sol.computed,
        "residual": sol.residual, "normalized_residual": sol.normalized, "sigma": meas.sigma,
        "edited": sol.edited.astype(bool)})
    order = np.lexsort((frame["kind"].to_numpy(dtype=str), problem.times, frame["station"].to_numpy(dtype=str)))
    return frame.iloc[order].reset_index(drop=True)


def estimate(tables, initial, stations=None, options: EstimateOptions | None = None, eop=None) -> EstimateResult:
    """Estimate the orbit state and the selected biases from pass tables (see the module docstring).

    Returns :class:`EstimateResult`; raises :class:`InputError` (exit 2) for invalid input and
    :class:`ProcessingError` (exit 1) when the estimation fails (too few data, rank deficiency,
    non-convergence), with diagnostics.
    """
    from trackproc.constants import force_model_constants
    from trackproc.io.statefile import State

    opt = options or EstimateOptions()
    problem = build_problem(tables, initial, stations, opt, eop)
    sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol)
    noise_report = None
    if opt.noise != "white" or opt.oscillator_noise is not None:
        previous = None
        for _ in range(2):            # REML on the residuals, GLS, REML again on its residuals
            cov, noise_report = pass_noise(problem, sol, opt)
            if cov is None and previous is None:
                break                 # white: the weighted fit stands
            sol = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol,
                                noise=cov, edited=sol.edited, x0=sol.values)
            previous = cov
    problem.params.set_values(sol.values)
    x = sol.values
    names = sol.names
    rtn = rtn_covariance(x[:3], x[3:6], sol.covariance[:6, :6])
    warnings = []
    if sol.dof > 0 and sol.variance_factor > 4.0:
        warnings.append(f"a-posteriori variance factor {sol.variance_factor:.3g} (> 4): the sigmas of the data "
                        "are too small or the model misses something; the covariance is optimistic")
    if sol.n_prior:
        from scipy.stats import chi2 as chi2_dist

        limit = float(chi2_dist.ppf(0.999, sol.n_prior))
        if sol.chi2_prior > limit:
            warnings.append(f"the solution departs from the a-priori values by chi2 = {sol.chi2_prior:.4g} over "
                            f"{sol.n_prior} constraints (99.9 % limit {limit:.3g}): the data and the a-priori "
                            "(initial state, biases) disagree; check for a bad pass")
    if sol.n_edited > 0.1 * sol.n_measurements:
        warnings.append(f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)")
    fixed = {d.name: d.value for d in problem.params if not d.selected}
    drifts = {d.name: d.epoch_s for d in problem.params if d.epoch_s is not None}
    diagnostics = {
        "converged": bool(sol.converged), "message": sol.message, "iterations": int(sol.iterations),
        "damped_steps": int(sol.damped_steps), "cost": float(sol.chi2), "cost_history": sol.cost_history,
        "dof": int(sol.dof), "variance_factor": sol.variance_factor, "wrms": sol.wrms,
        "apriori_rows": sol.n_prior, "chi2_apriori": sol.chi2_prior,
        "condition_number": sol.condition_number,
        "measurements": sol.n_measurements, "edited": sol.n_edited, "clip_sigma": opt.clip,
        "rms": _rms_table(problem, sol),
        "correlation": sol.correlation,
        "covariance_rtn": rtn, "sigma_rtn": {"radial_m": math.sqrt(rtn[0, 0]), "along_m": math.sqrt(rtn[1, 1]),
                                             "cross_m": math.sqrt(rtn[2, 2]), "radial_m_s": math.sqrt(rtn[3, 3]),
                                             "along_m_s": math.sqrt(rtn[4, 4]), "cross_m_s": math.sqrt(rtn[5, 5])},
        "units": problem.params.units(),
    }
    if noise_report is not None:
        diagnostics["noise"] = noise_report
    quality = estimate_quality(problem, sol)
    comparison = _compare(problem, sol) if opt.compare_doppler_only else None
    two, sol2 = _two_stage(problem, sol, opt) if opt.two_stage else (None, None)
    if comparison is not None:
        diagnostics["compare_doppler_only"] = comparison
    if two is not None:
        diagnostics["two_stage"] = _two_stage_dict(two, sol2)
    extra = {"estimation": {
        "method": "batch weighted least squares (Gauss-Newton by SVD, Levenberg-Marquardt damping)",
        "range_rate_model": problem.range_rate_model,
        "light_time": _light_time_note(problem.meas),
        "propagator": "Taylor (DT) with state transition matrix, quasi-inertial frame of the solution epoch",
        "earth": opt.earth, "doppler_bias": opt.doppler_bias, "doppler_bias_per": opt.doppler_bias_per,
        "fixed_parameters": fixed, "drift_epochs_s": drifts,
        "apriori": {n: s for n, s, m in zip(names, problem.params.apriori()[2], problem.params.apriori()[0]) if m},
        "apriori_initial": bool(opt.apriori_initial),
        "sources": sorted({str(s) for s in problem.sources}),
    }, "quality": quality.as_dict()}
    state = State.from_vectors(problem.epoch, x[:3], x[3:6], parameters=list(names), values=x, sigma=sol.sigma,
                               covariance=sol.covariance,
                               force_model=opt.force_model.label() if opt.force_model else opt.force,
                               constants=(opt.force_model.describe() if opt.force_model
                                          else force_model_constants(opt.force)),
                               eop_source=getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)",
                               diagnostics=diagnostics, extra=extra)
    return EstimateResult(state=state, solution=sol, problem=problem, residuals=residual_frame(problem, sol),
                          rtn_covariance=rtn, comparison=comparison, two_stage=two, two_stage_solution=sol2,
                          warnings=warnings, quality=quality)


def estimate_quality(problem: Problem, sol):
    """The :class:`~trackproc.methods.quality.Quality` of a batch solution: convergence, a-priori
    conflict (``rejected``: the covariance leans on an a-priori the data contradict), variance
    factor against its 99.9 % point, the pass that dominates the misfit (named), residual
    whiteness per pass (the worst named), edited samples."""
    from trackproc.methods import quality as qm

    q = qm.Quality()
    if not sol.converged:
        q.add("not_converged", "rejected", f"the solver did not converge ({sol.message})")
    if sol.n_prior:
        limit = qm.chi2_limit(sol.n_prior)
        q.add("apriori_conflict", "ok" if sol.chi2_prior <= limit else "rejected",
              f"a-priori chi2 {sol.chi2_prior:.4g} over {sol.n_prior} constraints (99.9 % limit {limit:.3g})"
              + ("" if sol.chi2_prior <= limit else ": the data and the a-priori disagree, the covariance that leans "
                 "on the a-priori does not hold"), value=sol.chi2_prior, limit=limit)
    vf_limit = qm.variance_factor_limit(sol.dof) if sol.dof > 0 else None
    if sol.dof > 0 and math.isfinite(sol.variance_factor):
        q.add("variance_factor", "ok" if sol.variance_factor <= vf_limit else "suspect",
              f"a-posteriori variance factor {sol.variance_factor:.4g} (99.9 % limit {vf_limit:.3g})",
              value=sol.variance_factor, limit=vf_limit)
    # per pass: its share of the misfit and the whiteness of its residuals (time order)
    meas = problem.meas
    kept = ~np.asarray(sol.edited, bool)
    z = np.asarray(sol.normalized, float)
    passes = []
    station, pass_id, kind = meas.station.astype(str), meas.pass_id.astype(str), meas.kind.astype(str)
    for key in sorted(set(zip(station, pass_id, kind))):
        rows = kept & (station == key[0]) & (pass_id == key[1]) & (kind == key[2])
        if not rows.any():
            continue
        idx = np.flatnonzero(rows)
        idx = idx[np.argsort(problem.times[idx], kind="stable")]
        w = qm.whiteness(z[idx])
        passes.append({"pass": f"{key[0]}/{key[1]} {key[2]}", "n": int(idx.size), "chi2": float(z[idx] @ z[idx]),
                       "whiteness": w})
    total = sum(p["chi2"] for p in passes)
    if len(passes) > 1 and total > 0 and sol.dof > 0 and sol.variance_factor > vf_limit:
        worst = max(passes, key=lambda p: p["chi2"] / p["n"])
        share = worst["chi2"] / total
        if share > 0.5:
            q.add("dominant_pass", "suspect",
                  f"pass {worst['pass']} carries {100 * share:.0f} % of the misfit with {worst['n']} of "
                  f"{sum(p['n'] for p in passes)} samples (variance factor {worst['chi2'] / worst['n']:.3g}): "
                  "check it, or leave it out", value=share, limit=0.5)
    if passes:
        worst = max(passes, key=lambda p: (p["whiteness"]["lag1_autocorrelation"]
                                          if math.isfinite(p["whiteness"]["lag1_autocorrelation"]) else -1.0))
        if math.isfinite(worst["whiteness"]["lag1_autocorrelation"]):
            before = len(q.reasons)
            qm.add_whiteness(q, worst["whiteness"])
            if len(q.reasons) > before:
                q.reasons[-1]["message"] = f"pass {worst['pass']}: " + q.reasons[-1]["message"]
    if sol.n_edited > 0.1 * sol.n_measurements:
        q.add("edited", "suspect", f"{sol.n_edited} of {sol.n_measurements} samples edited (> 10 %)",
              value=int(sol.n_edited), limit=0.1 * sol.n_measurements)
    return q




def pass_noise(problem: Problem, sol, opt: EstimateOptions):
    """The noise model of every pass's Doppler and range-rate samples from the residuals of
    ``sol`` (:func:`trackproc.methods.noise.fit_noise`: REML with the pass's Jacobian columns as
    fixed effects; the random walk of the transmitter frequency only for one-way passes with a
    frequency offset). Returns ``(PassCovariance or None when every pass is white, report)``;
    the report lists each pass's model and effective number of samples."""
    from trackproc.methods import noise as nz

    meas = problem.meas
    keep_all = ~np.asarray(sol.edited, bool)
    rr = np.isin(meas.kind, ["doppler", "range_rate"])
    blocks, report = [], {}
    names = problem.names
    _, jac_all = problem.model(np.asarray(sol.values, float))     # (a GLS solution's own rows are whitened)
    for st, pid in sorted(set(zip(meas.station[rr], meas.pass_id[rr]))):
        rows = np.flatnonzero(rr & (meas.station == st) & (meas.pass_id == pid))
        keep = keep_all[rows]
        if keep.sum() < 20:
            continue
        t = meas.t_s[rows]
        jac = np.asarray(jac_all, float)[rows]
        one_way = not bool(np.any(meas.two_way[rows]))
        osc = one_way and any(n in (f"doppler_offset:{pid}", f"doppler_offset:{st}") for n in names)
        if opt.noise == "auto":
            models = nz.MODELS if osc else ("white", "ar1")
        elif opt.noise == "white":
            models = ("white",)
        else:
            models = (opt.noise,)
        nf = nz.fit_noise(t[keep], np.asarray(sol.residual, float)[rows][keep], jac[keep], models=models,
                          walk=opt.oscillator_noise if osc else None, t0=float(t.min()))
        d = nf.as_dict()
        d.pop("candidates", None)
        report[f"{st}/{pid}"] = d
        if not nf.model.is_white:
            blocks.append((rows, nf.model, float(t.min())))
    if not blocks:
        return None, report
    return nz.PassCovariance(meas.sigma, meas.t_s, blocks), report


def _light_time_note(meas) -> str:
    """How the samples' light time was modelled (the state file's ``estimation`` record)."""
    if not meas.two_way.any():
        return "one-way, time tag at reception, range-rate > 0 receding"
    both = "one-way and " if (~meas.two_way & np.isin(meas.kind, ob.LINK_KINDS)).any() else ""
    return (f"{both}two-way (round trip to the same station, turnaround ratio 1: range = round trip / 2, "
            "range-rate = mean of both legs), time tag at reception, range-rate > 0 receding")


# ----------------------------------------------------------------------------- seed 002 reports

def _motion_columns(names):
    return [i for i, n in enumerate(names) if not n.startswith("range_bias:")]


def _compare(problem: Problem, sol) -> dict:
    """Seed 002 eqs. 9, 15: solve without the ranges (and range biases), compare motion blocks."""

    names = sol.names
    mcol = _motion_columns(names)
    motion = [names[i] for i in mcol]
    rows = problem.meas.kind != "range"
    out = {"parameters": motion, "extended_sigma": sol.sigma[mcol].tolist()}
    if rows.all() or not rows.any():
        out["doppler_only"] = "not computed: the data have no ranges, or only ranges"
        return out
    sub = _subproblem(problem, rows, keep_range_bias=False)
    try:
        sol1 = sub.solve(max_iterations=20, clip=None)
    except ProcessingError as exc:
        out["doppler_only"] = f"not observable without the ranges: {exc}"
        return out
    from trackproc.methods import two_stage as tsm

    idx = [sol1.names.index(n) for n in motion]
    kx = sol.covariance[np.ix_(mcol, mcol)]
    # the Doppler-only error matrix (A1ᵀ K⁻¹ A1)⁻¹ on the extended solution's Jacobian (same A1,
    # as in seed 002 eqs. 9 and 15), so that the two blocks differ only by what the ranges add
    a1 = rows & ~sol.edited
    k1 = _with_priors(tsm.covariance(sol.jacobian[a1][:, mcol], problem.meas.sigma[a1] ** 2), problem.priors, mcol)
    # eigenvalues of K1^-1/2 (K1 - Kx) K1^-1/2: 0 = the ranges add nothing in that direction
    # (seed 002 eq. 15, one range per offset), 1 = they determine it completely
    l_inv = np.linalg.inv(np.linalg.cholesky(k1))
    w = np.linalg.eigvalsh(l_inv @ (k1 - kx) @ l_inv.T)
    out.update({"doppler_only_sigma": np.sqrt(np.diag(k1)).tolist(),
                "doppler_only_solved_sigma": sol1.sigma[idx].tolist(),
                "doppler_only_values": sol1.values[idx].tolist(), "extended_values": sol.values[mcol].tolist(),
                "doppler_only_covariance": k1, "extended_covariance": kx,
                "relative_reduction_min": float(w.min()), "relative_reduction_max": float(w.max()),
                "ranges": int((~rows).sum())})
    return out


def _subproblem(problem: Problem, rows, keep_range_bias: bool) -> Problem:
    """The problem restricted to ``rows`` (and without range-bias drivers unless kept)."""
    meas = problem.meas.subset(np.flatnonzero(rows))
    params = pm.ParameterSet()
    for d in problem.params:
        if d.family == "range_bias" and not keep_range_bias:
            continue
        params.add(pm.ParameterDriver(d.name, d.unit, d.value, d.scale, apriori_sigma=d.apriori_sigma,
                                      apriori_value=d.apriori_value if d.apriori_value is not None else d.reference,
                                      selected=d.selected, bounds=d.bounds, epoch_s=d.epoch_s,
                                      description=d.description))
    epochs = {d.name: d.epoch_s for d in params if d.epoch_s is not None}
    modifiers = ob.bias_modifiers(meas, [d.name for d in params if d.family != "range_bias" or keep_range_bias],
                                  epochs)
    from trackproc.methods.least_squares import Prior

    mask, centre, sigma = params.apriori()
    priors = [Prior.diagonal(np.flatnonzero(mask), centre[mask], sigma[mask])] if mask.any() else []
    for p in problem.priors:          # a full initial-state prior stays on x..vz
        if p.covariance.shape[0] == 6 and np.array_equal(p.index, np.arange(6)) and not mask[:6].any():
            priors.append(p)
    return Problem(meas=meas, params=params, epoch=problem.epoch, frame=problem.frame, force=problem.force,
                   range_rate_model=problem.range_rate_model, modifiers=modifiers, priors=priors,
                   times=problem.times[rows], sources=problem.sources[rows], eop=problem.eop)


def _two_stage(problem: Problem, sol, opt: EstimateOptions):
    """Seed 002 eqs. 17-22: stage 1 per-pass offsets from the orbit without ranges, accumulated
    per station (Π); stage 2 with the bias-corrected ranges (error matrix D + E Π Eᵀ)."""
    from trackproc.methods import two_stage as tsm
    from trackproc.methods.least_squares import Prior

    meas = problem.meas
    is_range = meas.kind == "range"
    names = sol.names
    bias_names = [n for n in names if n.startswith("range_bias:")]
    if not bias_names or not is_range.any() or is_range.all():
        raise InputError("--two-stage needs ranges with --range-bias and other (Doppler, range-rate, angle) data",
                         column="--two-stage")
    # stage 0: the orbit from the data without ranges
    sub = _subproblem(problem, ~is_range, keep_range_bias=False)
    sol1 = sub.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol)
    motion = sol1.names
    k1 = sol1.covariance
    # stage 1: per-pass offsets against that orbit
    x_full = np.array([sol1.values[motion.index(n)] if n in motion else 0.0 for n in names])
    h, jac = problem.model(x_full)
    mcol = [names.index(n) for n in motion]
    rows = np.flatnonzero(is_range)
    w = 1.0 / meas.sigma[rows] ** 2
    res = meas.observed[rows] - h[rows]
    passes = sorted(set(meas.pass_id[rows]))
    est, var, a_pass, pass_station, table = [], [], [], [], []
    for p in passes:
        sel = meas.pass_id[rows] == p
        wp = w[sel]
        est.append(float(np.sum(wp * res[sel]) / wp.sum()))
        var.append(1.0 / wp.sum())
        a_pass.append((wp[:, None] * jac[rows[sel]][:, mcol]).sum(0) / wp.sum())
        station = meas.station[rows[sel]][0]
        pass_station.append(station)
        table.append({"pass_id": p, "station": station, "n": int(sel.sum()), "offset_m": est[-1],
                      "noise_sigma_m": math.sqrt(var[-1])})
    a_pass = np.array(a_pass)
    c_pass = np.diag(var) + a_pass @ k1 @ a_pass.T
    stations = [n.split(":", 1)[1] for n in bias_names]
    means, pi, _ = tsm.accumulate(est, c_pass, pass_station, stations)
    for row, s in zip(table, pass_station):
        row["orbit_sigma_m"] = float(np.sqrt(a_pass[table.index(row)] @ k1 @ a_pass[table.index(row)]))
    # stage 2: ranges corrected by the accumulated offsets, error matrix D + E Π Eᵀ (as a prior on the offsets)
    bidx = np.array([names.index(n) for n in bias_names])
    priors = [p for p in problem.priors if not np.isin(p.index, bidx).any()]
    priors.append(Prior(bidx, means, pi))
    x0 = x_full.copy()
    x0[bidx] = means
    sol2 = problem.solve(max_iterations=opt.max_iterations, clip=opt.clip, rank_rtol=opt.rank_rtol, x0=x0,
                         priors=priors)
    k_prime = sol2.covariance[np.ix_(mcol, mcol)]
    # K from the A1 rows, and ΔK by the inversion lemma, all from stage 2's Jacobian
    jac2 = sol2.jacobian
    keep = ~sol2.edited
    a1_rows = keep & ~is_range
    a2_rows = keep & is_range
    k = tsm.covariance(jac2[a1_rows][:, mcol], meas.sigma[a1_rows] ** 2)
    k_with_priors = _with_priors(k, problem.priors, mcol)
    e = jac2[a2_rows][:, bidx]
    a2c, eye = tsm.compress(jac2[a2_rows][:, mcol], meas.sigma[a2_rows] ** 2, e, pi)
    k_lemma, dk, _ = tsm.two_stage_update(k_with_priors, a2c, eye)
    err = float(np.abs(k_prime - k_lemma).max() / np.abs(k_with_priors).max())
    return tsm.TwoStage(names=motion, k=k_with_priors, k_prime=k_prime, delta_k=dk, stations=stations, biases=means,
                        pi=pi, passes=table, identity_error=err,
                        delta_k_min_eigenvalue=float(np.linalg.eigvalsh(dk).min())), sol2


def _with_priors(k, priors, mcol):
    """K including the a-priori constraints on the motion parameters (information added)."""
    if not priors:
        return k
    info = np.linalg.inv(k)
    pos = {c: i for i, c in enumerate(mcol)}
    for p in priors:
        if all(int(i) in pos for i in p.index):
            idx = [pos[int(i)] for i in p.index]
            info[np.ix_(idx, idx)] += np.linalg.inv(p.covariance)
    out = np.linalg.inv(info)
    return 0.5 * (out + out.T)


def _two_stage_dict(two, sol2) -> dict:
    return {"parameters": two.names, "K": two.k, "K_prime": two.k_prime, "delta_K": two.delta_k,
            "sigma_K": np.sqrt(np.diag(two.k)).tolist(), "sigma_K_prime": np.sqrt(np.diag(two.k_prime)).tolist(),
            "stations": two.stations, "stage1_offsets_m": two.biases.tolist(), "Pi": two.pi,
            "passes": two.passes, "identity_error": two.identity_error,
            "delta_K_min_eigenvalue": two.delta_k_min_eigenvalue,
            "stage2_values": dict(zip(sol2.names, sol2.values.tolist())),
            "stage2_sigma": dict(zip(sol2.names, sol2.sigma.tolist()))}


# ----------------------------------------------------------------------------- text and plot

def _for_people(value, unit) -> str:
    """A value with its unit as a person reads it: angles in degrees (radians stay in the files)."""
    if unit == "rad":
        return f"{math.degrees(value):.4g} deg"
    return f"{value:.4g} {unit}"


def _fmt(value, sigma, unit):
    if unit == "rad":     # angle biases: degrees for people
        value, sigma, unit = math.degrees(value), math.degrees(sigma), "deg"
    return f"{value:>18.6f} ± {sigma:<12.4g} {unit}"


def summary_text(result: EstimateResult) -> str:
    """One screen for a person: parameters ± sigma, RTN sigmas, fit statistics, RMS per station."""
    sol = result.solution
    st = result.state
    d = st.diagnostics
    units = d["units"]
    lines = [f"trackproc estimate: {'converged' if sol.converged else 'NOT converged'} in {sol.iterations} "
             f"iterations ({sol.message}); epoch {iso_utc(st.epoch, 3)}, GCRF, "
             f"force {st.force_model}, range-rate model {result.problem.range_rate_model}"]
    for name, value, sigma, unit in zip(sol.names, sol.values, sol.sigma, units):
        lines.append(f"  {name:<28s}{_fmt(value, sigma, unit)}")
    s = d["sigma_rtn"]
    lines.append(f"  sigma RTN: radial {s['radial_m']:.3g} m, along {s['along_m']:.3g} m, cross {s['cross_m']:.3g} m; "
                 f"{s['radial_m_s']:.3g}, {s['along_m_s']:.3g}, {s['cross_m_s']:.3g} m/s")
    lines.append(f"  samples {sol.n_measurements}, edited {sol.n_edited}, dof {sol.dof}, chi2 {sol.chi2:.6g}, "
                 f"variance factor {sol.variance_factor:.4g}, condition number {sol.condition_number:.3g}")
    for station, kinds in d["rms"].items():
        parts = [f"{k} {_for_people(v['rms'], v['unit'])} (n {v['n']}, edited {v['edited']}, wrms {v['wrms']:.3g})"
                 for k, v in kinds.items() if v["rms"] is not None]
        lines.append(f"  {station}: " + "; ".join(parts))
    if result.comparison and "doppler_only_sigma" in result.comparison:
        c = result.comparison
        lines.append("  seed 002 comparison (sigma): parameter, without ranges, extended")
        for n, a, b in zip(c["parameters"], c["doppler_only_sigma"], c["extended_sigma"]):
            lines.append(f"    {n:<28s}{a:>14.5g}{b:>14.5g}")
    elif result.comparison:
        lines.append(f"  seed 002 comparison: {result.comparison.get('doppler_only')}")
    if result.two_stage is not None:
        two = result.two_stage
        lines.append(f"  two-stage (seed 002 eqs. 17-22): |K' - (K - dK)|/|K| = {two.identity_error:.2g}, "
                     f"min eig dK = {two.delta_k_min_eigenvalue:.3g}")
        for n, a, b in zip(two.names, np.sqrt(np.diag(two.k)), np.sqrt(np.diag(two.k_prime))):
            lines.append(f"    {n:<28s} sigma K {a:>12.5g}  sigma K' {b:>12.5g}")
        for sname, b, p in zip(two.stations, two.biases, np.sqrt(np.diag(two.pi))):
            lines.append(f"    stage-1 range_bias:{sname} = {b:.3f} ± {p:.3g} m")
    for w in result.warnings:
        lines.append(f"  warning: {w}")
    if result.quality is not None:
        lines.append(f"  {result.quality.text()}")
    return "\n".join(lines) + "\n"
