"""The least-squares linearisation's R (methods/least_squares/iteration._tall_r, LAPACK dgeqrf by
SciPy's wrapper) is numpy's ``qr(mode="r")`` of the same augmented matrix bit for bit: the solves'
numbers (and the golden outputs) do not depend on which wrapper called the routine."""

import numpy as np
import pytest

from trackproc.methods.least_squares import iteration as it


@pytest.mark.parametrize("seed", range(6))
def test_the_same_r_as_numpys_qr(seed):
    rng = np.random.default_rng(seed)
    for m, n in ((9, 8), (40, 7), (600, 7), (1066, 9), (318, 8)):
        j = rng.normal(size=(m, n)) * 10.0 ** rng.uniform(-6, 6, n)        # columns of very different scales
        if seed % 2:
            j[:, -1] = j[:, 0] * (1 + 1e-12) + 1e-9 * rng.normal(size=m)     # nearly dependent columns
        b = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
        want = np.linalg.qr(np.column_stack([j, b]), mode="r")
        got = it._tall_r(j, b)
        assert got.shape == (n, n + 1)
        assert got.tobytes() == np.ascontiguousarray(want[:n]).tobytes()
        # and the solver's outputs from it: the same singular values and projected right-hand side
        u, s, vt = it.whitened_svd(j, b)
        u0, s0, vt0 = np.linalg.svd(want[:n, :n])
        assert s.tobytes() == s0.tobytes() and u.tobytes() == (u0.T @ want[:n, n]).tobytes()


def test_r_is_a_factor_of_the_matrix():
    rng = np.random.default_rng(11)
    j, b = rng.normal(size=(200, 5)), rng.normal(size=200)
    a = np.column_stack([j, b])
    r = np.vstack([it._tall_r(j, b), np.zeros((1, 6))])
    r[5, 5] = np.linalg.norm(b - j @ np.linalg.lstsq(j, b, rcond=None)[0])   # the residual's norm: R's last entry
    assert np.allclose(np.abs(np.linalg.qr(a, mode="r")), np.abs(r), rtol=1e-10, atol=1e-12)
    assert np.allclose(r.T @ r, a.T @ a, rtol=1e-10)


def test_prior_rows_kept_are_the_computed_ones_with_the_callers_priors():
    from trackproc.methods.least_squares.types import Prior

    rng = np.random.default_rng(5)
    m = rng.normal(size=(6, 6))
    cov = m @ m.T + 6 * np.eye(6)
    scales = 10.0 ** rng.uniform(-2, 3, 8)
    first = [Prior(np.arange(6), rng.normal(size=6), cov), Prior(np.array([7]), np.array([0.5]), np.array([[4.0]]))]
    later = [Prior(p.index, p.centre + 1.0, p.covariance) for p in first]     # other centres, same rows
    it._PRIOR_ROWS.clear()
    want_a, want_f = it._prior_rows(first, 8, scales)
    for priors in (first, later, later):
        a, factors = it.prior_rows(priors, 8, scales)
        assert a.tobytes() == want_a.tobytes()
        assert all(w.tobytes() == w0.tobytes() and p is q for (w, p), (w0, _), q in zip(factors, want_f, priors))
        a[...] = 0.0                                           # a caller's change does not reach the kept rows
        factors[0][0][...] = 0.0
        x = rng.normal(size=8)
        assert it.prior_rhs(it.prior_rows(priors, 8, scales)[1], x).tobytes() == \
            it.prior_rhs([(w, p) for (w, _), p in zip(want_f, priors)], x).tobytes()
    other = it.prior_rows([Prior(np.arange(6), first[0].centre, 2.0 * cov)], 8, scales)[0]
    assert not np.array_equal(other, want_a[:6])               # another covariance: its own rows
