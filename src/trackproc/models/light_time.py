"""The light-time solver, written once: the one-way (down) leg and the two-way up leg.

Used by the simulator (:mod:`trackproc.models.measurements`, the satellite by a Taylor
expansion about the reception time), the estimator (:mod:`trackproc.models.observation`, the
satellite from a dense trajectory) and the refinement (through the estimator). All vectors in
GCRF (m, m/s, s); every sample is time-tagged at **reception** ``t_r`` on the ground.

Down leg (README "Units, sign conventions, time and frames"): the signal received at ``t_r``
left the satellite at ``t_e = t_r - τ`` with

    c τ = ρ = |r_sat(t_r - τ) - r_st(t_r)|                                          (1)

solved by Newton's method on ``g(τ) = c τ - ρ(t_r - τ)``, ``g' = c + û·v_sat(t_e)``, to
``|Δτ| < 1e-12 s`` (0.3 mm). It is the light-time range that seed 004 eqs. 11-12 (and seed 002
eq. 17) write without light time.

Up leg (two-way, transponder turnaround ratio 1): the signal that reached the satellite at the
bounce time ``t_b = t_e`` left the same station at ``t_t = t_b - τ_u``; with ``T = τ_d + τ_u``
the round trip, the station is moved back from ``t_r`` with its GCRF velocity and centripetal
acceleration (the neglected jerk term is below 1e-8 m even for GEO round trips):

    R(T) = r_st - v_st T + a_st T²/2,   V(T) = v_st - a_st T
    c τ_u = ρ_u = |r_b - R(τ_d + τ_u)|                                              (2)

Newton on ``g(τ) = c τ - ρ_u``, ``g' = c - û_u·V``, from ``τ = τ_d``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from trackproc.constants import C_LIGHT

__all__ = ["LIGHT_TIME_TOL_S", "DownLeg", "UpLeg", "solve_down_leg", "station_back", "solve_up_leg"]

#: Convergence threshold of the light-time iterations, s.
LIGHT_TIME_TOL_S = 1e-12


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _norm(d):
    """``np.linalg.norm(d, axis=-1)`` of real vectors by the same operations (its vector case:
    square root of the sum of squares), without its dispatch: the light-time loop calls it often.

    For 3-vectors the sum of squares is written out, ``(x² + y²) + z²``: numpy's ``add.reduce``
    over a last axis of 3 adds the components in that order (the same bits,
    tests/models/test_light_time_norm.py), and the reduction over the short axis costs ~3.5x
    the three whole-column additions at a pass's samples."""
    p = d * d
    if p.shape[-1:] != (3,):
        return np.sqrt(np.add.reduce(p, axis=-1))
    return np.sqrt((p[..., 0] + p[..., 1]) + p[..., 2])


@dataclass(frozen=True)
class DownLeg:
    """Result of :func:`solve_down_leg` (arrays along the samples).

    ``tau_s`` light times, ``state`` (..., 6) the satellite's GCRF ``(r, v)`` at emission,
    ``rho_m`` ranges, ``u`` (..., 3) unit vectors from the station to the satellite,
    ``iterations`` Newton iterations taken.
    """

    tau_s: np.ndarray
    state: np.ndarray
    rho_m: np.ndarray
    u: np.ndarray
    iterations: int


def solve_down_leg(state_at: Callable[[np.ndarray], np.ndarray], r_st, tau0, *, c: float = C_LIGHT,
                   tol_s: float = LIGHT_TIME_TOL_S, max_iter: int = 10) -> DownLeg:
    """Emission of one-way signals received at ``r_st`` (..., 3): eq. (1) of the module docstring.

    ``state_at(tau)`` gives the satellite's GCRF state (..., 6) ``tau`` seconds before the
    reception times; ``tau0`` is the starting light time. Raises ``ArithmeticError`` if the
    iteration does not converge in ``max_iter`` steps.

    Implements the light-time range of seed 004 eqs. 11-12 and seed 002 eq. 17 (which omit the light time).
    """
    r_st = np.asarray(r_st, float)
    tau = np.asarray(tau0, float)
    for it in range(1, max_iter + 1):
        s = state_at(tau)
        d = s[..., :3] - r_st
        rho = _norm(d)
        u = d / rho[..., None]
        step = (c * tau - rho) / (c + _dot(u, s[..., 3:]))
        tau = tau - step
        if (np.abs(step) < tol_s).all():
            break
    else:
        raise ArithmeticError("light-time iteration did not converge")
    s = state_at(tau)
    d = s[..., :3] - r_st
    rho = _norm(d)
    return DownLeg(tau_s=tau, state=s, rho_m=rho, u=d / rho[..., None], iterations=it)


@dataclass(frozen=True)
class UpLeg:
    """Result of :func:`solve_up_leg` (arrays along the two-way samples).

    ``tau_s`` up-leg light times, ``rho_m`` up-leg ranges, ``u`` unit vectors from the station at
    ``t_t`` to the bounce point, ``r_st``/``v_st`` (..., 3) the station ``R(T)``, ``V(T)`` at
    ``t_t`` (eq. 2), ``iterations`` Newton iterations taken.
    """

    tau_s: np.ndarray
    rho_m: np.ndarray
    u: np.ndarray
    r_st: np.ndarray
    v_st: np.ndarray
    iterations: int


def station_back(r_st, v_st, a_st, big_t):
    """Station ``T`` seconds before ``t_r``: ``R = r - v T + a T²/2``, ``V = v - a T`` (eq. 2)."""
    t = np.asarray(big_t, float)[..., None]
    return r_st - v_st * t + a_st * (t * t / 2.0), v_st - a_st * t


def solve_up_leg(r_b, r_st, v_st, a_st, tau_down_s, *, c: float = C_LIGHT, tol_s: float = LIGHT_TIME_TOL_S,
                 max_iter: int = 10) -> UpLeg:
    """Up leg of two-way samples, eq. (2): the signal that reached the satellite at ``r_b``
    (..., 3) at the bounce time left the station ``τ_u`` earlier.

    ``r_st, v_st, a_st`` (..., 3): the station in GCRF at ``t_r``; ``tau_down_s`` the down leg's
    light time. Raises ``ArithmeticError`` if the iteration does not converge.

    Implements the two-way up leg (seed 004 item 1's two-way link).
    """
    r_b, r_st, v_st, a_st = (np.asarray(x, float) for x in (r_b, r_st, v_st, a_st))
    tau_d = np.asarray(tau_down_s, float)
    tau = tau_d.copy()
    for it in range(1, max_iter + 1):
        big_r, big_v = station_back(r_st, v_st, a_st, tau_d + tau)
        d = r_b - big_r
        rho = np.linalg.norm(d, axis=-1)
        step = (c * tau - rho) / (c - _dot(d / rho[..., None], big_v))
        tau = tau - step
        if (np.abs(step) < tol_s).all():
            break
    else:
        raise ArithmeticError("two-way up-leg light-time iteration did not converge")
    big_r, big_v = station_back(r_st, v_st, a_st, tau_d + tau)
    d = r_b - big_r
    rho = np.linalg.norm(d, axis=-1)
    return UpLeg(tau_s=tau, rho_m=rho, u=d / rho[..., None], r_st=big_r, v_st=big_v, iterations=it)
