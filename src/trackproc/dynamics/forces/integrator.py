"""Integration of the full force model: DOP853 with the variational equations.

The Taylor (DT) engine keeps two-body + J2 in its recurrences; the full model (a gravity
field to high degree, Sun, Moon, radiation pressure, drag) is integrated here by scipy's
8th-order Dormand-Prince method (Hairer, Nørsett & Wanner, *Solving ODEs I*, II.5) with tight
tolerances. The state is extended by the state transition matrix ``Φ`` and the parameter
sensitivities ``S`` (variational equations, Montenbruck & Gill 2000 eqs. 7.42-7.44)::

    Φ' = A Φ,   S' = A S + [0; ∂a/∂p],   A = [[0, I], [∂a/∂r, ∂a/∂v]]

The result is a :class:`trackproc.dynamics.taylor.Propagation` like the Taylor engine's, so
every consumer (dense states, STM, measurement spectra) works unchanged: each accepted
DOP853 step's 7th-degree dense output is converted to the position polynomial about the
step's start (8 Chebyshev-Lobatto samples, exact for a degree-7 polynomial, and the step's
velocities at both ends: degree 9, :func:`_spectra`), the velocity being its derivative.

Steps are at most ``T / (2N)`` (:func:`max_step_s`: T the orbital period, N the field's
degree), else DOP853's error estimate misses the field's shortest waves. Tolerances: ``rtol`` on the state (scaled by √(6/n) because scipy's error norm is the RMS
over all n integrated components), a loose ``STM_RTOL`` on Φ and S so that the step size is
set by the orbit alone. With radiation pressure, steps end at the shadow boundaries (penumbra
and umbra entry and exit, where the force's slope jumps and an RK step loses its order): a step
across one is redone to end :data:`EVENT_PAST_S` past it.

With numba (a dependency) the same DOP853 and right-hand side run compiled
(:mod:`trackproc.dynamics.forces.compiled`: no Python per step; once numba has run it, from its
stored machine code without importing numba, :mod:`trackproc.dynamics.forces.native`); chosen
automatically for runs long enough to pay for loading numba (:func:`use_compiled`),
``TRACKPROC_JIT=0`` keeps scipy's.
The right-hand sides agree to rounding; the steps differ slightly because DOP853's error
estimate of the positions is itself at the rounding level at rtol 1e-12 (the compiled sums
are in another order than numpy's BLAS), which moves a LEO day by ~10 µm (gravity, Sun, Moon)
to ~0.1 mm (drag): far inside the integration error.
"""

from __future__ import annotations

import logging

import numpy as np

from trackproc.dynamics.taylor import STATE_PARAMETERS, Outcome, Propagation
from trackproc.dynamics import jit

__all__ = ["propagate", "rtol_for", "RTOL", "STM_RTOL", "use_compiled"]

#: Default relative tolerance on the state (DOP853): a LEO day moves 0.2 mm from 1e-13 (17 cm at 1e-10).
RTOL = 1e-12
#: Absolute tolerances of the state: metres and m/s.
ATOL_M, ATOL_M_S = 1e-6, 1e-9
#: Relative and absolute tolerances of the STM and the parameter sensitivities.
STM_RTOL, STM_ATOL = 1e-8, 1e-8
#: scipy's floor on rtol (100 machine epsilons).
RTOL_FLOOR = 100 * np.finfo(float).eps
#: Loading numba and the cached kernels, once per process (s, measured: 0.45 s CPU). The stored
#: machine code loads in ~0.05 s, but the threshold stays: the choice must not depend on what is cached.
JIT_LOAD_S = 0.5
#: The numpy path's CPU seconds per second of run (LEO, 20x20 + Sun + Moon, rtol 1e-12, measured
#: 1.9 s and 3.6 s per day without and with the STM); fewer for higher orbits' longer steps.
NUMPY_COST = (2.2e-5, 4.2e-5)
#: How far past a shadow boundary a step is made to end (s): the kink then lies inside the step by
#: this much, its error (jump of the force's slope x EVENT_PAST_S²) nil.
EVENT_PAST_S = 1e-6
_DEGREE = 7
_NODES = 0.5 * (1.0 - np.cos(np.pi * np.arange(_DEGREE + 1) / _DEGREE))
_VINV = np.linalg.inv(np.vander(_NODES, _DEGREE + 1, increasing=True))
#: coefficients of a step's polynomial: the 8 nodes' values and the slopes at both ends
_NCOEF = _DEGREE + 3
_P = np.polynomial.polynomial
_W = _P.polyfromroots(_NODES)                                   # w(x) = prod (x - x_i), zero at every node
_DW0, _DW1 = _P.polyval(0.0, _P.polyder(_W)), _P.polyval(1.0, _P.polyder(_W))
_D0 = (np.arange(_DEGREE + 1) == 1).astype(float)              # p'(0) from increasing coefficients
_D1 = np.arange(_DEGREE + 1).astype(float)                      # p'(1)


def _derivative_pairs(n: int) -> tuple:
    """Indices of the position-like components of an integrated vector of length n (the state,
    then Φ and S row by row, :func:`propagate`) and of their time derivatives (the velocity rows)."""
    npar = (n - 42) // 6 if n > 6 else 0
    pos, vel = [0, 1, 2], [3, 4, 5]
    for base, width in ((6, 6), (42, npar)) if n > 6 else ():
        for i in range(3):
            pos += range(base + width * i, base + width * (i + 1))
            vel += range(base + width * (i + 3), base + width * (i + 4))
    return np.array(pos, int), np.array(vel, int)


def _spectra(vals: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``(S, n, 10)`` polynomial coefficients in seconds from the step's start of the dense output's
    values ``vals`` (S, 8 nodes, n) over steps of length ``h`` (S,): a position-like component through
    its 8 values, its slopes at both ends its velocity component's values there (Hermite conditions at
    the ends), so that neighbouring steps meet in position and velocity; a velocity-like component
    (unused) through its values. The value and slope at the start are taken out before the
    Vandermonde solve, against its rounding (~1e-16 × its condition ~1e4 × the values: on the 7e6 m
    of the position ~1e-5 m, on the curvature, ~1e4 m over a LEO step, ~1e-8 m), and the end slope is
    set by ``w(x) (α + β x)``, w zero at every node. Joins within ~4e-8 m and ~1e-12 m/s: a filter's
    time update between two of the reference's states takes any jitter there for a change of the orbit
    (docs/filter.md)."""
    pos, vel = _derivative_pairs(vals.shape[-1])
    start = vals[:, 0, :].copy()                                 # (S, n): the values at the step's start
    slope = np.zeros_like(start)
    slope[:, pos] = vals[:, 0, vel] * h[:, None]                 # d/dx, x = (t - t_old) / h
    rest = vals - start[:, None, :] - slope[:, None, :] * _NODES[None, :, None]
    a7 = np.matmul(_VINV, rest)                                  # (S, 8 powers, n)
    a = np.zeros((a7.shape[0], _NCOEF, a7.shape[2]))
    a[:, :_DEGREE + 1] = a7
    # the slopes at both ends made the step's velocities: w(x) (alpha + beta x) leaves the values at
    # the nodes and sets p'(0), p'(1)
    r0 = np.zeros_like(start)
    r1 = np.zeros_like(start)
    r0[:, pos] = -np.einsum("k,skn->sn", _D0, a7[:, :, pos])
    r1[:, pos] = (vals[:, -1, vel] - vals[:, 0, vel]) * h[:, None] - np.einsum("k,skn->sn", _D1, a7[:, :, pos])
    alpha = r0 / _DW0
    beta = r1 / _DW1 - alpha
    a[:, :_DEGREE + 2] += _W[None, :, None] * alpha[:, None, :]
    a[:, 1:] += _W[None, :, None] * beta[:, None, :]
    a[:, 0] += start
    a[:, 1] += slope
    return np.swapaxes(a, 1, 2) / h[:, None, None] ** np.arange(_NCOEF)


def max_step_s(model, state) -> float:
    """Largest step: half the period of the field's shortest wave along the orbit, ``T / (2N)``.

    DOP853's error estimate is fooled when a step spans a whole cycle of the forcing: a LEO
    day with a 70x70 field moved 7.5 cm between rtol 1e-13 and 3e-14 (80 s steps, the degree-70
    terms have an 81 s period there); capped at T/(2N) = 40 s, 1e-12 and 3e-14 agree to 10 µm.
    For degree 20 the cap (142 s in LEO) is barely reached at rtol 1e-12.
    """
    n = max(model.field.degree, 2)
    r = np.linalg.norm(state[:3])
    energy = 0.5 * float(np.dot(state[3:], state[3:])) - model.field.gm_m3_s2 / r
    a = -model.field.gm_m3_s2 / (2 * energy) if energy < 0 else r
    period = 2 * np.pi * np.sqrt(a ** 3 / model.field.gm_m3_s2)
    return float(period / (2 * n))


def rtol_for(tol: float) -> float:
    """The DOP853 rtol of a ``--tol``: ``tol`` itself, or :data:`RTOL` when it lies below
    DOP853's floor (the Taylor engine's tolerances, 1e-15 by default, are such)."""
    return float(tol) if tol >= RTOL_FLOOR else RTOL


def _rhs(env, stm: bool, n_par: int):
    if not stm:
        def f(t, y):
            return np.concatenate([y[3:6], env.acceleration(t, y[:3], y[3:6])[0]])
        return f

    def f(t, y):
        a, g, h, dp = env.partials(t, y[:3], y[3:6])
        phi = y[6:42].reshape(6, 6)
        out = np.empty_like(y)
        out[:3] = y[3:6]
        out[3:6] = a
        dphi = out[6:42].reshape(6, 6)
        dphi[:3] = phi[3:]
        dphi[3:] = g @ phi[:3] + h @ phi[3:]
        if n_par:
            s = y[42:].reshape(6, n_par)
            ds = out[42:].reshape(6, n_par)
            ds[:3] = s[3:]
            ds[3:] = g @ s[:3] + h @ s[3:] + dp
        return out
    return f


#: Geocentric radius at which a full-force propagation stops as re-entered: 100 km above the mean
#: Earth radius (6371 km), i.e. 93 to 114 km geodetic altitude; below it drag grows by orders of
#: magnitude within minutes, the steps shrink without bound and no force model here holds.
REENTRY_RADIUS_M = 6_471_000.0


def _reentry_step(radii) -> int | None:
    """Index of the first step ending below :data:`REENTRY_RADIUS_M`, or None."""
    below = np.flatnonzero(np.asarray(radii) < REENTRY_RADIUS_M)
    return int(below[0]) if below.size else None


def use_compiled(model, t_end_s: float, stm: bool = False) -> bool:
    """Whether a run of ``t_end_s`` seconds goes to the compiled integrator: numba usable
    (:func:`trackproc.dynamics.jit.enabled`, or the kernel's stored machine code,
    :mod:`trackproc.dynamics.forces.native`, which spares importing numba), the model covered
    (not NRLMSIS), and the numpy path's expected cost above loading the kernels. The choice
    depends on the call alone, never on what the process ran before or what is cached (the two
    paths agree to micrometres, not to the bit, and a batch's outputs must not depend on which
    tasks a worker happened to run first)."""
    if jit.mode() == "0":
        return False
    if not jit.forced() and abs(t_end_s) * NUMPY_COST[bool(stm)] < JIT_LOAD_S:
        return False
    from trackproc.dynamics.forces import native, tables  # start-up: no numba on these

    if not tables.supported(model):
        return False
    if native.stored():
        return True
    if not jit.enabled():
        return False
    try:
        from trackproc.dynamics.forces import compiled  # noqa: F401 - can numba build the kernels here
    except Exception as exc:                  # noqa: BLE001 - e.g. no writable numba cache: numpy
        _warn_once(f"compiled force model unavailable ({type(exc).__name__}: {exc}); using the numpy path")
        return False
    return True


_WARNED: set = set()


def _warn_once(message: str) -> None:
    if message not in _WARNED:
        _WARNED.add(message)
        logging.getLogger(__name__).warning(message)


def _run_compiled(env, y0, t_end_s, rt, at, max_step, max_steps, stm, est):
    """The compiled DOP853: accepted steps' times and their dense-output values at the nodes."""
    from trackproc.dynamics.forces import native, tables  # start-up: the compiled path's modules only

    model = env.model
    args = (y0, float(t_end_s), rt, at, float(max_step), int(max_steps), bool(stm), len(est),
            tables.environment_tables(env, est), tables.field_tables(model.field),
            tables.hessian_tables(tables.stm_field(env)))
    kernel = native.load(args)
    if kernel is not None:
        code, _, t_old, y_old, dense, t_last = kernel(*args)
    else:
        from trackproc.dynamics.forces import compiled  # start-up: loads numba and compiles (or reads) the kernels

        with jit.compile_once([compiled.integrate], "force", "the force kernels", 12):
            code, _, t_old, y_old, dense, t_last = compiled.integrate(*args)
        native.export(compiled.integrate, args)
    outcome = (Outcome.SUCCESS, Outcome.STEP_LIMIT, Outcome.NON_FINITE)[code]
    t_new = np.append(t_old[1:], t_last)[:t_old.size]
    h = t_new - t_old
    # scipy's Dop853DenseOutput at t_old + h * nodes, vectorised over the steps
    x = ((t_old[:, None] + h[:, None] * _NODES) - t_old[:, None]) / h[:, None]
    vals = np.zeros((t_old.size, _NODES.size, y0.size))
    for i in range(dense.shape[1]):
        vals += dense[:, None, dense.shape[1] - 1 - i, :]
        vals *= x[:, :, None] if i % 2 == 0 else (1 - x)[:, :, None]
    vals += y_old[:, None, :]
    return outcome, t_new, h, vals


def propagate(env, state0, t_end_s: float, *, stm: bool = False, rtol: float = RTOL,
              max_steps: int = 100_000, force_label: str = "full", compiled: bool | None = None) -> Propagation:
    """Integrate ``state0`` (6,) in the integration frame of ``env`` from t = 0 to ``t_end_s``.

    ``env`` a :class:`trackproc.dynamics.forces.model.Environment`. Returns a
    :class:`~trackproc.dynamics.taylor.Propagation` (parameters: the state, then the
    model's estimated force parameters, when ``stm``). ``compiled`` forces (True) or forbids
    (False) the numba integrator; None chooses (:func:`use_compiled`).
    """
    model = env.model
    est = tuple(model.estimated) if stm else ()
    npar = len(est)
    y0 = np.asarray(state0, float).reshape(6)
    if stm:
        y0 = np.concatenate([y0, np.eye(6).ravel(), np.zeros(6 * npar)])
    n = y0.size
    scale = np.sqrt(6.0 / n)
    rt = np.full(n, STM_RTOL)
    rt[:6] = max(rtol, RTOL_FLOOR / scale) * scale
    at = np.full(n, STM_ATOL)
    at[:3], at[3:6] = ATOL_M * scale, ATOL_M_S * scale
    if compiled is None:
        compiled = use_compiled(model, t_end_s, stm)
    if compiled:
        outcome, t_new, h, vals = _run_compiled(env, y0, t_end_s, rt, at, max_step_s(model, y0[:6]), max_steps,
                                                stm, est)
        k = _reentry_step(np.linalg.norm(vals[:, -1, :3], axis=1)) if len(vals) else None
        if k is not None:                        # the steps up to the first one that ends below
            outcome, t_new, h, vals = Outcome.REENTRY, t_new[:k + 1], h[:k + 1], vals[:k + 1]
        c = _spectra(vals, h)
        coefs = list(c[:, None, 0:3])
        senss = []
        if stm:
            phi = c[:, 6:42].reshape(-1, 6, 6, _NCOEF)[:, :3]
            sens = phi if not npar else np.concatenate([phi, c[:, 42:].reshape(-1, 6, npar, _NCOEF)[:, :3]], 2)
            senss = list(sens[:, None])
        return _result(model, outcome, [0.0] + list(t_new), coefs, senss, stm, est, rtol, force_label)
    from scipy.integrate import DOP853  # start-up: scipy.integrate (~0.3 s) only on the numpy path

    fun = _rhs(env, stm, npar)
    mstep = max_step_s(model, y0[:6])
    t_end = float(t_end_s)

    def solver_from(t0, y, bound, first=None):
        return DOP853(fun, t0, y, bound, rtol=rt, atol=at, max_step=mstep, first_step=first)

    solver = solver_from(0.0, y0, t_end)
    t_seg = t_end                                  # the current run's end: t_end or just past a shadow boundary
    signs = env.shadow_signs(0.0, y0)
    resume_h = None
    times = [0.0]
    coefs, senss = [], []
    outcome = Outcome.SUCCESS
    pos_rows = np.r_[0:3]
    while solver.status == "running":
        if len(coefs) >= max_steps:
            outcome = Outcome.STEP_LIMIT
            break
        with np.errstate(all="ignore"):
            solver.step()
        if solver.status == "failed" or not np.all(np.isfinite(solver.y)):
            outcome = Outcome.NON_FINITE
            break
        t_old, h = solver.t_old, solver.t - solver.t_old
        dense = solver.dense_output()
        if signs is not None:
            new = env.shadow_signs(solver.t, solver.y)
            if new != signs and solver.t != t_seg:
                # a shadow boundary inside the step: redo it to just past the boundary (unless
                # that point is not before the step's end: a redo would repeat the same step)
                t_star = _boundary(env, dense, t_old, solver.t, signs)
                t_next = t_star + EVENT_PAST_S * np.sign(h)
                t_next = min(t_next, t_end) if h > 0 else max(t_next, t_end)
                if (t_next - solver.t) * np.sign(h) < 0:
                    t_seg = t_next
                    resume_h = abs(h)
                    solver = solver_from(t_old, solver.y_old, t_seg, abs(t_seg - t_old))
                    continue
            signs = new
        vals = dense(t_old + h * _NODES)                            # (n, 8); 3 extra evaluations
        c = _spectra(vals.T[None], np.array([h]))[0]                # (n, 10), seconds
        coefs.append(c[pos_rows][None])
        if stm:
            phi = c[6:42].reshape(6, 6, -1)[:3]                        # (3, 6, 10)
            sens = phi if not npar else np.concatenate([phi, c[42:].reshape(6, npar, -1)[:3]], 1)
            senss.append(sens[None])
        times.append(solver.t)
        if _reentry_step([np.linalg.norm(solver.y[:3])]) is not None:
            outcome = Outcome.REENTRY
            break
        if solver.status == "finished" and t_seg != t_end:       # landed past a boundary: go on
            t_seg = t_end
            solver = solver_from(solver.t, solver.y, t_end, min(resume_h, abs(t_end - solver.t)))
    return _result(model, outcome, times, coefs, senss, stm, est, rtol, force_label)


def _boundary(env, dense, t0: float, t1: float, signs) -> float:
    """The first time in ``(t0, t1]`` where the shadow signs leave ``signs``, by bisection on the
    step's interpolant to 1e-9 s."""
    lo, hi = t0, t1
    while abs(hi - lo) > 1e-9:
        mid = 0.5 * (lo + hi)
        if env.shadow_signs(mid, dense(mid)) != signs:
            hi = mid
        else:
            lo = mid
    return hi


def _result(model, outcome, times, coefs, senss, stm, est, rtol, force_label) -> Propagation:
    npar = len(est)
    if coefs:
        coef_arr = np.stack(coefs)
        sens_arr = np.stack(senss) if stm else None
    else:
        coef_arr = np.empty((0, 1, 3, _NCOEF))
        sens_arr = np.empty((0, 1, 3, 6 + npar, _NCOEF)) if stm else None
    f = model.field
    return Propagation(outcome=outcome, step_times_s=np.array(times), coefficients=coef_arr,
                       sensitivities=sens_arr, parameters=(STATE_PARAMETERS + est) if stm else (),
                       order=_NCOEF - 2, tol=float(rtol), force=force_label, mu_m3_s2=f.gm_m3_s2,
                       j2=f.j2(), re_m=f.radius_m, batch=False)
