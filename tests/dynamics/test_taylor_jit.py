"""The numba-compiled Taylor step loop (issue 19): the same propagation as the numpy engine to
rounding (state, STM, d/d mu, dense output; LEO, eccentric, HEO; two-body and J2), against Kepler
on its own, the same outcomes, and the automatic choice of the engine (a pass never pays for numba).

The kernels are compiled once per checkout (numba cache=True; about 6 s of CPU the first time,
then ~0.2 s to load them in a process)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from trackproc.dynamics import jit, kepler, taylor
from trackproc.dynamics.taylor import Outcome, propagate

pytest.importorskip("numba")

#: seed 004 Table 1 "truth" state (km -> m): near-circular LEO, |r| = 7191 km.
LEO = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1])
#: an eccentric orbit (e ~ 0.1, perigee 6878 km), inclined 63 deg.
ECC = np.array([6878137.0, 0.0, 0.0, 0.0, 3630.0, 7126.0])
#: Molniya-like HEO at perigee: 6900 x 46220 km (e = 0.74), i = 63.4 deg, period 12 h.
HEO = np.array([6.9e6, 0.0, 0.0, 0.0, 4489.0, 8965.0])
DAY = 86400.0

CASES = [("two-body", LEO, DAY), ("j2", LEO, DAY), ("j2", ECC, DAY), ("two-body", HEO, DAY),
         ("j2", HEO, DAY)]


@pytest.fixture(autouse=True)
def _auto_mode(monkeypatch):
    """Each test starts from the automatic choice, whatever the caller's TRACKPROC_JIT."""
    monkeypatch.delenv("TRACKPROC_JIT", raising=False)


def _rel(a, b, axis=0):
    """max |a - b| / max |b| per component (columns of a state: metres and m/s apart)."""
    return float((np.abs(a - b) / np.abs(b).max(axis=axis, keepdims=True)).max())


@pytest.mark.parametrize("force,state,span", CASES)
def test_state_matches_numpy_engine(force, state, span):
    ref = propagate(state, 0.0, span, force=force, engine="numpy")
    res = propagate(state, 0.0, span, force=force, engine="compiled")
    assert res.engine == "compiled" and ref.engine == "numpy"
    assert res.outcome is Outcome.SUCCESS and res.n_steps == ref.n_steps
    np.testing.assert_allclose(res.step_times_s, ref.step_times_s, rtol=1e-9)
    # the first step's spectra: same recurrences, summation order apart
    np.testing.assert_allclose(res.coefficients[0], ref.coefficients[0], rtol=1e-12,
                               atol=1e-13 * np.abs(ref.coefficients[0]).max())
    t = np.linspace(0.0, span, 1441)
    a, b = res.state(t), ref.state(t)
    # measured 1e-13 .. 1e-12 (HEO velocity): rounding differences grown along the track
    assert _rel(a[:, :3], b[:, :3]) < 2e-12 and _rel(a[:, 3:], b[:, 3:]) < 2e-12


@pytest.mark.parametrize("force,state,span", CASES)
def test_stm_and_mu_sensitivity_match_numpy_engine(force, state, span):
    kw = dict(force=force, stm=True, mu_sensitivity=True)
    ref = propagate(state, 0.0, span, engine="numpy", **kw)
    res = propagate(state, 0.0, span, engine="compiled", **kw)
    assert res.parameters == ref.parameters and res.sensitivities.shape == ref.sensitivities.shape
    t = np.linspace(0.0, span, 97)
    ja, jb = res.jacobian(t), ref.jacobian(t)
    # each column against its own scale, over the whole arc (measured 4e-13 .. 1.1e-12)
    assert (np.abs(ja - jb).max(axis=(0, 1)) / np.abs(jb).max(axis=(0, 1))).max() < 1e-11
    assert _rel(res.state(t)[:, :3], ref.state(t)[:, :3]) < 1e-12
    np.testing.assert_array_equal(res.stm(0.0), np.eye(6))


def test_two_body_against_kepler():
    """Independent of the numpy engine: a LEO day and two HEO revolutions within 1 mm / 1 um/s."""
    for state in (LEO, HEO):
        t = np.linspace(0.0, DAY, 721)
        st = propagate(state, 0.0, DAY, force="two-body", engine="compiled").state(t)
        ref = kepler.propagate(state, t)
        assert np.abs(st[:, :3] - ref[:, :3]).max() < 1e-3
        assert np.abs(st[:, 3:] - ref[:, 3:]).max() < 1e-6


def test_dense_output_many_steps_unsorted_and_derivatives():
    """The compiled dense evaluator (many steps, few samples each) against numpy's, unsorted times."""
    ref = propagate(HEO, 0.0, DAY, engine="numpy")
    res = propagate(HEO, 0.0, DAY, engine="compiled")
    t = np.random.default_rng(3).uniform(0.0, DAY, 300)
    t[:3] = (0.0, DAY, res.step_times_s[5])                     # ends and a step boundary
    for d in (0, 1, 2):
        a, b = res.state(t, derivative=d), ref.state(t, derivative=d)
        assert a.shape == (300, 6)
        assert _rel(a, b) < 1e-11, d
    # first derivative = (v, a): the acceleration of the force model at the same positions
    acc = taylor.acceleration(res.state(t)[:, :3])
    assert _rel(res.state(t, derivative=1)[:, 3:], acc) < 1e-12
    assert res.state(1234.5).shape == (6,) and res.state(np.zeros((2, 3))).shape == (2, 3, 6)
    with pytest.raises(ValueError):
        res.state(DAY + 1.0)


def test_backward_matches_numpy_and_returns():
    fwd = propagate(ECC, 0.0, DAY, engine="compiled")
    back = propagate(fwd.state(DAY), DAY, 0.0, engine="compiled", stm=True)
    assert back.step_times_s[-1] == 0.0 and np.all(np.diff(back.step_times_s) < 0)
    assert np.abs(back.state(0.0)[:3] - ECC[:3]).max() < 1e-3
    ref = propagate(fwd.state(DAY), DAY, 0.0, engine="numpy", stm=True)
    t = np.linspace(DAY, 0.0, 49)
    assert _rel(back.stm(t).reshape(-1, 36), ref.stm(t).reshape(-1, 36)) < 1e-11


def test_outcomes_and_errors():
    res = propagate(LEO, 0.0, DAY, engine="compiled", max_steps=3)
    assert res.outcome is Outcome.STEP_LIMIT and res.n_steps == 3
    ref = propagate(LEO, 0.0, DAY, engine="numpy", max_steps=3)
    assert abs(res.t_end_s - ref.t_end_s) < 1e-6
    for stm in (False, True):
        bad = propagate(np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]), 0.0, 10.0, engine="compiled",
                        stm=stm)
        assert bad.outcome is Outcome.NON_FINITE and bad.n_steps == 0
    zero = propagate(LEO, 5.0, 5.0, engine="compiled")
    assert zero.outcome is Outcome.SUCCESS and zero.n_steps == 0
    with pytest.raises(ValueError):
        propagate(np.stack([LEO, ECC]), 0.0, 10.0, engine="compiled")   # one trajectory only
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 10.0, engine="fast")


def test_automatic_choice(monkeypatch):
    from trackproc.dynamics import taylor_jit

    taylor_jit.compile_all()
    assert taylor_jit.ready(False) and taylor_jit.ready(True)
    # a pass (1 step) stays numpy; an arc predicted beyond the break-even compiles
    assert propagate(LEO, 0.0, 600.0).engine == "numpy"
    long_arc = 1.05 * taylor.COMPILED_MIN_STEPS[False] * 800.0      # LEO steps are ~800 s
    assert propagate(LEO, 0.0, long_arc).engine == "compiled"
    with monkeypatch.context() as m:                                   # kernels never compiled
        m.setattr(taylor_jit, "ready", lambda stm: False)
        assert propagate(LEO, 0.0, long_arc).engine == "numpy"
        m.setattr(taylor, "COMPILE_MIN_STEPS", {False: 1000, True: 1000})
        assert propagate(LEO, 0.0, long_arc).engine == "compiled"
    assert propagate(np.stack([LEO, ECC]), 0.0, 600.0).engine == "numpy"   # batches stay numpy
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    assert propagate(LEO, 0.0, 600.0, stm=True).engine == "compiled"
    assert propagate(LEO, 0.0, 600.0, engine="numpy").engine == "numpy"
    monkeypatch.setenv("TRACKPROC_JIT", "0")
    assert not jit.enabled()
    assert propagate(LEO, 0.0, long_arc).engine == "numpy"
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 10.0, engine="compiled")
    monkeypatch.delenv("TRACKPROC_JIT")
    monkeypatch.setattr(taylor, "_compiled_available", lambda: False)  # numba not installed
    assert propagate(LEO, 0.0, long_arc).engine == "numpy"


def test_unusable_numba_falls_back_to_numpy(monkeypatch, caplog):
    """numba importable but the kernels' module is not (e.g. no writable cache): numpy, a warning."""
    long_arc = 1.05 * taylor.COMPILED_MIN_STEPS[False] * 800.0
    monkeypatch.setattr(taylor, "_JIT_MODULE", [])
    import trackproc.dynamics

    monkeypatch.delattr(trackproc.dynamics, "taylor_jit", raising=False)
    monkeypatch.setitem(sys.modules, "trackproc.dynamics.taylor_jit", None)   # import fails
    with caplog.at_level("WARNING"):
        assert propagate(LEO, 0.0, long_arc).engine == "numpy"
    assert "compiled Taylor engine unavailable" in caplog.text
    with pytest.raises(ValueError):
        propagate(LEO, 0.0, 10.0, engine="compiled")


def test_switch_follows_the_environment(monkeypatch):
    assert jit.enabled()
    monkeypatch.setenv("TRACKPROC_JIT", "0")
    assert not jit.enabled()
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    assert jit.enabled()


def test_a_pass_does_not_import_numba():
    """A single pass (what refine asks for) must not pay for ``import numba`` (issue 13 budget)."""
    code = ("import sys, numpy as np; from trackproc.dynamics import taylor; "
            "s = np.array([3774841.0, -1538034.0, 5924146.0, -4816.6, 3936.4, 4091.1]); "
            "r = taylor.propagate(s, 0.0, 600.0, stm=True); r.stm(np.linspace(0, 600, 601)); "
            "taylor.propagate(s, 0.0, 86400.0).state(np.linspace(0, 86400, 1441)); "
            "print('numba' in sys.modules, r.engine)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**__import__("os").environ, "TRACKPROC_JIT": ""}).stdout.split()
    assert out == ["False", "numpy"]
