"""``trackproc propagate``: an orbit state to an ephemeris, a state transition matrix, a propagated
covariance and a station's predicted measurements (a pass predictor).

1. The times: a grid ``start + k step`` over ``span`` (a negative span goes back in time; rows
   are always written in time order), or the reception times of a pass file.
2. The orbit: :func:`trackproc.dynamics.propagator.propagate` (adaptive Taylor / DT engine,
   two-body or two-body + J2 about the rotation axis of the state's epoch, tolerance
   ``tol``), with the STM when asked for or when the state has a covariance
   (``P(t) = Phi P0 Phi^T``).
3. The station (optional): :func:`trackproc.dynamics.measurement_spectra.predict` -- one-way
   light-time range, range-rate (``doppler``: derivative of the light-time range, or
   ``instantaneous``), azimuth/elevation, from the series in the image domain (seed 004
   eqs. 7-13); with a covariance also the 1-sigma of range and range-rate from the series'
   sensitivities. Doppler (one-way) ``= -f range_rate / c``.

The result is a :class:`~trackproc.io.ephemeris.Ephemeris` (columns in that module's
docstring) whose metadata names the force model, its constants and the Earth orientation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Optional

import numpy as np

from trackproc import vocabulary
from trackproc.constants import force_model_constants
from trackproc.errors import InputError, ProcessingError
from trackproc import __version__
from trackproc.dynamics import geodesy, propagator
from trackproc.dynamics import measurement_spectra as ms
from trackproc.dynamics import timescales as ts
from trackproc.io.ephemeris import (COV_COLUMNS, SCHEMA_VERSION, SIGMA_COLUMNS, STM_COLUMNS, Ephemeris,
                                    international_designator)
from trackproc.io.passfile import SIGN_CONVENTION
from trackproc.io.statefile import FORCE_LABELS
from trackproc.io.tle import tle_epoch
from trackproc.io.validate import check_carrier
from trackproc.isotime import iso_utc
from trackproc.models.observables import doppler_hz
from trackproc.pipeline.orbit_source import SGP4_LABEL, OrbitInput, Satellite, observe, sgp4_states
from trackproc.dynamics.forces import integrator

DEG = np.pi / 180.0
#: Below this geocentric distance (m) the orbit is taken to have entered the Earth.
MIN_RADIUS_M = 6_300_000.0
MAX_ROWS = 5_000_000


@dataclass
class PropagateOptions:
    """Options of :func:`propagate` (units in the names). Exactly one of ``span_s`` (with
    ``step_s``) or ``at_times`` (UTC ``datetime64[ns]``) gives the times."""

    span_s: Optional[float] = None
    step_s: Optional[float] = None
    start: Optional[np.datetime64] = None
    at_times: Optional[np.ndarray] = None
    force: str = "j2"
    earth: str = "wgs84"
    tol: float = 1e-15
    stm: bool = False
    station: Optional[object] = None
    carrier_hz: Optional[float] = None
    range_rate_model: str = "doppler"
    visible_only: bool = False
    elevation_mask_deg: float = 10.0
    light_time: bool = True
    #: Said in the metadata when a TLE is integrated instead of evaluated by SGP4.
    force_note: Optional[str] = None
    #: The ForceModel of ``force="full"`` (trackproc.dynamics.forces; cli.force_options builds it).
    force_model: Optional[object] = None


@dataclass
class PropagateResult:
    """Result of :func:`propagate`: the ephemeris (rows and metadata), the trajectory, the times
    (s from the state's epoch), the station prediction and the propagated covariances (GCRF)."""

    ephemeris: object
    trajectory: object
    t_s: np.ndarray
    prediction: object = None
    covariance: Optional[np.ndarray] = None


def grid_times(start: np.datetime64, span_s: float, step_s: float) -> np.ndarray:
    """UTC labels ``start + k step`` for k = 0 .. floor(|span|/step), backwards for a negative
    span, returned in increasing order (``datetime64[ns]``)."""
    step_ns = round(step_s * 1e9)
    n = math.floor(abs(span_s) / step_s * (1 + 1e-12)) + 1
    sign = 1 if span_s >= 0 else -1
    times = np.datetime64(start, "ns") + sign * np.arange(n, dtype=np.int64) * np.timedelta64(step_ns, "ns")
    return times[::sign]


def _check_options(options: PropagateOptions) -> None:
    grid = options.span_s is not None or options.step_s is not None
    if grid == (options.at_times is not None):
        raise InputError("give either --span S --step S, or --at PASSFILE", column="--span/--at")
    if grid:
        if options.span_s is None or options.step_s is None:
            raise InputError("--span and --step go together", column="--span" if options.span_s is None else "--step",
                             expected="both --span S and --step S")
        if not np.isfinite(options.span_s):
            raise InputError("must be finite", column="--span", found=options.span_s, expected="seconds")
        if not (np.isfinite(options.step_s) and options.step_s > 0):
            raise InputError("must be positive", column="--step", found=options.step_s, expected="a number > 0")
        if abs(options.span_s) / options.step_s > MAX_ROWS:
            raise InputError("too many rows", column="--step", found=options.step_s,
                             expected=f"at most {MAX_ROWS:g} steps over --span")
    elif len(options.at_times) == 0:
        raise InputError("no sample times", column="--at", expected="a pass file with at least one sample")
    if not (1e-18 < options.tol < 1e-3):
        raise InputError("out of range", column="--tol", found=options.tol, expected="a tolerance in (1e-18, 1e-3)")
    if options.force not in vocabulary.FORCES + ("sgp4",):
        raise InputError("unknown force model", column="--force", found=options.force,
                         expected=", ".join(vocabulary.FORCES) + " or sgp4 (a TLE)")
    if options.earth not in vocabulary.EARTHS:
        raise InputError("unknown Earth model", column="--earth", found=options.earth,
                         expected=" or ".join(vocabulary.EARTHS))
    if options.range_rate_model not in vocabulary.RANGE_RATE_MODELS:
        raise InputError("unknown range-rate model", column="--range-rate-model", found=options.range_rate_model,
                         expected=" or ".join(vocabulary.RANGE_RATE_MODELS))
    if options.station is None:
        for flag, given in (("--carrier-hz", options.carrier_hz is not None), ("--visible-only", options.visible_only)):
            if given:
                raise InputError("needs a station", column=flag, expected="--at-station ID (and --stations)")
    if options.carrier_hz is not None:
        check_carrier(options.carrier_hz)
    if not -90.0 <= options.elevation_mask_deg <= 90.0:
        raise InputError("out of range", column="--elevation-mask-deg", found=options.elevation_mask_deg,
                         expected="degrees in [-90, 90]")


def resolve_station(name: str, stations: Optional[Mapping] = None, pass_table=None):
    """The station ``name`` from a stations table, else from a pass file's metadata."""
    known = dict(pass_table.stations()) if pass_table is not None else {}
    known.update(stations or {})
    if name not in known:
        where = "the stations table" if stations else "the pass file's metadata" if pass_table is not None else None
        if where is None:
            raise InputError("station coordinates unknown", column="--at-station", found=name,
                             expected="--stations STATIONS.csv holding it")
        raise InputError(f"unknown station (not in {where})", column="--at-station", found=name,
                         expected="one of " + (", ".join(sorted(known)) or "(none)"))
    return known[name]


def pass_times(pass_table, station: Optional[str] = None) -> np.ndarray:
    """Unique sample times (UTC ``datetime64[ns]``, increasing) of a pass table, restricted to
    ``station``'s samples when the table has some."""
    times = pass_table.column("time")
    if station is not None:
        mine = pass_table.column("station") == station
        if mine.any():
            times = times[mine]
    return np.unique(np.asarray(times, dtype="datetime64[ns]"))


def requested_times(options: PropagateOptions, default_start) -> np.ndarray:
    """The output times (UTC ``datetime64[ns]``, increasing): ``--at``'s, or the grid from
    ``--start`` (default ``default_start``, the state's or the TLE's epoch)."""
    if options.at_times is not None:
        return np.unique(np.asarray(options.at_times, dtype="datetime64[ns]"))
    start = np.datetime64(options.start if options.start is not None else default_start, "ns")
    return grid_times(start, options.span_s, options.step_s)


def propagate_tle(tle, options: PropagateOptions, eop=None) -> PropagateResult:
    """A TLE evaluated by SGP4 at every requested time (``--force sgp4``, the default for a TLE).

    States are SGP4's (TEME -> GCRF, :func:`trackproc.pipeline.orbit_source.sgp4_states`); a
    station's observables are the one-way foundation model
    (:func:`trackproc.pipeline.orbit_source.observe`). No STM or covariance: SGP4 is not
    integrated here. ``trajectory`` of the result is None.
    """
    _check_options(options)
    if options.stm:
        raise InputError("SGP4 has no state transition matrix here", column="--stm",
                         expected="--force j2 or two-body (integrate from the TLE's state) for --stm")
    times = requested_times(options, tle_epoch(tle))
    states = sgp4_states(tle, times, eop)
    columns = state_columns(states, times)
    sat = Satellite(OrbitInput(tle=tle, source=tle.source), "sgp4", times[0], 0.0, 0.0, eop)
    t_s = np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(times), sat.jd0), float)
    prediction = None
    if options.station is not None:
        prediction = observe(sat, options.station, t_s, carrier_hz=options.carrier_hz or 1.0,
                             range_rate_model=options.range_rate_model, earth=options.earth)
        columns.update(station_columns(prediction, options.carrier_hz))
    ephemeris = Ephemeris(columns, _meta(None, options, None, eop, False, times, tle=tle))
    if options.visible_only:
        ephemeris = ephemeris.take(visible_rows(prediction, options, times))
    return PropagateResult(ephemeris=ephemeris, trajectory=None, t_s=t_s, prediction=prediction)


def propagate(initial, options: PropagateOptions, eop=None) -> PropagateResult:
    """Propagate ``initial`` (a GCRF :class:`~trackproc.io.statefile.State`) per ``options``.

    Raises :class:`~trackproc.errors.InputError` for inconsistent options and
    :class:`~trackproc.errors.ProcessingError` when the propagation stops early, the orbit
    enters the Earth, or (``visible_only``) no sample is above the mask.
    """
    _check_options(options)
    if options.force == "sgp4":
        raise InputError("SGP4 needs a TLE", column="--force", found="sgp4",
                         expected="a TLE input, or --force j2 / two-body for a state")
    times = requested_times(options, initial.epoch)
    t_s = np.asarray(ts.seconds_since(ts.datetime64_to_jd_utc(times), initial.jd_utc), float)
    cov0 = initial.state_covariance
    want_stm = options.stm or cov0 is not None
    try:
        traj = propagator.propagate_state(initial, t_s, force=options.force, eop=eop, tol=options.tol,
                                          stm=want_stm, force_model=options.force_model)
    except (ValueError, ArithmeticError) as exc:
        raise ProcessingError(f"propagation failed: {exc}") from None
    traj.raise_for_outcome()
    states = traj.state(t_s)

    columns = state_columns(states, times)
    phi = traj.stm(t_s) if want_stm else None
    if options.stm:
        flat = phi.reshape(-1, 36)
        for k, name in enumerate(STM_COLUMNS):
            columns[name] = flat[:, k]
    cov = None
    if cov0 is not None:
        cov = phi @ cov0 @ np.swapaxes(phi, -1, -2)
        cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
        sig = np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))
        for k, name in enumerate(SIGMA_COLUMNS):
            columns[name] = sig[:, k]
        flat = cov.reshape(-1, 36)
        for k, name in enumerate(COV_COLUMNS):
            columns[name] = flat[:, k]

    prediction = None
    if options.station is not None:
        st = options.station
        lat, lon, r_itrf = geodesy.station_itrf(st, options.earth)
        model = ms.StationModel.build(r_itrf, lat, lon, traj.epoch_jd_utc, traj.frame.q, t_s.min(), t_s.max(),
                                      eop=eop)
        try:
            prediction = ms.predict(traj, model, t_s, range_rate_model=options.range_rate_model,
                                    light_time=options.light_time, partials=cov0 is not None)
        except ArithmeticError as exc:
            raise ProcessingError(f"measurement prediction failed: {exc}") from None
        columns.update(station_columns(prediction, options.carrier_hz))
        if cov0 is not None:
            h_r, h_rr = prediction.d_range_d_state, prediction.d_range_rate_d_state
            columns["sigma_range_m"] = np.sqrt(np.einsum("ni,ij,nj->n", h_r, cov0, h_r))
            columns["sigma_range_rate_m_s"] = np.sqrt(np.einsum("ni,ij,nj->n", h_rr, cov0, h_rr))
            if options.carrier_hz is not None:
                # the one-way Doppler shift that sigma m/s of range-rate makes (its size)
                columns["sigma_doppler_hz"] = np.abs(doppler_hz(columns["sigma_range_rate_m_s"], options.carrier_hz))
    ephemeris = Ephemeris(columns, _meta(initial, options, traj, eop, cov0 is not None, times))
    if options.visible_only:
        keep = visible_rows(prediction, options, times)
        ephemeris = ephemeris.take(keep)
        if cov is not None:
            cov = cov[keep]
    return PropagateResult(ephemeris=ephemeris, trajectory=traj, t_s=t_s, prediction=prediction, covariance=cov)


def _meta(initial, options, traj, eop, has_cov, times, tle=None) -> dict:
    units = {"x_m": "m", "y_m": "m", "z_m": "m", "vx_m_s": "m/s", "vy_m_s": "m/s", "vz_m_s": "m/s"}
    meta = {
        "schema_version": SCHEMA_VERSION,
        "content": "ephemeris",
        "generator": "trackproc propagate",
        "time_scale": "UTC",
        "frame": "GCRF",
        "units": units,
        "initial_state": None,
        "start": iso_utc(times[0]), "end": iso_utc(times[-1]), "samples": len(times),
        "force_model": None,
        "constants": None,
        "earth_orientation": getattr(eop, "source", None) or "none (UT1-UTC = 0, no polar motion)",
        "propagator": None,
        "trackproc_version": __version__,
    }
    if tle is None:
        meta["initial_state"] = {"epoch": iso_utc(initial.epoch), "position_m": [float(x) for x in initial.r_m],
                                 "velocity_m_s": [float(x) for x in initial.v_m_s],
                                 "source": initial.source or initial.extra.get("source")}
        meta["force_model"] = FORCE_LABELS.get(options.force, options.force)
        meta["constants"] = force_model_constants(options.force)
        meta["propagator"] = {
            "method": "adaptive Taylor series (differential transformation, seed 000 eq. 14), dense output",
            "tol": float(options.tol), "order": int(traj.order), "steps": int(traj.n_steps),
            "integration_frame": "GCRF rotated by the bias-precession-nutation matrix of the state's epoch "
                                 f"({iso_utc(traj.epoch)}); J2 about that rotation axis",
        }
        if traj.force_model is not None:
            meta["force_model"] = traj.force_model.label()
            meta["constants"] = traj.force_model.describe()
            meta["propagator"] = {
                "method": "DOP853 (scipy) with the variational equations, dense output (trackproc.dynamics.forces)",
                "rtol": integrator.rtol_for(options.tol), "steps": int(traj.n_steps),
                "integration_frame": "GCRF (rotated by a constant matrix); the field acts in ITRF through IAU "
                                     "2006/2000A at every time"}
    if tle is not None:
        meta["initial_state"] = {"tle": [tle.line1, tle.line2], "name": tle.name, "source": tle.source}
        meta["force_model"] = "SGP4"
        meta["constants"] = {"model": "WGS-72 (SGP4's own)"}
        meta["propagator"] = {"method": SGP4_LABEL + ", evaluated at every output time"}
    elif options.force_note:
        meta["initial_state"]["note"] = options.force_note
    if options.stm:
        meta["stm"] = ("stm_I_J = d x_I(t) / d x_J(epoch), I, J = 1..6 = x, y, z, vx, vy, vz (GCRF, SI units); "
                       "row I is the state at the row's time")
    if has_cov:
        meta["covariance"] = {"source": "the state file's covariance of x..vz (GCRF)",
                              "propagation": "linear: P(t) = Phi(t, epoch) P0 Phi(t, epoch)^T",
                              "columns": "sigma_* = sqrt(diag P); cov_I_J = P[I, J] (m^2, m^2/s, m^2/s^2)"}
        units.update({name: unit for name, unit in zip(
            ("sigma_x_m", "sigma_y_m", "sigma_z_m", "sigma_vx_m_s", "sigma_vy_m_s", "sigma_vz_m_s"),
            ("m", "m", "m", "m/s", "m/s", "m/s"))})
    if options.station is not None:
        st = options.station
        meta["station"] = {"name": st.name, "lat_deg": float(st.lat_deg), "lon_deg": float(st.lon_deg),
                           "height_m": float(st.height_m), "earth": options.earth}
        meta["range_rate_model"] = options.range_rate_model
        meta["light_time"] = ("one-way, tagged at reception: satellite at t - rho/c, station at t"
                              if options.light_time else "none (geometry at the sample time)")
        meta["measurement_model"] = ("one-way foundation model (models/measurements.py: light-time iteration on "
                                     "SGP4 states, IAU 2006/2000A station); aberration and refraction neglected"
                                     if tle is not None else "image-domain spectra (seed 004 eqs. 7-13) on the Taylor steps; station by "
                                     "IAU 2006/2000A (Earth rotation angle exact, precession-nutation and polar "
                                     "motion interpolated); aberration and refraction neglected")
        meta["doppler_sign_convention"] = SIGN_CONVENTION
        units.update({"range_m": "m", "range_rate_m_s": "m/s", "azimuth_deg": "deg", "elevation_deg": "deg",
                      "light_time_s": "s"})
        if options.carrier_hz is not None:
            meta["carrier_hz"] = float(options.carrier_hz)
            meta["doppler_mode"] = "one-way"
            units["doppler_hz"] = "Hz"
        if has_cov:
            units.update({"sigma_range_m": "m", "sigma_range_rate_m_s": "m/s"})
            if options.carrier_hz is not None:
                units["sigma_doppler_hz"] = "Hz"
        if options.visible_only:
            meta["elevation_mask_deg"] = float(options.elevation_mask_deg)
    return meta


def oem_identity(initial, object_name: Optional[str] = None, object_id: Optional[str] = None) -> tuple[str, str]:
    """OBJECT_NAME and OBJECT_ID for an OEM: the options, else the TLE's name and international
    designator, else UNKNOWN."""
    tle = initial.extra.get("tle") if isinstance(initial.extra, dict) else None
    name = object_name or (initial.extra.get("tle_name") if isinstance(initial.extra, dict) else None) or "UNKNOWN"
    ident = object_id or (international_designator(tle[0]) if tle else None) or "UNKNOWN"
    return name, ident


def station_columns(prediction, carrier_hz) -> dict:
    """The ``--at-station`` columns of a prediction (either engine's): range, range-rate, one-way
    Doppler at ``carrier_hz`` (none without), azimuth, elevation in degrees, light time."""
    out = {"range_m": prediction.range_m, "range_rate_m_s": prediction.range_rate_m_s}
    if carrier_hz is not None:
        out["doppler_hz"] = doppler_hz(prediction.range_rate_m_s, carrier_hz)
    out.update(azimuth_deg=prediction.azimuth_rad / DEG, elevation_deg=prediction.elevation_rad / DEG,
               light_time_s=prediction.light_time_s)
    return out


def visible_rows(prediction, options, times) -> np.ndarray:
    """``--visible-only``: the rows above the elevation mask; a ProcessingError when there are none."""
    keep = prediction.elevation_rad >= options.elevation_mask_deg * DEG
    if not keep.any():
        raise ProcessingError(
            f"no visible pass: the satellite never rises above the {options.elevation_mask_deg:g} deg mask of "
            f"{options.station.name} between {iso_utc(times[0])} and {iso_utc(times[-1])} (maximum elevation "
            f"{np.degrees(prediction.elevation_rad.max()):.1f} deg); try a longer --span or a lower "
            "--elevation-mask-deg")
    return keep


def state_columns(states, times) -> dict:
    """The ephemeris columns ``time, x_m .. vz_m_s`` of GCRF ``states``; a ProcessingError when the
    orbit enters the Earth."""
    radius = np.linalg.norm(states[:, :3], axis=1)
    if np.any(radius < MIN_RADIUS_M):
        i = int(np.argmin(radius))
        raise ProcessingError(f"the orbit enters the Earth: |r| = {radius[i] / 1e3:.1f} km at "
                              f"{iso_utc(times[i])} (below {MIN_RADIUS_M / 1e3:.0f} km)")
    columns = {"time": np.asarray(times, dtype="datetime64[ns]")}
    for k, name in enumerate(("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s")):
        columns[name] = states[:, k]
    return columns
