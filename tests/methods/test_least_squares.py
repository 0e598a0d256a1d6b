"""The batch least-squares solver: closed-form linear cases, nonlinear convergence, damping,
editing, a-priori, and the failures (rank deficiency, too few data, non-convergence)."""

import numpy as np
import pytest

from trackproc.errors import ProcessingError
from trackproc.methods.least_squares import Options, Prior, combination_text, solve


def _linear(a):
    return lambda x: (a @ x, a.copy())


def test_linear_case_matches_the_normal_equations_closed_form():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(200, 4)) * [1.0, 10.0, 0.1, 3.0]
    x_true = np.array([1.0, -2.0, 30.0, 0.5])
    sig = rng.uniform(0.5, 2.0, 200)
    y = a @ x_true + rng.normal(size=200) * sig
    sol = solve(_linear(a), np.zeros(4), y, sig, names=list("abcd"), scales=[1, 0.1, 10, 1],
                options=Options(clip=None))
    w = 1.0 / sig ** 2
    n = a.T @ (a * w[:, None])
    np.testing.assert_allclose(sol.values, np.linalg.solve(n, a.T @ (w * y)), rtol=1e-10)
    np.testing.assert_allclose(sol.covariance, np.linalg.inv(n), rtol=1e-9)      # seed 002 eq. 9
    np.testing.assert_allclose(sol.sigma, np.sqrt(np.diag(np.linalg.inv(n))), rtol=1e-9)
    np.testing.assert_allclose(np.diag(sol.correlation), 1.0)
    assert sol.dof == 196 and sol.variance_factor == pytest.approx(sol.chi2 / 196)
    assert 0.7 < sol.variance_factor < 1.3
    assert sol.converged and sol.iterations <= 2
    np.testing.assert_allclose(sol.residual, y - a @ sol.values, atol=1e-9)
    np.testing.assert_allclose(sol.normalized, sol.residual / sig)


def test_ill_conditioned_linear_case_keeps_precision():
    """Condition number 2e7: the normal matrix has 4e14 (squared) and loses most digits."""
    t = np.linspace(0.0, 1.0, 50)
    a = np.vander(t, 11, increasing=True)
    x_true = np.arange(1.0, 12.0)
    y = a @ x_true
    sol = solve(_linear(a), np.zeros(11), y, np.full(50, 1e-3), names=[f"c{i}" for i in range(11)],
                options=Options(clip=None, rank_rtol=1e-12))
    assert sol.condition_number > 1e7
    np.testing.assert_allclose(sol.values, x_true, rtol=0, atol=1e-7)
    naive = np.linalg.solve(a.T @ a, a.T @ y)                 # what the solver avoids
    assert np.abs(naive - x_true).max() > 100 * np.abs(sol.values - x_true).max()


def test_nonlinear_fit_converges_with_damping_from_a_poor_start():
    t = np.linspace(0.0, 10.0, 80)
    truth = np.array([3.0, 0.4, 1.3])

    def model(p):
        amp, rate, freq = p
        h = amp * np.exp(-rate * t) * np.cos(freq * t)
        jac = np.stack([h / amp, -t * h, -amp * np.exp(-rate * t) * t * np.sin(freq * t)], -1)
        return h, jac

    rng = np.random.default_rng(0)
    y = model(truth)[0] + rng.normal(0, 0.01, t.size)
    sol = solve(model, [1.0, 1.0, 1.0], y, np.full(t.size, 0.01), names=["amp", "rate", "freq"],
                options=Options(clip=None, max_iterations=50))
    assert np.all(np.abs(sol.values - truth) < 4 * sol.sigma)
    assert sol.damped_steps >= 1
    assert all(b <= a * (1 + 1e-12) for a, b in zip(sol.cost_history, sol.cost_history[1:]))


def test_editing_flags_outliers_and_keeps_them_reported():
    rng = np.random.default_rng(5)
    a = np.column_stack([np.ones(300), np.linspace(-1, 1, 300)])
    y = a @ [5.0, 2.0] + rng.normal(0, 0.1, 300)
    bad = [10, 150, 299]
    y[bad] += [3.0, -2.0, 1.5]
    sol = solve(_linear(a), np.zeros(2), y, np.full(300, 0.1), names=["c", "s"], options=Options(clip=4.0))
    assert set(np.flatnonzero(sol.edited)) >= set(bad)
    assert sol.n_edited <= 5
    assert abs(sol.values[0] - 5.0) < 4 * sol.sigma[0]
    assert sol.residual[10] > 2.5                      # edited samples still carry residuals
    assert sol.dof == 300 - sol.n_edited - 2


def test_apriori_makes_a_deficient_problem_solvable_and_enters_the_covariance():
    a = np.column_stack([np.ones(50), np.ones(50)])    # only the sum is observed
    y = np.full(50, 3.0)
    with pytest.raises(ProcessingError) as caught:
        solve(_linear(a), np.zeros(2), y, np.ones(50), names=["x", "range_bias:KIR"])
    msg = str(caught.value)
    assert "rank-deficient" in msg and "x" in msg and "range_bias:KIR" in msg
    assert caught.value.diagnostics["unobservable"] == ["+0.71 x -0.71 range_bias:KIR"] or \
        caught.value.diagnostics["unobservable"] == ["+0.71 range_bias:KIR -0.71 x"]
    sol = solve(_linear(a), np.zeros(2), y, np.ones(50), names=["x", "b"],
                priors=[Prior.diagonal([1], [1.0], [0.5])])
    info = a.T @ a + np.diag([0.0, 4.0])
    np.testing.assert_allclose(sol.covariance, np.linalg.inv(info), rtol=1e-9)
    np.testing.assert_allclose(sol.values, [2.0, 1.0], atol=1e-9)
    assert sol.dof == 50 + 1 - 2


def test_full_prior_covariance_block():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(20, 3))
    cov_p = np.array([[4.0, 1.0], [1.0, 2.0]])
    sol = solve(_linear(a), np.zeros(3), a @ [1.0, 2.0, 3.0], np.ones(20), names=list("abc"),
                priors=[Prior(np.array([0, 2]), np.array([1.0, 3.0]), cov_p)], options=Options(clip=None))
    e = np.zeros((2, 3))
    e[0, 0] = e[1, 2] = 1.0
    np.testing.assert_allclose(sol.covariance, np.linalg.inv(a.T @ a + e.T @ np.linalg.inv(cov_p) @ e), rtol=1e-9)


def test_too_few_measurements_is_a_processing_error():
    a = np.ones((2, 3))
    with pytest.raises(ProcessingError, match="too few measurements: 2 kept"):
        solve(_linear(a), np.zeros(3), np.ones(2), np.ones(2), names=list("abc"))


def test_non_convergence_is_a_processing_error_with_history():
    t = np.linspace(0.0, 10.0, 80)

    def model(p):
        h = p[0] * np.exp(-p[1] * t)
        return h, np.stack([h / p[0], -t * h], -1)

    y = model([3.0, 0.4])[0]
    with pytest.raises(ProcessingError, match="did not converge in 1 iterations") as caught:
        solve(model, [1.0, 0.05], y, np.full(80, 1e-3), names=["a", "k"], options=Options(max_iterations=1))
    assert len(caught.value.diagnostics["cost_history"]) == 2


def test_azimuth_residuals_wrap():
    a = np.ones((4, 1))
    y = np.array([0.01, 2 * np.pi - 0.01, 0.02, 2 * np.pi - 0.02])
    sol = solve(_linear(a), [0.0], y, np.full(4, 0.01), names=["az"], periodic=np.ones(4, bool),
                options=Options(clip=None))
    assert abs(sol.values[0]) < 1e-12
    assert np.all(np.abs(sol.residual) < 0.03)


def test_model_failure_at_trial_point_is_damped():
    t = np.linspace(0, 1, 30)

    def model(p):
        if p[0] > 10:
            raise ArithmeticError("propagation failed")
        return p[0] * t + p[1], np.column_stack([t, np.ones_like(t)])

    y = 2.0 * t + 1.0
    sol = solve(model, [9.9, 0.0], y, np.full(30, 0.01), names=["a", "b"])
    np.testing.assert_allclose(sol.values, [2.0, 1.0], atol=1e-9)


def test_combination_text():
    assert combination_text(np.array([0.0, -1.0, 1.0]), ["a", "b", "c"]) in ("+0.71 b -0.71 c", "+0.71 c -0.71 b")
