"""Predicted measurements at given times (:func:`predict`): segments refined until the series converge, then evaluated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import geodesy
from trackproc.dynamics import spectra as sp
from trackproc.vocabulary import check_range_rate_model

from trackproc.dynamics.measurement_spectra.series import evaluate_segments, shift_matrix
from trackproc.dynamics.measurement_spectra.station import StationModel
from trackproc.dynamics.measurement_spectra.segments import SegmentSpectra, initial_segments, segment_spectra


_MAX_SPLIT_ROUNDS = 40


@dataclass(frozen=True)
class Prediction:
    """Predicted one-way measurements of one station at reception times ``t_s``.

    Arrays along the samples (input order): ``range_m``, ``range_rate_m_s`` (the chosen
    model), ``light_time_s``, ``azimuth_rad`` ([0, 2 pi)), ``elevation_rad``; with sensitivities
    ``d_range_d_state`` and ``d_range_rate_d_state`` (N, 6): partials with respect to the GCRF
    state at the trajectory's epoch (x, y, z, vx, vy, vz; m/m, m/(m/s), ...). ``rho_qi`` (N, 3)
    is the topocentric vector ``r_sat(t_e) - r_st(t)`` (quasi-inertial frame).

    ``segments`` holds the spectra (:class:`SegmentSpectra`), ``segment_index`` (N,) the
    segment of each sample, so that the series themselves can be reused (e.g. the integral
    cost of seed 004 eq. 14).
    """

    t_s: np.ndarray
    range_m: np.ndarray
    range_rate_m_s: np.ndarray
    light_time_s: np.ndarray
    azimuth_rad: np.ndarray
    elevation_rad: np.ndarray
    d_range_d_state: np.ndarray | None
    d_range_rate_d_state: np.ndarray | None
    rho_qi: np.ndarray
    range_rate_model: str
    light_time: bool
    segments: SegmentSpectra
    segment_index: np.ndarray


def _concat_segments(parts):
    if len(parts) == 1:
        return parts[0]
    fields = {}
    for name in SegmentSpectra.__dataclass_fields__:
        vals = [getattr(p, name) for p in parts]
        if name == "iterations":
            fields[name] = max(vals)
        elif vals[0] is None:
            fields[name] = None
        else:
            fields[name] = np.concatenate(vals, axis=0)
    return SegmentSpectra(**fields)


def predict(trajectory, station: StationModel, t_s, *, range_rate_model: str = "doppler",
            light_time: bool = True, partials: bool | None = None, tol: float | None = None,
            c: float = C_LIGHT) -> Prediction:
    """Range, range-rate, azimuth, elevation and their partials at reception times ``t_s``.

    Parameters
    ----------
    trajectory : :class:`~trackproc.dynamics.propagator.Trajectory`
        Covers the sample times (emission times may precede its start by the light time).
    station : StationModel
        Built on the trajectory's epoch and reference frame (``q_ref = trajectory.frame.q``).
    t_s : (N,)
        Reception times, s from the trajectory's epoch (any order).
    range_rate_model : ``"doppler"`` (default; the derivative of the light-time range) or
        ``"instantaneous"`` (Orekit's one-way RangeRate, without the light-time factor).
    light_time : bool
        One-way light time (default). False: geometry at the reception time (seed 004).
    partials : bool, optional
        Sensitivities to the epoch state; default: when the trajectory carries the STM.
    tol : float, optional
        Truncation tolerance of the range series (relative to the range); default the
        trajectory's.

    Implements seed 004 eqs. 7-13 (module docstring); raises ValueError for an unknown model.

    Over 100 lines with this docstring; its code is under 100.
    """
    check_range_rate_model(range_rate_model)
    t_in = np.atleast_1d(np.asarray(t_s, float))
    if t_in.ndim != 1 or t_in.size == 0 or not np.all(np.isfinite(t_in)):
        raise ValueError("t_s must be a non-empty 1-D array of finite times")
    if t_in.min() < trajectory.t_min_s - 1e-9 or t_in.max() > trajectory.t_max_s + 1e-9:
        raise ValueError(f"sample times [{t_in.min()}, {t_in.max()}] s lie outside the propagated interval "
                         f"[{trajectory.t_min_s}, {trajectory.t_max_s}] s")
    steps = trajectory.steps()
    if partials is None:
        partials = steps.sensitivities is not None
    if partials and steps.sensitivities is None:
        raise ValueError("partials need a trajectory propagated with stm=True")
    tol = float(trajectory.tol if tol is None else tol)
    n = steps.coefficients.shape[-1]
    order = np.argsort(t_in, kind="stable")
    t = t_in[order]
    step_idx = steps.locate(t)
    seg_of = initial_segments(t, step_idx, steps, station, tol, n)

    done = []
    done_members = []
    pending = [np.flatnonzero(seg_of == k) for k in range(seg_of[-1] + 1)]
    for _ in range(_MAX_SPLIT_ROUNDS):
        if not pending:
            break
        first = np.array([m[0] for m in pending])
        last = np.array([m[-1] for m in pending])
        centre = 0.5 * (t[first] + t[last])
        half = 0.5 * (t[last] - t[first])
        k = step_idx[first]
        shift = shift_matrix(centre - steps.t_expand_s[k], n)
        x = steps.coefficients[k] @ shift
        xs = None
        if partials:
            sens = steps.sensitivities[k]                                # (S, 3, 6, n)
            xs = (sens.reshape(k.size, 18, n) @ shift).reshape(k.size, 3, 6, n)
        st = station.spectra(centre, n)
        seg = segment_spectra(x, xs, st, centre, half, light_time=light_time, c=c,
                              vector_partials=range_rate_model == "instantaneous")
        scale = np.maximum(np.abs(seg.range[:, 0]), 1.0)
        bad = (seg.truncation_m() > tol * scale) & (half > 0)
        good = np.flatnonzero(~bad)
        if good.size:
            done.append(_take(seg, good))
            done_members.extend(pending[i] for i in good)
        pending = [half_ for i in np.flatnonzero(bad) for half_ in np.array_split(pending[i], 2)]
    else:
        raise ArithmeticError("could not split the pass into converging range segments")
    segs = _concat_segments(done)
    seg_index = np.empty(t.size, dtype=np.int64)
    bounds = np.empty((len(done_members), 2), dtype=np.int64)
    for i, members in enumerate(done_members):
        seg_index[members] = i
        bounds[i] = members[0], members[-1] + 1                         # contiguous in sorted time
    dt = t - segs.centre_s[seg_index]

    n_coef = segs.range.shape[-1]
    v0 = sp.vandermonde(dt, n_coef)
    v1 = sp.vandermonde(dt, n_coef, derivative=1)

    def at_samples(spec, vander=v0):
        return evaluate_segments(spec, bounds, vander)

    rng = at_samples(segs.range)
    rr = at_samples(segs.range, v1)
    rho = at_samples(segs.rho)                                           # (N, 3)
    v_sat = at_samples(segs.v_sat)
    factor = 1.0 + np.einsum("ni,ni->n", rho, v_sat) / (rng * c) if light_time else np.ones_like(rng)
    d_rng = d_rr = None
    if partials:
        big = trajectory.rotation                                      # x0_qi = big @ x0_gcrf
        d_rng_qi = at_samples(segs.d_range)                              # (N, 6)
        d_rr_qi = at_samples(segs.d_range, v1)
        if range_rate_model == "instantaneous" and light_time:
            # Vr_inst = Vr_dop * F, F = 1 + rho . v_sat / (c D)
            d_rho = at_samples(segs.d_rho)                               # (N, 3, 6)
            d_v = at_samples(segs.d_v_sat)
            dot = np.einsum("ni,ni->n", rho, v_sat)
            d_dot = np.einsum("nip,ni->np", d_rho, v_sat) + np.einsum("ni,nip->np", rho, d_v)
            d_factor = (d_dot - (dot / rng)[:, None] * d_rng_qi) / (c * rng)[:, None]
            d_rr_qi = d_rr_qi * factor[:, None] + rr[:, None] * d_factor
        d_rng = d_rng_qi @ big
        d_rr = d_rr_qi @ big
    if range_rate_model == "instantaneous":
        rr = rr * factor
    enu = station.to_enu(rho, t, centres_s=segs.centre_s[seg_index])
    az, el, _ = geodesy.enu_to_azel(enu)

    inv = np.empty_like(order)
    inv[order] = np.arange(order.size)

    def pick(a):
        return None if a is None else a[inv]

    return Prediction(t_s=t_in, range_m=rng[inv], range_rate_m_s=rr[inv],
                      light_time_s=(rng / c)[inv] if light_time else np.zeros(t_in.size),
                      azimuth_rad=az[inv], elevation_rad=el[inv], d_range_d_state=pick(d_rng),
                      d_range_rate_d_state=pick(d_rr), rho_qi=rho[inv], range_rate_model=range_rate_model,
                      light_time=light_time, segments=segs, segment_index=seg_index[inv])


def _take(seg: SegmentSpectra, idx) -> SegmentSpectra:
    fields = {}
    for name in SegmentSpectra.__dataclass_fields__:
        val = getattr(seg, name)
        fields[name] = val if (val is None or name == "iterations") else val[idx]
    return SegmentSpectra(**fields)
