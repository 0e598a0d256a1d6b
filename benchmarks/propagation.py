"""Propagation benchmark (issue 3): the Taylor (DT) engine against scipy DOP853 and heyoka.

Run:  python benchmarks/propagation.py [--quick] [--only import|jit|pass|day|batch|measurements]

Prints, for each case, the median of >= 5 timed runs, the ratios measured in the same run,
and the errors against references (universal-variable Kepler for two-body; DOP853 at
rtol 1e-13 and the Taylor engine at tol 1e-16 / order 30 for J2):

* import + first result (fresh interpreter, with and without numpy already imported);
* the compiled engine (issue 19, numba, :mod:`trackproc.dynamics.taylor_jit`): its cold cost in a
  fresh interpreter (``import numba`` + loading the cached kernels) against the numpy engine's
  first call, the warm cost per step of both, and the break-even number of steps that
  ``engine="auto"`` uses (``taylor.COMPILED_MIN_STEPS``); the pass and day sections print the
  numpy and the compiled engine side by side (warm medians);
* one 600 s LEO pass, 601 samples, tol 1e-15: two-body and two-body + J2, with and
  without the state transition matrix; DOP853 tuned to 1 mm (the loosest rtol that meets
  1 mm against the reference), DOP853 at rtol 1e-13, heyoka at tol 1e-15 (if installed);
* one day of LEO, one sample a minute;
* a batch of 1000 perturbed orbits over the pass (state; STM), in trajectory*samples/s;
  DOP853 on the stacked 6000-dimensional system, heyoka in SIMD batches;
* measurement spectra (issue 3 item 5): the pass's one-way light-time range-rate and its
  partials with respect to the initial state straight from the series
  (:mod:`trackproc.dynamics.measurement_spectra`), against the foundation's model
  (DOP853 reference orbit + ``models/measurements.py``, as ``trackproc simulate`` computes it)
  with central finite differences for the partials.

Timing is never asserted here or in tests; the targets of issue 3 are printed beside the
measured values.
"""

from __future__ import annotations

import os

# One BLAS thread, as trackproc runs: a multi-threaded BLAS on this shared 2-core machine made the
# dense output's matrix products (and so "state + STM") ~25x slower (issue 19).
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse  # noqa: E402
import math
import statistics
import subprocess
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

from trackproc.constants import J2, MU_EARTH, RE_EARTH
from trackproc.dynamics import kepler, taylor

#: seed 004 Table 1 "truth" state (km -> m): near-circular LEO, |r| = 7191 km, i = 55 deg.
LEO = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])
PASS_S = 600.0
N_SAMPLES = 601
DAY_S = 86400.0
TOL = 1e-15
BATCH = 1000
KJ2 = -1.5 * J2 * MU_EARTH * RE_EARTH ** 2


def engines():
    """The Taylor engines to time: numpy, and the compiled one when numba is importable."""
    from trackproc.dynamics import jit
    return ("numpy", "compiled") if jit.enabled() else ("numpy",)


# -- timing --------------------------------------------------------------------------------

def median_time(fn, repeat: int = 7, min_s: float = 0.02, clock=time.perf_counter) -> float:
    """Median over ``repeat`` runs of the mean time of one call (calls batched to >= min_s)."""
    fn()                                                     # warm-up (caches, tables)
    t0 = clock()
    fn()
    one = clock() - t0
    number = max(1, int(min_s / max(one, 1e-9)))
    runs = []
    for _ in range(repeat):
        t0 = clock()
        for _ in range(number):
            fn()
        runs.append((clock() - t0) / number)
    return statistics.median(runs)


def fmt_t(s: float) -> str:
    return f"{s * 1e3:9.3f} ms"


# -- right-hand sides for DOP853 -----------------------------------------------------------

def rhs_two_body(t, y):
    x, yy, z = y[0], y[1], y[2]
    r2 = x * x + yy * yy + z * z
    f = -MU_EARTH / (r2 * math.sqrt(r2))
    return np.array([y[3], y[4], y[5], f * x, f * yy, f * z])


def rhs_j2(t, y):
    x, yy, z = y[0], y[1], y[2]
    r2 = x * x + yy * yy + z * z
    w3 = 1.0 / (r2 * math.sqrt(r2))
    w5 = w3 / r2
    g = -MU_EARTH * w3 + KJ2 * (w5 - 5.0 * z * z * w5 / r2)
    return np.array([y[3], y[4], y[5], g * x, g * yy, (g + 2.0 * KJ2 * w5) * z])


def gravity_gradient(r, force):
    """d acceleration / d r, ``(..., 3, 3)`` for positions ``(..., 3)``, two-body (+ J2).

    With a_i = x_i f_i, f_x = f_y = -mu w3 + k (w5 - 5 z^2 w7), f_z = f_x + 2 k w5
    (w_m = r^-m, k = -3/2 J2 mu Re^2):
    G = diag(f_x, f_x, f_z) + q r r^T - 10 k w7 z (r e_z^T + e_z r^T),
    q = 3 mu w5 - 5 k w7 + 35 k z^2 w9. Checked against finite differences at start-up.
    """
    x = np.asarray(r, dtype=float)
    r2 = np.sum(x * x, axis=-1)[..., None, None]
    w3 = r2 ** -1.5
    w5, w7, w9 = w3 / r2, w3 / r2 ** 2, w3 / r2 ** 3
    k = KJ2 if force == "j2" else 0.0
    z = x[..., 2][..., None, None]
    fx = -MU_EARTH * w3 + k * (w5 - 5.0 * z * z * w7)
    fz = fx + 2.0 * k * w5
    q = 3.0 * MU_EARTH * w5 - 5.0 * k * w7 + 35.0 * k * z * z * w9
    g = q * x[..., :, None] * x[..., None, :]
    ez = np.array([0.0, 0.0, 1.0])
    g = g - 10.0 * k * w7 * z * (x[..., :, None] * ez + ez[:, None] * x[..., None, :])
    g = g + fx * np.diag([1.0, 1.0, 0.0]) + fz * np.diag([0.0, 0.0, 1.0])
    return g


def _check_gravity_gradient():
    r = LEO[:3]
    for force in ("two-body", "j2"):
        fd = np.stack([(taylor.acceleration(r + e, force=force)
                        - taylor.acceleration(r - e, force=force)) / 2.0
                       for e in np.eye(3)], axis=-1)
        g = gravity_gradient(r, force)
        assert np.abs(g - fd).max() < 1e-8 * np.abs(g).max(), force


def rhs_var(force):
    base = rhs_j2 if force == "j2" else rhs_two_body

    def f(t, y):
        out = np.empty(42)
        out[:6] = base(t, y[:6])
        phi = y[6:].reshape(6, 6)
        g = gravity_gradient(y[:3], force)
        d = np.empty((6, 6))
        d[:3] = phi[3:]
        d[3:] = g @ phi[:3]
        out[6:] = d.ravel()
        return out
    return f


def rhs_batch(force):
    def f(t, y):
        s = y.reshape(-1, 6)
        out = np.empty_like(s)
        out[:, :3] = s[:, 3:]
        out[:, 3:] = taylor.acceleration(s[:, :3], force=force)
        return out.ravel()
    return f


def rhs_batch_var(force, n):
    """Stacked state + STM of n trajectories: y = [n*6 states, n*36 STM entries]."""
    def f(t, y):
        s = y[:6 * n].reshape(n, 6)
        phi = y[6 * n:].reshape(n, 6, 6)
        out = np.empty_like(y)
        ds = out[:6 * n].reshape(n, 6)
        ds[:, :3] = s[:, 3:]
        ds[:, 3:] = taylor.acceleration(s[:, :3], force=force)
        dphi = out[6 * n:].reshape(n, 6, 6)
        dphi[:, :3] = phi[:, 3:]
        dphi[:, 3:] = gravity_gradient(s[:, :3], force) @ phi[:, :3]
        return out
    return f


def dop853(fun, y0, t_end, t_eval, rtol, atol):
    return solve_ivp(fun, (0.0, t_end), y0, method="DOP853", rtol=rtol, atol=atol,
                     t_eval=t_eval)


def pos_err(a, b):
    return float(np.linalg.norm(np.asarray(a)[..., :3] - np.asarray(b)[..., :3], axis=-1).max())


def tune_dop853(fun, y0, t_end, t_eval, ref, target_m=1e-3):
    """Loosest rtol (atol = rtol * 1 m) whose positions stay within target_m of ref."""
    for rtol in (1e-6, 3e-7, 1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 3e-11, 1e-11, 3e-12,
                 1e-12, 3e-13, 1e-13):
        sol = dop853(fun, y0, t_end, t_eval, rtol, rtol)
        if pos_err(sol.y.T, ref) <= target_m:
            return rtol, sol
    return None, None


# -- heyoka (optional) ---------------------------------------------------------------------

def heyoka_system(force):
    import heyoka as hy
    x, y, z, vx, vy, vz = hy.make_vars("x", "y", "z", "vx", "vy", "vz")
    r2 = x ** 2 + y ** 2 + z ** 2
    g = -MU_EARTH * r2 ** -1.5
    gz = g
    if force == "j2":
        g = g + KJ2 * (r2 ** -2.5 - 5.0 * z ** 2 * r2 ** -3.5)
        gz = g + 2.0 * KJ2 * r2 ** -2.5
    return [(x, vx), (y, vy), (z, vz), (vx, x * g), (vy, y * g), (vz, z * gz)]


# -- sections ------------------------------------------------------------------------------

def _subprocess_seconds(code: str, repeat: int) -> float:
    runs = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                 check=True).stdout) for _ in range(repeat)]
    return statistics.median(runs)


def section_import(repeat: int):
    first = ("import numpy as np; from trackproc.dynamics import taylor; "
             "r = taylor.propagate(np.array([7e6, 0, 0, 0, 7.5e3, 0.0]), 0.0, 60.0); "
             "s = r.state(np.linspace(0, 60, 61)); print(time.perf_counter() - t0)")
    print("\n== import + first result (fresh interpreter; 60 s two-body+J2, 61 samples) ==")
    cold = _subprocess_seconds("import time; t0 = time.perf_counter(); " + first, repeat)
    warm = _subprocess_seconds("import time, numpy; t0 = time.perf_counter(); " + first, repeat)
    alone = _subprocess_seconds("import time, numpy; t0 = time.perf_counter(); "
                                "import trackproc.dynamics.taylor; "
                                "print(time.perf_counter() - t0)", repeat)
    npy = _subprocess_seconds("import time; t0 = time.perf_counter(); import numpy; "
                              "print(time.perf_counter() - t0)", repeat)
    print(f"  numpy already imported      {fmt_t(warm)}  (target <= 50 ms)")
    print(f"  including the numpy import  {fmt_t(cold)}  (numpy alone {fmt_t(npy).strip()}; "
          f"import of taylor alone {fmt_t(alone).strip()})")


_COLD = """
import sys, time
import numpy as np, scipy.linalg  # noqa: F401  (trackproc's commands import scipy anyway)
from trackproc.dynamics import taylor
LEO = np.array({leo})
t = np.linspace(0.0, {span}, {n})
c0 = time.process_time()
r = taylor.propagate(LEO, 0.0, {span}, stm={stm}, engine="{eng}")
(r.stm if {stm} else r.state)(t)
print(time.process_time() - c0)
"""


def section_jit(repeat: int):
    """Cold (fresh interpreter: import numba + cached kernels) and warm cost of the compiled engine."""
    if "compiled" not in engines():
        print("\n== compiled engine: numba not importable (pip install trackproc[fast]) or TRACKPROC_JIT=0 ==")
        return
    print("\n== compiled Taylor engine (numba) vs numpy engine: J2 day, 1441 samples, CPU s ==")
    leo = ", ".join(repr(float(x)) for x in LEO)
    t = np.linspace(0.0, DAY_S, 1441)
    for stm in (False, True):
        cold = {}
        for eng in ("numpy", "compiled"):
            code = _COLD.format(leo=f"[{leo}]", span=DAY_S, n=1441, stm=stm, eng=eng)
            subprocess.run([sys.executable, "-c", code], capture_output=True, check=True)  # cache
            cold[eng] = _subprocess_seconds(code, repeat)
        warm = {}
        for eng in ("numpy", "compiled"):
            def run(eng=eng):
                r = taylor.propagate(LEO, 0.0, DAY_S, stm=stm, engine=eng)
                return r.stm(t) if stm else r.state(t)
            warm[eng] = median_time(run, repeat, clock=time.process_time)
        steps = taylor.propagate(LEO, 0.0, DAY_S, engine="numpy").n_steps
        per_np, per_c = warm["numpy"] / steps, warm["compiled"] / steps
        load = cold["compiled"] - warm["compiled"]
        even = load / (per_np - per_c)
        what = "state + STM" if stm else "state"
        print(f"  {what:<12} numpy: first call {fmt_t(cold['numpy'])}, warm {fmt_t(warm['numpy'])} "
              f"({per_np * 1e6:.1f} us/step);  compiled: first call {fmt_t(cold['compiled'])} "
              f"(import numba + cached kernels {fmt_t(load).strip()}), warm {fmt_t(warm['compiled'])} "
              f"({per_c * 1e6:.1f} us/step, {warm['numpy'] / warm['compiled']:.0f}x)")
        print(f"  {'':12} break-even of a fresh process: {even:.0f} steps "
              f"({even * DAY_S / steps / 86400:.1f} LEO days); engine='auto' compiles from "
              f"{taylor.COMPILED_MIN_STEPS[stm]} predicted steps")
    import tempfile
    with tempfile.TemporaryDirectory(prefix="trackproc-numba-") as cache:   # an empty numba cache
        out = subprocess.run([sys.executable, "-c", "from trackproc.dynamics import taylor_jit; "
                              "print(taylor_jit.compile_all())"], capture_output=True, text=True,
                             check=True, env={**os.environ, "NUMBA_CACHE_DIR": cache}).stdout
    print(f"  first compile of all kernels (once per installation, empty cache): {float(out):.1f} s CPU")


def ratio_line(name, t_other, t_taylor):
    r = t_other / t_taylor
    who = "Taylor" if r >= 1 else name
    return f"{name}/Taylor time {r:6.2f} ({who} {max(r, 1 / r):.1f}x faster)"


def heyoka_grid(ta, y0, t):
    def run():
        ta.time = 0.0
        ta.state[:] = y0
        return ta.propagate_grid(t)
    return run


def section_pass(force, have_heyoka, repeat):
    t = np.linspace(0.0, PASS_S, N_SAMPLES)
    fun = rhs_j2 if force == "j2" else rhs_two_body
    print(f"\n== one {PASS_S:.0f} s LEO pass, {N_SAMPLES} samples, {force}, tol {TOL:g} ==")
    if force == "two-body":
        ref = kepler.propagate(LEO, t)
        ref_name = "Kepler"
    else:
        ref = dop853(fun, LEO, PASS_S, t, 1e-13, 1e-9).y.T
        ref_name = "DOP853 rtol 1e-13"
    res = taylor.propagate(LEO, 0.0, PASS_S, force=force, tol=TOL, engine="numpy")
    st = res.state(t)
    print(f"  Taylor: order {res.order}, {res.n_steps} step(s) of "
          f"{np.round(np.abs(res.step_sizes_s), 1).tolist()} s")
    timed = {}
    for eng in engines():
        est = taylor.propagate(LEO, 0.0, PASS_S, force=force, tol=TOL, engine=eng).state(t)
        t_state = median_time(lambda: taylor.propagate(LEO, 0.0, PASS_S, force=force, tol=TOL,
                                                       engine=eng).state(t), repeat)
        t_stm = median_time(lambda: taylor.propagate(LEO, 0.0, PASS_S, force=force, tol=TOL,
                                                     stm=True, engine=eng).stm(t), repeat)
        phi = taylor.propagate(LEO, 0.0, PASS_S, force=force, tol=TOL, stm=True,
                               engine=eng).stm(t)
        timed[eng] = (t_state, t_stm)
        print(f"  Taylor {eng:<8} state   {fmt_t(t_state)}  (target <= 1 ms)  max |dr| vs {ref_name} "
              f"{pos_err(est, ref):.1e} m, |dv| {np.abs(est[:, 3:] - ref[:, 3:]).max():.1e} m/s")
        print(f"  Taylor {eng:<8} + STM   {fmt_t(t_stm)}  (target <= 2 ms)  max |det Phi - 1| "
              f"{np.abs(np.linalg.det(phi) - 1.0).max():.1e}")
    t_state, t_stm = timed["numpy"]
    rtol, sol = tune_dop853(fun, LEO, PASS_S, t, ref)
    t_dop = median_time(lambda: dop853(fun, LEO, PASS_S, t, rtol, rtol), repeat)
    print(f"  DOP853 @1 mm          {fmt_t(t_dop)}  rtol {rtol:g} (atol rtol*1 m), nfev "
          f"{sol.nfev}, err {pos_err(sol.y.T, ref):.1e} m;  {ratio_line('DOP853', t_dop, t_state)}"
          f"  [target Taylor >= 3x faster]")
    sol13 = dop853(fun, LEO, PASS_S, t, 1e-13, 1e-9)
    t_dop13 = median_time(lambda: dop853(fun, LEO, PASS_S, t, 1e-13, 1e-9), repeat)
    print(f"  DOP853 rtol 1e-13     {fmt_t(t_dop13)}  nfev {sol13.nfev};  "
          f"{ratio_line('DOP853', t_dop13, t_state)}")
    y0 = np.concatenate([LEO, np.eye(6).ravel()])
    vf = rhs_var(force)
    solv = dop853(vf, y0, PASS_S, t, rtol, rtol)
    t_dopv = median_time(lambda: dop853(vf, y0, PASS_S, t, rtol, rtol), repeat)
    phi_dop = solv.y.T[:, 6:].reshape(-1, 6, 6)
    rel = (np.linalg.norm(phi - phi_dop, axis=-2) / np.linalg.norm(phi, axis=-2)).max()
    print(f"  DOP853 42 var. eqs    {fmt_t(t_dopv)}  same rtol, STM column rel. diff. "
          f"{rel:.0e};  {ratio_line('DOP853', t_dopv, t_stm)}")
    if have_heyoka:
        import heyoka as hy
        ta = hy.taylor_adaptive(heyoka_system(force), LEO.tolist(), tol=TOL)
        run = heyoka_grid(ta, LEO, t)
        out = run()
        t_hy = median_time(run, repeat)
        print(f"  heyoka state          {fmt_t(t_hy)}  order {ta.order}, max |dr| vs Taylor "
              f"{pos_err(out[-1], st):.1e} m;  {ratio_line('heyoka', t_hy, t_state)}")
        if "compiled" in timed:
            print(f"  {'':22}{'':12}  compiled: {ratio_line('heyoka', t_hy, timed['compiled'][0])}")
        tv = hy.taylor_adaptive(hy.var_ode_sys(heyoka_system(force), hy.var_args.vars,
                                               order=1), LEO.tolist(), tol=TOL)
        run = heyoka_grid(tv, tv.state.copy(), t)
        outv = run()
        t_hyv = median_time(run, repeat)
        phi_hy = outv[-1][:, 6:].reshape(-1, 6, 6)
        rel = (np.linalg.norm(phi - phi_hy, axis=-2) / np.linalg.norm(phi, axis=-2)).max()
        print(f"  heyoka + var. eqs     {fmt_t(t_hyv)}  STM column rel. diff. vs Taylor "
              f"{rel:.0e};  {ratio_line('heyoka', t_hyv, t_stm)}")
        if "compiled" in timed:
            print(f"  {'':22}{'':12}  compiled: {ratio_line('heyoka', t_hyv, timed['compiled'][1])}")


def section_day(force, have_heyoka, repeat):
    t = np.linspace(0.0, DAY_S, 1441)
    fun = rhs_j2 if force == "j2" else rhs_two_body
    print(f"\n== one day of LEO, 1441 samples, {force}, tol {TOL:g} ==")
    res = taylor.propagate(LEO, 0.0, DAY_S, force=force, tol=TOL, engine="numpy")
    st = res.state(t)
    if force == "two-body":
        ref = kepler.propagate(LEO, t)
        ref_name, target = "Kepler", "1 mm"
    else:
        ref = dop853(fun, LEO, DAY_S, t, 1e-13, 1e-9).y.T
        ref_name, target = "DOP853 rtol 1e-13", "1 cm"
    timed = {}
    for eng in engines():
        est = taylor.propagate(LEO, 0.0, DAY_S, force=force, tol=TOL, engine=eng).state(t)
        timed[eng] = median_time(lambda: taylor.propagate(LEO, 0.0, DAY_S, force=force, tol=TOL,
                                                          engine=eng).state(t), 5)
        print(f"  Taylor {eng:<8}       {fmt_t(timed[eng])}  {res.n_steps} steps; max |dr| vs "
              f"{ref_name} {pos_err(est, ref):.1e} m (target <= {target}); vs numpy engine "
              f"{pos_err(est, st):.1e} m")
    t_tay = timed["numpy"]
    rtol, sol = tune_dop853(fun, LEO, DAY_S, t, ref)
    if rtol is None:
        print("  DOP853 cannot reach 1 mm over the day at rtol >= 1e-13")
    else:
        t_dop = median_time(lambda: dop853(fun, LEO, DAY_S, t, rtol, rtol), 5)
        print(f"  DOP853 @1 mm          {fmt_t(t_dop)}  rtol {rtol:g}, nfev {sol.nfev};  "
              f"{ratio_line('DOP853', t_dop, t_tay)}")
        if "compiled" in timed:
            print(f"  {'':22}{'':12}  compiled: {ratio_line('DOP853', t_dop, timed['compiled'])}")
    if have_heyoka:
        import heyoka as hy
        ta = hy.taylor_adaptive(heyoka_system(force), LEO.tolist(), tol=TOL)
        run = heyoka_grid(ta, LEO, t)
        out = run()
        t_hy = median_time(run, 5)
        print(f"  heyoka                {fmt_t(t_hy)}  max |dr| vs Taylor {pos_err(out[-1], st):.1e}"
              f" m;  {ratio_line('heyoka', t_hy, t_tay)}")
        if "compiled" in timed:
            print(f"  {'':22}{'':12}  compiled: {ratio_line('heyoka', t_hy, timed['compiled'])}")


def section_batch(have_heyoka, repeat, n=BATCH):
    force = "j2"
    t = np.linspace(0.0, PASS_S, N_SAMPLES)
    rng = np.random.default_rng(2024)
    batch = LEO + rng.normal(size=(n, 6)) * np.array([1e3] * 3 + [1.0] * 3)
    work = n * N_SAMPLES
    print(f"\n== batch of {n} perturbed orbits (1 km, 1 m/s), {PASS_S:.0f} s pass, "
          f"{N_SAMPLES} samples, {force}, tol {TOL:g} ==")
    res = taylor.propagate(batch, 0.0, PASS_S, force=force, tol=TOL)
    st = res.state(t)
    t_state = median_time(lambda: taylor.propagate(batch, 0.0, PASS_S, force=force,
                                                   tol=TOL).state(t), repeat)
    print(f"  Taylor state          {fmt_t(t_state)}  {work / t_state:.2e} traj*samples/s "
          f"(target >= 1e7); {res.n_steps} common step(s)")
    t_stm = median_time(lambda: taylor.propagate(batch, 0.0, PASS_S, force=force, tol=TOL,
                                                 stm=True).stm(t), 5)
    phi = taylor.propagate(batch, 0.0, PASS_S, force=force, tol=TOL, stm=True).stm(t)
    print(f"  Taylor state + STM    {fmt_t(t_stm)}  {work / t_stm:.2e} traj*samples/s "
          f"(target >= 2e6); output {phi.nbytes / 1e6:.0f} MB")
    idx = [0, n // 2, n - 1]
    err = max(pos_err(st[i], taylor.propagate(batch[i], 0.0, PASS_S, force=force, tol=TOL)
                      .state(t)) for i in idx)
    print(f"  max |dr| of 3 batch members vs their single runs: {err:.1e} m")
    fun = rhs_batch(force)
    y0 = batch.ravel()
    for rtol in (1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 3e-11, 1e-11):
        sol = dop853(fun, y0, PASS_S, t, rtol, rtol)
        ys = sol.y.T.reshape(N_SAMPLES, n, 6).transpose(1, 0, 2)
        if max(pos_err(ys[i], st[i]) for i in idx) <= 1e-3:
            t_dop = median_time(lambda: dop853(fun, y0, PASS_S, t, rtol, rtol), 5)
            print(f"  DOP853 stacked 6n-dim {fmt_t(t_dop)}  @1 mm: rtol {rtol:g}, "
                  f"{work / t_dop:.2e} traj*samples/s;  {ratio_line('DOP853', t_dop, t_state)}")
            vfun = rhs_batch_var(force, n)
            yv = np.concatenate([y0, np.tile(np.eye(6).ravel(), n)])
            t_dopv = median_time(lambda: dop853(vfun, yv, PASS_S, t, rtol, rtol), 5)
            print(f"  DOP853 stacked 42n var{fmt_t(t_dopv)}  same rtol, "
                  f"{work / t_dopv:.2e} traj*samples/s;  {ratio_line('DOP853', t_dopv, t_stm)}")
            break
    if have_heyoka:
        import heyoka as hy
        bs = hy.recommended_simd_size()
        grid = np.repeat(t[:, None], bs, axis=1)

        def make_run(tb, y, out_dim):
            def run():
                out = np.empty((n, N_SAMPLES, out_dim))
                for i in range(0, n - n % bs, bs):
                    tb.set_time(0.0)
                    tb.state[:] = y[i:i + bs].T
                    out[i:i + bs] = np.transpose(tb.propagate_grid(grid)[-1], (2, 0, 1))
                return out
            return run
        tb = hy.taylor_adaptive_batch(heyoka_system(force), np.ascontiguousarray(batch[:bs].T),
                                      tol=TOL)
        run = make_run(tb, batch, 6)
        out = run()
        t_hy = median_time(run, 5)
        print(f"  heyoka SIMD batch {bs}   {fmt_t(t_hy)}  {work / t_hy:.2e} traj*samples/s, "
              f"max |dr| vs Taylor {max(pos_err(out[i], st[i]) for i in idx[:2]):.1e} m;  "
              f"{ratio_line('heyoka', t_hy, t_state)}")
        yv = np.concatenate([batch, np.tile(np.eye(6).ravel(), (n, 1))], axis=1)
        tbv = hy.taylor_adaptive_batch(
            hy.var_ode_sys(heyoka_system(force), hy.var_args.vars, order=1),
            np.ascontiguousarray(yv[:bs].T), tol=TOL)
        run = make_run(tbv, yv, 42)
        run()
        t_hyv = median_time(run, 5)
        print(f"  heyoka SIMD var. eqs  {fmt_t(t_hyv)}  {work / t_hyv:.2e} traj*samples/s;  "
              f"{ratio_line('heyoka', t_hyv, t_stm)}")


def section_measurements(repeat):
    """Range-rate and its partials over a 601-sample pass, image domain vs foundation + FD."""
    from trackproc.dynamics import frames, geodesy, measurement_spectra, propagator, reference
    from trackproc.dynamics import timescales as ts
    from trackproc.models import measurements as mm

    epoch = np.datetime64("2026-03-20T09:30:00", "ns")
    jd = tuple(float(x) for x in ts.datetime64_to_jd_utc(epoch))
    eop = ts.EarthOrientation.constant(0.0)
    t = np.linspace(0.0, PASS_S, N_SAMPLES)
    r0, v0 = LEO[:3], LEO[3:]
    # a station under the ground track at mid-pass: a pass through the zenith
    q = frames.QuasiInertialFrame.at(*jd, eop).q
    mid_r, mid_v = reference.propagate_gcrf(r0, v0, [PASS_S / 2], q, "j2")
    jm = ts.add_seconds_utc(jd, np.array([PASS_S / 2]))
    lat, lon, _ = geodesy.itrf_to_geodetic(frames.gcrf_to_itrf(mid_r[0], mid_v[0], *jm, eop)[0][0])
    lat, lon = float(lat), float(lon)
    st_itrf = geodesy.geodetic_to_itrf(lat, lon, 0.0)
    print(f"\n== measurement spectra: one {PASS_S:.0f} s pass, {N_SAMPLES} samples, j2, tol {TOL:g}, "
          f"station at the sub-satellite point of mid-pass, one-way light time ==")

    def spectra_run(with_partials=True):
        traj = propagator.propagate(r0, v0, epoch, t, eop=eop, tol=TOL, stm=with_partials)
        st = measurement_spectra.StationModel.build(st_itrf, lat, lon, traj.epoch_jd_utc, traj.frame.q,
                                                    t[0], t[-1], eop=eop)
        return traj, st, measurement_spectra.predict(traj, st, t, partials=with_partials)

    traj, st, pred = spectra_run()
    t_all = median_time(spectra_run, repeat)
    t_pred = median_time(lambda: measurement_spectra.predict(traj, st, t), repeat)
    t_vals = median_time(lambda: spectra_run(False), repeat)
    j1, j2 = ts.add_seconds_utc(jd, t)
    track = mm.station_gcrf(st_itrf, j1, j2, eop)

    def foundation(x):
        r, v = reference.propagate_gcrf(x[:3], x[3:], t, q, "j2")
        a, jk = reference.acceleration_gcrf(r, v, q, "j2")
        return mm.observables(r, v, a, jk, track.r, track.v, track.a, track.gcrf_to_itrf, lat, lon,
                              carrier_hz=2.2e9)

    steps = np.array([10.0] * 3 + [0.01] * 3)

    def foundation_fd():
        base = foundation(LEO)
        d_rr = np.empty((N_SAMPLES, 6))
        for k in range(6):
            e = np.zeros(6)
            e[k] = steps[k]
            d_rr[:, k] = (foundation(LEO + e).range_rate_m_s - foundation(LEO - e).range_rate_m_s) / (2 * steps[k])
        return base, d_rr

    def foundation_full():
        return foundation(LEO), mm.station_gcrf(st_itrf, j1, j2, eop)

    base, fd = foundation_fd()
    t_found = median_time(foundation_full, max(3, repeat // 2))
    t_fd = median_time(foundation_fd, 3) + median_time(lambda: mm.station_gcrf(st_itrf, j1, j2, eop), 3)
    rel = np.abs(pred.d_range_rate_d_state - fd).max(axis=0) / np.abs(fd).max(axis=0)
    h = 0.25                   # 4th-order differences: truncation h^4|D^(5)|/30 vs 1e-8 m noise / h
    rng = [measurement_spectra.predict(traj, st, t[2:-2] + d, partials=False).range_m for d in (2 * h, h, -h, -2 * h)]
    numeric = (-rng[0] + 8 * rng[1] - 8 * rng[2] + rng[3]) / (12 * h)
    print(f"  {pred.segments.range.shape[0]} range segments (half-widths "
          f"{pred.segments.half_width_s.min():.0f}..{pred.segments.half_width_s.max():.0f} s), "
          f"{pred.segments.iterations} light-time passes; elevation up to {np.degrees(pred.elevation_rad.max()):.1f} deg")
    print(f"  spectra: propagate+STM+range-rate+partials {fmt_t(t_all)};  predict alone {fmt_t(t_pred)};  "
          f"values only (no STM) {fmt_t(t_vals)}")
    print(f"  foundation model, values only (DOP853 + station + light time)  {fmt_t(t_found)};  "
          f"{ratio_line('foundation', t_found, t_vals)}")
    print(f"  foundation + central FD partials (13 evaluations)   {fmt_t(t_fd)};  "
          f"{ratio_line('foundation+FD', t_fd, t_all)}")
    print(f"  range vs foundation max {np.abs(pred.range_m - base.range_m).max():.1e} m, range-rate "
          f"{np.abs(pred.range_rate_m_s - base.range_rate_m_s).max():.1e} m/s; range-rate vs numerical derivative "
          f"of the light-time range {np.abs(numeric - pred.range_rate_m_s[2:-2]).max():.1e} m/s (target <= 1e-6)")
    print(f"  partials d(range-rate)/d(x0) vs foundation central FD: max rel. diff. per column {rel.max():.1e}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="5 repeats instead of 9, no day runs")
    ap.add_argument("--only", choices=("import", "jit", "pass", "day", "batch", "measurements"),
                    help="run one section only")
    args = ap.parse_args(argv)
    repeat = 5 if args.quick else 9
    try:
        import heyoka  # noqa: F401
        have_heyoka = True
        hv = getattr(heyoka, "__version__", "?")
    except ImportError:
        have_heyoka = False
    import scipy
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, scipy {scipy.__version__}, "
          + (f"heyoka {hv}" if have_heyoka else "heyoka: not installed"))
    print(f"Taylor default order at tol {TOL:g}: {taylor.default_order(TOL)}; "
          f"median of {repeat} runs per figure")
    _check_gravity_gradient()

    def want(name):
        return args.only is None or args.only == name

    if want("import"):
        section_import(repeat=5)
    if want("jit"):
        section_jit(repeat=5)
    if want("pass"):
        for force in ("two-body", "j2"):
            section_pass(force, have_heyoka, repeat)
    if want("day") and (not args.quick or args.only == "day"):
        for force in ("two-body", "j2"):
            section_day(force, have_heyoka, repeat)
    if want("batch"):
        section_batch(have_heyoka, repeat)
    if want("measurements"):
        section_measurements(repeat)


if __name__ == "__main__":
    main()
