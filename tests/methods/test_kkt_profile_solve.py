"""solve_kkt as the profile covariance calls it: a linear constraint held at a node (the null-space
factorisation reused across iterates, the covariance from the run's last linearisation) and without
its diagnostics: checked against the closed form of equality-constrained least squares."""

import numpy as np
import pytest

from trackproc.methods.least_squares import Options, Prior
from trackproc.methods.refinement import solve_kkt


def _problem(nonlinear: float):
    rng = np.random.default_rng(11)
    a = rng.normal(size=(60, 5)) * [1.0, 3.0, 0.5, 2.0, 1.0]
    x_true = np.array([1.0, -2.0, 3.0, 0.5, -1.0])
    sig = rng.uniform(0.5, 1.5, 60)

    def model(x):
        # a mild quadratic term makes it take several Gauss-Newton iterations (0: linear)
        h = a @ x + nonlinear * (a[:, 0] * x[1] ** 2)
        jac = a.copy()
        jac[:, 1] += nonlinear * 2.0 * x[1] * a[:, 0]
        return h, jac

    y = model(x_true)[0] + rng.normal(size=60) * sig
    row = rng.normal(size=5)
    prior = Prior(np.array([2, 3]), np.array([3.2, 0.4]), np.diag([0.5, 0.8]) ** 2)
    return a, model, y, sig, row, prior


def _solve(model, y, sig, row, prior, target, diagnostics):
    def constraint(x):
        return np.array([row @ x - target]), row[None, :]

    return solve_kkt(model, np.zeros(5), y, sig, names=list("abcde"), constraints=constraint,
                     constraint_scale=lambda x: np.array([1.0]), scales=np.array([1.0, 0.5, 2.0, 1.0, 1.0]),
                     priors=[prior], options=Options(clip=None, step_tol=1e-9), diagnostics=diagnostics)


@pytest.mark.parametrize("diagnostics", [True, False])
def test_linear_constraint_matches_the_closed_form(diagnostics):
    """Linear model, one linear constraint rᵀx = t and an a-priori: the solution and its covariance
    are those of the bordered normal equations [[N, r], [rᵀ, 0]] (N = Jᵀ W J + prior information);
    the covariance is the top-left block of that matrix's inverse."""
    a, model, y, sig, row, prior = _problem(0.0)
    target = 1.7
    k = _solve(model, y, sig, row, prior, target, diagnostics)
    w = 1.0 / sig ** 2
    p_inv = np.zeros((5, 5))
    p_inv[np.ix_(prior.index, prior.index)] = np.linalg.inv(prior.covariance)
    p_rhs = np.zeros(5)
    p_rhs[prior.index] = np.linalg.solve(prior.covariance, prior.centre)
    normal = a.T @ (a * w[:, None]) + p_inv
    bordered = np.block([[normal, row[:, None]], [row[None, :], np.zeros((1, 1))]])
    full = np.linalg.inv(bordered)
    x_ref = full @ np.r_[a.T @ (w * y) + p_rhs, target]
    np.testing.assert_allclose(k.solution.values, x_ref[:5], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(k.solution.covariance, full[:5, :5], rtol=1e-7, atol=1e-12)
    assert abs(row @ k.solution.values - target) < 1e-12
    assert (k.multipliers is None) == (not diagnostics) and (k.sensitivity is None) == (not diagnostics)


def test_without_diagnostics_the_same_solution_bit_for_bit():
    """Several Gauss-Newton iterations (a curved model): the point and covariance without the
    diagnostics are exactly those with them (the diagnostics only read the solution)."""
    _, model, y, sig, row, prior = _problem(0.05)
    with_d = _solve(model, y, sig, row, prior, -0.8, True)
    without = _solve(model, y, sig, row, prior, -0.8, False)
    assert with_d.solution.iterations >= 2
    assert np.array_equal(with_d.solution.values, without.solution.values)
    assert np.array_equal(with_d.solution.covariance, without.solution.covariance)
    assert np.isnan(without.stationarity) and with_d.stationarity < 1e-6
    # the covariance is the bordered normal matrix's at the solution's own Jacobian
    jac = model(without.solution.values)[1]
    p_inv = np.zeros((5, 5))
    p_inv[np.ix_(prior.index, prior.index)] = np.linalg.inv(prior.covariance)
    normal = jac.T @ (jac / sig[:, None] ** 2) + p_inv
    full = np.linalg.inv(np.block([[normal, row[:, None]], [row[None, :], np.zeros((1, 1))]]))
    np.testing.assert_allclose(without.solution.covariance, full[:5, :5], rtol=1e-7, atol=1e-12)
    # the constrained covariance is singular across the constraint: no variance along rᵀx
    assert abs(row @ without.solution.covariance @ row) < 1e-10 * np.trace(without.solution.covariance)
