"""Reference propagator: two-body (+ J2) motion integrated by DOP853 at a tight tolerance.

This is the independent high-accuracy propagator behind ``trackproc simulate`` and the tests
of the Taylor (DT) engine: scipy's ``solve_ivp`` with the 8th-order Dormand-Prince method
(Hairer, Nørsett & Wanner, *Solving ODEs I*, II.5), ``rtol = 1e-13``.

Equations of motion (seed 004 eq. 4 plus the J2 zonal term, Vallado 4th ed. eq. 8-30)::

    r'' = -mu r / |r|^3 + a_J2(r)
    a_J2 = -3/2 J2 mu Re^2 / |r|^5 * [x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]

J2 acts about the z axis of the integration frame, which must therefore be the Earth's
rotation axis: :func:`propagate_gcrf` integrates in the
:class:`~trackproc.dynamics.frames.QuasiInertialFrame` of a reference epoch (GCRF rotated
by that epoch's bias-precession-nutation matrix) and converts to GCRF at the edges. The axis
is frozen at the reference epoch (it drifts by about 0.15 arcsec a day).

All functions are pure, take SI units (m, m/s, s) and numpy arrays, and never print.

Accuracy. No returned state comes from the 7th-order dense-output interpolant: DOP853 takes
its own adaptive steps, and each requested time gets one extra DOP853 step of its own from
the last accepted step before it (vectorized over all requested times). Measured for the
seed 004 LEO orbit (a = 7191 km) against the universal-variable Kepler solution: 1.2e-5 m
and 1.2e-8 m/s after one day (tests/dynamics/test_reference.py); the interpolant would add about
1e-6 m. A day of LEO at a 10 s output step costs about 0.1 s (≈ 900 steps).
"""

from __future__ import annotations

import numpy as np

from trackproc.constants import MU_EARTH, RE_EARTH
from trackproc.dynamics.gravity import acceleration, force_parameters, jerk  # noqa: F401  (re-exported)

#: Default relative tolerance of the reference integration.
RTOL = 1e-13
#: Default absolute tolerances: metres for position, m/s for velocity.
ATOL_M = 1e-7
ATOL_M_S = 1e-10


def _rhs(mu: float, j2: float, re: float):
    """Right-hand side ``y' = (v, a(r))`` for states of shape (6,) or (6, M) (vectorized)."""
    def f(_t, y):
        y = np.asarray(y, float)
        return np.concatenate([y[3:], acceleration(y[:3].T, mu, j2, re).T])
    return f


def _dop853_tableau():
    """DOP853 Butcher tableau (A, B, C) as used by scipy, or None if scipy's layout changed."""
    try:
        from scipy.integrate._ivp import dop853_coefficients as dc  # start-up: scipy.integrate (~0.3 s)
        n = dc.N_STAGES
        return dc.A[:n, :n], dc.B, dc.C[:n]
    except (ImportError, AttributeError):  # pragma: no cover - scipy internals moved
        return None


def _final_steps(fun, t_start: np.ndarray, y_start: np.ndarray, h: np.ndarray, tableau) -> np.ndarray:
    """One DOP853 step of size ``h`` from each ``(t_start, y_start)``, all at once.

    ``y_start`` has shape (M, 6). The 8th-order solution of one Runge-Kutta step (the same
    formula scipy's ``rk_step`` uses), vectorized over the M starting points.
    """
    a, b, c = tableau
    y = y_start.T                       # (6, M)
    k = np.empty((len(b),) + y.shape)
    k[0] = fun(t_start, y)
    for s in range(1, len(b)):
        dy = np.tensordot(a[s, :s], k[:s], axes=1) * h
        k[s] = fun(t_start + c[s] * h, y + dy)
    return (y + h * np.tensordot(b, k, axes=1)).T


def _integrate_to_nodes(fun, y0: np.ndarray, nodes: np.ndarray, rtol: float, atol: np.ndarray) -> np.ndarray:
    """States at ``nodes`` (sorted away from 0, all of one sign), never interpolated.

    DOP853 runs with its own adaptive steps to the last node, keeping every accepted step's
    start (t_k, y_k). Each node t then gets one extra DOP853 step from the last t_k before it,
    of size t - t_k (smaller than the accepted step there, so with a smaller local error).
    """
    from scipy.integrate import DOP853   # here: propagator.force_parameters imports this module (issue 19)

    tableau = _dop853_tableau()
    if tableau is None:  # pragma: no cover
        return _restart_at_nodes(fun, y0, nodes, rtol, atol)
    t_end = float(nodes[-1])
    if t_end == 0.0:
        return np.tile(np.asarray(y0, float), (nodes.size, 1))
    solver = DOP853(fun, 0.0, np.asarray(y0, float), t_end, rtol=rtol, atol=atol)
    ts_, ys_ = [0.0], [solver.y.copy()]
    while solver.status == "running":
        msg = solver.step()
        if solver.status == "failed":
            raise ArithmeticError(f"DOP853 failed at t = {solver.t:.3f} s: {msg}")
        ts_.append(solver.t)
        ys_.append(solver.y.copy())
    t_k = np.abs(np.asarray(ts_))
    y_k = np.asarray(ys_)
    sign = 1.0 if t_end > 0 else -1.0
    idx = np.searchsorted(t_k, np.abs(nodes), side="right") - 1
    idx = np.clip(idx, 0, len(t_k) - 1)
    h = nodes - sign * t_k[idx]
    out = y_k[idx].copy()
    move = h != 0
    if move.any():
        out[move] = _final_steps(fun, sign * t_k[idx][move], y_k[idx][move], h[move], tableau)
    return out


def _restart_at_nodes(fun, y0, nodes, rtol, atol):  # pragma: no cover - fallback only
    """Slow fallback: restart the solver at every node (each node the end of a step)."""
    from scipy.integrate import DOP853  # start-up: scipy.integrate (~0.3 s)

    out = np.empty((nodes.size, y0.size))
    t, y, h = 0.0, np.asarray(y0, float), None
    for i, t_next in enumerate(nodes):
        if t_next == t:
            out[i] = y
            continue
        solver = DOP853(fun, t, y, t_next, rtol=rtol, atol=atol,
                        first_step=None if h is None else min(h, abs(t_next - t)))
        while solver.status == "running":
            msg = solver.step()
            if solver.status == "failed":
                raise ArithmeticError(f"DOP853 failed at t = {solver.t:.3f} s: {msg}")
            if solver.t != t_next:
                h = abs(solver.step_size)
        t, y = solver.t, solver.y
        out[i] = y
    return out


def propagate(r0, v0, t_s, mu: float = MU_EARTH, j2: float = 0.0, re: float = RE_EARTH, *,
              rtol: float = RTOL, atol_m: float = ATOL_M, atol_m_s: float = ATOL_M_S):
    """States at times ``t_s`` (s from the initial epoch; any order, either sign).

    Parameters
    ----------
    r0, v0 : (3,) initial position (m) and velocity (m/s) in a frame whose z axis is the
        symmetry axis of the J2 field (ignored when ``j2 == 0``).
    t_s : (N,) times in SI seconds from the initial epoch; negative times propagate backward.
    mu, j2, re : gravitational parameter (m³/s²), J2 (unnormalized), equatorial radius (m).

    Returns
    -------
    r, v : (N, 3) positions (m) and velocities (m/s) at ``t_s``, in the frame of ``r0``.

    Every returned state is the end point of an integration step (see module docstring).
    """
    t_s = np.atleast_1d(np.asarray(t_s, float))
    y0 = np.concatenate([np.asarray(r0, float).reshape(3), np.asarray(v0, float).reshape(3)])
    atol = np.array([atol_m] * 3 + [atol_m_s] * 3)
    fun = _rhs(mu, j2, re)
    uniq, inverse = np.unique(t_s, return_inverse=True)
    states = np.empty((uniq.size, 6))
    fwd = uniq >= 0
    if fwd.any():
        states[fwd] = _integrate_to_nodes(fun, y0, uniq[fwd], rtol, atol)
    if (~fwd).any():
        back = uniq[~fwd][::-1]
        states[~fwd] = _integrate_to_nodes(fun, y0, back, rtol, atol)[::-1]
    states = states[inverse.reshape(-1)]
    return states[:, :3], states[:, 3:]


def propagate_gcrf(r0, v0, t_s, q, force: str = "j2", **kwargs):
    """:func:`propagate` from a GCRF state, integrating in a quasi-inertial frame.

    ``q`` is the GCRF -> quasi-inertial rotation (``QuasiInertialFrame.q``, whose z axis is
    the Earth's rotation axis at its reference epoch); J2 acts about that axis. Returns GCRF
    positions (m) and velocities (m/s) at ``t_s``.
    """
    mu, j2, re = force_parameters(force)
    q = np.asarray(q, float)
    r, v = propagate(q @ np.asarray(r0, float), q @ np.asarray(v0, float), t_s, mu, j2, re, **kwargs)
    return r @ q, v @ q


def acceleration_gcrf(r, v, q, force: str = "j2"):
    """Acceleration (m/s²) and jerk (m/s³) of GCRF states under the force model of
    :func:`propagate_gcrf` (J2 about the z axis of the frame ``q``)."""
    mu, j2, re = force_parameters(force)
    q = np.asarray(q, float)
    rq, vq = np.asarray(r, float) @ q.T, np.asarray(v, float) @ q.T
    return acceleration(rq, mu, j2, re) @ q, jerk(rq, vq, mu, j2, re) @ q
