"""The refined orbit at the pass: its highest elevation, its range-rate by the pass's link, the
time where that range-rate vanishes (the orbit's own traverse point) and its eccentricity; and
:func:`traverse_station`, which places a station so that a given state is the traverse point of
a visible pass (the seed 004 Table 1 scenario).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import frames, geodesy, propagator
from trackproc.dynamics import measurement_spectra as ms
from trackproc.dynamics import timescales as ts
from trackproc.errors import ProcessingError
from trackproc.methods.refinement import range_rate_samples
from trackproc.methods.roots import brentq
from trackproc.models import observation as ob
from trackproc.pipeline.refine.problem import Refinement, link_mode, state_prior_covariance
from trackproc.pipeline.timing import time_tag_rate
from trackproc.types import Station


def max_elevation_deg(ref: Refinement, x) -> Optional[float]:
    """Highest elevation (deg) of the refined orbit at the pass's sample times: from the series of
    :func:`model_traverse`'s prediction of the same ``x`` when the top of the pass lies inside its
    grid (:func:`_top_from_grid`), else by a prediction at all samples."""
    t = ref.problem.meas.t_s
    top = _top_from_grid(ref, x, t)
    if top is not None:
        return top
    try:
        traj = propagator.propagate(x[:3], x[3:6], ref.problem.epoch, [float(t.min()) - 1.0, float(t.max())],
                                    force=ref.options.force, frame=ref.problem.frame,
                                    eop=ref.problem.eop).raise_for_outcome()
        el = ms.predict(traj, ref.station_model, t, partials=False).elevation_rad
        return float(np.degrees(el.max()))
    except (ArithmeticError, ValueError, ProcessingError):
        return None


def link_range_rate(ref: Refinement, traj, t_s) -> np.ndarray:
    """The orbit's range-rate (m/s) at reception times ``t_s`` (s from the traverse epoch) by the
    pass's link: one-way from the DT spectra, two-way by the round trip (mean of both legs,
    :mod:`trackproc.models.observation` eqs. 7-9, on the same samples as the integral cost's
    :class:`~trackproc.methods.refinement.IntegralModel`), with the problem's range-rate model.
    ``traj`` carries its STM (the round trip's :func:`~trackproc.models.observation.evaluate`)."""
    t = np.atleast_1d(np.asarray(t_s, float))
    model = ref.problem.range_rate_model
    if link_mode(ref) == "one-way":
        return ms.predict(traj, ref.station_model, t, range_rate_model=model, partials=False).range_rate_m_s
    meas = range_rate_samples(ref.problem.epoch, ref.station_model.r_itrf_m, t, "two-way", ref.problem.eop)
    return ob.evaluate(meas, traj, n_columns=6, range_rate_model=model)[0]


def model_traverse(ref: Refinement, x) -> Optional[float]:
    """Seconds from the traverse epoch where the refined orbit's range-rate (by the pass's link,
    one- or two-way) vanishes (None if not within ±60 s); once per solution of ``ref``."""
    key = np.asarray(x, float).tobytes()
    if key not in ref.traverse_memo:
        ref.traverse_memo[key] = _model_traverse(ref, x, key)
    return ref.traverse_memo[key]


def _top_from_grid(ref: Refinement, x, t) -> Optional[float]:
    """The highest elevation (deg) at the samples ``t`` from the series of :func:`model_traverse`'s
    one-way grid prediction of ``x`` (seed 004 eqs. 10 and 13, as ``predict`` evaluates them, on the
    segment of the nearest grid point), or None when there is none or the highest of the samples
    it covers is the first or last of them: a single pass's elevation rises to one top and falls,
    so a top with lower samples on both sides inside the grid is the top of all samples."""
    grid = ref.traverse_memo.get(("grid", np.asarray(x, float).tobytes()))
    if grid is None:
        return None
    pred, t_grid = grid
    inside = np.flatnonzero((t >= t_grid[0]) & (t <= t_grid[-1]))
    if inside.size < 3:
        return None
    t_in = t[inside]
    j = np.clip(np.searchsorted(t_grid, t_in), 1, t_grid.size - 1)
    j = np.where(t_grid[j] - t_in <= t_in - t_grid[j - 1], j, j - 1)
    segs = pred.segments
    s = pred.segment_index[j]
    centres = segs.centre_s[s]
    powers = (t_in - centres)[:, None] ** np.arange(segs.rho.shape[-1])
    rho = np.einsum("nkc,nc->nk", segs.rho[s], powers)
    _, el, _ = geodesy.enu_to_azel(ref.station_model.to_enu(rho, t_in, centres_s=centres))
    i = int(np.argmax(el))
    if t_in[i] <= t_in.min() or t_in[i] >= t_in.max():
        return None
    return float(np.degrees(el[i]))


def _model_traverse(ref: Refinement, x, key=None) -> Optional[float]:
    try:
        traj = propagator.propagate(x[:3], x[3:6], ref.problem.epoch, [-62.0, 62.0], force=ref.options.force,
                                    stm=link_mode(ref) == "two-way", frame=ref.problem.frame,
                                    eop=ref.problem.eop).raise_for_outcome()
        t = np.linspace(-60.0, 60.0, 241)
        if link_mode(ref) == "one-way":
            pred = ms.predict(traj, ref.station_model, t, range_rate_model=ref.problem.range_rate_model,
                              partials=False)
            rr = pred.range_rate_m_s
            if key is not None:          # the same series give the highest elevation (max_elevation_deg)
                ref.traverse_memo[("grid", key)] = (pred, t)

            def at(m):
                return _series_range_rate(pred, t, m)
        else:
            rr = link_range_rate(ref, traj, t)

            def at(m):
                return float(link_range_rate(ref, traj, np.array([m]))[0])
        k = np.flatnonzero((rr[:-1] < 0) & (rr[1:] >= 0))
        if k.size == 0:
            return None
        i = int(k[np.argmin(np.abs(t[k]))])
        a, b = t[i], t[i + 1]
        fa, fb = rr[i], rr[i + 1]
        for _ in range(30):
            m = a - fa * (b - a) / (fb - fa)
            fm = at(m)
            if abs(fm) < 1e-9 or b - a < 1e-7:
                return float(m)
            if fm < 0:
                a, fa = m, fm
            else:
                b, fb = m, fm
        return float(m)
    except (ArithmeticError, ValueError, ProcessingError):
        return None


def _series_range_rate(pred, t_grid, m: float) -> float:
    """The one-way range-rate at ``m`` (s) from the series of the grid's own prediction ``pred``
    (seed 004 eq. 13, the inverse transform, on the segment of the grid point nearest ``m``): the
    secant's iterates read the spectra already made instead of a new one-point prediction each
    (~2 ms of per-call work). Within a segment's half-width the series meets the trajectory's
    range tolerance, so the value agrees with a prediction centred at ``m`` to that tolerance
    (tests/pipeline/test_refine_traverse.py)."""
    j = int(np.clip(np.searchsorted(t_grid, m), 1, t_grid.size - 1))
    j = j if t_grid[j] - m <= m - t_grid[j - 1] else j - 1
    segs = pred.segments
    s = int(pred.segment_index[j])
    dt = m - float(segs.centre_s[s])
    n = segs.range.shape[-1]
    rr = float((np.arange(1, n) * segs.range[s, 1:]) @ dt ** np.arange(n - 1))    # dD/dt (the doppler model)
    if pred.range_rate_model == "instantaneous":
        # Orekit's instantaneous range-rate: the doppler one times 1 + rho . v_sat / (c D)
        p0 = dt ** np.arange(n)
        rr *= 1.0 + float((segs.rho[s] @ p0) @ (segs.v_sat[s] @ p0)) / (float(segs.range[s] @ p0) * C_LIGHT)
    return rr


def time_tag_direction(ref: Refinement, x) -> Optional[np.ndarray]:
    """:func:`trackproc.pipeline.timing.time_tag_rate` of a refinement's solution ``x``."""
    return time_tag_rate(x, ref.problem.epoch, ref.options.force, ref.problem.frame, ref.problem.eop)


def time_tag_covariance(ref: Refinement, x, linear_cov, sigma_s: float) -> Optional[np.ndarray]:
    """The covariance a time-tag offset of 1-sigma ``sigma_s`` (s) adds to a solution (a consider
    parameter; Tapley, Schutz & Born 2004, section 6.3): the data describe the state moved by
    ``g Δt`` (:func:`time_tag_direction`), and the solution follows that move by its gain,
    ``δx̂ = (g, 0) − C[:, :6] P⁻¹ g`` (``C`` the linear covariance of all parameters, ``P`` the
    state a-priori; the whole move without one), so the term is ``δx̂ δx̂ᵀ σ²``."""
    g = time_tag_direction(ref, x)
    if g is None or not sigma_s > 0:
        return None
    c = np.asarray(linear_cov, float)
    move = np.zeros(c.shape[0])
    move[:6] = g
    pcov = state_prior_covariance(ref.priors) if ref.priors else None
    if pcov is not None:
        move = move - c[:, :6] @ np.linalg.solve(pcov, g)
    return np.outer(move, move) * sigma_s ** 2


def eccentricity(r, v, mu) -> float:
    r = np.asarray(r, float)
    v = np.asarray(v, float)
    e = ((v @ v - mu / np.linalg.norm(r)) * r - (r @ v) * v) / mu
    return float(np.linalg.norm(e))


def traverse_station(state, *, cross_track_m: float = 600e3, side: str = "left", height_m: float = 0.0,
                     name: str = "TRV", eop=None, earth: str = "wgs84", force: str = "j2",
                     range_rate_model: str = "doppler"):
    """A station for which ``state`` (GCRF, at its epoch) is the traverse point of a visible pass.

    The station is placed ``cross_track_m`` from the sub-satellite point at the epoch, to the
    ``side`` (``"left"``/``"right"``) of the ground track (perpendicular to the satellite's
    Earth-fixed velocity), then moved along the track until the one-way range-rate received at
    the epoch (light time, station motion, ``range_rate_model``) is zero to 1 µm/s. Returns
    ``(Station, info)`` with the elevation and range at the epoch (the top of the pass).
    Implements the seed 004 Table 1 scenario (the truth is the traverse point).
    """
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
