"""The numba-compiled full force model and DOP853 (dynamics/forces/compiled.py) against the numpy
path they replace: the same accelerations and Jacobians (every term: field, Sun, Moon, SRP in
and out of the shadow, Harris-Priester drag, relativity, empirical accelerations, the
truncated STM field), and the same trajectories, STM and parameter sensitivities to far below
the integration error. The first run compiles the kernels (~12 s of CPU, cached in __pycache__), hence
the slow tier.
"""

from __future__ import annotations

import erfa
import numpy as np
import pytest

from test_forces_orekit import LEO
from trackproc.dynamics import timescales as ts
from trackproc.dynamics.forces import ForceModel, Spacecraft, integrator, srp
from trackproc.dynamics.propagator import propagate, reference_frame
from trackproc.io.icgem import load_field

numba = pytest.importorskip("numba")
pytestmark = pytest.mark.slow

EPOCH = "2020-04-05T00:00:00"
SC = Spacecraft(mass_kg=10.0, srp_area_m2=0.1, cr=1.3, drag_area_m2=0.1, cd=2.1)


def _model(**kw):
    kw.setdefault("field", load_field(degree=30, date=EPOCH))
    return ForceModel(**kw)


def _env(model, span=86400.0):
    jd = tuple(float(x) for x in ts.datetime64_to_jd_utc(np.datetime64(EPOCH, "ns")))
    q = reference_frame(*jd, None).q
    return model.environment(jd, q, 0.0, span), q


def test_geodetic_height_matches_erfa():
    from trackproc.dynamics.forces import compiled

    rng = np.random.default_rng(1)
    r = rng.normal(size=(200, 3)) * 7e6
    r[0] = (0.0, 0.0, 6.5e6)                                   # the pole branch
    h = np.array([compiled._height(x) for x in r])
    assert np.abs(h - erfa.gc2gd(1, r)[2]).max() < 1e-8


def test_density_table_interpolation_is_np_interp_bit_for_bit():
    """The Harris-Priester table read with one search for both columns (compiled._interp2) gives
    numba's np.interp of each column to the last bit: at random heights, at every node, between
    nodes, at and beyond both ends, and NaN."""
    from trackproc.dynamics.forces import compiled

    @numba.njit
    def reference(x, xp, f1, f2):
        return np.interp(x, xp, f1), np.interp(x, xp, f2)

    xp, f1, f2 = compiled._HP_H, compiled._HP_LMIN, compiled._HP_LMAX
    rng = np.random.default_rng(3)
    heights = np.concatenate([rng.uniform(xp[0] - 1e4, xp[-1] + 1e4, 3000), xp, 0.5 * (xp[1:] + xp[:-1]),
                              np.nextafter(xp, -np.inf), np.nextafter(xp, np.inf), [np.nan]])
    got = np.array([compiled._interp2(h, xp, f1, f2) for h in heights])
    want = np.array([reference(h, xp, f1, f2) for h in heights])
    assert np.array_equal(got, want, equal_nan=True)
    numpy = np.array([(np.interp(h, xp, f1), np.interp(h, xp, f2)) for h in heights])   # and numpy's own
    assert np.array_equal(got, numpy, equal_nan=True)
    assert np.array_equal(np.array([compiled._interp2.py_func(h, xp, f1, f2) for h in heights]), got, equal_nan=True)
    assert np.isnan(got[-1]).all() and np.isfinite(got[:-1]).all()


def test_accelerations_and_partials_equal_the_numpy_path():
    """At 60 states along a LEO day (sunlit, penumbra, umbra; drag below 1000 km), all terms on,
    a 30x30 field with the STM's gradient on its 20x20 cut, every parameter kind estimated."""
    from trackproc.dynamics.forces import compiled

    model = _model(srp=True, drag=True, spacecraft=SC, empirical_rtn=(1e-8, -2e-8, 3e-9),
                   empirical_gcrf=(1e-9, 0.0, -2e-9), empirical_gcrf_rate=(0.0, 1e-13, 0.0),
                   estimated=("cr", "cd", "empirical_t", "empirical_x", "empirical_z_rate"))
    env, q = _env(model)
    traj = propagate(LEO[0], LEO[1], EPOCH, 86400.0, force=_model(), tol=1e-10)
    shadow = []
    for t in np.linspace(0.0, 86400.0, 60):
        s = traj.state(t)
        r, v = q @ s[:3], q @ s[3:]
        a_num = env.acceleration(t, r, v)[0]
        assert np.abs(compiled.perturbation(env, t, r, v) - a_num).max() <= 1e-14 * np.abs(a_num).max()
        # ∂a/∂r: the field's, Sun's and Moon's analytic here, central differences there (their
        # truncation, (1 m / r)², and rounding: 1e-9 measured); ∂a/∂v: differences of the whole
        # perturbation there (rounding 1e-18 m/s² / 2 mm/s = 5e-16), of the v-dependent terms here
        a, g, hv, dp = compiled.partials(env, t, r, v)
        a0, g0, hv0, dp0 = env.partials(t, r, v)
        assert np.abs(a - a0).max() <= 1e-14 * np.abs(a0).max()
        assert np.abs(g - g0).max() <= 1e-8 * np.abs(g0).max()
        assert np.abs(hv - hv0).max() <= 1e-6 * np.abs(hv0).max() + 1e-14          # a few of those
        assert np.abs(dp - dp0).max() <= 1e-12 * np.abs(dp0).max()
        _, sun, _, axis = env.at(t)
        shadow.append(float(srp.shadow_fraction(r[None], sun, model.earth_radius_m, axis, 1 / 298.257223563)[0]))
    assert min(shadow) == 0.0 and max(shadow) == 1.0                    # both sides of the shadow


@pytest.mark.parametrize("stm", [False, True])
def test_propagation_equals_the_numpy_path(stm, monkeypatch):
    """LEO 6 h, 20x20 + Sun + Moon + relativity + drag + SRP (four shadow crossings), rtol 1e-12:
    states within 50 µm (200 µm with the STM; the step-size control differs at the rounding level),
    STM and Cr/Cd sensitivities to 1e-6 of their size; the rtol 1e-10 run is further."""
    model = _model(field=load_field(degree=20, date=EPOCH), drag=True, srp=True, spacecraft=SC,
                   estimated=("cr", "cd") if stm else ())
    t = np.linspace(0.0, 6 * 3600.0, 13)[1:]
    runs = {}
    for flag in ("1", "0"):
        monkeypatch.setenv("TRACKPROC_JIT", flag)
        runs[flag] = propagate(LEO[0], LEO[1], EPOCH, t, force=model, stm=stm, tol=1e-12)
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    loose = propagate(LEO[0], LEO[1], EPOCH, t, force=model, tol=1e-10)
    d = np.linalg.norm(runs["1"].state(t)[:, :3] - runs["0"].state(t)[:, :3], axis=1).max()
    d_loose = np.linalg.norm(loose.state(t)[:, :3] - runs["0"].state(t)[:, :3], axis=1).max()
    # measured 6 µm (88 µm with the STM, whose components enter the step control) and 0.46 mm
    assert d < (2e-4 if stm else 5e-5) and d_loose > 2 * d
    assert abs(runs["1"].n_steps - runs["0"].n_steps) <= 2
    if stm:
        for a, b in ((runs["1"].stm(t), runs["0"].stm(t)),
                     (runs["1"].parameter_partials(t), runs["0"].parameter_partials(t))):
            assert np.abs(a - b).max() < 1e-6 * np.abs(b).max()


def test_switch_and_fallbacks(monkeypatch):
    model = _model(field=load_field(degree=8, date=EPOCH))
    monkeypatch.setenv("TRACKPROC_JIT", "0")
    assert not integrator.use_compiled(model, 86400.0, True)
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    assert integrator.use_compiled(model, 86400.0, True)
    msis = _model(field=load_field(degree=8, date=EPOCH), drag=True, spacecraft=SC, atmosphere="nrlmsis")
    assert not integrator.use_compiled(msis, 86400.0, True)
    monkeypatch.setenv("TRACKPROC_JIT", "")          # automatic: a short run stays on numpy, =1 forces
    assert not integrator.use_compiled(model, 60.0, False) and integrator.use_compiled(model, 86400.0, False)
    monkeypatch.setenv("TRACKPROC_JIT", " 1 ")
    assert integrator.use_compiled(model, 60.0, False)
    # numba importable but the kernels not loadable (e.g. no writable cache): the numpy path, no traceback
    import sys

    import trackproc.dynamics.forces as forces_package
    monkeypatch.setitem(sys.modules, "trackproc.dynamics.forces.compiled", None)
    monkeypatch.delattr(forces_package, "compiled", raising=False)
    assert not integrator.use_compiled(model, 86400.0, True)


def test_step_limit_and_backward_runs_like_the_numpy_path():
    model = _model(field=load_field(degree=8, date=EPOCH), third_bodies=("sun",))
    env, q = _env(model, 7200.0)
    s0 = np.concatenate([q @ np.asarray(LEO[0]), q @ np.asarray(LEO[1])])
    a = integrator.propagate(env, s0, 7200.0, max_steps=5, compiled=True)
    b = integrator.propagate(env, s0, 7200.0, max_steps=5, compiled=False)
    assert a.outcome == b.outcome and a.outcome.value == "step_limit" and a.coefficients.shape == b.coefficients.shape
    jd = tuple(float(x) for x in ts.datetime64_to_jd_utc(np.datetime64(EPOCH, "ns")))
    env = model.environment(jd, q, -7200.0, 0.0)
    a = integrator.propagate(env, s0, -7200.0, compiled=True)
    b = integrator.propagate(env, s0, -7200.0, compiled=False)
    assert a.step_times_s[-1] == b.step_times_s[-1] == -7200.0

    def end(p):                               # the last step's position polynomial at its end
        h = p.step_times_s[-1] - p.step_times_s[-2]
        return p.coefficients[-1, 0] @ h ** np.arange(p.coefficients.shape[-1])

    assert np.linalg.norm(end(a) - end(b)) < 1e-5


@pytest.mark.parametrize("orbit", ["leo", "lageos", "leo_backward"])
def test_radiation_pressure_converges_with_the_tolerance(orbit):
    """Steps end at the shadow boundaries (Environment.shadow_signs): with SRP the rtol 1e-12 run
    is within 1 mm of the 3e-14 one over a LEO day (measured 0.28 mm; 1.2 m when steps crossed
    the penumbra) and 3 days of LAGEOS (0.40 mm; 15 mm before), as without SRP (0.28 mm); and
    half a LEO day backwards (0.09 mm)."""
    from test_forces_orekit import LAGEOS

    state, span, sc = ((LEO, 86400.0, SC) if orbit == "leo" else
                       (LAGEOS, 3 * 86400.0, Spacecraft(mass_kg=405.38, srp_area_m2=0.2827, cr=1.13)))
    model = _model(field=load_field(degree=20, date=EPOCH), srp=True, spacecraft=sc)
    t = np.linspace(0.0, span, 73)[1:] * (-0.5 if orbit == "leo_backward" else 1.0)
    ref = propagate(state[0], state[1], EPOCH, t, force=model, tol=3e-14).state(t)[:, :3]
    run = propagate(state[0], state[1], EPOCH, t, force=model, tol=1e-12).state(t)[:, :3]
    assert np.linalg.norm(run - ref, axis=1).max() < 1e-3


def test_analytic_field_gradient_against_differences_and_symmetry():
    """compiled.hessian_tables: the operator of M&G eq. 3.33 applied once reproduces the field's
    own acceleration (1e-15 relative), twice a symmetric ∂a/∂r equal to central differences of
    the acceleration (steps 1 m: their truncation (h/r)² ~ 2e-14, measured 1e-9 with rounding)
    at points of all latitudes, for a 70x70 field too."""
    from trackproc.dynamics.forces import compiled, tables

    rng = np.random.default_rng(3)
    for deg in (20, 70):
        f = load_field(degree=deg, date=EPOCH)
        ht = compiled.hessian_tables(f)
        w = {(n, m): complex(f.cbar[n, m], -f.sbar[n, m]) / tables._normalisation(n, m)
             for n in range(1, deg + 1) for m in range(n + 1)}
        for _ in range(5):
            r = rng.normal(size=3)
            r *= rng.uniform(6.7e6, 2.6e7) / np.linalg.norm(r)
            z = f.solid_harmonics(r)[0]
            acc = f.acceleration(r, central=False)
            first = [f.gm_m3_s2 / f.radius_m ** 2 * sum((q * tables._normalisation(n, m) * z[n, m]).real
                                                        for (n, m), q in tables._derivative(w, i).items())
                     for i in range(3)]
            assert np.abs(np.array(first) - acc).max() < 1e-12 * np.abs(acc).max()
            g = np.empty((3, 3))
            compiled._field_hessian(r, ht, g)
            gd = np.stack([(f.acceleration(r + e, central=False) - f.acceleration(r - e, central=False)) / 2.0
                           for e in np.eye(3)], 1)
            assert np.array_equal(g, g.T) and np.abs(g - gd).max() < 1e-7 * np.abs(gd).max()
