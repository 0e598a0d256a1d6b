"""Per-segment spectra of the topocentric vector, the one-way light-time range and range-rate and
their sensitivities (seed 004 eqs. 11-13): :func:`segment_spectra`; the initial segmentation of a pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import spectra as sp
from trackproc.dynamics.frames import rotation_z

from trackproc.dynamics.measurement_spectra.series import (cauchy_sum, derivative_matrix, evaluate_series,
                                                           product_matrix, series_reciprocal, series_sqrt)


#: Terms m = 0..LIGHT_TIME_TERMS of the Taylor shift r(t - T) = sum (-T)^m/m! r^(m)(t).
LIGHT_TIME_TERMS = 4
#: Maximum passes of the light-time fixed point (converges in 4 from T = 0).
MAX_LIGHT_TIME_ITER = 8


#: Safety factor on the segment half-width ``tol^(1/n) rho / |v_rel|``.
SEGMENT_SAFETY = 0.8


@dataclass(frozen=True)
class SegmentSpectra:
    """Spectra of one batch of segments (leading axis S), H = 1 s, about ``centre_s``.

    ``range`` (S, n): the light-time range D; ``rho`` (S, 3, n): topocentric vector
    ``r_sat(t_e) - r_st(t)``; ``v_sat`` (S, 3, n): satellite velocity at emission time;
    ``a_sat`` (S, 3, n): its acceleration; ``station`` (S, 3, n); ``d_range`` (S, 6, n) or None:
    dD / d(initial quasi-inertial state); ``d_rho`` / ``d_v_sat`` (S, 3, 6, n) or None;
    ``iterations``: light-time passes.
    """

    centre_s: np.ndarray
    half_width_s: np.ndarray
    range: np.ndarray
    rho: np.ndarray
    v_sat: np.ndarray
    a_sat: np.ndarray
    station: np.ndarray
    d_range: np.ndarray | None
    d_rho: np.ndarray | None
    d_v_sat: np.ndarray | None
    iterations: int

    @property
    def range_rate(self) -> np.ndarray:
        """Spectra of dD/dt (``doppler`` model), derivative rule: ``Vr(K) = (K+1) D(K+1)``."""
        return sp.derivative(self.range)

    def truncation_m(self) -> np.ndarray:
        """Estimated truncation error of the range series at the half-width, m (S,)."""
        n = self.range.shape[-1]
        w = self.half_width_s[:, None]
        k = np.arange(n - 2, n)
        return np.sum(np.abs(self.range[:, -2:]) * w ** k, axis=-1)


def segment_spectra(x_sat, x_sens, station, centre_s, half_width_s, *, light_time: bool = True,
                    c: float = C_LIGHT, vector_partials: bool = True) -> SegmentSpectra:
    """Range, topocentric and light-time spectra of segments (seed 004 eqs. 11-12).

    Parameters
    ----------
    x_sat : (S, 3, n)
        Satellite position spectra about each segment centre (m, H = 1 s).
    x_sens : (S, 3, P, n) or None
        Their sensitivity spectra (d position / d parameter).
    station : (S, 3, n)
        Station position spectra about the same centres (m).
    centre_s, half_width_s : (S,)
        Expansion points and half-widths (s), for the light-time convergence test.
    light_time : bool
        One-way light time (default); False gives the instantaneous geometry of seed 004.
    vector_partials : bool
        Also the sensitivities of the topocentric vector and of the satellite velocity at
        emission (``d_rho``, ``d_v_sat``; needed by the instantaneous range-rate's partials).

    The light-time iteration and the sensitivities are described in the module docstring.
    """
    s, _, n = x_sat.shape
    dmat = derivative_matrix(n)
    w = np.asarray(half_width_s, float)
    wk = np.maximum(w, 1.0)[:, None] ** np.arange(n)
    eye = np.broadcast_to(np.eye(n), (s, n, n))
    rho = x_sat - station
    d = series_sqrt(cauchy_sum(rho, rho))
    e_op = eye
    iterations = 0
    previous = np.inf
    if light_time:
        for iterations in range(1, MAX_LIGHT_TIME_ITER + 1):
            u = product_matrix(d / c)
            term = eye
            e_op = eye.copy()
            for m in range(1, LIGHT_TIME_TERMS + 1):
                term = (dmat @ term) @ u * (-1.0 / m)
                e_op = e_op + term
            rho = x_sat @ e_op - station
            d_new = series_sqrt(cauchy_sum(rho, rho))
            change = float(np.max(np.sum(np.abs(d_new - d) * wk, axis=-1)))
            d = d_new
            # linear convergence: the next change is about change * (change / previous)
            ratio = min(1.0, change / previous) if np.isfinite(previous) and previous > 0 else 1.0
            if change < 1e-10 or change * ratio < 1e-12:
                break
            previous = change
        else:
            raise ArithmeticError(f"light-time iteration did not converge (last change {change:.3g} m)")
    x_v = x_sat @ dmat
    v_sat = x_v @ e_op
    a_sat = x_v @ dmat @ e_op
    d_range = d_rho = d_v = None
    if x_sens is not None:
        npar = x_sens.shape[2]
        flat = x_sens.reshape(s, 3 * npar, n)
        d_rho = (flat @ e_op).reshape(s, 3, npar, n)                # dr_sat(t_e)/dp, t_e held fixed
        num = np.einsum("sipl,silk->spk", d_rho, product_matrix(rho))  # rho . dr_sat(t_e)/dp
        den = d + (cauchy_sum(rho, v_sat) / c if light_time else 0.0)
        d_range = num @ product_matrix(series_reciprocal(den))
        if vector_partials:
            d_v = (flat @ dmat @ e_op).reshape(s, 3, npar, n)
            if light_time:
                # the emission time moves with the range: d rho = dr_sat(t_e) - v_sat(t_e) dD / c
                m_dd = product_matrix(d_range)
                d_rho = d_rho - np.einsum("sil,splk->sipk", v_sat, m_dd) / c
                d_v = d_v - np.einsum("sil,splk->sipk", a_sat, m_dd) / c
        else:
            d_rho = None
    return SegmentSpectra(centre_s=np.asarray(centre_s, float), half_width_s=w, range=d, rho=rho,
                          v_sat=v_sat, a_sat=a_sat, station=station, d_range=d_range, d_rho=d_rho,
                          d_v_sat=d_v, iterations=iterations)


def initial_segments(t, step_idx, steps, station, tol, n):
    """Group sorted sample times in segments: same step, width <= 2 kappa rho/|v_rel|.

    ``rho/|v_rel|`` (the straight-line distance to the nearest complex zero of D2) is computed
    at up to 64 of the samples and interpolated: it only sizes the segments, the truncation
    check in :func:`predict` decides.
    """
    if t.size == 1:
        return np.zeros(1, dtype=np.int64)
    probe = np.unique(np.linspace(0, t.size - 1, min(t.size, 64)).round().astype(int))
    tp, kp = t[probe], step_idx[probe]
    coef = steps.coefficients[kp]                                        # (M, 3, n)
    dt = tp - steps.t_expand_s[kp]
    r = evaluate_series(coef, dt)
    v = evaluate_series(coef, dt, 1)
    r_st, v_st = _approx_station(station, tp)
    radius = np.linalg.norm(r - r_st, axis=-1) / np.maximum(np.linalg.norm(v - v_st, axis=-1), 1.0)
    kappa = SEGMENT_SAFETY * tol ** (1.0 / n)
    width = 2.0 * kappa * np.interp(t, tp, radius)
    gap = np.diff(t) / np.minimum(width[1:], width[:-1])
    budget = np.concatenate([[0.0], np.cumsum(gap)])
    seg = np.floor(budget).astype(np.int64)
    new = np.concatenate([[True], (np.diff(seg) != 0) | (np.diff(step_idx) != 0)])
    return np.cumsum(new) - 1


def _approx_station(station, t):
    """Station position and velocity from the frozen rotation (for segment sizing only)."""
    theta = station.era0_rad + station.omega_rad_s * t
    r = np.einsum("nji,j->ni", rotation_z(theta), station.p_nodes[0]) @ station.pn_nodes[0].T
    v = station.omega_rad_s * np.stack([-r[:, 1], r[:, 0], np.zeros_like(t)], -1)
    return r, v
