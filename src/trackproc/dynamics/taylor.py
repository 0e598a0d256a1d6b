"""Adaptive Taylor (DT) integrator for two-body + J2 motion, with dense output and the STM.

The equations of motion, in a quasi-inertial frame whose z axis is the Earth's rotation
axis (the caller converts frames; README "Units, sign conventions, time and frames")::

    r'' = -mu r / |r|^3 + a_J2,
    a_J2 = -3/2 J2 mu Re^2 / r^5 [x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]

are turned into a *P-model* (seed 000 eq. 14): with H = 1 s the spectrum of the position
obeys ``X(K+2) = A(K) / ((K+1)(K+2))`` where A is the spectrum of the acceleration (seed 004
eq. 6, written for the general case instead of the paper's constant r):

    s = x*x + y*y + z*z                 (Cauchy products, docs/equations.md, notation)
    w3, w5, w7 = s^(-3/2), s^(-5/2), s^(-7/2)   (power rule, docs/equations.md, notation)
    T = z*z * w7
    h_xy = -mu w3 + k (w5 - 5 T),  h_z = h_xy + 2 k w5,   k = -3/2 J2 mu Re^2
    A_x = x * h_xy,  A_y = y * h_xy,  A_z = z * h_z

For two-body motion only ``h = -mu w3``. Each order K costs a handful of vectorised
contractions (only the new K-th coefficient of each product is computed), over any number of
trajectories at once (batch axis).

Step size and order follow Jorba & Zou (2005, Exp. Math. 14, 99), as heyoka does, with two
deliberate differences. The step is
``h = min over k in {p-1, p} of (tol * scale / |c_k|)^(1/k) * exp(-0.7/(p-1))``, with c_k the
k-th Taylor coefficients of position and of velocity (each against its own
``scale = max(1, |.|_inf)``: combined absolute/relative tolerance, per-vector so that metres
and m/s are not mixed); heyoka writes ``rho e^-2`` for ``rho tol^(1/p)``, equal when
``p = -ln(tol)/2``. The order is :func:`default_order` (24 at tol = 1e-15, where heyoka takes
19): numpy pays per order, not per flop, and a near-circular 600 s LEO pass then fits in one
step. In batch mode every trajectory takes the same (smallest) step. The step size is chosen
from the state only, never from the sensitivities.

The recurrences themselves (four kernels of the same series: batch or single trajectory, with
or without sensitivities) are in :mod:`trackproc.dynamics.taylor_series`; this module chooses
steps and orders, keeps the dense output and runs the propagation.

Compiled engine (optional, numba; :mod:`trackproc.dynamics.taylor_jit`): the same step loop
compiled whole, for a single trajectory. ``engine="auto"`` (default) takes it when numba is
importable, ``TRACKPROC_JIT`` is not ``0`` and the arc is long enough to repay loading numba and
the cached kernels in a fresh process (:data:`COMPILED_MIN_STEPS`, predicted from the first
step; :data:`COMPILE_MIN_STEPS` while the kernels were never compiled); ``TRACKPROC_JIT=1``
takes it for every single-trajectory propagation. The choice depends on the call's arguments,
the environment and (for arcs between the two thresholds) whether this installation has compiled
the kernels, never on what the process ran before; the two engines agree to rounding (~1e-13).

Dense output: every step keeps its position spectrum; the state at any set of times is the
inverse transform (one matrix product per step: powers of the offsets x coefficients),
without re-integration. Velocity and higher derivatives are derivatives of the same series.

Sensitivities (seed 004 eqs. 19-21, kept to the first order in the parameters): every
coefficient carries its gradient with respect to the initial state (and optionally mu); the
same recurrences, applied to these truncated dual numbers, give the state transition matrix
Phi(t, t0) and d state/d mu, dense like the state.

Limits: two-body and J2 only; the frame must have its z axis along the J2 axis; times are
plain float seconds (about 1e-16 relative resolution, so keep t0 near the data, not at
J2000); no event detection.

One responsibility, the adaptive Taylor integrator's step loop and dense output (the series
themselves are :mod:`trackproc.dynamics.taylor_series`); a little over 400 lines with its input
checks and the first step's kept series.
"""

from __future__ import annotations

import logging
import math
import threading

import numpy as np

from trackproc import vocabulary
from trackproc.constants import J2, MU_EARTH, RE_EARTH
from trackproc.dynamics import gravity, jit
from trackproc.dynamics.taylor_dense import Outcome, Propagation
from trackproc.dynamics.taylor_series import series_dual, series_state, series_state_single, series_var_single

__all__ = ["Outcome", "Propagation", "propagate", "default_order", "acceleration", "FORCES",
           "STATE_PARAMETERS", "ENGINES", "COMPILED_MIN_STEPS", "COMPILE_MIN_STEPS"]

FORCES = vocabulary.TAYLOR_FORCES   # what the Taylor engine integrates ("full": dynamics.forces)
STATE_PARAMETERS = vocabulary.STATE_NAMES

#: ``engine=`` of :func:`propagate`.
ENGINES = ("auto", "numpy", "compiled")
#: Predicted steps from which ``engine="auto"`` takes the compiled engine (state only, with
#: sensitivities): the break-even of a fresh process, where the numpy steps saved (~0.09 / 0.2 ms
#: of CPU each) pay for ``import numba`` and loading the cached kernels (~0.18 s);
#: benchmarks/propagation.py --only jit measures both (2000 / 1000 steps: 18 / 9 LEO days).
COMPILED_MIN_STEPS = {False: 2000, True: 1000}
#: The same when the kernels are not compiled yet (~6 s of CPU once per installation; ``python -m
#: trackproc.dynamics.taylor_jit`` or ``TRACKPROC_JIT=1`` compiles them ahead).
COMPILE_MIN_STEPS = {False: 100_000, True: 50_000}


def _jit_mode() -> str:
    """``"off"`` (TRACKPROC_JIT=0), ``"on"`` (TRACKPROC_JIT=1) or ``"auto"``; read at each call
    (:func:`trackproc.dynamics.jit.mode`)."""
    v = jit.mode()
    return "off" if v == "0" else "on" if v == "1" else "auto"


_JIT_MODULE: list = []         # [module or None] once looked up


def _jit_module(mode_on: bool = False):
    """:mod:`trackproc.dynamics.taylor_jit`, or None when numba is off, absent or unusable (cached).

    numba can refuse ``cache=True`` at import (no writable cache directory); the numpy engine
    then serves, with one warning. ``mode_on``: the caller has just read ``TRACKPROC_JIT`` as
    ``1`` (:func:`_jit_mode`), so the module once looked up is the answer without reading it again
    (it was looked up only with numba importable, which stays so).
    """
    if mode_on and _JIT_MODULE:
        return _JIT_MODULE[0]
    if not jit.enabled():
        return None
    if not _JIT_MODULE:
        try:
            from trackproc.dynamics import taylor_jit as mod
        except Exception as exc:                         # noqa: BLE001 - any failure: numpy
            logging.getLogger(__name__).warning(
                "compiled Taylor engine unavailable (%s: %s); using the numpy engine",
                type(exc).__name__, exc)
            mod = None
        _JIT_MODULE.append(mod)
    return _JIT_MODULE[0]


def _compiled_available() -> bool:
    return _jit_module() is not None


def _compiled_pays(stm: bool, predicted_steps: float) -> bool:
    """engine="auto": do the predicted steps repay loading (or first compiling) the kernels?"""
    if predicted_steps < COMPILED_MIN_STEPS[stm] or not _compiled_available():
        return False
    if predicted_steps >= COMPILE_MIN_STEPS[stm]:
        return True
    return _jit_module().ready(stm)


def default_order(tol: float) -> int:
    """Taylor order for a tolerance: ``ceil(-2/3 ln(tol))`` (24 at tol = 1e-15).

    With the step ``h = rho tol^(1/p)`` the work per unit time is ``c(p) / tol^(1/p)``. Jorba &
    Zou (2005) and heyoka count floating-point work, ``c ~ p^2``, whose minimum is
    ``p = -ln(tol)/2`` (heyoka uses ``ceil(-ln(tol)/2 + 1)``, 19 at 1e-15). In numpy the cost of
    an order is interpreter overhead (``c ~ p``, optimum ``-ln tol``) for one trajectory and
    flops (``c ~ p^2``) for large batches; ``c ~ p^1.5`` in between gives ``-2/3 ln(tol)``.
    Near-circular orbits gain more: their series converge far beyond the step.
    """
    return max(3, math.ceil(-2.0 * math.log(tol) / 3.0))


def acceleration(r_m, *, force: str = "j2", mu_m3_s2: float = MU_EARTH, j2: float = J2,
                 re_m: float = RE_EARTH) -> np.ndarray:
    """Acceleration (m/s^2) of the force model at positions ``r_m`` shaped ``(..., 3)``.

    The right-hand side whose spectrum the integrator builds (:func:`trackproc.dynamics.gravity.acceleration`);
    used by tests and by conventional integrators for comparison.
    """
    if force not in FORCES:
        raise ValueError(f"unknown force model {force!r}; expected one of {FORCES}")
    return gravity.acceleration(r_m, mu_m3_s2, j2 if force == "j2" else 0.0, re_m)



class _PerOrder(dict):
    def __init__(self, fn):
        super().__init__()
        self.fn = fn

    def __missing__(self, p):
        self[p] = v = self.fn(p)
        return v


_ORDER_FACTORS = _PerOrder(lambda p: np.array([1.0, 1.0, float(p), p + 1.0]))
_INV_K = _PerOrder(lambda p: np.array([1.0 / (p - 1), 1.0 / p, 1.0 / (p - 1), 1.0 / p]))


def _step_size(x, p, tol):
    """Jorba-Zou step (>= 0, may be inf) common to the batch, from value spectra (B, 3, p+2)."""
    a = np.abs(x[:, :, [0, 1, p - 1, p, p + 1]]).max(axis=1)          # (B, 5) max over x, y, z
    lt = math.log(tol)
    if a.shape[0] == 1:                     # one trajectory: the same formula in scalar arithmetic
        r, v, c1, c2, c3 = a[0].tolist()
        lr, lv = math.log(max(1.0, r)), math.log(max(1.0, v))
        cand = math.inf
        # |c_k| for position k = p-1, p and velocity k = p-1, p (V(k) = (k+1) X(k+1))
        for c, lo, k in ((c1, lr, p - 1), (c2, lr, p), (c2 * p, lv, p - 1), (c3 * (p + 1.0), lv, p)):
            if c > 0.0:
                cand = min(cand, (lt + lo - math.log(c)) / k)
        return math.exp(cand - 0.7 / (p - 1)) if cand < math.inf else math.inf
    lo = np.log(np.maximum(1.0, a[:, :2]))                             # (B, 2): r, v scale
    with np.errstate(divide="ignore"):
        hi = np.log(a[:, [2, 3, 3, 4]] * _ORDER_FACTORS[p])
    cand = ((lt + lo[:, [0, 0, 1, 1]] - hi) * _INV_K[p]).min()    # log (tol scale/|c_k|)^(1/k)
    return math.exp(float(cand) - 0.7 / (p - 1))



_FIRST = threading.local()      # .last: (key, spectra) of the last first step taken in this thread


def _first_series(kern, s0, p, mu, kj2, *args):
    """The spectra of a first step, ``kern(*args, p, mu, kj2[, mu_slot])``, kept for the next call
    from the same start: a trajectory covering times on both sides of its epoch is two runs from
    one state (:func:`trackproc.dynamics.propagator.propagate`), whose first series are the same
    numbers (the step direction enters only when the series is summed). The kept array is never
    written to (the runs stack copies of their spectra)."""
    key = (kern, s0.tobytes(), s0.shape, p, mu, kj2, args[4] if len(args) == 5 else None)
    last = getattr(_FIRST, "last", None)
    if last is not None and last[0] == key:
        return last[1]
    out = kern(*args[:4], p, mu, kj2, args[4]) if len(args) == 5 else kern(*args, p, mu, kj2)
    _FIRST.last = (key, out)
    return out


def propagate(state0, t0_s: float, t_end_s: float, *, force: str = "j2",
              mu_m3_s2: float = MU_EARTH, j2: float = J2, re_m: float = RE_EARTH,
              tol: float = 1e-15, order: int | None = None, stm: bool = False,
              mu_sensitivity: bool = False, max_steps: int = 100_000,
              engine: str = "auto") -> Propagation:
    """Integrate two-body (+ J2) motion from t0 to t_end with the adaptive Taylor method.

    Parameters
    ----------
    state0 : array ``(6,)`` or ``(B, 6)``
        Position (m) and velocity (m/s) at ``t0_s`` in the quasi-inertial frame whose z axis
        is the rotation axis of J2. A leading axis B integrates B trajectories together with a
        common step (the smallest any of them needs).
    t0_s, t_end_s : float
        Start and end times, s (any origin); ``t_end_s < t0_s`` integrates backward.
    force : ``"two-body"`` or ``"j2"``
    mu_m3_s2, j2, re_m : float
        Gravitational parameter (m^3/s^2), unnormalised J2 and its reference radius (m).
    tol : float
        Combined absolute/relative tolerance per step (down to about 1e-16).
    order : int, optional
        Taylor order; default :func:`default_order` (24 at 1e-15).
    stm : bool
        Also propagate first-order sensitivities (state transition matrix).
    mu_sensitivity : bool
        With ``stm``, also d state / d mu.
    max_steps : int
        Stop with ``Outcome.STEP_LIMIT`` after this many steps.
    engine : ``"auto"``, ``"numpy"`` or ``"compiled"``
        The step loop: numpy, the numba-compiled one (single trajectory; needs numba and
        ``TRACKPROC_JIT`` != 0) or the automatic choice (module docstring). Same results to
        rounding.

    Returns
    -------
    Propagation
        Outcome, step times, per-step spectra; ``.state(t)``, ``.stm(t)``,
        ``.dstate_dmu(t)`` evaluate them at any times inside the interval covered.

    Implements seed 000 eq. 14 (P-model) with seed 004 eq. 6 in general form (power rule for
    r^-3, r^-5, r^-7), and seed 004 eqs. 19-21 (first order) for the sensitivities.

    Over 100 lines: the argument checks are functions of their own; what stays is the numpy
    engine's step loop (series, step size, the switch to the compiled engine after the first
    step, the update), one loop body over shared arrays as in the compiled engine.
    """
    s0 = np.asarray(state0, dtype=float)
    batch = s0.ndim == 2
    _check_state_and_model(s0, force, tol)
    t0, t1 = float(t0_s), float(t_end_s)
    p = default_order(tol) if order is None else int(order)
    _check_span_and_options(t0, t1, p, stm, mu_sensitivity, engine)
    max_steps = int(max_steps)
    s0 = s0.reshape(-1, 6)
    nb = s0.shape[0]
    kj2 = -1.5 * j2 * mu_m3_s2 * re_m ** 2 if force == "j2" else 0.0
    if force == "j2" and kj2 == 0.0:
        force = "two-body"
    params = STATE_PARAMETERS + (("mu",) if mu_sensitivity else ())
    npar = len(params)
    mu_slot = 7 if mu_sensitivity else None

    mode = "off" if engine == "numpy" else "on" if engine == "compiled" else _jit_mode()
    if engine == "compiled" and (nb > 1 or not _compiled_available()):
        raise ValueError("engine='compiled' integrates one trajectory and needs numba "
                         "(pip install numba) with TRACKPROC_JIT != 0")
    tj = _jit_module(mode_on=True) if mode == "on" and nb == 1 else None
    if tj is not None:
        return _propagate_compiled(s0, t0, t1, p, mu_m3_s2, kj2, tol, stm, mu_sensitivity,
                                   max_steps, force=force, j2=j2, re_m=re_m, batch=batch, tj=tj)
    # auto: decided after the first step (its size predicts the number of steps)
    decide = mode == "auto" and nb == 1

    r = s0[:, :3].copy()
    v = s0[:, 3:].copy()
    if stm:
        dr = np.zeros((nb, 3, npar))
        dv = np.zeros((nb, 3, npar))
        dr[:, [0, 1, 2], [0, 1, 2]] = 1.0
        dv[:, [0, 1, 2], [3, 4, 5]] = 1.0
    n = p + 2
    kpow = np.arange(n, dtype=float)
    kder = np.arange(1, n, dtype=float)
    direction = 1.0 if t1 >= t0 else -1.0
    times = [t0]
    coefs, senss = [], []
    outcome = Outcome.SUCCESS
    t = t0
    if stm:
        kern = series_var_single if nb == 1 else series_dual
    else:
        kern = series_state_single if nb == 1 else series_state
    with np.errstate(all="ignore"):                          # overflow is detected below
        while t != t1:
            if len(coefs) >= max_steps:
                outcome = Outcome.STEP_LIMIT
                break
            try:
                if len(times) == 1:
                    out = _first_series(kern, s0, p, mu_m3_s2, kj2, r, v, dr, dv, mu_slot) if stm else \
                        _first_series(kern, s0, p, mu_m3_s2, kj2, r, v)
                elif stm:
                    out = kern(r, v, dr, dv, p, mu_m3_s2, kj2, mu_slot)
                else:
                    out = kern(r, v, p, mu_m3_s2, kj2)
                if stm:
                    xd = out
                    x = xd[:, :, 0]
                else:
                    x = out
            except (ZeroDivisionError, OverflowError):         # scalar kernel, e.g. r = 0
                outcome = Outcome.NON_FINITE
                break
            if not (np.isfinite(x).all() and (not stm or np.isfinite(xd).all())):
                outcome = Outcome.NON_FINITE
                break
            h = _step_size(x, p, tol)
            remaining = abs(t1 - t)
            if decide:
                decide = False
                if _compiled_pays(stm, remaining / h if h > 0.0 else math.inf):
                    return _propagate_compiled(s0, t0, t1, p, mu_m3_s2, kj2, tol, stm,
                                               mu_sensitivity, max_steps, force=force, j2=j2,
                                               re_m=re_m, batch=batch)
            last = not (h < remaining)
            hs = (t1 - t) if last else direction * h
            hp = hs ** kpow
            hd = kder * hp[:-1]
            if stm:
                rv = xd @ hp                               # (B, 3, J)
                vv = xd[..., 1:] @ hd
                r, v = rv[:, :, 0], vv[:, :, 0]
                dr, dv = rv[:, :, 1:], vv[:, :, 1:]
                senss.append(xd[:, :, 1:])
                coefs.append(x)
            else:
                r = x @ hp
                v = x[..., 1:] @ hd
                coefs.append(x)
            if not (np.isfinite(r).all() and np.isfinite(v).all()):
                coefs.pop()
                if stm:
                    senss.pop()
                outcome = Outcome.NON_FINITE
                break
            t = t1 if last else t + hs
            times.append(t)
    if coefs:
        coef_arr = np.stack(coefs)
        sens_arr = np.stack(senss) if stm else None
    else:
        coef_arr = np.empty((0, nb, 3, n))
        sens_arr = np.empty((0, nb, 3, npar, n)) if stm else None
    return Propagation(outcome=outcome, step_times_s=np.array(times), coefficients=coef_arr,
                       sensitivities=sens_arr, parameters=params if stm else (),
                       order=p, tol=tol, force=force, mu_m3_s2=mu_m3_s2,
                       j2=j2 if force == "j2" else 0.0, re_m=re_m, batch=batch)


_OUTCOMES: dict = {}


def _compiled_outcome(tj, code: int):
    """The :class:`Outcome` of a compiled loop's return code."""
    if not _OUTCOMES:
        _OUTCOMES.update({tj.OUTCOME_SUCCESS: Outcome.SUCCESS, tj.OUTCOME_STEP_LIMIT: Outcome.STEP_LIMIT,
                          tj.OUTCOME_NON_FINITE: Outcome.NON_FINITE})
    return _OUTCOMES[code]


def _check_state_and_model(s0: np.ndarray, force: str, tol: float) -> None:
    """ValueError for an initial state :func:`propagate` cannot take, an unknown force model or a
    tolerance outside (0, 1)."""
    if s0.shape[-1] != 6 or s0.ndim not in (1, 2) or (s0.ndim == 2 and s0.shape[0] == 0):
        raise ValueError(f"state0 must have shape (6,) or (B, 6); found {s0.shape}")
    if not np.isfinite(s0).all():
        raise ValueError("state0 must be finite; found NaN or infinity")
    if force not in FORCES:
        raise ValueError(f"unknown force model {force!r}; expected one of {FORCES}")
    if not (0.0 < tol < 1.0):
        raise ValueError(f"tol must lie in (0, 1); found {tol}")


def _check_span_and_options(t0: float, t1: float, p: int, stm: bool, mu_sensitivity: bool, engine: str) -> None:
    """ValueError for a non-finite span, an order below 3, μ sensitivities without the STM or an
    unknown engine."""
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise ValueError(f"t0_s and t_end_s must be finite; found {t0}, {t1}")
    if p < 3:
        raise ValueError(f"order must be >= 3; found {p}")
    if mu_sensitivity and not stm:
        raise ValueError("mu_sensitivity needs stm=True")
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; expected one of {ENGINES}")


_SENS0: dict = {}


def _initial_sensitivities(npar: int):
    """``d r0 / d p`` and ``d v0 / d p`` (3, npar) at the start: the identity on the state (fresh
    copies of arrays made once)."""
    made = _SENS0.get(npar)
    if made is None:
        dr0 = np.zeros((3, npar))
        dv0 = np.zeros((3, npar))
        dr0[[0, 1, 2], [0, 1, 2]] = 1.0
        dv0[[0, 1, 2], [3, 4, 5]] = 1.0
        made = _SENS0[npar] = (dr0, dv0)
    return made[0].copy(), made[1].copy()


def _propagate_compiled(s0, t0, t1, p, mu, kj2, tol, stm, mu_sensitivity, max_steps, *, force,
                        j2, re_m, batch, tj=None) -> Propagation:
    """:func:`propagate` of one trajectory by the compiled loop (:mod:`taylor_jit`, ``tj`` when
    the caller has it). The kernels do no numpy arithmetic, so no ``errstate`` around them."""
    tj = tj or _jit_module()
    r0 = np.ascontiguousarray(s0[0, :3], dtype=float)
    v0 = np.ascontiguousarray(s0[0, 3:], dtype=float)
    args = (float(t0), float(t1), int(p), float(mu), float(kj2))
    kernel = tj.propagate_var if stm else tj.propagate_state

    def run():
        if stm:
            dr0, dv0 = _initial_sensitivities(7 if mu_sensitivity else 6)
            code, times, coefs, sens = kernel(r0, v0, dr0, dv0, *args, 6 if mu_sensitivity else -1,
                                              float(tol), int(max_steps))
            return code, times, coefs, sens[:, None]
        return kernel(r0, v0, *args, float(tol), int(max_steps)) + (None,)

    if jit.warm(kernel):                  # compiled in this process: no lock to take
        code, times, coefs, sens = run()
    else:
        with jit.compile_once([kernel], "taylor", "the Taylor engine's kernels", 6):
            code, times, coefs, sens = run()
    outcome = _compiled_outcome(tj, int(code))
    params = STATE_PARAMETERS + (("mu",) if mu_sensitivity else ())
    return Propagation(outcome=outcome, step_times_s=times, coefficients=coefs[:, None],
                       sensitivities=sens, parameters=params if stm else (),
                       order=p, tol=tol, force=force, mu_m3_s2=mu,
                       j2=j2 if force == "j2" else 0.0, re_m=re_m, batch=batch, engine="compiled")
