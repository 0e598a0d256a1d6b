"""Measurement spectra in the image domain: a ground station, the topocentric vector, the one-way
light-time range and range-rate, and their sensitivities to the initial state.

Seed 004 eqs. 7-13 in general form, on the per-step spectra of the Taylor engine
(:mod:`trackproc.dynamics.taylor`, through :class:`trackproc.dynamics.propagator.Trajectory`).
All spectra have H = 1 s (Taylor coefficients; docs/equations.md, notation) and live in the
quasi-inertial frame of the trajectory (GCRF rotated by ``q_ref``, the precession-nutation
matrix of its reference epoch).

Station (seed 004 eqs. 7-10)
    GCRF -> ITRF is ``W R3(ERA) Q`` (IAU 2006/2000A), so a station fixed at ``r_itrf`` is, in
    the quasi-inertial frame,

        r_st(t) = P(t) R3(theta(t))^T p(t),   P = q_ref Q(t)^T,  p = W(t)^T r_itrf.

    ``theta`` is the Earth Rotation Angle, exactly linear in UT1 and so, inside a day of a
    tabulated EOP (UT1-TAI interpolated linearly), exactly linear in SI time:
    ``theta(c + tau) = ERA(c) + omega tau``. The spectra of ``cos theta``, ``sin theta`` are then
    closed form, ``C(K) = cos(ERA(c) + K pi/2) omega^K/K!`` and the same with sin -- the solution
    of the seed 004 eq. 9 recurrence for a linear angle (seed eq. 7 writes
    ``S = q Omega t + S0``). ``P`` (precession-nutation since the reference epoch: 0.15
    arcsec a day) and ``p`` (polar motion) vary slowly; each is interpolated quadratically
    through nodes at most 30 min apart and enters as an exact Cauchy product with a
    degree-2 polynomial. ``frozen=True`` drops that drift (P = I, p and omega those of the
    reference epoch, ``theta = era0 + omega t``): the seed-paper model, and exactly
    :meth:`QuasiInertialFrame.station <trackproc.dynamics.frames.QuasiInertialFrame.station>`.
    Its error is measured in the tests and reported in ``docs/propagate.md`` (about 1 cm of
    station position after 15 minutes from the reference epoch, metres after a day).

Topocentric vector, range, range-rate (seed 004 eqs. 11-12)
    ``rho(t) = r_sat(t_e) - r_st(t)``, ``D2 = rho . rho`` (Cauchy products),
    ``D = sqrt(D2)`` (square-root rule, eq. 12), ``Vr(K) = (K+1) D(K+1)`` (derivative rule).

One-way light time (README "Units, sign conventions, time and frames"; :mod:`trackproc.models.light_time`)
    A sample is time-tagged at reception ``t`` and the satellite is taken at the emission time
    ``t_e = t - T(t)``, ``c T = |r_sat(t - T) - r_st(t)|``. Here ``T`` is itself a spectrum:
    the composition ``r_sat(t - T(t)) = sum_m (-T)^m / m! r_sat^(m)(t)`` is a Taylor shift done
    in the image domain (derivative rule for ``r^(m)``, Cauchy powers of ``T``; ``m <= 4``,
    whose remainder ``T^5 |r^(5)| / 120`` is below 1e-13 m for LEO and GEO), and ``T`` is found
    by fixed-point iteration on spectra, ``T <- sqrt(D2(T)) / c``, which contracts by
    ``|u . v| / c ~ 3e-5`` per pass (after the geometric range, three passes reach 1e-12 m;
    the loop stops when the predicted next change is below 1e-12 m). The range
    spectrum ``D`` is then the light-time range as a function of reception time, so the
    derivative rule gives exactly the ``doppler`` range-rate model
    ``dD/dt = u . (v_sat(t_e) - v_st(t)) / (1 + u . v_sat(t_e)/c)``. The ``instantaneous``
    model (Orekit's) is ``u . (v_sat(t_e) - v_st(t))``, the same times the light-time factor
    ``F = 1 + u . v_sat(t_e)/c``.

Sensitivities (seed 004 eqs. 19-21, first order)
    The engine's sensitivity spectra ``dX/dx0`` go through the same retarded-time operator.
    Differentiating ``D = |rho|`` with ``T = D/c`` gives, as spectra,

        dD/dx0 = (rho . dr_sat(t_e)/dx0) / (D + rho . v_sat(t_e)/c)        (quotient rule)

    -- the light-time correction factor appears in the denominator -- and
    ``d Vr/dx0`` is its derivative rule. The instantaneous model's partials add the
    derivative of ``F`` (evaluated at the samples).

Segments
    A range series converges only within the distance (in complex time) to the nearest zero of
    ``D2``, about ``rho / |v_rel|`` (100 s at the top of an 800-km pass), which is shorter than
    a pass. Samples are therefore grouped in segments inside one Taylor step, each expanded
    about its midpoint with half-width ``w`` at most ``0.8 tol^(1/n) rho/|v_rel|``; the
    truncation ``sum_{K=n-2,n-1} |D(K)| w^K`` is then checked against ``tol max(D(0), 1 m)``
    and failing segments are halved (all segments of a pass are computed together, as
    arrays with a leading segment axis).

Products of spectra are done as matrix products: the Cauchy product ``u*v`` is ``u @ M(v)``
with the upper-triangular Toeplitz matrix ``M(v)[l, K] = V(K - l)``, the derivative rule is a
constant matrix and re-expanding about another point is ``u @ B(delta)``,
``B[j, K] = C(j, K) delta^(j-K)``; the retarded-time operator is
``E = sum_m (-1)^m/m! D^m M(T)^m``.

Limits: one-way measurements (no two-way round trip); aberration and refraction neglected,
as in :mod:`trackproc.models.observables` (whose conventions and range-rate models these series
follow); the station must never coincide with the
satellite (``D2(0) > 0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import erfa
import numpy as np

from trackproc.constants import C_LIGHT
from trackproc.dynamics import geodesy
from trackproc.dynamics import spectra as sp
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.frames import OMEGA_ERA, _r3
from trackproc.vocabulary import RANGE_RATE_MODELS, check_range_rate_model  # noqa: F401  (re-exported)

__all__ = ["RANGE_RATE_MODELS", "StationModel", "Prediction", "rotation_spectra", "predict",
           "segment_spectra", "LIGHT_TIME_TERMS"]

#: Terms m = 0..LIGHT_TIME_TERMS of the Taylor shift r(t - T) = sum (-T)^m/m! r^(m)(t).
LIGHT_TIME_TERMS = 4
#: Maximum passes of the light-time fixed point (converges in 4 from T = 0).
MAX_LIGHT_TIME_ITER = 8
#: Spacing of the nodes of the slow rotation (precession-nutation, polar motion), s.
SLOW_NODE_SPACING_S = 1800.0
#: Margin of the slow-rotation nodes beyond the requested interval, s.
_SLOW_PAD_S = 60.0
#: Safety factor on the segment half-width ``tol^(1/n) rho / |v_rel|``.
_SEGMENT_SAFETY = 0.8
_MAX_SPLIT_ROUNDS = 40


# --------------------------------------------------------------------------- matrix forms

@lru_cache(maxsize=16)
def _derivative_matrix(n: int) -> np.ndarray:
    """D with ``(u @ D)[K] = (K+1) U(K+1)``: the derivative rule (docs/equations.md, notation)."""
    d = np.zeros((n, n))
    k = np.arange(n - 1)
    d[k + 1, k] = k + 1.0
    return d


@lru_cache(maxsize=16)
def _toeplitz_index(n: int) -> tuple[np.ndarray, np.ndarray]:
    row, col = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    return np.where(col >= row, col - row, n), (col >= row)


def product_matrix(v) -> np.ndarray:
    """``M(v)`` (..., n, n) with ``u @ M(v) = u * v`` (Cauchy product, docs/equations.md, notation).

    Upper-triangular Toeplitz: ``M[l, K] = V(K - l)`` for ``K >= l``. ``M(u) M(v) = M(u*v)``:
    truncated series and these matrices form the same commutative algebra.
    """
    v = np.asarray(v, float)
    n = v.shape[-1]
    idx, _ = _toeplitz_index(n)
    pad = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], axis=-1)
    return pad[..., idx]


@lru_cache(maxsize=16)
def _binomials(n: int) -> np.ndarray:
    j, k = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    out = np.zeros((n, n))
    mask = j >= k
    out[mask] = [math.comb(int(a), int(b)) for a, b in zip(j[mask], k[mask])]
    return out


def shift_matrix(delta_s, n: int) -> np.ndarray:
    """``B(delta)`` (..., n, n): ``u @ B`` re-expands a spectrum about ``t* + delta``.

    ``B[j, K] = C(j, K) delta^(j - K)`` (Taylor's theorem for the polynomial the spectrum is).

    Implements the re-expansion of a spectrum about another centre (docs/equations.md, notation).
    """
    d = np.asarray(delta_s, float)[..., None, None]
    j, k = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    e = np.where(j >= k, j - k, 0)
    return _binomials(n) * np.where(j >= k, d ** e, 0.0)


def _cauchy_sum(u, v) -> np.ndarray:
    """``sum_i u_i * v_i`` over axis -2 (a dot product of vector spectra), (..., 3, n) -> (..., n)."""
    return np.einsum("...il,...ilk->...k", u, product_matrix(v))


def _evaluate(spec, dt, derivative: int = 0, *, vander=None):
    """Inverse transform of per-sample spectra ``spec`` (N, ..., n) at offsets ``dt`` (N,).

    ``vander`` may give the matrix ``sp.vandermonde(dt, n, derivative=derivative)`` once for all.
    """
    v = vander if vander is not None else sp.vandermonde(dt, spec.shape[-1], derivative=derivative)
    return np.einsum("n...k,nk->n...", spec, v)


def _evaluate_segments(spec, bounds, vander) -> np.ndarray:
    """Inverse transform of segment spectra ``spec`` (S, ..., n) at the samples: segment ``i``
    covers the sorted samples ``bounds[i, 0]:bounds[i, 1]``, ``vander`` (N, n) their powers of
    ``t - centre`` (one small matrix product per segment; no per-sample copy of the spectra)."""
    n = spec.shape[-1]
    tail = spec.shape[1:-1]
    flat = spec.reshape(spec.shape[0], -1, n)
    out = np.empty((vander.shape[0], flat.shape[1]))
    for i, (a, b) in enumerate(bounds):
        out[a:b] = vander[a:b] @ flat[i].T
    return out.reshape((vander.shape[0],) + tail)


def _sqrt(d2) -> np.ndarray:
    """Seed 004 eq. 12 on (S, n) spectra: ``D(K) = (D2(K) - sum_{l=1..K-1} D(K-l) D(l)) / (2 D(0))``.

    The same rule as :func:`trackproc.dynamics.spectra.sqrt`, with less per-order overhead.
    """
    if np.any(d2[:, 0] <= 0):
        raise ArithmeticError("the station-satellite distance vanishes (D2(0) <= 0)")
    n = d2.shape[-1]
    d = np.zeros_like(d2)
    d[:, 0] = np.sqrt(d2[:, 0])
    inv2 = 0.5 / d[:, 0]
    if n > 1:
        d[:, 1] = d2[:, 1] * inv2
    for k in range(2, n):
        d[:, k] = (d2[:, k] - np.einsum("sl,sl->s", d[:, 1:k], d[:, k - 1:0:-1])) * inv2
    return d


def _reciprocal(u) -> np.ndarray:
    """Spectrum of 1/u on (S, n) spectra: ``R(K) = -sum_{l=1..K} U(l) R(K-l) / U(0)`` (product rule)."""
    n = u.shape[-1]
    r = np.zeros_like(u)
    inv = 1.0 / u[:, 0]
    r[:, 0] = inv
    for k in range(1, n):
        r[:, k] = -np.einsum("sl,sl->s", u[:, 1:k + 1], r[:, k - 1::-1]) * inv
    return r


# --------------------------------------------------------------------------- the station

def rotation_spectra(theta_rad, omega_rad_s, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Spectra of ``cos`` and ``sin`` of the linear angle ``theta + omega tau``, shape (..., n).

    ``C(K) = cos(theta + K pi/2) omega^K / K!``, ``S(K) = sin(theta + K pi/2) omega^K / K!``:
    the closed-form solution of the seed 004 eq. 9 recurrence (``sin(K+1) = sum (l+1)/(K+1)
    S(l+1) cos(K-l)``, ...) when the angle's spectrum is ``(theta, omega, 0, ...)``, i.e. the
    sidereal angle of seed 004 eq. 7 with ``omega = q Omega``.

    >>> import numpy as np
    >>> from trackproc.dynamics import geodesy
from trackproc.dynamics import spectra as sp
    >>> c, s = rotation_spectra(0.3, 7.29e-5, 6)
    >>> sn, cs = sp.sin_cos(np.array([0.3, 7.29e-5, 0, 0, 0, 0]))
    >>> bool(np.allclose(c, cs, rtol=1e-13, atol=0) and np.allclose(s, sn, rtol=1e-13, atol=0))
    True
    """
    theta = np.asarray(theta_rad, float)[..., None]
    omega = np.asarray(omega_rad_s, float)[..., None]
    k = np.arange(n)
    fact = np.array([math.factorial(int(i)) for i in k], float)
    phase = theta + k * (np.pi / 2)
    scale = omega ** k / fact
    return np.cos(phase) * scale, np.sin(phase) * scale


def _times_poly(series, poly) -> np.ndarray:
    """Cauchy product of spectra (..., n) with short polynomials (..., d): sum_j P(j) S(K - j)."""
    n = series.shape[-1]
    out = series * poly[..., :1]
    for j in range(1, poly.shape[-1]):
        out[..., j:] += series[..., :n - j] * poly[..., j:j + 1]
    return out


def _era_rate(jd1, jd2, eop):
    """Earth Rotation Angle (rad) and its rate per SI second at UTC dates (the UT1 rate of a
    tabulated EOP by central differences over +-60 s, as :func:`frames.earth_rotation`)."""
    dut1, _, _ = eop.at(jd1, jd2)
    u1, u2 = ts.utc_to_ut1(jd1, jd2, dut1)
    era = np.asarray(erfa.era00(u1, u2), float)
    if eop.tabulated:
        d = 60.0 / ts.DAY_S
        mjd = np.asarray(jd1) - 2400000.5 + np.asarray(jd2)
        up = np.interp(mjd + d, eop.mjd, eop.ut1_minus_tai_s)
        dn = np.interp(mjd - d, eop.mjd, eop.ut1_minus_tai_s)
        rate = OMEGA_ERA * (1.0 + (up - dn) / 120.0)
    else:
        rate = np.full(era.shape, OMEGA_ERA)
    return era, rate


def _quadratic_about(nodes_t, values, c):
    """Coefficients (S, 3, ...) of the quadratic through the 3 nodes nearest each ``c``,
    re-expanded about ``c``: value(c + tau) = A0 + A1 tau + A2 tau^2."""
    k = nodes_t.size
    step = (nodes_t[-1] - nodes_t[0]) / (k - 1)
    i = np.clip(np.rint((c - nodes_t[0]) / step).astype(int) - 1, 0, k - 3)
    t0, t1, t2 = nodes_t[i], nodes_t[i + 1], nodes_t[i + 2]
    f0, f1, f2 = values[i], values[i + 1], values[i + 2]
    # Newton form about t0, then re-expanded about c
    shape = (-1,) + (1,) * (values.ndim - 1)

    def a(x):
        return x.reshape(shape)

    d01 = (f1 - f0) / a(t1 - t0)
    d12 = (f2 - f1) / a(t2 - t1)
    d012 = (d12 - d01) / a(t2 - t0)
    x0, x1 = a(c - t0), a(c - t1)
    c0 = f0 + d01 * x0 + d012 * x0 * x1
    c1 = d01 + d012 * (x0 + x1)
    c2 = d012
    return np.stack([c0, c1, c2], axis=1)


@dataclass(frozen=True)
class StationModel:
    """A station fixed on the Earth, seen from the quasi-inertial frame of a trajectory.

    ``r_st(t) = P(t) R3(theta(t))^T p(t)`` (module docstring); times ``t_s`` are SI seconds
    from ``epoch_jd_utc`` (the trajectory's epoch). Build with :meth:`build`.

    Attributes: ``r_itrf_m`` (3,), ``lat_rad``/``lon_rad`` (geodetic, for east-north-up),
    ``q_ref`` (GCRF -> quasi-inertial), ``frozen``, ``era0_rad``/``omega_rad_s`` (the angle
    at t = 0 and its rate), ``nodes_s`` with ``pn_nodes`` (K, 3, 3) = ``q_ref Q(t)^T``,
    ``p_nodes`` (K, 3) = ``W(t)^T r_itrf`` and ``w_nodes`` (K, 3, 3) = ``W(t)``.

    Implements seed 004 eqs. 7-10 (station and topocentric frame as spectra).
    """

    r_itrf_m: np.ndarray
    lat_rad: float
    lon_rad: float
    epoch_jd_utc: tuple
    q_ref: np.ndarray
    frozen: bool
    era0_rad: float
    omega_rad_s: float
    nodes_s: np.ndarray
    pn_nodes: np.ndarray
    p_nodes: np.ndarray
    w_nodes: np.ndarray
    eop: object = None

    @classmethod
    def build(cls, r_itrf_m, lat_rad: float, lon_rad: float, epoch_jd_utc: tuple, q_ref,
              t_lo_s: float, t_hi_s: float, *, eop=None, frozen: bool = False) -> StationModel:
        """Station model over ``[t_lo_s, t_hi_s]`` (s from the epoch; the slow rotation is
        tabulated there, with 60 s of margin, and extrapolated beyond)."""
        from trackproc.dynamics.frames import earth_rotation

        eop = eop or ts.EarthOrientation()
        r = np.asarray(r_itrf_m, float).reshape(3)
        lo, hi = float(t_lo_s) - _SLOW_PAD_S, float(t_hi_s) + _SLOW_PAD_S
        k = max(3, math.ceil((hi - lo) / SLOW_NODE_SPACING_S) + 1)
        nodes = np.linspace(lo, hi, k)
        j1, j2 = ts.add_seconds_utc(epoch_jd_utc, nodes)
        rot = earth_rotation(j1, j2, eop, rates=False)
        q_ref = np.asarray(q_ref, float)
        e1, e2 = ts.add_seconds_utc(epoch_jd_utc, np.array([0.0]))
        era0, omega0 = _era_rate(e1, e2, eop)
        if frozen:
            ref = earth_rotation(e1, e2, eop, rates=False)
            w = np.broadcast_to(ref.w[0], (k, 3, 3)).copy()
            pn = np.broadcast_to(q_ref @ ref.q[0].T, (k, 3, 3)).copy()
        else:
            w = np.asarray(rot.w)
            pn = q_ref @ np.swapaxes(np.asarray(rot.q), -1, -2)
        p = np.einsum("kji,j->ki", w, r)
        return cls(r_itrf_m=r, lat_rad=float(lat_rad), lon_rad=float(lon_rad),
                   epoch_jd_utc=tuple(epoch_jd_utc), q_ref=q_ref, frozen=bool(frozen),
                   era0_rad=float(era0[0]), omega_rad_s=float(omega0[0]), nodes_s=nodes,
                   pn_nodes=pn, p_nodes=p, w_nodes=w, eop=eop)

    def angle(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """``theta`` (rad) and ``omega`` (rad/s) at ``t_s``: the exact ERA and its rate, or
        ``era0 + omega t`` when frozen."""
        t = np.asarray(t_s, float)
        if self.frozen:
            return self.era0_rad + self.omega_rad_s * t, np.full(t.shape, self.omega_rad_s)
        j1, j2 = ts.add_seconds_utc(self.epoch_jd_utc, t)
        era, rate = _era_rate(j1, j2, self.eop)
        return era.reshape(t.shape), rate.reshape(t.shape)

    def _slow(self, c):
        """Per-centre quadratics of P (S, 3, 3, 3) [power, row, col] and p (S, 3, 3) [power, comp]."""
        if self.frozen:
            s = c.size
            pn = np.zeros((s, 3, 3, 3))
            pn[:, 0] = self.pn_nodes[0]
            p = np.zeros((s, 3, 3))
            p[:, 0] = self.p_nodes[0]
            return pn, p
        return (_quadratic_about(self.nodes_s, self.pn_nodes, c),
                _quadratic_about(self.nodes_s, self.p_nodes, c))

    def spectra(self, centres_s, n: int) -> np.ndarray:
        """Position spectra (S, 3, n) of the station about ``centres_s`` (quasi-inertial, m).

        Seed 004 eqs. 7-10 with eq. 9 in closed form (:func:`rotation_spectra`), times the
        slow precession-nutation and polar-motion polynomials.
        """
        c = np.atleast_1d(np.asarray(centres_s, float))
        theta, omega = self.angle(c)
        cs, sn = rotation_spectra(theta, omega, n)                     # (S, n)
        pn, p = self._slow(c)
        px = np.swapaxes(p, 1, 2)                                      # (S, comp, power)
        u = np.empty((c.size, 3, n))
        u[:, 0] = _times_poly(cs, px[:, 0]) - _times_poly(sn, px[:, 1])
        u[:, 1] = _times_poly(sn, px[:, 0]) + _times_poly(cs, px[:, 1])
        u[:, 2] = 0.0
        m = min(3, n)
        u[:, 2, :m] = px[:, 2, :m]
        out = np.einsum("sij,sjk->sik", pn[:, 0], u)
        out[..., 1:] += np.einsum("sij,sjk->sik", pn[:, 1], u[..., :-1])
        out[..., 2:] += np.einsum("sij,sjk->sik", pn[:, 2], u[..., :-2])
        return out

    def state(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """Station position (m) and velocity (m/s) in the quasi-inertial frame at ``t_s``."""
        t = np.atleast_1d(np.asarray(t_s, float))
        spec = self.spectra(t, 2)
        return spec[..., 0], spec[..., 1]

    def to_enu(self, d_qi, t_s, *, centres_s=None) -> np.ndarray:
        """East-north-up components (N, 3) of quasi-inertial vectors ``d_qi`` (N, 3) at ``t_s``.

        ``d_itrf = W R3(theta) P^T d``. With ``centres_s`` (N,), the angle is taken linear and
        the slow rotation quadratic about those points (as in the spectra; fewer ERFA calls).

        Implements seed 004 eq. 10.
        """
        from trackproc.dynamics import geodesy

        t = np.atleast_1d(np.asarray(t_s, float))
        if centres_s is None or self.frozen:
            theta, _ = self.angle(t)
            pn = self._slow(t)[0][:, 0]
            wq = self._w_quadratic(t)[:, 0]
        else:
            cu, inv = np.unique(np.asarray(centres_s, float), return_inverse=True)
            th_c, om_c = self.angle(cu)
            dt = t - cu[inv]
            theta = th_c[inv] + om_c[inv] * dt
            powers = np.stack([np.ones_like(dt), dt, dt * dt], axis=1)
            pn = np.einsum("sjab,sj->sab", self._slow(cu)[0][inv], powers)
            wq = np.einsum("sjab,sj->sab", self._w_quadratic(cu)[inv], powers)
        d_cirs = np.einsum("nji,nj->ni", pn, d_qi)                      # P^T d
        d_itrf = np.einsum("nij,nj->ni", wq, np.einsum("nij,nj->ni", _r3(theta), d_cirs))
        return np.einsum("ij,nj->ni", geodesy.enu_matrix(self.lat_rad, self.lon_rad), d_itrf)

    def _w_quadratic(self, c):
        if self.frozen:
            out = np.zeros((c.size, 3, 3, 3))
            out[:, 0] = self.w_nodes[0]
            return out
        return _quadratic_about(self.nodes_s, self.w_nodes, c)


# --------------------------------------------------------------------------- segments

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
    dmat = _derivative_matrix(n)
    w = np.asarray(half_width_s, float)
    wk = np.maximum(w, 1.0)[:, None] ** np.arange(n)
    eye = np.broadcast_to(np.eye(n), (s, n, n))
    rho = x_sat - station
    d = _sqrt(_cauchy_sum(rho, rho))
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
            d_new = _sqrt(_cauchy_sum(rho, rho))
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
        den = d + (_cauchy_sum(rho, v_sat) / c if light_time else 0.0)
        d_range = num @ product_matrix(_reciprocal(den))
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


def _initial_segments(t, step_idx, steps, station, tol, n):
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
    r = _evaluate(coef, dt)
    v = _evaluate(coef, dt, 1)
    r_st, v_st = _approx_station(station, tp)
    radius = np.linalg.norm(r - r_st, axis=-1) / np.maximum(np.linalg.norm(v - v_st, axis=-1), 1.0)
    kappa = _SEGMENT_SAFETY * tol ** (1.0 / n)
    width = 2.0 * kappa * np.interp(t, tp, radius)
    gap = np.diff(t) / np.minimum(width[1:], width[:-1])
    budget = np.concatenate([[0.0], np.cumsum(gap)])
    seg = np.floor(budget).astype(np.int64)
    new = np.concatenate([[True], (np.diff(seg) != 0) | (np.diff(step_idx) != 0)])
    return np.cumsum(new) - 1


def _approx_station(station, t):
    """Station position and velocity from the frozen rotation (for segment sizing only)."""
    theta = station.era0_rad + station.omega_rad_s * t
    r = np.einsum("nji,j->ni", _r3(theta), station.p_nodes[0]) @ station.pn_nodes[0].T
    v = station.omega_rad_s * np.stack([-r[:, 1], r[:, 0], np.zeros_like(t)], -1)
    return r, v


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
    seg_of = _initial_segments(t, step_idx, steps, station, tol, n)

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
        return _evaluate_segments(spec, bounds, vander)

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
