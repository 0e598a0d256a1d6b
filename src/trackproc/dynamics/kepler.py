"""Analytic two-body propagation by universal variables (any conic, forward or backward).

The reference solution for the Taylor integrator's tests and for the simulator. Pure
functions on numpy arrays, SI units.

Method: Bate, Mueller & White (1971) ch. 4 and Vallado (2013) algorithm 8 ("KEPLER"), with
the Stumpff functions c2(z), c3(z) (z = alpha chi^2, alpha = 2/r0 - v0^2/mu) and Conway's
(1986) Laguerre iteration for the universal anomaly chi, which converges for every conic
from a crude start. Elliptic times are first reduced modulo the period so that many
revolutions do not cost accuracy.
"""

from __future__ import annotations

import math

import numpy as np

from trackproc.constants import MU_EARTH
from trackproc.errors import ProcessingError

__all__ = ["stumpff", "universal_anomaly", "propagate", "specific_energy", "classical_elements",
           "angular_momentum", "period"]

# |z| below which c2, c3 come from their Taylor series (the closed forms cancel near 0).
_Z_SERIES = 10.0
_N_SERIES = 24
_C2_TERMS = np.array([(-1.0) ** k / math.factorial(2 * k + 2) for k in range(_N_SERIES)])
_C3_TERMS = np.array([(-1.0) ** k / math.factorial(2 * k + 3) for k in range(_N_SERIES)])


def stumpff(z) -> tuple[np.ndarray, np.ndarray]:
    """Stumpff functions ``c2(z) = (1 - cos sqrt z)/z`` and ``c3(z) = (sqrt z - sin sqrt z)/z^1.5``.

    Continued to z <= 0 by cosh/sinh (hyperbolic orbits) and through z = 0 (parabolic:
    c2 = 1/2, c3 = 1/6). Accurate to a few ulp everywhere: series for |z| < 10, the
    half-angle forms ``2 sin^2(sqrt(z)/2) / z`` elsewhere.
    """
    z = np.asarray(z, dtype=float)
    c2 = np.empty_like(z)
    c3 = np.empty_like(z)
    small = np.abs(z) < _Z_SERIES
    pos = z >= _Z_SERIES
    neg = z <= -_Z_SERIES
    if np.any(small):
        zs = z[small]
        a2 = np.full_like(zs, _C2_TERMS[-1])
        a3 = np.full_like(zs, _C3_TERMS[-1])
        for k in range(_N_SERIES - 2, -1, -1):
            a2 = a2 * zs + _C2_TERMS[k]
            a3 = a3 * zs + _C3_TERMS[k]
        c2[small], c3[small] = a2, a3
    if np.any(pos):
        zp = z[pos]
        s = np.sqrt(zp)
        c2[pos] = 2.0 * np.sin(0.5 * s) ** 2 / zp
        c3[pos] = (s - np.sin(s)) / (zp * s)
    if np.any(neg):
        zn = -z[neg]
        s = np.sqrt(zn)
        c2[neg] = 2.0 * np.sinh(0.5 * s) ** 2 / zn
        c3[neg] = (np.sinh(s) - s) / (zn * s)
    return c2, c3


def specific_energy(state, mu_m3_s2: float = MU_EARTH) -> np.ndarray:
    """Specific orbital energy ``v^2/2 - mu/r`` (J/kg) of states shaped ``(..., 6)``."""
    s = np.asarray(state, dtype=float)
    return 0.5 * np.sum(s[..., 3:] ** 2, -1) - mu_m3_s2 / np.linalg.norm(s[..., :3], axis=-1)


def angular_momentum(state) -> np.ndarray:
    """Specific angular momentum ``r x v`` (m^2/s) of states shaped ``(..., 6)``."""
    s = np.asarray(state, dtype=float)
    return np.cross(s[..., :3], s[..., 3:])


def period(state, mu_m3_s2: float = MU_EARTH) -> np.ndarray:
    """Orbital period ``2 pi sqrt(a^3/mu)`` (s); inf for parabolic and hyperbolic states."""
    s = np.asarray(state, dtype=float)
    alpha = 2.0 / np.linalg.norm(s[..., :3], axis=-1) - np.sum(s[..., 3:] ** 2, -1) / mu_m3_s2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(alpha > 0, 2.0 * np.pi / np.sqrt(mu_m3_s2 * np.abs(alpha) ** 3), np.inf)


def universal_anomaly(r0_m, sigma0_m, alpha_1_m, dt_s, mu_m3_s2: float = MU_EARTH,
                      max_iter: int = 60) -> np.ndarray:
    """Solve the universal Kepler equation for chi (m^0.5), elementwise over broadcast inputs.

    ``sqrt(mu) dt = sigma0 chi^2 c2(z) + (1 - alpha r0) chi^3 c3(z) + r0 chi``, z = alpha chi^2,
    sigma0 = r0.v0 / sqrt(mu) (Bate, Mueller & White eq. 4.4-14; Vallado alg. 8). Laguerre
    iteration (Conway 1986, n = 5) from Vallado's starting values, until the relative change
    is below 4 ulp or the residual is at the rounding level of its terms. Raises :class:`ProcessingError` if any element does not converge.
    """
    r0, sig, alpha, dt = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                               for x in (r0_m, sigma0_m, alpha_1_m, dt_s)))
    smu = math.sqrt(mu_m3_s2)
    # Starting values (Vallado alg. 8).
    chi = np.where(alpha > 0, smu * dt * alpha, smu * dt / np.maximum(r0, 1.0))
    hyp = alpha < -1e-12 / np.maximum(r0, 1.0)
    if np.any(hyp):
        a = 1.0 / alpha[hyp]
        s = np.sign(dt[hyp])
        with np.errstate(invalid="ignore", divide="ignore"):
            arg = (-2.0 * mu_m3_s2 * alpha[hyp] * dt[hyp]) / (
                sig[hyp] * smu + s * np.sqrt(-mu_m3_s2 * a) * (1.0 - r0[hyp] * alpha[hyp]))
            guess = s * np.sqrt(-a) * np.log(arg)
        chi[hyp] = np.where(np.isfinite(guess) & (arg > 0), guess, chi[hyp])
    n = 5.0
    done = np.zeros(chi.shape, dtype=bool)
    target = smu * dt
    for _ in range(max_iter):
        z = alpha * chi * chi
        c2, c3 = stumpff(z)
        t1 = sig * chi * chi * c2
        t2 = (1.0 - alpha * r0) * chi ** 3 * c3
        f = t1 + t2 + r0 * chi - target
        # residual at the rounding level of its terms: chi cannot get better
        noise = 16.0 * np.finfo(float).eps * (np.abs(t1) + np.abs(t2) + np.abs(r0 * chi)
                                               + np.abs(target))
        fp = sig * chi * (1.0 - z * c3) + (1.0 - alpha * r0) * chi * chi * c2 + r0
        fpp = sig * (1.0 - z * c2) + (1.0 - alpha * r0) * chi * (1.0 - z * c3)
        disc = np.sqrt(np.abs((n - 1.0) ** 2 * fp * fp - n * (n - 1.0) * f * fpp))
        denom = fp + np.sign(fp) * disc
        step = np.where(denom != 0, n * f / np.where(denom != 0, denom, 1.0), 0.0)
        step = np.where(done, 0.0, step)
        chi = chi - step
        small = np.abs(step) <= 4.0 * np.finfo(float).eps * np.maximum(np.abs(chi), 1e-300)
        done = done | small | (step == 0) | (np.abs(f) <= noise)
        if np.all(done):
            break
    if not np.all(done) or not np.all(np.isfinite(chi)):
        bad = int(np.sum(~done | ~np.isfinite(chi)))
        raise ProcessingError(
            f"universal Kepler equation did not converge for {bad} time(s) in {max_iter} "
            f"iterations", {"not_converged": bad})
    return chi


def propagate(state0, dt_s, mu_m3_s2: float = MU_EARTH) -> np.ndarray:
    """Two-body states at times ``t0 + dt_s`` from the state at t0, by universal variables.

    Parameters
    ----------
    state0 : array ``(6,)`` or ``(B, 6)``
        Position (m) and velocity (m/s) at t0 in an inertial frame.
    dt_s : scalar or array ``(M,)``
        Times since t0, s; negative values propagate backward.
    mu_m3_s2 : float
        Gravitational parameter, m^3/s^2.

    Returns
    -------
    array ``(6,)``, ``(M, 6)``, ``(B, 6)`` or ``(B, M, 6)``
        Following the shapes of ``state0`` and ``dt_s``.

    Notes
    -----
    Lagrange coefficients (Vallado alg. 8): ``f = 1 - chi^2 c2/r0``, ``g = dt - chi^3 c3/sqrt(mu)``,
    ``gdot = 1 - chi^2 c2/r``, ``fdot = sqrt(mu) chi (z c3 - 1)/(r r0)``. Any conic; elliptic
    times are reduced modulo the period first.
    """
    s0 = np.asarray(state0, dtype=float)
    if s0.shape[-1] != 6 or s0.ndim > 2:
        raise ValueError(f"state0 must have shape (6,) or (B, 6); found {s0.shape}")
    dt = np.asarray(dt_s, dtype=float)
    if dt.ndim > 1:
        raise ValueError(f"dt_s must be a scalar or 1-D; found shape {dt.shape}")
    r0v = s0[..., :3][..., None, :]                  # (..., 1, 3)
    v0v = s0[..., 3:][..., None, :]
    dtm = np.atleast_1d(dt)                           # (M,)
    r0 = np.linalg.norm(r0v, axis=-1)                 # (..., 1)
    v0sq = np.sum(v0v * v0v, axis=-1)
    smu = math.sqrt(mu_m3_s2)
    sig = np.sum(r0v * v0v, axis=-1) / smu
    alpha = 2.0 / r0 - v0sq / mu_m3_s2
    # Reduce elliptic times modulo the period.
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(alpha > 0, 2.0 * np.pi / np.sqrt(mu_m3_s2 * np.abs(alpha) ** 3), np.inf)
    dtb = np.broadcast_to(dtm, np.broadcast_shapes(per.shape, dtm.shape))
    red = np.where(np.isfinite(per), dtb - np.round(dtb / np.where(np.isfinite(per), per, 1.0))
                   * np.where(np.isfinite(per), per, 0.0), dtb)
    chi = universal_anomaly(r0, sig, alpha, red, mu_m3_s2)
    z = alpha * chi * chi
    c2, c3 = stumpff(z)
    chi2c2 = chi * chi * c2
    f = 1.0 - chi2c2 / r0
    g = red - chi ** 3 * c3 / smu
    r = r0v * f[..., None] + v0v * g[..., None]
    rn = np.linalg.norm(r, axis=-1)
    fdot = smu * chi * (z * c3 - 1.0) / (rn * r0)
    gdot = 1.0 - chi2c2 / rn
    v = r0v * fdot[..., None] + v0v * gdot[..., None]
    out = np.concatenate([r, v], axis=-1)
    if dt.ndim == 0:
        out = out[..., 0, :]
    return out


def classical_elements(r_m, v_m_s, mu_m3_s2: float = MU_EARTH) -> dict:
    """Osculating classical elements of one state (Vallado 2013, algorithm 9 "RV2COE").

    Returns a (semi-major axis, m; negative for a hyperbola), e, i, RAAN, argument of perigee,
    true, eccentric-free mean anomaly and argument of latitude u = omega + nu (well defined on a
    circular orbit, where omega and nu are not), angles in degrees for people, and the period.
    RAAN is undefined for an equatorial orbit and omega for a circular one: those are None.
    """
    r = np.asarray(r_m, float)
    v = np.asarray(v_m_s, float)
    rn, vn = float(np.linalg.norm(r)), float(np.linalg.norm(v))
    h = np.cross(r, v)
    hn = float(np.linalg.norm(h))
    node = np.cross([0.0, 0.0, 1.0], h)
    nn = float(np.linalg.norm(node))
    e_vec = ((vn * vn - mu_m3_s2 / rn) * r - float(r @ v) * v) / mu_m3_s2
    e = float(np.linalg.norm(e_vec))
    energy = vn * vn / 2.0 - mu_m3_s2 / rn
    a = -mu_m3_s2 / (2.0 * energy) if energy != 0.0 else math.inf
    inc = math.acos(max(-1.0, min(1.0, h[2] / hn)))
    tiny = 1e-11

    def angle(x, y, flip):
        value = math.acos(max(-1.0, min(1.0, x / y)))
        return 2.0 * math.pi - value if flip else value

    raan = angle(node[0], nn, node[1] < 0) if nn > tiny * hn else None
    argp = angle(float(node @ e_vec), nn * e, e_vec[2] < 0) if (raan is not None and e > tiny) else None
    nu = angle(float(e_vec @ r), e * rn, float(r @ v) < 0) if e > tiny else None
    if raan is not None:
        u = angle(float(node @ r), nn * rn, r[2] < 0)
    else:  # equatorial: the true longitude from the x axis
        u = angle(r[0], rn, (r[1] < 0) != (h[2] < 0))
    mean = None
    if nu is not None and e < 1.0:
        ecc_anom = 2.0 * math.atan2(math.sqrt(1.0 - e) * math.sin(nu / 2.0), math.sqrt(1.0 + e) * math.cos(nu / 2.0))
        mean = (ecc_anom - e * math.sin(ecc_anom)) % (2.0 * math.pi)
    deg = lambda x: None if x is None else math.degrees(x)  # noqa: E731
    return {"a_m": a, "e": e, "i_deg": deg(inc), "raan_deg": deg(raan), "argp_deg": deg(argp),
            "true_anomaly_deg": deg(nu), "mean_anomaly_deg": deg(mean), "arg_latitude_deg": deg(u),
            "period_s": 2.0 * math.pi * math.sqrt(a ** 3 / mu_m3_s2) if 0.0 < a < math.inf else None,
            "frame": "GCRF (osculating, two-body)"}
