"""The bounded trust-region solver against scipy's least_squares(trf) on the same problems."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from frictiond import tyre_model as tm
from frictiond.trust_region import solve, solve_normal


def rosenbrock(x):
    r = np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])
    J = np.array([[-20 * x[0], 10.0], [-1.0, 0.0]])
    return r, J


@pytest.mark.parametrize(
    "lb,ub,expected",
    [((-2, -2), (2, 2), (1.0, 1.0)), ((-2, -2), (0.5, 2), (0.5, 0.25)), ((-2, -2), (3, 0.5), None)],
)
def test_rosenbrock_with_bounds_matches_least_squares(lb, ub, expected):
    lb, ub = np.array(lb, float), np.array(ub, float)
    res = solve(rosenbrock, np.array([-1.2, 0.4]), lb, ub, max_iterations=300, ftol=1e-14, xtol=1e-14, gtol=1e-14)
    ref = least_squares(lambda x: rosenbrock(x)[0], [-1.2, 0.4], jac=lambda x: rosenbrock(x)[1], bounds=(lb, ub),
                        method="trf", ftol=1e-14, xtol=1e-14, gtol=1e-14)
    assert res.converged
    assert np.all(res.x >= lb) and np.all(res.x <= ub)
    np.testing.assert_allclose(res.x, ref.x, atol=1e-5)
    assert res.cost == pytest.approx(ref.cost, abs=1e-8)
    if expected is not None:
        np.testing.assert_allclose(res.x, expected, atol=1e-5)


def test_recovers_lugre_parameters_from_exact_data():
    rng = np.random.default_rng(7)
    truth = tm.LugreParams(theta=1.6, sigma0=260.0, v_s=4.0, sigma2=0.003)
    slip = rng.uniform(0.005, 0.5, 300)
    speed = rng.uniform(5, 30, 300)
    y = tm.mu(slip, speed, truth)
    names = ("theta", "sigma0", "v_s", "sigma2")
    scale = np.array([1.0, 180.0, 6.57, 0.0018])

    def fun(x):
        p = truth.with_values(**dict(zip(names, x * scale)))
        m, J = tm.mu_and_jacobian(slip, speed, p, names)
        return m - y, J * scale

    res = solve(fun, np.array([1.0, 1.0, 1.0, 1.0]), np.array([0.3, 0.1, 0.05, 0.0]), np.array([40, 10, 10, 10.0]),
                max_iterations=200, ftol=1e-15, xtol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(res.x * scale, [1.6, 260.0, 4.0, 0.003], rtol=1e-5)


def test_iteration_bound_and_warm_radius_are_honoured():
    res = solve(rosenbrock, np.array([-1.2, 1.0]), np.array([-5.0, -5.0]), np.array([5.0, 5.0]), max_iterations=2)
    assert res.iterations == 2 and not res.converged
    again = solve(rosenbrock, res.x, np.array([-5.0, -5.0]), np.array([5.0, 5.0]), radius=res.radius, max_iterations=2)
    assert again.cost < res.cost


def test_predicted_ftol_skips_evaluating_a_step_that_promises_almost_nothing():
    def normal(x):
        r, J = rosenbrock(x)
        return 0.5 * float(r @ r), J.T @ r, J.T @ J, None

    near = np.array([0.999, 0.998])
    plain = solve_normal(normal, near, np.full(2, -np.inf), np.full(2, np.inf), max_iterations=5)
    early = solve_normal(normal, near, np.full(2, -np.inf), np.full(2, np.inf), max_iterations=5,
                         predicted_ftol=2.0)   # a Gauss–Newton step never promises more than the cost
    assert plain.evaluations > 1 and plain.cost < 1e-12
    assert early.evaluations == 1 and early.converged
    np.testing.assert_array_equal(early.x, near)
