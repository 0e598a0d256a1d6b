"""A refinement's noise model carried to another refinement of the same pass without REML
(pipeline/refine/problem.with_noise_of): at another solution epoch (a traverse re-solve) and with
samples removed (a second signal edited out). Independent reference: the covariance of the source
refinement at the same instants — the noise model depends on time differences and on the instant
its random walk starts, not on the epoch the times are counted from."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from trackproc.io.statefile import State
from trackproc.methods import noise as nz
from trackproc.pipeline.refine import RefineOptions, prepare
from trackproc.pipeline.refine.problem import with_noise_of

from test_refine import EOP, EPOCH, STALE_RV, scenario, table

MODEL = nz.NoiseModel(0.5, 2.0, 30.0, 0.05)   # white, AR(1) sigma (Hz) and tau (s), walk (Hz/sqrt(s))
MOVE_S = 20.0


def _pair():
    """The pass refined at its own epoch with a noise model whose walk starts 5 s after the first
    sample, and the same pass prepared at an epoch ``MOVE_S`` later."""
    _, _, sim = scenario(noise=False)
    stale = State.from_vectors(EPOCH, STALE_RV[:3], STALE_RV[3:])
    opt = RefineOptions(doppler_bias="offset+drift")
    ref = prepare(table(sim), stale, None, opt, EOP)
    t = ref.problem.meas.t_s
    noise = nz.PassCovariance(ref.problem.meas.sigma, t, [(np.arange(t.size), MODEL, float(t.min()) + 5.0)])
    edited = np.zeros(t.size, bool)
    edited[3] = True
    ref = replace(ref, noise=noise, noise_edited=edited, noise_report={"model": "test"})
    epoch = ref.problem.epoch + np.timedelta64(int(MOVE_S * 1e9), "ns")
    moved = prepare(table(sim), stale, None, replace(opt, traverse_epoch=epoch), EOP)
    return ref, moved


def _cov(r):
    (_, model, t0), = r.noise.blocks
    return model.covariance(r.problem.meas.t_s, t0)


def test_the_noise_model_carries_over_to_another_epoch_either_way():
    ref, moved = _pair()
    assert np.allclose(moved.problem.meas.t_s, ref.problem.meas.t_s - MOVE_S, rtol=0, atol=1e-6)
    same = with_noise_of(moved, ref)
    other = with_noise_of(moved, ref, same_samples=False)
    want = _cov(ref)
    for carried in (same, other):
        assert carried.noise_report == {"model": "test"}
        assert np.isclose(carried.noise.blocks[0][2], ref.noise.blocks[0][2] - MOVE_S, rtol=0, atol=1e-6)
        np.testing.assert_allclose(_cov(carried), want, rtol=1e-9, atol=1e-12)
    assert same.noise_edited is ref.noise_edited          # the same samples: the fit's edits stand
    assert other.noise_edited is None                     # other samples: nothing starts edited


def test_with_samples_removed_the_block_spans_what_is_left():
    ref, _ = _pair()
    keep = np.arange(ref.problem.meas.t_s.size) >= 10
    fewer = replace(ref, problem=replace(ref.problem, meas=ref.problem.meas.subset(keep)))
    carried = with_noise_of(fewer, ref, same_samples=False)
    (idx, _, t0), = carried.noise.blocks
    assert np.array_equal(idx, np.arange(int(keep.sum())))
    assert t0 == ref.noise.blocks[0][2]                    # the same epoch: the walk starts where it did
    np.testing.assert_allclose(_cov(carried), _cov(ref)[np.ix_(keep, keep)], rtol=1e-9, atol=1e-12)
