"""Reference frames: GCRF <-> ITRF (IAU 2006/2000A, CIO based, via ERFA), EME2000, TEME,
and the quasi-inertial frame used inside the propagator.

Conventions: rotation matrices act on column vectors, ``r_to = M @ r_from``; arrays of
vectors have shape ``(N, 3)`` and matrices ``(N, 3, 3)``. Times are UTC two-part JDs.

GCRF -> ITRF is ``W(xp, yp, s') · R3(ERA(UT1)) · Q(TT)`` where ``Q`` is the GCRS->CIRS
matrix (bias, precession, nutation and the CIO locator, ``erfa.c2i06a``), ``R3(ERA)`` the
Earth rotation and ``W`` polar motion (``erfa.pom00``). Velocities are the exact time
derivative of the position transform: the ``-ω × r`` term of the Earth rotation (``ω`` the
rate of the Earth Rotation Angle per SI second, including the UT1 rate of a tabulated EOP,
i.e. the length-of-day excess) plus the slow rates ``dQ/dt`` and ``dW/dt`` of
precession-nutation and polar motion. Those slow terms are small (of order 1e-5 m/s at the
Earth's surface: 1.1e-5 m/s for a station on 2026-03-20, 1.7e-5 m/s with a 1.5 ms
length-of-day excess) but a range-rate model checked against a numerical derivative of the
light-time range at 1e-6 m/s needs them.
"""

from __future__ import annotations

from dataclasses import dataclass

import erfa
import numpy as np

from trackproc.dynamics import timescales as ts

#: Rate of the Earth Rotation Angle, rad per UT1 second (IERS Conventions 2010 eq. 5.15).
OMEGA_ERA = 2.0 * np.pi * 1.00273781191135448 / ts.DAY_S


def _r3(angle) -> np.ndarray:
    """Frame rotation about z by ``angle`` (ERFA ``rz`` convention), shape (..., 3, 3)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(np.shape(c) + (3, 3), dtype=np.result_type(c))   # filled in place: nested np.stack
    out[..., 0, 0] = c                                                # cost 4x more on small arrays
    out[..., 0, 1] = s
    out[..., 1, 0] = -s
    out[..., 1, 1] = c
    out[..., 2, 2] = 1.0
    return out


rotation_z = _r3   # the public name (dynamics.measurement_spectra rotates the station with it)


def _omega_cross(r, omega=OMEGA_ERA) -> np.ndarray:
    """``ω ẑ × r`` for the Earth Rotation Angle rate ``omega`` (rad/s, scalar or per date)."""
    r = np.asarray(r, float)
    omega = np.asarray(omega, float)[..., None]
    return omega * np.stack([-r[..., 1], r[..., 0], np.zeros_like(r[..., 0])], -1)


def _mv(m, v):
    return np.einsum("...ij,...j->...i", m, v)


def _mtv(m, v):
    return np.einsum("...ji,...j->...i", m, v)


@dataclass(frozen=True)
class EarthRotation:
    """The three factors of GCRF -> ITRF at a set of UTC dates (all arrays along the dates),
    and their rates per SI second (for velocities)."""

    q: np.ndarray      # GCRS -> CIRS (bias-precession-nutation), (N, 3, 3)
    era: np.ndarray    # Earth Rotation Angle, rad, (N,)
    w: np.ndarray      # TIRS -> ITRS (polar motion), (N, 3, 3)
    q_dot: np.ndarray | None = None     # dQ/dt, 1/s, (N, 3, 3)
    era_rate: np.ndarray | None = None  # dERA/dt, rad/s, (N,)
    w_dot: np.ndarray | None = None     # dW/dt, 1/s, (N, 3, 3)

    @property
    def matrix(self) -> np.ndarray:
        """Full GCRF -> ITRF rotation, (N, 3, 3)."""
        return self.w @ _r3(self.era) @ self.q

    @property
    def omega(self) -> np.ndarray:
        """Earth Rotation Angle rate per SI second (OMEGA_ERA when no rates were computed)."""
        return self.era_rate if self.era_rate is not None else np.full(np.shape(self.era), OMEGA_ERA)


#: Spacing of the grid on which Q (GCRS -> CIRS) is evaluated and interpolated, days.
_Q_NODE_D = 1.0 / 48.0
#: Half-width of the central differences of polar motion and UT1 (s).
_RATE_DELTA_S = 60.0
#: Q at grid nodes, by node number (half hours since J2000 TT); shared by every call in the process
#: (a batch worker keeps it warm across passes). Bounded: cleared beyond _Q_CACHE_MAX nodes.
_Q_NODES: dict[int, np.ndarray] = {}
_Q_CACHE_MAX = 200_000
#: Node spans (a day) read by offset from the first node rather than sorted by np.unique.
_Q_SPAN_NODES = 48


def _q_at_nodes(nodes: np.ndarray) -> np.ndarray:
    """``erfa.c2i06a`` at grid nodes (node numbers, int array), (len(nodes), 3, 3), from the cache."""
    lo, hi = int(nodes.min()), int(nodes.max())
    if hi - lo < _Q_SPAN_NODES:
        # a pass or a day: every node of the span is asked for (4 a date, consecutive), so the span
        # is the distinct nodes and the offset their index, without np.unique's sort (~0.1 ms a pass)
        uniq, inverse = np.arange(lo, hi + 1), nodes - lo
    else:
        uniq, inverse = np.unique(nodes, return_inverse=True)
    missing = [int(i) for i in uniq if int(i) not in _Q_NODES]
    if missing:
        if len(_Q_NODES) + len(missing) > _Q_CACHE_MAX:
            _Q_NODES.clear()
        values = np.asarray(erfa.c2i06a(2451545.0, np.asarray(missing, float) * _Q_NODE_D))
        _Q_NODES.update(zip(missing, values))
    return np.stack([_Q_NODES[int(i)] for i in uniq])[inverse.reshape(nodes.shape)]


def precession_nutation(tt1, tt2, rates: bool = True):
    """GCRS -> CIRS matrix Q (bias, precession, nutation, CIO locator; ``erfa.c2i06a``) at TT
    two-part JDs, and its rate dQ/dt per SI second (None without ``rates``).

    Q varies on time scales of days (its fastest sizeable nutation term has a period of 13.66 d),
    so ``c2i06a`` (the full IAU 2000A series, ~30 us a date) is evaluated on a 30-minute grid and
    interpolated by the 4-point Lagrange cubic; dQ/dt is that cubic's derivative. Against the
    direct evaluation over 2019-2027: |dQ| < 1e-15 (rounding; 3e-9 m at 7000 km) and dQ/dt
    within 6e-7 relative (tests/io/test_frames_grid.py). The result does not depend on which
    other dates are asked for in the same call or earlier (nodes are fixed in TT).

    Implements seed 004 eq. 7 in general form (IAU 2006/2000A precession-nutation).
    """
    t = (np.asarray(tt1, float) - 2451545.0) + np.asarray(tt2, float)
    x = t / _Q_NODE_D
    i0 = np.floor(x)
    u = (x - i0)[..., None, None]
    nodes = _q_at_nodes(i0.astype(np.int64)[..., None] + np.arange(-1, 3))     # (..., 4, 3, 3)
    qm, q0, q1, q2 = (nodes[..., k, :, :] for k in range(4))
    up, um, um2 = u + 1.0, u - 1.0, u - 2.0
    q = (-(u * um * um2) / 6.0) * qm + (up * um * um2 / 2.0) * q0 \
        - (up * u * um2 / 2.0) * q1 + (up * u * um / 6.0) * q2
    if not rates:
        return q, None
    uu = u * u
    q_dot = (-(3.0 * uu - 6.0 * u + 2.0) / 6.0) * qm + ((3.0 * uu - 4.0 * u - 1.0) / 2.0) * q0 \
        - ((3.0 * uu - 2.0 * u - 2.0) / 2.0) * q1 + ((3.0 * uu - 1.0) / 6.0) * q2
    return q, q_dot / (_Q_NODE_D * ts.DAY_S)


def earth_rotation(jd1, jd2, eop: ts.EarthOrientation | None = None, rates: bool = True) -> EarthRotation:
    """Earth orientation factors at UTC two-part JDs (IAU 2006/2000A, CIO based).

    Q comes from :func:`precession_nutation` (30-minute grid, interpolated). With ``rates`` (the
    default) also their time derivatives per SI second: ``dQ/dt`` (the interpolant's), the ERA rate ``OMEGA_ERA * (1 + d(UT1-TAI)/dt)`` (the UT1 rate of a
    tabulated EOP; zero excess for a constant UT1-UTC) and ``dW/dt`` by central differences
    of polar motion and s' over ±60 s.

    Implements seed 004 eq. 7 in general form (IAU 2006/2000A, UT1, polar motion).
    """
    eop = eop or ts.EarthOrientation()
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    tt1, tt2 = ts.utc_to_tt(jd1, jd2)
    dut1, xp, yp = eop.at(jd1, jd2)
    u1, u2 = ts.utc_to_ut1(jd1, jd2, dut1)
    q, q_dot = precession_nutation(tt1, tt2, rates)
    era = erfa.era00(u1, u2)
    w = erfa.pom00(xp, yp, erfa.sp00(tt1, tt2))
    if not rates:
        return EarthRotation(q=q, era=np.asarray(era), w=np.asarray(w))
    d = _RATE_DELTA_S / ts.DAY_S
    _, xpp, ypp = eop.at(jd1, jd2 + d)
    _, xpm, ypm = eop.at(jd1, jd2 - d)
    w_dot = (np.asarray(erfa.pom00(xpp, ypp, erfa.sp00(tt1, tt2 + d)))
             - np.asarray(erfa.pom00(xpm, ypm, erfa.sp00(tt1, tt2 - d)))) / (2.0 * _RATE_DELTA_S)
    era_rate = era_rate_si(jd1, jd2, eop)
    return EarthRotation(q=q, era=np.asarray(era), w=np.asarray(w),
                         q_dot=q_dot, era_rate=era_rate, w_dot=w_dot)


def gcrf_to_itrf(r, v, jd1, jd2, eop=None, *, rotation: EarthRotation | None = None):
    """Position (m) and velocity (m/s) from GCRF to ITRF at UTC two-part JDs.

    ``r``, ``v`` have shape (N, 3) for N dates, (3,) for one, or (..., N, 3) to transform
    several points (e.g. stations) at the same N dates. ``rotation`` (from
    :func:`earth_rotation` at these dates, with rates) saves recomputing it.

    Implements seed 004 eq. 7 (inertial -> Greenwich) in general form.
    """
    rot = rotation if rotation is not None else earth_rotation(jd1, jd2, eop)
    r, v = np.atleast_2d(r), np.atleast_2d(v)
    r3 = _r3(rot.era)
    r_cirs = _mv(rot.q, r)
    v_cirs = _mv(rot.q, v) + _mv(rot.q_dot, r)
    r_tirs = _mv(r3, r_cirs)
    v_tirs = _mv(r3, v_cirs) - _omega_cross(r_tirs, rot.omega)
    return _mv(rot.w, r_tirs), _mv(rot.w, v_tirs) + _mv(rot.w_dot, r_tirs)


def itrf_to_gcrf(r, v, jd1, jd2, eop=None, *, rotation: EarthRotation | None = None):
    """Position (m) and velocity (m/s) from ITRF to GCRF at UTC two-part JDs (shapes as
    :func:`gcrf_to_itrf`).

    Implements seed 004 eq. 7 (Greenwich -> inertial) in general form.
    """
    rot = rotation if rotation is not None else earth_rotation(jd1, jd2, eop)
    r, v = np.atleast_2d(r), np.atleast_2d(v)
    r3 = _r3(rot.era)
    r_tirs = _mtv(rot.w, r)
    v_tirs = _mtv(rot.w, v - _mv(rot.w_dot, r_tirs))
    r_cirs = _mtv(r3, r_tirs)
    v_cirs = _mtv(r3, v_tirs + _omega_cross(r_tirs, rot.omega))
    r_gcrf = _mtv(rot.q, r_cirs)
    return r_gcrf, _mtv(rot.q, v_cirs - _mv(rot.q_dot, r_gcrf))


def frame_bias_matrix() -> np.ndarray:
    """GCRS -> mean J2000 (EME2000) frame bias, IAU 2006 (``erfa.bp06`` rb, time independent)."""
    rb, _, _ = erfa.bp06(2451545.0, 0.0)
    return np.asarray(rb)


def eme2000_to_gcrf(r, v):
    """EME2000 (mean equator and equinox of J2000) -> GCRF: the frame bias (~23 mas)."""
    rb = frame_bias_matrix()
    return _mtv(rb, np.atleast_2d(r)), _mtv(rb, np.atleast_2d(v))


def gcrf_to_eme2000(r, v):
    rb = frame_bias_matrix()
    return _mv(rb, np.atleast_2d(r)), _mv(rb, np.atleast_2d(v))


def teme_to_itrf(r, v, jd1, jd2, eop=None):
    """TEME (the frame of SGP4 output) -> ITRF: GMST 1982 about z, then polar motion.

    Vallado et al. 2006, "Revisiting Spacetrack Report #3", AIAA 2006-6753, eqs. for TEME -> PEF.
    """
    eop = eop or ts.EarthOrientation()
    jd1, jd2 = np.broadcast_arrays(np.atleast_1d(np.asarray(jd1, float)), np.atleast_1d(np.asarray(jd2, float)))
    dut1, xp, yp = eop.at(jd1, jd2)
    u1, u2 = ts.utc_to_ut1(jd1, jd2, dut1)
    gmst = erfa.gmst82(u1, u2)
    r_pef = _mv(_r3(gmst), np.atleast_2d(r))
    v_pef = _mv(_r3(gmst), np.atleast_2d(v)) - _omega_cross(r_pef)
    w = np.asarray(erfa.pom00(xp, yp, np.zeros_like(xp)))
    return _mv(w, r_pef), _mv(w, v_pef)


def teme_to_gcrf(r, v, jd1, jd2, eop=None):
    r_itrf, v_itrf = teme_to_itrf(r, v, jd1, jd2, eop)
    return itrf_to_gcrf(r_itrf, v_itrf, jd1, jd2, eop)


def to_gcrf(frame: str, r, v, jd1, jd2, eop=None):
    """Convert a state given in ``frame`` (GCRF, EME2000/J2000, TEME, ITRF) to GCRF."""
    key = frame.strip().upper().replace("-", "").replace("_", "")
    if key in ("GCRF", "GCRS", "ICRF"):
        return np.atleast_2d(np.asarray(r, float)), np.atleast_2d(np.asarray(v, float))
    if key in ("EME2000", "J2000"):
        return eme2000_to_gcrf(r, v)
    if key == "TEME":
        return teme_to_gcrf(r, v, jd1, jd2, eop)
    if key in ("ITRF", "ITRS", "ECEF", "ECF"):
        return itrf_to_gcrf(r, v, jd1, jd2, eop)
    raise ValueError(f"unknown frame {frame!r}; expected GCRF, EME2000, TEME or ITRF")


SUPPORTED_FRAMES = ("GCRF", "EME2000", "TEME", "ITRF")


@dataclass(frozen=True)
class QuasiInertialFrame:
    """The propagator's frame: GCRF rotated by the precession-nutation matrix of a reference epoch.

    In it the Earth's rotation axis is z (so J2 acts about z) and ITRF is reached by a plain
    rotation through the Earth Rotation Angle, linear in time: ``ERA(t) = era0 + ω t`` with t
    in SI seconds from the reference epoch (README "Units, sign conventions, time and frames"). Precession-nutation and polar
    motion are frozen at the reference epoch: choose it mid-pass; the frozen terms drift by
    about 0.15 arcsec a day (about 5 m at LEO radius after a day, < 1 cm over a 15-minute pass).

    Implements seed 004 eq. 7 (the sidereal angle ``S = q Ω t + S0``) in its exact form: ERA linear in SI time.
    """

    ref_jd_utc: tuple
    q: np.ndarray       # GCRF -> quasi-inertial, (3, 3)
    w: np.ndarray       # polar motion at the reference epoch, (3, 3)
    era0: float         # ERA at the reference epoch, rad
    omega: float = OMEGA_ERA

    @classmethod
    def at(cls, jd1: float, jd2: float, eop=None) -> "QuasiInertialFrame":
        rot = earth_rotation(jd1, jd2, eop, rates=False)
        return cls(ref_jd_utc=(float(np.ravel(jd1)[0]), float(np.ravel(jd2)[0])),
                   q=rot.q[0], w=rot.w[0], era0=float(rot.era[0]))

    def era(self, t_s):
        """Earth Rotation Angle (rad) at ``t_s`` seconds after the reference epoch."""
        return self.era0 + self.omega * np.asarray(t_s, float)

    def from_gcrf(self, r, v):
        return _mv(self.q, np.asarray(r, float)), _mv(self.q, np.asarray(v, float))

    def to_gcrf(self, r, v):
        return _mtv(self.q, np.asarray(r, float)), _mtv(self.q, np.asarray(v, float))

    def to_itrf(self, t_s, r, v):
        """Quasi-inertial -> ITRF at ``t_s`` seconds after the reference epoch."""
        rot = _r3(self.era(t_s))
        r_t = _mv(rot, np.asarray(r, float))
        v_t = _mv(rot, np.asarray(v, float)) - _omega_cross(r_t) * (self.omega / OMEGA_ERA)
        return _mv(self.w, r_t), _mv(self.w, v_t)

    def station(self, t_s, r_itrf):
        """Station position (m) and velocity (m/s) in this frame at ``t_s`` seconds after the epoch."""
        t_s = np.asarray(t_s, float)
        r_tirs = _mtv(self.w, np.asarray(r_itrf, float))
        r = _mtv(_r3(self.era(t_s)), np.broadcast_to(r_tirs, t_s.shape + (3,)))
        return r, _omega_cross(r) * (self.omega / OMEGA_ERA)


def era_rate_si(jd1, jd2, eop) -> np.ndarray:
    """Earth Rotation Angle rate (rad per SI second) at UTC two-part JDs: ``OMEGA_ERA`` times
    ``1 + d(UT1 - TAI)/dt`` of a tabulated EOP (central differences over ±60 s), else ``OMEGA_ERA``.
    The one home of the ERA rate (:func:`earth_rotation`, the image-domain station model)."""
    jd1, jd2 = np.asarray(jd1, float), np.asarray(jd2, float)
    if not eop.tabulated:
        return np.full(np.broadcast(jd1, jd2).shape, OMEGA_ERA)
    d = _RATE_DELTA_S / ts.DAY_S
    mjd = jd1 - 2400000.5 + jd2
    ut1_tai = [np.interp(mjd + k * d, eop.mjd, eop.ut1_minus_tai_s) for k in (1, -1)]
    return OMEGA_ERA * (1.0 + (ut1_tai[0] - ut1_tai[1]) / (2.0 * _RATE_DELTA_S))
