"""Seed 002: the extended-state theorem (eqs. 10-16) and the two-stage method (eqs. 17-22),
checked numerically with the Jacobians of a simulated case and with random matrices."""

from __future__ import annotations

import numpy as np
import pytest
from test_estimate import BIASES, EOP, TRUTH, simulated, tables

from trackproc.methods import two_stage as tsm
from trackproc.pipeline.estimate import EstimateOptions, build_problem, estimate

RNG = np.random.default_rng(7)


def _rel(a, b):
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(b).max())


@pytest.fixture(scope="module")
def jacobians():
    """A1 (Doppler partials), A2 (range partials) and E of a 3-station simulation at the truth."""
    sim = simulated(kinds=("doppler", "range"), hours=12.0)
    # the paper's setting: no transmitter parameters (the simulated Doppler has no offset)
    pb = build_problem(tables(sim), TRUTH, None, EstimateOptions(range_bias=True, doppler_bias="none"), EOP)
    _, jac = pb.model(pb.x0)
    names = pb.names
    motion = [i for i, n in enumerate(names) if not n.startswith("range_bias:")]
    bias = [i for i, n in enumerate(names) if n.startswith("range_bias:")]
    dop = pb.meas.kind == "doppler"
    rng_rows = np.flatnonzero(pb.meas.kind == "range")
    return {"a1": jac[dop][:, motion], "k_n": pb.meas.sigma[dop] ** 2, "a2": jac[rng_rows][:, motion],
            "e": jac[rng_rows][:, bias], "pi": pb.meas.sigma[rng_rows] ** 2,
            "station": pb.meas.station[rng_rows], "bias_names": [names[i] for i in bias]}


def test_seed002_theorem_one_range_per_offset(jacobians):
    """Eqs. 15-16 to round-off: with one range per offset (the paper's setting) the motion block
    of the extended error matrix is the Doppler-only one, and the offsets' block is Π + A2 K A2ᵀ."""
    j = jacobians
    stations = [n.split(":")[1] for n in j["bias_names"]]
    pick = [int(np.flatnonzero(j["station"] == s)[len(np.flatnonzero(j["station"] == s)) // 2]) for s in stations]
    a2, e, pi = j["a2"][pick], j["e"][pick], j["pi"][pick]
    np.testing.assert_array_equal(e, np.eye(len(stations)))
    full = tsm.extended_covariance(j["a1"], j["k_n"], a2, pi, e)
    m = j["a1"].shape[1]
    k_motion, k_offsets = tsm.theorem_blocks(j["a1"], j["k_n"], a2, pi)
    assert _rel(full[:m, :m], k_motion) < 1e-9
    assert _rel(full[m:, m:], k_offsets) < 1e-9
    assert _rel(full[:m, m:], -k_motion @ a2.T) < 1e-9                       # eq. 14 off-diagonal block


def test_seed002_many_ranges_per_offset_add_information(jacobians):
    """With every range sample of each station the motion block is strictly smaller: the
    difference (Doppler-only minus extended) is positive definite."""
    j = jacobians
    full = tsm.extended_covariance(j["a1"], j["k_n"], j["a2"], j["pi"], j["e"])
    m = j["a1"].shape[1]
    k1 = tsm.covariance(j["a1"], j["k_n"])
    diff = k1 - full[:m, :m]
    l_inv = np.linalg.inv(np.linalg.cholesky(k1))
    w = np.linalg.eigvalsh(l_inv @ diff @ l_inv.T)            # relative to K1 itself
    assert w.min() > 1e-4, w
    assert np.all(np.sqrt(np.diag(full[:m, :m])) < np.sqrt(np.diag(k1)))


def test_two_stage_lemma_random_matrices():
    m, n2 = 6, 9
    a = RNG.normal(size=(40, m))
    k = tsm.covariance(a, np.full(40, 0.3))
    a2 = RNG.normal(size=(n2, m))
    b = RNG.normal(size=(n2, n2))
    pi = b @ b.T + np.eye(n2)
    k_prime, dk, s = tsm.two_stage_update(k, a2, pi)
    np.testing.assert_allclose(s, pi + a2 @ k @ a2.T)
    assert _rel(k_prime, tsm.information_update(k, a2, pi)) < 1e-12         # eq. 19 = eqs. 20-21
    assert _rel(dk, k @ a2.T @ np.linalg.inv(s) @ a2 @ k) < 1e-10          # eq. 22
    assert tsm.is_psd(dk) and np.linalg.eigvalsh(dk).min() > 0             # n2 >= m: positive definite


def test_compress_gives_the_same_update(jacobians):
    j = jacobians
    rows = np.arange(0, j["a2"].shape[0], 3)
    a2, e, d = j["a2"][rows], j["e"][rows], j["pi"][rows]
    b = RNG.normal(size=(e.shape[1], e.shape[1]))
    pi_off = b @ b.T + 4.0 * np.eye(e.shape[1])
    k = tsm.covariance(j["a1"], j["k_n"])
    big = np.diag(d) + e @ pi_off @ e.T
    ref, dk_ref, _ = tsm.two_stage_update(k, a2, big)
    a2c, eye = tsm.compress(a2, d, e, pi_off)
    got, dk_got, _ = tsm.two_stage_update(k, a2c, eye)
    assert a2c.shape == (k.shape[0], k.shape[0])
    assert _rel(got, ref) < 1e-10 and _rel(dk_got, dk_ref) < 1e-9


def test_accumulate_weighted_means():
    est = np.array([1.0, 3.0, 10.0])
    c = np.diag([1.0, 3.0, 2.0])
    means, pi, m = tsm.accumulate(est, c, ["A", "A", "B"], ["A", "B"])
    np.testing.assert_allclose(means, [(1.0 + 3.0 / 3) / (1 + 1 / 3), 10.0])
    np.testing.assert_allclose(pi, np.diag([1.0 / (1 + 1 / 3), 2.0]))
    with pytest.raises(ValueError, match="no pass"):
        tsm.accumulate(est, c, ["A", "A", "B"], ["A", "C"])


def test_two_stage_method_in_the_pipeline():
    """``--two-stage``: K, K', ΔK reported; ΔK positive semidefinite; K' = K - ΔK to round-off,
    with ΔK = K A2ᵀ S⁻¹ A2 K, S = Π + A2 K A2ᵀ; stage-1 offsets near the truth."""
    sim = simulated(kinds=("doppler", "range"), hours=12.0)
    res = estimate(tables(sim), TRUTH, None, EstimateOptions(range_bias=True, two_stage=True,
                                                             compare_doppler_only=True), EOP)
    two = res.two_stage
    assert two.identity_error < 1e-9
    assert tsm.is_psd(two.delta_k)
    np.testing.assert_allclose(two.k - two.delta_k, two.k_prime, rtol=0, atol=1e-9 * np.abs(two.k).max())
    assert np.all(np.diag(two.k_prime) <= np.diag(two.k))
    for name, b, p in zip(two.stations, two.biases, np.sqrt(np.diag(two.pi))):
        assert abs(b - BIASES[name]) < 3 * p
    # the explicit S form on the same Jacobian (n2 x n2) agrees with the compressed report
    sol2 = res.two_stage_solution
    pb = res.problem
    names = sol2.names
    mcol = [names.index(n) for n in two.names]
    bidx = [names.index(f"range_bias:{s}") for s in two.stations]
    isr = (pb.meas.kind == "range") & ~sol2.edited
    a2 = sol2.jacobian[isr][:, mcol]
    e = sol2.jacobian[isr][:, bidx]
    big = np.diag(pb.meas.sigma[isr] ** 2) + e @ two.pi @ e.T
    k_prime, dk, s = tsm.two_stage_update(two.k, a2, big)
    assert _rel(k_prime, two.k_prime) < 1e-9 and _rel(dk, two.delta_k) < 1e-6
    # the comparison report: without the ranges vs extended
    c = res.comparison
    assert c["relative_reduction_min"] > -1e-6 and c["relative_reduction_max"] > 0.1 and len(c["doppler_only_sigma"]) == len(c["parameters"])
    d = res.state.diagnostics["two_stage"]
    assert set(d) >= {"K", "K_prime", "delta_K", "Pi", "stage1_offsets_m", "identity_error", "passes"}
