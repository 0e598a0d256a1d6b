"""``trackproc accuracy``: sigma(t) of a predicted orbit from the initial covariance (seed 000).

Steps:

1. The initial covariance: the 6 x 6 position/velocity block of the state file's covariance
   (GCRF; extended parameters such as range biases do not move the orbit and drop out), or
   ``diag(sigma^2)`` of the state file's ``sigma``, or the command line's
   ``--sigma-position-m`` / ``--sigma-velocity-m-s`` (GCRF or RTN axes, which then take
   precedence over the file).
2. The nominal orbit and its first-order sensitivity spectra: the propagation façade
   (:func:`trackproc.dynamics.propagator.propagate_state`, Taylor/DT engine in the
   quasi-inertial frame of the epoch, ``stm=True``) over ``epoch + k * step``, k = 0 ..
   floor(span/step) (UTC labels; elapsed SI seconds through TAI).
3. The moments, by up to three methods (:mod:`trackproc.methods.accuracy`):
   ``spectral`` -- seed 000 eqs. 21-25 on the first-order random spectra (Cauchy products in
   the image domain); ``stm`` -- ``Phi P0 Phi^T``; ``monte-carlo`` -- N draws of
   ``N(x0, P0)`` propagated by the engine's batch mode in the same frame, sample moments
   accumulated about the nominal orbit (chunks of :data:`MC_CHUNK` draws).
4. Output: one row per time with the nominal state, sigma of each component in GCRF and along
   radial / along-track / cross-track axes, and with ``at_station`` sigma of range and
   range-rate (geometric partials) with the nominal range, range-rate and elevation; extra
   methods as ``stm_`` / ``mc_`` prefixed columns. On request the covariance function
   ``R(t_i, t_j)`` of every component over the grid (seed 000 eq. 25), from the first method.

Also :func:`seed_example`, the seed's worked example (eqs. 29-34) with its truncation study.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from trackproc.io.tables import arrow_table_bytes
from trackproc.pipeline.plotting import require_matplotlib  # noqa: F401  (re-exported for the CLI)
from trackproc.constants import MU_EARTH, force_model_constants
from trackproc.vocabulary import FORCES
from trackproc.errors import InputError
from trackproc.io.statefile import STATE_PARAMETERS
from trackproc.methods import accuracy as ac

METHODS = ("spectral", "stm", "monte-carlo", "all")
FORMATS = ("parquet", "arrow", "csv", "json")
#: Monte Carlo sample count when the method asks for it and --monte-carlo does not say.
DEFAULT_MONTE_CARLO = 1000
#: Draws propagated together in one batch (memory: chunk x times x 6 floats).
MC_CHUNK = 1000
MAX_TIMES = 1_000_000
MAX_MONTE_CARLO = 1_000_000
#: Largest grid for the correlation matrix R(t_i, t_j) (pairs grow as the square).
MAX_CORRELATION_TIMES = 500
#: Column prefix of each method when it is not the first (unprefixed) one.
PREFIX = {"spectral": "spectral_", "stm": "stm_", "monte-carlo": "mc_"}
#: (name, unit suffix, unit) of the six inertial and six RTN components.
COMPONENTS = (("x", "m", "m"), ("y", "m", "m"), ("z", "m", "m"),
              ("vx", "m_s", "m/s"), ("vy", "m_s", "m/s"), ("vz", "m_s", "m/s"))
RTN_COMPONENTS = (("radial", "m", "m"), ("along", "m", "m"), ("cross", "m", "m"),
                  ("v_radial", "m_s", "m/s"), ("v_along", "m_s", "m/s"), ("v_cross", "m_s", "m/s"))
RTN_CONVENTION = ("radial = r/|r|, cross = r x v/|r x v|, along = cross x radial, at the nominal state; "
                  "v_radial, v_along, v_cross = rates of change of the radial/along/cross position errors "
                  "(M dv - w x M dr, w = |r x v|/r^2 about cross: the Clohessy-Wiltshire convention)")


@dataclass
class AccuracyOptions:
    """Options of :func:`accuracy` (units in the names). ``monte_carlo`` = N draws (None: the
    default N when the method needs them, else no Monte Carlo); sigmas are 1 or 3 values, on
    ``sigma_frame`` axes (``gcrf`` or ``rtn``)."""

    span_s: float
    step_s: float
    force: str = "j2"
    method: str = "spectral"
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None
    monte_carlo: Optional[int] = None
    seed: Optional[int] = None
    sigma_position_m: Optional[Sequence[float]] = None
    sigma_velocity_m_s: Optional[Sequence[float]] = None
    sigma_frame: str = "gcrf"
    at_station: Optional[str] = None
    earth: str = "wgs84"
    correlation: bool = False

    @property
    def methods(self) -> tuple:
        """Methods to run, the first one giving the unprefixed columns."""
        if self.method == "all":
            return ("spectral", "stm", "monte-carlo")
        if self.method == "monte-carlo":
            return ("monte-carlo",)
        return (self.method,) + (("monte-carlo",) if self.monte_carlo is not None else ())

    @property
    def n_samples(self) -> Optional[int]:
        if "monte-carlo" not in self.methods:
            return None
        return DEFAULT_MONTE_CARLO if self.monte_carlo is None else int(self.monte_carlo)


@dataclass
class AccuracyResult:
    """Result of :func:`accuracy`.

    ``frame``: one row per time (see the module docstring); ``meta``: provenance and checks;
    ``times`` (M,) UTC ``datetime64[ns]``; ``elapsed_s`` (M,); ``nominal`` (M, 6) GCRF;
    ``covariance`` and ``covariance_rtn``: method -> (M, 6, 6); ``observables``: method ->
    (M, 2, 2) covariance of range and range-rate (with a station); ``initial_covariance``
    (6, 6) GCRF; ``correlation``: None or {"method", "cov": component -> (M, M)}.
    """

    frame: pd.DataFrame
    meta: dict
    times: np.ndarray
    elapsed_s: np.ndarray
    nominal: np.ndarray
    covariance: dict
    covariance_rtn: dict
    observables: dict
    initial_covariance: np.ndarray
    correlation: Optional[dict] = None
    station_track: Optional[dict] = field(default=None, repr=False)


# ============================================================================ inputs

def _check_options(options: AccuracyOptions) -> None:
    def positive(flag, value):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError("must be positive", column=flag, found=value, expected="a number > 0")

    positive("--span", options.span_s)
    positive("--step", options.step_s)
    if options.span_s / options.step_s > MAX_TIMES:
        raise InputError("too many times", column="--step", found=options.step_s,
                         expected=f"at most {MAX_TIMES} steps over --span")
    if options.method not in METHODS:
        raise InputError("unknown method", column="--method", found=options.method, expected=" | ".join(METHODS))
    if options.force not in FORCES:
        raise InputError("unknown force model", column="--force", found=options.force, expected=" or ".join(FORCES))
    if options.force == "full" and options.n_samples:
        # each draw would be a full DOP853 integration (about a second per day of LEO): not offered
        raise InputError("Monte Carlo draws use the Taylor engine's batch mode (two-body, j2)", column="--method",
                         found=f"{options.method} with --force full",
                         expected="--method spectral or stm (no --monte-carlo) with --force full")
    if options.monte_carlo is not None and not (2 <= int(options.monte_carlo) <= MAX_MONTE_CARLO):
        raise InputError("invalid sample count", column="--monte-carlo", found=options.monte_carlo,
                         expected=f"an integer in [2, {MAX_MONTE_CARLO}]")
    if options.sigma_frame not in ("gcrf", "rtn"):
        raise InputError("unknown frame", column="--sigma-frame", found=options.sigma_frame, expected="gcrf or rtn")
    if options.correlation and options.span_s / options.step_s + 1 > MAX_CORRELATION_TIMES + 1e-9:
        raise InputError("too many times for the correlation matrix", column="--correlation",
                         found=f"{int(options.span_s / options.step_s) + 1} times",
                         expected=f"at most {MAX_CORRELATION_TIMES} (a larger --step or a shorter --span)")


def _sigma_triplet(values, flag) -> np.ndarray:
    v = np.atleast_1d(np.asarray(values, dtype=float))
    if v.size == 1:
        v = np.repeat(v, 3)
    if v.size != 3 or not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InputError("invalid sigma", column=flag, found=",".join(repr(float(x)) for x in v),
                         expected="one value or three comma-separated values, each >= 0")
    return v


def initial_covariance(state, options: AccuracyOptions) -> tuple[np.ndarray, str]:
    """The 6 x 6 GCRF covariance of the initial state and a description of where it came from.

    Raises :class:`InputError` naming the state file and the field when there is none.
    """
    pos, vel = options.sigma_position_m, options.sigma_velocity_m_s
    if (pos is None) != (vel is None):
        missing = "--sigma-velocity-m-s" if vel is None else "--sigma-position-m"
        raise InputError("give both sigma options", column=missing,
                         expected="--sigma-position-m and --sigma-velocity-m-s together")
    if pos is not None:
        sig = np.concatenate([_sigma_triplet(pos, "--sigma-position-m"),
                              _sigma_triplet(vel, "--sigma-velocity-m-s")])
        cov = np.diag(sig ** 2)
        label = "--sigma-position-m / --sigma-velocity-m-s"
        if options.sigma_frame == "rtn":
            m = ac.rtn_rotation(state.r_m, state.v_m_s)
            big = np.zeros((6, 6))
            big[:3, :3] = big[3:, 3:] = m
            cov = big.T @ cov @ big
            label += " on radial/along/cross axes"
        else:
            label += " on GCRF axes"
        if getattr(state, "state_covariance", None) is not None:
            label += " (the state file's covariance is not used)"
    elif state.state_covariance is not None:
        cov = np.asarray(state.state_covariance, float)
        label = "state file covariance (x .. vz block, GCRF)"
    elif state.sigma is not None and all(p in state.parameters for p in STATE_PARAMETERS):
        idx = [state.parameters.index(p) for p in STATE_PARAMETERS]
        cov = np.diag(np.asarray(state.sigma, float)[idx] ** 2)
        label = "state file sigma (uncorrelated, GCRF)"
    else:
        raise InputError("no initial covariance", file=state.source, column="covariance",
                         expected="a covariance (or sigma) over x, y, z, vx, vy, vz in the state file, "
                                  "or --sigma-position-m and --sigma-velocity-m-s")
    if not np.any(np.diag(cov) > 0):
        raise InputError("the initial covariance is zero", file=state.source if pos is None else None,
                         column="covariance" if pos is None else "--sigma-position-m",
                         expected="at least one positive variance")
    return 0.5 * (cov + cov.T), label


# ============================================================================ the computation

def accuracy(state, options: AccuracyOptions, stations: Optional[dict] = None, eop=None,
             stations_source: Optional[str] = None) -> AccuracyResult:
    """Mean, sigma and (on request) the covariance function of the orbit predicted from ``state``.

    Parameters
    ----------
    state : :class:`~trackproc.io.statefile.State` (GCRF) with a covariance, or use the sigma options.
    options : :class:`AccuracyOptions`.
    stations : name -> station (``lat_deg``, ``lon_deg``, ``height_m``), needed with ``at_station``.
    eop : :class:`~trackproc.dynamics.timescales.EarthOrientation` or None.
    stations_source : the stations file name, for error messages.
    """
    from trackproc.dynamics import timescales as ts
    from trackproc.dynamics.propagator import propagate_state
    from trackproc.pipeline.simulate import time_grid

    _check_options(options)
    if options.at_station is not None:
        if not stations or options.at_station not in stations:
            raise InputError("unknown station", file=stations_source, column="--at-station", found=options.at_station,
                             expected="a station of the stations table: " + ", ".join(sorted(stations or {})))
    cov0, cov_label = initial_covariance(state, options)
    times = time_grid(state.epoch, options.span_s, options.step_s)
    t = np.maximum(ts.seconds_since(ts.datetime64_to_jd_utc(times), state.jd_utc), 0.0)   # SI s (leap s)
    traj = propagate_state(state, float(t.max(initial=0.0)), force=options.force, eop=eop, stm=True,
                           force_model=options.force_model)
    traj.raise_for_outcome()
    nominal = traj.state(t)                        # (M, 6) GCRF
    big_q = traj.rotation                          # GCRF -> quasi-inertial
    cov0_q = big_q @ cov0 @ big_q.T

    covs, factors = {}, {}
    for method in options.methods:
        if method == "spectral":
            p_q = ac.spectral_covariance(traj, t, cov0_q)
            covs[method] = big_q.T @ p_q @ big_q
            if options.correlation:
                factors[method] = big_q.T @ ac.spectral_factors(traj, t, cov0_q)
        elif method == "stm":
            phi = traj.stm(t)
            covs[method] = ac.stm_covariance(phi, cov0)
            if options.correlation:
                factors[method] = phi @ ac.normalizing_factor(cov0)

    track = None
    if options.at_station is not None:
        track = _station_track(stations[options.at_station], times, nominal, options.earth, eop)

    mc = None
    if "monte-carlo" in options.methods:
        mc = _monte_carlo(traj, state, cov0, t, nominal, options, track)
        covs["monte-carlo"] = mc["cov"]

    rtn = {m: ac.to_rtn(c, nominal[:, :3], nominal[:, 3:]) for m, c in covs.items()}
    obs = {}
    if track is not None:
        for m, c in covs.items():
            obs[m] = ac.observable_covariance(track["jacobian"], c)
        if mc is not None:
            obs["monte-carlo"] = mc["obs_cov"]

    frame = _frame(times, t, nominal, covs, rtn, obs, track, options, mc)
    checks = _checks(covs, rtn, options.n_samples)
    correlation = None
    if options.correlation:
        first = options.methods[0]
        correlation = _correlation(first, factors.get(first), mc, nominal)
    meta = _meta(state, options, traj, cov0, cov_label, checks, eop, track, mc)
    return AccuracyResult(frame=frame, meta=meta, times=times, elapsed_s=t, nominal=nominal, covariance=covs,
                          covariance_rtn=rtn, observables=obs, initial_covariance=cov0, correlation=correlation,
                          station_track=track)


def _station_track(station, times, nominal, earth, eop) -> dict:
    """Station in GCRF at the grid times, nominal range / range-rate / elevation and partials."""
    from trackproc.dynamics import geodesy
    from trackproc.dynamics import timescales as ts
    from trackproc.models.observables import azel

    lat, lon, r_itrf = geodesy.station_itrf(station, earth)
    jd1, jd2 = ts.datetime64_to_jd_utc(times)
    st = geodesy.station_gcrf(r_itrf, jd1, jd2, eop)
    d = nominal[:, :3] - st.r
    rng = np.linalg.norm(d, axis=-1)
    rr = np.sum(d * (nominal[:, 3:] - st.v), axis=-1) / rng
    _, el = azel(d, st.gcrf_to_itrf, lat, lon)
    return {"name": station.name if hasattr(station, "name") else None, "r": st.r, "v": st.v,
            "range_m": rng, "range_rate_m_s": rr, "elevation_rad": el,
            "jacobian": ac.range_range_rate_jacobian(nominal[:, :3], nominal[:, 3:], st.r, st.v),
            "station": station}


def _monte_carlo(traj, state, cov0, t, nominal, options, track) -> dict:
    """N draws of N(x0, P0) propagated in the façade's frame by the engine's batch mode.

    Moments accumulate about the nominal orbit (deviations of metres, not positions of
    thousands of kilometres, so the sums lose nothing), chunk by chunk.
    """
    from trackproc.dynamics import taylor

    n = options.n_samples
    q = traj.frame.q
    big_q = traj.rotation
    draws = ac.sample_initial_states(state.rv, cov0, n, options.seed)          # (N, 6) GCRF
    m = t.size
    s1 = np.zeros((m, 6))
    s2 = np.zeros((m, 6, 6))
    o1 = np.zeros((m, 2))
    o2 = np.zeros((m, 2, 2))
    corr = {} if options.correlation else None
    rot = None
    if options.correlation:
        rot = ac.rtn_jacobian(nominal[:, :3], nominal[:, 3:])
        corr = {"s1": np.zeros((m, 12)), "s2": np.zeros((12, m, m))}
    for a in range(0, n, MC_CHUNK):
        chunk = draws[a:a + MC_CHUNK] @ big_q.T                              # quasi-inertial
        run = taylor.propagate(chunk, 0.0, traj.t_max_s, force=traj.force, mu_m3_s2=traj.mu_m3_s2, j2=traj.j2,
                               re_m=traj.re_m, tol=traj.tol).raise_for_outcome()
        x = run.state(t)                                                      # (B, M, 6)
        x = np.concatenate([x[..., :3] @ q, x[..., 3:] @ q], axis=-1)         # GCRF
        d = x - nominal[None]
        s1 += d.sum(0)
        s2 += np.einsum("bmi,bmj->mij", d, d)
        if track is not None:
            dr = x[..., :3] - track["r"][None]
            rng = np.linalg.norm(dr, axis=-1)
            rr = np.sum(dr * (x[..., 3:] - track["v"][None]), axis=-1) / rng
            do = np.stack([rng - track["range_m"][None], rr - track["range_rate_m_s"][None]], -1)
            o1 += do.sum(0)
            o2 += np.einsum("bmi,bmj->mij", do, do)
        if corr is not None:
            d_rtn = np.einsum("mij,bmj->bmi", rot, d)                          # the 6 x 6 RTN map, as to_rtn
            dd = np.concatenate([d, d_rtn], axis=-1)                          # (B, M, 12)
            corr["s1"] += dd.sum(0)
            for c in range(12):                                               # BLAS: (M x B)(B x M)
                dc = np.ascontiguousarray(dd[:, :, c])
                corr["s2"][c] += dc.T @ dc
    mean_dev = s1 / n
    cov = (s2 - n * np.einsum("mi,mj->mij", mean_dev, mean_dev)) / (n - 1)
    out = {"n": n, "seed": options.seed, "cov": 0.5 * (cov + np.swapaxes(cov, -1, -2)), "mean_dev": mean_dev}
    if track is not None:
        om = o1 / n
        out["obs_cov"] = (o2 - n * np.einsum("mi,mj->mij", om, om)) / (n - 1)
        out["obs_mean_dev"] = om
    if corr is not None:
        cm = corr["s1"] / n                                                   # (M, 12)
        out["cross"] = (corr["s2"] - n * np.einsum("mc,kc->cmk", cm, cm)) / (n - 1)
    return out


def _columns(prefix, cov, rtn, obs) -> dict:
    cols = {}
    sig = ac.sigmas(cov)
    for k, (name, unit, _) in enumerate(COMPONENTS):
        cols[f"{prefix}sigma_{name}_{unit}"] = sig[:, k]
    sig = ac.sigmas(rtn)
    for k, (name, unit, _) in enumerate(RTN_COMPONENTS):
        cols[f"{prefix}sigma_{name}_{unit}"] = sig[:, k]
    cols[f"{prefix}sigma_position_m"] = np.sqrt(np.clip(np.trace(cov[:, :3, :3], axis1=1, axis2=2), 0, None))
    cols[f"{prefix}sigma_velocity_m_s"] = np.sqrt(np.clip(np.trace(cov[:, 3:, 3:], axis1=1, axis2=2), 0, None))
    if obs is not None:
        so = ac.sigmas(obs)
        cols[f"{prefix}sigma_range_m"] = so[:, 0]
        cols[f"{prefix}sigma_range_rate_m_s"] = so[:, 1]
    return cols


def _frame(times, t, nominal, covs, rtn, obs, track, options, mc) -> pd.DataFrame:
    # elapsed time to the nanosecond the times carry (not 600.0000000000026 from the JD arithmetic)
    cols = {"time": pd.DatetimeIndex(times).tz_localize("UTC"), "elapsed_s": np.round(t, 9)}
    for k, (name, unit, _) in enumerate(COMPONENTS):
        cols[f"{name}_{unit}"] = nominal[:, k]
    first = options.methods[0]
    cols.update(_columns("", covs[first], rtn[first], obs.get(first)))
    if track is not None:
        cols["range_m"] = track["range_m"]
        cols["range_rate_m_s"] = track["range_rate_m_s"]
        cols["elevation_deg"] = np.degrees(track["elevation_rad"])
    for method in options.methods[1:]:
        cols.update(_columns(PREFIX[method], covs[method], rtn[method], obs.get(method)))
    if mc is not None:
        prefix = "" if first == "monte-carlo" else "mc_"
        cols[f"{prefix}mean_offset_position_m"] = np.linalg.norm(mc["mean_dev"][:, :3], axis=-1)
        cols[f"{prefix}mean_offset_velocity_m_s"] = np.linalg.norm(mc["mean_dev"][:, 3:], axis=-1)
    return pd.DataFrame(cols)


def _checks(covs, rtn, n_samples) -> dict:
    """Cross-checks between the methods that ran: relative sigma differences and MC z-scores."""
    out = {}

    def diag(c, r):
        return np.concatenate([np.diagonal(c, axis1=1, axis2=2), np.diagonal(r, axis1=1, axis2=2)], -1)

    if "spectral" in covs and "stm" in covs:
        a, b = np.sqrt(np.clip(diag(covs["spectral"], rtn["spectral"]), 0, None)), \
            np.sqrt(np.clip(diag(covs["stm"], rtn["stm"]), 0, None))
        ok = b > 0
        out["spectral_vs_stm_max_relative_sigma_difference"] = float(np.max(np.abs(a - b)[ok] / b[ok])) if ok.any() \
            else 0.0
    if "monte-carlo" in covs:
        lin = "spectral" if "spectral" in covs else "stm" if "stm" in covs else None
        bounds = ac.monte_carlo_bounds(n_samples)
        out["monte_carlo_variance_relative_sd"] = bounds["variance_relative_sd"]
        if lin is not None:
            v_mc = diag(covs["monte-carlo"], rtn["monte-carlo"])
            v_lin = diag(covs[lin], rtn[lin])
            ok = v_lin > 0
            z = (v_mc[ok] / v_lin[ok] - 1.0) / bounds["variance_relative_sd"]
            out["monte_carlo_vs_linear_max_abs_z"] = float(np.max(np.abs(z))) if z.size else 0.0
            out["monte_carlo_vs_linear_reference"] = lin
    return out


def _correlation(method, factor, mc, nominal) -> dict:
    """Covariance function R(t_i, t_j) of every component, (M, M) each (seed 000 eq. 25)."""
    names = [c[0] for c in COMPONENTS] + [c[0] for c in RTN_COMPONENTS]
    if method == "monte-carlo":
        cross = mc["cross"]                                                   # (12, M, M)
    else:
        f = np.concatenate([factor, ac.rtn_jacobian(nominal[:, :3], nominal[:, 3:]) @ factor], axis=1)  # (M, 12, k)
        cross = np.einsum("mck,nck->cmn", f, f)
    return {"method": method, "components": names, "cov": {n: cross[i] for i, n in enumerate(names)}}


def _meta(state, options, traj, cov0, cov_label, checks, eop, track, mc) -> dict:
    from trackproc import __version__
    from trackproc.io.statefile import FORCE_LABELS, format_epoch

    units = {"time": "UTC", "elapsed_s": "s"}
    meta = {
        "schema_version": 1,
        "product": "trackproc accuracy",
        "time_scale": "UTC",
        "frame": "GCRF",
        "epoch": format_epoch(state.epoch),
        "state_source": state.source,
        "span_s": float(options.span_s),
        "step_s": float(options.step_s),
        "force_model": (options.force_model.label() if options.force_model is not None
                        else FORCE_LABELS.get(options.force, options.force)),
        "constants": (options.force_model.describe() if options.force_model is not None
                      else force_model_constants(options.force)),
        "earth_orientation": getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)",
        "methods": list(options.methods),
        "unprefixed_method": options.methods[0],
        "column_prefixes": {m: ("" if m == options.methods[0] else PREFIX[m]) for m in options.methods},
        "initial_covariance": {"source": cov_label, "sigma": np.sqrt(np.clip(np.diag(cov0), 0, None)).tolist(),
                               "matrix": cov0.tolist(), "parameters": list(STATE_PARAMETERS)},
        "rtn_axes": RTN_CONVENTION,
        "first_order": ("spectral (seed 000 eqs. 21-25 on the engine's first-order sensitivity spectra) and stm "
                        "(Phi P0 Phi^T) are first order in the initial errors and give the same numbers; "
                        "Monte Carlo keeps every nonlinearity"),
        "propagator": {"engine": "adaptive Taylor (DT), trackproc.dynamics.taylor via dynamics.propagator",
                       "frame": "quasi-inertial frame of the epoch (J2 about its rotation axis)",
                       "order": traj.order, "tol": traj.tol, "steps": traj.n_steps},
        "checks": checks,
        "trackproc_version": __version__,
        "units": units,
    }
    if mc is not None:
        meta["monte_carlo"] = {"n_samples": mc["n"], "seed": mc["seed"], **ac.monte_carlo_bounds(mc["n"]),
                               "note": "sd of the sample variance of N Gaussian draws: sqrt(2/(N-1)) relative"}
    if track is not None:
        st = track["station"]
        meta["station"] = {"name": options.at_station, "lat_deg": float(st.lat_deg), "lon_deg": float(st.lon_deg),
                           "height_m": float(st.height_m), "earth": options.earth,
                           "model": "geometric range |r - r_st| and range-rate u.(v - v_st) at the sample time "
                                    "(no light time; partials change by v/c ~ 3e-5 relative)"}
    return meta


# ============================================================================ the seed's example

@dataclass
class SeedExampleOptions:
    """Seed 000's worked example: one axis of a circular orbit of radius ``radius_m``."""

    span_s: float = 6000.0
    step_s: float = 100.0
    radius_m: float = 7.0e6
    sigma_position_m: float = 100.0
    sigma_velocity_m_s: float = 0.1
    discretes: tuple = (4, 6)
    mu_m3_s2: float = MU_EARTH


@dataclass
class SeedExampleResult:
    frame: pd.DataFrame
    meta: dict
    options: SeedExampleOptions
    n_rad_s: float


def seed_example(options: SeedExampleOptions) -> SeedExampleResult:
    """The seed's worked example (seed 000 eqs. 29-34): sigma_x(t) exactly, by the spectral
    method with enough discretes, and truncated at ``discretes`` (4 and 6 in the paper).

    Columns: ``elapsed_s``, ``mean_x_m`` (eq. 18, the nominal x0 cos(nt)), ``sigma_x_m`` and
    ``sigma_vx_m_s`` (exact), ``sigma_x_spectral_m``, ``sigma_vx_spectral_m_s`` and
    ``rel_err_var_x_spectral`` (enough discretes, restarted expansion), ``sigma_x_n{N}_m`` and
    ``rel_err_var_x_n{N}`` (single expansion H = t with N discretes, the paper's method),
    ``velocity_share`` (fraction of D_x due to the velocity error) and ``velocity_weight_s2``
    (``tan^2(nt)/n^2``, the seed's conclusion).
    """
    o = options
    for flag, value in (("--span", o.span_s), ("--step", o.step_s), ("--radius-m", o.radius_m)):
        if not (math.isfinite(value) and value > 0):
            raise InputError("must be positive", column=flag, found=value, expected="a number > 0")
    if o.span_s / o.step_s > MAX_TIMES:
        raise InputError("too many times", column="--step", found=o.step_s, expected=f"at most {MAX_TIMES} steps")
    for flag, value in (("--sigma-position-m", o.sigma_position_m), ("--sigma-velocity-m-s", o.sigma_velocity_m_s)):
        if not (math.isfinite(value) and value >= 0):
            raise InputError("invalid sigma", column=flag, found=value, expected="a number >= 0")
    if o.sigma_position_m == 0 and o.sigma_velocity_m_s == 0:
        raise InputError("both sigmas are zero", column="--sigma-position-m", expected="at least one positive sigma")
    bad = [d for d in o.discretes if not (isinstance(d, int) and 1 <= d <= 200)]
    if bad or not o.discretes:
        raise InputError("invalid number of discretes", column="--discretes", found=bad or "none",
                         expected="integers in [1, 200], e.g. 4,6")
    n = math.sqrt(o.mu_m3_s2 / o.radius_m ** 3)
    t = np.arange(int(math.floor(o.span_s / o.step_s * (1 + 1e-12))) + 1) * float(o.step_s)
    s1, s2 = float(o.sigma_position_m), float(o.sigma_velocity_m_s)
    exact = ac.seed000_variance_exact(t, s1, s2, n)
    exact_v = ac.seed000_velocity_variance_exact(t, s1, s2, n)
    spectral = ac.seed000_statistics(t, s1, s2, n, x0_m=o.radius_m)
    cols = {"elapsed_s": t, "mean_x_m": spectral["mean_x_m"], "sigma_x_m": np.sqrt(exact),
            "sigma_vx_m_s": np.sqrt(exact_v), "sigma_x_spectral_m": spectral["sigma_x_m"],
            "sigma_vx_spectral_m_s": spectral["sigma_vx_m_s"],
            "rel_err_var_x_spectral": _rel(spectral["var_x_m2"], exact)}
    for nd in o.discretes:
        st = ac.seed000_statistics(t, s1, s2, n, n_discretes=nd, x0_m=o.radius_m)
        cols[f"sigma_x_n{nd}_m"] = st["sigma_x_m"]
        cols[f"rel_err_var_x_n{nd}"] = _rel(st["var_x_m2"], exact)
    vel = s2 ** 2 * np.sin(n * t) ** 2 / n ** 2
    cols["velocity_share"] = np.divide(vel, exact, out=np.zeros_like(vel), where=exact > 0)
    with np.errstate(over="ignore"):
        cols["velocity_weight_s2"] = ac.seed000_velocity_weight(t, n)
    from trackproc import __version__

    meta = {"schema_version": 1, "product": "trackproc accuracy --seed-example",
            "model": "seed 000 eqs. 29-31: x'' = -(mu/r^3) x, x(0) = x0 - v1, x'(0) = g0 - v2, "
                     "independent zero-mean v1 (position), v2 (velocity); x0 = r, g0 = 0",
            "ground_truth": "D_x(t) = s1^2 cos^2(n t) + s2^2 sin^2(n t)/n^2 (the printed eqs. 33-34 have typos)",
            "radius_m": o.radius_m, "mu_m3_s2": o.mu_m3_s2, "n_rad_s": n, "period_s": 2 * math.pi / n,
            "sigma_position_m": s1, "sigma_velocity_m_s": s2, "discretes": list(o.discretes),
            "spectral": {"discretes": spectral["n_discretes"], "restart_s": 0.5 / n,
                         "note": "expansion restarted every 0.5/n s (|n H| <= 0.5), as the DT engine steps"},
            "truncated": "single expansion about t = 0 with H = t and N discretes (the paper's method); "
                         "complete Cauchy products, so N = 4 reproduces eq. 33 (typos corrected)",
            "span_s": o.span_s, "step_s": o.step_s, "trackproc_version": __version__}
    return SeedExampleResult(frame=pd.DataFrame(cols), meta=meta, options=o, n_rad_s=n)


def _rel(value, exact):
    return np.divide(value - exact, exact, out=np.zeros_like(exact), where=exact > 0)


def truncation_table(result: SeedExampleResult, times_s: Sequence[float]) -> pd.DataFrame:
    """Rows of the example frame at ``times_s`` (nearest grid times): the README's table."""
    f = result.frame
    idx = [int(np.argmin(np.abs(f["elapsed_s"].to_numpy() - x))) for x in times_s]
    cols = ["elapsed_s", "sigma_x_m"] + [c for c in f.columns if c.startswith("rel_err_var_x")]
    return f.iloc[idx][cols].reset_index(drop=True)


# ============================================================================ output

def table_bytes(frame: pd.DataFrame, meta: dict, fmt: str) -> bytes:
    """The one-row-per-time table as ``parquet``, ``arrow`` (IPC stream), ``csv`` or ``json``.

    Parquet/Arrow carry ``meta`` under the ``trackproc`` key of the schema metadata, CSV on a
    first ``# trackproc: {...}`` line (as pass files do); JSON is
    ``{"columns": [...], "metadata": {...}, "rows": [{column: value}, ...]}`` with ISO 8601
    times and null for NaN.
    """
    import pyarrow as pa

    from trackproc.io.jsonutil import dumps, json_ready
    from trackproc.io.passfile import iso_times, meta_json
    from trackproc.io.tabular import META_KEY, csv_metadata_line

    fmt = getattr(fmt, "value", fmt)
    meta_text = meta_json(json_ready(meta))
    if fmt == "json":
        cols = {c: (list(iso_times(frame[c])) if c.startswith("time") else frame[c].to_numpy()) for c in frame.columns}
        rows = [{c: cols[c][i] for c in frame.columns} for i in range(len(frame))]
        return dumps({"columns": list(frame.columns), "metadata": meta, "rows": rows}).encode("utf-8")
    if fmt == "csv":
        import csv

        out = io.StringIO()
        out.write(csv_metadata_line(meta_text))
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(list(frame.columns))
        cells = [iso_times(frame[c]) if c.startswith("time") else frame[c].to_numpy() for c in frame.columns]
        for row in zip(*cells):
            writer.writerow([v if isinstance(v, str) else repr(float(v)) for v in row])
        return out.getvalue().encode("utf-8")
    arrays, fields = [], []
    for c in frame.columns:
        if c.startswith("time"):
            ns = frame[c].dt.tz_convert("UTC").dt.tz_localize(None).dt.as_unit("ns").to_numpy()
            arrays.append(pa.array(ns, pa.timestamp("ns")).cast(pa.timestamp("ns", tz="UTC")))
            fields.append(pa.field(c, pa.timestamp("ns", tz="UTC"), nullable=False))
        else:
            arrays.append(pa.array(frame[c].to_numpy(dtype=np.float64), pa.float64()))
            fields.append(pa.field(c, pa.float64()))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata={META_KEY: meta_text.encode()}))
    if fmt not in ("parquet", "arrow"):
        raise ValueError(f"unknown format {fmt!r}; expected one of {FORMATS}")
    return arrow_table_bytes(table, fmt)


def correlation_frame(result: AccuracyResult) -> pd.DataFrame:
    """The covariance function as a long table: one row per pair (t_i, t_j), all pairs.

    Columns ``time_1, time_2, elapsed_1_s, elapsed_2_s``, then per component ``cov_<c>_<unit^2>``
    (``cov_x_m2``, ``cov_vx_m2_s2``, ``cov_radial_m2``, ...) and ``corr_<c>``
    (``R(t_i, t_j) / sqrt(D(t_i) D(t_j))``).
    """
    c = result.correlation
    m = result.elapsed_s.size
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    i, j = i.ravel(), j.ravel()
    t = pd.DatetimeIndex(result.times).tz_localize("UTC")
    cols = {"time_1": t[i], "time_2": t[j], "elapsed_1_s": result.elapsed_s[i], "elapsed_2_s": result.elapsed_s[j]}
    units = {name: u for name, u, _ in COMPONENTS + RTN_COMPONENTS}
    for name in c["components"]:
        cov = c["cov"][name]
        unit = "m2" if units[name] == "m" else "m2_s2"
        cols[f"cov_{name}_{unit}"] = cov[i, j]
        d = np.diagonal(cov)
        cols[f"corr_{name}"] = ac.correlation_coefficients(cov, d, d)[i, j]
    return pd.DataFrame(cols)


def correlation_bytes(result: AccuracyResult, fmt: str) -> bytes:
    """``--correlation FILE``: JSON matrices, or the long table of :func:`correlation_frame`."""
    from trackproc.io.jsonutil import dumps
    from trackproc.io.passfile import iso_times

    fmt = getattr(fmt, "value", fmt)
    c = result.correlation
    meta = dict(result.meta)
    meta["correlation"] = {"method": c["method"],
                           "definition": "R(t_i, t_j) = E[dx(t_i) dx(t_j)] of each component (seed 000 eq. 25); "
                                         "corr = R / sqrt(D(t_i) D(t_j))"}
    if fmt == "json":
        units = {name: u for name, u, _ in COMPONENTS + RTN_COMPONENTS}
        cov = {f"{n}_{'m2' if units[n] == 'm' else 'm2_s2'}": c["cov"][n] for n in c["components"]}
        corr = {}
        for n in c["components"]:
            d = np.diagonal(c["cov"][n])
            corr[n] = ac.correlation_coefficients(c["cov"][n], d, d)
        t = pd.Series(pd.DatetimeIndex(result.times).tz_localize("UTC"))
        return dumps({"metadata": meta, "times": list(iso_times(t)), "elapsed_s": result.elapsed_s,
                      "covariance": cov, "correlation": corr}).encode("utf-8")
    return table_bytes(correlation_frame(result), meta, fmt)


# ============================================================================ plots


def _pyplot():
    require_matplotlib()
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return buf.getvalue()


def plot_bytes(result: AccuracyResult) -> bytes:
    """PNG: sigma(t) of position and velocity along radial / along-track / cross-track (and of
    range and range-rate at the station), every method that ran (like seed 000 Fig. 1-2)."""
    plt = _pyplot()
    f = result.frame
    methods = result.meta["methods"]
    prefixes = result.meta["column_prefixes"]
    hours = f["elapsed_s"].to_numpy() / 3600.0
    panels = [("position", [("radial", "m"), ("along", "m"), ("cross", "m")], "sigma, m"),
              ("velocity", [("v_radial", "m_s"), ("v_along", "m_s"), ("v_cross", "m_s")], "sigma, m/s")]
    if "sigma_range_m" in f.columns:
        # one unit per panel; the station's sigmas only while the satellite is above its horizon
        name = result.meta["station"]["name"]
        panels.append((f"station {name}: range (while visible)", [("range", "m")], "sigma, m"))
        panels.append((f"station {name}: range-rate (while visible)", [("range_rate", "m_s")], "sigma, m/s"))
    visible = (f["elevation_deg"].to_numpy() > 0.0) if "elevation_deg" in f.columns else np.ones(len(f), bool)
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 3.4 * len(panels)), sharex=True, squeeze=False)
    styles = {"spectral": dict(ls="-", lw=1.6), "stm": dict(ls="--", lw=1.2), "monte-carlo": dict(ls="", marker=".")}
    colors = ["C0", "C1", "C2"]
    for ax, (title, comps, ylabel) in zip(axes[:, 0], panels):
        for k, (name, unit) in enumerate(comps):
            for method in methods:
                col = f"{prefixes[method]}sigma_{name}_{unit}"
                if col not in f.columns:
                    continue
                label = f"{name} ({method})"
                values = f[col].to_numpy(dtype=float)
                if title.startswith("station"):
                    values = np.where(visible, values, np.nan)   # below the horizon: no measurement
                ax.plot(hours, values, color=colors[k], label=label, **styles[method])
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}: 1-sigma of the predicted state", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=len(methods))
    axes[-1, 0].set_xlabel(f"hours since {result.meta['epoch']}")
    fig.suptitle(f"trackproc accuracy: {result.meta['force_model']}, {result.meta['initial_covariance']['source']}",
                 fontsize=9)
    fig.tight_layout()
    return _png(fig)


def seed_example_plot_bytes(result: SeedExampleResult) -> bytes:
    """PNG like seed 000 Fig. 1-2 (sigma_x(t) for fixed position error and velocity errors in the
    ratio 2, and the converse) plus the truncation study (4 and 6 discretes vs enough)."""
    plt = _pyplot()
    o, n = result.options, result.n_rad_s
    f = result.frame
    t = f["elapsed_s"].to_numpy()
    tt = np.linspace(0.0, t[-1], 600)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    ax = axes[0, 0]
    for k in (0.5, 1.0, 2.0):
        ax.plot(tt, np.sqrt(ac.seed000_variance_exact(tt, o.sigma_position_m, k * o.sigma_velocity_m_s, n)),
                label=f"sigma_v2 = {k * o.sigma_velocity_m_s:g} m/s")
    ax.set_title(f"Fig. 1: sigma_v1 = {o.sigma_position_m:g} m fixed, velocity errors in ratio 2", fontsize=10)
    ax = axes[0, 1]
    for k in (0.5, 1.0, 2.0):
        ax.plot(tt, np.sqrt(ac.seed000_variance_exact(tt, k * o.sigma_position_m, o.sigma_velocity_m_s, n)),
                label=f"sigma_v1 = {k * o.sigma_position_m:g} m")
    ax.set_title(f"Fig. 2: sigma_v2 = {o.sigma_velocity_m_s:g} m/s fixed, position errors in ratio 2", fontsize=10)
    for ax in axes[0]:
        ax.set_xlabel("extrapolation time t, s")
        ax.set_ylabel("sigma_x(t), m")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(t, f["sigma_x_m"], "k-", lw=2, label="exact")
    ax.plot(t, f["sigma_x_spectral_m"], ls=":", color="gold", lw=2,
            label=f"spectral, {result.meta['spectral']['discretes']} discretes, restarted")
    for nd in o.discretes:
        ax.plot(t, f[f"sigma_x_n{nd}_m"], label=f"{nd} discretes (H = t)")
    top = float(np.max(f["sigma_x_m"])) * 3
    ax.set_ylim(0, top)
    ax.set_title("sigma_x(t) from truncated spectra", fontsize=10)
    ax = axes[1, 1]
    floor = 1e-17
    for nd in o.discretes:
        ax.semilogy(t[1:], np.maximum(np.abs(f[f"rel_err_var_x_n{nd}"].to_numpy()[1:]), floor),
                    label=f"{nd} discretes (H = t)")
    ax.semilogy(t[1:], np.maximum(np.abs(f["rel_err_var_x_spectral"].to_numpy()[1:]), floor), "k",
                label="enough discretes")
    ax.set_title("|D_x - exact| / exact", fontsize=10)
    for ax in axes[1]:
        ax.set_xlabel("extrapolation time t, s")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[1, 0].set_ylabel("sigma_x(t), m")
    fig.suptitle(f"seed 000 example: r = {o.radius_m / 1e3:g} km, n = {n:.4e} rad/s, "
                 f"period {2 * math.pi / n:.0f} s", fontsize=10)
    fig.tight_layout()
    return _png(fig)
