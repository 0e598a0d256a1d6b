"""The ground station in the image domain (seed 004 eqs. 7-10): rotation spectra and :class:`StationModel`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import erfa
import numpy as np

from trackproc.dynamics import geodesy
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.frames import earth_rotation, era_rate_si, rotation_z


#: Spacing of the nodes of the slow rotation (precession-nutation, polar motion), s.
SLOW_NODE_SPACING_S = 1800.0
#: Margin of the slow-rotation nodes beyond the requested interval, s.
_SLOW_PAD_S = 60.0


def rotation_spectra(theta_rad, omega_rad_s, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Spectra of ``cos`` and ``sin`` of the linear angle ``theta + omega tau``, shape (..., n).

    ``C(K) = cos(theta + K pi/2) omega^K / K!``, ``S(K) = sin(theta + K pi/2) omega^K / K!``:
    the closed-form solution of the seed 004 eq. 9 recurrence (``sin(K+1) = sum (l+1)/(K+1)
    S(l+1) cos(K-l)``, ...) when the angle's spectrum is ``(theta, omega, 0, ...)``, i.e. the
    sidereal angle of seed 004 eq. 7 with ``omega = q Omega``.

    >>> import numpy as np
    >>> from trackproc.dynamics import geodesy
    >>> from trackproc.dynamics import spectra as sp
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
    tabulated EOP, :func:`~trackproc.dynamics.frames.era_rate_si`)."""
    dut1, _, _ = eop.at(jd1, jd2)
    u1, u2 = ts.utc_to_ut1(jd1, jd2, dut1)
    era = np.asarray(erfa.era00(u1, u2), float)
    return era, era_rate_si(jd1, jd2, eop)


def _frozen_arrays(arrays: tuple) -> tuple:
    """``arrays`` made read-only: they are kept (:meth:`StationModel._kept`) and shared."""
    for a in arrays:
        a.flags.writeable = False
    return arrays


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
    #: what depends on the sample times only, kept for the next model evaluation (:meth:`_kept`)
    _memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def _kept(self, key, make):
        """``make()``, kept under ``key`` for the next calls (the last 32): a refinement evaluates
        the model at the same sample times and segment centres on every iteration, and the
        station's rotation there (ERFA's angle, the slow quadratics) does not depend on the orbit."""
        memo = self._memo
        got = memo.get(key)
        if got is None:
            got = make()
            if len(memo) >= 32:
                memo.pop(next(iter(memo)))
            memo[key] = got
        return got

    @classmethod
    def build(cls, r_itrf_m, lat_rad: float, lon_rad: float, epoch_jd_utc: tuple, q_ref,
              t_lo_s: float, t_hi_s: float, *, eop=None, frozen: bool = False) -> StationModel:
        """Station model over ``[t_lo_s, t_hi_s]`` (s from the epoch; the slow rotation is
        tabulated there, with 60 s of margin, and extrapolated beyond)."""
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
        # kept: :meth:`spectra` and :meth:`to_enu` ask for the same centres within one prediction
        return self._kept(("angle", t.tobytes(), t.shape), lambda: _frozen_arrays(self._angle(t)))

    def _angle(self, t):
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
        return self._kept(("slow", c.tobytes(), c.shape), lambda: _frozen_arrays(
            (_quadratic_about(self.nodes_s, self.pn_nodes, c), _quadratic_about(self.nodes_s, self.p_nodes, c))))

    def spectra(self, centres_s, n: int) -> np.ndarray:
        """Position spectra (S, 3, n) of the station about ``centres_s`` (quasi-inertial, m).

        Seed 004 eqs. 7-10 with eq. 9 in closed form (:func:`rotation_spectra`), times the
        slow precession-nutation and polar-motion polynomials.
        """
        c = np.atleast_1d(np.asarray(centres_s, float))
        return self._kept(("spectra", c.tobytes(), c.shape, int(n)), lambda: self._spectra(c, n)).copy()

    def _spectra(self, c, n: int) -> np.ndarray:
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
        t = np.atleast_1d(np.asarray(t_s, float))
        plain = centres_s is None or self.frozen
        cen = None if plain else np.asarray(centres_s, float)
        key = ("enu", t.tobytes(), t.shape, None if plain else (cen.tobytes(), cen.shape))
        pn, wq, rz = self._kept(key, lambda: self._enu_rotations(t, cen))
        d_cirs = np.einsum("nji,nj->ni", pn, d_qi)                      # P^T d
        d_itrf = np.einsum("nij,nj->ni", wq, np.einsum("nij,nj->ni", rz, d_cirs))
        return np.einsum("ij,nj->ni", geodesy.enu_matrix(self.lat_rad, self.lon_rad), d_itrf)

    def _enu_rotations(self, t, centres):
        """``P``, ``W`` and ``R3(theta)`` (N, 3, 3) at ``t`` for :meth:`to_enu` (about ``centres``
        when given)."""
        if centres is None:
            theta, _ = self.angle(t)
            pn = self._slow(t)[0][:, 0]
            wq = self._w_quadratic(t)[:, 0]
        else:
            cu, inv = np.unique(centres, return_inverse=True)
            th_c, om_c = self.angle(cu)
            dt = t - cu[inv]
            theta = th_c[inv] + om_c[inv] * dt
            powers = np.stack([np.ones_like(dt), dt, dt * dt], axis=1)
            pn = np.einsum("sjab,sj->sab", self._slow(cu)[0][inv], powers)
            wq = np.einsum("sjab,sj->sab", self._w_quadratic(cu)[inv], powers)
        return pn, wq, rotation_z(theta)

    def _w_quadratic(self, c):
        if self.frozen:
            out = np.zeros((c.size, 3, 3, 3))
            out[:, 0] = self.w_nodes[0]
            return out
        return _quadratic_about(self.nodes_s, self.w_nodes, c)
