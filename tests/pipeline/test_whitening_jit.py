"""The compiled gain recursion of the two-state Kalman filter (methods/whitening_jit.py, numba,
optional) against the Python loop it replaces (methods/whitening.py MarkovFactor._kalman): the
same bits (innovation variances, log|C|; the whitened rows, by the compiled filter's state
recursion, to rounding) on irregular grids with duplicate times
and near-zero gaps, and the REML noise fit of a pass identical either way; TRACKPROC_JIT=0 and
an unset TRACKPROC_JIT in a process without numba keep the Python loop."""

from __future__ import annotations

import numpy as np
import pytest

from trackproc.methods import noise as nz
from trackproc.methods import whitening

numba = pytest.importorskip("numba")

BOTH = [
    nz.NoiseModel(0.7, 1.5, 12.0, 0.2),
    nz.NoiseModel(0.05, 2.0, 300.0, 0.05),         # white small beside them (ill-conditioned C)
    nz.NoiseModel(3.0, 0.1, 1.0, 1e-4),
]


def _grid(seed: int, n: int = 300) -> np.ndarray:
    rng = np.random.default_rng(seed)
    gaps = rng.exponential(2.0, n - 1)
    gaps[rng.choice(n - 1, 8, replace=False)] = 0.0                          # duplicate times
    gaps[rng.choice(n - 1, 8, replace=False)] = 10.0 ** rng.uniform(-9, -4, 8)   # near-zero gaps
    return 50.0 + np.concatenate([[0.0], np.cumsum(gaps)])


def _factor(model, t, t0, mode, monkeypatch):
    monkeypatch.setenv("TRACKPROC_JIT", mode)
    fac = whitening.MarkovFactor(model, t, t0)
    assert (whitening.compiled_riccati() is not None) == (mode == "1")
    return fac


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("model", BOTH, ids=lambda m: f"both-{m.white}")
def test_compiled_riccati_gives_the_same_bits(model, seed, monkeypatch):
    t = _grid(seed)
    m = np.random.default_rng(seed).normal(size=(t.size, 4))
    for t0 in (None, float(t[0]) - 3.0):
        py = _factor(model, t, t0, "0", monkeypatch)
        jit = _factor(model, t, t0, "1", monkeypatch)
        assert py._mode == jit._mode == "both"
        assert np.array_equal(py._s, jit._s)
        assert py.logdet == jit.logdet
        # the compiled filter whitens by the state recursion, the Python path by a banded
        # triangular solve: the same innovations to rounding, not bit for bit
        np.testing.assert_allclose(jit.whiten(m), py.whiten(m), rtol=0, atol=1e-12 * np.abs(py.whiten(m)).max())


def test_reml_fit_identical_with_and_without_the_kernel(monkeypatch):
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 500.0, 1.0)
    walk = np.cumsum(rng.normal(0.0, 0.05, t.size))
    ar = np.zeros(t.size)
    for i in range(1, t.size):
        ar[i] = 0.9 * ar[i - 1] + rng.normal(0.0, 0.4)
    r = rng.normal(0.0, 0.6, t.size) + walk + ar
    x = np.column_stack([np.ones(t.size), t - t[0]])
    fits = []
    for mode in ("0", "1"):
        monkeypatch.setenv("TRACKPROC_JIT", mode)
        fits.append(nz.fit_noise(t, r, x))
    assert fits[0].model == fits[1].model
    assert fits[0].candidates == fits[1].candidates


def test_unset_switch_uses_the_kernel_only_once_numba_is_loaded(monkeypatch):
    import sys

    monkeypatch.delenv("TRACKPROC_JIT", raising=False)
    monkeypatch.delitem(sys.modules, "numba")           # a process that has not paid for numba
    assert whitening.compiled_riccati() is None
    monkeypatch.setitem(sys.modules, "numba", numba)    # one that has (a batch worker)
    assert whitening.compiled_riccati() is not None
    monkeypatch.setenv("TRACKPROC_JIT", "0")
    assert whitening.compiled_riccati() is None


def test_batch_runs_its_refine_and_estimate_tasks_with_the_compiled_kernels(monkeypatch, tmp_path):
    """A chain that refines or estimates runs its tasks as under TRACKPROC_JIT=1 when numba is
    installed, whatever the number of tasks or workers; TRACKPROC_JIT=0 (the user's) wins."""
    from trackproc.dynamics import jit, taylor
    from trackproc.pipeline.batch.config import resolve
    from trackproc.pipeline.batch.kernels import compiled_kernels

    def settings(steps):
        return resolve(None, {"batch.inputs": [str(tmp_path)], "batch.output": str(tmp_path / "out"),
                              "batch.steps": steps, "refine.initial": str(tmp_path / "stale.json")}, environ={})

    monkeypatch.delenv("TRACKPROC_JIT", raising=False)
    refine = settings(["ingest", "smooth", "refine"])
    assert compiled_kernels(refine)
    assert not compiled_kernels(settings(["ingest", "smooth"]))          # nothing compiled to use
    assert taylor._jit_mode() == "auto"
    with jit.default("1"):                                                 # what run_task does for such a task
        assert taylor._jit_mode() == "on" and whitening.compiled_riccati() is not None
        monkeypatch.setenv("TRACKPROC_JIT", "0")                           # the user's setting wins
        assert taylor._jit_mode() == "off" and whitening.compiled_riccati() is None
        assert not compiled_kernels(refine)
    monkeypatch.delenv("TRACKPROC_JIT")
    assert taylor._jit_mode() == "auto"                                    # restored after the block


REML_MODELS = [
    nz.NoiseModel(0.6, 1.2, 25.0, 0.0),            # AR(1)
    nz.NoiseModel(0.6, 0.0, 0.0, 0.03),            # walk
    *BOTH,
    nz.NoiseModel(0.7, 7e-4, 900.0, 0.05),         # an AR(1) the offset and drift nearly absorb
]


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("model", REML_MODELS, ids=lambda m: m.name + f"-{m.white}")
def test_compiled_reml_pass_against_the_dense_likelihood(model, seed, monkeypatch):
    """The search's one-pass restricted likelihood (whitening_jit.reml_terms via _Reml.fast)
    against the n x n Cholesky form (the oracle) and the O(n) path, scaled and not, to rounding,
    on a grid with duplicate times and near-zero gaps."""
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    assert whitening.compiled_reml() is not None
    t = _grid(seed, 200)
    rng = np.random.default_rng(seed)
    x = nz._basis(np.column_stack([np.ones(t.size), t - t[0], np.sin(t / 40.0), rng.normal(size=t.size)]))
    r = rng.normal(size=t.size) + np.cumsum(rng.normal(0.0, 0.1, t.size))
    for t0 in (float(t[0]), float(t[0]) - 3.0):
        fast, exact = nz._Reml(t, r, x, t0), nz._Reml(t, r, x, t0, dense=True)
        for profile in (True, False):
            ref = exact(model, profile)[0]
            assert fast.fast(model, profile) == pytest.approx(ref, rel=1e-10, abs=1e-8)
            assert fast.fast(model, profile) == pytest.approx(fast(model, profile)[0], rel=1e-11, abs=1e-9)


def test_compiled_reml_pass_refuses_a_covariance_not_positive_definite(monkeypatch):
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    t = np.arange(50.0)
    x = nz._basis(np.ones((50, 1)))
    reml = nz._Reml(t, np.random.default_rng(1).normal(size=50), x, 0.0)
    bad = nz.NoiseModel(0.0, 0.0, 0.0, 0.1)          # no white noise, a walk from 0 at t0: S_0 = 0
    assert reml.fast(bad) == -np.inf == reml(bad)[0]
    assert np.isnan(whitening.compiled_reml()(np.ones(1), np.zeros(2), 0.0, 0.0, 0.0, -1.0, np.ones((2, 2)), 1)[0])


def test_compiled_reml_pass_log_determinant_over_a_wide_range_of_variances(monkeypatch):
    """log|C| summed through products: variances near 1e±200 and products beyond the double range."""
    monkeypatch.setenv("TRACKPROC_JIT", "1")
    t = np.arange(400.0)
    rng = np.random.default_rng(3)
    x = nz._basis(np.column_stack([np.ones(t.size), t]))
    for white in (1e-100, 1e-20, 1.0, 1e20, 1e100):
        r = white * rng.normal(size=t.size)
        reml = nz._Reml(t, r, x, 0.0)
        for model in (nz.NoiseModel(white, 0.5 * white, 30.0), nz.NoiseModel(white, 0.0, 0.0, 0.01 * white)):
            assert reml.fast(model, profile=False) == pytest.approx(reml(model, profile=False)[0], rel=1e-11)
    # a first variance just below 1e150, the next ones near 1e160: their product is beyond the doubles
    r = 1e80 * rng.normal(size=t.size)
    model = nz.NoiseModel(10.0 ** 74.6, 0.0, 0.0, 1e80)
    reml = nz._Reml(t, r, x, 0.0)
    assert reml.fast(model, profile=False) == pytest.approx(reml(model, profile=False)[0], rel=1e-11)
